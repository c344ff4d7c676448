"""The path parameter of a moving TCP: projection onto the path near the previous estimate.

Used by the controller every sample (thesis §6.4 computes theta by atan2 about the circle's
centre; for any other path this module does the same job): ``PathTracker.update(p, prev)``
returns the theta in [0, 2 pi] of the path point nearest to p among those within
``window_m`` of arc length of the previous estimate, so it never jumps to a distant part of
a path that comes back near itself (a figure of eight, the two long sides of a narrow
rectangle). For the horizontal ``CirclePath`` use its ``theta_of`` (atan2, the thesis).

How: a table of the path's points and tangents every ``spacing_m`` (with the pieces' ends);
the nearest table point inside the window, then the exact minimum of the distance on the
cubic Hermite curve through the two neighbouring intervals (a few Newton steps in plain
floats). Interpolation error O(h^4 / r^3): 1e-10 m at h = 2 mm on a 20 mm blend.
Measured cost: see irb_control/benchmarks/bench_paths.py (about 20 us per update).
numpy only, no ROS.
"""
from __future__ import annotations

import math
from bisect import bisect_right

import numpy as np

from .path import TWO_PI, PathBase


class PathTracker:
    """Follows the path parameter of a point moving along ``path`` (see module docstring)."""

    def __init__(self, path: PathBase, spacing_m: float = 2e-3, window_m: float = 0.02):
        self.path = path
        th, pts = path.table(spacing_m)
        self.theta = th
        self.points = pts
        self.tangents = path.d_point(th)
        self.closed = bool(path.closed)
        n = th.size - 1 if self.closed else th.size      # distinct nodes (2 pi == 0 closed)
        self._n = n
        step = float(np.max(np.diff(th))) * path.length / TWO_PI
        self._w = max(int(math.ceil(window_m / max(step, 1e-9))), 2)
        # the table padded by the window on both sides (cyclically if closed): one slice
        w = self._w
        if self.closed:
            pad = np.concatenate([np.arange(n - w, n) % n, np.arange(n), np.arange(w + 2) % n])
        else:
            pad = np.concatenate([np.zeros(w, int), np.arange(th.size),
                                  np.full(w + 2, th.size - 1)])
        self._pad_idx = pad
        self._pad_pts = pts[pad]
        self._pts_l = pts.tolist()
        self._tan_l = self.tangents.tolist()
        self._th_l = th.tolist()

    def index(self, theta: float) -> int:
        """Table interval containing ``theta``."""
        j = bisect_right(self._th_l, theta) - 1
        return min(max(j, 0), len(self._th_l) - 2)

    def update(self, p, theta_prev: float) -> float:
        """theta [rad] of the path point nearest p (3,) within the window around
        ``theta_prev`` (in [0, 2 pi]; wraps for closed paths)."""
        x, y, z = float(p[0]), float(p[1]), float(p[2])
        j0 = self.index(theta_prev)
        w = self._w
        d = self._pad_pts[j0:j0 + 2 * w + 2] - np.array((x, y, z))
        k = int(np.argmin(np.einsum('ij,ij->i', d, d)))
        j = int(self._pad_idx[j0 + k])
        # the interval ahead of node j if p lies ahead of it along the tangent, else behind
        P, T = self._pts_l[j], self._tan_l[j]
        ahead = (x - P[0]) * T[0] + (y - P[1]) * T[1] + (z - P[2]) * T[2] >= 0.0
        if ahead:
            a = j if j + 1 < self.theta.size else j - 1
        else:
            a = (j - 1) % self._n if self.closed else max(j - 1, 0)
        best = self._hermite_min(a, x, y, z)
        if self.closed and best >= TWO_PI:
            best -= TWO_PI
        return best

    def _hermite_min(self, a: int, x: float, y: float, z: float) -> float:
        """theta of the point nearest (x, y, z) on the cubic Hermite curve over table
        interval a (clamped to the interval), by Newton steps from the chord projection."""
        t0, t1 = self._th_l[a], self._th_l[a + 1]
        h = t1 - t0
        p0x, p0y, p0z = self._pts_l[a]
        p1x, p1y, p1z = self._pts_l[a + 1]
        m0x, m0y, m0z = self._tan_l[a]
        m1x, m1y, m1z = self._tan_l[a + 1]
        m0x, m0y, m0z, m1x, m1y, m1z = m0x * h, m0y * h, m0z * h, m1x * h, m1y * h, m1z * h
        # c(u) - p = A u^3 + B u^2 + C u + D, u in [0, 1]
        ax, ay, az = (2 * (p0x - p1x) + m0x + m1x, 2 * (p0y - p1y) + m0y + m1y,
                      2 * (p0z - p1z) + m0z + m1z)
        bx, by, bz = (3 * (p1x - p0x) - 2 * m0x - m1x, 3 * (p1y - p0y) - 2 * m0y - m1y,
                      3 * (p1z - p0z) - 2 * m0z - m1z)
        dx, dy, dz = p0x - x, p0y - y, p0z - z
        cx, cy, cz = p1x - p0x, p1y - p0y, p1z - p0z
        cc = cx * cx + cy * cy + cz * cz
        u = -(dx * cx + dy * cy + dz * cz) / cc if cc > 0 else 0.0
        u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
        for _ in range(3):
            ex = ((ax * u + bx) * u + m0x) * u + dx
            ey = ((ay * u + by) * u + m0y) * u + dy
            ez = ((az * u + bz) * u + m0z) * u + dz
            fx = (3 * ax * u + 2 * bx) * u + m0x
            fy = (3 * ay * u + 2 * by) * u + m0y
            fz = (3 * az * u + 2 * bz) * u + m0z
            f = ex * fx + ey * fy + ez * fz
            fp = (fx * fx + fy * fy + fz * fz + ex * (6 * ax * u + 2 * bx)
                  + ey * (6 * ay * u + 2 * by) + ez * (6 * az * u + 2 * bz))
            if fp <= 0.0:
                break
            u -= f / fp
            u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
        return t0 + u * h
