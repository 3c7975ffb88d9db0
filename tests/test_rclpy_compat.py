"""The one module that touches rclpy's private names checks them, and names what is missing."""

import pathlib
import re
import time

import pytest
from rclpy.node import Node

from cft_action import _rclpy_compat
from cft_action.errors import BindingUnavailable


def test_the_installed_rclpy_is_the_tested_one():
    assert _rclpy_compat._installed_version()[:2] == _rclpy_compat.TESTED_RCLPY
    _rclpy_compat._check()


def test_a_missing_private_name_is_a_clear_error(monkeypatch):
    monkeypatch.delattr(Node, '_wake_executor')
    with pytest.raises(BindingUnavailable,
                       match=r'lacks Node\._wake_executor.*tested with rclpy 7\.1'):
        _rclpy_compat._check()


def test_no_other_module_touches_rclpy_internals():
    package = pathlib.Path(_rclpy_compat.__file__).parent
    marker = re.compile(r'implementation_singleton|_declare_qos_parameters|\bnode\._[a-z]'
                        r'|\._(feedback_callbacks|client_handle|pending_result_requests|is_\w+_ready)\b')
    offenders = [path.name for path in package.glob('*.py')
                 if path.name != '_rclpy_compat.py' and marker.search(path.read_text())]
    assert offenders == []


def test_each_request_future_is_bound_once_per_executor(ros):
    """rclpy's executor binds every future of a waitable at every wake (``_set_executor``); the
    action client's futures are bound once per executor that spins it, and every request still
    completes in it (``_rclpy_compat.BoundFutures``)."""
    from rclpy.executors import SingleThreadedExecutor
    from test_msgs.action import Fibonacci

    from cft_action import ActionClient
    from harness.ros import unique_name
    from tests.test_action_client import start_server

    action = '/' + unique_name('fib')
    server = start_server(action)
    try:
        client = ActionClient(ros.node, Fibonacci, action)
        assert client.wait_for_server(timeout_sec=20)
        bindings: dict[int, list] = {}

        def counted(future):
            bind = future._set_executor
            future._set_executor = lambda executor: (
                bindings.setdefault(id(future), []).append(executor), bind(executor))
            return future

        goals = [counted(client.send_goal_async(Fibonacci.Goal(order=2))) for _ in range(10)]
        assert ros.spin_until(lambda: all(f.done() for f in goals), 20)
        ros.spin_for(0.1)  # the done callbacks, which remove the futures, are executor tasks
        assert all(f.result().accepted for f in goals)
        assert [len(bindings.get(id(f), [])) for f in goals] == [1] * 10
        assert all(bindings[id(f)] == [ros.executor] for f in goals)
        results = [counted(f.result().get_result_async()) for f in goals]
        # Spun by another executor: its futures are bound to that one, once each.
        other = SingleThreadedExecutor(context=ros.context)
        ros.executor.remove_node(ros.node)
        other.add_node(ros.node)
        deadline = time.monotonic() + 20
        while not all(f.done() for f in results) and time.monotonic() < deadline:
            other.spin_once(timeout_sec=0.05)
        for _ in range(5):  # the done callbacks, tasks of `other` now
            other.spin_once(timeout_sec=0.01)
        other.remove_node(ros.node)
        ros.executor.add_node(ros.node)
        assert all(f.done() for f in results)
        assert all(bindings[id(f)] == [other] for f in results)
        assert not any(f in client._futures for f in goals + results)
    finally:
        server.stop()
