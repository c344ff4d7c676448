"""What the model computes for a circle: joint ranges, speeds and torques (numpy only)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .model import RobotModel
from .path import CirclePath, joint_path


@dataclass(frozen=True)
class CircleReport:
    """Figures of a circle run at constant theta-speed 2 pi / period.

    Arrays are (3,) per actuated joint: ranges [rad], peak |qd| [rad/s], peak |tau| [N m]
    (rigid body + nominal friction), energy [J] = int sum_i |tau_i qd_i| dt (eq. 6.9).
    """

    path_length: float
    joint_path_length: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    peak_speed: np.ndarray
    peak_torque: np.ndarray
    energy: float
    period: float


def circle_report(model: RobotModel, path: CirclePath, period: float, n: int = 721
                  ) -> CircleReport:
    """Evaluate ``path`` at uniform theta-speed over ``period`` [s] on ``n`` grid points."""
    theta = np.linspace(0.0, 2.0 * np.pi, n)
    jp = joint_path(model, path, theta)
    thetad = 2.0 * np.pi / period
    qd = jp.dq * thetad
    qdd = jp.ddq * thetad**2
    tau = np.array([model.inverse_dynamics_with_friction(jp.q[k], qd[k], qdd[k])
                    for k in range(n)])
    power = np.abs(tau * qd).sum(axis=1)
    t = theta / thetad
    return CircleReport(
        path_length=path.length,
        joint_path_length=np.abs(np.diff(jp.q, axis=0)).sum(axis=0),
        q_min=jp.q.min(axis=0), q_max=jp.q.max(axis=0),
        peak_speed=np.abs(qd).max(axis=0), peak_torque=np.abs(tau).max(axis=0),
        energy=float(np.trapezoid(power, t)), period=period)
