"""The library's timers never race the user's executor (issue 28).

The action client pauses its timers while they have no work. A node timer paused by ``cancel()``
from one thread, while a ``MultiThreadedExecutor`` had already taken it as ready in another,
made rclpy raise ``failed to call timer: timer is canceled`` into the executor: client processes
died, and goals that the timer held never completed. These tests pause and resume from other
threads as fast as they can, under a 4-thread executor.
"""

import random
import threading
import time

import pytest
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor

from cft_action.action._paused_timer import PausedTimer
from harness.ros import RosSession

TOGGLE_S = 3.0


@pytest.mark.parametrize('group', [ReentrantCallbackGroup, MutuallyExclusiveCallbackGroup])
def test_pause_and_resume_from_other_threads_never_raise_into_the_executor(group):
    ros = RosSession(MultiThreadedExecutor, num_threads=4)
    try:
        calls: list[float] = []
        timer = PausedTimer(ros.node, 0.0005, lambda: calls.append(time.monotonic()), group())
        errors: list[BaseException] = []
        stop = threading.Event()

        def spin() -> None:
            try:
                while not stop.is_set():
                    ros.executor.spin_once(timeout_sec=0.05)
            except Exception as error:  # noqa: BLE001 - the finding
                errors.append(error)

        def toggle() -> None:
            while not stop.is_set():  # paused at every phase of a firing: before, in, after
                timer.resume()
                time.sleep(random.uniform(0, 0.002))
                timer.pause()
                time.sleep(random.uniform(0, 0.0005))

        threads = [threading.Thread(target=spin)]
        threads += [threading.Thread(target=toggle) for _ in range(2)]
        for thread in threads:
            thread.start()
        time.sleep(TOGGLE_S)
        stop.set()
        for thread in threads:
            thread.join(timeout=10)
        assert not any(thread.is_alive() for thread in threads)
        assert not errors, errors
        assert calls, 'the timer never ran while resumed'
        timer.pause()
        paused_at = len(calls)
        timer.resume()
        assert ros.spin_until(lambda: len(calls) > paused_at, 5), 'no run after the last resume'
        timer.destroy()
        ros.spin_for(0.3)  # the pool's last handlers end before the executor's shutdown
    finally:
        ros.close()


def test_a_paused_timer_does_not_run_and_a_destroyed_one_leaves_the_node(ros):
    calls = []
    timer = PausedTimer(ros.node, 0.01, lambda: calls.append(1), ros.node.default_callback_group)
    end = time.monotonic() + 0.3
    while time.monotonic() < end:
        ros.executor.spin_once(timeout_sec=0.05)
    assert calls == []
    timer.resume()
    assert ros.spin_until(lambda: len(calls) >= 3, 5)
    timer.destroy()
    assert timer not in list(ros.node.waitables)
    count = len(calls)
    end = time.monotonic() + 0.2
    while time.monotonic() < end:
        ros.executor.spin_once(timeout_sec=0.05)
    assert len(calls) == count
    timer.resume()  # after destroy: nothing, no error
    timer.pause()
