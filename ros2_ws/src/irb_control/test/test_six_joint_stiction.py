"""Six-joint PD+'s stiction prediction and stiction dither (issue 30): off by default (the
three-axis step untouched: its hashes are test_six_joint_control.py's), bounded, acting only
while a command is published in the modes they are for, reset on stop/enable. Tracking
figures: benchmarks/RESULTS.md 'Six-joint control'."""
from __future__ import annotations

import math

import numpy as np
import pytest
from irb_description.path import LinePath
from irb_description.six_axis_model import SixJointModel, nominal_six_joint_friction

from irb_control.closed_loop import six_axis_controller_config
from irb_control.pd_plus import (MODE_HOLD, MODE_IDLE, MODE_RAMP, MODE_STOPPED,
                                 ControllerConfig, PdPlusController)
from irb_control.profiles import TimeTrajectory

Q0 = np.array([0.0, 0.6, 0.2, 0.0, -0.5, 0.0])
PATH = LinePath(np.array([0.6, 0.0, 0.3]), np.array([0.7, 0.0, 0.3]))
T = 0.004032


@pytest.fixture(scope='module')
def six():
    return SixJointModel(None)


@pytest.fixture(scope='module')
def fm():
    return nominal_six_joint_friction()


def test_off_by_default_and_settings_checked():
    c = ControllerConfig()
    assert not c.stiction_prediction and c.dither_amplitude_nm is None
    with pytest.raises(ValueError, match='stiction_prediction needs stribeck_measured'):
        ControllerConfig(stiction_prediction=True)
    with pytest.raises(ValueError, match='dither_amplitude_nm must be 3'):
        ControllerConfig(dither_amplitude_nm=(0.1, 0.1))
    with pytest.raises(ValueError, match='dither_amplitude_nm must be 3'):
        ControllerConfig(dither_amplitude_nm=(0.1, -0.1, 0.0))
    for bad in (0, 3, 1.5):
        with pytest.raises(ValueError, match='dither_period_samples'):
            ControllerConfig(dither_period_samples=bad)
    with pytest.raises(ValueError, match='stiction_rest_speed_rad_s'):
        ControllerConfig(stiction_rest_speed_rad_s=math.nan)
    # the six-axis configuration file turns the prediction on, no dither, no integral
    c6 = six_axis_controller_config()
    assert c6.stiction_prediction and c6.dither_amplitude_nm is None and c6.ki is None


def test_slide_is_the_stick_slip_of_one_joint(six, fm):
    """``_slide``: at rest below the breakaway it stays at rest; above it accelerates by at
    most (drive - F_c) / m; sliding without drive it comes to rest and never reverses."""
    ctrl = PdPlusController(six, PATH, six_axis_controller_config(), fm)
    j = fm.joints[5]
    m = 0.025
    assert ctrl._slide(5, 0.0, 0.99 * j.static, 0.0, m) == 0.0
    assert ctrl._slide(5, 0.002, -0.99 * j.static, 0.0, m) == 0.0   # below rest speed: rest
    v = ctrl._slide(5, 0.0, 1.2 * j.static, 0.0, m)
    assert 0.0 < v <= T * (1.2 * j.static - j.coulomb) / m
    v = ctrl._slide(5, 0.0, -1.2 * j.static, 0.0, m)
    assert -T * (1.2 * j.static - j.coulomb) / m <= v < 0.0
    # a reference acceleration asks for torque m a: m a above F_s breaks it away the same way
    assert ctrl._slide(5, 0.0, 0.0, 1.2 * j.static / m, m) > 0.0
    v = 0.1
    for _ in range(10):
        v2 = ctrl._slide(5, v, 0.0, 0.0, m)
        assert 0.0 <= v2 <= v
        v = v2
    assert v == 0.0


def _hold(six, fm, **cfg):
    ctrl = PdPlusController(six, PATH, six_axis_controller_config(**cfg), fm)
    ok, why = ctrl.motors_on(Q0)          # IDLE -> HOLD of Q0
    assert ok, why
    return ctrl


def test_prediction_switches_the_hump_on_the_commands_in_flight(six, fm):
    """With commands in flight that break joint 6 away, the hump is off (Coulomb) although
    the measurement still says 'at rest'; without the prediction it is the breakaway level;
    the commands in flight are forgotten on stop (nothing is published there)."""
    j = fm.joints[5]
    on = _hold(six, fm)
    off = _hold(six, fm, stiction_prediction=False)
    at_rest = [0.0] * 6
    # three commands in flight that push joint 6 with 2 F_s beyond the model terms
    for _ in range(3):
        on._pred_flight.append(([0.0] * 5 + [2.0 * j.static], [0.0] * 6))
    # the step's hump speeds: joint 6 predicted sliding (well above v_s: e^-(v/v_s)^2 ~ 0)
    v6 = 0.0
    for u_j, a_j in on._pred_flight:
        v6 = on._slide(5, v6, u_j[5], a_j[5], 0.025)
    assert v6 > 3 * j.stribeck_velocity
    tf_on = on._friction_torque_n([0.0, 0, 0, 0, 0, 1e-3], at_rest,
                                  [0.0] * 5 + [v6])[5]
    tf_off = off._friction_torque_n([0.0, 0, 0, 0, 0, 1e-3], at_rest)[5]
    assert tf_off == pytest.approx(j.static + j.viscous * 1e-3 * math.exp(-1e-6 / 0.125),
                                   rel=1e-9)
    assert tf_on == pytest.approx(j.coulomb, abs=0.01)
    # a step fills the flight with its own command (n samples), a stop clears it
    ctrl = _hold(six, fm)
    for k in range(5):
        o = ctrl.step(k * T, Q0, np.zeros(6))
        assert o.publish and o.mode == MODE_HOLD
    assert len(ctrl._pred_flight) == ctrl.config.prediction_samples
    ctrl.stop('test')
    assert len(ctrl._pred_flight) == 0
    o = ctrl.step(1.0, Q0, np.zeros(6))
    assert not o.publish and o.mode == MODE_STOPPED
    assert len(ctrl._pred_flight) == 0


def test_dither_only_while_publishing_in_path_time_hold(six, fm):
    """The dither: +-a in the command's friction part with the configured period, the same
    command otherwise; none in the ramp, IDLE or STOPPED; bounded by the rate and torque
    limits; restarts its phase on enable."""
    a = (0.0, 0.0, 0.0, 0.2, 0.2, 0.3)
    base = dict(stiction_prediction=False, gain_design_inertia_kg_m2=None)
    d2 = _hold(six, fm, dither_amplitude_nm=a, **base)
    d4 = _hold(six, fm, dither_amplitude_nm=a, dither_period_samples=4, **base)
    ref = _hold(six, fm, **base)
    diff2, diff4 = [], []
    for k in range(8):
        q = Q0 + 1e-4 * math.sin(k)
        o2, o4, o0 = (c.step(k * T, q, np.zeros(6)) for c in (d2, d4, ref))
        assert o2.publish and o4.publish and o0.publish and o2.mode == MODE_HOLD
        diff2.append(o2.tau - o0.tau)
        diff4.append(o4.tau - o0.tau)
    s2 = np.array([1, -1] * 4)[:, None] * np.array(a)
    s4 = np.array([1, 1, -1, -1] * 2)[:, None] * np.array(a)
    np.testing.assert_allclose(diff2, s2, atol=1e-9)
    np.testing.assert_allclose(diff4, s4, atol=1e-9)
    # bounded: a torque limit below the dither clips the command to it
    lim = _hold(six, fm, dither_amplitude_nm=(0, 0, 0, 0, 0, 5.0),
                torque_limit_nm=(700.0, 900.0, 450.0, 60.0, 60.0, 0.5), **base)
    for k in range(6):
        o = lim.step(k * T, Q0, np.zeros(6))
        assert abs(o.tau[5]) <= 0.5
    # no command in IDLE (motors off) and STOPPED: no dither either
    d2.motors_off(np.zeros(6))
    assert d2.mode == MODE_IDLE and d2._dither_k == 0
    o = d2.step(1.0, Q0, np.zeros(6))
    assert not o.publish and not np.any(o.tau)
    d4.stop('test')
    o = d4.step(1.0, Q0, np.zeros(6))
    assert not o.publish and not np.any(o.tau) and d4._dither_k == 0
    # in the ramp: none (the same command as without the dither)
    traj = TimeTrajectory(np.array([0.0, 1.0]), np.vstack([Q0 + 0.05, Q0 + 0.05]),
                          np.zeros((2, 6)), np.zeros((2, 6)))
    r_d = PdPlusController(six, PATH, six_axis_controller_config(dither_amplitude_nm=a, **base),
                           fm)
    r_0 = PdPlusController(six, PATH, six_axis_controller_config(**base), fm)
    for c in (r_d, r_0):
        c.set_time_trajectory(traj)
        assert c.enable()[0]
    for k in range(10):
        o_d, o_0 = (c.step(k * T, Q0, np.zeros(6)) for c in (r_d, r_0))
        assert o_d.mode == MODE_RAMP and o_d.publish
        np.testing.assert_array_equal(o_d.tau, o_0.tau)
    assert r_d._dither_k == 0


def test_prediction_reduces_joint_6_stick_slip_in_closed_loop():
    """Closed loop (plant with its own friction as feed-forward, the six-axis config): the
    rectangle with the nozzle normal to its plane, rest to rest in 6 s; joint 6 creeps and
    reverses on it. With the stiction prediction the orientation error and joint 6's error
    are smaller than without (the goal's figures: irb_bringup bench_six_joint.py)."""
    from irb_description.orientation import joint_path6, orientation_from_spec
    from irb_description.path import rectangle_path
    from irb_description.six_axis import SixAxisKinematics, pose

    from irb_control.closed_loop import build_six_joint, simulate_closed_loop
    from irb_control.profiles import polynomial_theta_of_time, profile_from_theta_samples
    tcp = pose(np.eye(3), [0.0, 0.0, 0.10])
    six = SixJointModel(tcp)
    path = rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025)
    law = orientation_from_spec({'law': 'path_normal', 'normal': [0.3, 0.1, 1.0],
                                 'x_mode': 'fixed'}, path)
    kin = SixAxisKinematics(tcp=tcp)
    cfg = joint_path6(kin, path, law, np.linspace(0.0, 2 * np.pi, 721)).configuration

    def joints(theta):
        return joint_path6(kin, path, law, theta, configuration=cfg, derivatives=True)
    t, th, thd, thdd = polynomial_theta_of_time(6.0)
    prof = profile_from_theta_samples(six, path, th, thd, thdd, t, grid=1441, joints=joints)
    worst = {}
    for pred in (True, False):
        plant, ctrl = build_six_joint(prof, path, tcp, friction_mode='file', model=six,
                                      controller_config=six_axis_controller_config(
                                          stiction_prediction=pred))
        r = simulate_closed_loop(plant, ctrl, 7.5)
        assert r.stop_reason == '' and r.finished()
        sel = r.mode == 2
        T = kin.fk(r.q[sel])
        th = np.array([path.theta_of(p) for p in T[:, :3, 3]])
        th[-20:] = np.where(th[-20:] < 1.0, th[-20:] + 2 * np.pi, th[-20:])   # lap's end
        R = law.rotation(np.clip(th, 0, 2 * np.pi))
        ang = 2 * np.arcsin(np.clip(np.linalg.norm((R - T[:, :3, :3]).reshape(-1, 9), axis=1)
                                    / np.sqrt(8), 0, 1))
        worst[pred] = (float(ang.max()), float(np.nanmax(np.abs(r.joint_error()[sel][:, 5]))))
    assert worst[True][0] < worst[False][0], worst
    assert worst[True][1] < worst[False][1], worst
