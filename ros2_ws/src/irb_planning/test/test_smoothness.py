"""Smoothness limits (issue 28): on by default, no torque step at the rest ends, played jerk
and torque rate within their limits (outside the 1 ms twin intervals at a blend end's
curvature jump, reported apart), and pdplus's gate rules accept the plans.

The played figures come from the tests' own player (played.py: the message's quintic on ns
stamps, pinocchio torques), not from the planner's check."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest
import yaml

from irb_description.trajectory_rules import worst_inconsistency
from irb_planning.planner import Planner, PlannerSettings, request_path
from irb_planning.profile import ThetaProfile
from irb_planning.request import PlanRequest

_spec = importlib.util.spec_from_file_location('played', Path(__file__).parent / 'played.py')
played = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(played)

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'planner.yaml'


@pytest.fixture(scope='module')
def planner():
    return Planner(settings=PlannerSettings(grid_size=40, cache_size=4, limit_cost=False))


def test_default_on_and_documented():
    s = PlannerSettings()
    assert s.jerk_limits
    params = yaml.safe_load(CONFIG.read_text())['planner']['ros__parameters']
    assert params['jerk_limits'] is True
    assert list(params['joint_jerk_limit_rad_s3']) == list(s.joint_jerk_limit_rad_s3)
    assert params['tcp_jerk_limit_m_s3'] == s.tcp_jerk_limit_m_s3
    assert list(params['torque_rate_limit_nm_s']) == list(s.torque_rate_limit_nm_s)


def test_cubic_rest_interval_is_exact():
    """Constant path jerk from rest: theta = j t^3 / 6 on the first interval, mirrored at
    the end; sample and theta_at invert each other, theta_dot is d theta / dt."""
    th = np.linspace(0, 2 * np.pi, 10)
    h = th[1]
    b = np.ones(10)
    b[0] = b[-1] = 0
    a = np.zeros(10)
    a[1] = 1 / (1.5 * h)
    for k in range(1, 8):
        a[k + 1] = -a[k]                     # b constant inside
    p = ThetaProfile(th, np.sqrt(b), a)
    assert p.cubic_ends == (True, True)
    t1 = 3 * h / 1.0
    assert p.times[1] == pytest.approx(t1)
    j = a[1] / t1
    t = np.linspace(0, t1, 7)
    x, td, tdd = p.sample(t)
    np.testing.assert_allclose(x, j * t ** 3 / 6, atol=1e-12)
    np.testing.assert_allclose(td, j * t ** 2 / 2, atol=1e-12)
    np.testing.assert_allclose(tdd, j * t, atol=1e-12)
    np.testing.assert_allclose(p.theta_at(x)[0], t, atol=1e-9)
    x, td, tdd = p.sample(p.duration - t)
    np.testing.assert_allclose(2 * np.pi - x, j * t ** 3 / 6, atol=1e-12)
    np.testing.assert_allclose(tdd, -j * t, atol=1e-12)


def _played_rates(model, tr, windows):
    """Peak joint jerk and rigid-torque rate as played, outside the ``windows`` (the twin
    intervals around a blend end's curvature jump, which the plan reports apart)."""
    p = played.play(model, tr['t'], tr['q'], tr['qd'], tr['qdd'])
    jerk = np.abs(np.diff(p.qdd, axis=0)) / np.diff(p.t)[:, None]
    ti = p.t[p.idx]
    rigid = p.tau - model.friction.torque(p.qd[p.idx])
    rate = np.abs(np.diff(rigid, axis=0)) / np.diff(ti)[:, None]
    out_j, out_r = np.ones(jerk.shape[0], bool), np.ones(rate.shape[0], bool)
    for lo, hi in (() if windows is None else windows):
        out_j &= ~((p.t[1:] > lo) & (p.t[:-1] < hi))
        out_r &= ~((ti[1:] > lo) & (ti[:-1] < hi))
    return jerk[out_j].max(axis=0), rate[out_r].max(axis=0), not out_j.all()


REQUESTS = {
    'line': PlanRequest(path_type='line', waypoints=np.array([[0.7, -0.3, 0.3],
                                                              [0.7, 0.3, 0.3]]),
                        duration=2.0),
    'polyline': PlanRequest(path_type='polyline', waypoints=np.array(
        [[0.6, -0.15, 0.3], [0.8, -0.15, 0.3], [0.8, 0.15, 0.3], [0.6, 0.15, 0.3]]),
        blend_radii=np.array([0.03]), duration=4.0,
        tcp_speed_min=0.1, tcp_speed_max=0.4, tcp_accel_max=2.0, tcp_ramp_length=0.05),
    'circle_periodic': PlanRequest(radius=0.1, duration=2.5, boundary='periodic'),
}


@pytest.mark.parametrize('kind', sorted(REQUESTS))
def test_played_smooth_and_gate(planner, kind):
    res = planner.plan(REQUESTS[kind])
    tr = res.trajectory
    model = planner.model
    sm = planner.smooth_limits
    windows = planner._blend_windows(res.profile, request_path(res.request))
    jerk, rate, blends = _played_rates(model, tr, windows)
    assert blends == (kind == 'polyline') == bool(res.verification.blend_end_peaks)
    assert np.all(jerk <= sm.jerk * 1.01), jerk          # finite differences at 10 kHz
    assert np.all(rate <= sm.torque_rate * 1.01), rate
    assert res.verification.tcp_jerk_peak <= sm.tcp_jerk * (1 + 1e-6)
    # pdplus's gate: the shared consistency rule at full tolerance
    assert worst_inconsistency(played.message_stamps(tr['t']), tr['q'], tr['qd'],
                               tr['qdd']) is None
    if REQUESTS[kind].boundary != 'periodic':
        zero = np.zeros(3)
        for k in (0, -1):        # no torque step: the static torque at both rest ends
            static = model.inverse_dynamics(tr['q'][k], zero, zero)
            np.testing.assert_allclose(tr['tau'][k], static, atol=1e-6)
            np.testing.assert_allclose(tr['qdd'][k], 0.0, atol=1e-9)
        # and the first control sample (4.032 ms) moves the rigid torque by little
        c = played.play(model, tr['t'], tr['q'], tr['qd'], tr['qdd'], rate=1 / 0.004032)
        rigid = c.tau - model.friction.torque(c.qd[c.idx])
        assert np.all(np.abs(rigid[1] - rigid[0]) <= sm.torque_rate * 0.004032)
