"""Filter events at the server's writer, counted on the server by the guard.

Every change of a client's feedback filter is an event at the server's feedback writer, and on an
unguarded Fast DDS 2.14 server such events can crash it (docs/SAFETY.md). The guard sees each one
(``process_reader_filter_info``) and counts them: a reader of the library's class that it keeps
itself once per event (``kept``, docs/INTERNALS.md section 18), or a filter of the class that it
created or changed for Fast DDS's collection (``changes``, with ``CFT_GUARD_KEEP_READERS=0``), so
the server itself can tell how many events a client caused.
"""

from __future__ import annotations

import uuid

from test_msgs.action import Fibonacci
from unique_identifier_msgs.msg import UUID

from cft_action import ActionClient, guard
from harness.ros import unique_name
from tests.support import action_server, result_of, round_trip, send, server_evidence


def compiled(child) -> int:
    stats = child.request_json('stats', 'STATS')
    # The feedback readers' filters: status readers are kept too (never changed, one each).
    return (stats['guard_filter']['kept'] - stats['guard_status']['kept']
            + stats['guard_filter_class']['changes'])


def test_client_mode_changes_its_filter_only_for_an_untagged_caller_uuid(ros):
    action = '/' + unique_name('fib_events')
    child = action_server(action, 0.01, env=guard.environment())
    try:
        client = ActionClient(ros.node, Fibonacci, action)
        assert client.wait_for_server(timeout_sec=20)
        assert round_trip(ros, client), server_evidence(child)
        # The reader's one filter, created with the client, reaches the writer once.
        assert ros.spin_until(lambda: compiled(child) >= 1, timeout=20)
        created = compiled(child)
        assert created == 1

        feedback = []
        handles = [send(ros, client, 3, feedback_callback=feedback.append) for _ in range(20)]
        handles += [send(ros, client, 3) for _ in range(5)]  # no callback, no term either
        handles.append(send(ros, client, 3, feedback_callback=feedback.append,
                            goal_uuid=client.new_goal_uuid()))
        for handle in handles:
            assert result_of(ros, handle).status == 4  # SUCCEEDED
        ros.spin_for(1.0)
        assert client.feedback_filter_state.updates == 0
        assert compiled(child) == created, 'a client-mode client changed its filter'

        # A caller-supplied UUID without the tag needs a term of its own: one update, one event.
        untagged = send(ros, client, 3, feedback_callback=feedback.append,
                        goal_uuid=UUID(uuid=list(uuid.uuid4().bytes)))
        assert result_of(ros, untagged).status == 4
        assert client.feedback_filter_state.updates == 1
        assert ros.spin_until(lambda: compiled(child) == created + 1, timeout=20)
        client.destroy()
    finally:
        child.stop()
