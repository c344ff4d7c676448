"""benchmarks/bench_published.py's core (cycle_shares, ours_vs_published) on given trajectories,
against an independent computation; no planner run (fast)."""
import dataclasses
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from irb_description.electrical import load_electrical

BENCH = Path(__file__).resolve().parents[1] / 'benchmarks' / 'bench_published.py'


@pytest.fixture(scope='module')
def bench():
    spec = importlib.util.spec_from_file_location('bench_published', BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _readme_power(m, tau, qd, mode):
    """Grid power [W] per sample, vectorised straight from the README table (no model code)."""
    pj = tau * qd
    mot = pj >= 0
    em, eg = m.gear_efficiency_motoring, m.gear_efficiency_generating
    pg = np.where(mot, pj / em, pj * eg)
    i_q = tau / m.gear_ratio * np.where(mot, 1 / em, eg) / m.torque_constant
    pe = pg + m.resistance * i_q ** 2
    pax = np.where(pe > 0, pe / m.drive_efficiency, pe * m.drive_efficiency) + m.drive_idle_power
    s = pax.sum(axis=1)
    bus = {'none': np.clip(pax, 0, None).sum(axis=1), 'shared': np.clip(s, 0, None),
           'regenerative': np.where(s > 0, s, m.regenerative_efficiency * s)}[mode]
    copper = (m.resistance * i_q ** 2).sum(axis=1)
    return m.standby_power + bus, copper


def _played_like(seed=11):
    """A rest-to-rest swing of 3 axes on irregular stamps (like a played plan, with noise)."""
    rng = np.random.default_rng(seed)
    t = np.sort(np.r_[0.0, rng.uniform(0, 2.5, 900), 2.5])
    s = t / 2.5
    qd = np.stack([np.sin(np.pi * s) ** 2 * a for a in (1.5, -1.0, 2.0)], axis=1)
    qdd = np.gradient(qd, t, axis=0)
    tau = np.array([40.0, 300.0, 90.0]) + qdd * np.array([8.0, 12.0, 3.0]) \
        + 20 * np.tanh(qd / 0.05) + rng.normal(0, 1.0, qd.shape)
    return t, tau, qd


@pytest.mark.parametrize('mode', ['none', 'shared', 'regenerative'])
def test_cycle_shares_against_readme_formulas(bench, mode):
    m = load_electrical().axes(3)
    t, tau, qd = _played_like()
    got = bench.cycle_shares(m, t, tau, qd)[mode]
    p, pcu = _readme_power(m, tau, qd, mode)
    dt = np.diff(t)
    total = float(np.sum(0.5 * (p[1:] + p[:-1]) * dt))
    copper = float(np.sum(0.5 * (pcu[1:] + pcu[:-1]) * dt))
    assert got['energy_j']['total'] == pytest.approx(total, rel=1e-10)
    s = got['shares_pct']
    assert s['standby'] == pytest.approx(100 * m.standby_power * 2.5 / total, rel=1e-10)
    assert s['copper'] == pytest.approx(100 * copper / total, rel=1e-10)
    assert s['drive_idle'] == pytest.approx(100 * m.drive_idle_power.sum() * 2.5 / total)
    assert s['parts_sum'] == pytest.approx(100.0, abs=1e-9)
    assert 0 < s['standby'] < 100 and s['motion'] == pytest.approx(100 - s['standby'])


def test_holding_still_is_standby_idle_and_holding_copper(bench):
    m = load_electrical().axes(3)
    t = np.linspace(0.0, 4.0, 5)
    tau = np.tile([0.0, 250.0, 60.0], (5, 1))
    got = bench.cycle_shares(m, t, tau, np.zeros((5, 3)), modes=('shared',))['shared']
    i2 = (250.0 / 120 / 0.85 / 0.95) ** 2, (60.0 / 100 / 0.85 / 0.80) ** 2
    hold = (1.6 * i2[0] + 2.5 * i2[1]) / 0.95
    p = 250.0 + 24.0 + hold
    assert got['energy_j']['total'] == pytest.approx(4.0 * p, rel=1e-12)
    assert got['shares_pct']['standby'] == pytest.approx(100 * 250.0 / p, rel=1e-12)
    assert got['shares_pct']['work'] == 0.0


def test_ours_vs_published_takes_the_range_of_the_matching_share(bench):
    rows = [dict(duration_s=10.0, plan='trapezoid',
                 by_mode={'shared': {'shares_pct': {'standby': 87.0, 'copper': 2.0}},
                          'none': {'shares_pct': {'standby': 86.0, 'copper': 2.5}}}),
            dict(duration_s=1.0, plan='optimum_electrical_shared',
                 by_mode={'shared': {'shares_pct': {'standby': 50.0, 'copper': 4.0}}})]
    pub = [dict(figure='x', compare_with='standby'), dict(figure='y', compare_with=None)]
    out = bench.ours_vs_published(rows, pub)
    assert out[0]['ours_range'] == [50.0, 87.0] and len(out[0]['ours']) == 3
    assert out[1]['ours_range'] is None and out[1]['figure'] == 'y'


def test_placement_spread_reads_reachable_points_only(bench, tmp_path):
    f = tmp_path / 'energy.json'
    assert bench.placement_spread(f) is None
    f.write_text('{"placement": [{"model": "mechanical", "map_j": [[1.0, 9.0]]}, '
                 '{"model": "electrical_shared", "refused": 2, '
                 '"map_j": [[[100.0, null], [80.0, null]], [[90.0, 95.0], [null, 85.0]]]}]}')
    got = bench.placement_spread(f)
    assert got['value'] == pytest.approx(100 * (100.0 - 80.0) / 100.0)
    assert got['points'] == 5 and got['min_j'] == 80.0 and got['refused'] == 2
    out = bench.ours_vs_published([], [dict(compare_with='placement_spread_pct')],
                                  {'placement_spread_pct': got})
    assert out[0]['ours_range'] == [got['value'], got['value']]


def test_standby_share_at_is_exact_against_a_recomputed_model(bench):
    """Re-evaluating the standby share at another P_sb equals recomputing the flows with a model
    whose only change is P_sb (the standby energy of a fixed duration is additive)."""
    m = load_electrical().axes(3)
    t, tau, qd = _played_like(seed=5)
    e = bench.cycle_shares(m, t, tau, qd, modes=('shared',))['shared']['energy_j']
    for p in (150.0, 400.0):
        m2 = dataclasses.replace(m, standby_power=p)
        ref = bench.cycle_shares(m2, t, tau, qd, modes=('shared',))['shared']['shares_pct']
        assert bench.standby_share_at(e, m.standby_power, p) == pytest.approx(
            ref['standby'], rel=1e-12)
    assert bench.standby_share_at(e, m.standby_power, m.standby_power) == pytest.approx(
        100 * e['standby'] / e['total'], rel=1e-12)


def test_standby_sweep_covers_every_row_and_mode(bench):
    rows = [dict(duration_s=10.0, plan='trapezoid',
                 by_mode={'shared': {'energy_j': {'standby': 2500.0, 'total': 2866.6}},
                          'none': {'energy_j': {'standby': 2500.0, 'total': 2870.0}}}),
            dict(duration_s=1.0, plan='optimum_electrical_shared',
                 by_mode={'shared': {'energy_j': {'standby': 250.0, 'total': 450.0}}})]
    out = bench.standby_sweep(rows, 250.0, powers=(250.0, 400.0))
    assert [(o['plan'], o['mode']) for o in out] == [
        ('trapezoid', 'shared'), ('trapezoid', 'none'), ('optimum_electrical_shared', 'shared')]
    assert out[0]['standby_pct']['250'] == pytest.approx(100 * 2500.0 / 2866.6)
    assert out[2]['standby_pct']['400'] == pytest.approx(100 * 400.0 / 600.0)


def test_published_entries_are_complete(bench):
    """Every published figure names its source, address, where it was read and what it is
    compared with; the not-verified list says why."""
    keys = {'quantity', 'figure', 'authors', 'title', 'venue', 'year', 'url', 'robot', 'cycle',
            'where', 'read', 'compare_with'}
    for p in bench.PUBLISHED:
        assert keys <= set(p), p.get('quantity')
        assert p['figure'] and p['url'] and p['read'] and p['where']
    assert all(n['source'] and n['why'] for n in bench.NOT_VERIFIED)
