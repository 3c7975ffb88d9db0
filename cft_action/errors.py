# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The exceptions of cft_action: one base, :class:`CftActionError`, and no ROS import.

Every error that the package raises derives from :class:`CftActionError`, so ``except
CftActionError`` catches them all. Each also derives from the builtin exception that fits, so code
written against the builtins keeps working: :class:`ValueError` for input that cannot be used,
:class:`RuntimeError` for a failure of rcl or of the libraries below it. An argument of the wrong
type raises :class:`TypeError`, as in rclpy.

The errors that belong to one module are defined there, and subclass these:
:class:`cft_action.topics.sql.FilterError` and
:class:`cft_action.action.goal_filter.ExpressionTooLong` (``ValueError``),
:class:`cft_action.guard.GuardUnavailable` (``RuntimeError``) and
:class:`cft_action.topics.topic_api.TopicToolError`.
"""

from __future__ import annotations

from typing import Optional

__all__ = ['BindingUnavailable', 'CftActionError', 'ContentFilterError', 'InvalidArgumentError']


class CftActionError(Exception):
    """The base of every error that cft_action raises."""


class InvalidArgumentError(CftActionError, ValueError):
    """An argument that cft_action cannot use, such as an unknown mode or an unquotable literal."""


class ContentFilterError(CftActionError, RuntimeError):
    """A content-filter operation failed; the message carries rcl's own error string.

    :ivar function: the rcl function that failed, or None for a check done in Python.
    :ivar ret: the ``rcl_ret_t`` it returned, or None.
    :ivar rcl_error: rcl's error string, as ``rcutils_get_error_string()`` gave it.
    """

    def __init__(self, message: str, *, function: Optional[str] = None,
                 ret: Optional[int] = None, rcl_error: str = '') -> None:
        super().__init__(message)
        self.function = function
        self.ret = ret
        self.rcl_error = rcl_error


class BindingUnavailable(CftActionError, RuntimeError):
    """The rcl libraries, or a symbol that :mod:`cft_action._rcl` needs, cannot be loaded."""
