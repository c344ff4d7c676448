"""Segment detection and the fits on synthetic data with known answers."""
import numpy as np
import pytest
from irb_description.friction import JointFriction

from irb_identification.friction_fit import (FitConfig, fit_parametric, fit_polynomial,
                                             identify_points, identify_series)
from irb_identification.profiles import DEFAULT_SPEEDS, ConstantVelocityProfile
from irb_identification.segments import SpeedPoint, find_segments, speed_points
from irb_identification.series import JointSeries

TRUE = JointFriction(coulomb=10.0, static=14.0, stribeck_velocity=0.06, viscous=8.0)


def sweep(c, joint=0, n=3, gravity=5.0, t0=0.0):
    """One eq. 4.1 run at speed c with ideal tracking (as synthetic_series) and its profile."""
    p = ConstantVelocityProfile.for_speed(c)
    t = np.arange(0, p.duration, 0.004032)
    v = np.zeros((len(t), n))
    v[:, joint] = p.velocity(t)
    q = np.zeros((len(t), n))
    q[:, joint] = p.position(t)
    tau = np.zeros((len(t), n))
    tau[:, joint] = TRUE.torque(v[:, joint]) + gravity * (1 + q[:, joint])
    return t + t0, q, v, tau, p


def synthetic_series(speeds, joint=0, n=3, gravity=5.0, noise=0.0, rng=None):
    """Ideal tracking of eq. 4.1: tau = tau_f(v) + gravity * (1 + q) (position dependent)."""
    parts, t0 = [], 0.0
    for c in speeds:
        t, q, v, tau, p = sweep(c, joint, n, gravity, t0)
        if noise:
            tau += noise * rng.standard_normal(tau.shape)
        parts.append(JointSeries(t, tuple(f'j{k}' for k in range(n)), q, v, tau))
        t0 += p.duration + 1.0
    return JointSeries.concatenate(parts)


def test_segments_find_the_holds():
    s = synthetic_series([0.1, 1.0])
    segs = find_segments(s, 0)
    assert len(segs) == 4
    assert sorted(round(g.speed, 6) for g in segs) == [-1.0, -0.1, 0.1, 1.0]
    assert find_segments(s, 1) == []                 # joint 1 never moved
    points, warnings = speed_points(segs)
    assert not warnings and len(points) == 2
    for p in points:
        assert p.tau_f == pytest.approx(float(TRUE.torque(p.speed)), rel=1e-3)  # sampling


def test_one_sided_speed_is_reported():
    s = synthetic_series([0.5])
    segs = [g for g in find_segments(s, 0) if g.speed > 0]
    points, warnings = speed_points(segs)
    assert points == [] and 'only with sign +' in warnings[0]


def test_parametric_fit_recovers_truth_with_ci(rng):
    c = np.array(DEFAULT_SPEEDS)
    v = np.r_[c, -c]
    tau = TRUE.torque(v) + 0.05 * rng.standard_normal(len(v))
    fit = fit_parametric(v, tau)
    for name in ('coulomb', 'static', 'stribeck_velocity', 'viscous'):
        est, true = getattr(fit, name), getattr(TRUE, name)
        assert abs(est - true) < max(fit.ci95[name] * 1.5, 1e-3), name
        assert fit.ci95[name] < 0.1 * true
    band = fit.band95(np.array([0.5, 1.0]))
    assert np.all(band > 0) and np.all(band < 0.2)


def test_mirrored_points_are_one_measurement_not_two(rng):
    """eq. 4.8 gives f_neg = -f_pos: 4 speeds mirrored are 4 independent points for the 4
    parameters, no residual left: no interval (it was 0 or 1e-14, a false certainty, and a
    Stribeck term kept on it); 6 speeds give a finite interval."""
    from irb_identification.friction_fit import independent_points
    c4 = np.array([0.05, 0.2, 0.5, 1.0])
    f4 = TRUE.torque(c4) + 0.05 * rng.standard_normal(4)
    assert independent_points(np.r_[c4, -c4], np.r_[f4, -f4]) == 4
    fit = fit_parametric(np.r_[c4, -c4], np.r_[f4, -f4])
    assert fit.dof == 0 and fit.ci95 == {}
    # identify: the Stribeck term has no support then (interval unknown) and is dropped;
    # the Coulomb + viscous fit keeps 2 residual degrees of freedom and real intervals
    res = identify_points('j', [SpeedPoint(c, f, -f, f, f, -f, 0.01, 1, 1)
                                for c, f in zip(c4, f4)])
    assert any('Stribeck term dropped' in w for w in res.warnings), res.warnings
    assert res.parametric.dof == 2 and res.parametric.ci95['coulomb'] > 1e-6
    c6 = np.array([0.05, 0.1, 0.2, 0.4, 0.7, 1.0])
    f6 = TRUE.torque(c6) + 0.05 * rng.standard_normal(6)
    mirrored = fit_parametric(np.r_[c6, -c6], np.r_[f6, -f6])
    assert mirrored.dof == 2 and mirrored.ci95['coulomb'] > 1e-6
    # a measurement of its own in each direction (not mirrored) counts twice
    g6 = -(TRUE.torque(c6) + 0.05 * rng.standard_normal(6))
    assert independent_points(np.r_[c6, -c6], np.r_[f6, g6]) == 12


def test_polynomial_fit_is_exact_on_polynomials():
    v = np.linspace(0.05, 2, 12)
    coef = np.array([3.0, 2.0, -1.0, 0.5, 0.1, -0.02])
    assert np.allclose(fit_polynomial(v, np.polynomial.polynomial.polyval(v, coef), 5), coef)


def test_too_few_speeds_and_no_segments():
    pts = [SpeedPoint(c, 1, -1, 1, 1, -1, 0, 1, 1) for c in (0.1, 0.2, 0.3)]
    r = identify_points('j0', pts, FitConfig(min_speeds=4))
    assert r.error and 'need at least 4' in r.error
    res = identify_series([synthetic_series([0.1, 0.3])], ['j0', 'j1', 'j2'])
    assert 'need at least' in res[0].error
    assert 'no constant-speed segments' in res[1].error


def test_identify_synthetic_noisy(rng):
    s = synthetic_series(DEFAULT_SPEEDS, joint=2, noise=1.0, rng=rng)
    res = identify_series([s], ['j0', 'j1', 'j2'])
    r = res[2]
    assert r.error is None, r.error
    assert r.parametric.coulomb == pytest.approx(TRUE.coulomb, rel=0.02)
    assert r.parametric.viscous == pytest.approx(TRUE.viscous, rel=0.02)
    assert r.friction.valid_range == (0.02, 2.0) or np.allclose(
        r.friction.valid_range, (0.02, 2.0), rtol=1e-3)
    assert len(r.friction.polynomial_positive) == 8


def test_too_few_points_for_the_parametric_fit_is_a_joint_error_not_a_crash():
    from irb_identification.friction_fit import FitConfig, identify_points
    from irb_identification.segments import SpeedPoint
    pts = [SpeedPoint(speed=c, tau_plus=12 + c, tau_minus=-8 - c, tau_f=10 + c, f_pos=10 + c,
                      f_neg=-10 - c, sem=0.1, n_plus=1, n_minus=1) for c in (0.1, 0.5)]
    r = identify_points('joint_1', pts, FitConfig(min_speeds=2))
    assert r.friction is None and 'too few' in r.error


def test_stick_slip_signature():
    from irb_identification.segments import SegmentConfig, stick_slip
    rng = np.random.default_rng(3)
    t = np.arange(0, 2.0, 0.004032)
    c = 0.1
    assert stick_slip(c + 0.002 * rng.standard_normal(len(t))) is None     # noise only
    wobble = c + 0.03 * np.sin(2 * np.pi * t / 1.0)
    assert 'not steady' in stick_slip(wobble)
    stuck = np.full(len(t), c)
    stuck[100:103] = 0.0                              # three samples at rest inside the hold
    assert 'stops inside the hold' in stick_slip(stuck)
    stuck[101] = c                                   # two isolated samples: a glitch, not a stop
    assert stick_slip(stuck) is None
    assert stick_slip(-stuck) is None                # sign-symmetric
    assert 'stops' in stick_slip(-np.where(np.arange(len(t)) % 40 < 4, 0.0, c))
    assert stick_slip(stuck, SegmentConfig(stick_samples=1)) is not None


def test_stick_slip_hold_is_rejected_reported_and_the_fit_keeps_the_truth(rng):
    """The +0.1 rad/s hold wobbles slowly (it passes the rolling test) with a torque bias as
    stick-slip gives; it must be left out, reported, and the fit stay on the truth."""
    parts, t0, spoiled = [], 0.0, None
    for c in DEFAULT_SPEEDS:
        t, q, v, tau, p = sweep(c, t0=t0)
        if c == 0.1:
            a, b, _ = p.hold_windows()[0]
            m = (t - t0 >= a) & (t - t0 <= b)
            v[m, 0] = c + 0.03 * np.sin(2 * np.pi * (t[m] - t0 - a) / 1.0)
            tau[m, 0] += 5.0
            spoiled = (t0 + a, t0 + b)
        tau[:, 0] += 0.3 * rng.standard_normal(len(t))
        parts.append(JointSeries(t, ('j0', 'j1', 'j2'), q, v, tau))
        t0 = t[-1] + 1.0
    s = JointSeries.concatenate(parts)
    rejected = []
    segs = find_segments(s, 0, rejected=rejected)
    assert len(rejected) == 1
    r = rejected[0]
    assert r.joint == 0 and r.speed == pytest.approx(0.1, rel=0.05)
    assert spoiled[0] < r.t_start < r.t_end < spoiled[1] and 'not steady' in r.reason
    assert not any(spoiled[0] <= g.t_start <= spoiled[1] for g in segs)
    res = identify_series([s], ['j0', 'j1', 'j2'], labels=['bag_a'])[0]
    assert res.error is None
    assert [(lab, x.reason) for lab, x in res.rejected] == [('bag_a', r.reason)]
    assert any('1 hold(s) rejected' in w and 'bag_a' in w for w in res.warnings)
    assert any('only with sign -' in w for w in res.warnings)       # 0.1 rad/s lost its pair
    assert 0.1 not in [round(p.speed, 3) for p in res.points]
    assert res.parametric.coulomb == pytest.approx(TRUE.coulomb, rel=0.02)
    assert res.parametric.viscous == pytest.approx(TRUE.viscous, rel=0.02)


def test_recording_gaps_do_not_bias_the_hold_average():
    """Gravity 50 (1 + q) N m varies by 40 N m over the stroke; a burst of dropped messages in
    the first half of the +c hold must not move its time average (eq. 4.8 stays exact)."""
    t, q, v, tau, p = sweep(0.5, gravity=50.0)
    a, b, _ = p.hold_windows()[0]
    keep = ~((t >= a + 0.3 * (b - a)) & (t <= a + 0.6 * (b - a)))
    s = JointSeries(t[keep], ('j0', 'j1', 'j2'), q[keep], v[keep], tau[keep])
    segs = find_segments(s, 0)
    plus = [g for g in segs if g.speed > 0][0]
    # truth: the time average of tau over the segment's span (q linear in t)
    q_mid = 0.5 * sum(p.position(np.array([plus.t_start, plus.t_end])))
    assert plus.torque == pytest.approx(float(TRUE.torque(0.5)) + 50 * (1 + q_mid), abs=1e-6)
    (point,), _ = speed_points(segs)
    assert point.tau_f == pytest.approx(float(TRUE.torque(0.5)), rel=1e-3)


def test_a_sweep_lost_to_chatter_is_reported():
    t, q, v, tau, _ = sweep(0.06)
    moving = np.abs(v[:, 0]) > 0.03
    v[moving, 0] += 0.06 * np.sin(2 * np.pi * 15 * t[moving])    # 15 Hz stick-slip chatter
    s = JointSeries(t, ('j0', 'j1', 'j2'), q, v, tau)
    assert find_segments(s, 0) == []
    res = identify_series([s], ['j0', 'j1', 'j2'], labels=['bag_x'])
    assert 'no constant-speed segments' in res[0].error
    assert any('bag_x: j0 moved back and forth on its own' in w for w in res[0].warnings)
    assert not res[1].warnings                       # joints that never moved: no warning


def test_effort_lag_is_referred_to_where_the_torque_acted():
    """The effort is the torque of the period before each sample: gravity 300 (1 + q) N m
    then pairs with q - c T/2, which biases eq. 4.8 by 300 c T/2 unless effort_lag_s says so."""
    from irb_identification.segments import SegmentConfig
    lag = 0.004032 / 2
    parts, t0 = [], 0.0
    for c in (0.2, 1.0):
        t, q, v, tau, _ = sweep(c, gravity=300.0, t0=t0)
        tau[:, 0] -= 300.0 * v[:, 0] * lag               # gravity where the torque acted
        parts.append(JointSeries(t, ('j0', 'j1', 'j2'), q, v, tau))
        t0 = t[-1] + 1.0
    s = JointSeries.concatenate(parts)
    for cfg, ok in ((SegmentConfig(), False), (SegmentConfig(effort_lag_s=lag), True)):
        points, _ = speed_points(find_segments(s, 0, cfg))
        for p in points:
            err = p.tau_f - float(TRUE.torque(p.speed))
            if ok:
                assert err == pytest.approx(0.0, abs=1e-3 * p.tau_f)
            else:
                assert err == pytest.approx(-300.0 * p.speed * lag, rel=0.02)
