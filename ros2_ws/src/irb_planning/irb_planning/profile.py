"""A motion profile along the path: theta-speed on a theta grid (numpy only, no ROS).

Every planner (transcription, Fourier, trapezoid, time-optimal) hands its result over in this
one form, and the evaluator and the controller read only this form:

* nodes theta_k (N,) [rad], increasing, theta_0 = 0, theta_{N-1} = 2 pi;
* theta-speed theta_dot_k (N,) [rad/s] >= 0 (0 only at a rest end);
* optionally theta_ddot_k (N,) [rad/s^2] at the nodes.

Between nodes, b = theta_dot^2 follows b' = 2 theta_ddot (Verscheure et al. 2009):

* without node accelerations ("linear" profile), b is linear in theta on each interval, so
  theta_ddot is constant there, a_k = (b_{k+1} - b_k) / (2 dtheta_k);
* with node accelerations ("quadratic" profile, what the transcription returns), theta_ddot is
  linear in theta on each interval and b quadratic:
  b(theta_k + s) = b_k + 2 a_k s + (a_{k+1} - a_k) s^2 / dtheta_k, which needs
  b_{k+1} - b_k = (a_k + a_{k+1}) dtheta_k (checked).

Time law. A linear profile spends exactly dt_k = 2 dtheta_k / (theta_dot_k + theta_dot_{k+1})
on interval k. A quadratic profile splits every interval into ``TIME_SUBSTEPS`` equal pieces
and applies that rule on each piece (b from the quadratic at the piece ends); the relative error
against the exact integral of dtheta / sqrt(b) is O((dtheta / TIME_SUBSTEPS)^2). The
transcription's duration uses the same rule, so planned and sampled durations agree exactly.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: pieces per interval of the time law of a quadratic profile
TIME_SUBSTEPS = 4
#: relative tolerance of the check b_{k+1} - b_k = (a_k + a_{k+1}) dtheta_k
CONSISTENCY_RTOL = 1e-6


def quadratic_b(b0, a0, a1, h, s):
    """b at offset s [rad] into an interval of length h with node b0, a0, a1 (broadcasting)."""
    return b0 + 2.0 * a0 * s + (a1 - a0) / h * s ** 2


def linear_node_accelerations(theta: np.ndarray, b: np.ndarray) -> np.ndarray:
    """theta_ddot at the nodes (N,) [rad/s^2] of b = theta_dot^2 (N,) linear between nodes
    theta (N,): the mean of the two neighbouring intervals' (b_{k+1} - b_k) / (2 dtheta_k)."""
    a = np.diff(b) / (2.0 * np.diff(theta))
    return np.concatenate([a[:1], 0.5 * (a[:-1] + a[1:]), a[-1:]])


@dataclass(frozen=True)
class ThetaProfile:
    """theta (N,) [rad], theta_dot (N,) [rad/s] and optionally theta_ddot (N,) [rad/s^2] at
    the nodes; see the module docstring for what lies between the nodes."""

    theta: np.ndarray
    theta_dot: np.ndarray
    node_theta_ddot: np.ndarray | None = None

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
        if self.node_theta_ddot is not None:
            a = np.asarray(self.node_theta_ddot, float)
            object.__setattr__(self, 'node_theta_ddot', a)
            if a.shape != th.shape or not np.all(np.isfinite(a)):
                raise ValueError('theta_ddot must be finite with the shape of theta')
            b, h = td ** 2, np.diff(th)
            gap = np.abs(np.diff(b) - (a[:-1] + a[1:]) * h)
            if np.any(gap > CONSISTENCY_RTOL * max(1.0, float(b.max()))):
                raise ValueError('theta_ddot inconsistent with theta_dot: b_{k+1} - b_k != '
                                 f'(a_k + a_{{k+1}}) dtheta_k (worst {gap.max():.3g})')
            b_pieces = self._pieces(th, b, a)[1]     # clamped at 0 (round-off)
            if np.any(b_pieces[:-1] + b_pieces[1:] <= 0):
                raise ValueError('theta_dot^2 of the quadratic profile goes negative or stops '
                                 'inside an interval')
        object.__setattr__(self, '_law', self._time_law())

    @property
    def quadratic(self) -> bool:
        """True if theta_ddot is linear in theta between nodes (node accelerations given)."""
        return self.node_theta_ddot is not None

    @staticmethod
    def _pieces(th, b, a):
        """theta and b at the TIME_SUBSTEPS pieces of every interval, ((M,), (M,))."""
        h = np.diff(th)
        s = h[:, None] * (np.arange(TIME_SUBSTEPS) / TIME_SUBSTEPS)[None, :]
        bs = quadratic_b(b[:-1, None], a[:-1, None], a[1:, None], h[:, None], s)
        theta = np.append((th[:-1, None] + s).ravel(), th[-1])
        return theta, np.append(np.maximum(bs.ravel(), 0.0), b[-1])

    def _time_law(self):
        """Pieces with b linear on each: theta_j, theta_dot_j (M,), t_j (M,)."""
        if self.quadratic:
            theta, b = self._pieces(self.theta, self.theta_dot ** 2, self.node_theta_ddot)
            v = np.sqrt(b)
        else:
            theta, v = self.theta, self.theta_dot
        dt = 2.0 * np.diff(theta) / (v[:-1] + v[1:])
        return theta, v, np.concatenate([[0.0], np.cumsum(dt)])

    @property
    def theta_ddot(self) -> np.ndarray:
        """Linear profile: a_k (N-1,) [rad/s^2], constant on interval k. Quadratic profile:
        the mean theta_ddot of each interval, (a_k + a_{k+1}) / 2 (N-1,)."""
        if self.quadratic:
            return 0.5 * (self.node_theta_ddot[:-1] + self.node_theta_ddot[1:])
        return np.diff(self.theta_dot ** 2) / (2.0 * np.diff(self.theta))

    @property
    def theta_ddot_nodes(self) -> np.ndarray:
        """theta_ddot at the nodes (N,) [rad/s^2]: the node values of a quadratic profile;
        for a linear one the mean of the two neighbouring intervals."""
        if self.quadratic:
            return self.node_theta_ddot
        return linear_node_accelerations(self.theta, self.theta_dot ** 2)

    @property
    def times(self) -> np.ndarray:
        """t_k (N,) [s] at the nodes, t_0 = 0."""
        t = self._law[2]
        return t[::TIME_SUBSTEPS] if self.quadratic else t

    @property
    def duration(self) -> float:
        """T [s]."""
        return float(self._law[2][-1])

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """theta, theta_dot, theta_ddot at times ``t`` (M,) [s] in [0, T].

        theta(t) follows the time law (exact for a linear profile: constant theta_ddot per
        interval, theta = theta_k + theta_dot_k s + a_k s^2 / 2 with s = t - t_k). For a
        quadratic profile theta_dot and theta_ddot are then those of the quadratic b at that
        theta.
        """
        th, v, tk = self._law
        t = np.clip(np.asarray(t, float), 0.0, tk[-1])
        k = np.clip(np.searchsorted(tk, t, side='right') - 1, 0, th.size - 2)
        s = t - tk[k]
        a = (v[k + 1] ** 2 - v[k] ** 2) / (2.0 * (th[k + 1] - th[k]))
        theta = np.minimum(th[k] + v[k] * s + 0.5 * a * s ** 2, th[k + 1])
        theta_dot = np.maximum(v[k] + a * s, 0.0)
        if not self.quadratic:
            return theta, theta_dot, a
        i = np.clip(np.searchsorted(self.theta, theta, side='right') - 1, 0,
                    self.theta.size - 2)
        h = self.theta[i + 1] - self.theta[i]
        a0, a1 = self.node_theta_ddot[i], self.node_theta_ddot[i + 1]
        sq = theta - self.theta[i]
        b = quadratic_b(self.theta_dot[i] ** 2, a0, a1, h, sq)
        return theta, np.sqrt(np.maximum(b, 0.0)), a0 + (a1 - a0) * sq / h

    def scaled_in_time(self, factor: float) -> 'ThetaProfile':
        """The same path speed shape run ``factor`` times slower (duration x factor)."""
        a = None if self.node_theta_ddot is None else self.node_theta_ddot / factor ** 2
        return ThetaProfile(self.theta, self.theta_dot / factor, a)

    @classmethod
    def from_function(cls, theta_dot, n: int = 2001) -> 'ThetaProfile':
        """Sample a callable theta_dot(theta) [rad/s] on ``n`` uniform nodes over [0, 2 pi]."""
        theta = np.linspace(0.0, 2.0 * np.pi, n)
        return cls(theta, np.asarray(theta_dot(theta), float))
