"""Work-cycle planner (cycle.py): the DP is the discrete optimum (brute force on small random
instances), the certificate's gap is >= 0, modes are used only where their transitions fit,
cycle YAML errors are one-line messages. Pure: no planner, synthetic fronts."""
import math

import numpy as np
import pytest
import yaml

from irb_description.power_modes import BRAKES, BUS_OFF, HOLD, MODES, load_power_modes
from irb_planning.cycle import (CycleError, MotionItem, StationItem, brute_force, load_cycle,
                                lower_bound, lower_hull, parse_cycle, solve, station_energy,
                                stations_and_motions)


@pytest.fixture(scope='module')
def pm():
    from irb_description.electrical import load_electrical
    return load_power_modes(electrical=load_electrical().axes(3))


def _front(rng, name, step, k):
    """A random front: k durations on the grid, energy = standby-like slope + a decreasing
    motion part + noise (not convex on purpose)."""
    n0 = int(rng.integers(4, 30))
    ns = np.sort(rng.choice(np.arange(n0, n0 + 40), size=k, replace=False))
    d = ns * step
    e = 274.0 * d + 400.0 / d + rng.uniform(0, 30, k)
    return MotionItem(name, tuple(float(x) for x in d), tuple(float(x) for x in e))


def _instance(rng, step):
    items = []
    for k in range(int(rng.integers(1, 3))):
        items.append(_front(rng, f'm{k}', step, int(rng.integers(1, 4))))
        if rng.random() < 0.8:
            modes = tuple(m for m in MODES if rng.random() < 0.7 or m == HOLD)
            items.append(StationItem(f's{k}', float(rng.choice([0.0, 0.3, 1.0, 2.5])),
                                     bool(rng.random() < 0.7), modes,
                                     float(rng.uniform(270, 300))))
    if not any(isinstance(it, StationItem) and it.wait for it in items):
        items.append(StationItem('idle', 0.0, True, MODES, 280.0))
    return items


def test_dp_equals_brute_force_and_gap_is_nonnegative(pm):
    rng = np.random.default_rng(29)
    step = 0.25
    checked = 0
    for _ in range(200):
        items = _instance(rng, step)
        fastest = sum(min(it.durations) for it in items if isinstance(it, MotionItem))
        fixed = sum(it.fixed_s for it in items if isinstance(it, StationItem))
        takt = fastest + fixed + float(rng.uniform(0.0, 6.0))
        n_steps = (takt - fixed) / step
        if n_steps > 40:
            continue
        bf = brute_force(items, takt, step, pm)
        if not math.isfinite(bf):
            with pytest.raises(CycleError):
                solve(items, takt, step, pm)
            continue
        sol = solve(items, takt, step, pm)
        assert sol.total_j == pytest.approx(bf, rel=1e-12, abs=1e-9)
        assert sol.gap_j >= -1e-9 and sol.lower_bound_j <= sol.total_j + 1e-9
        # the choices add up: energy and exactly the takt
        assert sum(c['energy_j'] for c in sol.choices) == pytest.approx(sol.total_j)
        assert sum(c['duration_s'] for c in sol.choices) == pytest.approx(takt, abs=1e-9)
        # every station's mode fits its duration and is allowed there
        for c, it in zip(sol.choices, items):
            if c['kind'] == 'station':
                assert c['mode'] in it.modes
                assert pm.feasible(c['mode'], c['duration_s'])
        # the relaxation's durations fill the takt too
        assert sum(sol.relaxed_durations) == pytest.approx(takt, abs=1e-6)
        checked += 1
    assert checked >= 30


def test_modes_need_their_transitions_to_fit(pm):
    hp = 285.0
    st = StationItem('s', 0.0, True, MODES, hp)
    d = 0.999 * pm.min_wait_s(BUS_OFF)
    mode, _ = station_energy(st, d, pm)
    assert mode != BUS_OFF and pm.feasible(mode, d)
    only_off = StationItem('s', 0.0, True, (BUS_OFF,), hp)
    assert station_energy(only_off, d, pm) == (None, math.inf)
    # a cycle whose only station allows bus_off but has too little time is refused
    items = [MotionItem('m', (1.0,), (300.0,)), StationItem('s', 0.0, True, (BUS_OFF,), hp)]
    with pytest.raises(CycleError, match='no choice'):
        solve(items, 1.0 + d, 0.05, pm)
    long = solve(items, 1.0 + 30.0, 0.05, pm)
    assert long.choices[1]['mode'] == BUS_OFF


def test_deeper_mode_chosen_when_it_pays(pm):
    hp = 285.0
    items = [MotionItem('m', (2.0, 3.0), (600.0, 850.0)),
             StationItem('s', 6.0, True, MODES, hp)]
    sol = solve(items, 30.0, 0.05, pm)
    st = sol.choices[1]
    best = min(pm.wait_energy_j(m, st['duration_s'], hp) for m in MODES
               if pm.feasible(m, st['duration_s']))
    assert st['energy_j'] == pytest.approx(best)
    assert st['mode'] in (BRAKES, BUS_OFF)
    hold_only = solve([items[0], StationItem('s', 6.0, True, (HOLD,), hp)], 30.0, 0.05, pm)
    assert hold_only.total_j > sol.total_j


def test_lower_hull_is_below_every_point():
    rng = np.random.default_rng(1)
    x = np.sort(rng.uniform(0, 10, 30))
    y = rng.normal(0, 1, 30)
    hx, hy = lower_hull(x, y)
    assert np.all(np.interp(x, hx, hy) <= y + 1e-12)
    slopes = np.diff(hy) / np.diff(hx)
    assert np.all(np.diff(slopes) >= -1e-12)


def test_lower_bound_infeasible_when_too_short(pm):
    items = [MotionItem('m', (2.0,), (500.0,)), StationItem('s', 1.0, True, MODES, 280.0)]
    assert lower_bound(items, 2.5, pm)[0] == math.inf
    with pytest.raises(CycleError, match='longer than the takt'):
        solve(items, 2.5, 0.05, pm)


def test_stations_merge_cyclically():
    spec = parse_cycle({'takt_s': 30, 'operations': [
        {'fixed': 'load', 'duration_s': 2.0, 'modes': ['hold', 'brakes']},
        {'motion': 'a', 'path': {'type': 'line', 'waypoints': [[0.6, 0, 0.3], [0.6, 0.1, 0.3]]}},
        {'motion': 'b', 'path': {'type': 'line', 'waypoints': [[0.6, 0.1, 0.3], [0.6, 0, 0.3]]}},
        {'fixed': 'unload', 'duration_s': 3.0}]})
    items = stations_and_motions(spec, {'a': 281.0, 'b': 282.0})
    kinds = [type(it).__name__ for it in items]
    assert kinds == ['Operation', 'Operation', 'StationItem']
    st = items[-1]
    assert st.members == ('unload', 'idle', 'load') and st.fixed_s == 5.0 and st.wait
    assert st.modes == (HOLD, BRAKES) and st.holding_power_w == 282.0


GOOD = {'takt_s': 20.0, 'operations': [
    {'motion': 'a', 'path': {'type': 'line', 'waypoints': [[0.6, 0, 0.3], [0.6, 0.1, 0.3]]}},
    {'wait': 'w'}]}


@pytest.mark.parametrize('mutate, match', [
    (lambda d: d.pop('takt_s'), 'missing `takt_s`'),
    (lambda d: d.update(takt_s=-3), 'must be > 0'),
    (lambda d: d.update(takt_s='soon'), 'finite number'),
    (lambda d: d.update(tact_s=3), 'unknown keys'),
    (lambda d: d.update(operations=[]), 'non-empty list'),
    (lambda d: d['operations'].append({'fixed': 'x'}), 'missing `duration_s`'),
    (lambda d: d['operations'].append({'wait': 'v', 'modes': ['nap']}), '`modes`'),
    (lambda d: d['operations'].append({'wait': 'w'}), 'unique'),
    (lambda d: d['operations'].append({'motion': 'm', 'wait': 'v'}), 'exactly one'),
    (lambda d: d['operations'].append({'motion': 'm'}), 'needs one of `path`'),
    (lambda d: d['operations'].append({'motion': 'm', 'path': {'type': 'blob'}}),
     'unknown path type'),
    (lambda d: d['operations'].append(
        {'motion': 'm', 'path': {'type': 'line', 'waypoints': [[0, 0, 0], [1, 0, 0]],
                                 'process': {'tcp_speed_max': -1}}}), 'finite number >= 0'),
    (lambda d: d['operations'].append({'fixed': 'f', 'duration_s': 1, 'speed': 2}),
     'takes'),
    (lambda d: d.update(energy_model='mechanical'), 'electrical_'),
    (lambda d: d.update(limit_scaling=1.5), 'limit_scaling'),
])
def test_cycle_yaml_errors_are_one_line(tmp_path, mutate, match):
    import copy
    d = copy.deepcopy(GOOD)
    mutate(d)
    p = tmp_path / 'c.yaml'
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(CycleError, match=match) as err:
        load_cycle(p)
    assert '\n' not in str(err.value)


def test_limit_scaling_reaches_every_plan_request_and_the_cache_key():
    from irb_planning.cycle import _cache_key, parse_cycle, plan_request
    from types import SimpleNamespace
    import copy
    d = copy.deepcopy(GOOD)
    full = parse_cycle(copy.deepcopy(d))
    d['limit_scaling'] = 0.9
    spec = parse_cycle(d)
    assert spec.limit_scaling == 0.9 and full.limit_scaling == 0.0
    op = spec.motions[0]
    assert plan_request(op, 1.0, 'energy', 'electrical_shared', 30, '',
                        spec.limit_scaling).limit_scaling == 0.9
    from irb_planning.planner import PlannerSettings
    planner = SimpleNamespace(settings=PlannerSettings(grid_size=30), electrical='e')
    # plans at other limits are other plans; without the key the old caches stay valid
    assert _cache_key(planner, op, spec, 'electrical_shared') != _cache_key(
        planner, op, full, 'electrical_shared')
    # fronts planned without the smoothness limits (issue 28) are not reused with them
    loose = SimpleNamespace(settings=PlannerSettings(grid_size=30, jerk_limits=False),
                            electrical='e')
    assert _cache_key(planner, op, full, 'electrical_shared') != _cache_key(
        loose, op, full, 'electrical_shared')


def test_unreadable_cycle_files(tmp_path):
    with pytest.raises(CycleError, match='cannot read'):
        load_cycle(tmp_path / 'none.yaml')
    p = tmp_path / 'bad.yaml'
    p.write_text('takt_s: [1,\n')
    with pytest.raises(CycleError, match='not YAML') as err:
        load_cycle(p)
    assert '\n' not in str(err.value)
    p.write_bytes(b'\xff\xfe takt')
    with pytest.raises(CycleError, match='UTF-8'):
        load_cycle(p)


def test_the_installed_gluing_cycle_parses():
    from irb_planning.cycle import check_continuity
    from pathlib import Path
    f = Path(__file__).resolve().parent.parent / 'config' / 'cycle_gluing.yaml'
    spec = load_cycle(f)
    assert [op.kind for op in spec.operations] == ['motion', 'motion', 'fixed', 'wait',
                                                   'motion']
    assert spec.motions[0].process['tcp_speed_min'] == 0.09
    check_continuity(spec)


def test_cli_end_to_end_with_the_planner(tmp_path, capsys):
    """A small circle, a fixed step and a wait through the real planner (grid 30, the
    time-optimal plan and one front point): the JSON adds up, the hold power is the
    electrical model at the pose's gravity torque, the plan beats baseline A, and a second
    run at another takt plans nothing."""
    import json
    from irb_description.electrical import load_electrical
    from irb_description.model import RobotModel
    from irb_planning.cycle_cli import main
    cyc = {'takt_s': 12.0, 'grid_size': 30,
           'operations': [{'motion': 'loop', 'path': {'type': 'circle', 'center': [0.6, 0, 0.3],
                                                      'radius': 0.05}, 'durations_s': [1.0]},
                          {'fixed': 'load', 'duration_s': 4.0},
                          {'wait': 'idle'}]}
    f = tmp_path / 'c.yaml'
    f.write_text(yaml.safe_dump(cyc))
    out = tmp_path / 'out'
    assert main(['--cycle', str(f), '--out', str(out), '--no-plots']) == 0
    first = capsys.readouterr().out
    assert ': time-optimal' in first and 'certificate' in first
    res = json.loads((out / 'cycle_plan.json').read_text())
    ops = res['operations']
    assert sum(o['energy_j'] for o in ops) == pytest.approx(res['energy_j'])
    assert sum(o['duration_s'] for o in ops) == pytest.approx(12.0)
    assert res['gap_j'] >= -1e-9 and res['energy_j'] <= res['baseline_a_j']
    st = [o for o in ops if o['kind'] == 'station'][0]
    assert st['members'] == ['load', 'idle']
    m = RobotModel.load()
    q_end = json.loads((out / 'motions' / 'loop.plan.json').read_text())['trajectory']['q'][-1]
    e = load_electrical().axes(3)
    hp = float(e.power(m.gravity(np.array(q_end)), np.zeros(3)))
    assert st['holding_power_w'] == pytest.approx(hp, rel=1e-9)
    assert (out / 'motions' / 'loop.path.yaml').is_file()
    assert main(['--cycle', str(f), '--out', str(out), '--no-plots', '--takt', '15']) == 0
    second = capsys.readouterr().out
    assert ': time-optimal' not in second and ' -> ' not in second   # all from the cache
    assert json.loads((out / 'cycle_plan.json').read_text())['takt_s'] == 15.0
    assert main(['--cycle', str(f), '--out', str(out), '--takt', '3']) == 1
    assert 'longer than the takt' in capsys.readouterr().err


def test_unreachable_and_broken_chains_are_refused_before_planning():
    from irb_description.model import RobotModel
    from irb_planning.cycle import check_continuity, check_reachable
    far = parse_cycle({'takt_s': 20, 'operations': [
        {'motion': 'out', 'path': {'type': 'line', 'waypoints': [[0.6, 0, 0.3], [2.5, 0, 0.3]]}},
        {'motion': 'in', 'path': {'type': 'line',
                                  'waypoints': [[2.5, 0, 0.3], [0.6, 0, 0.3]]}}]})
    with pytest.raises(CycleError, match='motion out: path unreachable') as err:
        check_reachable(far, RobotModel.load())
    assert '\n' not in str(err.value)
    gap = parse_cycle({'takt_s': 20, 'operations': [
        {'motion': 'a', 'path': {'type': 'line', 'waypoints': [[0.6, 0, 0.3], [0.6, 0.1, 0.3]]}},
        {'motion': 'b', 'path': {'type': 'line',
                                 'waypoints': [[0.6, 0.1, 0.31], [0.6, 0, 0.3]]}}]})
    with pytest.raises(CycleError, match='motion b starts at'):
        check_continuity(gap)


def test_a_plan_pdplus_gate_would_refuse_is_not_kept(tmp_path, monkeypatch, capsys):
    """cycle.gate_check applies pdplus's plan-gate rules (irb_description.trajectory_rules)
    to every plan: with a gate taking at most 12 rad/s^2 the time-optimal move to the part
    exchange pose (12.7 rad/s^2 near its end, set by the jerk limits, grid 30) is refused
    after the re-plans at tighter limits, in one line naming the rule. (That the kept plans
    pass pdplus's own gate: irb_bringup test_cross_package_plans.)"""
    from irb_planning import cycle
    from irb_planning.cycle_cli import main
    line = {'type': 'line', 'waypoints': [[0.7, -0.09950371902099892, 0.3099503719020999],
                                          [0.45, -0.45, 0.45]]}
    cyc = {'takt_s': 4.0, 'grid_size': 30,
           'operations': [{'motion': 'to_exchange', 'path': line, 'durations_s': [0.7]},
                          {'wait': 'idle'},
                          {'motion': 'back', 'path': {'type': 'line', 'waypoints':
                                                      line['waypoints'][::-1]},
                           'durations_s': [0.7]}]}
    f = tmp_path / 'c.yaml'
    f.write_text(yaml.safe_dump(cyc))
    monkeypatch.setattr(cycle, 'GATE_MAX_ACCELERATION_RAD_S2', 12.0)
    assert main(['--cycle', str(f), '--out', str(tmp_path / 'out'), '--no-plots',
                 '--cache', str(tmp_path / 'fronts')]) == 1
    err = capsys.readouterr().err.strip()
    assert "pdplus's plan gate refuses it" in err and 'limiting it to 12' in err
    assert '\n' not in err
