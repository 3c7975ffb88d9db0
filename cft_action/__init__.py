# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""cft_action: content-filtered action feedback and topics for ROS 2 Jazzy.

``from cft_action import ActionClient`` is a drop-in for :class:`rclpy.action.ActionClient` whose
feedback subscription receives only the feedback of its own goals.

The package is laid out by concern: :mod:`cft_action.action` (the action client and its parts),
:mod:`cft_action.parameters`, :mod:`cft_action.topics` (content-filtered subscriptions, DDS-SQL, the
topic tools' helpers), :mod:`cft_action.verb` (the ``cft-action`` verbs), :mod:`cft_action.guard`
(the server guard's Python face) and ``cft_action/native/`` (the C: ``guard/`` runs in servers,
``reader/`` in clients, the rest in both). The modules of the flat layout before it
(``cft_action.client``, ``cft_action.sql``, ...) still import, as the modules they became.

Importing the package imports no ROS module: the names that need rclpy are loaded on first use
(PEP 562), so the pure modules (:mod:`cft_action.topics.sql`, :mod:`cft_action.topics.filters`,
:mod:`cft_action.action.goal_filter`, :mod:`cft_action.errors`) and ``cft-action --help`` work
without loading librcl.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
from types import ModuleType
from typing import Any, Optional, Sequence, TYPE_CHECKING

from cft_action.errors import CftActionError, ContentFilterError, InvalidArgumentError

if TYPE_CHECKING:
    from cft_action.action.client import (ActionClient, FeedbackFilterState, GoalStatusState,
                                          ResponseFilterState)
    from cft_action.parameters.parameter_events import (ParameterEventFilterState,
                                                        ParameterEventHandler)
    from cft_action.topics.rate import (active_subscription_count, poll, RateFilterState,
                                        rate_filter_state, set_max_rate, stop_polling)
    from cft_action.topics.subscription import (ContentFilterOptions,
                                                create_filtered_subscription, get_content_filter,
                                                is_content_filter_supported, is_filtered,
                                                set_content_filter)

# name: the module that defines it, imported when the name is first used
_LAZY = {
    'ActionClient': 'action.client',
    'FeedbackFilterState': 'action.client',
    'GoalStatusState': 'action.client',
    'ResponseFilterState': 'action.client',
    'ParameterEventFilterState': 'parameters.parameter_events',
    'ParameterEventHandler': 'parameters.parameter_events',
    'ContentFilterOptions': 'topics.subscription',
    'create_filtered_subscription': 'topics.subscription',
    'get_content_filter': 'topics.subscription',
    'is_content_filter_supported': 'topics.subscription',
    'is_filtered': 'topics.subscription',
    'set_content_filter': 'topics.subscription',
    'RateFilterState': 'topics.rate',
    'active_subscription_count': 'topics.rate',
    'poll': 'topics.rate',
    'rate_filter_state': 'topics.rate',
    'set_max_rate': 'topics.rate',
    'stop_polling': 'topics.rate',
}

# The public modules of the flat layout, and the modules they are now. ``import cft_action.sql``
# gives the module ``cft_action.topics.sql`` itself (one module object, under both names).
_MOVED = {
    'client': 'action.client',
    'goal_filter': 'action.goal_filter',
    'parameter_events': 'parameters.parameter_events',
    'arrival': 'topics.arrival',
    'filters': 'topics.filters',
    'message_types': 'topics.message_types',
    'message_yaml': 'topics.message_yaml',
    'sql': 'topics.sql',
    'subscription': 'topics.subscription',
    'topic_api': 'topics.topic_api',
}


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports ``cft_action.<old>`` as the module it moved to (:data:`_MOVED`)."""

    def find_spec(self, fullname: str, path: Optional[Sequence[str]],
                  target: Optional[ModuleType] = None) -> Optional[importlib.machinery.ModuleSpec]:
        package, _, name = fullname.rpartition('.')
        if package != __name__ or name not in _MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        module = importlib.import_module(f'{__name__}.{_MOVED[spec.name.rpartition(".")[2]]}')
        spec.loader_state = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        # The module has run already; the import system gave it the alias's spec: give it back its
        # own, so that it keeps one name for reload() and introspection.
        alias = module.__spec__
        if alias is not None:
            module.__spec__ = alias.loader_state


sys.meta_path.append(_MovedModules())

__all__ = [
    'ActionClient', 'CftActionError', 'ContentFilterError', 'FeedbackFilterState',
    'GoalStatusState', 'InvalidArgumentError', 'ParameterEventFilterState', 'ParameterEventHandler',
    'ContentFilterOptions', 'ResponseFilterState', 'create_filtered_subscription',
    'get_content_filter', 'is_content_filter_supported', 'is_filtered', 'set_content_filter',
    'RateFilterState', 'active_subscription_count', 'poll', 'rate_filter_state', 'set_max_rate',
    'stop_polling',
]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is not None:
        value = getattr(importlib.import_module(f'{__name__}.{module}'), name)
    elif name.startswith('__'):
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    else:
        # A submodule not imported yet: ``import cft_action`` then ``cft_action.topics`` works, as
        # it did when the package imported its modules eagerly.
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
