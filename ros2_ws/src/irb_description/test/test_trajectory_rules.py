"""trajectory_rules: spacing, stamps, the consistency rule, the gate's limit notes (pure)."""
import numpy as np
import pytest

from irb_description.trajectory_rules import (MIN_POINT_SPACING_S, gate_limit_notes, spaced,
                                              stamps_ns, worst_inconsistency)


def test_spaced_keeps_the_ends_and_no_two_points_closer_than_the_minimum():
    rng = np.random.default_rng(3)
    for _ in range(50):
        t = np.sort(np.concatenate([[0.0, 1.0], rng.uniform(0, 1, rng.integers(0, 200))]))
        t = np.unique(t)
        k = spaced(t, 0.01)
        assert k[0] == 0 and k[-1] == t.size - 1
        assert np.all(np.diff(t[k]) >= 0.01 - 1e-9)
        # nothing dropped that had room: every dropped point is within 0.01 of a kept one
        dropped = np.setdiff1d(np.arange(t.size), k)
        assert all(np.min(np.abs(t[k] - t[j])) < 0.01 for j in dropped)


def test_stamps_are_nanoseconds():
    t = stamps_ns([0.1234567894, 2.9999999999996])
    assert t[0] == pytest.approx(0.123456789, abs=1e-15)
    assert t[1] == pytest.approx(3.0, abs=1e-15)


def quintic_samples(t):
    """q = t^5 - t^3 per joint (x 1, x -2), its rates exact."""
    c = np.array([1.0, -2.0])
    q = (t ** 5 - t ** 3)[:, None] * c
    qd = (5 * t ** 4 - 3 * t ** 2)[:, None] * c
    qdd = (20 * t ** 3 - 6 * t)[:, None] * c
    return q, qd, qdd


def test_consistent_rates_pass_and_an_unexplained_step_is_named():
    t = np.linspace(0.0, 1.0, 101)
    q, qd, qdd = quintic_samples(t)
    assert worst_inconsistency(t, q, qd, qdd) is None
    q[40:, 1] += 0.01                     # a 10 mrad step the declared velocities ignore
    bad = worst_inconsistency(t, q, qd, qdd)
    assert (bad.what, bad.point, bad.joint) == ('positions vs velocities', 39, 1)
    assert bad.excess > bad.allowed
    qd2 = qd.copy()
    qd2[60, 0] += 0.5                      # a velocity spike without acceleration
    bad = worst_inconsistency(t, quintic_samples(t)[0], qd2, qdd)
    assert bad.joint == 0 and bad.point in (59, 60)


def test_gate_limit_notes_name_the_joint_and_the_share():
    qdd = np.array([[0.0, 1.0, 60.0], [0.0, 0.0, 0.0]])
    tau = np.array([[10.0, 95.0, 1.0], [0.0, 0.0, 0.0]])
    notes = gate_limit_notes(qdd, tau, np.array([100.0, 100.0, 100.0]))
    assert len(notes) == 2
    assert 'joint 3 reaches 60 rad/s^2' in notes[0]
    assert 'joint 2 reaches 95.0%' in notes[1] and 'limit_scaling <= 0.947' in notes[1]
    assert gate_limit_notes(qdd * 0.5, tau * 0.5, np.full(3, 100.0)) == []
    assert MIN_POINT_SPACING_S == 1e-3
