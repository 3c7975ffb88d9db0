"""The one module that touches rclpy's private names checks them, and names what is missing."""

import pathlib
import re

import pytest
from rclpy.node import Node

from cft_action import _rclpy_compat
from cft_action.errors import BindingUnavailable


def test_the_installed_rclpy_is_the_tested_one():
    assert _rclpy_compat._installed_version()[:2] == _rclpy_compat.TESTED_RCLPY
    _rclpy_compat._check()


def test_a_missing_private_name_is_a_clear_error(monkeypatch):
    monkeypatch.delattr(Node, '_wake_executor')
    with pytest.raises(BindingUnavailable,
                       match=r'lacks Node\._wake_executor.*tested with rclpy 7\.1'):
        _rclpy_compat._check()


def test_no_other_module_touches_rclpy_internals():
    package = pathlib.Path(_rclpy_compat.__file__).parent
    marker = re.compile(r'implementation_singleton|_declare_qos_parameters|\bnode\._[a-z]'
                        r'|\._(feedback_callbacks|client_handle|pending_result_requests|is_\w+_ready)\b')
    offenders = [path.name for path in package.glob('*.py')
                 if path.name != '_rclpy_compat.py' and marker.search(path.read_text())]
    assert offenders == []
