"""The load demo's accounting: own and foreign feedback add up to what the server published.

A small load (N = 3 client processes, 2 goals each) against the demo's own server, through the
same harness as ``make demo`` and ``make bench``. Bytes are taken from message counts here (no
network namespaces): this test checks behaviour and bookkeeping; the figures come from the demo and
the benchmark.
"""

from __future__ import annotations

import pytest

from harness import load

CLIENTS, GOALS, ORDER = 3, 2, 20


@pytest.fixture(scope='module')
def result():
    """One run, plain rclpy then cft client mode; shared by the tests of this module."""
    # settle_s: no phase here changes its filter after its goals (plain rclpy, client mode), so
    # the grace of goals mode's last update (load.SETTLE_S) is not waited for.
    spec = load.LoadSpec(clients=CLIENTS, goals=GOALS, order=ORDER, network='count',
                         drain_timeout=20, settle_s=1.0)
    return load.run_load(spec, ['rclpy', 'client'], progress=lambda line: None)


def phase(result, config):
    return next(p for p in result['phases'] if p['config'] == config)


def test_the_server_published_every_goals_feedback(result):
    for p in result['phases']:
        assert p['accepted'] == CLIENTS * GOALS
        assert p['published'] == CLIENTS * GOALS * ORDER
        assert p['guard'].startswith('active'), p['guard']


def test_plain_clients_take_all_feedback_own_and_foreign(result):
    p = phase(result, 'rclpy')
    for client in p['clients']:
        assert client['own'] + client['foreign'] == p['published'], client
        assert client['own'] == GOALS * ORDER
        assert client['callbacks'] == client['own']
        assert client['misrouted'] == 0
        assert client['updates'] == 0
    summary = p['summary']
    assert summary['foreign_per_client'] == p['published'] * (CLIENTS - 1) / CLIENTS
    assert summary['latency_samples'] == CLIENTS * GOALS * ORDER


def test_client_mode_takes_only_its_own_feedback(result):
    p = phase(result, 'client')
    for client in p['clients']:
        assert client['active'], client['reason']
        assert client['foreign'] == 0, client
        assert client['own'] == GOALS * ORDER
        assert client['callbacks'] == client['own']
        assert client['misrouted'] == 0
        # The library's own counters agree with the harness's.
        assert client['lib_taken'] == client['own']
        assert client['lib_dropped'] == 0
        assert client['updates'] == 0
    summary = p['summary']
    assert summary['foreign_per_client'] == 0
    assert summary['ratio_to_plain']['foreign'] == 0


def test_estimated_bytes_follow_the_counts(result):
    size = load.feedback_size(0)
    assert result['bytes_method'] == 'estimated'
    for p in result['phases']:
        for client in p['clients']:
            assert client['est_bytes'] == (client['own'] + client['foreign']) * size
    plain, filtered = phase(result, 'rclpy')['summary'], phase(result, 'client')['summary']
    assert filtered['ratio_to_plain']['bytes'] == pytest.approx(1 / CLIENTS)
    assert filtered['bytes_to_own_feedback'] == pytest.approx(1.0)
    assert plain['bytes_to_own_feedback'] == pytest.approx(CLIENTS)


def test_rounds_alternate_the_configurations():
    """Plain first, then the order reversed in every even round (``make demo``'s unguarded
    server, ``benchmarks.server_cost --rounds``)."""
    assert load.round_order(['rclpy', 'client'], 3) == [
        (1, 'rclpy'), (1, 'client'), (2, 'client'), (2, 'rclpy'), (3, 'rclpy'), (3, 'client')]


def test_pooled_phases_put_the_servers_counters_together():
    """A configuration's phases against one server, as one: CPU per message and rate over the
    phases' counters added up (not the mean of their ratios); the clients' figures averaged."""
    def ran(published: int, goals_s: float, cpu_s: float, own: float) -> dict:
        return {'config': 'client', 'published_at_goals': published, 'goals_s': goals_s,
                'server_cpu_goals_s': cpu_s, 'intervals': published, 'interval_s': goals_s,
                'summary': {'own_per_client': own, 'latency_p50_ms': None, 'bytes_method': 'x',
                            'server_cpu_ms_per_msg': 1000 * cpu_s / published}}

    pooled = load.pool_phases([ran(1000, 2.0, 0.1, 10), ran(3000, 2.0, 0.5, 20)])
    summary = pooled['summary']
    assert pooled['pooled_phases'] == 2 and pooled['published_at_goals'] == 4000
    assert summary['server_cpu_ms_per_msg'] == pytest.approx(0.15)
    assert summary['server_msgs_per_s'] == pytest.approx(1000)
    assert summary['achieved_rate_hz'] == pytest.approx(1000)
    assert summary['own_per_client'] == 15
    assert summary['latency_p50_ms'] is None and summary['bytes_method'] == 'x'
