# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Which DDS-SQL filter expressions does the loaded Fast DDS accept on a reader?

Run in a stack's environment (compat/stack_env.sh), from the repository root::

    python -m compat.expression_limits

Fast DDS's 2.14.x branch after v2.14.6 (CVE-2026-22591, commit d96f0ebf32) refuses an expression
longer than 16 KiB or nesting parentheses deeper than 256; v2.14.5 and v2.14.6 have no such check.
This sets filters of given lengths and depths on a std_msgs/Int32 subscription through rcl (the
library's own binding) and prints ``LIMIT kind size accepted|refused``.
"""

from __future__ import annotations

import rclpy
from std_msgs.msg import Int32

from cft_action import _rcl


def of_length(n: int) -> str:
    """An expression of exactly ``n`` characters (n >= 8): ``data = 1 OR data = 1 ...``, padded."""
    expression = 'data = 1'
    while len(expression) + 12 <= n:
        expression += ' OR data = 1'
    return 'data' + ' ' * (n - len(expression)) + expression[4:]  # blanks between tokens


def of_depth(d: int) -> str:
    return '(' * d + 'data = 1' + ')' * d


def main() -> None:
    rclpy.init()
    node = rclpy.create_node('compat_expression_limits')
    try:
        for kind, sizes, make in (('length', (8192, 16384, 16385, 20000, 60000), of_length),
                                  ('depth', (255, 256, 257), of_depth)):
            for size in sizes:
                sub = node.create_subscription(Int32, f'/compat_limits_{kind}_{size}',
                                               lambda m: None, 10)
                try:
                    _rcl.set_content_filter(sub.handle.pointer, make(size))
                    verdict = 'accepted'
                except _rcl.ContentFilterError as error:
                    verdict = f'refused ({str(error)[-80:]})'
                print(f'LIMIT {kind} {size} {verdict}', flush=True)
                node.destroy_subscription(sub)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
