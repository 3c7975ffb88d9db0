"""A client process for the ActionClient tests: sends goals on command and reports what arrived.

Usage: ``python -m tests.helpers.fib_client ACTION MODE GOALS ORDER [WRITER_FILTERING]``
MODE is a cft_action feedback_filter mode, or ``rclpy``; WRITER_FILTERING is the client's
``writer_filtering`` (default ``guarded``). Before ``READY`` the client proves its
goal service and its feedback path (:func:`tests.support.prove_feedback_path`): wait_for_server
only sees the server in the graph, and a server that matched the client's feedback reader late
loses a goal's first feedback for any client. Then the line ``go`` sends GOALS goals of ORDER
feedback messages each, waits for their results, and prints ``RESULT <json>``; its ``taken`` and
``dropped`` count from the client's creation, ``proof_taken`` is what the proof took of them;
``reader_verdicts`` counts from the creation too, ``proof_verdicts`` is the proof's share;
``responses_dropped`` and ``responses_passed``, from the creation, are the response filter's
(other participants' goal, cancel and result replies dropped by its readers, and its own);
``stale_handles`` counts the goal handles that the status topic left short of SUCCEEDED.
"""

import json
import sys
import time
import uuid

import rclpy
from action_msgs.msg import GoalStatus
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from test_msgs.action import Fibonacci
from unique_identifier_msgs.msg import UUID

from cft_action import ActionClient
from tests.support import connect_helper_client


# rclpy's default depth of 10 drops goal responses and feedback in bursts, and any keep-last
# queue drops when this process lags on a loaded machine: keep all, as the server does.
DEEP = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000,
                  reliability=ReliabilityPolicy.RELIABLE)
#: Seconds without feedback of a goal after which its result is asked for, its feedback complete
#: or not.
QUIET = 2.0
DEEP_QOS = {'goal_service_qos_profile': DEEP, 'result_service_qos_profile': DEEP,
            'cancel_service_qos_profile': DEEP, 'feedback_sub_qos_profile': DEEP}


def main() -> None:
    action, mode, goals, order = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    writer_filtering = sys.argv[5] if len(sys.argv) > 5 else 'guarded'
    rclpy.init()
    node = Node(f'cft_test_client_{uuid.uuid4().hex[:8]}')
    if mode == 'rclpy':
        from rclpy.action import ActionClient as RclpyActionClient
        client = RclpyActionClient(node, Fibonacci, action, **DEEP_QOS)
        client.new_goal_uuid = lambda: UUID(uuid=list(uuid.uuid4().bytes))
    else:
        client = ActionClient(node, Fibonacci, action, feedback_filter=mode,
                              writer_filtering=writer_filtering, **DEEP_QOS)
    if not connect_helper_client(node, client):
        return
    proof = getattr(client, 'feedback_filter_state', None)
    proof_verdicts = client._reader.reader_verdicts if proof else 0
    print('READY', flush=True)
    sys.stdin.readline()

    received: dict[bytes, list[int]] = {}
    last_heard: dict[bytes, float] = {}
    misrouted = 0

    def callback_for(goal_uuid: bytes):
        def on_feedback(msg):
            nonlocal misrouted
            if bytes(msg.goal_id.uuid) != goal_uuid:
                misrouted += 1
            received[goal_uuid].append(msg.feedback.sequence[0])
            last_heard[goal_uuid] = time.monotonic()
        return on_feedback

    results, handles, unasked = [], [], []

    def on_response(future):
        handles.append(future.result())
        unasked.append(future.result())
        last_heard[bytes(future.result().goal_id.uuid)] = time.monotonic()

    def ask_results() -> None:
        # Plain rclpy forgets a goal's feedback callback when its result arrives, and on a loaded
        # machine a result can overtake the goal's last feedback: ask for a goal's result once its
        # feedback is complete, or after QUIET s without any, so that what counts is the routing.
        for handle in list(unasked):
            key = bytes(handle.goal_id.uuid)
            if len(received[key]) >= order or time.monotonic() - last_heard[key] > QUIET:
                unasked.remove(handle)
                results.append(handle.get_result_async())

    for _ in range(goals):
        goal_uuid = client.new_goal_uuid()
        key = bytes(goal_uuid.uuid)
        received[key] = []
        future = client.send_goal_async(Fibonacci.Goal(order=order), callback_for(key),
                                        goal_uuid=goal_uuid)
        future.add_done_callback(on_response)
        rclpy.spin_once(node, timeout_sec=0)  # a backlog past the queue depths would drop data
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (
            len(results) == goals and all(r.done() for r in results)):
        rclpy.spin_once(node, timeout_sec=0.05)
        ask_results()
    # Stragglers: a sample lost on the way is resent after the writer's next heartbeat (3 s in
    # Fast DDS), after its goal's result; then a second for anything that should not arrive.
    end = time.monotonic() + 10.0
    while time.monotonic() < end and sum(map(len, received.values())) < goals * order:
        rclpy.spin_once(node, timeout_sec=0.05)
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    state = getattr(client, 'feedback_filter_state', None)
    print('RESULT ' + json.dumps({
        'complete_goals': sum(ks == list(range(order)) for ks in received.values()),
        'own_received': sum(len(ks) for ks in received.values()),
        'misrouted': misrouted,
        'goal_ids': [key.hex() for key in received],
        'results': sum(r.done() for r in results),
        # goal handles whose status the status topic did not bring to SUCCEEDED
        'stale_handles': sum(h.status != GoalStatus.STATUS_SUCCEEDED for h in handles),
        'stale_statuses': [h.status for h in handles if h.status != GoalStatus.STATUS_SUCCEEDED],
        # goal index (in sending order) -> the feedback it got, for the first incomplete goals
        'incomplete': repr({i: ks for i, ks in enumerate(received.values())
                            if ks != list(range(order))})[:400],
        **({'taken': state.feedback_taken, 'dropped': state.feedback_dropped,
            'proof_taken': proof.feedback_taken if proof else 0, 'proof_verdicts': proof_verdicts,
            'active': state.active, 'reason': state.reason, 'updates': state.updates,
            'held_goals': state.held_goals, 'arrival_timeouts': state.arrival_timeouts,
            'filtered_in': state.filtered_in, 'reader_verdicts': client._reader.reader_verdicts,
            'responses_dropped': client.response_filter_state.dropped,
            'responses_passed': client.response_filter_state.passed}
           if state else {}),
    }), flush=True)
    sys.stdin.readline()
    client.destroy()
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
