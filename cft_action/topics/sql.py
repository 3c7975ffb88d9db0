# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""A Python evaluator for the DDS-SQL filter expressions of Fast DDS 2.14: pure, no ROS import.

This is the client-side fallback of ``cft-action topic ... --content-filter-fallback=client`` and
the diagnostician of expressions that Fast DDS rejects. Its verdicts follow what Fast DDS 2.14 does,
quirks included, so that a filter gives the same messages whether the middleware or Python applies
it (``tests/test_topic_cli.py`` checks this against real filtered subscriptions):

- ``AND`` and ``OR`` have the *same* precedence and associate to the left: ``a OR b AND c`` is
  ``(a OR b) AND c``, unlike SQL. ``NOT`` applies to the condition right after it, and the rest of
  its list is grouped: ``a AND NOT b OR c`` is ``a AND ((NOT b) OR c)``. Use parentheses.
- Keywords are all upper or all lower case (``AND``/``and``); ``!=`` is ``<>``; ``x BETWEEN a AND
  b`` and ``x NOT BETWEEN a AND b`` are supported, and so is ``MATCH`` (a regular expression).
- ``LIKE`` turns ``%`` and ``*`` into ``.*`` and ``_`` and ``?`` into ``.``; the rest of the
  pattern is an ECMAScript regular expression, so ``.`` matches any character. A pattern that is
  not a valid regular expression makes Fast DDS abort the process, so :func:`compile_filter`
  rejects every pattern that it cannot prove safe, and patterns taken from a field.
- An integer literal is read like C's ``strtoull(s, 0)``: ``0x1F`` is hex and ``010`` is *octal*.
- A float field compared with a float literal is compared in single precision: ``float32_value =
  0.1`` holds for the value ``0.1f``. An integer field compared with a float literal is too.
- NaN compares *equal* to everything (Fast DDS compares with ``<`` and ``>`` only).
- Strings compare byte-wise like ``strcmp``; a string field is cut at 255 bytes and at a NUL.
- An ``int8`` field is read as an unsigned byte (rmw_fastrtps describes it as an octet): -1 is 255,
  so ``int8_field < 0`` never holds (:attr:`Kind.INT8_AS_OCTET`; :attr:`Filter.warnings` says so).
- A sample whose indexed field does not exist (a sequence too short) is dropped, unless the
  expression was decided before that field was needed; fields are read in the order of their
  names, as Fast DDS does.

Field kinds come from a *schema*, a callable that maps a field path to a :class:`Kind` (see
:func:`cft_action.topics.message_types.message_schema` for ROS messages); without one, kinds are
inferred from the values of each message, which cannot tell ``float32`` from ``float64``.
"""

from __future__ import annotations

import enum
import math
import re
import struct
from dataclasses import dataclass
from decimal import Decimal
from typing import Any, Callable, Iterable, Optional, Sequence, Union

from cft_action.errors import CftActionError

__all__ = [
    'Filter', 'FilterError', 'FieldPath', 'Kind', 'Schema', 'check_filter', 'compile_filter',
    'like_to_regex', 'parse', 'parse_literal',
]

#: A field as a path of ``(member name, index or None)`` steps: ``a.b[2]`` is
#: ``(('a', None), ('b', 2))``.
FieldPath = tuple[tuple[str, Optional[int]], ...]


class Kind(enum.IntEnum):
    """The kind of a value, in Fast DDS's order of promotion."""

    BOOLEAN = 0
    INTEGER = 1  # signed and unsigned alike: Python compares them exactly, as Fast DDS does
    FLOAT_CONST = 2  # a float literal (a long double in Fast DDS)
    FLOAT32 = 3
    FLOAT64 = 4
    CHAR = 5  # a one-character literal such as 'a'
    STRING = 6
    #: A field of ROS type ``int8``, which rmw_fastrtps describes to Fast DDS as an unsigned byte:
    #: -1 is read as 255, so ``x < 0`` never holds. Compared as an INTEGER, after that reading.
    INT8_AS_OCTET = 7

    def describe(self) -> str:
        return _KIND_NAMES[self]


_KIND_NAMES = {
    Kind.BOOLEAN: 'boolean', Kind.INTEGER: 'integer', Kind.FLOAT_CONST: 'float',
    Kind.FLOAT32: 'float32', Kind.FLOAT64: 'float64', Kind.CHAR: 'char', Kind.STRING: 'string',
    Kind.INT8_AS_OCTET: 'int8, read as an unsigned byte',
}
_NUMERIC = frozenset({Kind.INTEGER, Kind.FLOAT_CONST, Kind.FLOAT32, Kind.FLOAT64})
_TEXT = frozenset({Kind.CHAR, Kind.STRING})

#: Maps a field path to its kind; raises :class:`LookupError` whose message is the reason.
Schema = Callable[[FieldPath], Kind]


class FilterError(CftActionError, ValueError):
    """An expression that cannot be applied: its syntax, a field, a parameter or a type.

    ``str()`` gives one line that names the expression and the reason; :attr:`detail` adds a caret
    under the position when it is known.
    """

    def __init__(self, expression: str, reason: str, position: Optional[int] = None) -> None:
        self.expression = expression
        self.reason = reason
        self.position = position
        where = f' (at column {position + 1})' if position is not None else ''
        super().__init__(f'content filter {expression!r}: {reason}{where}')

    @property
    def detail(self) -> str:
        """The message, with the expression and a caret under the position, as Fast DDS logs it."""
        if self.position is None:
            return str(self)
        return f'{self}\n  {self.expression}\n  {" " * self.position}^'


# --- the syntax tree ------------------------------------------------------------------------------

@dataclass(frozen=True)
class Field:
    text: str  # as written; Fast DDS reads fields in the order of these texts
    path: FieldPath
    pos: int


@dataclass(frozen=True)
class Const:
    kind: Kind
    value: Any  # bool, int, float, or bytes for CHAR and STRING
    text: str
    pos: int


@dataclass(frozen=True)
class Param:
    index: int
    pos: int


Operand = Union[Field, Const, Param]


@dataclass(frozen=True)
class Compare:
    op: str  # '=', '<>', '<', '<=', '>', '>=', 'LIKE', 'MATCH'
    left: Operand
    right: Operand
    pos: int


@dataclass(frozen=True)
class Between:
    field: Field
    low: Operand
    high: Operand
    negated: bool
    pos: int


@dataclass(frozen=True)
class And:
    left: Any
    right: Any


@dataclass(frozen=True)
class Or:
    left: Any
    right: Any


@dataclass(frozen=True)
class Not:
    operand: Any


# --- tokens ---------------------------------------------------------------------------------------

_KEYWORDS = {
    'AND': 'AND', 'and': 'AND', 'OR': 'OR', 'or': 'OR', 'NOT': 'NOT', 'not': 'NOT',
    'BETWEEN': 'BETWEEN', 'between': 'BETWEEN', 'LIKE': 'LIKE', 'like': 'LIKE',
    'MATCH': 'MATCH', 'match': 'MATCH', 'TRUE': 'TRUE', 'true': 'TRUE', 'FALSE': 'FALSE',
    'false': 'FALSE',
}
_TOKEN = re.compile(r'''
    (?P<space>\s+)
  | (?P<string>['`][^'\r\n]*')
  | (?P<float>[+-]?\d+(?:[eE][+-]?\d+|\.\d+(?:[eE][+-]?\d+)?))
  | (?P<hex>[+-]?0[xX][0-9a-fA-F]+)
  | (?P<integer>[+-]?\d+)
  | (?P<param>%\d\d?)
  | (?P<op><>|!=|<=|>=|<|>|=)
  | (?P<paren>[()])
  | (?P<word>[A-Za-z_]\w*(?:\[\d+\])?(?:\.[A-Za-z_]\w*(?:\[\d+\])?)*)
''', re.VERBOSE | re.ASCII)
_FIELD_PART = re.compile(r'([A-Za-z_]\w*)(?:\[(\d+)\])?', re.ASCII)


@dataclass(frozen=True)
class _Token:
    type: str  # 'string', 'float', 'hex', 'integer', 'param', 'op', 'paren', 'field', a keyword
    text: str
    pos: int


def _tokenize(expression: str) -> list[_Token]:
    tokens = []
    pos = 0
    while pos < len(expression):
        match = _TOKEN.match(expression, pos)
        if not match:
            if expression[pos] in '\'`':
                raise FilterError(expression, 'unterminated string: a string literal is closed by '
                                  "' and cannot contain ' or a line break", pos)
            raise FilterError(expression, f'unexpected character {expression[pos]!r}', pos)
        kind = match.lastgroup or ''  # every alternative of _TOKEN is a named group
        text = match.group()
        if kind == 'word':
            kind = _KEYWORDS.get(text, 'field')
        elif kind == 'op' and text == '!=':
            text = '<>'
        if kind != 'space':
            tokens.append(_Token(kind, text, pos))
        pos = match.end()
    return tokens


# --- literals -------------------------------------------------------------------------------------

_LONG_DOUBLE_MAX_EXPONENT = 4931  # std::stold fails beyond this decimal exponent


def _c_integer(expression: str, text: str, pos: int) -> tuple[Kind, int]:
    """Read an integer the way Fast DDS does, with ``std::stoull(text, nullptr, 0)``."""
    negative = text.startswith('-')
    body = text.lstrip('+-')
    if body[:2] in ('0x', '0X'):
        value = int(body[2:], 16)
    elif body.startswith('0'):
        # C reads a leading 0 as octal, and stops at the first digit that is not octal
        value = int(re.sub('[^0-7].*', '', body) or '0', 8)
    else:
        value = int(body)
    if negative:
        value = -value
        if value < -2 ** 63:
            raise FilterError(expression, f'integer {text} is out of the range of int64', pos)
    elif value >= 2 ** 64:
        raise FilterError(expression, f'integer {text} is out of the range of uint64', pos)
    return Kind.INTEGER, value


def _literal(expression: str, token: _Token) -> Const:
    text, pos = token.text, token.pos
    if token.type in ('TRUE', 'FALSE'):
        return Const(Kind.BOOLEAN, token.type == 'TRUE', text, pos)
    if token.type in ('integer', 'hex'):
        kind, value = _c_integer(expression, text, pos)
        return Const(kind, value, text, pos)
    if token.type == 'float':
        if Decimal(text).adjusted() > _LONG_DOUBLE_MAX_EXPONENT:
            raise FilterError(expression, f'float {text} is out of range', pos)
        return Const(Kind.FLOAT_CONST, float(text), text, pos)
    if token.type == 'string':
        content = text[1:-1].encode('utf-8')
        if len(content) == 1:
            return Const(Kind.CHAR, content, text, pos)
        if len(content) > 255:
            raise FilterError(expression, 'string constant has more than 255 characters', pos)
        return Const(Kind.STRING, content, text, pos)
    raise AssertionError(token)


_LITERAL_TYPES = frozenset({'TRUE', 'FALSE', 'integer', 'hex', 'float', 'string'})


def parse_literal(text: str) -> Const:
    """Parse an expression parameter as Fast DDS does: the whole text must be one DDS literal.

    :raises FilterError: naming the text, if it is not a literal (a bare string, for instance).
    """
    try:
        tokens = _tokenize(text)
    except FilterError:
        tokens = []
    if len(tokens) != 1 or tokens[0].type not in _LITERAL_TYPES or (
            tokens[0].type not in ('TRUE', 'FALSE') and text != tokens[0].text):
        reason = 'not a DDS literal'
        if "'" not in text:
            reason += f": a string must be quoted, as in '{text}'"
        raise FilterError(text, reason)
    return _literal(text, tokens[0])


# --- the parser -----------------------------------------------------------------------------------

class _Parser:
    """Recursive descent over Fast DDS's grammar, building the tree that Fast DDS builds.

    ``ConditionList := Condition ((AND | OR) Condition)*``, folded to the left, and
    ``Condition := '(' ConditionList ')' | NOT ConditionList | Predicate``.
    """

    def __init__(self, expression: str) -> None:
        self.expression = expression
        self.tokens = _tokenize(expression)
        self.i = 0

    def error(self, reason: str, token: Optional[_Token] = None):
        token = token or self.peek()
        position = token.pos if token else len(self.expression)
        return FilterError(self.expression, reason, position)

    def peek(self, ahead: int = 0) -> Optional[_Token]:
        index = self.i + ahead
        return self.tokens[index] if index < len(self.tokens) else None

    def peek_type(self, ahead: int = 0) -> Optional[str]:
        token = self.peek(ahead)
        return token.type if token is not None else None

    def take(self) -> _Token:
        token = self.peek()
        if token is None:
            raise self.error('unexpected end of the expression')
        self.i += 1
        return token

    def parse(self):
        if not self.tokens:
            raise FilterError(self.expression, 'the expression is empty')
        tree = self.condition_list()
        token = self.peek()
        if token is not None:
            if token.type == 'paren':
                raise self.error("unbalanced ')'")
            raise self.error(f'expected AND or OR, not {token.text!r}')
        return tree

    def condition_list(self):
        tree = self.condition()
        return self.continue_list(tree)

    def continue_list(self, tree):
        while self.peek_type() in ('AND', 'OR'):
            op = self.take().type
            right = self.condition()
            tree = And(tree, right) if op == 'AND' else Or(tree, right)
        return tree

    def condition(self):
        token = self.peek()
        if token is None:
            raise self.error('expected a condition')
        if token.type == 'paren' and token.text == '(':
            self.take()
            tree = self.condition_list()
            closing = self.peek()
            if closing is None or closing.text != ')':
                raise self.error("expected ')'" if closing is None
                                 else f"expected ')', AND or OR, not {closing.text!r}")
            self.take()
            return tree
        if token.type == 'NOT':
            self.take()
            return self.continue_list(Not(self.condition()))
        return self.predicate()

    def operand(self) -> Operand:
        token = self.peek()
        if token is None:
            raise self.error('expected a field name, a literal or a parameter')
        if token.type == 'field':
            self.take()
            path = tuple((name, int(index) if index else None)
                         for name, index in _FIELD_PART.findall(token.text))
            return Field(token.text, path, token.pos)
        if token.type == 'param':
            self.take()
            return Param(int(token.text[1:]), token.pos)
        if token.type in _LITERAL_TYPES:
            self.take()
            return _literal(self.expression, token)
        raise self.error(f'expected a field name, a literal or a parameter, not {token.text!r}')

    def predicate(self):
        left = self.operand()
        token = self.peek()
        if isinstance(left, Field) and token is not None and (
                token.type == 'BETWEEN'
                or (token.type == 'NOT' and self.peek_type(1) == 'BETWEEN')):
            negated = token.type == 'NOT'
            self.take()
            if negated:
                self.take()
            low = self.operand()
            if self.peek_type() != 'AND':
                raise self.error('expected AND in BETWEEN ... AND ...')
            self.take()
            high = self.operand()
            for bound in (low, high):
                if isinstance(bound, Field):
                    raise self.error('the bounds of BETWEEN are literals or parameters',
                                     _Token('', '', bound.pos))
            return Between(left, low, high, negated, token.pos)
        if token is None or not (token.type == 'op' or token.type in ('LIKE', 'MATCH')):
            found = 'the end' if token is None else repr(token.text)
            raise self.error(f'expected a comparison operator (=, <>, <, <=, >, >=, LIKE, MATCH) '
                             f'or BETWEEN, not {found}')
        self.take()
        op = token.text if token.type == 'op' else token.type
        right = self.operand()
        if not isinstance(left, Field) and not isinstance(right, Field):
            raise FilterError(self.expression, 'a comparison needs a field name on one side',
                              left.pos)
        return Compare(op, left, right, token.pos)


def parse(expression: str):
    """Parse ``expression`` into a syntax tree, without looking at fields, types or parameters.

    :raises FilterError: naming the expression, the reason and the position.
    """
    return _Parser(expression).parse()


# --- numbers and strings as Fast DDS holds them ---------------------------------------------------

def _f32(value: float) -> float:
    """Round a double to single precision, as a C cast does (overflow gives infinity)."""
    try:
        return struct.unpack('f', struct.pack('f', value))[0]
    except OverflowError:
        return math.copysign(math.inf, value)


def _int_to_f32(value: int) -> float:
    """Round an integer to single precision in one step, as ``(float)(long double)n`` does."""
    magnitude = abs(value)
    shift = magnitude.bit_length() - 24
    if shift > 0:
        quotient, remainder = divmod(magnitude, 1 << shift)
        half = 1 << (shift - 1)
        if remainder > half or (remainder == half and quotient & 1):
            quotient += 1
        magnitude = quotient << shift
    return float(magnitude if value >= 0 else -magnitude)


def _c_string(value: Union[str, bytes]) -> bytes:
    """A string as Fast DDS compares it: UTF-8, cut at a NUL and at 255 bytes (``string_255``)."""
    data = value.encode('utf-8') if isinstance(value, str) else bytes(value)
    return data.split(b'\0', 1)[0][:255]


def _cmp(a, b) -> int:
    """Fast DDS's three-way comparison: NaN is neither less nor greater, so it is 'equal'."""
    return -1 if a < b else 1 if a > b else 0


def _compare(left_kind: Kind, left, right_kind: Kind, right) -> int:
    kind = max(left_kind, right_kind)
    if kind in (Kind.BOOLEAN, Kind.INTEGER):
        return _cmp(int(left), int(right))
    if kind in (Kind.FLOAT_CONST, Kind.FLOAT32):
        return _cmp(_to_f32(left_kind, left), _to_f32(right_kind, right))
    if kind == Kind.FLOAT64:
        return _cmp(float(left), float(right))
    return _cmp(left, right)  # CHAR and STRING, as bytes


def _to_f32(kind: Kind, value) -> float:
    return _int_to_f32(int(value)) if kind <= Kind.INTEGER else _f32(value)


def _compatible(a: Kind, b: Kind) -> bool:
    """Fast DDS's ``check_value_compatibility``: booleans meet integers, numbers meet numbers."""
    if a == Kind.BOOLEAN or b == Kind.BOOLEAN:
        return {a, b} <= {Kind.BOOLEAN, Kind.INTEGER}
    if a in _NUMERIC:
        return b in _NUMERIC
    return a in _TEXT and b in _TEXT


# --- regular expressions --------------------------------------------------------------------------

_SAFE_ESCAPES = frozenset('dDwWsSbBnrtfv123456789^$\\.*+?()[]{}|/-')
_SAFE_CLASS_ESCAPES = frozenset('dDwWsSbnrtfv^$\\.*+?()[]{}|/-')
_QUANTIFIER = re.compile(r'\{(\d+)(,(\d*))?\}')


def like_to_regex(pattern: str) -> str:
    """Turn a LIKE pattern into the regular expression that Fast DDS matches: ``%`` and ``*``
    become ``.*``, ``_`` and ``?`` become ``.``; everything else is left as it is."""
    return pattern.replace('*', '.*').replace('?', '.').replace('%', '.*').replace('_', '.')


def _ecmascript_to_python(regex: str) -> str:
    """Check that ``regex`` uses only syntax that ECMAScript (std::regex) and Python read alike,
    and return the Python spelling; raise ``ValueError`` naming what is not safe.

    Fast DDS aborts the whole process on a pattern that std::regex rejects, so anything not known
    to be safe is refused: groups other than ``(?:``, ``(?=`` and ``(?!``, braces that are not a
    quantifier, escapes other than classes and punctuation, POSIX classes, possessive quantifiers.
    Outside brackets ``.`` becomes ``[^\\n\\r]``, ``^`` ``\\A`` and ``$`` ``\\Z``.
    """
    out = []
    i = 0
    after_atom = False  # a quantifier may follow
    quantified = 0  # 1: just after a quantifier, where a lazy '?' may follow; 2: after that '?'
    groups = []  # for each open group: whether it is a lookahead, which cannot be quantified
    while i < len(regex):
        c = regex[i]
        if c in '*+?{':
            if c == '{':
                match = _QUANTIFIER.match(regex, i)
                if not match:
                    raise ValueError("a '{' that is not a quantifier {m}, {m,} or {m,n}")
                if match.group(3) and int(match.group(3)) < int(match.group(1)):
                    raise ValueError(f'the quantifier {match.group()} is out of order')
                token = match.group()
            else:
                token = c
            if token == '?' and quantified == 1:
                out.append('?')  # lazy
                quantified = 2
            elif not after_atom:
                raise ValueError(f'{token!r} has nothing to repeat')
            else:
                out.append(token)
                quantified = 1
            i += len(token)
            after_atom = False
            continue
        quantified = 0
        if c == '\\':
            if i + 1 >= len(regex) or regex[i + 1] not in _SAFE_ESCAPES:
                raise ValueError(f'the escape {regex[i:i + 2]!r} is not known to be safe')
            out.append(regex[i:i + 2])
            after_atom = regex[i + 1] not in 'bB'
            i += 2
        elif c == '[':
            i, text = _bracket(regex, i)
            out.append(text)
            after_atom = True
        elif c == '(':
            if regex.startswith('(?', i):
                if regex[i + 2:i + 3] not in (':', '=', '!'):
                    raise ValueError(f'the group {regex[i:i + 3]!r} is not ECMAScript')
                groups.append(regex[i + 2] != ':')
                out.append(regex[i:i + 3])
                i += 3
            else:
                groups.append(False)
                out.append('(')
                i += 1
            after_atom = False
        elif c == ')':
            if not groups:
                raise ValueError("an unbalanced ')'")
            after_atom = not groups.pop()
            out.append(')')
            i += 1
        elif c in ']}':
            raise ValueError(f'a lone {c!r}')
        else:
            out.append({'|': '|', '.': '[^\\n\\r]', '^': '\\A', '$': '\\Z'}.get(c) or re.escape(c))
            after_atom = c not in '|^$'
            i += 1
    if groups:
        raise ValueError("an unbalanced '('")
    return ''.join(out)


def _bracket(regex: str, start: int) -> tuple[int, str]:
    """Read a bracket expression; return its end and its Python spelling."""
    i = start + 1
    if regex.startswith('^', i):
        i += 1
    if regex.startswith(']', i):
        raise ValueError("a ']' first in brackets, which ECMAScript and Python read differently")
    while i < len(regex) and regex[i] != ']':
        c = regex[i]
        if c == '[':
            raise ValueError("a '[' inside brackets (POSIX classes are not portable)")
        if c == '\\':
            if i + 1 >= len(regex) or regex[i + 1] not in _SAFE_CLASS_ESCAPES:
                raise ValueError(f'the escape {regex[i:i + 2]!r} is not known to be safe')
            i += 2
            continue
        if regex[i:i + 2] in ('--', '&&', '~~', '||'):
            raise ValueError(f'{regex[i:i + 2]!r} inside brackets')
        i += 1
    if i >= len(regex):
        raise ValueError("an unterminated '['")
    return i + 1, regex[start:i + 1]


def _compile_pattern(expression: str, op: str, pattern: bytes, pos: int) -> re.Pattern:
    text = pattern.decode('utf-8', 'surrogateescape')
    regex = like_to_regex(text) if op == 'LIKE' else text
    try:
        python_regex = _ecmascript_to_python(regex)
        return re.compile(python_regex.encode('utf-8', 'surrogateescape'), re.DOTALL)
    except (ValueError, re.error) as e:
        raise FilterError(
            expression, f'{op} pattern {text!r} is not a regular expression that this tool can '
            f'prove safe for Fast DDS, which aborts the process on an invalid one: {e}',
            pos) from None


# --- compiled filters -----------------------------------------------------------------------------

class _Missing(Exception):
    """A field that the sample does not have: an index past the end of a sequence."""


@dataclass
class _Operand:
    kind: Optional[Kind]  # None: a field whose kind comes from each value (no schema)
    value: Any = None
    field: Optional[Field] = None


@dataclass
class _Predicate:
    op: str
    left: _Operand
    right: _Operand
    pattern: Optional[re.Pattern]
    pos: int


def _value_kind(value) -> tuple[Kind, Any]:
    """The kind of a field value when there is no schema, and the value as Fast DDS holds it."""
    dtype = getattr(value, 'dtype', None)
    if dtype is not None:  # a numpy scalar, from a fixed-size array of a ROS message
        value = value.item()
        if dtype.kind == 'f':
            return (Kind.FLOAT32 if dtype.itemsize == 4 else Kind.FLOAT64), float(value)
    if isinstance(value, bool):
        return Kind.BOOLEAN, value
    if isinstance(value, int):
        return Kind.INTEGER, value
    if isinstance(value, float):
        return Kind.FLOAT64, value
    if isinstance(value, (bytes, bytearray)) and len(value) == 1:
        return Kind.INTEGER, value[0]  # a ROS octet
    if isinstance(value, str):
        return Kind.STRING, _c_string(value)
    raise LookupError(f'is a {type(value).__name__}, not a primitive value')


def _convert(kind: Kind, value):
    if kind == Kind.INT8_AS_OCTET:
        return (value[0] if isinstance(value, (bytes, bytearray)) else int(value)) & 0xFF
    if kind == Kind.BOOLEAN:
        return bool(value)
    if kind == Kind.INTEGER:
        if isinstance(value, (bytes, bytearray)):
            return value[0]
        return int(value)
    if kind in (Kind.FLOAT32, Kind.FLOAT64):
        return float(value)
    return _c_string(value)


class Filter:
    """A compiled filter expression: call :meth:`matches` with a message.

    Build it with :func:`compile_filter`.
    """

    def __init__(self, expression: str, parameters: Sequence[str], tree, schema: Optional[Schema],
                 fields: dict[str, Field], kinds: dict[str, Optional[Kind]], root) -> None:
        self.expression = expression
        self.parameters = list(parameters)
        self.tree = tree
        self.schema = schema
        self._fields = fields
        self._kinds = kinds
        self._order = sorted(fields)  # Fast DDS keeps fields in a std::map by their text
        self._root = root
        #: Notes on how Fast DDS reads the fields, for the user: e.g. an int8 read as unsigned.
        self.warnings: list[str] = []

    @property
    def field_names(self) -> list[str]:
        """The fields the expression reads, in the order Fast DDS reads them."""
        return list(self._order)

    def __call__(self, message) -> bool:
        return self.matches(message)

    def matches(self, message) -> bool:
        """Return whether ``message`` passes the filter, as Fast DDS 2.14 decides.

        :raises FilterError: without a schema, if a field is missing from the message's type or a
            value's kind cannot be compared as the expression asks.
        """
        values: dict[str, tuple[Kind, Any]] = {}
        for name in self._order:
            if self._state(self._root, values) is not None:
                break  # decided before this field was needed, as in Fast DDS
            try:
                values[name] = self._read(message, name)
            except _Missing:
                return False
        return self._state(self._root, values) is True

    def _read(self, message, name: str) -> tuple[Kind, Any]:
        field = self._fields[name]
        value = message
        for member, index in field.path:
            try:
                value = getattr(value, member)
            except AttributeError:
                raise FilterError(self.expression, f'field {field.text!r} not found: '
                                  f'{type(value).__name__} has no member {member!r}',
                                  field.pos) from None
            if index is not None:
                if index >= len(value):
                    raise _Missing
                value = value[index]
        kind = self._kinds[name]
        if kind is None:
            try:
                return _value_kind(value)
            except LookupError as e:
                raise FilterError(self.expression, f'field {field.text!r} {e}', field.pos) from None
        return _comparable(kind), _convert(kind, value)

    def _state(self, node, values) -> Optional[bool]:
        """Three-valued evaluation: None while a field that decides it is not read yet."""
        if isinstance(node, _Predicate):
            left_value = self._operand(node.left, values)
            right_value = self._operand(node.right, values)
            if left_value is None or right_value is None:
                return None
            return self._decide(node, left_value, right_value)
        if isinstance(node, Not):
            state = self._state(node.operand, values)
            return None if state is None else not state
        left = self._state(node.left, values)
        if isinstance(node, And):
            if left is False:
                return False
            right = self._state(node.right, values)
            if right is False:
                return False
            return True if left is True and right is True else None
        if left is True:
            return True
        right = self._state(node.right, values)
        if right is True:
            return True
        return False if left is False and right is False else None

    @staticmethod
    def _operand(operand: _Operand, values) -> Optional[tuple[Kind, Any]]:
        if operand.field is None:
            assert operand.kind is not None  # a constant's kind is known when it is parsed
            return operand.kind, operand.value
        return values.get(operand.field.text)

    def _decide(self, node: _Predicate, left, right) -> bool:
        (left_kind, left_value), (right_kind, right_value) = left, right
        if node.pattern is not None:
            if left_kind not in _TEXT:  # only without a schema
                raise FilterError(self.expression, f'{node.op} needs a string field, not a value '
                                  f'of kind {left_kind.describe()}', node.pos)
            return node.pattern.fullmatch(left_value) is not None
        if not _compatible(left_kind, right_kind):  # only without a schema
            raise FilterError(self.expression, f'cannot compare a value of kind '
                              f'{left_kind.describe()} with one of kind {right_kind.describe()}',
                              node.pos)
        result = _compare(left_kind, left_value, right_kind, right_value)
        return {'=': result == 0, '<>': result != 0, '<': result < 0, '<=': result <= 0,
                '>': result > 0, '>=': result >= 0}[node.op]


def compile_filter(expression: str, parameters: Iterable[str] = (),
                   schema: Optional[Schema] = None) -> Filter:
    """Parse and check ``expression`` with its ``parameters``, as Fast DDS 2.14 would.

    :param expression: A DDS-SQL filter expression.
    :param parameters: The values of ``%0`` .. ``%99`` as DDS literals (strings quoted: ``'a'``);
        :func:`cft_action.topics.filters.dds_literal` makes them. Only the ones used are parsed.
    :param schema: Gives the kind of each field, and raises :class:`LookupError` with the reason
        for a field that does not exist or is not primitive; without it kinds are inferred from each
        message.
    :raises FilterError: naming the expression and the reason: syntax, unknown field, missing or
        malformed parameter, types that cannot be compared, a LIKE/MATCH pattern that is not safe.
    """
    parameters = list(parameters)
    tree = parse(expression)
    fields: dict[str, Field] = {}
    kinds: dict[str, Optional[Kind]] = {}
    bound_params: dict[int, Const] = {}
    warnings: list[str] = []

    def bind(operand: Operand) -> _Operand:
        if isinstance(operand, Const):
            return _Operand(operand.kind, operand.value)
        if isinstance(operand, Param):
            if operand.index >= len(parameters):
                raise FilterError(expression, f'parameter %{operand.index} has no value '
                                  f'({len(parameters)} given)', operand.pos)
            if operand.index not in bound_params:
                text = parameters[operand.index]
                try:
                    bound_params[operand.index] = parse_literal(text)
                except FilterError as e:
                    raise FilterError(expression, f'parameter %{operand.index} = {text!r} is '
                                      f'{e.reason}', operand.pos) from None
            const = bound_params[operand.index]
            return _Operand(const.kind, const.value)
        if operand.text not in fields:
            kind = None
            if schema is not None:
                try:
                    kind = schema(operand.path)
                except LookupError as e:
                    reason = e.args[0] if e.args else 'field not found'
                    raise FilterError(expression, f'field {operand.text!r}: {reason}',
                                      operand.pos) from None
            fields[operand.text] = operand
            kinds[operand.text] = kind
            if kind == Kind.INT8_AS_OCTET:
                warnings.append(
                    f'field {operand.text!r} is an int8, which Fast DDS 2.14 reads as an unsigned '
                    'byte: -1 is compared as 255, so a negative value never matches "< 0"')
        kind = kinds[operand.text]
        return _Operand(None if kind is None else _comparable(kind), field=fields[operand.text])

    def check(op: str, left: _Operand, right: _Operand, pos: int, left_src, right_src) -> None:
        if left.kind is None or right.kind is None:
            return  # no schema: checked on each message
        if op in ('LIKE', 'MATCH'):
            if not any(isinstance(src, Field) and operand.kind == Kind.STRING
                       for src, operand in ((left_src, left), (right_src, right))):
                raise FilterError(expression, f'{op} needs a string field on one side', pos)
        if not _compatible(left.kind, right.kind):
            raise FilterError(expression, f'cannot compare {_describe(left_src, left.kind)} with '
                              f'{_describe(right_src, right.kind)}', pos)

    def build(node):
        if isinstance(node, (And, Or)):
            return type(node)(build(node.left), build(node.right))
        if isinstance(node, Not):
            return Not(build(node.operand))
        if isinstance(node, Between):
            field, low, high = bind(node.field), bind(node.low), bind(node.high)
            for bound, src in ((low, node.low), (high, node.high)):
                check('<=', field, bound, node.pos, node.field, src)
            check('<=', low, high, node.pos, node.low, node.high)
            if node.negated:  # Fast DDS: low > field OR field > high
                return Or(_Predicate('>', low, field, None, node.pos),
                          _Predicate('>', field, high, None, node.pos))
            return And(_Predicate('<=', low, field, None, node.pos),
                       _Predicate('<=', field, high, None, node.pos))
        left, right = bind(node.left), bind(node.right)
        check(node.op, left, right, node.pos, node.left, node.right)
        pattern = None
        if node.op in ('LIKE', 'MATCH'):
            if right.field is not None:
                raise FilterError(
                    expression, f'the {node.op} pattern is the field {node.right.text!r}: Fast '
                    'DDS would compile every sample\'s value as a regular expression and abort '
                    'on an invalid one, so patterns must be literals or parameters', node.pos)
            if right.kind not in _TEXT:
                raise FilterError(expression, f'the {node.op} pattern must be a string', node.pos)
            pattern = _compile_pattern(expression, node.op, right.value, node.pos)
        return _Predicate(node.op, left, right, pattern, node.pos)

    root = build(tree)
    result = Filter(expression, parameters, tree, schema, fields, kinds, root)
    result.warnings = warnings
    return result


# The shape of the action client's goal filters (cft_action.topics.filters.any_of of
# uuid_prefix_term): equalities of a field with a small decimal integer, ANDed, and conjunctions in
# parentheses ORed. It has no string, parameter, pattern or literal out of range, and its grammar is
# that of _TOKEN and parse: every expression of this shape compiles (tests/test_sql.py checks both
# ways).
_KEYWORD = f'(?:{"|".join(_KEYWORDS)})'
_EQUALITY = (rf'(?!{_KEYWORD}\b)[A-Za-z_]\w*(?:\[\d{{1,9}}\])?'
             rf'(?:\.(?!{_KEYWORD}\b)[A-Za-z_]\w*(?:\[\d{{1,9}}\])?)* = (?:0|[1-9]\d{{0,17}})')
_CONJUNCTION = rf'{_EQUALITY}(?: AND {_EQUALITY})*'
_GOAL_FILTER_SHAPE = re.compile(
    rf'{_CONJUNCTION}|\({_CONJUNCTION}\)(?: OR \({_CONJUNCTION}\))+', re.ASCII)


def check_filter(expression: str, parameters: Iterable[str] = ()) -> None:
    """Raise :class:`FilterError` for an expression that Fast DDS 2.14 would reject or abort on.

    As :func:`compile_filter` without its result, and in linear time with a regular expression
    for the shape of the action client's goal filters, which it may check on every update: for a
    60 kB one that is a few milliseconds instead of a tenth of a second.
    """
    if _GOAL_FILTER_SHAPE.fullmatch(expression):
        return
    compile_filter(expression, parameters)


def _comparable(kind: Kind) -> Kind:
    return Kind.INTEGER if kind == Kind.INT8_AS_OCTET else kind


def _describe(src: Operand, kind: Kind) -> str:
    if isinstance(src, Field):
        return f'field {src.text!r} ({kind.describe()})'
    if isinstance(src, Param):
        return f'parameter %{src.index} ({kind.describe()})'
    return f'{src.text} ({kind.describe()})'
