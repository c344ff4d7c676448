"""cycle_exec (issue 29 item 4): the executed cycle's energy against its plan, on synthetic
series whose energies are known by construction (no ROS, no simulator)."""
import json

import numpy as np
import pytest
from irb_bringup.cycle_exec import (CycleRunError, Models, StepEvents, compare_cycle,
                                    first_gap, load_plan, plan_predictions, sag_at_release,
                                    schedule, station_prediction, summarise, window_energy)
from irb_description.electrical import load_electrical
from irb_description.power_modes import load_power_modes

T = 0.004032


def test_window_energy_counts_whole_and_partial_samples():
    t = np.arange(0, 1000) * T
    p = np.where(t < 2.0, 100.0, 300.0)
    # [0, 2) at 100 W (the sample holding across 2.0 s counts with its part before 2.0)
    k = int(np.ceil(2.0 / T))           # first sample at 300 W
    exact = 100.0 * k * T - 100.0 * (k * T - 2.0) if k * T > 2.0 else 200.0
    assert window_energy(t, p, 0.0, 2.0, T) == pytest.approx(exact, rel=1e-9)
    # a window inside one sample: its power times the window's length
    assert window_energy(t, p, 3.0 + 0.001, 3.0 + 0.002, T) == pytest.approx(0.3, rel=1e-9)
    # the sum of adjacent windows is the window over both
    a, b, c = 0.37, 1.91, 3.5
    assert (window_energy(t, p, a, b, T) + window_energy(t, p, b, c, T)
            == pytest.approx(window_energy(t, p, a, c, T), rel=1e-12))


def test_a_gap_or_a_window_not_covered_is_an_error_never_less_energy():
    t = np.arange(0, 1000) * T
    p = np.full(t.size, 200.0)
    holed = np.delete(np.arange(t.size), range(400, 403))
    with pytest.raises(CycleRunError, match='gap'):
        window_energy(t[holed], p[holed], 0.5, 3.0, T)
    assert first_gap(t[holed], T) == pytest.approx((399 * T, 4 * T))
    assert first_gap(t, T) is None
    with pytest.raises(CycleRunError, match='does not cover'):
        window_energy(t, p, 1.0, t[-1] + 1.0, T)


def _models():
    nom = load_electrical().axes(3)
    plant = nom.scaled(standby_power=1.1) if hasattr(nom, 'scaled') else nom
    return Models(nom, plant, load_power_modes(electrical=nom),
                  load_power_modes(electrical=plant), lambda q: np.array([0.0, 40.0, 10.0]))


def _plan(tmp_path, models):
    """A one-motion cycle (1 s there, 1 s back folded into one motion) with a brakes
    station, its energies computed on the planner's models as the cycle planner does."""
    t = np.linspace(0.0, 1.0, 51)
    s = 0.5 - 0.5 * np.cos(np.pi * t)
    q = np.column_stack([0.2 * s, 0.5 + 0.1 * s, 0.3 + 0.0 * s])
    qd = np.gradient(q, t, axis=0)
    qdd = np.gradient(qd, t, axis=0)
    tau = np.column_stack([5 * qdd[:, 0], 40 + 8 * qdd[:, 1], 10 + 0 * t])
    mot = tmp_path / 'motions'
    mot.mkdir()
    (mot / 'm.path.yaml').write_text('{type: line, waypoints: [[0.6, 0, 0.3], [0.6, 0.1, 0.3]]}')
    e_m = models.planner_electrical.energy(np.linspace(0, 1, 1001), *[
        np.column_stack([np.interp(np.linspace(0, 1, 1001), t, c) for c in x.T])
        for x in (tau, qd)], 'shared')
    (mot / 'm.plan.json').write_text(json.dumps({'path_file': 'm.path.yaml', 'trajectory': {
        't': t.tolist(), 'q': q.tolist(), 'qd': qd.tolist(), 'qdd': qdd.tolist(),
        'tau': tau.tolist()}}))
    hp = models.hold_power(q[-1], plant=False)
    e_s = models.planner_modes.wait_energy_j('brakes', 3.0, hp)
    (tmp_path / 'cycle_plan.json').write_text(json.dumps({
        'takt_s': 4.0, 'energy_j': e_m + e_s, 'energy_model': 'electrical_shared',
        'operations': [
            {'kind': 'station', 'name': 'st', 'mode': 'brakes', 'duration_s': 3.0,
             'energy_j': e_s, 'holding_power_w': hp},
            {'kind': 'motion', 'name': 'm', 'duration_s': 1.0, 'energy_j': e_m}]}))
    return load_plan(tmp_path)


def test_plan_schedule_and_an_execution_as_planned_measures_the_plan(tmp_path):
    models = _models()
    plan = _plan(tmp_path, models)
    assert [s.kind for s in plan.steps] == ['motion', 'station']     # starts with a motion
    acts = schedule(plan, models.plant_modes)
    t_out = models.plant_modes.transition('brakes', 'hold').duration_s
    assert [(a.kind, a.t_s, a.mode) for a in acts] == [
        ('enable', 0.0, ''), ('send', 0.0, ''), ('mode', 1.0, 'brakes'),
        ('mode', 4.0 - t_out, 'hold'), ('released', 4.0 - t_out, ''), ('wait', 4.0, '')]
    preds = plan_predictions(plan, models)
    # synthetic "measurement": the plant model's power, step by step, at the planned timing
    m = plan.steps[0]
    hp = models.hold_power(m.q_end)
    tt = np.arange(0, int(4.0 / T) + 10) * T
    p = np.empty(tt.size)
    mot = tt < 1.0
    p[mot] = preds[0]['plant_model_j'] / 1.0
    pm = models.plant_modes
    tin, tout = pm.transition('hold', 'brakes', hp), pm.transition('brakes', 'hold', hp)
    for lo, hi, w in ((1.0, 1.0 + tin.duration_s, tin.energy_j / tin.duration_s),
                      (1.0 + tin.duration_s, 4.0 - tout.duration_s, pm.power_w('brakes')),
                      (4.0 - tout.duration_s, 4.0, tout.energy_j / tout.duration_s),
                      (4.0, 99.0, hp)):
        p[(tt >= lo) & (tt < hi)] = w
    ev = [StepEvents(0.0, 1.0, t_path=0.0),
          StepEvents(1.0, 4.0, t_mode=1.0, t_hold=4.0 - tout.duration_s)]
    c = compare_cycle(plan, models, preds, ev, (0.0, 4.0), tt, p, T)
    # boundaries fall inside samples: the piecewise power is exact to one sample per edge
    assert c['measured_j'] == pytest.approx(preds[0]['plant_model_j']
                                            + preds[1]['plant_model_j'], abs=4 * 300 * T)
    assert abs(c['terms_j']['timing']) < 1e-6
    assert c['terms_j']['electrical_parameters'] == pytest.approx(
        sum(x['plant_model_j'] for x in preds) - plan.energy_j)
    assert abs(c['measured_vs_predicted_percent']) < 0.5
    # a station half a second shorter in its mode is named a timing term, of the expected size
    ev2 = [StepEvents(0.0, 1.5, t_path=0.1), StepEvents(1.5, 4.0, t_mode=1.5,
                                                        t_hold=4.0 - tout.duration_s)]
    c2 = compare_cycle(plan, models, preds, ev2, (0.0, 4.0), tt, p, T)
    s2 = c2['steps'][1]
    assert s2['terms_j']['timing'] == pytest.approx(-0.5 * pm.power_w('brakes'), rel=1e-9)
    summ = summarise([c, c2], plan, [[1e-5, 2e-5, 0.0]], [])
    assert summ['cycles'] == 2 and summ['stops'] == 0
    assert summ['sag_at_release_mrad']['max'] == pytest.approx(0.02)


def test_station_prediction_is_the_wait_energy_at_the_planned_requests():
    pm = _models().plant_modes
    for mode in ('hold', 'brakes', 'bus_off'):
        d = 12.0
        tout = pm.transition(mode, 'hold').duration_s
        e = station_prediction(pm, mode, 290.0, 5.0, 5.0 + d, 5.0, 5.0 + d - tout)
        assert e == pytest.approx(pm.wait_energy_j(mode, d, 290.0), rel=1e-12)


def test_sag_is_the_largest_departure_from_the_braked_pose():
    t = np.arange(0, 200) * T
    q = np.tile([0.1, 0.5, 0.3], (t.size, 1))
    q[120:125, 1] -= 3e-5                 # a dip after the release at t[100]
    s = sag_at_release(t, q, t[100], t[199])
    assert s == pytest.approx([0.0, 3e-5, 0.0])
    with pytest.raises(CycleRunError):
        sag_at_release(t, q, t[199] + 1.0, t[199] + 2.0)


def test_a_plan_that_is_not_one_is_one_line(tmp_path):
    with pytest.raises(CycleRunError, match='cannot read'):
        load_plan(tmp_path / 'nope')
    (tmp_path / 'cycle_plan.json').write_text('{"a": 1}')
    with pytest.raises(CycleRunError, match='not a cycle plan'):
        load_plan(tmp_path)
