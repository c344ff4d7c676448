"""Plans that any trajectory controller plays smoothly (issue 28).

Oracle: ``played.py``, the message played by quintic interpolation on a 10 kHz clock with the
stamps as the message carries them, TCP rates and torques from pinocchio (nothing shared with
the planner's check). Consistency by ``irb_description.trajectory_rules`` at the full
tolerances a plan gate uses (the planner keeps half of them)."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest
from irb_description.path import path_spec, rectangle_path
from irb_description.trajectory_rules import MIN_POINT_SPACING_S, worst_inconsistency

from irb_planning.request import ERROR_INFEASIBLE_DURATION, PlanError, PlanRequest

_spec = importlib.util.spec_from_file_location('played', Path(__file__).with_name('played.py'))
played = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(played)
message_stamps, play = played.message_stamps, played.play

RECT = path_spec(rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025))
WAY = [[0.55, -0.25, 0.25], [0.8, -0.2, 0.3], [0.85, 0.05, 0.4], [0.7, 0.2, 0.35],
       [0.55, 0.15, 0.3]]
LINE_UP = np.array([[0.7, 0.1, 0.0], [0.7, 0.1, 0.6]])


def rect(**kw):
    return PlanRequest(path_type='polyline', waypoints=np.asarray(RECT['waypoints'], float),
                       blend_radii=np.asarray(RECT['blend_radii'], float), closed=True, **kw)


def requests(rng):
    """Four requests over the path types with random grids, durations and bands: the
    rectangle with its gluing band at a random |a| bound (the point pairs of issue 28 were
    at its blend ends), a blended polyline and a spline at a random duration, the circle
    at rest."""
    g = lambda: int(rng.integers(30, 81))                      # noqa: E731
    amax = float(rng.uniform(1.0, 3.0))
    return [
        rect(duration=float(rng.uniform(7.0, 9.0)), grid_size=g(), tcp_speed_min=0.09,
             tcp_speed_max=0.15, tcp_ramp_length=0.04, tcp_accel_max=amax),
        PlanRequest(path_type='polyline', waypoints=np.asarray(WAY, float),
                    blend_radii=np.array([0.03, 0.05, 0.02]), grid_size=g(),
                    duration=float(rng.uniform(2.5, 4.0))),
        PlanRequest(path_type='spline', waypoints=np.asarray(WAY, float), grid_size=g(),
                    duration=float(rng.uniform(2.5, 4.0)), boundary='periodic',
                    closed=True),
        PlanRequest(grid_size=g(), duration=float(rng.uniform(2.0, 4.0))),
    ]


def test_every_success_as_played_at_10_khz_keeps_its_limits_and_reports_its_peaks(
        planner, model, rng):
    lim = model.limits
    for req in requests(rng):
        r = planner.plan(req)
        tr, ver = r.trajectory, r.verification
        what = f'{req.path_type} grid {req.grid_size}'
        ts = message_stamps(tr['t'])
        assert np.diff(ts).min() >= MIN_POINT_SPACING_S - 1e-9, what
        # what the planner calls a success, a gate with the full tolerances accepts
        assert worst_inconsistency(ts, tr['q'], tr['qd'], tr['qdd']) is None, what
        p = play(model, tr['t'], tr['q'], tr['qd'], tr['qdd'], stride=2)
        peak_v, peak_tau = np.abs(p.qd).max(axis=0), np.abs(p.tau).max(axis=0)
        print(what, 'points', ts.size, 'played peaks: speed', peak_v, 'torque', peak_tau,
              'TCP |a|', p.tcp_accel.max())
        assert np.all(peak_v <= lim.velocity * (1 + 1e-6)), what
        assert np.all(peak_tau <= lim.torque * (1 + 1e-6)), what
        # the reported peaks are the played ones (the check plays at 10 kHz too, on its
        # own instants: 2e-3 for sampling at different instants)
        np.testing.assert_allclose(ver.peak_torque, peak_tau, rtol=2e-3, err_msg=what)
        np.testing.assert_allclose(ver.peak_speed, peak_v, rtol=2e-3, err_msg=what)
        if req.tcp_accel_max > 0:
            assert p.tcp_accel.max() <= req.tcp_accel_max * (1 + 1e-4), what
            assert ver.tcp_accel_peak == pytest.approx(p.tcp_accel.max(), rel=2e-3), what
            assert p.tcp_speed.max() <= req.tcp_speed_max * (1 + 1e-6), what


def test_the_vertical_line_with_the_default_ramp_plans_inside_its_band(planner, model):
    """Issue 28: 0.7 0.1 0.0 -> 0.7 0.1 0.6 m, 2.4 s, 0.2-0.3 m/s, |a| <= 2 m/s^2, default
    ramp (v_min^2 / a_max = 20 mm) was refused with 'no motion at all keeps the process
    constraints': the floor over each interval of the ramp was its larger node's."""
    req = PlanRequest(path_type='line', waypoints=LINE_UP, duration=2.4, tcp_speed_min=0.2,
                      tcp_speed_max=0.3, tcp_accel_max=2.0)
    r = planner.plan(req)
    assert r.verification.ok and r.evaluation.ok
    p = play(model, r.trajectory['t'], r.trajectory['q'], r.trajectory['qd'],
             r.trajectory['qdd'], stride=4)
    assert p.tcp_accel.max() <= 2.0 * (1 + 1e-4)
    assert p.tcp_speed.max() <= 0.3 * (1 + 1e-6)
    # beyond the 20 mm ramps the floor: the TCP's height is its arc length on this line
    z = np.array([model.fk(q)[2] for q in p.q[p.idx]])
    moving = (z >= 0.02) & (z <= 0.58)
    assert p.tcp_speed[moving].min() >= 0.2 * (1 - 1e-4)


def test_a_ramp_too_short_for_the_acceleration_bound_is_refused_with_its_certificate(
        planner):
    # refused before any solve, naming the bound and by how much. With the jerk limits (on
    # by default, issue 28) the floor over a rest ramp rises as v_min (d / r)^(2/3), the
    # speed of a constant-jerk start (a rest interval's motion), whose top needs (2/3) v_min^2
    # / r = 0.0267 / 0.012 = 2.222 m/s^2 > 1.5 (by 48.1 %); a constant-acceleration start
    # would need v_min^2 / (2 r) = 1.667 (by 11.1 %), still above 1.5: a true refusal
    req = PlanRequest(path_type='line', waypoints=LINE_UP, duration=2.4, tcp_speed_min=0.2,
                      tcp_speed_max=0.3, tcp_accel_max=1.5, tcp_ramp_length=0.012)
    with pytest.raises(PlanError) as exc:
        planner.plan(req)
    assert exc.value.code == ERROR_INFEASIBLE_DURATION
    assert '2.222 m/s^2 > tcp_accel_max 1.5' in exc.value.message
    assert 'by 48.1 %' in exc.value.message
