"""Reference profiles for the PD+ controller (no ROS imports).

* ``PathProfile``: a theta-profile along a path. Grid theta (N,) [rad] with theta_dot = h(theta)
  [rad/s], theta_ddot [rad/s^2] and the joint references on the same grid,
  q = Phi(theta), qd = Phi'(theta) theta_dot, qdd = Phi''(theta) theta_dot^2 + Phi'(theta)
  theta_ddot (thesis eq. 6.1-6.3), each (N, 3). Interpolated linearly in theta.
* ``TimeTrajectory``: q(t), qd(t), qdd(t) on a time grid t (N,) [s] for the time-driven mode
  (identification sweeps, comparisons). Interpolated linearly in t.
* Builders: the thesis's default circle profile with a fourth-order polynomial speed profile
  (§4.5), a profile from any theta(t) samples, a joint trajectory turned into a theta-profile,
  and single-joint (1 - cos) sine trajectories (§4.4).
"""
from __future__ import annotations

import gc
import math
import threading
import time
from bisect import bisect_left, bisect_right
from dataclasses import dataclass

import numpy as np
from irb_description.model import RobotModel
from irb_description.path import CirclePath, PathBase, joint_path


class ProfileError(ValueError):
    """A profile or trajectory is malformed (shape, NaN, not monotonic, outside limits)."""


def _check_finite(name: str, *arrays) -> None:
    for a in arrays:
        if not np.all(np.isfinite(a)):
            raise ProfileError(f'{name}: non-finite values')


@dataclass(frozen=True)
class PathProfile:
    """theta-profile with joint references; see module docstring. ``t`` (N,) [s] optional."""

    theta: np.ndarray
    theta_dot: np.ndarray
    theta_ddot: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    t: np.ndarray | None = None

    def __post_init__(self):
        n = len(self.theta)
        if n < 2:
            raise ProfileError('a profile needs at least 2 points')
        for name in ('theta_dot', 'theta_ddot'):
            if np.shape(getattr(self, name)) != (n,):
                raise ProfileError(f'{name} must have shape ({n},)')
        joints = np.shape(self.q)[1] if np.ndim(self.q) == 2 else 3
        for name in ('q', 'qd', 'qdd'):      # (n, 3), or (n, 6) for the six-joint arm
            if np.shape(getattr(self, name)) != (n, joints) or joints not in (3, 6):
                raise ProfileError(f'{name} must have shape ({n}, 3) or ({n}, 6), the same '
                                   'for q, qd and qdd')
        _check_finite('theta-profile', self.theta, self.theta_dot, self.theta_ddot, self.q,
                      self.qd, self.qdd)
        if np.any(np.diff(self.theta) <= 0):
            raise ProfileError('theta grid must be strictly increasing')
        if np.any(self.theta_dot <= 0):
            raise ProfileError('theta_dot = h(theta) must be > 0 (theta-driven control '
                               'stands still where it is 0)')
        if not _SLICED.active:
            self._finish(None, 0)

    def _finish(self, pause, chunk: int) -> None:
        # one table for a single interpolation call per step: [theta_dot, theta_ddot, q, qd, qdd]
        _set_table(self, (self.theta_dot, self.theta_ddot, self.q, self.qd, self.qdd), pause)
        _set_interp_cache(self, self.theta, pause, chunk)
        thl, hl = self._xl, self._rows_l
        slope = []
        for a, b in _ranges(len(thl) - 1, chunk, pause):
            slope += [(hl[i + 1][0] - hl[i][0]) / (thl[i + 1] - thl[i]) for i in range(a, b)]
        object.__setattr__(self, '_h_slope', slope)

    @property
    def theta_start(self) -> float:
        return float(self.theta[0])

    @property
    def theta_end(self) -> float:
        return float(self.theta[-1])

    def h(self, theta: float) -> float:
        """theta_dot [rad/s] at theta [rad] (clamped to the grid).

        Linear interpolation exactly as ``np.interp(theta, self.theta, self.theta_dot)`` (same
        operations, same result to the bit), in plain floats: called 4 times per control step.
        """
        x = self._xl
        if not theta <= x[-1]:          # beyond the end (np.interp: right value; NaN: NaN)
            return self._rows_l[-1][0] if theta > x[-1] else math.nan
        if theta < x[0]:
            return self._rows_l[0][0]
        j = bisect_right(x, theta) - 1
        if j == len(x) - 1 or x[j] == theta:
            return self._rows_l[j][0]
        return self._h_slope[j] * (theta - x[j]) + self._rows_l[j][0]

    def sample(self, theta: float) -> np.ndarray:
        """Row (11,): theta_dot, theta_ddot, q (3), qd (3), qdd (3) at theta (clamped)."""
        th = self.theta
        if theta <= th[0]:
            return self._table[0].copy()
        if theta >= th[-1]:
            return self._table[-1].copy()
        i = int(np.searchsorted(th, theta)) - 1
        w = (theta - th[i]) / (th[i + 1] - th[i])
        return self._table[i] + w * (self._table[i + 1] - self._table[i])

    def sample_list(self, theta: float) -> list:
        """``sample(theta)`` as a list of 11 floats (same values to the bit, ~10x faster)."""
        return _sample_list(self, theta, False)

    def check_limits(self, model: RobotModel, speed_fraction: float = 1.0) -> None:
        """ProfileError if q leaves the position limits or |qd| exceeds the speed limits."""
        lim = model.limits
        if np.any(self.q < lim.lower) or np.any(self.q > lim.upper):
            raise ProfileError('theta-profile leaves the joint position limits')
        if np.any(np.abs(self.qd) > speed_fraction * lim.velocity):
            raise ProfileError(f'theta-profile exceeds {speed_fraction:.0%} of the speed limits '
                               f'(peak {np.abs(self.qd).max(axis=0).round(3).tolist()} rad/s)')


@dataclass(frozen=True)
class TimeTrajectory:
    """q(t), qd(t), qdd(t): t (N,) [s] from 0, each reference (N, 3) [rad, rad/s, rad/s^2]."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray

    def __post_init__(self):
        n = len(self.t)
        if n < 2:
            raise ProfileError('a trajectory needs at least 2 points')
        joints = np.shape(self.q)[1] if np.ndim(self.q) == 2 else 3
        for name in ('q', 'qd', 'qdd'):      # (n, 3), or (n, 6) for the six-joint arm
            if np.shape(getattr(self, name)) != (n, joints) or joints not in (3, 6):
                raise ProfileError(f'{name} must have shape ({n}, 3) or ({n}, 6), the same '
                                   'for q, qd and qdd')
        _check_finite('trajectory', self.t, self.q, self.qd, self.qdd)
        if np.any(np.diff(self.t) <= 0):
            raise ProfileError('trajectory time must be strictly increasing')
        if not _SLICED.active:
            self._finish(None, 0)

    def _finish(self, pause, chunk: int) -> None:
        _set_table(self, (self.q, self.qd, self.qdd), pause)
        _set_interp_cache(self, self.t, pause, chunk)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def sample(self, t: float) -> np.ndarray:
        """Row (3 n,): q (n), qd (n), qdd (n) at time t [s] since the start (clamped; after
        the end the final position with zero speed and acceleration)."""
        tt = self.t
        if t <= tt[0]:
            return self._table[0].copy()
        if t >= tt[-1]:
            row = self._table[-1].copy()
            row[row.size // 3:] = 0.0        # the rates of the n joints (n = 3 or 6)
            return row
        i = int(np.searchsorted(tt, t)) - 1
        w = (t - tt[i]) / (tt[i + 1] - tt[i])
        return self._table[i] + w * (self._table[i + 1] - self._table[i])

    def sample_list(self, t: float) -> list:
        """``sample(t)`` as a list of 9 floats (same values to the bit, ~10x faster)."""
        return _sample_list(self, t, True)

    def check_limits(self, model: RobotModel, speed_fraction: float = 1.0) -> None:
        lim = model.limits
        if np.any(self.q < lim.lower) or np.any(self.q > lim.upper):
            raise ProfileError('trajectory leaves the joint position limits')
        if np.any(np.abs(self.qd) > speed_fraction * lim.velocity):
            raise ProfileError('trajectory exceeds the speed limits')


class _Sliced(threading.local):
    active = False      # inside build_sliced: __post_init__ checks only, no tables


_SLICED = _Sliced()


def _ranges(n: int, chunk: int, pause):
    """(a, b) slices of range(n), ``chunk`` long (0: one slice), ``pause()`` between them."""
    if chunk <= 0 or pause is None:
        yield 0, n
        return
    for a in range(0, n, chunk):
        if a:
            pause()
        yield a, min(a + chunk, n)


def _set_table(obj, columns, pause) -> None:
    """``_table`` = np.column_stack(columns), column block by column block when ``pause``."""
    if pause is None:
        object.__setattr__(obj, '_table', np.column_stack(columns))
        return
    cols = [np.asarray(c, float).reshape(len(c), -1) for c in columns]
    n = len(cols[0])
    table = np.empty((n, sum(c.shape[1] for c in cols)))
    for a in range(0, n, 1024):           # row blocks: the pages are first touched in pieces
        pause()
        table[a:a + 1024] = np.column_stack([c[a:a + 1024] for c in cols])
    object.__setattr__(obj, '_table', table)


def _set_interp_cache(obj, grid: np.ndarray, pause=None, chunk: int = 0) -> None:
    """Plain-float copies of the grid and the table rows for the per-step interpolation
    (``chunk`` rows at a time with ``pause()`` between them: see ``build_sliced``)."""
    g = np.asarray(grid, float)
    xl, rows = [], []
    for a, b in _ranges(len(g), chunk, pause):
        xl += g[a:b].tolist()
        rows += obj._table[a:b].tolist()
    object.__setattr__(obj, '_xl', xl)
    object.__setattr__(obj, '_rows_l', rows)


def _yield_gil() -> None:
    time.sleep(0)        # releases the interpreter lock: a waiting thread runs now


def build_sliced(cls, arrays: dict, chunk: int = 256, pause=_yield_gil, freeze: bool = False):
    """``cls(**arrays)`` (PathProfile or TimeTrajectory), the same object to the bit, built in
    slices of ``chunk`` rows with ``pause()`` between them, for a thread that must not hold
    the interpreter lock for long while another one runs a control loop: converting a
    20 000-point table to the plain-float rows the step interpolates from holds it for
    3-16 ms in one piece (several periods); in slices of 256 rows each piece is ~0.1-0.3 ms.
    The cyclic garbage collector is held off meanwhile: the ~20 000 new row lists would set
    off generation-1/2 collections that walk the heap with the lock held (8-27 ms measured);
    collection resumes afterwards. ``freeze``: the new objects are moved to the permanent
    generation (``gc.freeze``) *before* collection resumes, as pdplus does at start-up:
    re-enabled first, the next allocation anywhere (the control thread's) set off a
    young-generation collection over all ~240 000 new objects, 3-9 ms measured (load 9-11);
    frozen first, 0.4-0.6 ms for the same allocations."""
    was = gc.isenabled()
    gc.disable()
    try:
        _SLICED.active = True
        try:
            obj = cls(**arrays)           # the checks (vectorised), no tables
        finally:
            _SLICED.active = False
        obj._finish(pause, chunk)
    finally:
        if freeze:
            gc.freeze()
        if was:
            gc.enable()
    return obj


def dispose_sliced(obj, chunk: int = 256, pause=_yield_gil) -> None:
    """Free a profile (PathProfile, TimeTrajectory) in slices: its plain-float tables
    (``_rows_l``, ``_xl``, ``_h_slope``: for 20 000 points some 240 000 objects) are emptied
    ``chunk`` items at a time with ``pause()`` between, so no single piece holds the
    interpreter lock for long. Dropped in one piece, a 20 000-point PathProfile took 9-11 ms
    (measured at load 13 on 2 cores): at ~enable, on the control thread, that left a joint
    state unanswered. Anything else (a dict of such objects, a path) is walked one level."""
    items = list(obj.values()) if isinstance(obj, dict) else [obj]
    for it in items:
        for name in ('_rows_l', '_xl', '_h_slope'):
            lst = getattr(it, '__dict__', {}).get(name)
            if isinstance(lst, list):
                while lst:
                    del lst[-chunk:]
                    pause()


def _sample_list(obj, x: float, zero_rates_after_end: bool) -> list:
    """Row of ``obj._table`` at x, linear, clamped: the arithmetic of ``sample`` in floats
    (numpy's element-wise a + w (b - a) is IEEE per element, so the result is identical)."""
    xl, rows = obj._xl, obj._rows_l
    if x <= xl[0]:
        return rows[0][:]
    if x >= xl[-1]:
        row = rows[-1][:]
        if zero_rates_after_end:        # q (n), qd (n), qdd (n): the rates are zero
            n = len(row) // 3
            row[n:] = [0.0] * (len(row) - n)
        return row
    i = bisect_left(xl, x) - 1          # = np.searchsorted(grid, x) - 1
    w = (x - xl[i]) / (xl[i + 1] - xl[i])
    a, b = rows[i], rows[i + 1]
    return [x0 + w * (x1 - x0) for x0, x1 in zip(a, b)]


# --- builders ------------------------------------------------------------------------------
def polynomial_theta_of_time(duration: float, n: int = 2001, theta_end: float = 2 * np.pi):
    """Fourth-order polynomial speed profile (thesis §4.5): theta_dot(t) = 30 theta_end s^2
    (1 - s)^2 / T, s = t / T, so theta goes 0 -> theta_end with zero speed and acceleration at
    both ends (theta(t) = theta_end (10 s^3 - 15 s^4 + 6 s^5)).

    Returns t, theta, theta_dot, theta_ddot, each (n,), SI units.
    """
    if not duration > 0:
        raise ProfileError(f'duration must be > 0, got {duration}')
    t = np.linspace(0.0, duration, n)
    s = t / duration
    theta = theta_end * (10 * s**3 - 15 * s**4 + 6 * s**5)
    theta_dot = theta_end / duration * 30 * s**2 * (1 - s) ** 2
    theta_ddot = theta_end / duration**2 * 60 * s * (1 - s) * (1 - 2 * s)
    return t, theta, theta_dot, theta_ddot


def profile_from_theta_samples(model: RobotModel, path: PathBase, theta: np.ndarray,
                               theta_dot: np.ndarray, theta_ddot: np.ndarray,
                               t: np.ndarray | None = None, min_theta_dot: float = 0.05,
                               grid: int = 721, joints=None) -> PathProfile:
    """PathProfile on a uniform theta grid from samples theta (M,), theta_dot, theta_ddot.

    The samples are resampled to ``grid`` points in theta. theta_dot is floored at
    ``min_theta_dot`` [rad/s] (delta of thesis §6.1) where it would stop the theta-driven
    controller (at the ends of a rest-to-rest profile); theta_ddot is set to 0 there.
    ``joints``: theta (M,) -> an object with q, dq, ddq (M, n) (e.g. the six joints of
    ``irb_description.orientation.joint_path6``); None = the three-axis ``joint_path``.
    """
    theta = np.asarray(theta, float)
    _check_finite('theta samples', theta, theta_dot, theta_ddot)
    if theta.ndim != 1 or len(theta) < 2 or np.any(np.diff(theta) < 0):
        raise ProfileError('theta samples must be a non-decreasing 1-D array')
    keep = np.concatenate([[True], np.diff(theta) > 0])
    th_u = np.linspace(theta[0], theta[-1], grid)
    thd = np.interp(th_u, theta[keep], np.asarray(theta_dot, float)[keep])
    thdd = np.interp(th_u, theta[keep], np.asarray(theta_ddot, float)[keep])
    floor = thd < min_theta_dot
    thd = np.where(floor, min_theta_dot, thd)
    thdd = np.where(floor, 0.0, thdd)
    jp = joint_path(model, path, th_u) if joints is None else joints(th_u)
    qd = jp.dq * thd[:, None]
    qdd = jp.ddq * thd[:, None] ** 2 + jp.dq * thdd[:, None]
    tt = None
    if t is not None:
        tt = np.interp(th_u, theta[keep], np.asarray(t, float)[keep])
    return PathProfile(th_u, thd, thdd, jp.q, qd, qdd, tt)


def default_circle_profile(model: RobotModel, path: PathBase, duration: float = 10.0,
                           min_theta_dot: float = 0.05, grid: int = 721) -> PathProfile:
    """The built-in default: one circle in ``duration`` [s] with the polynomial speed profile."""
    t, th, thd, thdd = polynomial_theta_of_time(duration)
    return profile_from_theta_samples(model, path, th, thd, thdd, t, min_theta_dot, grid)


def profile_from_joint_trajectory(model: RobotModel, path: PathBase, t: np.ndarray,
                                  q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                                  min_theta_dot: float = 0.05) -> PathProfile:
    """theta-profile from a joint trajectory (N,) / (N, 3) that follows ``path``.

    theta = atan2 of FK(q) about the centre (unwrapped, from 0; for any other path the
    projection followed from the start, PathTracker), theta_dot = p'(theta) . J qd
    / |p'|^2; theta_ddot by differentiating theta_dot in time. The joint references are the
    trajectory's own; theta_dot is floored at ``min_theta_dot``.
    """
    t, q, qd, qdd = (np.asarray(a, float) for a in (t, q, qd, qdd))
    _check_finite('joint trajectory', t, q, qd, qdd)
    pts = np.array([model.fk(qi) for qi in q])
    if type(path) is CirclePath:
        theta = np.unwrap(np.arctan2(pts[:, 1] - path.center[1], pts[:, 0] - path.center[0])
                          * path.direction)
        theta = theta - theta[0] + path.theta_of(pts[0])
        off = max(np.max(np.abs(np.linalg.norm((pts - path.point(theta))[:, :2], axis=1))),
                  np.max(np.abs(pts[:, 2] - path.center[2])))
    else:       # any other path: followed point by point from the start (PathTracker)
        from irb_description.path_tracking import PathTracker
        step = float(np.max(np.linalg.norm(np.diff(pts, axis=0), axis=1))) if len(pts) > 1 \
            else 0.0
        tr = PathTracker(path, window_m=max(0.02, 3.0 * step))
        theta = np.empty(len(pts))
        prev = float(path.theta_of(pts[0]))
        if path.closed and prev > np.pi:
            prev = 0.0 if np.linalg.norm(path.point(0.0) - pts[0]) < 5e-3 else prev
        for k, p in enumerate(pts):
            prev = theta[k] = tr.update(p, prev)
        if path.closed:
            theta = np.unwrap(theta)
            theta -= 2 * np.pi * np.round(theta[0] / (2 * np.pi))
        off = float(np.max(np.linalg.norm(pts - path.point(np.clip(theta, 0, 2 * np.pi)),
                                          axis=1)))
    if off > 5e-3:
        raise ProfileError(f'joint trajectory does not follow the path: its TCP is up to '
                           f'{off * 1e3:.1f} mm from it (> 5 mm)')
    dp = path.d_point(theta)
    v = np.array([model.jacobian(qi) @ qdi for qi, qdi in zip(q, qd)])
    thd = np.einsum('ij,ij->i', dp, v) / np.einsum('ij,ij->i', dp, dp)
    thdd = np.gradient(thd, t) if len(t) > 2 else np.zeros_like(thd)
    keep = np.concatenate([[True], np.diff(theta) > 1e-9])
    theta, thd, thdd, t, q, qd, qdd = (a[keep] for a in (theta, thd, thdd, t, q, qd, qdd))
    floor = thd < min_theta_dot
    thd = np.where(floor, min_theta_dot, thd)
    thdd = np.where(floor, 0.0, thdd)
    return PathProfile(theta, thd, thdd, q, qd, qdd, t)


def sine_trajectory(q0: np.ndarray, joint: int, peak_speed: float, amplitude: float = 0.3,
                    cycles: float = 1.0, dt: float = 0.004032) -> TimeTrajectory:
    """Single-joint motion q_j = q0_j + A (1 - cos(w t)), w = peak_speed / A (thesis §4.4).

    Starts at rest, peak speed ``peak_speed`` [rad/s]; ``cycles`` periods 2 pi / w; the other
    joints stay at q0 (n,) [rad]. ``joint`` is 0 .. n - 1.
    """
    n = len(q0)
    if joint not in range(n) or not peak_speed > 0 or not amplitude > 0 or not cycles > 0:
        raise ProfileError(f'joint in 0..{n - 1}, peak_speed > 0, amplitude > 0, cycles > 0')
    w = peak_speed / amplitude
    duration = cycles * 2 * np.pi / w
    t = np.arange(0.0, duration + dt / 2, dt)
    q = np.tile(np.asarray(q0, float), (len(t), 1))
    qd = np.zeros_like(q)
    qdd = np.zeros_like(q)
    q[:, joint] += amplitude * (1 - np.cos(w * t))
    qd[:, joint] = amplitude * w * np.sin(w * t)
    qdd[:, joint] = amplitude * w**2 * np.cos(w * t)
    return TimeTrajectory(t, q, qd, qdd)
