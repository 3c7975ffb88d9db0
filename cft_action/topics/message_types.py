# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""ROS message types as rosidl describes them: their fields, their classes, their DDS-SQL kinds.

One walk over a type's ``SLOT_TYPES`` serves every user: :func:`message_schema` for
:mod:`cft_action.topics.sql`, :func:`first_primitive_field` for the filter probe of
:func:`cft_action.create_filtered_subscription`, and :mod:`cft_action.topics.message_yaml`.
rosidl_parser is imported only when a type is walked.
"""

from __future__ import annotations

import importlib
import re
from typing import Any, Iterator, Optional

from cft_action.topics import sql

__all__ = ['class_of', 'fields_of', 'first_primitive_field', 'is_message', 'message_schema',
           'type_name']


def is_message(value: Any) -> bool:
    """Whether ``value`` is a ROS message, or a message class."""
    return hasattr(value, 'get_fields_and_field_types') and hasattr(value, 'SLOT_TYPES')


def fields_of(msg: Any) -> Iterator[tuple[str, Any]]:
    """``(name, rosidl slot type)`` of each field of a message or message class, in order."""
    # rosidl generates both in lockstep.
    return zip(msg.get_fields_and_field_types(), msg.SLOT_TYPES)


def class_of(slot: Any) -> Any:
    """The Python class of a rosidl ``NamespacedType``, for messages and the parts of services
    and actions.

    ``test_msgs/action/Fibonacci_Feedback`` is not an attribute of ``test_msgs.action``, only of
    its generated module ``test_msgs.action._fibonacci`` (the action's name in snake case).
    """
    package = importlib.import_module('.'.join(slot.namespaces))
    if hasattr(package, slot.name):
        return getattr(package, slot.name)
    interface = slot.name.split('_', 1)[0]
    snake = re.sub(r'(?<=[a-z0-9])([A-Z])|(?<=[A-Z])([A-Z])(?=[a-z])', r'_\1\2', interface)
    module = importlib.import_module(f'{package.__name__}._{snake.lower()}')
    return getattr(module, slot.name)


def type_name(slot: Any) -> str:
    """The name of a rosidl slot type, as ``ros2 topic echo`` prints it."""
    from rosidl_parser.definition import (AbstractString, AbstractWString, BasicType,
                                          NamespacedType)
    if isinstance(slot, BasicType):
        return slot.typename
    if isinstance(slot, AbstractString):
        return 'string'
    if isinstance(slot, AbstractWString):
        return 'wstring'
    if isinstance(slot, NamespacedType):
        return '/'.join(slot.namespaced_name())
    return 'unknown'


def _slot_kind(slot: Any) -> sql.Kind:
    from rosidl_parser.definition import AbstractString, AbstractWString, BasicType
    if isinstance(slot, BasicType):
        name = slot.typename
        if name == 'boolean':
            return sql.Kind.BOOLEAN
        if name == 'float':
            return sql.Kind.FLOAT32
        if name in ('double', 'long double'):
            return sql.Kind.FLOAT64
        if name == 'char':
            return sql.Kind.CHAR
        if name == 'int8':
            return sql.Kind.INT8_AS_OCTET
        if name == 'wchar':
            raise LookupError('is a wchar, which Fast DDS cannot filter on')
        return sql.Kind.INTEGER  # octet, (u)int8 .. (u)int64
    if isinstance(slot, AbstractString):
        return sql.Kind.STRING
    if isinstance(slot, AbstractWString):
        raise LookupError('is a wstring, which Fast DDS cannot filter on')
    raise LookupError(f'has the type {type_name(slot)}, which is not primitive')


def message_schema(msg_type: Any) -> sql.Schema:
    """The :data:`cft_action.topics.sql.Schema` of a ROS message type: the kind of each field path.

    It applies Fast DDS's rules: arrays and sequences must be indexed, a fixed-size array's index
    must be within its size, and the field at the end of the path must be primitive.
    """
    from rosidl_parser.definition import AbstractNestedType, Array, NamespacedType

    def kind_of(path: sql.FieldPath) -> sql.Kind:
        current = msg_type
        for step, (name, index) in enumerate(path):
            fields = dict(fields_of(current))
            if name not in fields:
                raise LookupError(f'field not found: {current.__name__} has the fields '
                                  f'{", ".join(fields)}')
            slot = fields[name]
            if isinstance(slot, AbstractNestedType):
                if index is None:
                    raise LookupError(f'{name} is an array or sequence, so it needs an index, '
                                      f'as in {name}[0]')
                if isinstance(slot, Array) and index >= slot.size:
                    raise LookupError(f'index {index} is greater than maximum size: {name} has '
                                      f'{slot.size} elements')
                slot = slot.value_type
            elif index is not None:
                raise LookupError(f'{name} is not an array or sequence')
            last = step == len(path) - 1
            if isinstance(slot, NamespacedType):
                if last:
                    raise LookupError(f"is a message ({'/'.join(slot.namespaced_name())}), not "
                                      'a primitive value: name one of its fields')
                current = class_of(slot)
            elif not last:
                raise LookupError(f'{name} is not a message, so it has no field '
                                  f'{path[step + 1][0]}')
            else:
                try:
                    return _slot_kind(slot)
                except LookupError as e:
                    raise LookupError(f'{name} {e}') from None
        raise LookupError('empty field name')

    return kind_of


def first_primitive_field(msg_type: Any, prefix: str = '') -> Optional[str]:
    """The DDS-SQL name of the first primitive field of ``msg_type``, or None."""
    from rosidl_parser.definition import AbstractString, Array, BasicType, NamespacedType
    for name, slot in fields_of(msg_type):
        if isinstance(slot, (BasicType, AbstractString)):
            return prefix + name
        if isinstance(slot, Array) and isinstance(slot.value_type, (BasicType, AbstractString)):
            return f'{prefix}{name}[0]'
        if isinstance(slot, NamespacedType):
            found = first_primitive_field(class_of(slot), f'{prefix}{name}.')
            if found:
                return found
    return None
