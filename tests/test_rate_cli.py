"""`cft-action topic echo --poll N` and `topic hz --max-rate HZ`: the real CLI as subprocesses,
against a publisher under the guard in its own process (its writer drops what is not asked for)."""

import re

from cft_action import guard
from harness.ros import unique_name
from tests.support import helper_process
from tests.test_topic_cli import Cli, RELIABLE, run_cli


def test_poll_prints_n_per_publisher_and_exits_and_max_rate_limits_hz():
    prefix = '/' + unique_name('cft_rate_cli')
    topic = prefix + '/ints'
    child = helper_process('tests.helpers.publisher', [prefix], env=guard.environment())
    clis = []
    try:
        clis = [Cli('topic', 'echo', topic, 'std_msgs/msg/Int32', '--poll', '3', '--timeout', '30',
                    *RELIABLE),
                Cli('topic', 'hz', topic, 'std_msgs/msg/Int32', '--max-rate', '5', '--timeout',
                    '10', *RELIABLE)]
        assert child.request('wait ints 2', 'MATCHED') == 'MATCHED'
        child.send('steady 100 4 0')
        echo, hz = clis
        assert echo.wait(30) == 0, echo.log()  # by itself, once the publisher's 3 came
        assert [d['data'] for d in echo.documents()] == [0, 1, 2], echo.log()
        assert hz.wait(30) == 0, hz.log()
        # The first message after each 0.2 s passes the writer: 4 s make 20 (21 with the first),
        # all before hz's --timeout, which counts from its start. hz's rate is of arrival times,
        # which a loaded machine bunches; the count is the writer's decision.
        windows = [int(m) for m in re.findall(r'window: ([0-9]+)', '\n'.join(hz.stdout))]
        assert windows and 18 <= windows[-1] <= 21, hz.log()
    finally:
        for cli in clis:
            cli.interrupt()
        child.stop()


def test_rate_flags_reject_a_content_filter_and_bad_values():
    topic = '/' + unique_name('cft_rate_bad')
    combined = run_cli('topic', 'echo', topic, 'std_msgs/msg/Int32', '--max-rate', '2',
                       '--content-filter', 'data > 0', '--timeout', '5')
    assert combined.proc.returncode == 2, combined.log()
    assert 'take no --content-filter' in '\n'.join(combined.stderr), combined.log()
    for flags in (['--max-rate', '0'], ['--poll', '-1']):
        bad = run_cli('topic', 'echo', topic, 'std_msgs/msg/Int32', *flags, '--timeout', '5')
        assert bad.proc.returncode == 2, bad.log()
        assert flags[0] in '\n'.join(bad.stderr), bad.log()
