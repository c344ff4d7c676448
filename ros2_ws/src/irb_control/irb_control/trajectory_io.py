"""JointTrajectory <-> profiles (message adapter for pdplus; the math is in profiles.py).

Accepted on /planned_trajectory (trajectory_msgs/JointTrajectory):

* theta-profile: joint_names == ['theta']; each point carries positions [theta] [rad],
  velocities [theta_dot] [rad/s], accelerations [theta_ddot] [rad/s^2] (optional, else
  differentiated) and time_from_start. The controller maps it through Phi of its path.
* joint trajectory: joint_names contain joint_1..joint_3 (extra joints ignored); points carry
  positions, velocities and accelerations (optional: differentiated) and time_from_start.
  theta-driven mode: theta is computed from FK of the points (the trajectory must lie on the
  configured path); time-driven mode: q(t) is used as it is.
"""
from __future__ import annotations

import numpy as np
from irb_description.model import RobotModel
from irb_description.path import PathBase
from irb_description.stamps import sec_nanosec
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from .profiles import (PathProfile, ProfileError, TimeTrajectory,
                       profile_from_joint_trajectory, profile_from_theta_samples)

THETA_JOINT = 'theta'


def _column(points, attr: str, idx: list[int]) -> np.ndarray | None:
    rows = [getattr(p, attr) for p in points]
    if any(len(r) == 0 for r in rows):
        return None
    if any(len(r) <= max(idx) for r in rows):
        raise ProfileError(f'point {attr} shorter than joint_names')
    return np.array([[r[i] for i in idx] for r in rows], float)


def _times(msg: JointTrajectory) -> np.ndarray:
    return np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9
                     for p in msg.points], float)


def _arrays(msg: JointTrajectory, idx: list[int]):
    if len(msg.points) < 2:
        raise ProfileError('trajectory needs at least 2 points')
    t = _times(msg)
    pos = _column(msg.points, 'positions', idx)
    if pos is None:
        raise ProfileError('trajectory points need positions')
    vel = _column(msg.points, 'velocities', idx)
    acc = _column(msg.points, 'accelerations', idx)
    if vel is None:
        vel = np.gradient(pos, t, axis=0)
    if acc is None:
        acc = np.gradient(vel, t, axis=0)
    return t, pos, vel, acc


def profile_from_msg(msg: JointTrajectory, model: RobotModel, path: PathBase,
                     time_driven: bool, min_theta_dot: float = 0.05
                     ) -> PathProfile | TimeTrajectory:
    """The profile a JointTrajectory describes (see module docstring); ProfileError if bad."""
    names = list(msg.joint_names)
    if names == [THETA_JOINT]:
        t, th, thd, thdd = _arrays(msg, [0])
        if time_driven:
            prof = profile_from_theta_samples(model, path, th[:, 0], thd[:, 0], thdd[:, 0], t,
                                              min_theta_dot)
            # time-driven: q(t) of the theta-profile at the message's times
            rows = np.array([prof.sample(x) for x in th[:, 0]])
            return TimeTrajectory(t - t[0], rows[:, 2:5], rows[:, 5:8], rows[:, 8:11])
        return profile_from_theta_samples(model, path, th[:, 0], thd[:, 0], thdd[:, 0], t,
                                          min_theta_dot)
    try:
        idx = [names.index(n) for n in model.joint_names]
    except ValueError as exc:
        raise ProfileError(f'joint_names {names} must be [theta] or contain '
                           f'{model.joint_names}') from exc
    t, q, qd, qdd = _arrays(msg, idx)
    if time_driven:
        return TimeTrajectory(t - t[0], q, qd, qdd)
    return profile_from_joint_trajectory(model, path, t, q, qd, qdd, min_theta_dot)


def theta_profile_msg(t: np.ndarray, theta: np.ndarray, theta_dot: np.ndarray,
                      theta_ddot: np.ndarray) -> JointTrajectory:
    """A theta-profile as JointTrajectory (joint_names ['theta'])."""
    msg = JointTrajectory(joint_names=[THETA_JOINT])
    for ti, a, b, c in zip(t, theta, theta_dot, theta_ddot):
        p = JointTrajectoryPoint(positions=[float(a)], velocities=[float(b)],
                                 accelerations=[float(c)])
        p.time_from_start.sec, p.time_from_start.nanosec = sec_nanosec(float(ti))
        msg.points.append(p)
    return msg
