"""PD+ controller core: feed-forward law, friction blend, ramp, theta prediction, safety."""
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from irb_control.pd_plus import (MODE_HOLD, MODE_IDLE, MODE_PATH, MODE_RAMP, MODE_STOPPED,
                                 MODE_TIME, ControllerConfig, PdPlusController, Watchdog,
                                 friction_blend, gain_scale, quintic_ramp, ramp_duration)
from irb_control.profiles import (PathProfile, ProfileError, default_circle_profile,
                                  sine_trajectory)

T = 0.004032


@pytest.fixture(scope='module')
def profile(model, circle):
    return default_circle_profile(model, circle, 10.0)


def make(model, circle, profile, friction=None, **kw):
    c = PdPlusController(model, circle, ControllerConfig(**kw), friction)
    c.set_path_profile(profile)
    return c


def run_to_path(ctrl, profile, t0=0.0):
    """Enable and step with the robot exactly at the path start until PATH mode."""
    q0 = profile.q[0]
    ctrl.enable()
    t = t0
    out = ctrl.step(t, q0, np.zeros(3))
    while out.mode == MODE_RAMP:
        t += T
        out = ctrl.step(t, q0, np.zeros(3))
    return t, out


def test_friction_blend_formula():
    a = 0.25
    qd_ref = np.array([0.0, 0.25, 2.0])
    qd_meas = np.array([0.1, 0.1, 1.8])
    v = friction_blend(qd_ref, qd_meas, a)
    alpha = np.exp(-qd_ref**2 / (2 * a * a))
    assert_allclose(v, alpha * qd_ref + (1 - alpha) * qd_meas)
    assert v[0] == 0.0                                  # alpha = 1 at zero reference speed
    assert v[1] == pytest.approx(np.exp(-0.5) * 0.25 + (1 - np.exp(-0.5)) * 0.1)
    assert v[2] == pytest.approx(1.8, abs=1e-6)          # measurement at high speed


def test_torque_equals_inverse_dynamics_when_errors_are_zero(model, circle, profile, rng):
    """With zero errors (q = q_ref, qd = qd_ref), no prediction: tau = RNEA + tau_f(qd_ref)."""
    ctrl = make(model, circle, profile, model.friction, prediction_samples=0,
                theta_max_lead_rad=0.0)
    t, _ = run_to_path(ctrl, profile)
    for th in rng.uniform(0.3, 6.0, 5):
        row = profile.sample(th)
        q, qd = row[2:5], row[5:8]
        ctrl._theta = ctrl._theta_v = th - 1e-9
        t += T
        out = ctrl.step(t, q, qd)
        assert out.mode == MODE_PATH
        assert_allclose(out.q_ref, q, atol=1e-6)
        assert_allclose(out.q_error, 0.0, atol=1e-5)
        expected = (model.inverse_dynamics(q, qd, out.qdd_ref)
                    + model.friction.torque(qd))
        # inertia-scheduled gains (no prediction here: M at the measured q)
        sc = gain_scale(np.diag(model.mass_matrix(q)), ctrl.config.gain_design_inertia_kg_m2)
        tau_fb = sc * (ctrl.kp * out.q_error + ctrl.kd * out.qd_error)
        # theta from FK(IK(p)) is exact to ~1e-9 rad, hence 1e-4 N m
        assert_allclose(out.tau_model + out.tau_friction, expected, rtol=1e-9, atol=1e-4)
        assert_allclose(out.tau, expected + tau_fb, atol=1e-4)
        assert np.max(np.abs(tau_fb)) < 1.0


def test_feedback_law(model, circle, profile):
    ctrl = make(model, circle, profile, None, prediction_samples=0, theta_max_lead_rad=0.0,
                torque_rate_limit_nm_s=(1e9, 1e9, 1e9))
    t, out = run_to_path(ctrl, profile)
    q = profile.q[0] + np.array([0.001, -0.002, 0.003])
    qd = np.array([0.01, 0.0, -0.02])
    out = ctrl.step(t + T, q, qd)
    assert_allclose(out.tau_feedback, ctrl.kp * (out.q_ref - q) + ctrl.kd * (out.qd_ref - qd))
    assert_allclose(out.tau_friction, 0.0)
    assert_allclose(out.tau, out.tau_model + out.tau_feedback)


def test_ramp_from_current_pose(model, circle, profile):
    ctrl = make(model, circle, profile, prediction_samples=0)
    q_start = profile.q[0]
    q0 = q_start + np.array([0.05, -0.04, 0.03])
    ctrl.enable()
    out = ctrl.step(1.0, q0, np.zeros(3))
    assert out.mode == MODE_RAMP and out.publish
    assert_allclose(out.q_ref, q0, atol=1e-12)
    assert_allclose(out.qd_ref, 0.0, atol=1e-12)
    out = ctrl.step(1.25, q0, np.zeros(3))
    assert_allclose(out.q_ref, 0.5 * (q0 + q_start), atol=1e-12)   # quintic midpoint
    assert np.all(np.abs(out.qd_ref) > 0)
    out = ctrl.step(1.5 + 1e-9, q_start, np.zeros(3))
    assert out.mode == MODE_PATH


def test_quintic_ramp_and_duration():
    q0, q1 = np.zeros(3), np.array([1.0, -0.5, 0.2])
    q, qd, qdd = quintic_ramp(q0, q1, 2.0, 1.0)
    assert_allclose(q, 0.5 * q1)
    assert_allclose(qd, 1.875 * q1 / 2.0)
    assert_allclose(qdd, 0.0, atol=1e-12)
    assert_allclose(quintic_ramp(q0, q1, 2.0, 5.0)[0], q1)
    vmax = np.array([2.6, 2.8, 3.0])
    assert ramp_duration(q0, q0 + 0.01, vmax) == 0.5
    assert ramp_duration(q0, np.array([1.3, 0, 0]), vmax, speed_fraction=0.5) == \
        pytest.approx(1.875 * 1.3 / 1.3)


def test_theta_prediction_three_samples(model, circle, profile):
    ctrl = make(model, circle, profile, theta_max_lead_rad=0.0)
    t, _ = run_to_path(ctrl, profile)
    th = 2.0
    q = model.ik(circle.point(th))
    out = ctrl.step(t + T, q, np.zeros(3))
    assert out.theta == pytest.approx(th, abs=1e-9)
    expect = th
    for _ in range(3):
        expect += T * profile.h(expect)
    assert out.theta_predicted == pytest.approx(expect, abs=1e-12)
    assert out.theta_dot_ref == pytest.approx(profile.h(expect), rel=1e-6)
    row = profile.sample(expect)
    assert_allclose(out.q_ref, row[2:5])


def test_theta_unwraps_and_holds_at_end(model, circle, profile):
    ctrl = make(model, circle, profile, theta_max_lead_rad=0.0)
    t, _ = run_to_path(ctrl, profile)
    for th in np.linspace(0.0, 2 * np.pi - 0.01, 60):
        t += T
        out = ctrl.step(t, model.ik(circle.point(th)), np.zeros(3))
        assert out.mode == MODE_PATH and out.theta == pytest.approx(th, abs=1e-6)
    # crossing 2 pi: atan2 wraps to ~0, the controller must not restart the circle
    t += T
    out = ctrl.step(t, model.ik(circle.point(2 * np.pi + 0.01)), np.zeros(3))
    assert out.mode == MODE_HOLD
    assert_allclose(out.q_ref, profile.q[-1])
    assert_allclose(out.qd_ref, 0.0)


def test_limits_torque_and_rate(model, circle, profile):
    ctrl = make(model, circle, profile, torque_limit_nm=(50.0, 300.0, 100.0),
                torque_rate_limit_nm_s=(1000.0, 1000.0, 1000.0),
                max_tracking_error_rad=(1.0, 1.0, 1.0))
    ctrl.enable()
    q0 = profile.q[0]
    prev = ctrl.step(0.0, q0, np.zeros(3)).tau
    assert np.all(np.abs(prev) <= [50.0, 300.0, 100.0])
    for k in range(1, 20):
        out = ctrl.step(k * T, q0 + 0.3 * np.array([1, -1, 1]), np.zeros(3))
        assert np.all(np.abs(out.tau) <= np.array([50.0, 300.0, 100.0]) + 1e-9)
        assert np.all(np.abs(out.tau - prev) <= 1000.0 * T + 1e-9)
        prev = out.tau


@pytest.mark.parametrize('bad', [
    (np.array([np.nan, 0.0, 0.0]), np.zeros(3)),
    (np.zeros(3), np.array([0.0, np.inf, 0.0])),
    (np.zeros(2), np.zeros(3)),
    (np.zeros(3), np.full(3, -np.inf)),
])
def test_nonfinite_inputs_never_reach_output(model, circle, profile, bad):
    ctrl = make(model, circle, profile, model.friction)
    ctrl.enable()
    q0 = profile.q[0]
    ctrl.step(0.0, q0, np.zeros(3))
    out = ctrl.step(T, *bad)
    assert not out.publish and out.rejected_input
    assert np.all(np.isfinite(out.tau))
    assert ctrl.rejected_inputs == 1
    out = ctrl.step(math.nan, q0, np.zeros(3))
    assert not out.publish
    out = ctrl.step(2 * T, q0, np.zeros(3))          # valid again: back to normal
    assert out.publish and np.all(np.isfinite(out.tau))


def test_nonfinite_model_output_latches_stop(model, circle, profile):
    ctrl = make(model, circle, profile)
    ctrl.enable()
    ctrl.kp = np.array([np.nan, 1.0, 1.0])          # a corrupted gain
    out = ctrl.step(0.0, profile.q[0], np.zeros(3))
    assert not out.publish and out.mode == MODE_STOPPED
    assert 'non-finite' in out.stop_reason and np.all(np.isfinite(out.tau))


def test_speed_position_and_tracking_aborts_latch(model, circle, profile):
    q0 = profile.q[0]
    ctrl = make(model, circle, profile)
    ctrl.enable()
    ctrl.step(0.0, q0, np.zeros(3))
    out = ctrl.step(T, q0, np.array([0.0, 3.5, 0.0]))
    assert out.mode == MODE_STOPPED and 'speed limit' in out.stop_reason and not out.publish
    out = ctrl.step(2 * T, q0, np.zeros(3))          # latched
    assert out.mode == MODE_STOPPED and not out.publish

    ctrl = make(model, circle, profile)
    ctrl.enable()
    out = ctrl.step(0.0, np.array([0.0, 2.5, 0.0]), np.zeros(3))
    assert out.mode == MODE_STOPPED and 'position limit' in out.stop_reason

    ctrl = make(model, circle, profile, max_tracking_error_rad=(0.01, 0.01, 0.01))
    t, _ = run_to_path(ctrl, profile)
    out = ctrl.step(t + T, profile.q[0] + np.array([0.0, 0.02, 0.0]), np.zeros(3))
    assert out.mode == MODE_STOPPED and 'tracking error' in out.stop_reason
    ok, _ = ctrl.enable()                              # enable clears the latch
    assert ok
    out = ctrl.step(t + 2 * T, profile.q[0], np.zeros(3))
    assert out.mode == MODE_RAMP and out.publish


def test_stop_and_enable(model, circle, profile):
    ctrl = make(model, circle, profile)
    out = ctrl.step(0.0, profile.q[0], np.zeros(3))
    assert out.mode == MODE_IDLE and not out.publish
    ctrl.enable()
    assert ctrl.step(T, profile.q[0], np.zeros(3)).publish
    ctrl.stop('operator')
    out = ctrl.step(2 * T, profile.q[0], np.zeros(3))
    assert out.mode == MODE_STOPPED and out.stop_reason == 'operator' and not out.publish
    ctrl.stop('second reason')                         # first reason is kept
    assert ctrl.stop_reason == 'operator'


def test_watchdog():
    wd = Watchdog(T, 3)
    assert not wd.expired(100.0)                       # never fed: nothing to watch yet
    wd.feed(0.0)
    assert not wd.expired(3 * T)
    assert not wd.expired(3.4 * T)
    assert wd.expired(3.6 * T)
    wd.feed(1.0)
    assert not wd.expired(1.0 + T)
    assert Watchdog(T, 3, minimum_timeout_s=1.0).timeout_s == 1.0


def test_profile_validation(model, circle, profile):
    with pytest.raises(ProfileError):
        PathProfile(profile.theta, profile.theta_dot * 0, profile.theta_ddot, profile.q,
                    profile.qd, profile.qdd)
    bad_q = profile.q.copy()
    bad_q[5, 1] = np.nan
    with pytest.raises(ProfileError):
        PathProfile(profile.theta, profile.theta_dot, profile.theta_ddot, bad_q, profile.qd,
                    profile.qdd)
    fast = PathProfile(profile.theta, profile.theta_dot * 20, profile.theta_ddot, profile.q,
                       profile.qd * 20, profile.qdd)
    ctrl = PdPlusController(model, circle)
    with pytest.raises(ProfileError, match='speed'):
        ctrl.set_path_profile(fast)


def test_time_driven_mode(model, circle, profile):
    q0 = profile.q[0]
    traj = sine_trajectory(q0, 2, 0.5, amplitude=0.2)
    ctrl = PdPlusController(model, circle, ControllerConfig(
        prediction_samples=3, max_tracking_error_rad=(1.0, 1.0, 1.0)))
    ctrl.set_time_trajectory(traj)
    ctrl.enable()
    t = 0.0
    out = ctrl.step(t, q0, np.zeros(3))
    while out.mode == MODE_RAMP:
        t += T
        out = ctrl.step(t, q0, np.zeros(3))
    assert out.mode == MODE_TIME
    t += 1.0
    out = ctrl.step(t, q0, np.zeros(3))
    row = traj.sample(t - 0.5 + 3 * T)
    assert_allclose(out.q_ref, row[:3], atol=1e-4)
    out = ctrl.step(t + traj.duration, q0, np.zeros(3))
    assert out.mode == MODE_HOLD


def test_settle_gate_needs_a_steady_stream_for_the_settle_time():
    from irb_control.pd_plus import SettleGate
    T = 0.004032
    gate = SettleGate(0.25, T)
    times = 100.0 + T * np.arange(200)
    ready = [gate.feed(t) for t in times]
    first = ready.index(True)
    assert not any(ready[:first]) and all(ready[first:])
    assert times[first] - times[0] >= 0.25 and times[first - 1] - times[0] < 0.25
    # a gap of more than 3 periods starts the count again; 3 periods do not
    assert gate.feed(times[-1] + 3.0 * T)
    t = times[-1] + 3.0 * T + 3.5 * T
    assert not gate.feed(t)
    assert not gate.feed(t + 0.2) and not gate.feed(t + 0.2 + 3.2 * T)
    assert not gate.feed(t + 0.26)          # the gap before restarted the count
    assert SettleGate(0.0, T).feed(5.0)     # 0: ready on the first sample


def test_friction_feedforward_reads_asymmetry_and_offset(model, circle, profile):
    """pdplus's float path for parametric maps equals irb_description's FrictionMap."""
    from irb_description.friction import FrictionMap, JointFriction
    fm = FrictionMap(tuple(model.joint_names), tuple(
        JointFriction(10.0 + i, 13.0 + i, 0.08, 5.0, (0.01, 2.0), coulomb_positive=11.0 + i,
                      coulomb_negative=9.0 + i, offset=0.4 - 0.3 * i) for i in range(3)))
    ctrl = make(model, circle, profile, friction=fm)
    for qd_ref, qd in (([0.5, -0.3, 0.02], [0.45, -0.31, 0.0]),
                       ([-1.2, 0.0, 0.3], [-1.1, 0.001, 0.25])):
        a = ctrl.config.friction_blend_a
        v = friction_blend(np.array(qd_ref), np.array(qd), a)
        got = ctrl._friction_torque(qd_ref, tuple(qd))
        assert_allclose(got, fm.torque(v), rtol=1e-12, atol=1e-12)
        # and the per-sign levels are really used (not the symmetric mean)
        assert not np.allclose(got, FrictionMap(fm.joint_names, tuple(
            JointFriction(j.coulomb, j.static, j.stribeck_velocity, j.viscous)
            for j in fm.joints)).torque(v))
