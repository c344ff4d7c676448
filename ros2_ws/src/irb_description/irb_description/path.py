"""Paths for the TCP and their joint-space images Phi(theta), Phi'(theta), Phi''(theta).

Thesis eq. 5.1-5.5 and 6.1-6.3: q = Phi(theta), qd = Phi'(theta) thetad,
qdd = Phi''(theta) thetad^2 + Phi'(theta) thetadd. Phi comes from the closed-form IK;
Phi' = J^-1 p'(theta) and Phi'' = J^-1 (p''(theta) - dJ/dt Phi'), in closed form
(``RobotModel.arm_derivatives``, checked against pinocchio's Jacobian in the tests).

Every path has one parameter theta in [0, 2 pi] proportional to arc length,
theta = 2 pi sigma / L (sigma the arc length from the start, L the length), so s = theta / 2 pi
runs over [0, 1]. For the thesis's circle this theta is its angle (eq. 5.1), so the planner,
its profiles and the controller need no other parameter. Types: ``CirclePath`` (horizontal,
the thesis's, unchanged), ``ArcPath`` (circle or arc in any plane), ``LinePath``,
``PolylinePath`` (waypoints, a circular blend of given radius at each corner: C1, curvature
bounded by 1 / radius) and ``SplinePath`` (C2 cubic spline through waypoints, re-parametrised
by arc length). ``path_from_spec`` builds any of them from a plain mapping (YAML, messages).
No ROS imports.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .model import RobotModel, UnreachableError
from .params import yaml_problem

TWO_PI = 2.0 * np.pi
PATH_TYPES = ('circle', 'arc', 'line', 'polyline', 'spline')
#: optional block of a path mapping with process constraints for the planner (not geometry)
PROCESS_KEY = 'process'
#: its keys, SI units: TCP speed band [m/s], |TCP acceleration| bound [m/s^2], length [m] at
#: each rest end where the speed may stay below tcp_speed_min (the planner's PlanRequest)
PROCESS_FIELDS = ('tcp_speed_max', 'tcp_speed_min', 'tcp_accel_max', 'tcp_ramp_length')


class PathBase:
    """What every path offers besides point / d_point / dd_point (theta -> (..., 3)).

    ``closed``: the end is the start (with the same tangent), so theta wraps at 2 pi;
    ``length`` [m]; ``breaks``: theta values where the curvature may jump (piece ends);
    ``distance(p)`` [m] from points to the path; ``theta_of(p)`` the parameter of the nearest
    path point (global search; ``PathTracker`` follows a moving point locally).
    """

    closed = False
    breaks = np.zeros(0)

    def table(self, spacing_m: float = 2e-3) -> tuple[np.ndarray, np.ndarray]:
        """A dense theta grid (K,) with the piece ends and its points (K, 3)."""
        n = max(int(math.ceil(self.length / spacing_m)), 64)
        th = np.linspace(0.0, TWO_PI, n + 1)
        if self.breaks.size:        # no node within a quarter spacing of a piece end
            near = np.abs(th[:, None] - self.breaks[None, :]).min(axis=1) < 0.25 * th[1]
            near[[0, -1]] = False
            th = np.union1d(th[~near], self.breaks)
        return th, self.point(th)

    def theta_of(self, p: np.ndarray) -> np.ndarray:
        """theta in [0, 2 pi] of the nearest path point to each of p (..., 3) [m]: Newton
        steps on (p(theta) - x) . p'(theta) = 0 inside the two table intervals around the
        nearest point of a dense table (scipy KD-tree), and around every other table point
        that may neighbour the true nearest point (within d_1 + h / 2 of x: d_1 the nearest
        table distance, h the longest table chord), the nearest result kept: where the path
        passes close by itself (two legs of a closed spline 0.19 mm apart) a point of one
        leg is not put on the other. All points at once; on a closed path table point 0 is
        the last one too."""
        p = np.asarray(p, float)
        flat = p.reshape(-1, 3)
        th, tree, h = self._table()
        last = th.size - 1
        k = min(8, th.size)
        dist, idx = tree.query(flat, k=k)
        dist, idx = dist.reshape(-1, k), idx.reshape(-1, k)
        reach = dist[:, 0] + 0.5 * h * (1 + 1e-9)
        j = idx[:, 0]
        out = _newton(self, flat, th, j)
        best = np.linalg.norm(self.point(out) - flat, axis=1)
        rows, cand = [], []
        for c in range(1, k):
            r = np.flatnonzero((dist[:, c] <= reach) & (np.abs(idx[:, c] - j) > 1))
            rows.append(r)
            cand.append(idx[r, c])
        if self.closed:          # point n is point 0: the other end's interval too
            r = np.flatnonzero((j == 0) | (j == last))
            rows.append(r)
            cand.append(np.where(j[r] == 0, last, 0))
        crowded = np.flatnonzero(dist[:, -1] <= reach) if k <= last else np.zeros(0, int)
        if crowded.size:         # the k nearest all within reach: every table point in it
            found = tree.query_ball_point(flat[crowded], reach[crowded])
            rows.append(np.repeat(crowded, [len(f) for f in found]))
            cand.append(np.concatenate([np.asarray(f, int) for f in found]))
        r, c = np.concatenate(rows), np.concatenate(cand)
        if r.size:
            tc = _newton(self, flat[r], th, c)
            dc = np.linalg.norm(self.point(tc) - flat[r], axis=1)
            order = np.lexsort((dc, r))              # per point, its nearest result first
            first = order[np.r_[True, r[order][1:] != r[order][:-1]]]
            better = dc[first] < best[r[first]]
            out[r[first][better]] = tc[first][better]
        # the ends exactly: within 1e-12 rad (~1e-13 m) of 0 or 2 pi is the end (Newton on
        # an end point itself stops a few ulp from it, and a ramp's speed floor, zero at the
        # end, is then a few 1e-11 m/s above a played speed of exactly 0); on a closed path
        # 2 pi is 0
        out = np.where(out <= 1e-12, 0.0, out)
        end = out >= TWO_PI - 1e-12
        out = np.where(end, 0.0 if self.closed else TWO_PI, out)
        return out.reshape(p.shape[:-1])

    def distance(self, p: np.ndarray) -> np.ndarray:
        """Distance [m] of p (..., 3) from the path (nearest point by ``theta_of``)."""
        p = np.asarray(p, float)
        return np.linalg.norm(p - self.point(self.theta_of(p)), axis=-1)

    def _table(self):
        cache = self.__dict__.get('_table_cache')
        if cache is None:
            from scipy.spatial import cKDTree
            th, pts = self.table(1e-3)
            cache = (th, cKDTree(pts), float(np.linalg.norm(np.diff(pts, axis=0),
                                                            axis=1).max()))
            object.__setattr__(self, '_table_cache', cache)
        return cache


def _newton(path, x, th, j, iters: int = 8) -> np.ndarray:
    """theta (M,) near table indices j (M,) minimising |p(theta) - x| for points x (M, 3):
    Newton on (p - x) . p' = 0, kept inside the two table intervals around each j."""
    lo, hi = th[np.maximum(j - 1, 0)], th[np.minimum(j + 1, th.size - 1)]
    t = th[j].astype(float)
    for _ in range(iters):
        d = path.point(t) - x
        d1 = path.d_point(t)
        f = (d * d1).sum(axis=1)
        fp = (d1 * d1).sum(axis=1) + (d * path.dd_point(t)).sum(axis=1)
        step = np.where(fp > 0, f / np.where(fp > 0, fp, 1.0), 0.0)
        t = np.clip(t - step, lo, hi)
        if np.abs(step).max(initial=0.0) < 1e-14:
            break
    return t


@dataclass(frozen=True)
class CirclePath(PathBase):
    """Horizontal circle p(theta) = c + r (cos(s theta + phi0), sin(s theta + phi0), 0).

    center (3,) [m], radius [m], start_angle phi0 [rad], direction s = +1 (counter-clockwise
    seen from above) or -1; theta in [0, 2 pi] runs once around from the start point.
    The thesis circle: center (0.6, 0, 0.13) m, radius 0.15 m (eq. 5.15).
    """

    center: np.ndarray
    radius: float
    start_angle: float = 0.0
    direction: int = 1
    closed = True

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

    def distance(self, p: np.ndarray) -> np.ndarray:
        """Distance [m] of p (..., 3) from the circle (closed form)."""
        d = np.asarray(p, float) - self.center
        return np.hypot(np.hypot(d[..., 0], d[..., 1]) - self.radius, d[..., 2])


def _unit(v, what='vector'):
    v = np.asarray(v, float)
    n = float(np.linalg.norm(v))
    if not (np.isfinite(n) and n > 1e-12):
        raise ValueError(f'{what} must be a finite non-zero 3-vector, got {v.tolist()}')
    return v / n


def plane_axes(normal) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, v, n): the unit normal n and in-plane axes; u is the base x axis projected into
    the plane (the base y axis if the normal is along x), v = n x u."""
    n = _unit(normal, 'normal')
    ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = _unit(ref - (ref @ n) * n)
    return u, np.cross(n, u), n


@dataclass(frozen=True)
class ArcPath(PathBase):
    """Circle or arc in any plane: p = c + r (cos(phi) a + sin(phi) b),
    phi = sweep theta / 2 pi, a = cos(phi0) u + sin(phi0) v (the start direction), b = n x a
    (``plane_axes``: u is the base x axis projected into the plane).

    center (3,) [m], normal (3,), radius [m], start_angle phi0 [rad], sweep [rad] (sign:
    counter-clockwise about the normal; |sweep| = 2 pi is a full, closed circle).
    """

    center: np.ndarray
    normal: np.ndarray
    radius: float
    start_angle: float = 0.0
    sweep: float = TWO_PI

    def __post_init__(self):
        c = np.asarray(self.center, float)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ValueError(f'center must be 3 finite numbers, got {self.center!r}')
        if not (np.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f'radius must be > 0, got {self.radius!r}')
        if not (np.isfinite(self.sweep) and 0 < abs(self.sweep) <= TWO_PI * (1 + 1e-12)):
            raise ValueError(f'sweep must be in [-2 pi, 2 pi] and not 0, got {self.sweep!r}')
        if not np.isfinite(self.start_angle):
            raise ValueError('start_angle must be finite')
        u, v, n = plane_axes(self.normal)
        a = math.cos(self.start_angle) * u + math.sin(self.start_angle) * v
        object.__setattr__(self, 'center', c)
        object.__setattr__(self, 'normal', n)
        object.__setattr__(self, '_a', a)
        object.__setattr__(self, '_b', np.cross(n, a))
        object.__setattr__(self, '_k', float(self.sweep) / TWO_PI)

    @property
    def closed(self) -> bool:
        return abs(abs(self.sweep) - TWO_PI) <= 1e-12 * TWO_PI

    @property
    def length(self) -> float:
        return abs(self.sweep) * self.radius

    def _cs(self, theta):
        ph = self._k * np.asarray(theta, float)
        return np.cos(ph)[..., None], np.sin(ph)[..., None]

    def point(self, theta):
        c, s = self._cs(theta)
        return self.center + self.radius * (c * self._a + s * self._b)

    def d_point(self, theta):
        c, s = self._cs(theta)
        return self._k * self.radius * (-s * self._a + c * self._b)

    def dd_point(self, theta):
        c, s = self._cs(theta)
        return -self._k ** 2 * self.radius * (c * self._a + s * self._b)

    def distance(self, p):
        if not self.closed:
            return super().distance(p)
        d = np.asarray(p, float) - self.center
        h = d @ self.normal
        rho = np.linalg.norm(d - h[..., None] * self.normal, axis=-1)
        return np.hypot(rho - self.radius, h)


@dataclass(frozen=True)
class LinePath(PathBase):
    """Straight segment p = start + (theta / 2 pi) (end - start)."""

    start: np.ndarray
    end: np.ndarray

    def __post_init__(self):
        a, b = np.asarray(self.start, float), np.asarray(self.end, float)
        for name, x in (('start', a), ('end', b)):
            if x.shape != (3,) or not np.all(np.isfinite(x)):
                raise ValueError(f'line {name} must be 3 finite numbers, got {x!r}')
        if np.linalg.norm(b - a) < 1e-6:
            raise ValueError('line start and end must be at least 1 um apart')
        object.__setattr__(self, 'start', a)
        object.__setattr__(self, 'end', b)
        object.__setattr__(self, '_d', (b - a) / TWO_PI)

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.end - self.start))

    def point(self, theta):
        return self.start + np.asarray(theta, float)[..., None] * self._d

    def d_point(self, theta):
        return np.broadcast_to(self._d, np.shape(theta) + (3,)).copy()

    def dd_point(self, theta):
        return np.zeros(np.shape(theta) + (3,))


class _Pieces(PathBase):
    """A path made of lines and circular arcs, each parametrised by arc length: a piece is
    (sigma0, length, kind, data); kind 'line' data = (p0, direction), kind 'arc' data =
    (centre, e1, e2, r) with p = c + r (cos(x / r) e1 + sin(x / r) e2), x = sigma - sigma0."""

    def _finish(self, pieces):
        self._pieces = pieces
        self._s0 = np.array([p[0] for p in pieces])
        self._len = sum(p[1] for p in pieces)
        self._lam = self._len / TWO_PI
        self.breaks = self._s0[1:] / self._lam
        P0 = np.array([p[3][0] for p in pieces])                 # point or centre
        E1 = np.array([p[3][1] for p in pieces])                 # direction or e1
        E2 = np.array([p[3][2] if p[2] == 'arc' else np.zeros(3) for p in pieces])
        R = np.array([p[3][3] if p[2] == 'arc' else np.inf for p in pieces])
        self._arr = (P0, E1, E2, R, np.array([p[2] == 'arc' for p in pieces]))

    @property
    def length(self) -> float:
        return self._len

    def _eval(self, theta, order):
        th = np.asarray(theta, float)
        sig = th.ravel() * self._lam
        k = np.clip(np.searchsorted(self._s0, sig, side='right') - 1, 0, len(self._pieces) - 1)
        x = (sig - self._s0[k])[:, None]
        P0, E1, E2, R, arc = (a[k] for a in self._arr)
        Rr = np.where(arc, R, 1.0)[:, None]
        ang = x / Rr
        c, s = np.cos(ang), np.sin(ang)
        isarc = arc[:, None]
        lam = self._lam
        if order == 0:
            out = np.where(isarc, P0 + Rr * (c * E1 + s * E2), P0 + x * E1)
        elif order == 1:
            out = lam * np.where(isarc, -s * E1 + c * E2, E1)
        else:
            out = lam ** 2 * np.where(isarc, -(c * E1 + s * E2) / Rr, 0.0 * E1)
        return out.reshape(th.shape + (3,))

    def point(self, theta):
        return self._eval(theta, 0)

    def d_point(self, theta):
        return self._eval(theta, 1)

    def dd_point(self, theta):
        return self._eval(theta, 2)


def _waypoints(waypoints, closed, least):
    w = np.asarray(waypoints, float)
    if w.ndim != 2 or w.shape[1] != 3 or not np.all(np.isfinite(w)):
        raise ValueError('waypoints must be a list of finite [x, y, z] points')
    if closed and w.shape[0] > 1 and np.linalg.norm(w[-1] - w[0]) < 1e-9:
        w = w[:-1]                          # a closed list may repeat its first point
    if w.shape[0] < least:
        raise ValueError(f'needs at least {least} distinct waypoints, got {w.shape[0]}')
    seg = np.linalg.norm(np.diff(np.vstack([w, w[:1]]) if closed else w, axis=0), axis=1)
    if np.any(seg < 1e-6):
        raise ValueError(f'consecutive waypoints {int(np.argmin(seg))} and the next coincide')
    return w


class PolylinePath(_Pieces):
    """Straight segments through waypoints (K, 3) [m] with a circular blend at every corner.

    blend_radii: one radius [m] for all corners, or one per corner (K - 2 open; K closed, the
    corner at waypoint k for k = 0..K-1). The blend is the arc of that radius tangent to both
    segments, so the path is C1 and its curvature is 0 or 1 / radius: the speed need not drop
    to zero at a corner. A closed polyline runs from waypoint 0 round to it; waypoint 0 must
    lie on a straight stretch (between its neighbours), so the path starts and ends on a line.
    """

    def __init__(self, waypoints, blend_radii, closed: bool = False):
        self.closed = bool(closed)
        w = _waypoints(waypoints, self.closed, 3 if self.closed else 2)
        self.waypoints = w
        K = w.shape[0]
        corners = list(range(K)) if self.closed else list(range(1, K - 1))
        r = np.atleast_1d(np.asarray(blend_radii, float))
        if r.size == 1 and corners:
            r = np.full(len(corners), float(r[0]))
        if r.size != len(corners) and corners:
            raise ValueError(f'{len(corners)} corners need 1 or {len(corners)} blend radii, '
                             f'got {r.size}')
        if not np.all(np.isfinite(r)) or np.any(r < 0):
            raise ValueError('blend radii must be finite and >= 0')
        self.blend_radii = r if corners else np.zeros(0)
        pts = np.vstack([w, w[:1]]) if self.closed else w
        nseg = pts.shape[0] - 1
        dirs = np.diff(pts, axis=0)
        seglen = np.linalg.norm(dirs, axis=1)
        dirs = dirs / seglen[:, None]
        # the corner at waypoint k joins segment k-1 (in) and k (out), cyclically if closed
        cut = np.zeros((nseg, 2))         # length taken from the start / end of each segment
        arcs = {}
        for j, k in enumerate(corners):
            d_in, d_out = dirs[(k - 1) % nseg], dirs[k % nseg]
            cos_a = float(d_in @ d_out)
            alpha = math.atan2(float(np.linalg.norm(np.cross(d_in, d_out))), cos_a)
            if alpha < 1e-9:
                continue                  # straight through: no blend needed
            if k == 0:
                raise ValueError('waypoint 0 of a closed polyline is a corner: start on a '
                                 'straight stretch (add a waypoint between two corners)')
            if alpha > math.pi - 1e-6:
                raise ValueError(f'the path turns back at waypoint {k}: no blend possible')
            if not r[j] > 0:
                raise ValueError(f'corner at waypoint {k} needs a blend radius > 0 (a sharp '
                                 'corner stops the motion)')
            t = r[j] * math.tan(alpha / 2)
            cut[(k - 1) % nseg, 1] = t
            cut[k % nseg, 0] = t
            n1 = _unit(d_out - cos_a * d_in)
            arcs[k] = (w[k] - t * d_in + r[j] * n1, -n1, d_in, r[j], alpha)
        free = seglen - cut.sum(axis=1)
        if np.any(free < -1e-12):
            i = int(np.argmin(free))
            raise ValueError(f'blends overlap on segment {i} ({seglen[i] * 1e3:.1f} mm long, '
                             f'blends take {cut[i].sum() * 1e3:.1f} mm): smaller blend radii')
        pieces, s = [], 0.0
        for i in range(nseg):
            if free[i] > 1e-12:
                pieces.append((s, free[i], 'line', (pts[i] + cut[i, 0] * dirs[i], dirs[i],
                                                    None, None)))
                s += free[i]
            k = i + 1
            if k in arcs or (self.closed and k == nseg and 0 in arcs):
                c, e1, e2, rr, alpha = arcs[k % K]
                pieces.append((s, rr * alpha, 'arc', (c, e1, e2, rr)))
                s += rr * alpha
        self._finish(pieces)


class SplinePath(PathBase):
    """C2 cubic spline through waypoints (K, 3) [m] (scipy CubicSpline on chord length;
    'natural' ends, or periodic if ``closed``), re-parametrised by arc length: the arc length
    of the spline parameter u by 12-point Gauss-Legendre per piece of a dense table
    (TABLE_PIECES per knot interval), its inverse by Newton steps from that table (to
    ~1e-12 m), so p' = (L / 2 pi) T (unit tangent) and p'' = (L / 2 pi)^2 kappa N exactly
    (no speed ripple along the path). (One Gauss-Legendre rule per knot interval was off by
    up to 3e-4 m where a long interval holds a tight bend, issue 28: p(theta) then disagreed
    with p' by up to 1.6 % of a 0.4 mm step, and a plan's points, taken from p, with its
    velocities and accelerations, taken from p' and p'': played by quintic interpolation a
    closed spline's periodic plan had a joint jerk of 1847 rad/s^3 where the profile has
    193.)"""

    #: table pieces per knot interval, each integrated by 12-point Gauss-Legendre
    TABLE_PIECES = 64

    _GL = np.polynomial.legendre.leggauss(12)

    def __init__(self, waypoints, closed: bool = False):
        from scipy.interpolate import CubicSpline
        self.closed = bool(closed)
        w = _waypoints(waypoints, self.closed, 3 if self.closed else 2)
        self.waypoints = w
        pts = np.vstack([w, w[:1]]) if self.closed else w
        u = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        self._sp = CubicSpline(u, pts, bc_type='periodic' if self.closed else 'natural')
        self._d1, self._d2 = self._sp.derivative(1), self._sp.derivative(2)
        self._u = u
        # a dense table of (u, sigma): Gauss-Legendre on every piece, summed
        m = self.TABLE_PIECES
        tu = np.concatenate([np.linspace(u[i], u[i + 1], m + 1)[:-1] for i in range(u.size - 1)]
                            + [u[-1:]])
        x, wts = self._GL
        mid, half = 0.5 * (tu[1:] + tu[:-1]), 0.5 * np.diff(tu)
        sp = np.linalg.norm(self._d1(mid[:, None] + half[:, None] * x[None, :]), axis=2)
        self._tu = tu
        self._ts = np.concatenate([[0.0], np.cumsum(half * (sp * wts).sum(axis=1))])
        self._sk = self._ts[::m]                      # at the knots
        self._len = float(self._ts[-1])
        self._lam = self._len / TWO_PI
        self.breaks = np.zeros(0)
        speed = np.linalg.norm(self._d1(tu), axis=1)
        if speed.min() < 1e-3 * speed.max():
            raise ValueError('the spline through these waypoints nearly stops (a cusp): '
                             'space the waypoints more evenly')

    def _sigma(self, u):
        """Arc length [m] from the start to spline parameter(s) u (M,): the table's value at
        the start of u's piece plus Gauss-Legendre over the rest."""
        u = np.asarray(u, float)
        k = np.clip(np.searchsorted(self._tu, u, side='right') - 1, 0, self._tu.size - 2)
        a = self._tu[k]
        x, wts = self._GL
        m, h = 0.5 * (a + u), 0.5 * (u - a)
        sp = np.linalg.norm(self._d1(m[:, None] + h[:, None] * x[None, :]), axis=2)
        return self._ts[k] + h * (sp * wts).sum(axis=1)

    @property
    def length(self) -> float:
        return self._len

    @property
    def knots(self) -> np.ndarray:
        """theta [rad] of the interior knots, where p''' jumps (p'' is continuous) (K,)."""
        return self._sk[1:-1] / self._lam

    def _u_of(self, theta):
        sig = np.clip(np.asarray(theta, float).ravel() * self._lam, 0.0, self._len)
        u = np.interp(sig, self._ts, self._tu)
        for _ in range(3):
            u = u - (self._sigma(u) - sig) / np.linalg.norm(self._d1(u), axis=1)
            u = np.clip(u, self._u[0], self._u[-1])
        return u

    def point(self, theta):
        return self._sp(self._u_of(theta)).reshape(np.shape(theta) + (3,))

    def d_point(self, theta):
        d1 = self._d1(self._u_of(theta))
        out = self._lam * d1 / np.linalg.norm(d1, axis=1)[:, None]
        return out.reshape(np.shape(theta) + (3,))

    def dd_point(self, theta):
        u = self._u_of(theta)
        d1, d2 = self._d1(u), self._d2(u)
        sp = np.linalg.norm(d1, axis=1)[:, None]
        us = 1.0 / sp                                       # du/dsigma
        uss = -(d1 * d2).sum(axis=1)[:, None] / sp ** 4     # d2u/dsigma2
        out = self._lam ** 2 * (d2 * us ** 2 + d1 * uss)
        return out.reshape(np.shape(theta) + (3,))


def path_from_spec(spec: dict) -> PathBase:
    """A path from a plain mapping (a YAML file's, or a PathSpec message's fields).

    type 'circle': center, radius, start_angle (0), direction (+1) -- horizontal (thesis);
    'arc': center, normal, radius, start_angle (0), sweep (2 pi);
    'line': waypoints [start, end];
    'polyline': waypoints, blend_radii (one, or one per corner), closed (false);
    'spline': waypoints, closed (false).
    An optional ``process`` block (TCP speed band, ``process_from_spec``) is not geometry and
    is ignored here. ValueError with the reason for anything else.
    """
    if not isinstance(spec, dict):
        raise ValueError('a path spec must be a mapping with a "type"')
    kind = spec.get('type', 'circle') or 'circle'
    known = {'circle': {'center', 'radius', 'start_angle', 'direction'},
             'arc': {'center', 'normal', 'radius', 'start_angle', 'sweep'},
             'line': {'waypoints'}, 'polyline': {'waypoints', 'blend_radii', 'closed'},
             'spline': {'waypoints', 'closed'}}
    if kind not in known:
        raise ValueError(f'unknown path type {kind!r}; one of {list(PATH_TYPES)}')
    extra = set(spec) - known[kind] - {'type', PROCESS_KEY}
    if 'orientation' in extra:
        # read by irb_description.orientation (six axes); the three-axis planner and pdplus
        # cannot keep a tool orientation, and say so rather than drop the block
        raise ValueError("an 'orientation' block needs the six-axis chain "
                         '(irb_description.orientation, doc/six_axis.md; plan it with '
                         '`ros2 run irb_planning plan6`); the planner and pdplus drive '
                         'joints 1-3 with the wrist locked')
    if extra:
        raise ValueError(f'path type {kind!r} takes {sorted(known[kind])}, not {sorted(extra)}')

    def need(key):
        if key not in spec:
            raise ValueError(f'path type {kind!r} needs {key!r}')
        return spec[key]

    def num(key, default):
        x = spec.get(key, default)
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise ValueError(f'{key} must be a number, got {x!r}')
        return float(x)
    try:
        if kind == 'circle':
            d = spec.get('direction', 1)
            return CirclePath(np.asarray(need('center'), float), num('radius', 0.0),
                              num('start_angle', 0.0), d if d in (1, -1) else d)
        if kind == 'arc':
            return ArcPath(np.asarray(need('center'), float), np.asarray(need('normal'), float),
                           num('radius', 0.0), num('start_angle', 0.0), num('sweep', TWO_PI))
        w = np.asarray(need('waypoints'), float)
        if kind == 'line':
            if w.shape != (2, 3):
                raise ValueError('a line needs waypoints [[x, y, z], [x, y, z]] (start, end)')
            return LinePath(w[0], w[1])
        closed = spec.get('closed', False)
        if not isinstance(closed, bool):
            raise ValueError(f'closed must be true or false, got {closed!r}')
        if kind == 'polyline':
            return PolylinePath(w, spec.get('blend_radii', [0.0]), closed)
        return SplinePath(w, closed)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{kind}: {exc}') from None


def process_from_spec(spec: dict) -> dict:
    """The ``process`` block of a path mapping as {field: float} (only the fields it has; {}
    without a block): a process's constraints along the path, e.g. a gluing bead's speed band

        process: {tcp_speed_max: 0.15, tcp_speed_min: 0.09, tcp_accel_max: 1.0,
                  tcp_ramp_length: 0.04}

    ValueError (one line) for unknown keys or values that are not finite numbers >= 0. Whether
    the band fits the path and the duration is the planner's to judge."""
    if not isinstance(spec, dict) or spec.get(PROCESS_KEY) is None:
        return {}
    block = spec[PROCESS_KEY]
    if not isinstance(block, dict):
        raise ValueError(f'{PROCESS_KEY} must be a mapping of {list(PROCESS_FIELDS)}')
    extra = set(block) - set(PROCESS_FIELDS)
    if extra:
        raise ValueError(f'{PROCESS_KEY} takes {list(PROCESS_FIELDS)}, not {sorted(extra)}')
    out = {}
    for key, x in block.items():
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) \
                or x < 0:
            raise ValueError(f'{PROCESS_KEY}.{key} must be a finite number >= 0, got {x!r}')
        out[key] = float(x)
    return out


def path_spec(path: PathBase) -> dict:
    """The plain mapping ``path_from_spec`` builds ``path`` from (YAML-ready lists/floats)."""
    if isinstance(path, CirclePath):
        return dict(type='circle', center=path.center.tolist(), radius=float(path.radius),
                    start_angle=float(path.start_angle), direction=int(path.direction))
    if isinstance(path, ArcPath):
        return dict(type='arc', center=path.center.tolist(), normal=path.normal.tolist(),
                    radius=float(path.radius), start_angle=float(path.start_angle),
                    sweep=float(path.sweep))
    if isinstance(path, LinePath):
        return dict(type='line', waypoints=[path.start.tolist(), path.end.tolist()])
    if isinstance(path, PolylinePath):
        return dict(type='polyline', waypoints=path.waypoints.tolist(),
                    blend_radii=path.blend_radii.tolist(), closed=path.closed)
    if isinstance(path, SplinePath):
        return dict(type='spline', waypoints=path.waypoints.tolist(), closed=path.closed)
    raise ValueError(f'not a path: {path!r}')


def rectangle_path(center, normal, width: float, height: float, blend_radius: float,
                   axis=None) -> PolylinePath:
    """A closed rectangle width x height [m] about ``center`` in the plane with ``normal``,
    corners blended with ``blend_radius`` [m]; the width runs along ``axis`` (default: the
    plane's u axis, ``plane_axes``); starts in the middle of the first width edge."""
    u, v, n = plane_axes(normal)
    if axis is not None:
        u = _unit(np.asarray(axis, float) - (np.asarray(axis, float) @ n) * n, 'axis')
        v = np.cross(n, u)
    c = np.asarray(center, float)
    hw, hh = 0.5 * width, 0.5 * height
    w = [c - hh * v, c + hw * u - hh * v, c + hw * u + hh * v, c - hw * u + hh * v,
         c - hw * u - hh * v]
    return PolylinePath(np.array(w), [0.0] + [blend_radius] * 4, closed=True)


@dataclass(frozen=True)
class JointPath:
    """Phi, Phi', Phi'' sampled on a theta grid: theta (N,), q/dq/ddq (N, 3)."""

    theta: np.ndarray
    q: np.ndarray      # [rad]
    dq: np.ndarray     # [rad/rad]
    ddq: np.ndarray    # [rad/rad^2]


def joint_path(model: RobotModel, path: PathBase, theta: np.ndarray,
               branch: str = 'elbow_up') -> JointPath:
    """Phi(theta), Phi'(theta), Phi''(theta) of ``path`` at the grid ``theta`` (N,) [rad].

    Any path type (theta in [0, 2 pi]); the elbow stays on ``branch`` all along, joint 1 is
    atan2 (``check_joint_path`` makes sure it does not wrap on the way).
    Raises model.UnreachableError when any point is outside the workspace or joint limits.
    """
    theta = np.atleast_1d(np.asarray(theta, float))
    q = model.ik_many(path.point(theta), branch)
    dq, ddq = model.arm_derivatives(q, path.d_point(theta), path.dd_point(theta))
    return JointPath(theta, q, dq, ddq)


def thesis_circle() -> CirclePath:
    """The thesis's circle: centre (0.6, 0, 0.13) m, r = 0.15 m, start at (0.75, 0, 0.13)."""
    return CirclePath(np.array([0.6, 0.0, 0.13]), 0.15, 0.0, 1)


def check_joint_path(model: RobotModel, path: PathBase, samples: int = 4096,
                     branch: str = 'elbow_up') -> None:
    """Check the whole joint motion along ``path``, not only points: reachable everywhere,
    continuous (joint 1 unwrapped across +-180 deg) and inside the position limits between the
    samples too. Raises UnreachableError naming the joint, theta [rad] and the TCP point.

    Also refused: a joint that jumps between two samples by more than 4 times what its
    derivative Phi' allows (passing the base axis, where joint 1 turns by pi, or a stretched
    arm, where the elbow would change branch).

    ``samples`` theta values over [0, 2 pi] plus the pieces' ends; between two samples a
    joint cannot pass a limit unseen: the check uses max(q_k, q_k+1) + |q''| dtheta^2 / 8 (the
    largest excursion of a function with that curvature above its chord), q'' by finite
    differences.
    """
    theta = np.union1d(np.linspace(0.0, 2.0 * np.pi, samples), path.breaks)
    pts = path.point(theta)
    try:
        q = model.ik_many(pts, branch, check_limits=False)
    except UnreachableError as exc:
        raise UnreachableError(f'the path leaves the workspace: {exc}') from None
    q[:, 0] = np.unwrap(q[:, 0])
    q[:, 0] -= 2 * np.pi * np.round(q[0, 0] / (2 * np.pi))    # start inside (-pi, pi]
    h = np.diff(theta)
    with np.errstate(divide='ignore', invalid='ignore'):
        dq, _ = model.arm_derivatives(q, path.d_point(theta), path.dd_point(theta))
    allowed = 4.0 * np.maximum(np.abs(dq[:-1]), np.abs(dq[1:])) * h[:, None] + 1e-9
    jump = np.abs(np.diff(q, axis=0)) > allowed
    if np.any(jump) or not np.all(np.isfinite(dq)):
        k, i = (np.unravel_index(int(np.argmax(jump)), jump.shape) if np.any(jump)
                else np.unravel_index(int(np.argmax(~np.isfinite(dq))), dq.shape))
        raise UnreachableError(
            f'{model.joint_names[i]} jumps along the path near theta = {theta[k]:.4f} rad, '
            f'point {np.round(pts[k], 4).tolist()} m (the path passes the base axis or a '
            'stretched arm, where the inverse kinematics changes branch)')
    ddq = np.zeros_like(q)
    ddq[1:-1] = 2 * ((q[2:] - q[1:-1]) / h[1:, None] - (q[1:-1] - q[:-2]) / h[:-1, None]) / (
        h[1:, None] + h[:-1, None])
    hh = h[:, None]
    curv = np.maximum(np.abs(ddq[:-1]), np.abs(ddq[1:])) * hh ** 2 / 8
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


def read_path_spec(name):
    """The mapping a YAML path file holds (not checked as a path yet); ValueError with one line
    saying why not (missing file, not YAML)."""
    import yaml
    try:
        with open(name) as f:
            return yaml.safe_load(f)
    except OSError as exc:
        raise ValueError(f'cannot read path file {name}: {exc.strerror}') from None
    except yaml.YAMLError as exc:
        raise ValueError(f'path file {name} is not YAML: {yaml_problem(exc)}') from None


def load_path_file(name) -> PathBase:
    """A path from a YAML file holding a ``path_from_spec`` mapping; ValueError with one line
    saying why not (missing file, not YAML, not a valid path)."""
    spec = read_path_spec(name)
    try:
        return path_from_spec(spec)
    except ValueError as exc:
        raise ValueError(f'path file {name}: {exc}') from None
