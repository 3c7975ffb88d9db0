"""Unit tests of the feedback-filter planner: which terms, and when the filter must change."""

import itertools
import uuid

import pytest

from cft_action.topics.filters import NEVER_MATCH, uuid_prefix_term
from cft_action.action.goal_filter import (DEFAULT_RESERVE, ExpressionTooLong, GoalFilterPlan,
                                    MAX_EXPRESSION_BYTES, TAG_BYTES, TERM_BYTES)


def test_client_mode_matches_only_the_tag_and_never_grows_for_its_own_uuids():
    plan = GoalFilterPlan('client', tag=b'\x01\x02\x03\x04')
    expression = plan.initial()
    assert expression == ('goal_id.uuid[0] = 1 AND goal_id.uuid[1] = 2 AND '
                          'goal_id.uuid[2] = 3 AND goal_id.uuid[3] = 4')
    for _ in range(1000):
        goal = plan.uuid_for_feedback()
        assert goal[:TAG_BYTES] == b'\x01\x02\x03\x04'
        assert uuid.UUID(bytes=goal).version == 4
        assert not plan.watch(goal)
    assert plan.live_goals == 0


def test_client_mode_adds_an_exact_term_for_a_foreign_uuid():
    plan = GoalFilterPlan('client', tag=b'\xaa' * 4)
    plan.initial()
    own = bytes(range(16))
    assert plan.watch(own)
    expression = plan.grow()
    assert 'goal_id.uuid[15] = 15' in expression and expression.count(' OR ') == 1
    assert not plan.watch(own)  # already matched
    plan.finish(own)
    assert plan.has_stale_terms()
    assert plan.shrink().count(' OR ') == 0
    assert plan.shrink() is None


def test_untagged_uuids_never_match_the_tag():
    values = itertools.cycle([b'\x07' * 16, b'\x08' * 16])
    plan = GoalFilterPlan('client', tag=b'\x07' * 4, new_uuid=lambda: next(values))
    assert plan.untagged_uuid() == b'\x08' * 16


def test_goals_mode_announces_a_reserve_and_batches_bursts():
    plan = GoalFilterPlan('goals')
    assert plan.initial() != NEVER_MATCH
    updates = 0
    for _ in range(200):
        if plan.watch(plan.uuid_for_feedback()):
            plan.grow()
            updates += 1
    assert plan.live_goals == 200
    assert updates <= 8  # 200 goals in a burst: the reserve follows the number of live goals


def test_goals_mode_terms_are_short_for_generated_and_full_for_supplied_uuids():
    plan = GoalFilterPlan('goals', reserve=0)
    plan.initial()
    generated = plan.uuid_for_feedback()
    supplied = bytes(range(100, 116))
    assert plan.watch(generated) and plan.watch(supplied)
    expression = plan.grow()
    terms = {term.strip('()') for term in expression.split(' OR ')}
    assert terms == {uuid_prefix_term(generated[:TERM_BYTES]), uuid_prefix_term(supplied)}


def test_goals_mode_empty_set_is_never_match_not_empty():
    plan = GoalFilterPlan('goals', reserve=0)
    assert plan.initial() == NEVER_MATCH
    goal = plan.uuid_for_feedback()
    plan.watch(goal)
    plan.grow()
    plan.finish(goal)
    assert plan.shrink() == NEVER_MATCH


def test_generated_prefixes_are_unique():
    values = itertools.cycle([b'\x01' * 16, b'\x01' * 4 + b'\x02' * 12, b'\x03' * 16])
    plan = GoalFilterPlan('goals', reserve=0, new_uuid=lambda: next(values))
    first = plan.uuid_for_feedback()
    plan.watch(first)
    second = plan.uuid_for_feedback()
    assert second[:TERM_BYTES] != first[:TERM_BYTES]


def test_expressions_that_would_not_fit_discovery_are_refused():
    plan = GoalFilterPlan('client')
    plan.initial()
    with pytest.raises(ExpressionTooLong, match=str(MAX_EXPRESSION_BYTES)):
        for _ in range(1000):
            plan.watch(uuid.uuid4().bytes)
            plan.grow()


def test_reserve_is_dropped_before_refusing():
    plan = GoalFilterPlan('goals', reserve=DEFAULT_RESERVE)
    plan.initial()
    for _ in range(540):
        if plan.watch(plan.uuid_for_feedback()):
            plan.grow()
    assert len(plan.grow().encode()) <= MAX_EXPRESSION_BYTES


def test_revisions_tell_which_update_first_matched_a_goal():
    """A goal matched only by a later expression must wait for that update at the server.

    The initial expression is revision 0, and the n-th update after it revision n: the reader's
    update count, which the arrival gate proves."""
    plan = GoalFilterPlan('goals', reserve=2)
    plan.initial()
    assert plan.revision == 0
    reserved = [plan.uuid_for_feedback() for _ in range(2)]
    assert [plan.revision_matching(u) for u in reserved] == [0, 0]
    assert not any(plan.watch(u) for u in reserved)
    fresh = plan.uuid_for_feedback()  # the reserve is used up
    assert plan.revision_matching(fresh) is None and plan.watch(fresh)
    plan.grow()
    assert plan.revision == 1 and plan.revision_matching(fresh) == 1
    assert plan.revision_matching(reserved[0]) == 0  # a term keeps the revision that added it
    plan.finish(fresh)
    plan.shrink()
    assert plan.revision == 2 and plan.revision_matching(fresh) is None

    client = GoalFilterPlan('client')
    client.initial()
    assert client.revision_matching(client.tagged_uuid()) == 0
    foreign = uuid.uuid4().bytes
    assert client.watch(foreign)
    client.grow()
    assert client.revision_matching(foreign) == 1
