"""cft_action.topics.sql: the DDS-SQL evaluator of the client-side fallback, with the quirks of Fast
DDS.

Every quirk pinned here was measured against Fast DDS by test_topic_cli's agreement test.
"""

import math
from types import SimpleNamespace as Msg

import pytest

from cft_action.topics import sql
from cft_action.topics.sql import Kind


def matches(expression, message, parameters=(), schema=None):
    return sql.compile_filter(expression, parameters, schema).matches(message)


def kinds(**by_name):
    """A schema from top-level field names to kinds; any index is accepted."""
    def schema(path):
        name = path[0][0]
        if name not in by_name:
            raise LookupError('field not found')
        return by_name[name]
    return schema


# --- grammar and precedence -----------------------------------------------------------------------

@pytest.mark.parametrize('a, b, c, expected', [
    (1, 0, 0, False),  # SQL would say True: AND binds tighter there
    (1, 1, 1, True),
    (0, 1, 1, True),
])
def test_and_and_or_have_the_same_precedence_and_fold_left(a, b, c, expected):
    assert matches('a = 1 OR b = 1 AND c = 1', Msg(a=a, b=b, c=c)) is expected
    assert matches('(a = 1 OR b = 1) AND c = 1', Msg(a=a, b=b, c=c)) is expected
    assert matches('a = 1 OR (b = 1 AND c = 1)', Msg(a=a, b=b, c=c)) is bool(a or (b and c))


def test_not_groups_the_rest_of_its_list():
    # a AND ((NOT b) OR c), not ((a AND NOT b) OR c)
    assert matches('a = 1 AND NOT b = 1 OR c = 1', Msg(a=0, b=0, c=1)) is False
    assert matches('a = 1 AND NOT b = 1 OR c = 1', Msg(a=1, b=1, c=1)) is True
    assert matches('NOT a = 1 AND b = 1', Msg(a=0, b=1)) is True  # (NOT a) AND b
    assert matches('NOT (a = 1 AND b = 1)', Msg(a=0, b=0)) is True
    assert matches('NOT NOT a = 1', Msg(a=1)) is True


def test_tree_shape():
    tree = sql.parse('a = 1 or b <> 2 and NOT c != 3')
    assert isinstance(tree, sql.And)
    assert isinstance(tree.left, sql.Or)
    assert isinstance(tree.right, sql.Not)
    assert tree.right.operand.op == '<>'


@pytest.mark.parametrize('expression, value, expected', [
    ('data = 5', 5, True), ('data <> 5', 5, False), ('data != 5', 4, True),
    ('data < 5', 4, True), ('data <= 5', 5, True), ('data > 5', 5, False),
    ('data >= 5', 5, True), ('5 > data', 4, True), ('-5 < data', -4, True),
    ('data BETWEEN 1 AND 5', 5, True), ('data BETWEEN 1 AND 5', 6, False),
    ('data NOT BETWEEN 1 AND 5', 1, False), ('data NOT BETWEEN 1 AND 5', 0, True),
    ('data between 5 AND 1', 3, False),
])
def test_comparisons(expression, value, expected):
    assert matches(expression, Msg(data=value)) is expected


def test_field_against_field_and_nested_indexed_paths():
    message = Msg(pose=Msg(x=1.5, y=2.5), values=[3, 4], items=[Msg(name='a'), Msg(name='b')])
    assert matches('pose.x < pose.y', message)
    assert matches('values[1] > values[0] AND items[1].name = %0', message, ["'b'"])
    assert not matches('values[0] = pose.x', message)


# --- literals and parameters ----------------------------------------------------------------------

@pytest.mark.parametrize('literal, value', [
    ('010', 8),  # read like strtoull(s, 0): octal
    ('0x1F', 31), ('0X1f', 31), ('-0x10', -16), ('+7', 7), ('08', 0), ('0', 0),
    ('18446744073709551615', 2 ** 64 - 1), ('-9223372036854775808', -2 ** 63),
])
def test_integer_literals_are_read_like_c(literal, value):
    assert matches(f'data = {literal}', Msg(data=value))


@pytest.mark.parametrize('literal', ['18446744073709551616', '-9223372036854775809', '1e5000'])
def test_literals_out_of_range_are_errors(literal):
    with pytest.raises(sql.FilterError, match='out of'):
        sql.compile_filter(f'data = {literal}')


def test_parameters_are_dds_literals():
    assert matches('data = %0', Msg(data='hi'), ["'hi'"])
    assert matches('data = %0', Msg(data='hi'), ["`hi'"])  # Fast DDS opens with either quote
    assert matches('data > %0 AND data < %1', Msg(data=2.5), ['2', '3.0'])
    assert matches('flag = %0', Msg(flag=True), [' TRUE '])  # booleans may be padded
    assert matches('data = %0', Msg(data=1), ['1', 'not a literal'])  # %1 unused: not parsed
    with pytest.raises(sql.FilterError, match=r"parameter %0 = 'hi' is not a DDS literal: a string "
                                              r"must be quoted, as in 'hi'"):
        sql.compile_filter('data = %0', ['hi'])
    with pytest.raises(sql.FilterError, match=r'parameter %1 has no value \(1 given\)'):
        sql.compile_filter('data = %1', ['1'])
    for text in (' 1', '1 ', '.5', '1.', "'a' 'b'", "`a`"):
        with pytest.raises(sql.FilterError):
            sql.parse_literal(text)


def test_string_literals():
    assert sql.parse_literal("'a'").kind == Kind.CHAR
    assert sql.parse_literal("'ab'").kind == Kind.STRING
    assert sql.parse_literal("''").value == b''
    assert sql.parse_literal("'é'").kind == Kind.STRING  # two bytes
    assert sql.parse_literal(f"'{'x' * 255}'").kind == Kind.STRING
    with pytest.raises(sql.FilterError, match='more than 255 characters'):
        sql.parse_literal(f"'{'x' * 256}'")


# --- how Fast DDS compares ------------------------------------------------------------------------

def test_nan_compares_equal_to_everything():
    nan = Msg(data=math.nan)
    assert matches('data = 5', nan) and matches('data <= 5', nan) and matches('data >= 5', nan)
    assert not matches('data < 5', nan) and not matches('data <> 5', nan)


def test_float32_fields_compare_in_single_precision():
    f32 = 0.10000000149011612  # 0.1f
    assert matches('data = 0.1', Msg(data=f32), schema=kinds(data=Kind.FLOAT32))
    assert not matches('data = 0.1', Msg(data=f32), schema=kinds(data=Kind.FLOAT64))
    assert matches('data = 0.1', Msg(data=0.1), schema=kinds(data=Kind.FLOAT64))


def test_integer_fields_against_float_literals_compare_in_single_precision():
    assert matches('data = 16777216.0', Msg(data=16777217))  # 2**24 + 1 rounds to 2**24
    assert not matches('data = 16777216', Msg(data=16777217))
    assert matches('data > 1.5', Msg(data=2)) and not matches('data > 2.5', Msg(data=2))
    assert matches('data = 9007199254740993.0', Msg(data=2 ** 53 + 1))


def test_booleans_meet_integers_but_not_floats():
    assert matches('flag = 1', Msg(flag=True)) and matches('flag = TRUE', Msg(flag=True))
    assert matches('flag < TRUE', Msg(flag=False), schema=kinds(flag=Kind.BOOLEAN))
    with pytest.raises(sql.FilterError, match='cannot compare'):
        sql.compile_filter('flag = 1.5', schema=kinds(flag=Kind.BOOLEAN))


def test_strings_compare_like_strcmp_on_255_bytes():
    assert matches("data > 'z'", Msg(data='é'))  # UTF-8 bytes, not code points... same order
    assert matches("data < 'b'", Msg(data='a\0zzz'))  # cut at the NUL
    long = 'x' * 300
    assert matches('data = %0', Msg(data=long), [f"'{'x' * 255}'"])  # cut at 255 bytes
    assert matches("data = 'a'", Msg(data='a'))  # a char literal promoted to a string
    assert matches("'abc' < data", Msg(data='abd'))


def test_int8_is_read_as_an_unsigned_byte():
    schema = kinds(data=Kind.INT8_AS_OCTET)
    compiled = sql.compile_filter('data < 0', schema=schema)
    assert not compiled.matches(Msg(data=-1))
    assert sql.compile_filter('data = 255', schema=schema).matches(Msg(data=-1))
    assert 'unsigned byte' in compiled.warnings[0]


# --- LIKE and MATCH -------------------------------------------------------------------------------

@pytest.mark.parametrize('pattern, value, expected', [
    ('hello%', 'hello world', True), ('%world', 'hello world', True), ('h_llo', 'hallo', True),
    ('h_llo', 'hllo', False), ('%', '', True), ('_', '', False), ('', '', True),
    ('h*o', 'hello', True), ('h?llo', 'hello', True),  # * and ? too
    ('a.b', 'axb', True),  # the rest is a regular expression: '.' is any character
    ('a\\_b', 'a.b', True), ('a\\_b', 'axb', False),  # '\_' became '\.'
    ('h[ae]llo', 'hallo', True), ('(hello|world)', 'world', True), ('%l{2}o%', 'hello', True),
    ('hello', 'Hello', False), ('caf_', 'café', False),  # é is two bytes, as in std::regex
    ('a.b', 'a\rb', False), ('a.b', 'a\nb', False),  # ECMAScript '.' stops at line ends
])
def test_like(pattern, value, expected):
    assert matches(f"data LIKE '{pattern}'", Msg(data=value)) is expected
    assert matches('data like %0', Msg(data=value), [f"'{pattern}'"]) is expected


def test_match_is_a_regular_expression():
    assert matches("data MATCH 'h.*o'", Msg(data='hello'))
    assert not matches("data MATCH 'h.*o'", Msg(data='hello!'))  # the whole value
    assert matches("data match '[a-z]+'", Msg(data='abc'))


def test_like_to_regex():
    assert sql.like_to_regex('%a_b*c?') == '.*a.b.*c.'


@pytest.mark.parametrize('pattern', [
    'a(b', 'a)b', '[a', 'a{', 'x{2,1}', 'a**', '*a', 'a*+', '(?P<n>a)', '(?<=a)b', '(?>a)',
    '\\x41', '\\u0041', '\\A', '[]a]', '[[:alpha:]]', '[a--b]', '(?=a)*', 'a]', 'a}',
])
def test_patterns_not_proven_safe_for_fast_dds_are_refused(pattern):
    """std::regex aborts Fast DDS on an invalid pattern (std::terminate): these never reach it."""
    with pytest.raises(sql.FilterError, match='not a regular expression that this tool can prove '
                                              'safe'):
        sql.compile_filter('data MATCH %0', [f"'{pattern}'"])


@pytest.mark.parametrize('pattern', ['a??', 'a*?', 'a{2,3}?', '(a|b)+', '(?:ab)*', 'a(?=b)',
                                     '\\d+\\.\\d*', '[^a-z\\]]', '^a$', '\\bx\\b', 'é+'])
def test_safe_patterns_are_accepted(pattern):
    sql.compile_filter('data MATCH %0', [f"'{pattern}'"])


def test_like_needs_a_string_field_and_a_literal_pattern():
    schema = kinds(data=Kind.INTEGER, name=Kind.STRING, other=Kind.STRING)
    with pytest.raises(sql.FilterError, match='LIKE needs a string field'):
        sql.compile_filter("data LIKE 'a%'", schema=schema)
    with pytest.raises(sql.FilterError, match="pattern is the field 'other'"):
        sql.compile_filter('name LIKE other', schema=schema)


# --- fields that a sample does not have -----------------------------------------------------------

def test_a_missing_field_drops_the_sample_unless_already_decided():
    """Fast DDS reads fields in the order of their names and stops once the result is known."""
    compiled = sql.compile_filter('values[3] = 1 OR flag = 1')
    assert compiled.field_names == ['flag', 'values[3]']
    assert compiled.matches(Msg(values=[], flag=1))  # decided by 'flag' before 'values[3]'
    assert not compiled.matches(Msg(values=[], flag=0))
    compiled = sql.compile_filter('zeta = 1 OR values[3] = 1')
    assert not compiled.matches(Msg(values=[], zeta=1))  # 'values[3]' is read first: dropped
    assert compiled.matches(Msg(values=[0, 0, 0, 1], zeta=0))
    assert not matches('NOT values[0] = 1', Msg(values=[]))


# --- errors name the expression, the reason and the place -----------------------------------------

@pytest.mark.parametrize('expression, reason, column', [
    ('data > > 3', "expected a field name, a literal or a parameter, not '>'", 8),
    ("data = 'abc", 'unterminated string', 8),
    ('(data = 1', "expected ')'", 10),
    ('data = 1)', "unbalanced ')'", 9),
    ('3 = 4', 'a comparison needs a field name on one side', 1),
    ('data = 1 AND', 'expected a condition', 13),
    ('data LIKE', 'expected a field name, a literal or a parameter', 10),
    ('data ~ 1', "unexpected character '~'", 6),
    ('data BETWEEN 1 OR 2', 'expected AND in BETWEEN', 16),
    ('data = 1 data = 2', "expected AND or OR, not 'data'", 10),
    ('data = %100', "expected AND or OR, not '0'", 11),
])
def test_syntax_errors(expression, reason, column):
    with pytest.raises(sql.FilterError) as info:
        sql.parse(expression)
    error = info.value
    assert error.expression == expression and reason in error.reason
    assert str(error) == f'content filter {expression!r}: {error.reason} (at column {column})'
    assert error.detail.splitlines()[1:] == [f'  {expression}', '  ' + ' ' * (column - 1) + '^']


def test_empty_expression():
    with pytest.raises(sql.FilterError, match='the expression is empty'):
        sql.parse('  ')


def test_schema_errors_name_the_field():
    schema = kinds(data=Kind.INTEGER, name=Kind.STRING)
    with pytest.raises(sql.FilterError, match=r"field 'nope': field not found \(at column 1\)"):
        sql.compile_filter('nope = 1', schema=schema)
    with pytest.raises(sql.FilterError, match=r"cannot compare field 'data' \(integer\) with "
                                              r"'xy' \(string\)"):
        sql.compile_filter("data = 'xy'", schema=schema)
    with pytest.raises(sql.FilterError, match=r"cannot compare field 'name' \(string\) with "
                                              r"parameter %0 \(float\)"):
        sql.compile_filter('name = %0', ['1.5'], schema)


def test_without_a_schema_kinds_come_from_the_values():
    compiled = sql.compile_filter("data = 'x'")
    with pytest.raises(sql.FilterError, match='cannot compare a value of kind integer with one of '
                                              'kind char'):
        compiled.matches(Msg(data=1))
    with pytest.raises(sql.FilterError, match='LIKE needs a string field, not a value of kind '
                                              'float64'):
        sql.compile_filter("data LIKE 'a%'").matches(Msg(data=1.5))
    with pytest.raises(sql.FilterError, match="field 'data' not found"):
        compiled.matches(Msg(other=1))
    assert matches('data = 1', Msg(data=b'\x01'))  # a ROS octet


# --- check_filter: the linear-time shape of goal filters ---------------------------------------

def _goal_filters():
    import random
    from cft_action.action.goal_filter import GoalFilterPlan
    rng = random.Random(7)
    for mode in ('client', 'goals'):
        plan = GoalFilterPlan(mode, new_uuid=lambda: rng.randbytes(16))
        yield plan.initial()
        for _ in range(20):
            plan.watch(rng.randbytes(16))
            yield plan.grow()


def test_every_goal_filter_has_the_fast_shape_and_compiles():
    for expression in _goal_filters():
        assert sql._GOAL_FILTER_SHAPE.fullmatch(expression), expression
        sql.compile_filter(expression)


@pytest.mark.parametrize('expression', [
    'a = 0', 'a_1[999999999].b = 123456789012345678', '(x = 1 AND y = 2) OR (z = 3)',
    'ANDY = 1', 'orbit.NOTE = 2', '(a = 1) OR (b = 2) OR (c = 3 AND d = 4)',
])
def test_what_the_fast_shape_accepts_compiles(expression):
    assert sql._GOAL_FILTER_SHAPE.fullmatch(expression)
    sql.compile_filter(expression)


@pytest.mark.parametrize('expression', [
    'AND = 1', 'a.or = 1', 'a = 01', 'a = -1', "a = 'x'", 'a = %0', '(a = 1)', 'a = 1 OR b = 2',
    '(a = 1) OR b = 2', 'a = 1 AND', 'a LIKE 1', 'a = 1234567890123456789012', 'a  = 1',
])
def test_anything_else_takes_the_full_check(expression):
    assert not sql._GOAL_FILTER_SHAPE.fullmatch(expression)


@pytest.mark.parametrize('expression', ['AND = 1', 'a = 1 AND', "a LIKE '[x'", '(a = 1'])
def test_check_filter_rejects_as_compile_filter_does(expression):
    with pytest.raises(sql.FilterError):
        sql.compile_filter(expression)
    with pytest.raises(sql.FilterError):
        sql.check_filter(expression)
