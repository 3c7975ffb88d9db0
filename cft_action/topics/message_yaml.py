# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""ROS messages as YAML and CSV, as ``ros2 topic echo`` prints them.

Jazzy has no ``rosidl_runtime_py`` on PyPI, so :func:`message_to_yaml` and :func:`message_to_csv`
are written here once.
"""

from __future__ import annotations

import array
import sys
from collections import OrderedDict
from typing import Optional

import yaml

from cft_action.topics.message_types import fields_of, is_message, type_name

__all__ = ['message_to_csv', 'message_to_ordereddict', 'message_to_yaml']


def _abbreviate(value, slot) -> str:
    from rosidl_parser.definition import Array, BoundedSequence
    name = type_name(slot.value_type)
    if isinstance(slot, Array):
        return f'<array type: {name}[{slot.size}]>'
    if isinstance(slot, BoundedSequence):
        return f'<sequence type: {name}[{slot.maximum_size}], length: {len(value)}>'
    return f'<sequence type: {name}, length: {len(value)}>'


def message_to_ordereddict(msg, *, truncate_length: Optional[int] = None, no_arr: bool = False,
                           no_str: bool = False) -> OrderedDict:
    """Return the fields of ``msg`` as an :class:`OrderedDict`, nested messages as nested dicts.

    :param truncate_length: Cut strings, bytes and arrays longer than this, marking the cut ``...``.
    :param no_arr: Replace arrays and sequences by a description of their type and length.
    :param no_str: Replace strings by their length.
    """
    result = OrderedDict()
    for name, slot in fields_of(msg):
        result[name] = _plain(getattr(msg, name), slot, truncate_length, no_arr, no_str)
    return result


def _plain(value, slot, truncate_length, no_arr, no_str):
    if isinstance(value, (bytes, bytearray)):
        text = ''.join(chr(b) for b in value)
        if truncate_length is not None and len(text) > truncate_length:
            text = text[:truncate_length] + '...'
        return text
    if isinstance(value, str):
        if no_str:
            return f'<string length: <{len(value)}>>'
        if truncate_length is not None and len(value) > truncate_length:
            return value[:truncate_length] + '...'
        return value
    if hasattr(value, 'dtype') and getattr(value, 'ndim', 0) == 0:  # a numpy scalar
        return value.item()
    if isinstance(value, (list, tuple, array.array)) or hasattr(value, 'dtype'):  # or an ndarray
        if no_arr and slot is not None:
            return _abbreviate(value, slot)
        items = list(value)
        cut = truncate_length is not None and len(items) > truncate_length
        if cut:
            items = items[:truncate_length]
        items = [_plain(v, None, truncate_length, no_arr, no_str) for v in items]
        return items + ['...'] if cut else items
    if isinstance(value, (bool, int, float)) or value is None:
        return value
    if isinstance(value, dict):
        return OrderedDict((k, _plain(v, None, truncate_length, no_arr, no_str))
                           for k, v in value.items())
    if is_message(value):
        return message_to_ordereddict(value, truncate_length=truncate_length, no_arr=no_arr,
                                      no_str=no_str)
    return str(value)


class _YamlDumper(yaml.SafeDumper):
    """A safe dumper that keeps the order of an OrderedDict, without touching yaml's globals."""


_YamlDumper.add_representer(
    OrderedDict, lambda dumper, data: dumper.represent_mapping(
        'tag:yaml.org,2002:map', data.items()))


def message_to_yaml(msg, *, truncate_length: Optional[int] = None, no_arr: bool = False,
                    no_str: bool = False, flow_style: bool = False) -> str:
    """Return ``msg`` as YAML, as ``ros2 topic echo`` prints it (without the ``---`` line).

    The arguments are those of :func:`message_to_ordereddict`; ``flow_style`` prints collections
    inline.
    """
    return yaml.dump(
        message_to_ordereddict(msg, truncate_length=truncate_length, no_arr=no_arr,
                               no_str=no_str),
        Dumper=_YamlDumper, allow_unicode=True, width=sys.maxsize, default_flow_style=flow_style,
        sort_keys=False)


def message_to_csv(msg, *, truncate_length: Optional[int] = None, no_arr: bool = False,
                   no_str: bool = False) -> str:
    """Return every field of ``msg``, recursively, separated by commas, as ``ros2 topic echo
    --csv`` prints it (rosidl_runtime_py's ``message_to_csv``).

    The arguments are those of :func:`message_to_ordereddict`; an array cut at ``truncate_length``
    ends with ``...``, and ``str()`` spells every value (a ``byte`` as ``b'A'``).
    """
    return ','.join(_csv(getattr(msg, name), slot, truncate_length, no_arr, no_str)
                    for name, slot in fields_of(msg))


def _csv(value, slot, truncate_length, no_arr, no_str) -> str:
    if isinstance(value, (list, tuple, array.array)) or (
            hasattr(value, 'dtype') and getattr(value, 'ndim', 0) > 0):
        if no_arr and slot is not None:
            return _abbreviate(value, slot)
        items = list(value)
        cut = truncate_length is not None and len(items) > truncate_length
        texts = [_csv(v, None, truncate_length, no_arr, no_str) for v in items[:truncate_length]]
        return ','.join(texts + ['...'] if cut else texts)
    if is_message(value):
        return message_to_csv(value, truncate_length=truncate_length, no_arr=no_arr,
                              no_str=no_str)
    if isinstance(value, str) and no_str:
        return f'<string length: <{len(value)}>>'
    if isinstance(value, str) and truncate_length is not None and len(value) > truncate_length:
        value = value[:truncate_length] + '...'
    elif isinstance(value, bytes) and truncate_length is not None \
            and len(value) > truncate_length:
        value = value[:truncate_length] + b'...'
    return str(value)
