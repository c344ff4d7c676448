"""plan_checks on its own (numpy only): what the controller will demand (issue 14, defect 9)."""
import numpy as np
import pytest
from irb_control.plan_checks import PlanLimits, PlanRejected, check_joint_plan

T = 0.004032
LIM = PlanLimits(lower=np.full(3, -3.0), upper=np.full(3, 3.0), velocity=np.full(3, 2.5),
                 torque=np.full(3, 500.0))


def quintic(n=500):
    """A smooth rest-to-rest move of 0.6 rad on every joint, sampled every period."""
    t = np.arange(n) * T
    s = t / t[-1]
    q = (0.6 * (10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5))[:, None] * np.ones(3)
    qd = (0.6 * (30 * s ** 2 - 60 * s ** 3 + 30 * s ** 4) / t[-1])[:, None] * np.ones(3)
    qdd = (0.6 * (60 * s - 180 * s ** 2 + 120 * s ** 3) / t[-1] ** 2)[:, None] * np.ones(3)
    return t, q, qd, qdd


def trapezoid(t, accel=8.0, speed=0.6, t0=0.1):
    """Velocity trapezoid with piecewise constant acceleration (switches at arbitrary times):
    the shape of the identification sweeps (eq. 4.1)."""
    t1 = speed / accel
    qdd = np.where(t < t0, 0.0, np.where(t < t0 + t1, accel, 0.0))
    qd = np.clip((t - t0) * accel, 0.0, speed)
    q = np.where(t < t0, 0.0, np.where(t < t0 + t1, 0.5 * accel * (t - t0) ** 2,
                                      0.5 * accel * t1 ** 2 + speed * (t - t0 - t1)))
    return q, qd, qdd


def test_smooth_plan_passes_and_reports_peaks():
    t, q, qd, qdd = quintic()
    out = check_joint_plan(t, q, qd, qdd, LIM)
    assert out['points'] == t.size and max(out['peak_speed']) == pytest.approx(
        np.abs(qd).max())


@pytest.mark.parametrize('t0', [0.1, 0.1 + 0.5 * T, 0.1 + 0.9 * T])
def test_accelerations_switching_at_or_between_points_pass(t0):
    # an identification sweep was refused by the trapezoid rule: "change +0.032 over 4.03 ms
    # while the declared rates explain +0.01613" at the end of its 8 rad/s^2 ramp
    t = np.arange(300) * T
    q, qd, qdd = trapezoid(t, t0=t0)
    z = np.zeros_like(t)
    check_joint_plan(t, np.c_[q, z, z], np.c_[qd, z, z], np.c_[qdd, z, z], LIM)


@pytest.mark.parametrize('fault, needle', [
    ('step', 'inconsistent positions vs velocities: joint 1 at point 99'),
    ('chatter', 'inconsistent positions vs velocities: joint 3'),
    ('wrong accelerations', 'inconsistent velocities vs accelerations: joint 2'),
    ('acceleration', 'acceleration limit: joint 1 at point 50'),
    ('speed', 'speed limit: joint 2'),
    ('position', 'position limit: joint 3'),
    ('nan', 'non-finite velocities'),
    ('time', 'time not strictly increasing at point 10'),
])
def test_faults_are_refused_with_the_joint_and_point(fault, needle):
    t, q, qd, qdd = quintic()
    if fault == 'step':
        q[100:, 0] += 1.0
    elif fault == 'chatter':
        q[:, 2] += 0.04 * (-1) ** np.arange(t.size)
    elif fault == 'wrong accelerations':
        qdd[200:, 1] += 5.0
    elif fault == 'acceleration':
        qdd[50, 0] = 1e5
    elif fault == 'speed':
        qd[10, 1] = 3.0
    elif fault == 'position':
        q[300:, 2] += 2.6
    elif fault == 'nan':
        qd[5, 0] = np.nan
    else:
        t[10] = t[9]
    with pytest.raises(PlanRejected, match=needle):
        check_joint_plan(t, q, qd, qdd, LIM)


def test_size_and_feed_forward_torque():
    t, q, qd, qdd = quintic()
    small = PlanLimits(LIM.lower, LIM.upper, LIM.velocity, LIM.torque, max_points=100)
    with pytest.raises(PlanRejected, match='more than max_plan_points = 100'):
        check_joint_plan(t, q, qd, qdd, small)
    with pytest.raises(PlanRejected, match='torque: joint 1'):
        check_joint_plan(t, q, qd, qdd, LIM, lambda q, qd, qdd: 460.0 + 0 * q)
    out = check_joint_plan(t, q, qd, qdd, LIM, lambda q, qd, qdd: 440.0 + 0 * q)
    assert out['peak_feed_forward'] == [440.0] * 3
