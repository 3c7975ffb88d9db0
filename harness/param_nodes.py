"""Nodes whose parameters change on command, for the parameter event tests and benchmark.

Usage: ``python -m harness.param_nodes NODE [NODE ...]``, each NODE a fully qualified name such as
``/ns/name``.
Every node declares the integer parameters ``value`` and ``sync`` (0). Commands on stdin, one per
line:
  set NODE PARAM N   set PARAM of NODE to 1..N, one parameter event each; replies SET NODE PARAM N
  burst N            set ``value`` to 1..N on every node, interleaved; replies BURST N
  matched N          wait until every node's /parameter_events publisher has at least N matched
                     subscriptions; replies MATCHED or TIMEOUT
  programs           replies PROGRAMS {...}: cft_action.guard.program_counts() in this process
  remote NODE PARAM true|false
                     set a bool parameter of another process's NODE through its parameter
                     service; replies REMOTE OK or REMOTE FAIL <reason>
"""

import functools
import json
import sys
import threading

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient

from cft_action import guard
from harness.polling import TIMEOUT, wait_until
from harness.ros import leave_spinning_process



def make_node(fully_qualified_name: str) -> Node:
    namespace, _, name = fully_qualified_name.rpartition('/')
    node = Node(name, namespace=namespace or '/')
    node.declare_parameter('value', 0)
    node.declare_parameter('sync', 0)
    return node


def subscribed(nodes: list[Node], wanted: int) -> bool:
    """Whether every node's /parameter_events writer has at least ``wanted`` readers."""
    return all(n._parameter_event_publisher.get_subscription_count() >= wanted for n in nodes)


def remote_set(client: AsyncParameterClient, name: str, value: bool) -> str:
    if not client.wait_for_services(timeout_sec=TIMEOUT):
        return 'FAIL no parameter services'
    future = client.set_parameters([Parameter(name, value=value)])
    if not wait_until(future.done):
        return 'FAIL no response'
    results = future.result().results
    if not all(r.successful for r in results):
        return 'FAIL ' + '; '.join(r.reason for r in results)
    return 'OK'


def main() -> None:
    rclpy.init()
    nodes = {name: make_node(name) for name in sys.argv[1:]}
    for name, node in nodes.items():
        assert node.get_fully_qualified_name() == name, (name, node.get_fully_qualified_name())
    # The parameter client needs an executor, and so do the nodes' parameter services, which
    # ParameterEventHandler.wait_for_filter calls; publishing their events needs none.
    client_node = Node('cft_test_param_client')
    executor = SingleThreadedExecutor()
    for node in [*nodes.values(), client_node]:
        executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    clients: dict[str, AsyncParameterClient] = {}
    print('READY', flush=True)
    for line in sys.stdin:
        words = line.split()
        if not words:
            continue
        if words[0] == 'set':
            target, param, count = words[1], words[2], int(words[3])
            for i in range(1, count + 1):
                nodes[target].set_parameters([Parameter(param, value=i)])
            print(f'SET {target} {param} {count}', flush=True)
        elif words[0] == 'burst':
            count = int(words[1])
            for i in range(1, count + 1):
                for node in nodes.values():
                    node.set_parameters([Parameter('value', value=i)])
            print(f'BURST {count}', flush=True)
        elif words[0] == 'matched':
            matched = wait_until(functools.partial(subscribed, list(nodes.values()),
                                                   int(words[1])))
            print('MATCHED' if matched else 'TIMEOUT', flush=True)
        elif words[0] == 'programs':
            print(f'PROGRAMS {json.dumps(guard.program_counts())}', flush=True)
        elif words[0] == 'remote':
            if words[1] not in clients:
                clients[words[1]] = AsyncParameterClient(client_node, words[1])
            reply = remote_set(clients[words[1]], words[2], words[3] == 'true')
            print(f'REMOTE {reply}', flush=True)
    def destroy() -> None:
        for node in [*nodes.values(), client_node]:
            node.destroy_node()
    leave_spinning_process(executor, [spinner], destroy)


if __name__ == '__main__':
    main()
