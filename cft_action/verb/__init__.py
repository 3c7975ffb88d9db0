# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The verbs of ``cft-action``, one module each, as ros2cli's ``ros2topic/verb/*.py``.

Every verb module has the same face, which :mod:`cft_action.cli` builds its parsers from:

- ``HELP``: the one-line help in the command list;
- ``DESCRIPTION`` and ``EPILOG``: the text of the verb's own ``--help``;
- ``add_arguments(parser)``: the verb's arguments;
- ``main(args, parser, prog) -> int``: runs the verb; returns the exit status.

The modules import rclpy only when ``main`` runs, so that ``--help`` stays fast. What the topic
verbs share is in :mod:`cft_action.topics.topic_api`, what the action verbs share in
:mod:`cft_action.action.action_api`.
"""

#: The verbs of ``cft-action topic``, each a module of this package.
TOPIC_VERBS = ('bw', 'echo', 'hz')

#: The verbs of ``cft-action action``, by the module of this package that each is.
ACTION_VERBS = {'info': 'action_info', 'list': 'action_list'}


def examples(*command_lines: str) -> str:
    """An ``EPILOG``: the example command lines under ``examples:``, as ros2cli shows them."""
    return '\n'.join(['examples:', *(f'  {line}' for line in command_lines)])
