"""The exception hierarchy: one base, the builtin that fits mixed in, today's names kept."""

import importlib
import pkgutil

import pytest

import cft_action
from cft_action import _native
from cft_action.errors import (BindingUnavailable, CftActionError, ContentFilterError,
                               InvalidArgumentError)
from cft_action.topics.filters import dds_literal, uuid_prefix_term
from cft_action.action.goal_filter import GoalFilterPlan


def _public_exceptions():
    """Every public exception class defined in a module of the package."""
    found = []
    for info in pkgutil.walk_packages(cft_action.__path__, 'cft_action.'):
        if info.name.rpartition('.')[2] in _native.LIBRARIES:
            continue  # shared objects to preload or to load with ctypes, not Python modules
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if (isinstance(value, type) and issubclass(value, BaseException)
                    and value.__module__ == module.__name__ and not name.startswith('_')):
                found.append(value)
    return found


def test_every_error_of_the_package_derives_from_the_base():
    exceptions = _public_exceptions()
    assert len(exceptions) >= 9
    assert [e for e in exceptions if not issubclass(e, CftActionError)] == []


@pytest.mark.parametrize('module, name, builtin', [
    ('cft_action', 'ContentFilterError', RuntimeError),
    ('cft_action.errors', 'InvalidArgumentError', ValueError),
    ('cft_action.errors', 'BindingUnavailable', RuntimeError),
    ('cft_action._rcl', 'ContentFilterError', RuntimeError),
    ('cft_action._rcl', 'BindingUnavailable', RuntimeError),
    ('cft_action.topics.subscription', 'ContentFilterError', RuntimeError),
    ('cft_action.guard', 'GuardUnavailable', RuntimeError),
    ('cft_action.action.goal_filter', 'ExpressionTooLong', ValueError),
    ('cft_action.topics.sql', 'FilterError', ValueError),
    ('cft_action.topics.topic_api', 'TopicToolError', Exception),
    ('cft_action.topics.topic_api', 'FilterUnavailable', Exception),
])
def test_todays_names_import_where_they_did(module, name, builtin):
    error = getattr(importlib.import_module(module), name)
    assert issubclass(error, CftActionError)
    assert issubclass(error, builtin)


def test_the_public_content_filter_error_lives_in_the_public_module():
    from cft_action import _rcl

    assert _rcl.ContentFilterError is ContentFilterError is cft_action.ContentFilterError
    assert _rcl.BindingUnavailable is BindingUnavailable
    assert ContentFilterError.__module__ == 'cft_action.errors'
    assert cft_action.CftActionError is CftActionError


@pytest.mark.parametrize('call', [
    lambda: dds_literal(float('nan')),
    lambda: dds_literal("it's"),
    lambda: uuid_prefix_term(b''),
    lambda: GoalFilterPlan('off'),
    lambda: GoalFilterPlan('goals').tagged_uuid(),
])
def test_bad_input_is_an_invalid_argument_error_and_a_value_error(call):
    with pytest.raises(InvalidArgumentError):
        call()
    with pytest.raises(ValueError):
        call()


def test_a_content_filter_error_keeps_rcls_details():
    error = ContentFilterError('failed', function='rcl_x', ret=1, rcl_error='why')
    assert (str(error), error.function, error.ret, error.rcl_error) == ('failed', 'rcl_x', 1, 'why')
