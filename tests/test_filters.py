"""Unit tests of the pure expression and literal helpers: no ROS, milliseconds."""

import pytest

from cft_action.topics.filters import (any_of, dds_literal, goal_filter_expression, never_match_on,
                                NEVER_MATCH, uuid_prefix_term)


@pytest.mark.parametrize('value, literal', [
    # the literal forms Fast DDS accepts (docs/INTERNALS.md section 5)
    ('hello', "'hello'"),                # bare string: quoted
    ("'hello'", "'hello'"),              # already quoted: unchanged
    ("`hello'", "`hello'"),              # backtick-quoted (Fast DDS closes with '): unchanged
    ('TRUE', 'TRUE'),                    # boolean
    ('42', '42'),                        # integer
    ('-3.5e2', '-3.5e2'),                # float
    ('0x1F', '0x1F'),                    # hex
    ('', "''"),                          # empty string
    # Python values
    (True, 'TRUE'), (False, 'FALSE'), (7, '7'), (-7, '-7'), (2.5, '2.5'),
    # near misses of the literal forms are bare strings
    ('12abc', "'12abc'"), ('true', "'true'"), ('0x', "'0x'"), ('hello world', "'hello world'"),
    ('.5', "'.5'"), ('5.', "'5.'"),      # Fast DDS rejects both as numbers
    # non-ASCII passes through inside the quotes
    ('héllo ✓', "'héllo ✓'"),
    ("'日本'", "'日本'"),
])
def test_dds_literal(value, literal):
    assert dds_literal(value) == literal


@pytest.mark.parametrize('value', ["it's", 'back`tick', "'a'b'", '`hello`'])
def test_embedded_quotes_cannot_be_quoted(value):
    with pytest.raises(ValueError, match='quote'):
        dds_literal(value)


@pytest.mark.parametrize('value', [float('nan'), float('inf')])
def test_non_finite_floats_are_refused(value):
    with pytest.raises(ValueError):
        dds_literal(value)


def test_other_types_are_refused():
    with pytest.raises(TypeError):
        dds_literal(b'bytes')


def test_uuid_prefix_term_indexes_every_byte():
    assert uuid_prefix_term(bytes([1, 255])) == 'goal_id.uuid[0] = 1 AND goal_id.uuid[1] = 255'
    with pytest.raises(ValueError):
        uuid_prefix_term(b'')
    with pytest.raises(ValueError):
        uuid_prefix_term(bytes(17))


def test_any_of():
    assert any_of([]) == NEVER_MATCH
    assert any_of(['a = 1']) == 'a = 1'
    assert any_of(['a = 1', 'b = 2']) == '(a = 1) OR (b = 2)'


def test_goal_filter_expression_is_canonical():
    one, two = bytes([2, 3]), bytes([1])
    assert goal_filter_expression([one, two]) == goal_filter_expression([two, one, one])
    assert goal_filter_expression([]) == NEVER_MATCH


def test_never_match_on():
    assert never_match_on('x.y[0]') == 'x.y[0] = x.y[0] AND x.y[0] <> x.y[0]'
