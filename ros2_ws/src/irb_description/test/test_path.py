"""Circle path and its joint-space derivatives (eq. 5.1-5.6, 6.1-6.3)."""
import numpy as np
import pytest
from numpy.testing import assert_allclose

from irb_description.model import UnreachableError
from irb_description.path import CirclePath, joint_path, thesis_circle


def test_circle_points_and_theta_round_trip():
    c = CirclePath(np.array([0.6, 0.1, 0.2]), 0.1, start_angle=0.7, direction=-1)
    theta = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    p = c.point(theta)
    assert_allclose(np.linalg.norm(p - c.center, axis=1), 0.1, atol=1e-15)
    assert_allclose(p[:, 2], 0.2)
    assert_allclose(c.theta_of(p), theta, atol=1e-12)
    assert c.length == pytest.approx(2 * np.pi * 0.1)


def test_thesis_circle_starts_stretched_out():
    assert_allclose(thesis_circle().point(0.0), [0.75, 0.0, 0.13])   # thesis ch. 7 p0


@pytest.mark.parametrize('kwargs', [
    dict(center=np.array([0.6, 0, 0.13]), radius=0.0),
    dict(center=np.array([0.6, 0, 0.13]), radius=-0.1),
    dict(center=np.array([0.6, np.nan, 0.13]), radius=0.1),
    dict(center=np.array([0.6, 0, 0.13]), radius=0.1, direction=2),
])
def test_bad_circles_are_refused(kwargs):
    with pytest.raises(ValueError):
        CirclePath(**kwargs)


def test_path_derivatives_match_finite_differences():
    c = CirclePath(np.array([0.6, 0.05, 0.3]), 0.12, 0.3, -1)
    theta = np.linspace(0, 2 * np.pi, 13)
    h = 1e-5
    assert_allclose(c.d_point(theta), (c.point(theta + h) - c.point(theta - h)) / (2 * h),
                    atol=1e-9)
    assert_allclose(c.dd_point(theta),
                    (c.d_point(theta + h) - c.d_point(theta - h)) / (2 * h), atol=1e-9)


def test_phi_derivatives_match_finite_differences(model):
    c = thesis_circle()
    theta = np.linspace(0, 2 * np.pi, 37)
    h = 1e-5
    jp = joint_path(model, c, theta)
    plus, minus = joint_path(model, c, theta + h), joint_path(model, c, theta - h)
    assert_allclose(jp.dq, (plus.q - minus.q) / (2 * h), atol=1e-8)
    assert_allclose(jp.ddq, (plus.dq - minus.dq) / (2 * h), atol=1e-6)
    # the joint path really is the circle
    assert_allclose(np.array([model.fk(q) for q in jp.q]), c.point(theta), atol=1e-12)


def test_phi_second_derivative_by_second_difference(model):
    c = thesis_circle()
    theta = np.linspace(0.1, 6.0, 9)
    h = 1e-4
    jp = joint_path(model, c, theta)
    q_p, q_m = joint_path(model, c, theta + h).q, joint_path(model, c, theta - h).q
    assert_allclose(jp.ddq, (q_p - 2 * jp.q + q_m) / h**2, atol=1e-5)


def test_thesis_circle_is_reachable_within_speed_limits_at_10s(model):
    theta = np.linspace(0, 2 * np.pi, 721)
    jp = joint_path(model, thesis_circle(), theta)
    assert np.all(jp.q >= model.limits.lower) and np.all(jp.q <= model.limits.upper)
    qd = jp.dq * (2 * np.pi / 10.0)
    assert np.all(np.abs(qd).max(axis=0) < model.limits.velocity)
    # thesis fig. 5.4: joint 1 sweeps +-atan(0.15 / 0.6)
    assert np.degrees(jp.q[:, 0].max()) == pytest.approx(np.degrees(np.arcsin(0.15 / 0.6)),
                                                         abs=0.01)


def test_unreachable_circle_raises(model):
    with pytest.raises(UnreachableError):
        joint_path(model, CirclePath(np.array([1.5, 0.0, 0.13]), 0.15), np.linspace(0, 1, 5))
