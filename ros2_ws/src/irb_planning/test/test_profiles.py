"""Profiles without a solver: theta-profile algebra, trapezoid, Fourier evaluation."""
import numpy as np
import pytest
from numpy.testing import assert_allclose

from irb_planning.baselines import stribeck_envelope, trapezoid_profile
from irb_planning.fourier import fourier_basis, fourier_theta_ddot, fourier_theta_dot
from irb_planning.profile import ThetaProfile


def test_constant_speed_profile_times_and_sampling():
    pr = ThetaProfile(np.linspace(0, 2 * np.pi, 11), np.full(11, 2.0))
    assert_allclose(pr.duration, np.pi, rtol=1e-12)
    theta, theta_dot, theta_ddot = pr.sample(np.array([0.0, 1.0, np.pi]))
    assert_allclose(theta, [0.0, 2.0, 2 * np.pi], atol=1e-12)
    assert_allclose(theta_dot, 2.0)
    assert_allclose(theta_ddot, 0.0)


def test_sampling_is_exact_for_constant_acceleration():
    # theta = t^2 / 2 (a = 1) from rest: b = 2 theta is linear, so any grid is exact
    theta = np.sort(np.r_[0.0, np.random.default_rng(1).uniform(0, 2 * np.pi, 7), 2 * np.pi])
    pr = ThetaProfile(theta, np.sqrt(2 * theta))
    assert_allclose(pr.duration, np.sqrt(4 * np.pi), rtol=1e-12)
    t = np.linspace(0, pr.duration, 50)
    th, thd, thdd = pr.sample(t)
    assert_allclose(th, 0.5 * t ** 2, atol=1e-12)
    assert_allclose(thd, t, atol=1e-12)
    assert_allclose(thdd, 1.0, atol=1e-12)


def test_quadratic_profile_with_constant_acceleration_equals_the_linear_one():
    theta = np.linspace(0, 2 * np.pi, 9)
    lin = ThetaProfile(theta, np.sqrt(2 * theta))            # a = 1 everywhere
    quad = ThetaProfile(theta, np.sqrt(2 * theta), np.ones(9))
    assert quad.quadratic and not lin.quadratic
    assert_allclose(quad.duration, lin.duration, rtol=1e-12)
    t = np.linspace(0, lin.duration, 40)
    for a, b in zip(quad.sample(t), lin.sample(t)):
        assert_allclose(a, b, atol=1e-12)


def test_quadratic_profile_follows_linear_theta_ddot():
    # theta_ddot = 1 + theta / 2 from theta_dot = 1: b = 1 + 2 theta + theta^2 / 2 (exact
    # quadratic); time law against the exact integral of dtheta / sqrt(b)
    theta = np.linspace(0, 2 * np.pi, 21)
    b = 1 + 2 * theta + theta ** 2 / 2
    pr = ThetaProfile(theta, np.sqrt(b), 1 + theta / 2)
    # b = ((theta + 2)^2 - 2) / 2: T = sqrt(2) (acosh((2 pi + 2) / sqrt 2) - acosh(sqrt 2))
    t_exact = np.sqrt(2) * (np.arccosh((2 * np.pi + 2) / np.sqrt(2)) - np.arccosh(np.sqrt(2)))
    assert_allclose(pr.duration, t_exact, rtol=1e-13)
    th, thd, thdd = pr.sample(np.linspace(0, pr.duration, 30))
    assert_allclose(thd, np.sqrt(1 + 2 * th + th ** 2 / 2), rtol=1e-12)
    assert_allclose(thdd, 1 + th / 2, rtol=1e-12)
    assert_allclose(pr.theta_ddot_nodes, 1 + theta / 2)
    slow = pr.scaled_in_time(2.0)
    assert_allclose(slow.duration, 2 * pr.duration, rtol=1e-12)
    assert_allclose(slow.theta_ddot_nodes, pr.theta_ddot_nodes / 4)


def test_quadratic_profile_rejects_inconsistent_accelerations():
    theta = np.linspace(0, 2 * np.pi, 9)
    with pytest.raises(ValueError, match='inconsistent'):
        ThetaProfile(theta, np.full(9, 2.0), np.full(9, 0.5))
    with pytest.raises(ValueError):
        ThetaProfile(theta, np.full(9, 2.0), np.zeros(8))


def test_profile_rejects_bad_input():
    with pytest.raises(ValueError):
        ThetaProfile(np.array([0.0, 1.0]), np.array([0.0, 0.0]))
    with pytest.raises(ValueError):
        ThetaProfile(np.array([0.0, np.nan]), np.array([1.0, 1.0]))


@pytest.mark.parametrize('duration, ramp', [(1.0, 0.1), (10.0, 0.1), (3.0, 0.5)])
def test_trapezoid_profile(duration, ramp):
    pr = trapezoid_profile(duration, ramp)
    assert_allclose(pr.duration, duration, rtol=1e-12)
    assert pr.theta_dot[0] == 0 and pr.theta_dot[-1] == 0
    v_c = 2 * np.pi / (duration * (1 - ramp))
    assert_allclose(pr.theta_dot.max(), v_c, rtol=1e-12)
    a = pr.theta_ddot
    assert_allclose(np.abs(a[np.abs(a) > 1e-9]), v_c / (ramp * duration), rtol=1e-9)
    # time at the end of the ramp
    t_end_ramp = pr.times[np.argmax(pr.theta_dot >= v_c * (1 - 1e-12))]
    assert_allclose(t_end_ramp, ramp * duration, rtol=1e-9)


def test_fourier_profile_evaluation():
    c = np.array([1.5, 0.2, -0.1, 0.05, 0.3, 0.0, -0.02])     # order 3
    th = np.linspace(0, 2 * np.pi, 2001)
    h = fourier_theta_dot(c, th)
    expected = (1.5 + 0.2 * np.sin(th) - 0.1 * np.sin(2 * th) + 0.05 * np.sin(3 * th)
                + 0.3 * np.cos(th) - 0.02 * np.cos(3 * th))
    assert_allclose(h, expected, atol=1e-12)
    assert_allclose(np.trapezoid(h, th) / (2 * np.pi), c[0], atol=1e-9)   # eq. 6.5
    dh = np.gradient(h, th)
    assert_allclose(fourier_theta_ddot(c, th)[5:-5], (dh * h)[5:-5], atol=1e-4)   # eq. 6.6
    B, dB = fourier_basis(th, 3)
    assert B.shape == dB.shape == (th.size, 7)


@pytest.mark.parametrize('df, fv, vs', [(6.0, 25.0, 0.05), (3.0, 12.0, 0.05), (10.0, 1.0, 0.1)])
def test_stribeck_envelope_is_a_concave_majorant(df, fv, vs):
    u1, u2, margin = stribeck_envelope(df, fv, vs)
    assert 0 < u1 < u2

    def G(u):
        return df * np.exp(-u) + fv * vs * np.sqrt(u)

    def G_hat(u):
        chord = G(u1) + (G(u2) - G(u1)) / (u2 - u1) * (u - u1) + margin
        return np.where((u > u1) & (u < u2), chord, G(u))
    u = np.concatenate([[0.0], np.geomspace(1e-7, 1e3, 20001)])
    gh = G_hat(u)
    assert np.all(gh >= G(u) - 1e-12)
    # concave: every point lies on or above the chord of its neighbours (uneven spacing)
    w = (u[1:-1] - u[:-2]) / (u[2:] - u[:-2])
    assert np.all(gh[1:-1] >= (1 - w) * gh[:-2] + w * gh[2:] - 1e-9)
    assert margin < 1e-6 * df


def test_time_law_is_the_exact_integral_against_quad():
    # the closed form of int ds / sqrt(b0 + 2 a0 s + kappa s^2) against scipy's adaptive
    # quadrature (1/sqrt weight at rest ends), over random intervals of every kind
    from scipy.integrate import quad

    from irb_planning.profile import time_to
    rng = np.random.default_rng(5)
    checked = 0
    for i in range(600):
        h = rng.uniform(1e-3, 0.5)
        kind = i % 3
        if kind == 0:            # leaving rest
            b0, a0, a1 = 0.0, rng.uniform(1e-3, 5), rng.uniform(-5, 5)
        elif kind == 1:          # reaching rest: b(h) = 0
            a0, a1 = rng.uniform(-5, 5), -rng.uniform(1e-2, 5)
            b0 = -(a0 + a1) * h
            if b0 <= 0:
                continue
        else:
            b0 = rng.uniform(1e-3, 10)
            a0 = rng.normal() * 10 ** rng.uniform(-6, 1)
            a1 = rng.normal() * 10 ** rng.uniform(-6, 1)
        kappa = (a1 - a0) / h

        def b(x):
            return b0 + 2 * a0 * x + kappa * x * x
        if np.min(b(np.linspace(0, h, 1001))[1:-1]) <= 1e-6:
            continue
        b_end = 0.0 if kind == 1 else None
        got = float(time_to(b0, a0, kappa, h, b_end))
        if kind == 0:
            # b = x (2 a0 + kappa x): the weight takes the 1/sqrt(x)
            ref = quad(lambda x: 1 / np.sqrt(2 * a0 + kappa * x), 0, h,
                       weight='alg', wvar=(-0.5, 0),
                       epsabs=0, epsrel=1e-12)[0]
        elif kind == 1:
            # b = (h - x) (-2 a1 + kappa (h - x))
            ref = quad(lambda x: 1 / np.sqrt(-2 * a1 + kappa * (h - x)), 0, h, weight='alg',
                       wvar=(0, -0.5), epsabs=0, epsrel=1e-12)[0]
        else:
            ref = quad(lambda x: 1 / np.sqrt(b(x)), 0, h, epsabs=0, epsrel=1e-12)[0]
        assert got == pytest.approx(ref, rel=1e-9), (kind, b0, a0, a1, h)
        checked += 1
    assert checked > 300


def test_sample_and_theta_at_invert_each_other():
    theta = np.linspace(0, 2 * np.pi, 21)
    b = 1 + 2 * theta + theta ** 2 / 2
    pr = ThetaProfile(theta, np.sqrt(b), 1 + theta / 2)
    th = np.linspace(0, 2 * np.pi, 77)
    t, thd, thdd = pr.theta_at(th)
    th2, thd2, thdd2 = pr.sample(t)
    assert_allclose(th2, th, atol=1e-12)
    assert_allclose(thd2, thd, rtol=1e-12)
    # b = ((theta + 2)^2 - 2) / 2: t(theta) = sqrt(2) (acosh((theta + 2)/sqrt 2) - acosh(sqrt 2))
    exact = np.sqrt(2) * (np.arccosh((th + 2) / np.sqrt(2)) - np.arccosh(np.sqrt(2)))
    assert_allclose(t, exact, rtol=1e-12, atol=1e-15)


def test_quadratic_profile_that_dips_below_zero_is_refused():
    # the shape of the 30 s defect: leaving rest with theta_ddot < 0, so b < 0 just after it
    td = np.array([0.0, np.sqrt(0.5), 0.0])
    a = np.array([-0.55, 1.05, -1.55])          # consistent: b1 - b0 = (a0 + a1) * 1 etc.
    with pytest.raises(ValueError, match='negative'):
        ThetaProfile(np.array([0.0, 1.0, 2.0]), td, a)
