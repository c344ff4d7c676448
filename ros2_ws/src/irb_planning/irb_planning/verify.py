"""The independent check of a plan as a controller will play it (numpy/scipy only, no ROS).

It receives what the service returns, not the optimiser's internals: the trajectory message's
points (t, q, qd, qdd), the theta profile (node theta, theta_dot, theta_ddot), the circle as
numbers, the DH table and limits as numbers, a rigid-body torque function and the friction
map as the file's mapping. It shares no code with the optimiser, the model's IK or the
profile's time law:

* **time law**: the message's stamps against its own integration of dtheta / theta_dot
  (adaptive Gauss-Kronrod, scipy ``quad``, with the 1/sqrt weight at rest ends) of the profile
  as interpolated (b = theta_dot^2 quadratic between nodes with the node theta_ddot), on every
  segment between consecutive points; theta of each point from its own FK (DH product) and
  atan2 about the centre (thesis eq. 5.6);
* **as played**: quintic Hermite interpolation between the points (what a joint-trajectory
  controller does with positions, velocities and accelerations), sampled at ``rate_hz`` and at
  least ``min_samples_per_segment`` per segment; the TCP by its own DH forward kinematics, its
  distance to the circle;
* **continuity**: no joint moves between two points by more than their velocities and
  accelerations allow (a wrap of joint 1 at +-180 deg is a jump of 2 pi);
* **limits** along the played trajectory: positions, speeds, torques = rigid body (the given
  function, pinocchio RNEA on the URDF in the planner) + friction evaluated from the map's
  numbers here;
* **energy** of the played trajectory, int sum_i |tau_i qd_i| dt (thesis eq. 6.8-6.9), and
  its electrical energy for every DC-bus mode when an ElectricalModel is given;
* **process constraints** (``TcpBand``) along the played trajectory: TCP velocity and
  acceleration from its own DH kinematics, differentiated in closed form through the DH
  product (v = dp/dt, a = d2p/dt2 from q, qd, qdd), the speed band (the floor only where the
  TCP's own projection onto the path is beyond the ramp length of arc length from both
  rest ends, the arc length from its own table of the path) and |a|;
* **smoothness** (``SmoothLimits``) along the played trajectory: joint jerk from the quintic
  polynomials' own third derivative, TCP jerk and the rate of the rigid-body torque as finite
  differences of the played samples (TCP acceleration from the DH product above, torque from
  the given function; friction's Coulomb step when a joint starts is left out: it is the same
  for every plan that moves that joint).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import warnings

import numpy as np
from scipy.integrate import IntegrationWarning, quad

#: relative tolerance of limit checks (round-off, not a margin)
LIMIT_RTOL = 1e-6


@dataclass(frozen=True)
class Circle:
    """Horizontal circle: center (3,) [m], radius [m], start angle [rad], direction +-1."""

    center: np.ndarray
    radius: float
    start_angle: float
    direction: int

    def deviation(self, p: np.ndarray) -> np.ndarray:
        """Distance [m] of points p (M, 3) from the circle."""
        d = p - self.center
        return np.hypot(np.hypot(d[:, 0], d[:, 1]) - self.radius, d[:, 2])

    def theta(self, p: np.ndarray) -> np.ndarray:
        """theta (M,) [rad] of points along a sequence, unwrapped from 0 (eq. 5.6)."""
        d = p - self.center
        ang = self.direction * (np.arctan2(d[:, 1], d[:, 0]) - self.start_angle)
        ang = np.unwrap(ang)
        return ang - 2 * np.pi * np.round(ang[0] / (2 * np.pi))

    def arc_length(self, theta: np.ndarray) -> np.ndarray:
        """Arc length [m] from the start of the points at ``theta``."""
        return self.radius * np.asarray(theta, float)


class PathCurve:
    """Any other path, given by its definition p(theta), p'(theta), p''(theta) (vectorised
    callables; theta in [0, 2 pi]) and whether it is closed: what the request asked for. The
    nearest path point of each TCP point is found here: the nearest of a dense table (one
    point per 0.5 mm, a KD-tree), then Newton steps on (p(theta) - x) . p'(theta) = 0 inside
    the two table intervals around it (to ~1e-13 rad)."""

    def __init__(self, point: Callable, d_point: Callable, dd_point: Callable, closed: bool):
        from scipy.spatial import cKDTree
        self.point, self.d_point, self.dd_point = point, d_point, dd_point
        self.closed = bool(closed)
        coarse = point(np.linspace(0.0, 2 * np.pi, 257))
        length = float(np.linalg.norm(np.diff(coarse, axis=0), axis=1).sum())
        n = int(min(max(length / 5e-4, 256), 200000))
        self._th = np.linspace(0.0, 2 * np.pi, n + 1)
        table = point(self._th)
        self._tree = cKDTree(table)
        self._sigma = None
        self._table = table
        self._h = float(np.linalg.norm(np.diff(table, axis=0), axis=1).max())

    def arc_length(self, theta: np.ndarray) -> np.ndarray:
        """Arc length [m] from the start of the points at ``theta``: chords of a table of
        16 points per table interval, summed and interpolated."""
        if self._sigma is None:
            fine = np.linspace(0.0, 2 * np.pi, 16 * (self._th.size - 1) + 1)
            chords = np.linalg.norm(np.diff(self.point(fine), axis=0), axis=1)
            self._fine, self._sigma = fine, np.concatenate([[0.0], np.cumsum(chords)])
        return np.interp(np.asarray(theta, float), self._fine, self._sigma)

    def _nearest(self, p: np.ndarray) -> np.ndarray:
        # the last projection is kept: the check asks for the deviation and for theta of
        # the same played samples (an array equal to the last one gets the same answer)
        memo = getattr(self, '_memo', None)
        if memo is not None and memo[0].shape == p.shape and np.array_equal(memo[0], p):
            return memo[1].copy()
        self._ties = {}
        t = self._project(p)
        self._memo = (p.copy(), t.copy(), self._ties)
        return t

    def _project(self, p: np.ndarray, k: int = 8) -> np.ndarray:
        """Newton from the nearest table point, and from every other table point that may
        lie in the interval of the true nearest point: all within d_1 + h / 2 (d_1 the
        nearest table point's distance, h the longest table chord; the true foot's interval
        has an end within d* + h / 2 <= d_1 + h / 2). A path that passes close by itself (two
        legs of a closed spline 0.19 mm apart) would otherwise put a point of one leg on the
        other; the nearest of the Newton results is kept. On a closed path table point n is
        point 0, so a point near the start also tries the last interval."""
        last = self._th.size - 1
        k = min(k, last + 1)
        dist, idx = self._tree.query(p, k=k)
        dist, idx = dist.reshape(len(p), k), idx.reshape(len(p), k)
        reach = dist[:, 0] + 0.5 * self._h * (1 + 1e-9)
        j = idx[:, 0]
        t = self._newton(p, j)
        best = np.linalg.norm(self.point(t) - p, axis=1)
        rows = [np.flatnonzero((dist[:, c] <= reach) & (np.abs(idx[:, c] - j) > 1))
                for c in range(1, k)]
        cand = [idx[r, c] for c, r in enumerate(rows, start=1)]
        if self.closed:
            r = np.flatnonzero((j == 0) | (j == last))
            rows.append(r)
            cand.append(np.where(j[r] == 0, last, 0))
        crowded = np.flatnonzero(dist[:, -1] <= reach) if k <= last else np.zeros(0, int)
        if crowded.size:    # the k nearest all within reach: every table point in it
            found = self._tree.query_ball_point(p[crowded], reach[crowded])
            rows.append(np.repeat(crowded, [len(f) for f in found]))
            cand.append(np.concatenate([np.asarray(f, int) for f in found]))
        r, c = np.concatenate(rows), np.concatenate(cand)
        if r.size:
            tc = self._newton(p[r], c)
            dc = np.linalg.norm(self.point(tc) - p[r], axis=1)
            order = np.lexsort((dc, r))             # per point, its nearest result first
            first = order[np.r_[True, r[order][1:] != r[order][:-1]]]
            better = dc[first] < best[r[first]]
            t[r[first][better]] = tc[first][better]
            best[r[first][better]] = dc[first][better]
            # where the path crosses itself a point can be on two legs at once: those
            # within TIE_M of its nearest are kept for ``theta`` to choose by continuity
            apart = np.abs(tc - t[r])
            if self.closed:     # theta 0 and 2 pi are one point
                apart = np.minimum(apart, 2 * np.pi - apart)
            tie = np.flatnonzero((dc <= best[r] + self.TIE_M) & (apart > 1e-9))
            for row in np.unique(r[tie]):
                self._ties[int(row)] = tc[tie[r[tie] == row]]
        return t

    def _newton(self, p: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Newton steps per sample, each sample until its own step is below 1e-14 rad (at
        most 8): the samples still moving are the only ones evaluated again."""
        th = self._th
        lo, hi = th[np.maximum(j - 1, 0)], th[np.minimum(j + 1, th.size - 1)]
        t = th[j].copy()
        live = np.arange(t.size)
        for _ in range(8):
            tl, pl = t[live], p[live]
            d = self.point(tl) - pl
            d1 = self.d_point(tl)
            f = (d * d1).sum(axis=1)
            fp = (d1 * d1).sum(axis=1) + (d * self.dd_point(tl)).sum(axis=1)
            step = np.where(fp > 0, f / np.where(fp > 0, fp, 1.0), 0.0)
            t[live] = np.clip(tl - step, lo[live], hi[live])
            live = live[np.abs(step) >= 1e-14]
            if live.size == 0:
                break
        return t

    #: [m] a point as close as this to two legs of a path that crosses itself is on either
    TIE_M = 1e-6

    def deviation(self, p: np.ndarray) -> np.ndarray:
        """Distance [m] of points p (M, 3) from the path."""
        return np.linalg.norm(p - self.point(self._nearest(p)), axis=1)

    def theta(self, p: np.ndarray) -> np.ndarray:
        """theta (M,) [rad] of points along a sequence, from about 0 (unwrapped on a closed
        path, so the sequence's last point of a full lap is at about 2 pi). A point on two
        legs at once (where the path crosses itself) takes the leg nearest in theta to the
        point before it (the first: to theta 0)."""
        t = self._nearest(p)
        ties = self._memo[2]
        for r in sorted(ties):
            prev = t[r - 1] if r else 0.0
            options = np.append(ties[r], t[r])
            gap = np.abs(options - prev)
            if self.closed:
                gap = np.minimum(gap, 2 * np.pi - gap)
            t[r] = options[int(np.argmin(gap))]
        if not self.closed:
            return t
        t = np.unwrap(np.mod(t, 2 * np.pi))
        return t - 2 * np.pi * np.round(t[0] / (2 * np.pi))


@dataclass(frozen=True)
class DHTable:
    """DH parameters (6,) each: a [m], alpha [rad], d [m], theta offset [rad]."""

    a: np.ndarray
    alpha: np.ndarray
    d: np.ndarray
    offset: np.ndarray

    def forward(self, q: np.ndarray) -> np.ndarray:
        """T_6^0 (M, 4, 4) of joint vectors q (M, <= 6 columns; missing joints at 0): the
        product A_1 ... A_6, A_i = Rz(theta) Tz(d) Tx(a) Rx(alpha), theta_i = q_i + offset_i.
        The checkers' own kinematics (three-axis `verify`, six-axis `six_axis_check`)."""
        q = np.atleast_2d(np.asarray(q, float))
        M = q.shape[0]
        q6 = np.zeros((M, 6))
        q6[:, :q.shape[1]] = q          # fewer than six columns: the others at 0
        T = np.broadcast_to(np.eye(4), (M, 4, 4)).copy()
        for i in range(6):
            th = q6[:, i] + self.offset[i]
            ct, st = np.cos(th), np.sin(th)
            ca, sa = np.cos(self.alpha[i]), np.sin(self.alpha[i])
            A = np.zeros((M, 4, 4))
            A[:, 0, 0], A[:, 0, 1], A[:, 0, 2], A[:, 0, 3] = ct, -st * ca, st * sa, self.a[i] * ct
            A[:, 1, 0], A[:, 1, 1], A[:, 1, 2], A[:, 1, 3] = st, ct * ca, -ct * sa, self.a[i] * st
            A[:, 2, 1], A[:, 2, 2], A[:, 2, 3] = sa, ca, self.d[i]
            A[:, 3, 3] = 1.0
            T = T @ A
        return T


def dh_point_rates(dh: DHTable, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                   origin=None, positions: bool = False) -> tuple[np.ndarray, ...]:
    """Velocity and acceleration (M, 3) [m/s, m/s^2] of a point fixed on the flange (DH frame
    6; ``origin``: its homogeneous coordinates (4,) there, default the origin e_4, e.g. a
    TCP's last column) under joint motions (M, <= 6): the
    DH product A_1 ... A_6 applied to it and differentiated in time, from the
    right: x_7 = origin, x_i = A_i x_(i+1), x_i' = A_i x_(i+1)' + qd_i A_i,th x_(i+1),
    x_i'' = A_i x_(i+1)'' + 2 qd_i A_i,th x_(i+1)' + (qd_i^2 A_i,thth + qdd_i A_i,th)
    x_(i+1); the TCP's (p, v, a) are x_1, x_1', x_1'' (A_i,th = dA_i/dtheta_i). Vectors,
    not 4 x 4 products, so a 10 kHz play of a long plan costs milliseconds per second of
    motion. ``positions``: (p, v, a), p the TCP of the same product (= ``tcp``)."""
    q, qd, qdd = (np.atleast_2d(np.asarray(x, float)) for x in (q, qd, qdd))
    M, n = q.shape
    zero = np.zeros(M)
    o = [0.0, 0.0, 0.0, 1.0] if origin is None else [float(v) for v in origin]
    x = [zero + o[0], zero + o[1], zero + o[2], zero + o[3]]   # x_7: the point on the flange
    x1, x2 = [zero] * 4, [zero] * 4                 # its first and second time derivatives

    def parts(v, a, ca, sa):
        # A_i v = (c u - s g, s u + c g, sa v1 + ca v2 + d v3, v3) with u = v0 + a v3,
        # g = ca v1 - sa v2; A_i,th v = (-s u - c g, c u - s g, 0, 0) and A_i,thth v =
        # -(c u - s g, s u + c g, 0, 0)
        return v[0] + a * v[3], ca * v[1] - sa * v[2]

    for i in range(5, -1, -1):
        a, d = float(dh.a[i]), float(dh.d[i])
        ca, sa = float(np.cos(dh.alpha[i])), float(np.sin(dh.alpha[i]))
        th = (q[:, i] if i < n else 0.0) + float(dh.offset[i])
        c, s_ = np.cos(th) + zero, np.sin(th) + zero

        def apply(v):
            u, g = parts(v, a, ca, sa)
            return [c * u - s_ * g, s_ * u + c * g, sa * v[1] + ca * v[2] + d * v[3], v[3]]

        def d_theta(v):
            u, g = parts(v, a, ca, sa)
            return [-s_ * u - c * g, c * u - s_ * g, zero, zero]

        if i < n and (np.any(qd[:, i]) or np.any(qdd[:, i])):
            w, wd = qd[:, i], qdd[:, i]
            dx, dx1 = d_theta(x), d_theta(x1)
            ax = apply(x)
            # A_i,thth x = -(the rotating rows of A_i x)
            x2 = [r + 2 * w * e1 + wd * e0 for r, e1, e0 in zip(apply(x2), dx1, dx)]
            x2[0] = x2[0] - w ** 2 * ax[0]
            x2[1] = x2[1] - w ** 2 * ax[1]
            x1 = [r + w * e0 for r, e0 in zip(apply(x1), dx)]
            x = ax
        else:
            x, x1, x2 = apply(x), apply(x1), apply(x2)
    p, v, acc = (np.stack(y[:3], axis=1) for y in (x, x1, x2))
    if positions:
        return p, v, acc
    return v, acc


@dataclass(frozen=True)
class ArmKinematics:
    """DH table (6,) each [m]/[rad], and the limits (3,) checked: lower/upper [rad],
    velocity [rad/s], torque [N m]. Joints 4-6 are at 0 (the simplified model)."""

    a: np.ndarray
    alpha: np.ndarray
    d: np.ndarray
    offset: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    torque: np.ndarray

    def tcp(self, q: np.ndarray) -> np.ndarray:
        """TCP positions (M, 3) [m] of joint angles q (M, 3): the DH product A1...A6."""
        return DHTable(self.a, self.alpha, self.d, self.offset).forward(q)[:, :3, 3]

    def tcp_rates(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                  positions: bool = False) -> tuple[np.ndarray, ...]:
        """TCP velocity and acceleration (M, 3) [m/s, m/s^2] of joint motions (M, <= 6)
        (``dh_point_rates`` at the flange's origin); ``positions``: (p, v, a)."""
        return dh_point_rates(DHTable(self.a, self.alpha, self.d, self.offset), q, qd, qdd,
                              positions=positions)


@dataclass(frozen=True)
class SmoothLimits:
    """Smoothness limits to check: joint jerk (n,) [rad/s^3], |TCP jerk| [m/s^3] (0 = none),
    rate of the rigid-body torque (n,) [N m/s]."""

    jerk: np.ndarray
    tcp_jerk: float
    torque_rate: np.ndarray


@dataclass(frozen=True)
class TcpBand:
    """Process constraints to check (0 = none): TCP speed ceiling and floor [m/s], the
    floor away from the rest ends beyond ``ramp_length`` [m] of arc length (the whole path
    if the plan is periodic), bound on |TCP acceleration| [m/s^2]. Over the ramps the floor
    is v_min (d / ramp_length)^ramp_exponent (d the distance to the nearer rest end)."""

    speed_max: float = 0.0
    speed_min: float = 0.0
    accel_max: float = 0.0
    ramp_length: float = 0.0
    ramp_exponent: float = 0.5

    @property
    def active(self) -> bool:
        return bool(self.speed_max > 0 or self.speed_min > 0 or self.accel_max > 0)


class MapFriction:
    """Friction torque from a friction-map file's ``joints`` mapping, evaluated here.

    Per joint: sign(v) (F_c + (F_s - F_c) exp(-(v/v_s)^2)) + F_v v, with separate Coulomb and
    static levels per sign and an offset where the map has them; inside ``valid_range`` the
    per-sign polynomials when present (increasing powers of v)."""

    def __init__(self, joints: dict, names: list[str]):
        self.params = [joints[n] for n in names]

    @staticmethod
    def _joint(p: dict, v: np.ndarray) -> np.ndarray:
        fc = float(p['coulomb'])
        fs = float(p.get('static', fc))
        vs = float(p.get('stribeck_velocity', 0.05))
        fcp, fcn = float(p.get('coulomb_positive', fc)), float(p.get('coulomb_negative', fc))
        fsp = float(p.get('static_positive', fs - fc + fcp))
        fsn = float(p.get('static_negative', fs - fc + fcn))
        e = np.exp(-(v / vs) ** 2)
        level = np.where(v > 0, fcp + (fsp - fcp) * e, fcn + (fsn - fcn) * e)
        out = np.sign(v) * level + float(p['viscous']) * v + float(p.get('offset', 0.0))
        if 'polynomial_positive' in p and 'polynomial_negative' in p:
            lo, hi = (float(x) for x in p.get('valid_range', (0.0, np.inf)))
            inside = (np.abs(v) >= lo) & (np.abs(v) <= hi)
            for key, side in (('polynomial_positive', v > 0), ('polynomial_negative', v < 0)):
                poly = np.zeros_like(v)
                for power, c in enumerate(p[key]):
                    poly = poly + float(c) * v ** power
                out = np.where(inside & side, poly, out)
        return out

    def __call__(self, v: np.ndarray) -> np.ndarray:
        v = np.atleast_2d(v)
        return np.stack([self._joint(p, v[:, i]) for i, p in enumerate(self.params)], axis=1)


@dataclass
class Verification:
    """Outcome: ok, problems (one line each); max_path_deviation [m] of the played TCP;
    max_time_error [-] relative, per segment; energy [J], duration [s], peak torque/speed
    (n,) of the played trajectory; the played samples t, q, qd, qdd, tau; electrical: the
    played trajectory's ElectricalModel.breakdown [J] (empty without a model)."""

    problems: list[str]
    max_path_deviation: float
    max_time_error: float
    energy: float
    duration: float
    peak_torque: np.ndarray
    peak_speed: np.ndarray
    t: np.ndarray = field(repr=False, default=None)
    q: np.ndarray = field(repr=False, default=None)
    qd: np.ndarray = field(repr=False, default=None)
    qdd: np.ndarray = field(repr=False, default=None)
    tau: np.ndarray = field(repr=False, default=None)
    electrical: dict = field(default_factory=dict)
    tcp_speed_peak: float = float('nan')    # [m/s] as played (NaN: no TcpBand checked)
    tcp_speed_low: float = float('nan')     # [m/s] lowest away from the rest ends
    tcp_accel_peak: float = float('nan')    # [m/s^2] largest |TCP acceleration|
    tcp_floor_ratio: float = float('nan')   # lowest speed / floor (floor rising over ramps)
    peak_jerk: np.ndarray | None = None     # (n,) [rad/s^3] as played
    tcp_jerk_peak: float = float('nan')     # [m/s^3] as played
    peak_torque_rate: np.ndarray | None = None   # (n,) [N m/s] rigid-body torque, as played
    tau_rigid: np.ndarray = field(repr=False, default=None)   # played, without friction
    blend_end_peaks: dict = field(default_factory=dict)   # the same inside exempt windows

    @property
    def ok(self) -> bool:
        return not self.problems


def profile_segment_time(theta_nodes, theta_dot, theta_ddot, th0: float, th1: float,
                         quadratic: bool = True) -> float:
    """Own integration of dtheta / theta_dot from th0 to th1 [rad] over the profile whose
    b = theta_dot^2 is quadratic between nodes (b' = 2 theta_ddot, theta_ddot linear between
    the node values) or, if not ``quadratic``, linear between nodes (theta_ddot constant)."""
    if not quadratic:     # the slope of b on each interval, at both of its ends
        slope = np.diff(np.asarray(theta_dot) ** 2) / (2 * np.diff(theta_nodes))
        theta_ddot = (slope, slope)
    else:
        theta_ddot = (theta_ddot[:-1], theta_ddot[1:])
    with warnings.catch_warnings():       # quad's round-off notes: the error is checked
        warnings.simplefilter('ignore', IntegrationWarning)
        return _segment_time(theta_nodes, theta_dot, theta_ddot, th0, th1)


def _segment_time(theta_nodes, theta_dot, theta_ddot, th0, th1):
    total = 0.0
    k0 = max(int(np.searchsorted(theta_nodes, th0, side='right')) - 1, 0)
    k1 = min(int(np.searchsorted(theta_nodes, th1, side='left')), theta_nodes.size - 1)
    for k in range(k0, k1):
        lo, hi = max(th0, theta_nodes[k]), min(th1, theta_nodes[k + 1])
        if hi <= lo:
            continue
        h = theta_nodes[k + 1] - theta_nodes[k]
        b0, a0, a1 = theta_dot[k] ** 2, theta_ddot[0][k], theta_ddot[1][k]

        def b(x, b0=b0, a0=a0, a1=a1, h=h, k=k):
            s = x - theta_nodes[k]
            return b0 + 2 * a0 * s + (a1 - a0) * s * s / h
        left_rest = theta_dot[k] == 0 and lo == theta_nodes[k]
        right_rest = theta_dot[k + 1] == 0 and hi == theta_nodes[k + 1]
        kappa = (a1 - a0) / h
        if theta_dot[k] == 0 and a0 == 0:
            # constant path jerk from rest: b = b1 (s / h)^(4/3), theta_dot ~ s^(2/3)
            c = theta_dot[k + 1] / h ** (2 / 3)
            total += quad(lambda x: 1 / c, lo, hi, weight='alg', wvar=(-2 / 3, 0.0),
                          epsabs=0.0, epsrel=1e-10)[0] if lo == theta_nodes[k] else \
                quad(lambda x: 1 / (c * (x - theta_nodes[k]) ** (2 / 3)), lo, hi,
                     epsabs=0.0, epsrel=1e-10)[0]
            continue
        if theta_dot[k + 1] == 0 and a1 == 0:
            c = theta_dot[k] / h ** (2 / 3)
            total += quad(lambda x: 1 / c, lo, hi, weight='alg', wvar=(0.0, -2 / 3),
                          epsabs=0.0, epsrel=1e-10)[0] if hi == theta_nodes[k + 1] else \
                quad(lambda x: 1 / (c * (theta_nodes[k + 1] - x) ** (2 / 3)), lo, hi,
                     epsabs=0.0, epsrel=1e-10)[0]
            continue
        if left_rest:      # b = s (2 a0 + kappa s): quad's 1/sqrt weight takes the 1/sqrt(s)
            val = quad(lambda x: 1 / np.sqrt(max(2 * a0 + kappa * (x - lo), 1e-300)), lo, hi,
                       weight='alg', wvar=(-0.5, 0.0), epsabs=0.0, epsrel=1e-10,
                       limit=200)[0]
        elif right_rest:   # b = (h - s) (-2 a1 + kappa (h - s))
            val = quad(lambda x: 1 / np.sqrt(max(-2 * a1 + kappa * (hi - x), 1e-300)), lo, hi,
                       weight='alg', wvar=(0.0, -0.5), epsabs=0.0, epsrel=1e-10,
                       limit=200)[0]
        else:
            val = quad(lambda x: 1 / np.sqrt(max(b(x), 1e-300)), lo, hi, epsabs=0.0,
                       epsrel=1e-10, limit=200)[0]
        total += val
    return total


def quintic(t0, t1, p0, p1, rate: float, min_samples: int, jerk: bool = False):
    """Sample the quintic Hermite segments between points (positions, velocities,
    accelerations p0/p1 = (q, qd, qdd), each (K, n)) over [t0, t1] (K,): (t, q, qd, qdd),
    each segment at max(min_samples, T rate) instants from its start (end excluded)."""
    q0, v0, a0 = p0
    q1, v1, a1 = p1
    T = t1 - t0
    m = np.maximum(min_samples, np.ceil(T * rate)).astype(int)
    seg = np.repeat(np.arange(T.size), m)
    first = np.cumsum(m) - m
    s = (np.arange(seg.size) - first[seg]) / m[seg] * T[seg]
    # q(s) = c0 + c1 s + ... + c5 s^5 matching q, qd, qdd at both ends
    Tc = T[:, None]
    c0, c1, c2 = q0, v0, 0.5 * a0
    d = q1 - (c0 + c1 * Tc + c2 * Tc ** 2)
    e = v1 - (c1 + 2 * c2 * Tc)
    f = a1 - 2 * c2
    c3 = (10 * d - 4 * e * Tc + 0.5 * f * Tc ** 2) / Tc ** 3
    c4 = (-15 * d + 7 * e * Tc - f * Tc ** 2) / Tc ** 4
    c5 = (6 * d - 3 * e * Tc + 0.5 * f * Tc ** 2) / Tc ** 5
    c0, c1, c2, c3, c4, c5 = (c[seg] for c in (c0, c1, c2, c3, c4, c5))
    S = s[:, None]
    q = c0 + S * (c1 + S * (c2 + S * (c3 + S * (c4 + S * c5))))
    qd = c1 + S * (2 * c2 + S * (3 * c3 + S * (4 * c4 + S * 5 * c5)))
    qdd = 2 * c2 + S * (6 * c3 + S * (12 * c4 + S * 20 * c5))
    if jerk:
        return t0[seg] + s, q, qd, qdd, 6 * c3 + S * (24 * c4 + S * 60 * c5)
    return t0[seg] + s, q, qd, qdd


def verify_plan(t, q, qd, qdd, profile, circle: Circle | PathCurve, kin: ArmKinematics,
                rigid_torque: Callable, friction: Callable, rest: bool,
                rate_hz: float = 1000.0, min_samples_per_segment: int = 8,
                path_tolerance_m: float = 1e-4, time_rtol: float = 1e-6,
                electrical=None, band: TcpBand | None = None,
                stamp_resolution_s: float = 0.0,
                smooth: SmoothLimits | None = None,
                smooth_exempt: np.ndarray | None = None) -> Verification:
    """Check a plan's trajectory message as played (see module docstring).

    t (K,) [s]; q, qd, qdd (K, n); profile = (theta, theta_dot, theta_ddot, quadratic): node
    arrays and whether theta_ddot is linear between nodes (else b is);
    rigid_torque(q, qd, qdd) (M, n) -> (M, n); friction(v (M, n)) -> (M, n).
    ``stamp_resolution_s``: the stamps are rounded to it (1 ns in a message): each segment's
    time may differ from the profile's by that much besides ``time_rtol``.
    """
    problems = []
    t, q, qd, qdd = (np.asarray(x, float) for x in (t, q, qd, qdd))
    th_n, thd_n, thdd_n = (np.asarray(x, float) for x in profile[:3])
    quadratic = bool(profile[3])
    n = q.shape[1]
    if not all(np.all(np.isfinite(x)) for x in (t, q, qd, qdd)):
        return Verification(['non-finite values in the trajectory'], np.inf, np.inf, np.nan,
                            np.nan, np.full(n, np.nan), np.full(n, np.nan))
    if t.size < 2 or np.any(np.diff(t) <= 0):
        return Verification(['time stamps not strictly increasing'], np.inf, np.inf, np.nan,
                            np.nan, np.full(n, np.nan), np.full(n, np.nan))
    # --- the points: on the path, their theta, the time law -----------------------------
    p = kin.tcp(q)
    dev_pts = circle.deviation(p)
    if dev_pts.max() > 1e-6:
        k = int(np.argmax(dev_pts))
        problems.append(f'point {k} (t = {t[k]:.3f} s) is {dev_pts[k] * 1e3:.3f} mm off the '
                        'path')
    theta = circle.theta(p)
    if abs(theta[0]) > 1e-6 or abs(theta[-1] - 2 * np.pi) > 1e-6 or np.any(np.diff(theta) < 0):
        problems.append('the points do not run once along the path in order '
                        f'(theta {theta[0]:.4f} .. {theta[-1]:.4f} rad)')
    theta = np.clip(theta, 0.0, 2 * np.pi)
    worst_time = 0.0
    for k in range(t.size - 1):
        expected = profile_segment_time(th_n, thd_n, thdd_n, theta[k], theta[k + 1], quadratic)
        err = max(abs((t[k + 1] - t[k]) - expected) - stamp_resolution_s, 0.0) / max(
            expected, 1e-12)
        if err > worst_time:
            worst_time, k_time = err, k
    if worst_time > time_rtol:
        problems.append(f'time stamps disagree with the profile: segment {k_time} '
                        f'(t = {t[k_time]:.3f} s) off by {worst_time:.2e} relative')
    # --- continuity between points ------------------------------------------------------
    dt = np.diff(t)[:, None]
    reach = (0.5 * (np.abs(qd[:-1]) + np.abs(qd[1:])) * dt
             + 0.5 * np.maximum(np.abs(qdd[:-1]), np.abs(qdd[1:])) * dt ** 2)
    jump = np.abs(np.diff(q, axis=0)) - 1.5 * reach - 1e-6
    if np.any(jump > 0):
        k, i = np.unravel_index(int(np.argmax(jump)), jump.shape)
        problems.append(f'joint {i + 1} jumps by {np.degrees(abs(q[k + 1, i] - q[k, i])):.1f} '
                        f'deg between points {k} and {k + 1} (t = {t[k]:.3f} s)')
    if rest and (np.abs(qd[0]).max() > 1e-9 or np.abs(qd[-1]).max() > 1e-9):
        problems.append('a rest-to-rest plan does not start and end at rest')
    # --- as played ------------------------------------------------------------------------
    ts, qs, qds, qdds, jerk = quintic(t[:-1], t[1:], (q[:-1], qd[:-1], qdd[:-1]),
                                      (q[1:], qd[1:], qdd[1:]), rate_hz,
                                      min_samples_per_segment, jerk=True)
    ts, qs, qds, qdds = (np.concatenate([x, y[-1:]]) for x, y in
                         ((ts, t), (qs, q), (qds, qd), (qdds, qdd)))
    # TCP position, velocity, acceleration of every sample from one DH product pass (the
    # deviation, the band and the TCP jerk share it: 2 passes cost half the check's time)
    rates = kin.tcp_rates(qs, qds, qdds, positions=True)
    dev = circle.deviation(rates[0])
    k = int(np.argmax(dev))
    if dev[k] > path_tolerance_m:
        problems.append(f'played by quintic interpolation the TCP leaves the path by '
                        f'{dev[k] * 1e3:.3f} mm at t = {ts[k]:.3f} s (> '
                        f'{path_tolerance_m * 1e3:g} mm)')
    tau_r = np.asarray(rigid_torque(qs, qds, qdds), float)
    tau = tau_r + friction(qds)
    peak_tau, peak_v = np.abs(tau).max(axis=0), np.abs(qds).max(axis=0)
    for i in range(n):
        if np.any(qs[:, i] < kin.lower[i] - 1e-9) or np.any(qs[:, i] > kin.upper[i] + 1e-9):
            j = int(np.argmax(np.maximum(kin.lower[i] - qs[:, i], qs[:, i] - kin.upper[i])))
            problems.append(f'joint {i + 1} at {np.degrees(qs[j, i]):.2f} deg leaves its limits '
                            f'[{np.degrees(kin.lower[i]):.0f}, {np.degrees(kin.upper[i]):.0f}] '
                            f'at t = {ts[j]:.3f} s')
        if peak_v[i] > kin.velocity[i] * (1 + LIMIT_RTOL):
            j = int(np.argmax(np.abs(qds[:, i])))
            problems.append(f'joint {i + 1} speed {peak_v[i]:.3f} rad/s > '
                            f'{kin.velocity[i]:.3f} at t = {ts[j]:.3f} s')
        if peak_tau[i] > kin.torque[i] * (1 + LIMIT_RTOL):
            j = int(np.argmax(np.abs(tau[:, i])))
            problems.append(f'joint {i + 1} torque {peak_tau[i]:.2f} N m > '
                            f'{kin.torque[i]:.2f} at t = {ts[j]:.3f} s')
    if not np.all(np.isfinite(tau)):
        problems.append('non-finite torque')
    energy = float(np.trapezoid(np.abs(tau * qds).sum(axis=1), ts))
    elec = electrical.breakdown(ts, tau, qds) if electrical is not None else {}
    tcp = (check_band(band, ts, qs, qds, qdds, circle, kin, rest, problems, rates)
           if band is not None and band.active else (np.nan,) * 4)
    # smoothness: samples (jerk) and sample pairs (rates) inside an exempt window (the twin
    # points around a blend end's curvature jump) are reported apart
    dts = np.diff(ts)[:, None]
    rate = np.abs(np.diff(tau_r, axis=0)) / dts
    acc = rates[2]
    tj = np.linalg.norm(np.diff(acc, axis=0), axis=1) / dts[:, 0]
    out_j, out_r = np.ones(jerk.shape[0], bool), np.ones(rate.shape[0], bool)
    for lo, hi in (() if smooth_exempt is None else np.asarray(smooth_exempt, float)):
        out_j &= ~((ts[:-1] >= lo) & (ts[:-1] < hi))
        out_r &= ~((ts[1:] > lo) & (ts[:-1] < hi))
    zero = np.zeros(n)
    peak_j = np.abs(jerk[out_j]).max(axis=0) if out_j.any() else zero
    peak_rate = rate[out_r].max(axis=0) if out_r.any() else zero
    tcp_j = float(tj[out_r].max()) if out_r.any() else 0.0
    blend = {}
    if not out_j.all():
        blend = {'joint_jerk': np.abs(jerk[~out_j]).max(axis=0),
                 'torque_rate': rate[~out_r].max(axis=0), 'tcp_jerk': float(tj[~out_r].max())}
    if smooth is not None:
        check_smooth(smooth, ts, np.where(out_j[:, None], jerk, 0.0),
                     np.where(out_r[:, None], rate, 0.0), np.where(out_r, tj, 0.0), problems)
    return Verification(problems, float(dev.max()), float(worst_time), energy,
                        float(t[-1] - t[0]), peak_tau, peak_v, ts, qs, qds, qdds, tau, elec,
                        *tcp, peak_j, tcp_j, peak_rate, tau_r, blend)


def check_smooth(lim: SmoothLimits, ts, jerk, rate, tcp_jerk, problems: list) -> None:
    """The smoothness limits on the played samples (jerk (M, n) at the samples, rate (M-1, n)
    and tcp_jerk (M-1,) between them; 0 where exempt); a line per broken one in
    ``problems``."""
    for i in range(jerk.shape[1]):
        k = int(np.argmax(np.abs(jerk[:, i])))
        if abs(jerk[k, i]) > lim.jerk[i] * (1 + LIMIT_RTOL):
            problems.append(f'joint {i + 1} jerk {abs(jerk[k, i]):.1f} rad/s^3 > '
                            f'{lim.jerk[i]:g} at t = {ts[k]:.4f} s')
        k = int(np.argmax(rate[:, i]))
        if rate[k, i] > lim.torque_rate[i] * (1 + LIMIT_RTOL):
            problems.append(f'joint {i + 1} torque rate {rate[k, i]:.0f} N m/s > '
                            f'{lim.torque_rate[i]:g} at t = {ts[k]:.4f} s')
    k = int(np.argmax(tcp_jerk))
    if lim.tcp_jerk > 0 and tcp_jerk[k] > lim.tcp_jerk * (1 + LIMIT_RTOL):
        problems.append(f'tcp jerk {tcp_jerk[k]:.1f} m/s^3 > {lim.tcp_jerk:g} at '
                        f't = {ts[k]:.4f} s')


#: [m] distance from a rest end within which a played sample counts as at rest (the
#: projection of the TCP at rest onto the path is exact only to round-off)
REST_SLACK_M = 1e-6


def check_band(band: TcpBand, ts, qs, qds, qdds, circle, kin: ArmKinematics, rest: bool,
               problems: list, rates: tuple | None = None) -> tuple[float, float, float, float]:
    """The process constraints on the played samples; appends a line per broken one to
    ``problems`` (worded without ' speed ' / ' torque ': they are not the joint limits whose
    breach makes the planner add message points). Returns (peak TCP speed, lowest TCP speed
    away from the rest ends, peak |TCP acceleration|, lowest speed / floor). ``rates``: the
    samples' (p, v, a) of ``kin.tcp_rates(..., positions=True)`` if already computed."""
    pos, vel, acc = rates if rates is not None else kin.tcp_rates(qs, qds, qdds, True)
    speed, amag = np.linalg.norm(vel, axis=1), np.linalg.norm(acc, axis=1)
    theta = np.clip(circle.theta(pos), 0.0, 2 * np.pi)
    sigma = circle.arc_length(theta)
    length = float(circle.arc_length(np.array([2 * np.pi]))[0])
    # the floor: v_min beyond the ramps; over them v_min sqrt(d / ramp), d the distance to
    # the nearer rest end (a constant-acceleration start or stop reaching v_min at the ramp);
    # d counted from REST_SLACK_M on: a sample at rest projects onto the path within round-off
    # of its end, where a floor of v_min sqrt(1e-12 / ramp) > 0 = its speed would be 'broken'
    d = np.minimum(sigma, length - sigma) - REST_SLACK_M
    frac = (np.clip(d / max(band.ramp_length, 1e-300), 0.0, 1.0) if rest
            else np.ones(sigma.size))
    moving = frac >= 1.0
    low = float(speed[moving].min()) if np.any(moving) else float('nan')
    floor = band.speed_min * frac ** band.ramp_exponent
    ramp = (frac > 0) & ~moving
    ratio = float(np.min(speed[frac > 0] / floor[frac > 0])) if (
        band.speed_min > 0 and np.any(frac > 0)) else float('nan')
    if band.speed_max > 0 and speed.max() > band.speed_max * (1 + LIMIT_RTOL):
        k = int(np.argmax(speed))
        problems.append(f'tcp_speed_max {band.speed_max:.4g} m/s exceeded: the TCP moves at '
                        f'{speed[k]:.4g} m/s at t = {ts[k]:.3f} s ({sigma[k] * 1e3:.0f} mm '
                        'along the path)')
    if band.speed_min > 0 and np.any(moving) and low < band.speed_min * (1 - LIMIT_RTOL):
        k = int(np.flatnonzero(moving)[np.argmin(speed[moving])])
        problems.append(f'tcp_speed_min {band.speed_min:.4g} m/s not kept: the TCP moves at '
                        f'{speed[k]:.4g} m/s at t = {ts[k]:.3f} s ({sigma[k] * 1e3:.0f} mm '
                        f'along the path, ramps {band.ramp_length * 1e3:.0f} mm)')
    if band.speed_min > 0 and np.any(ramp) and np.any(speed[ramp] < floor[ramp]
                                                        * (1 - LIMIT_RTOL)):
        k = int(np.flatnonzero(ramp)[np.argmin(speed[ramp] / floor[ramp])])
        problems.append(f'tcp_speed_min ramp not kept: the TCP moves at {speed[k]:.4g} m/s '
                        f'{sigma[k] * 1e3:.1f} mm along the path (t = {ts[k]:.3f} s), below '
                        f'the ramp floor {floor[k]:.4g} m/s')
    if band.accel_max > 0 and amag.max() > band.accel_max * (1 + LIMIT_RTOL):
        k = int(np.argmax(amag))
        problems.append(f'tcp_accel_max {band.accel_max:.4g} m/s^2 exceeded: '
                        f'|TCP acceleration| {amag[k]:.4g} m/s^2 at t = {ts[k]:.3f} s '
                        f'({sigma[k] * 1e3:.0f} mm along the path)')
    return float(speed.max()), low, float(amag.max()), ratio
