"""A certificate for a refused TCP speed floor under the TCP jerk limit (issue 28): a lower
bound on the TCP jerk that every motion along the path with its TCP speed in [v_min, v_max]
has, from the path's geometry alone. No ROS imports.

For a motion along a path of curvature kappa(s) at speed v(s) (arc length s, tangential
acceleration a_t = v dv/ds), the Frenet frame gives the TCP jerk's component along the
principal normal N exactly:

    jerk . N = 3 kappa v a_t + dkappa/ds v^3 = d(kappa v^3)/ds

so |d(kappa v^3)/ds| <= |jerk| <= J along the path, whatever the time law. With v_min <= v(s)
<= v_max(s), kappa v^3 lies in [kappa v_min^3, kappa v_max^3] at every s, and for any two
points s_1, s_2 (arc length ell between them along the path, either way round a closed one)

    J >= (kappa(s_2) v_min^3 - kappa(s_1) v_max(s_1)^3) / ell.

The certificate is the largest such bound over pairs of fine path samples: a tight bend
entered from a straighter stretch at least v_min fast needs kappa v^3 to rise by that much
within ell. s_2 only where the floor holds (beyond the rest ramps); v_max(s) the smaller of
tcp_speed_max and the speed the joint speed limits allow there. A curvature jump (a circular
blend's end) makes the normal jerk unbounded for every motion at speed: the planner exempts
those, so paths with interior piece ends get no certificate here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: rows of the pair table computed at once (CHUNK x M floats)
CHUNK = 256


@dataclass(frozen=True)
class JerkCertificate:
    """Every motion along the path within the speed band has a TCP jerk of at least ``need``
    [m/s^3] (its normal component) somewhere between ``from_m`` and ``to_m`` of arc length
    (``to_m`` < ``from_m`` on a closed path: across its start); ``limit`` the planner's."""

    need: float
    limit: float
    from_m: float
    to_m: float
    kappa_from: float       # [1/m] curvature at from_m (speed at most v_max there)
    kappa_to: float         # [1/m] at to_m (speed at least v_min there)

    @property
    def ratio(self) -> float:
        return self.need / self.limit

    @property
    def proves(self) -> bool:
        """The bound exceeds the limit: no motion in the band keeps the limit."""
        return self.need > self.limit

    def shortfall(self) -> str:
        """Why a bound at or below the limit proves nothing (a refusal without certificate)."""
        return (f'no certificate: the strongest TCP jerk bound of certificate.py is '
                f'{self.need:.4g} m/s^3 <= the limit {self.limit:.4g} m/s^3 '
                f'(kappa v^3 from {self.from_m * 1e3:.1f} mm to {self.to_m * 1e3:.1f} mm)')

    def text(self) -> str:
        return (f'every motion with its TCP speed in the band has a TCP jerk of at least '
                f'{self.need:.4g} m/s^3 > the limit {self.limit:.4g} m/s^3 (by '
                f'{100 * (self.ratio - 1):.1f} %; tcp_jerk_limit_m_s3): kappa v^3 must rise '
                f'from at most {self.kappa_from:.3g} 1/m x v_max^3 at {self.from_m * 1e3:.1f} mm '
                f'to at least {self.kappa_to:.3g} 1/m x v_min^3 at {self.to_m * 1e3:.1f} mm '
                'along the path, and its rate d(kappa v^3)/ds is the jerk\'s normal '
                'component (certificate.py)')


def curvature(d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """|p' x p''| / |p'|^3 (M,) [1/m] from derivatives in any parameter (M, 3)."""
    return (np.linalg.norm(np.cross(d1, d2), axis=1)
            / np.linalg.norm(d1, axis=1) ** 3)


def jerk_certificate(sigma: np.ndarray, length: float, kappa: np.ndarray, v_cap: np.ndarray,
                     v_min: float, tcp_jerk: float, periodic: bool,
                     zone: tuple[float, float] | None = None, strict: bool = True
                     ) -> JerkCertificate | None:
    """The strongest bound (None: none above ``tcp_jerk`` (``strict``; else the strongest
    one whatever its value, None only without a positive one), or no TCP jerk limit).

    sigma (M,) arc length [m] of fine path samples (increasing from 0), ``length`` [m] the
    path's (a closed path's loop closes from the last sample back to the first); kappa (M,)
    curvature [1/m]; v_cap (M,) the highest TCP speed allowed there [m/s]; v_min [m/s] the
    floor, which holds on ``zone`` (s_lo, s_hi) [m] (None: all along); tcp_jerk [m/s^3]."""
    if not tcp_jerk > 0 or not v_min > 0:
        return None
    sigma = np.asarray(sigma, float)
    lo = kappa * v_min ** 3
    hi = kappa * np.asarray(v_cap, float) ** 3
    inside = np.ones(sigma.size, bool) if zone is None else (
        (sigma >= zone[0]) & (sigma <= zone[1]))
    cand = np.flatnonzero(inside)
    best, k_best, i_best = -np.inf, -1, -1
    for start in range(0, cand.size, CHUNK):         # every pair, CHUNK rows at a time
        rows = cand[start:start + CHUNK]
        ell = np.abs(sigma[None, :] - sigma[rows][:, None])
        if periodic:
            ell = np.minimum(ell, length - ell)
        with np.errstate(divide='ignore', invalid='ignore'):
            need = np.where(ell > 0, (lo[rows][:, None] - hi[None, :]) / ell, -np.inf)
        k, i = np.unravel_index(int(np.argmax(need)), need.shape)
        if need[k, i] > best:
            best, k_best, i_best = float(need[k, i]), int(rows[k]), int(i)
    if not best > (tcp_jerk if strict else 0.0):
        return None
    j, i = k_best, i_best
    return JerkCertificate(best, float(tcp_jerk), float(sigma[i]),
                           float(sigma[j]), float(kappa[i]), float(kappa[j]))
