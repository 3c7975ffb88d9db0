"""Bystanders in the load harness: a plain client next to the phase's clients, accounted apart.

One server, two phases: the bystander next to 2 ``client``-mode clients, then alone
(``run_phase(config, clients=0)``). Bytes are estimated from message counts (no network
namespaces): this checks the bookkeeping, and :func:`harness.load.bystander_figures`, that
``benchmarks/bystander.py`` relies on, not figures.
"""

from __future__ import annotations

import pytest

from harness import load

NEIGHBOURS, GOALS, ORDER = 2, 1, 10


@pytest.fixture(scope='module')
def phases():
    """The bystander next to NEIGHBOURS client-mode clients, then alone."""
    spec = load.LoadSpec(clients=NEIGHBOURS, goals=GOALS, order=ORDER, rate_hz=50.0,
                         network='count', settle_s=1.0, drain_timeout=20, bystanders=1)
    run = load.LoadRun(spec, progress=lambda line: None)
    try:
        return [run.run_phase('client'), run.run_phase('rclpy', clients=0)]
    finally:
        run.close()


def test_the_bystander_takes_every_goals_feedback(phases):
    for phase, neighbours in zip(phases, (NEIGHBOURS, 0)):
        assert phase['n_clients'] == len(phase['clients']) == neighbours
        assert phase['accepted'] == (neighbours + 1) * GOALS
        assert phase['published'] == (neighbours + 1) * GOALS * ORDER
        [report] = phase['bystanders']
        assert report['active'] is False  # plain rclpy
        assert report['own'] == GOALS * ORDER
        assert report['own'] + report['foreign'] == phase['published']
        assert phase['bystander_summary']['latency_samples'] == GOALS * ORDER


def test_the_neighbours_figures_leave_the_bystander_out(phases):
    with_neighbours, alone = phases
    assert with_neighbours['summary']['foreign_per_client'] == 0
    assert with_neighbours['summary']['own_per_client'] == GOALS * ORDER
    assert with_neighbours['summary']['updates_per_goal'] == 0
    for key in ('own_per_client', 'bytes_per_client', 'own_feedback_bytes_per_client'):
        assert alone['summary'][key] is None
    assert alone['summary']['updates_per_goal'] is None


def test_bystander_figures_per_sample(phases):
    rows = [load.bystander_figures(p) for p in phases]
    assert [r['neighbours'] for r in rows] == [NEIGHBOURS, 0]
    assert [r['lost'] for r in rows] == [0, 0]
    assert rows[0]['neighbour_config'] == 'client' and rows[1]['neighbour_config'] is None
    assert rows[0]['rx_bytes_per_sample'] is None  # no network namespaces here
