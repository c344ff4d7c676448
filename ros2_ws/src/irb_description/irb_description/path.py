"""Paths for the TCP and their joint-space images Phi(theta), Phi'(theta), Phi''(theta).

Thesis eq. 5.1-5.5 and 6.1-6.3: q = Phi(theta), qd = Phi'(theta) thetad,
qdd = Phi''(theta) thetad^2 + Phi'(theta) thetadd. Phi comes from the closed-form IK;
Phi' = J^-1 p'(theta) and Phi'' = J^-1 (p''(theta) - dJ/dt Phi'), in closed form
(``RobotModel.arm_derivatives``, checked against pinocchio's Jacobian in the tests).
No ROS imports.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .model import RobotModel, UnreachableError


@dataclass(frozen=True)
class CirclePath:
    """Horizontal circle p(theta) = c + r (cos(s theta + phi0), sin(s theta + phi0), 0).

    center (3,) [m], radius [m], start_angle phi0 [rad], direction s = +1 (counter-clockwise
    seen from above) or -1; theta in [0, 2 pi] runs once around from the start point.
    The thesis circle: center (0.6, 0, 0.13) m, radius 0.15 m (eq. 5.15).
    """

    center: np.ndarray
    radius: float
    start_angle: float = 0.0
    direction: int = 1

    def __post_init__(self):
        c = np.asarray(self.center, float)
        object.__setattr__(self, 'center', c)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ValueError(f'center must be 3 finite numbers, got {self.center!r}')
        if not np.isfinite(self.radius) or self.radius <= 0:
            raise ValueError(f'radius must be > 0, got {self.radius!r}')
        if not np.isfinite(self.start_angle):
            raise ValueError('start_angle must be finite')
        if self.direction not in (1, -1):
            raise ValueError(f'direction must be +1 or -1, got {self.direction!r}')

    @property
    def length(self) -> float:
        """Path length [m]."""
        return 2.0 * np.pi * self.radius

    def _angle(self, theta):
        return self.direction * np.asarray(theta, float) + self.start_angle

    def point(self, theta) -> np.ndarray:
        """p(theta), (..., 3) [m]."""
        a = self._angle(theta)
        return self.center + self.radius * np.stack(
            [np.cos(a), np.sin(a), np.zeros_like(a)], axis=-1)

    def d_point(self, theta) -> np.ndarray:
        """p'(theta), (..., 3) [m/rad]."""
        a = self._angle(theta)
        return self.direction * self.radius * np.stack(
            [-np.sin(a), np.cos(a), np.zeros_like(a)], axis=-1)

    def dd_point(self, theta) -> np.ndarray:
        """p''(theta), (..., 3) [m/rad^2]."""
        a = self._angle(theta)
        return -self.radius * np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=-1)

    def theta_of(self, p: np.ndarray) -> np.ndarray:
        """theta in [0, 2 pi) of the point(s) p (..., 3) [m], by atan2 about the centre (5.6)."""
        p = np.asarray(p, float)
        ang = np.arctan2(p[..., 1] - self.center[1], p[..., 0] - self.center[0])
        theta = np.mod(self.direction * (ang - self.start_angle), 2.0 * np.pi)
        return np.where(theta >= 2.0 * np.pi, 0.0, theta)   # mod gives 2 pi for -eps


@dataclass(frozen=True)
class JointPath:
    """Phi, Phi', Phi'' sampled on a theta grid: theta (N,), q/dq/ddq (N, 3)."""

    theta: np.ndarray
    q: np.ndarray      # [rad]
    dq: np.ndarray     # [rad/rad]
    ddq: np.ndarray    # [rad/rad^2]


def joint_path(model: RobotModel, path: CirclePath, theta: np.ndarray,
               branch: str = 'elbow_up') -> JointPath:
    """Phi(theta), Phi'(theta), Phi''(theta) of ``path`` at the grid ``theta`` (N,) [rad].

    Raises model.UnreachableError when any point is outside the workspace or joint limits.
    """
    theta = np.atleast_1d(np.asarray(theta, float))
    q = model.ik_many(path.point(theta), branch)
    dq, ddq = model.arm_derivatives(q, path.d_point(theta), path.dd_point(theta))
    return JointPath(theta, q, dq, ddq)


def thesis_circle() -> CirclePath:
    """The thesis's circle: centre (0.6, 0, 0.13) m, r = 0.15 m, start at (0.75, 0, 0.13)."""
    return CirclePath(np.array([0.6, 0.0, 0.13]), 0.15, 0.0, 1)


def check_joint_path(model: RobotModel, path: CirclePath, samples: int = 4096,
                     branch: str = 'elbow_up') -> None:
    """Check the whole joint motion along ``path``, not only points: reachable everywhere,
    continuous (joint 1 unwrapped across +-180 deg) and inside the position limits between the
    samples too. Raises UnreachableError naming the joint, theta [rad] and the TCP point.

    ``samples`` theta values over [0, 2 pi]; between two samples a joint cannot pass a limit
    unseen: the check uses max(q_k, q_k+1) + |q''| dtheta^2 / 8 (the largest excursion of a
    function with that curvature above its chord), q'' by finite differences.
    """
    theta = np.linspace(0.0, 2.0 * np.pi, samples)
    pts = path.point(theta)
    try:
        q = model.ik_many(pts, branch, check_limits=False)
    except UnreachableError as exc:
        raise UnreachableError(f'the path leaves the workspace: {exc}') from None
    q[:, 0] = np.unwrap(q[:, 0])
    q[:, 0] -= 2 * np.pi * np.round(q[0, 0] / (2 * np.pi))    # start inside (-pi, pi]
    h = theta[1] - theta[0]
    ddq = np.zeros_like(q)
    ddq[1:-1] = (q[2:] - 2 * q[1:-1] + q[:-2]) / h ** 2
    curv = np.maximum(np.abs(ddq[:-1]), np.abs(ddq[1:])) * h ** 2 / 8
    hi_seg = np.maximum(q[:-1], q[1:]) + curv
    lo_seg = np.minimum(q[:-1], q[1:]) - curv
    lower, upper = model.limits.lower, model.limits.upper
    for i, name in enumerate(model.joint_names):
        out = (hi_seg[:, i] > upper[i]) | (lo_seg[:, i] < lower[i])
        if np.any(out):
            k = int(np.argmax(out))
            side, lim = ((upper[i], 'upper') if hi_seg[k, i] > upper[i]
                         else (lower[i], 'lower'))
            raise UnreachableError(
                f'{name} crosses its {lim} limit ({np.degrees(side):.0f} deg) along the path '
                f'near theta = {theta[k]:.4f} rad, point {np.round(pts[k], 4).tolist()} m '
                f'({name} = {np.degrees(q[k, i]):.1f} deg there'
                + (', continuing across +-180 deg' if i == 0 and abs(q[k, i]) > np.pi - 0.2
                   else '') + ')')
