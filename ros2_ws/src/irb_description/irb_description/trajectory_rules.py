"""Rules a joint trajectory message keeps so that any trajectory controller plays it as meant
(numpy only, no ROS). The planner checks its messages with them before it answers, and a
consumer (pdplus's plan gate) checks what it receives with the same functions, so what one
calls a success the other accepts.

* **spacing**: consecutive points at least ``MIN_POINT_SPACING_S`` apart. A controller
  interpolates the points by quintics matching q, qd, qdd at both ends; over an interval of
  tens of microseconds the quintic's acceleration depends on the stamps to the nanosecond
  (a 1 ns change moved the played TCP acceleration of a 20 us pair by 3 to 5 m/s^2, issue 28).
  At 1 ms the same nanosecond moves it by about 6e-2 rad/s^2 per rad/s, and the planner puts
  its points at the stamps' exact instants anyway (``stamps_ns``).
* **stamps**: ``time_from_start`` has a resolution of 1 ns (``STAMP_RESOLUTION_S``);
  ``stamps_ns`` rounds times as the message will carry them.
* **consistency**: between neighbours the mean rate of q (and of qd) lies between the rates
  declared at the two points (mean-value theorem for a rate monotone within one interval),
  within ``atol + rtol * max |declared rate| * dt``. It holds for smooth plans and for
  accelerations that switch at or between points (trapezoid ramps, a path's piece ends); it
  refuses a step or a chatter that the declared rates do not explain.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: [s] smallest interval between two points of a trajectory message
MIN_POINT_SPACING_S = 1e-3
#: [s] resolution of builtin_interfaces Duration (time_from_start)
STAMP_RESOLUTION_S = 1e-9
#: consistency tolerances: residual / what the declared rates allow, and absolute [rad]
#: (positions vs velocities) or [rad/s] (velocities vs accelerations)
CONSISTENCY_RTOL = 0.05
CONSISTENCY_ATOL = 2e-4
#: a consumer's further limits on a plan (pdplus's plan gate defaults): |qdd| of any joint
#: [rad/s^2] and the feed-forward torque's share of the torque limit at the points
GATE_MAX_ACCELERATION_RAD_S2 = 50.0
GATE_TORQUE_FRACTION = 0.9


@dataclass(frozen=True)
class Inconsistency:
    """The worst breach of the consistency rule: ``what`` ('positions vs velocities' or
    'velocities vs accelerations'), interval ``point`` -> point + 1 (0-based), ``joint``
    (0-based), the change over the interval, the range the declared rates allow, dt [s],
    and how far beyond the tolerance it is (``excess`` - ``allowed``, same unit as change)."""

    what: str
    point: int
    joint: int
    change: float
    low: float
    high: float
    dt: float
    excess: float
    allowed: float

    def detail(self) -> str:
        return (f'change {self.change:+.4g} over {self.dt * 1e3:.2f} ms while the declared '
                f'rates allow {self.low:+.4g} to {self.high:+.4g}')


def worst_inconsistency(t, q, qd, qdd, rtol: float = CONSISTENCY_RTOL,
                        atol: float = CONSISTENCY_ATOL) -> Inconsistency | None:
    """The worst interval that breaks the consistency rule (module docstring), or None.
    t (N,) [s] strictly increasing; q, qd, qdd (N, n)."""
    t, q, qd, qdd = (np.asarray(a, float) for a in (t, q, qd, qdd))
    d = np.diff(t)[:, None]
    worst = None
    for what, x, v in (('positions vs velocities', q, qd),
                       ('velocities vs accelerations', qd, qdd)):
        rate = np.diff(x, axis=0) / d
        lo, hi = np.minimum(v[:-1], v[1:]), np.maximum(v[:-1], v[1:])
        excess = np.maximum(lo - rate, rate - hi).clip(min=0.0) * d
        allowed = atol + rtol * np.maximum(np.abs(v[:-1]), np.abs(v[1:])) * d
        over = excess - allowed
        if over.size and over.max() > 0:
            k, i = np.unravel_index(int(np.argmax(over)), over.shape)
            if worst is None or over[k, i] > worst.excess - worst.allowed:
                worst = Inconsistency(what, int(k), int(i), float(x[k + 1, i] - x[k, i]),
                                      float(lo[k, i] * d[k, 0]), float(hi[k, i] * d[k, 0]),
                                      float(d[k, 0]), float(excess[k, i]),
                                      float(allowed[k, i]))
    return worst


def gate_limit_notes(qdd, tau, torque_limit,
                     max_acceleration: float = GATE_MAX_ACCELERATION_RAD_S2,
                     torque_fraction: float = GATE_TORQUE_FRACTION) -> list[str]:
    """One line per limit a plan gate with these defaults would refuse at the points:
    qdd, tau (N, n) at the message points [rad/s^2, N m]; torque_limit (n,) [N m]."""
    out = []
    qdd, tau = np.abs(np.asarray(qdd, float)), np.abs(np.asarray(tau, float))
    k, i = np.unravel_index(int(np.argmax(qdd)), qdd.shape)
    if qdd[k, i] > max_acceleration:
        out.append(f'|qdd| of joint {i + 1} reaches {qdd[k, i]:.3g} rad/s^2 at point {k} '
                   f'(a plan gate limiting it to {max_acceleration:g} refuses it)')
    share = tau / np.asarray(torque_limit, float)[None, :]
    k, i = np.unravel_index(int(np.argmax(share)), share.shape)
    if share[k, i] > torque_fraction:
        out.append(f'the torque of joint {i + 1} reaches {share[k, i]:.1%} of its limit at '
                   f'point {k} (a plan gate keeping {torque_fraction:.0%} for feedback '
                   'refuses it; ask for limit_scaling <= '
                   f'{torque_fraction / share[k, i]:.3f})')
    return out


def stamps_ns(t) -> np.ndarray:
    """Times [s] rounded to the message's resolution (1 ns), as time_from_start carries them."""
    return np.round(np.asarray(t, float) / STAMP_RESOLUTION_S) * STAMP_RESOLUTION_S


def closest_points(t) -> tuple[int, float]:
    """(k, dt): the closest pair of consecutive points, k -> k + 1, and their interval [s]
    (-1, inf for fewer than 2 points)."""
    dt = np.diff(np.asarray(t, float))
    if dt.size == 0:
        return -1, float('inf')
    k = int(np.argmin(dt))
    return k, float(dt[k])


def spaced(t, min_spacing: float = MIN_POINT_SPACING_S, priority=None) -> np.ndarray:
    """Indices of the points of ``t`` (N,) [s] (increasing) to keep so that consecutive kept
    points are at least ``min_spacing`` apart (minus half a stamp resolution). The first and
    the last are always kept; then, by decreasing ``priority`` (N,) (None: all equal) and
    in time order within a level, a point is kept if it is at least ``min_spacing`` from
    every point kept so far. The caller ranks the points it must not lose (e.g. where an
    acceleration peaks: the mean-value rule holds only for rates monotone within an
    interval) above those it added for density."""
    import bisect
    t = np.asarray(t, float)
    n = t.size
    if n <= 2:
        return np.arange(n)
    tol = min_spacing - 0.5 * STAMP_RESOLUTION_S
    pr = np.zeros(n) if priority is None else np.asarray(priority, float)
    kept_t, kept = [t[0], t[-1]], [0, n - 1]
    if t[-1] - t[0] < tol:
        return np.array([0, n - 1])
    for k in np.lexsort((np.arange(1, n - 1), -pr[1:-1])) + 1:
        j = bisect.bisect_left(kept_t, t[k])
        if t[k] - kept_t[j - 1] >= tol and kept_t[j] - t[k] >= tol:
            kept_t.insert(j, t[k])
            kept.insert(j, int(k))
    return np.asarray(kept, int)
