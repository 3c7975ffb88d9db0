# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""cft_action: content-filtered action feedback and topics for ROS 2 Jazzy.

``from cft_action import ActionClient`` is a drop-in for :class:`rclpy.action.ActionClient` whose
feedback subscription receives only the feedback of its own goals.
"""

from cft_action.client import ActionClient, FeedbackFilterState
from cft_action.errors import CftActionError, ContentFilterError, InvalidArgumentError
from cft_action.parameter_events import ParameterEventFilterState, ParameterEventHandler
from cft_action.subscription import (
    ContentFilterOptions,
    create_filtered_subscription,
    get_content_filter,
    is_content_filter_supported,
    is_filtered,
    set_content_filter,
)

__all__ = [
    'ActionClient', 'CftActionError', 'ContentFilterError', 'FeedbackFilterState',
    'InvalidArgumentError', 'ParameterEventFilterState', 'ParameterEventHandler', 'ContentFilterOptions', 'create_filtered_subscription',
    'get_content_filter', 'is_content_filter_supported', 'is_filtered', 'set_content_filter',
]
