# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Status on the wire on Fast DDS 3.3+ (Lyrical's 3.6.2, `make compat-kilted`): under the guard,
each of the library's clients, whose status reader asks for its own goals' status only (a
USER_DATA mark, cft_action/action/_goal_status.py), receives the status samples that change one of
its goals, or that it is owed, through the status writer's public sample prefilter
(cft_action/native/guard/fastdds3/, _guard_status.c's verdict, as on Fast DDS 2.14); plain
clients receive every sample. The captures and rules are tests/test_status_wire.py's. As on 2.14,
an owed sample is left for the client to ask for, and the status writer heartbeats every 100 ms.
"""

from __future__ import annotations

import os

import pytest

from tests.test_fastdds3_replies import MISSING
from tests.test_status_wire import (assert_no_stale_handle, assert_own_or_owed, BURST, mixed_run,
                                    status_off_run, status_on_the_wire)

pytestmark = [
    pytest.mark.skipif(MISSING is not None, reason=MISSING or ''),
    pytest.mark.skipif(os.geteuid() != 0, reason='a raw socket needs root'),
]


def test_each_client_receives_the_status_samples_of_its_own_goals() -> None:
    """tests/test_status_wire.py's mixed_run: the library's clients receive the samples that change
    their goals, or owed ones, through the status writer's prefilter (one kept writer)."""
    run = mixed_run()
    status = run.stats_after['guard_status']
    assert status['kept'] == 1 and status['verdicts'] > 0 and status['withheld'] > 0, status
    assert status['unknown'] == status['malformed'] == 0, status


def test_bursts_of_transitions_leave_no_goal_handle_behind() -> None:
    """48 one-feedback goals of six clients, released at once: samples replace each other in the
    keep-last 1 history before the clients acknowledge them, so some are owed, and every handle
    still ends SUCCEEDED, as the plain client's do."""
    run = status_on_the_wire(BURST)
    assert_no_stale_handle(run, BURST)
    assert_own_or_owed(run, BURST)
    status = run.stats_after['guard_status']
    assert status['owed'] > 0 and status['withheld'] > 0, status
    # Owed samples are not sent with the write (the clients ask for the writer's latest), and the
    # status writer heartbeats every 100 ms (its DataWriterQos, set with the routing).
    assert status['deferred'] > 0 and status['heartbeat_periods'] == 1, status


def test_with_the_status_filter_off_every_client_receives_every_sample() -> None:
    """``CFT_GUARD_STATUS=off``: the status writer sends as rmw_fastrtps does, said once."""
    run = status_off_run()
    said = [line for line in run.server_lines if 'status goes to every client' in line]
    assert len(said) == 1, run.server_lines
