# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Is a compatibility stack really loaded, and does plain ROS work on it?

Run with the stack's environment (compat/stack_env.sh), from the repository root::

    eval "$(compat/stack_env.sh VENV STACK)"; VENV/bin/python -m compat.verify_stack STACK

It starts a plain rclpy action server (test_msgs/Fibonacci) in a second process, then in this one:

- checks both processes' ``/proc/<pid>/maps``: the Fast DDS library (``libfastrtps.so.2.14``, or
  ``libfastdds.so.3.<minor>`` for a Fast DDS 3 stack), ``librmw_fastrtps_shared_cpp.so`` and
  ``librmw_fastrtps_cpp.so`` must come from ``STACK/install/lib`` (or, with ``wheels``, from the
  venv), and no other copy of any may be mapped; so must ``libfastcdr.so`` if the stack has one;
- checks that no mapped library needs versioned symbols (``readelf -V``) of a Fast DDS soname other
  than the mapped one's: a library of the wheels built against another Fast DDS would run on this
  one's ABI (a Fast DDS 3 stack answers the wheels' ``NEEDED libfastdds.so.3.2``, which rcl and
  rclpy carry without using a symbol of it, with its own library; see docs/COMPATIBILITY.md);
- waits for the server (``wait_for_server``), sends a goal, and requires acceptance, feedback and
  the result;
- queries the graph: the server node's publishers, subscriptions, services by node, and the
  action's names and types.

Prints one ``CHECK name ok|FAIL detail`` line per check and exits 1 if any failed. Uses no
cft_action code: it tests the stack, not the library.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

from harness.domain import unused_domain

ACTION = f'/compat_verify_{os.getpid()}'
ORDER = 5


def mapped(pid: int, name: str) -> set[str]:
    """The paths of every mapped file of process ``pid`` whose name starts with ``name``."""
    paths = set()
    for line in Path(f'/proc/{pid}/maps').read_text().splitlines():
        parts = line.split(None, 5)
        if len(parts) == 6 and os.path.basename(parts[5]).startswith(name):
            paths.add(parts[5])
    return paths


def soname(path: str) -> str:
    """The DT_SONAME of the ELF file at ``path`` ('' if none)."""
    out = subprocess.run(['readelf', '-dW', path], capture_output=True, text=True).stdout
    found = re.search(r'\(SONAME\)\s+Library soname: \[([^]]+)\]', out)
    return found.group(1) if found else ''


def foreign_needs(pid: int, dds: str) -> list[str]:
    """Mapped libraries that need versioned symbols of a Fast DDS soname other than ``dds``."""
    bad = []
    for path in sorted(mapped(pid, 'lib')):
        if '.so' not in os.path.basename(path) or not os.path.exists(path):
            continue
        out = subprocess.run(['readelf', '-VW', path], capture_output=True, text=True).stdout
        for name in re.findall(r'File: (lib(?:fastdds|fastrtps)\.so[.0-9]*)', out):
            if name != dds:
                bad.append(f'{os.path.basename(path)} needs {name}')
    return bad


def serve() -> None:
    """The server process: a plain rclpy ActionServer publishing feedback every 50 ms."""
    import rclpy
    from rclpy.action import ActionServer
    from rclpy.executors import MultiThreadedExecutor
    from test_msgs.action import Fibonacci

    rclpy.init()
    node = rclpy.create_node('compat_verify_server')

    def execute(goal_handle):
        feedback = Fibonacci.Feedback()
        feedback.sequence = [0, 1]
        for i in range(1, goal_handle.request.order):
            feedback.sequence.append(feedback.sequence[i] + feedback.sequence[i - 1])
            goal_handle.publish_feedback(feedback)
            time.sleep(0.05)
        goal_handle.succeed()
        return Fibonacci.Result(sequence=feedback.sequence)

    ActionServer(node, Fibonacci, ACTION if len(sys.argv) < 4 else sys.argv[3], execute)
    print('READY', flush=True)
    executor = MultiThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    finally:
        rclpy.try_shutdown()


def main() -> int:
    stack = sys.argv[1]
    if stack == 'wheels':
        libdir = str(Path(sys.prefix, 'lib').resolve())
    else:
        libdir = str(Path(stack, 'install', 'lib').resolve())
    # The family: 2.14's libfastrtps, or 3.x's libfastdds.
    dds = 'libfastrtps.so' if Path(libdir, 'libfastrtps.so.2.14').exists() else 'libfastdds.so'
    os.environ.setdefault('ROS_DOMAIN_ID', str(unused_domain()))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    failed = []

    def check(name: str, ok: bool, detail: object = '') -> None:
        print(f'CHECK {name} {"ok" if ok else "FAIL"} {detail}'.rstrip(), flush=True)
        if not ok:
            failed.append(name)

    server = subprocess.Popen([sys.executable, '-u', '-m', 'compat.verify_stack', stack, 'serve',
                               ACTION], stdout=subprocess.PIPE, text=True)
    assert server.stdout is not None  # a pipe: Popen(stdout=PIPE)
    try:
        ready = server.stdout.readline().strip()
        check('server_started', ready == 'READY', ready)

        import rclpy
        from rclpy.action import ActionClient
        from test_msgs.action import Fibonacci

        rclpy.init()
        node = rclpy.create_node('compat_verify_client')
        try:
            client = ActionClient(node, Fibonacci, ACTION)
            # Only now is the rmw (and so Fast DDS) loaded in this process.
            for who, pid in (('client', os.getpid()), ('server', server.pid)):
                # A stack that brings its own Fast-CDR (3.6 needs 2.3.6) must have it mapped.
                cdr = ('libfastcdr.so',) if Path(libdir, 'libfastcdr.so.2').exists() else ()
                for lib in (dds, 'librmw_fastrtps_shared_cpp.so', 'librmw_fastrtps_cpp.so') + cdr:
                    paths = {str(Path(p).resolve()) for p in mapped(pid, lib)}
                    good = len(paths) == 1 and os.path.dirname(next(iter(paths))) == libdir
                    check(f'maps_{who}_{lib}', good, sorted(paths))
                    if lib == dds and len(paths) == 1:
                        name = soname(next(iter(paths)))
                        bad = foreign_needs(pid, name)
                        check(f'needs_{who}_only_{name}', not bad, bad[:5])
            t0 = time.monotonic()
            check('wait_for_server', client.wait_for_server(timeout_sec=10.0),
                  f'{time.monotonic() - t0:.2f} s')
            feedback = []
            future = client.send_goal_async(Fibonacci.Goal(order=ORDER),
                                            feedback_callback=lambda m: feedback.append(
                                                list(m.feedback.sequence)))
            rclpy.spin_until_future_complete(node, future, timeout_sec=10.0)
            handle = future.result() if future.done() else None
            check('goal_accepted', handle is not None and handle.accepted)
            if handle is not None and handle.accepted:
                result = handle.get_result_async()
                rclpy.spin_until_future_complete(node, result, timeout_sec=10.0)
                sequence = list(result.result().result.sequence) if result.done() else None
                check('result', sequence == [0, 1, 1, 2, 3, 5], sequence)
                check('feedback', len(feedback) >= 1 and feedback[-1] == sequence,
                      f'{len(feedback)} messages')
            deadline = time.monotonic() + 5
            while True:
                pubs = dict(node.get_publisher_names_and_types_by_node(
                    'compat_verify_server', '/'))
                subs = dict(node.get_subscriber_names_and_types_by_node(
                    'compat_verify_server', '/'))
                srvs = dict(node.get_service_names_and_types_by_node(
                    'compat_verify_server', '/'))
                if f'{ACTION}/_action/feedback' in pubs or time.monotonic() > deadline:
                    break
                rclpy.spin_once(node, timeout_sec=0.1)
            check('graph_publishers_by_node', f'{ACTION}/_action/feedback' in pubs
                  and f'{ACTION}/_action/status' in pubs, sorted(pubs))
            check('graph_services_by_node', f'{ACTION}/_action/send_goal' in srvs,
                  sorted(srvs))
            check('graph_subscriptions_by_node', isinstance(subs, dict), sorted(subs))
            names = dict(rclpy.action.get_action_names_and_types(node))
            check('graph_action_names', names.get(ACTION) == ['test_msgs/action/Fibonacci'],
                  names.get(ACTION))
            check('graph_node_names', 'compat_verify_server' in node.get_node_names())
        finally:
            node.destroy_node()
            rclpy.try_shutdown()
    finally:
        server.terminate()
        try:
            server.wait(timeout=10)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
    print('VERIFY', 'FAIL ' + ' '.join(failed) if failed else 'ok', flush=True)
    return 1 if failed else 0


if __name__ == '__main__':
    if len(sys.argv) >= 3 and sys.argv[2] == 'serve':
        serve()
    else:
        sys.exit(main())
