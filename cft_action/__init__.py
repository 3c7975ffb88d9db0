# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""cft_action: content-filtered action feedback and topics for ROS 2 Jazzy.

``from cft_action import ActionClient`` is a drop-in for :class:`rclpy.action.ActionClient` whose
feedback subscription receives only the feedback of its own goals.

Importing the package imports no ROS module: the names that need rclpy are loaded on first use
(PEP 562), so the pure modules (:mod:`cft_action.sql`, :mod:`cft_action.filters`,
:mod:`cft_action.goal_filter`, :mod:`cft_action.errors`) and ``cft-action --help`` work without
loading librcl.
"""

from __future__ import annotations

import importlib
from typing import Any, TYPE_CHECKING

from cft_action.errors import CftActionError, ContentFilterError, InvalidArgumentError

if TYPE_CHECKING:
    from cft_action.client import (ActionClient, FeedbackFilterState, GoalStatusState,
                                   ResponseFilterState)
    from cft_action.parameter_events import ParameterEventFilterState, ParameterEventHandler
    from cft_action.subscription import (ContentFilterOptions, create_filtered_subscription,
                                         get_content_filter, is_content_filter_supported,
                                         is_filtered, set_content_filter)

# name: the module that defines it, imported when the name is first used
_LAZY = {
    'ActionClient': 'client',
    'FeedbackFilterState': 'client',
    'GoalStatusState': 'client',
    'ResponseFilterState': 'client',
    'ParameterEventFilterState': 'parameter_events',
    'ParameterEventHandler': 'parameter_events',
    'ContentFilterOptions': 'subscription',
    'create_filtered_subscription': 'subscription',
    'get_content_filter': 'subscription',
    'is_content_filter_supported': 'subscription',
    'is_filtered': 'subscription',
    'set_content_filter': 'subscription',
}

__all__ = [
    'ActionClient', 'CftActionError', 'ContentFilterError', 'FeedbackFilterState',
    'GoalStatusState', 'InvalidArgumentError', 'ParameterEventFilterState', 'ParameterEventHandler',
    'ContentFilterOptions', 'ResponseFilterState', 'create_filtered_subscription',
    'get_content_filter', 'is_content_filter_supported', 'is_filtered', 'set_content_filter',
]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is not None:
        value = getattr(importlib.import_module(f'{__name__}.{module}'), name)
    elif name.startswith('__'):
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    else:
        # A submodule not imported yet: ``import cft_action`` then ``cft_action.sql`` works, as it
        # did when the package imported its modules eagerly.
        try:
            value = importlib.import_module(f'{__name__}.{name}')
        except ModuleNotFoundError as e:
            if e.name != f'{__name__}.{name}':
                raise
            raise AttributeError(f'module {__name__!r} has no attribute {name!r}') from None
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
