"""Six-joint PD+'s wrist stiction measures (issue 30): integral action (bounded, anti-windup,
never acting while not enabled, reset on stop/enable) and the Stribeck term on the measured
speed; both off by default, so the three-axis step is untouched (its hashes:
test_six_joint_control.py). Tracking figures: benchmarks/RESULTS.md 'Six-joint control'."""
from __future__ import annotations

import numpy as np
import pytest
from irb_description.path import LinePath
from irb_description.six_axis_model import SixJointModel

from irb_control.closed_loop import six_axis_controller_config
from irb_control.pd_plus import (MODE_HOLD, MODE_IDLE, MODE_STOPPED, ControllerConfig,
                                 PdPlusController)

Q0 = np.array([0.0, 0.6, 0.2, 0.0, -0.5, 0.0])
KI = (0.0, 0.0, 0.0, 2000.0, 2000.0, 400.0)
LIM = (0.0, 0.0, 0.0, 0.5, 0.5, 0.3)


@pytest.fixture(scope='module')
def six():
    return SixJointModel(None)


def _holding(six, **cfg):
    c = six_axis_controller_config(ki=KI, integral_limit_nm=LIM, **cfg)
    path = LinePath(np.array([0.6, 0.0, 0.3]), np.array([0.7, 0.0, 0.3]))
    ctrl = PdPlusController(six, path, c)
    ok, why = ctrl.motors_on(Q0)          # IDLE -> HOLD of Q0, the integral at zero
    assert ok, why
    return ctrl


def test_integral_is_bounded_and_zero_when_stopped(six):
    # constant gains, so that tau_feedback - (kp e + kd de) is the integral torque alone
    ctrl = _holding(six, gain_design_inertia_kg_m2=None)
    kp, kd = np.asarray(ctrl.config.kp), np.asarray(ctrl.config.kd)
    off = np.array([0.0, 0.0, 0.0, -0.004, 0.004, -0.004])    # the wrist held off its pose
    fb_i = []
    for k in range(400):                  # 1.6 s: Ki e T accumulates far beyond the bounds
        o = ctrl.step(k * 0.004, Q0 + off, np.zeros(6))
        assert o.publish and o.mode == MODE_HOLD
        fb_i.append(o.tau_feedback - (kp * o.q_error + kd * o.qd_error))
    fb_i = np.array(fb_i)
    # the integral torque: the sign of the error, growing by Ki e T, never beyond its bound
    assert np.all(np.abs(fb_i) <= np.array(LIM) + 1e-12)
    assert np.allclose(fb_i[-1], np.sign(-off) * np.array(LIM), atol=1e-12)
    T = ctrl.config.period_s
    assert np.allclose(fb_i[0], np.array(KI) * -off * T, rtol=1e-6, atol=1e-12)
    ctrl.stop('test')
    o = ctrl.step(2.0, Q0 + off, np.zeros(6))
    assert o.mode == MODE_STOPPED and not o.publish and not np.any(o.tau)
    assert ctrl._integral == [0.0] * 6
    ok, _ = ctrl.motors_off(np.zeros(6))          # STOPPED stays latched; IDLE: no command
    ctrl2 = _holding(six)
    ctrl2.motors_off(np.zeros(6))
    assert ctrl2.mode == MODE_IDLE
    o = ctrl2.step(0.0, Q0 + off, np.zeros(6))
    assert not o.publish and ctrl2._integral == [0.0] * 6


def test_integral_holds_while_the_command_is_limited(six):
    """Anti-windup: with a torque limit below what the error asks, the integral stays put."""
    ctrl = _holding(six, torque_limit_nm=(700.0, 900.0, 450.0, 60.0, 60.0, 1e-3))
    for k in range(50):
        ctrl.step(k * 0.004, Q0 + np.array([0, 0, 0, 0, 0, -0.004]), np.zeros(6))
    assert ctrl._integral[5] == 0.0 and ctrl._integral[3] == 0.0


def test_stribeck_on_the_measured_speed(six):
    """stribeck_measured: the hump F_s - F_c at the measured speed (sticking: breakaway;
    sliding: Coulomb), the rest of the map on the eq. 4.9 blend; off = the thesis's map."""
    from irb_description.six_axis_model import nominal_six_joint_friction
    fm = nominal_six_joint_friction()
    path = LinePath(np.array([0.6, 0.0, 0.3]), np.array([0.7, 0.0, 0.3]))
    on = PdPlusController(six, path, six_axis_controller_config(), fm)
    off = PdPlusController(six, path, six_axis_controller_config(
        ki=None, integral_limit_nm=None, stribeck_measured=None, stiction_prediction=False),
        fm)
    ref = [0.0, 0.0, 0.0, 0.005, 0.005, 0.005]                 # a creeping reference
    j6 = fm.joints[5]
    stuck = on._friction_torque_n(ref, [0.0] * 6)
    slide = on._friction_torque_n(ref, [0.0, 0.0, 0.0, 0.2, 0.2, 0.2])
    plain = off._friction_torque_n(ref, [0.0, 0.0, 0.0, 0.2, 0.2, 0.2])
    v = 0.005       # alpha(0.005) ~ 1: the blend is the reference speed
    a = np.exp(-v * v / (2 * 0.25 ** 2))
    vb = a * v + (1 - a) * 0.2
    assert stuck[5] == pytest.approx(j6.static + j6.viscous * a * v, abs=1e-12)
    assert slide[5] == pytest.approx(
        j6.coulomb + (j6.static - j6.coulomb) * np.exp(-(0.2 / j6.stribeck_velocity) ** 2)
        + j6.viscous * vb, abs=1e-12)
    assert plain[5] == pytest.approx(float(fm.torque(np.array([0, 0, 0, vb, vb, vb]))[5]),
                                     abs=1e-12)
    assert slide[:3] == plain[:3]           # joints 1-3: the thesis's map on the blend


def test_settings_are_checked():
    with pytest.raises(ValueError, match='go together'):
        ControllerConfig(ki=(1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match='ki must be 3'):
        ControllerConfig(ki=(1.0, 1.0), integral_limit_nm=(1.0, 1.0))
    with pytest.raises(ValueError, match='stribeck_measured'):
        ControllerConfig(stribeck_measured=(1.0, 0.0, 0.0))
    assert ControllerConfig().ki is None and ControllerConfig().stribeck_measured is None
