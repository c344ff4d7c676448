"""A motion profile along the path: theta-speed on a theta grid (numpy only, no ROS).

Every planner (transcription, Fourier, trapezoid, time-optimal) hands its result over in this
one form, and the evaluator and the controller read only this form:

* nodes theta_k (N,) [rad], increasing, theta_0 = 0, theta_{N-1} = 2 pi;
* theta-speed theta_dot_k (N,) [rad/s] >= 0 (0 only at a rest end);
* between nodes b = theta_dot^2 is linear in theta, i.e. theta_ddot is constant on each
  interval: a_k = (b_{k+1} - b_k) / (2 (theta_{k+1} - theta_k)) [rad/s^2]
  (b' = 2 a, Verscheure et al. 2009). The time spent on an interval is then exactly
  dt_k = 2 dtheta_k / (theta_dot_k + theta_dot_{k+1}).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ThetaProfile:
    """theta (N,) [rad] and theta_dot (N,) [rad/s]; b = theta_dot^2 linear between nodes."""

    theta: np.ndarray
    theta_dot: np.ndarray

    def __post_init__(self):
        th = np.asarray(self.theta, float)
        td = np.asarray(self.theta_dot, float)
        object.__setattr__(self, 'theta', th)
        object.__setattr__(self, 'theta_dot', td)
        if th.ndim != 1 or th.shape != td.shape or th.size < 2:
            raise ValueError('theta and theta_dot must be 1-D of equal length >= 2')
        if not (np.all(np.isfinite(th)) and np.all(np.isfinite(td))):
            raise ValueError('profile contains non-finite values')
        if np.any(np.diff(th) <= 0):
            raise ValueError('theta must be strictly increasing')
        if np.any(td < 0) or np.any(td[:-1] + td[1:] <= 0):
            raise ValueError('theta_dot must be >= 0 and not 0 at two neighbouring nodes')

    @property
    def theta_ddot(self) -> np.ndarray:
        """a_k (N-1,) [rad/s^2], constant on interval k."""
        return np.diff(self.theta_dot ** 2) / (2.0 * np.diff(self.theta))

    @property
    def theta_ddot_nodes(self) -> np.ndarray:
        """theta_ddot at the nodes (N,) [rad/s^2]: mean of the two neighbouring intervals."""
        a = self.theta_ddot
        return np.concatenate([a[:1], 0.5 * (a[:-1] + a[1:]), a[-1:]])

    @property
    def times(self) -> np.ndarray:
        """t_k (N,) [s] at the nodes, t_0 = 0."""
        dt = 2.0 * np.diff(self.theta) / (self.theta_dot[:-1] + self.theta_dot[1:])
        return np.concatenate([[0.0], np.cumsum(dt)])

    @property
    def duration(self) -> float:
        """T [s]."""
        return float(self.times[-1])

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """theta, theta_dot, theta_ddot at times ``t`` (M,) [s] in [0, T], exactly.

        Constant theta_ddot per interval: theta = theta_k + theta_dot_k s + a_k s^2 / 2 with
        s = t - t_k.
        """
        t = np.clip(np.asarray(t, float), 0.0, self.duration)
        tk = self.times
        k = np.clip(np.searchsorted(tk, t, side='right') - 1, 0, self.theta.size - 2)
        s = t - tk[k]
        a = self.theta_ddot[k]
        theta = self.theta[k] + self.theta_dot[k] * s + 0.5 * a * s ** 2
        theta_dot = self.theta_dot[k] + a * s
        theta = np.minimum(theta, self.theta[k + 1])    # round-off at the interval end
        return theta, np.maximum(theta_dot, 0.0), a

    @classmethod
    def from_function(cls, theta_dot, n: int = 2001) -> 'ThetaProfile':
        """Sample a callable theta_dot(theta) [rad/s] on ``n`` uniform nodes over [0, 2 pi]."""
        theta = np.linspace(0.0, 2.0 * np.pi, n)
        return cls(theta, np.asarray(theta_dot(theta), float))
