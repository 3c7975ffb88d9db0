# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Building DDS-SQL filter expressions and literals: pure functions, no ROS import.

Fast DDS parses every expression parameter as a DDS literal, so a bare string such as ``hello`` is a
parse error and must be sent as ``'hello'`` (eProsima/Fast-DDS#4199). :func:`dds_literal` applies
that rule once, for every caller. The other helpers build the ``goal_id.uuid`` expressions of the
action client. Fast DDS requires array members to be indexed, so a UUID is matched byte by byte.
"""

from __future__ import annotations

import math
import re
from typing import Iterable, NamedTuple, Union

from cft_action.errors import InvalidArgumentError

GOAL_UUID_FIELD = 'goal_id.uuid'

#: An expression that no sample matches. rmw_fastrtps recreates the DataReader when a filter is set
#: to ``""``, so an empty set of goals is expressed with this instead.
NEVER_MATCH = f'{GOAL_UUID_FIELD}[0] = 0 AND {GOAL_UUID_FIELD}[0] = 1'

#: An expression that every feedback sample matches: an in-place way back to receiving everything.
MATCH_ALL = f'{GOAL_UUID_FIELD}[0] = {GOAL_UUID_FIELD}[0]'

_QUOTES = ("'", '`')
# Fast DDS opens a string with ' or a backtick, closes it with ', and wants digits on both sides
# of a decimal point (measured: `hello` and .5 and 5. are parse errors, `hello' is not).
_NUMBER = re.compile(r'[+-]?(0[xX][0-9a-fA-F]+|\d+(\.\d+)?([eE][+-]?\d+)?)')
_BOOLEANS = ('TRUE', 'FALSE')

Literal = Union[str, bool, int, float]


class ContentFilterOptions(NamedTuple):
    """A filter expression and its parameters, named as in Kilted's rclpy.

    It unpacks as ``(expression, parameters)``.
    """

    filter_expression: str
    expression_parameters: list[str]


def dds_literal(value: Literal) -> str:
    """Return ``value`` as a DDS-SQL literal that Fast DDS accepts as an expression parameter.

    - ``bool`` becomes ``TRUE`` or ``FALSE``; ``int`` and finite ``float`` become numbers.
    - A string that already is a literal passes through unchanged: quoted (opened with ``'`` or a
      backtick, closed with ``'``), a number (integer, float or hex, optionally signed), ``TRUE``
      or ``FALSE``. Note that Fast DDS reads a leading ``0`` as octal: ``010`` is 8.
    - Any other string is a bare string and is wrapped in single quotes; ``''`` for the empty one.

    :raises ValueError: if the value cannot be written as a DDS literal: a non-finite float, or a
        string containing a quote character, which the Fast DDS grammar has no way to escape.
    :raises TypeError: for any other type.
    """
    if isinstance(value, bool):
        return 'TRUE' if value else 'FALSE'
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise InvalidArgumentError(f'{value!r} has no DDS literal form')
        return repr(value)
    if not isinstance(value, str):
        raise TypeError(f'cannot make a DDS literal of {type(value).__name__} {value!r}')
    if len(value) >= 2 and value[0] in _QUOTES and value[-1] == "'":
        inner = value[1:-1]
        if any(q in inner for q in _QUOTES):
            raise InvalidArgumentError(
                f'{value!r}: a quote inside a quoted DDS string cannot be escaped')
        return value
    if value in _BOOLEANS or _NUMBER.fullmatch(value):
        return value
    if any(q in value for q in _QUOTES):
        raise InvalidArgumentError(f'{value!r} contains a quote character; the DDS-SQL grammar of '
                                   'Fast DDS has no escape for it, so it cannot be a string '
                                   'literal')
    return f"'{value}'"


def never_match_on(field: str) -> str:
    """An expression that no sample matches, valid for any comparable ``field``, NaN included."""
    return f'{field} = {field} AND {field} <> {field}'


def dds_literals(values: Iterable[Literal]) -> list[str]:
    """Apply :func:`dds_literal` to each of ``values``."""
    return [dds_literal(v) for v in values]


def uuid_prefix_term(prefix: bytes, field: str = GOAL_UUID_FIELD) -> str:
    """Match a UUID field whose first bytes equal ``prefix``: one indexed equality per byte."""
    if not 1 <= len(prefix) <= 16:
        raise InvalidArgumentError(f'a UUID prefix has 1 to 16 bytes, not {len(prefix)}')
    return ' AND '.join(f'{field}[{i}] = {b}' for i, b in enumerate(prefix))


def any_of(terms: Iterable[str]) -> str:
    """OR-join ``terms``, each in parentheses; no terms give :data:`NEVER_MATCH`."""
    terms = list(terms)
    if not terms:
        return NEVER_MATCH
    if len(terms) == 1:
        return terms[0]
    return ' OR '.join(f'({t})' for t in terms)


def goal_filter_expression(prefixes: Iterable[bytes]) -> str:
    """The feedback filter matching goal UUIDs that start with any of ``prefixes``.

    The result is ordered, so that the same set always gives the same expression.
    """
    return any_of(uuid_prefix_term(p) for p in sorted(set(prefixes)))
