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


def synthetic_series(speeds, joint=0, n=3, gravity=5.0, noise=0.0, rng=None):
    """Ideal tracking of eq. 4.1: tau = tau_f(v) + gravity * (1 + q) (position dependent)."""
    parts, t0 = [], 0.0
    for c in speeds:
        p = ConstantVelocityProfile.for_speed(c)
        t = np.arange(0, p.duration, 0.004032)
        v = np.zeros((len(t), n))
        v[:, joint] = p.velocity(t)
        q = np.zeros((len(t), n))
        q[:, joint] = p.position(t)
        tau = np.zeros((len(t), n))
        tau[:, joint] = TRUE.torque(v[:, joint]) + gravity * (1 + q[:, joint])
        if noise:
            tau += noise * rng.standard_normal(tau.shape)
        parts.append(JointSeries(t + t0, tuple(f'j{k}' for k in range(n)), q, v, tau))
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
    assert r.friction.valid_range == (0.02, 2.0) or np.allclose(r.friction.valid_range,
                                                                 (0.02, 2.0), rtol=1e-3)
    assert len(r.friction.polynomial_positive) == 8



def test_too_few_points_for_the_parametric_fit_is_a_joint_error_not_a_crash():
    from irb_identification.friction_fit import FitConfig, identify_points
    from irb_identification.segments import SpeedPoint
    pts = [SpeedPoint(speed=c, tau_plus=12 + c, tau_minus=-8 - c, tau_f=10 + c, f_pos=10 + c,
                      f_neg=-10 - c, sem=0.1, n_plus=1, n_minus=1) for c in (0.1, 0.5)]
    r = identify_points('joint_1', pts, FitConfig(min_speeds=2))
    assert r.friction is None and 'too few' in r.error
