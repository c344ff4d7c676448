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

Time law (exact). On every interval the time is the exact integral of dtheta / theta_dot of
the profile as interpolated: for a linear profile 2 dtheta_k / (theta_dot_k + theta_dot_{k+1})
(constant theta_ddot); for a quadratic profile the closed form of the integral of
1 / sqrt(b0 + 2 a0 s + kappa s^2) (log/atan forms written without cancellation, split at the
vertex of b; ``interval_time``), which includes the rest ends b = 0 (finite when the profile
leaves or reaches rest with theta_ddot != 0). ``sample`` inverts that law exactly (bisection on
the closed form), so time stamps, samples and the duration are those of the profile itself,
not of an approximation. The NLP (transcription.py) uses a piecewise approximation of this law
(``TIME_SUBSTEPS`` pieces per interval) for its duration; the planner rescales the returned
profile in time so that its exact duration is the requested one.
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


def interval_min_b(b0, a0, kappa, h):
    """Minimum of b(s) = b0 + 2 a0 s + kappa s^2 over s in [0, h] (elementwise)."""
    b1 = b0 + 2.0 * a0 * h + kappa * h ** 2
    with np.errstate(divide='ignore', invalid='ignore'):
        s_v = -a0 / kappa
        inside = (kappa > 0) & (s_v > 0) & (s_v < h)
        b_v = np.where(inside, b0 + a0 * s_v, np.inf)
    return np.minimum(np.minimum(b0, b1), b_v)


def _time_increasing(r, a0, sq0, a_s, sq_s, s):
    """kappa = r^2 > 0, theta_ddot >= 0 on the piece: (1/r) ln(P_s / P_0), P = a + r sqrt(b)."""
    S = (a0 + a_s) / (sq0 + sq_s)
    return np.log1p(r * s * (r + S) / (a0 + r * sq0)) / r


def _time_decreasing(r, a0, sq0, a_s, sq_s, s):
    """kappa = r^2 > 0, theta_ddot <= 0 on the piece: (1/r) ln(Q_0 / Q_s), Q = r sqrt(b) - a
    (the same antiderivative as ``_time_increasing`` without cancellation)."""
    S = (a0 + a_s) / (sq0 + sq_s)
    return np.log1p(r * s * (r - S) / (r * sq_s - a_s)) / r


def time_to(b0, a0, kappa, s, b_s=None):
    """Exact time [s] to go from s = 0 to ``s`` [rad] with theta_dot^2 = b0 + 2 a0 s + kappa s^2
    (theta_ddot = a0 + kappa s), elementwise. inf where theta_dot reaches 0 on the way with
    zero slope (no finite time); the caller guarantees b > 0 inside (0, s).

    Antiderivatives of 1 / sqrt(b): kappa > 0: ln(a + sqrt(kappa b)) / sqrt(kappa);
    kappa < 0: -asin(a / R) / sqrt(-kappa), R^2 = a^2 - kappa b; kappa = 0: 2 sqrt(b) / 2 a0.
    Written as log1p / atan2 of differences that are formed without cancellation, so they stay
    exact to round-off down to kappa -> 0 and at rest ends (b0 = 0 or b(s) = 0). ``b_s``, if
    given, is b at s exactly (a node value: 0 at a rest end, where b computed from the
    coefficients would carry round-off that the 1/sqrt singularity amplifies)."""
    b0, a0, kappa, s = np.broadcast_arrays(*(np.asarray(x, float) for x in (b0, a0, kappa, s)))
    a_s = a0 + kappa * s
    if b_s is None:
        b_s = b0 + s * (a0 + a_s)
    b_s = np.maximum(np.broadcast_to(np.asarray(b_s, float), b0.shape), 0.0)
    sq0, sq_s = np.sqrt(np.maximum(b0, 0.0)), np.sqrt(b_s)
    with np.errstate(divide='ignore', invalid='ignore'):
        lin = 2.0 * s / (sq0 + sq_s)                        # kappa = 0 (b linear)
        pos, neg = kappa > 0, kappa < 0
        r = np.sqrt(np.abs(kappa))
        # kappa < 0: (1/rho) atan2(rho (a0 sqrt(b_s) - a_s sqrt(b0)), rho^2 sqrt(b0 b_s) + a0 a_s)
        S = (a0 + a_s) / (sq0 + sq_s)
        num = s * (a0 * S + r ** 2 * sq0)
        t_neg = np.arctan2(r * num, r ** 2 * sq0 * sq_s + a0 * a_s) / r
        # kappa > 0: split at the vertex of b where theta_ddot changes sign
        t_inc = _time_increasing(r, a0, sq0, a_s, sq_s, s)
        t_dec = _time_decreasing(r, a0, sq0, a_s, sq_s, s)
        s_v = -a0 / kappa
        b_v = np.maximum(b0 + a0 * s_v, 0.0)
        sq_v = np.sqrt(b_v)
        t_split = (_time_decreasing(r, a0, sq0, 0.0, sq_v, s_v)
                   + _time_increasing(r, 0.0, sq_v, a_s, sq_s, s - s_v))
        t_pos = np.where(a0 >= 0, t_inc, np.where(a_s <= 0, t_dec, t_split))
        out = np.where(pos, t_pos, np.where(neg, t_neg, lin))
    out = np.where(s == 0, 0.0, out)
    return np.where(np.isnan(out), np.inf, out)


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
            w = np.ones(h.size)
            w[0] = 1.5 if (td[0] == 0 and a[0] == 0) else 1.0
            w[-1] = 1.5 if (td[-1] == 0 and a[-1] == 0) else w[-1]
            gap = np.abs(np.diff(b) - w * (a[:-1] + a[1:]) * h)
            if np.any(gap > CONSISTENCY_RTOL * max(1.0, float(b.max()))):
                raise ValueError('theta_ddot inconsistent with theta_dot: b_{k+1} - b_k != '
                                 f'(a_k + a_{{k+1}}) dtheta_k (worst {gap.max():.3g})')
            low = interval_min_b(b[:-1], a[:-1], (a[1:] - a[:-1]) / h, h)
            low[w > 1.0] = 0.0          # cubic rest intervals: b monotone from 0
            if np.any(low < -CONSISTENCY_RTOL * max(1.0, float(b.max()))):
                raise ValueError('theta_dot^2 of the quadratic profile goes negative inside an '
                                 'interval')
        object.__setattr__(self, '_law', self._time_law())

    @property
    def cubic_ends(self) -> tuple[bool, bool]:
        """(start, end): whether the first / last interval is a cubic rest interval (module
        docstring: b = a = 0 at that rest node of a quadratic profile)."""
        if not self.quadratic:
            return (False, False)
        a, td = self.node_theta_ddot, self.theta_dot
        return (bool(td[0] == 0 and a[0] == 0), bool(td[-1] == 0 and a[-1] == 0))

    def _cubic(self, end: bool):
        """(h, t_interval, j) of the cubic rest interval at the start / ``end``."""
        k = -2 if end else 1
        h = float(self.theta[-1] - self.theta[-2]) if end else float(self.theta[1]
                                                                     - self.theta[0])
        sq = float(self.theta_dot[k])
        t_int = 3.0 * h / sq
        return h, t_int, abs(float(self.node_theta_ddot[k])) / t_int

    def _cubic_at_time(self, end: bool, tau):
        """(s, theta_dot, theta_ddot) at time tau [s] from the interval's start."""
        h, t_int, j = self._cubic(end)
        tau = np.clip(tau, 0.0, t_int)
        if not end:
            return j * tau ** 3 / 6.0, 0.5 * j * tau ** 2, j * tau
        r = t_int - tau
        return h - j * r ** 3 / 6.0, 0.5 * j * r ** 2, -j * r

    def _cubic_at_s(self, end: bool, s):
        """(tau from the interval's start [s], theta_dot, theta_ddot) at offset s [rad]."""
        h, t_int, j = self._cubic(end)
        s = np.clip(s, 0.0, h)
        if not end:
            tau = np.cbrt(6.0 * s / j)
            return tau, 0.5 * j * tau ** 2, j * tau
        r = np.cbrt(6.0 * (h - s) / j)
        return t_int - r, 0.5 * j * r ** 2, -j * r

    @property
    def quadratic(self) -> bool:
        """True if theta_ddot is linear in theta between nodes (node accelerations given)."""
        return self.node_theta_ddot is not None

    def _coefficients(self):
        """Per interval (N-1,): b0, a0, kappa (b = b0 + 2 a0 s + kappa s^2), h."""
        h = np.diff(self.theta)
        b = self.theta_dot ** 2
        if self.quadratic:
            a = self.node_theta_ddot
            return b[:-1], a[:-1], (a[1:] - a[:-1]) / h, h
        return b[:-1], np.diff(b) / (2.0 * h), np.zeros_like(h), h

    def _time_law(self):
        """Node times t_k (N,) [s] of the exact law."""
        b0, a0, kappa, h = self._coefficients()
        with np.errstate(divide='ignore', invalid='ignore'):
            dt = time_to(b0, a0, kappa, h, self.theta_dot[1:] ** 2)
        start, end = self.cubic_ends
        if start:
            dt[0] = self._cubic(False)[1]
        if end:
            dt[-1] = self._cubic(True)[1]
        if not np.all(np.isfinite(dt)):
            k = int(np.argmax(~np.isfinite(dt)))
            raise ValueError(f'theta_dot reaches 0 inside interval {k} (no finite time)')
        return np.concatenate([[0.0], np.cumsum(dt)])

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
        """t_k (N,) [s] at the nodes, t_0 = 0 (exact time law)."""
        return self._law

    @property
    def duration(self) -> float:
        """T [s]."""
        return float(self._law[-1])

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """theta, theta_dot, theta_ddot at times ``t`` (M,) [s] in [0, T], exact: theta(t) is
        the inverse of the exact time law (bisection on the closed form to round-off), and
        theta_dot, theta_ddot are those of the interpolated profile at that theta."""
        tk = self._law
        t = np.clip(np.asarray(t, float), 0.0, tk[-1])
        k = np.clip(np.searchsorted(tk, t, side='right') - 1, 0, self.theta.size - 2)
        b0, a0, kappa, h = (c[k] for c in self._coefficients())
        tau = t - tk[k]
        lo, hi = np.zeros_like(tau), h.copy()
        for _ in range(60):                 # h 2^-60: round-off
            mid = 0.5 * (lo + hi)
            later = time_to(b0, a0, kappa, mid) > tau
            hi = np.where(later, mid, hi)
            lo = np.where(later, lo, mid)
        s = np.where(tau <= 0.0, 0.0, np.where(t >= tk[k + 1], h, 0.5 * (lo + hi)))
        td, tdd = self._speed(k, s, b0, a0, kappa, h), a0 + kappa * s
        for end, mask in zip((False, True), self._cubic_masks(k)):
            if np.any(mask):
                s_c, td_c, tdd_c = self._cubic_at_time(end, tau[mask])
                s, td, tdd = s.copy(), td.copy(), tdd.copy()
                s[mask], td[mask], tdd[mask] = s_c, td_c, tdd_c
        return self.theta[k] + s, td, tdd

    def _cubic_masks(self, k):
        """Which of the interval indices k lie in the cubic rest intervals (start, end)."""
        start, end = self.cubic_ends
        last = self.theta.size - 2
        return ((k == 0) if start else np.zeros(k.shape, bool),
                (k == last) if end else np.zeros(k.shape, bool))

    def _speed(self, k, s, b0, a0, kappa, h):
        """theta_dot at offset s into interval k; the node values exactly at the nodes."""
        b = np.sqrt(np.maximum(b0 + 2.0 * a0 * s + kappa * s ** 2, 0.0))
        return np.where(s <= 0, self.theta_dot[k], np.where(s >= h, self.theta_dot[k + 1], b))

    def theta_at(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """t [s], theta_dot [rad/s], theta_ddot [rad/s^2] of the profile at path parameters
        ``theta`` (M,) in [0, 2 pi] (exact: the inverse of ``sample``)."""
        theta = np.clip(np.asarray(theta, float), self.theta[0], self.theta[-1])
        k = np.clip(np.searchsorted(self.theta, theta, side='right') - 1, 0,
                    self.theta.size - 2)
        b0, a0, kappa, h = (c[k] for c in self._coefficients())
        s = theta - self.theta[k]
        b_s = np.where(s >= h, self.theta_dot[k + 1] ** 2, b0 + 2.0 * a0 * s + kappa * s ** 2)
        with np.errstate(divide='ignore', invalid='ignore'):
            t = self._law[k] + time_to(b0, a0, kappa, s, b_s)
        td, tdd = self._speed(k, s, b0, a0, kappa, h), a0 + kappa * s
        for end, mask in zip((False, True), self._cubic_masks(k)):
            if np.any(mask):
                tau, td_c, tdd_c = self._cubic_at_s(end, s[mask])
                t, td, tdd = t.copy(), td.copy(), tdd.copy()
                t[mask], td[mask], tdd[mask] = self._law[k[mask]] + tau, td_c, tdd_c
        return t, td, tdd

    def scaled_in_time(self, factor: float) -> 'ThetaProfile':
        """The same path speed shape run ``factor`` times slower (duration x factor)."""
        a = None if self.node_theta_ddot is None else self.node_theta_ddot / factor ** 2
        return ThetaProfile(self.theta, self.theta_dot / factor, a)

    @classmethod
    def from_function(cls, theta_dot, n: int = 2001) -> 'ThetaProfile':
        """Sample a callable theta_dot(theta) [rad/s] on ``n`` uniform nodes over [0, 2 pi]."""
        theta = np.linspace(0.0, 2.0 * np.pi, n)
        return cls(theta, np.asarray(theta_dot(theta), float))
