"""The reader lock: a process that changes a filter while its reader evaluates it must not crash.

Fast DDS 2.14 replaces a reader's filter expression without a lock against the reader's own
evaluation of it in a receive thread (cft_action/native/reader/_reader_lock.c, docs/INTERNALS.md
section 13). Measured without the lock (2026-12-02): a subscriber that churned its filter against a
20 kHz publisher died with SIGSEGV in 4 of 4 runs of 10-20 s; a `client`-mode client sending 100
goals at once with caller-supplied UUIDs, with goal holding off, in 3 of 3; this test's churn
crashed or hung in 2 of 8 runs of 10 s and passed its survival check in the rest. With the lock:
none of 4 runs of each crashed.
The test therefore also asserts that the hazardous path ran: the reader evaluated its own filter
while it changed, under the lock.
"""

import json

from cft_action import _rcl, guard
from harness.ros import unique_name
from tests.support import helper_process


def test_the_reader_lock_is_installed(ros):
    assert _rcl.reader_lock_status() == ''


def test_filter_changes_while_samples_arrive_do_not_crash_the_reader():
    prefix = '/' + unique_name('cft_churn')
    # Under the guard: the churn is also Fast-DDS#4878's event at the publisher's writer, which
    # crashed an unguarded publisher midway (make test-asan reported it), unasserted.
    publisher = helper_process('tests.helpers.publisher', [prefix, 10], env=guard.environment())
    churn = None
    try:
        publisher.send('flood 40')  # longer than the churn; the publisher is stopped after it
        churn = helper_process('tests.helpers.filter_churn', [f'{prefix}/ints', 6], timeout=40)
        line = churn.expect('SURVIVED', timeout=30)
        assert churn.wait(10) == 0, churn.tail()
    finally:
        if churn is not None:
            churn.stop()
        publisher.stop()
    report = json.loads(line.split(' ', 1)[1])
    assert report['changes'] > 100 and report['received'] > 0, report
    # the reader evaluated its filter itself, under the lock, and every swap took the lock
    assert report['evaluations'] > 0 and report['replacements'] >= report['changes'], report
