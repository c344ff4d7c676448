"""A six-joint time trajectory after its end: the final pose of all six joints with zero
rates (the three-joint row layout once zeroed q of joints 4-6 there, and pdplus joints:=6 then
stopped every time-driven run with a tracking error at its end)."""
import numpy as np

from irb_control.profiles import TimeTrajectory


def test_after_the_end_the_final_pose_of_six_joints():
    t = np.linspace(0.0, 1.0, 11)
    q = np.outer(t, [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]) + 0.05
    traj = TimeTrajectory(t, q, np.gradient(q, t, axis=0), np.zeros_like(q))
    for row in (traj.sample(2.0), np.array(traj.sample_list(2.0))):
        np.testing.assert_array_equal(row[:6], q[-1])
        np.testing.assert_array_equal(row[6:], 0.0)


def test_three_joints_unchanged():
    t = np.linspace(0.0, 1.0, 11)
    q = np.outer(t, [0.1, 0.2, 0.3])
    traj = TimeTrajectory(t, q, np.gradient(q, t, axis=0), np.ones_like(q))
    for row in (traj.sample(2.0), np.array(traj.sample_list(2.0))):
        np.testing.assert_array_equal(row, np.r_[q[-1], np.zeros(6)])
