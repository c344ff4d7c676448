"""The thesis's Fourier theta-speed profile (eq. 6.4-6.6), optimised with IPOPT (baseline).

    theta_dot = h(theta) = c_0 + sum_{i=1..n} (a_i sin(i theta) + b_i cos(i theta))  [rad/s]
    theta_ddot = h'(theta) h(theta)                                               (6.6)

with order n in {3, 5, 7} (2n + 1 coefficients; c_0 is the thesis's b_1, the mean of h over
theta, eq. 6.5; omega = 1 so the profile is 2 pi-periodic: the motion starts and ends at
theta_dot = h(0) > 0, as in the thesis). On K uniform nodes of [0, 2 pi) (periodic, so the
trapezoidal rule is spectrally accurate for smooth integrands):

    minimise  w_E E + w_T T,  E = (2 pi / K) sum_k sum_i |tau_ik Phi'_ik|,  T = (2 pi/K) sum 1/h_k
    s.t.      h_k >= delta, |Phi'_i h_k| <= v_max,i, |tau_ik| <= tau_max,i, T = T_req (or free)

with tau = m h h' + c h^2 + g + tau_f(Phi' h) (problem.PathDynamics) and |.| exact by the
split y = e+ - e- (e+, e- >= 0). No ROS imports.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Callable

import casadi as ca
import numpy as np

from .problem import PathDynamics, SolveStats, ipopt_options, speed_bound
from .profile import ThetaProfile
from .transcription import SolveRequest

ORDERS = (3, 5, 7)


def fourier_basis(theta: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """B, dB (K, 2 order + 1) with h = B c and h' = dB c for c = (c_0, a_1..a_n, b_1..b_n)."""
    theta = np.asarray(theta, float)[:, None]
    i = np.arange(1, order + 1)[None, :]
    B = np.hstack([np.ones((theta.shape[0], 1)), np.sin(i * theta), np.cos(i * theta)])
    dB = np.hstack([np.zeros((theta.shape[0], 1)), i * np.cos(i * theta),
                    -i * np.sin(i * theta)])
    return B, dB


def fourier_theta_dot(coeffs: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """h(theta) (K,) [rad/s] for coefficients (2 n + 1,)."""
    coeffs = np.asarray(coeffs, float)
    return fourier_basis(theta, (coeffs.size - 1) // 2)[0] @ coeffs


def fourier_theta_ddot(coeffs: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """h'(theta) h(theta) (K,) [rad/s^2] (eq. 6.6)."""
    coeffs = np.asarray(coeffs, float)
    B, dB = fourier_basis(theta, (coeffs.size - 1) // 2)
    return (dB @ coeffs) * (B @ coeffs)


@dataclass(frozen=True)
class FourierResult:
    """coeffs (2n+1,); profile sampled on ``n_profile`` nodes; energy [J], duration [s] of
    the optimiser's quadrature; peak torque (n,) [N m]; stats."""

    coeffs: np.ndarray
    profile: ThetaProfile
    energy: float
    duration: float
    peak_torque: np.ndarray
    stats: SolveStats


class FourierProblem:
    """Fourier NLP of one order on one path and periodic grid (nodes exclude 2 pi)."""

    def __init__(self, nodes: PathDynamics, friction: Callable, order: int,
                 max_iter: int = 1000, tol: float = 1e-8, n_profile: int = 2001):
        if order not in ORDERS:
            raise ValueError(f'Fourier order must be one of {ORDERS}, not {order}')
        t0 = time.perf_counter()
        self.nodes, self.order, self.n_profile = nodes, order, n_profile
        self._lock = threading.Lock()
        K, n = nodes.dq.shape
        self.K, self.n = K, n
        w = 2 * np.pi / K
        B, dB = fourier_basis(nodes.theta, order)

        # --- decision variables ----------------------------------------------------------
        c = ca.SX.sym('c', 2 * order + 1)
        e = ca.SX.sym('e', 2 * n * K)                # |y| = e+ + e-
        x = ca.vertcat(c, e)
        p = ca.SX.sym('p', 2)                        # (w_E, w_T)

        # --- dynamics ----------------------------------------------------------------------
        h = ca.mtimes(ca.DM(B), c)
        dh = ca.mtimes(ca.DM(dB), c)
        rep = lambda row: ca.repmat(ca.reshape(row, 1, -1), n, 1)  # noqa: E731
        rigid = (ca.DM(nodes.m.T) * rep(h * dh) + ca.DM(nodes.c.T) * rep(h ** 2)
                 + ca.DM(nodes.g.T))
        tau = rigid + friction(ca.DM(nodes.dq.T) * rep(h))
        y = ca.vec(tau * ca.DM(nodes.dq.T))

        # --- objective -------------------------------------------------------------------
        e_pos, e_neg = e[:n * K], e[n * K:]
        energy = w * ca.sum1(e_pos + e_neg)
        duration = w * ca.sum1(1 / h)
        f = p[0] * energy + p[1] * duration

        # --- path constraints ------------------------------------------------------------
        sg = np.sign(nodes.dq.T)
        rev = (sg != np.roll(sg, -1, axis=1)).ravel(order='F')
        self._rev_joint = np.flatnonzero(rev) % n
        probe = ca.DM(np.array([[0.01, -0.01]] * n))
        self._breakaway = np.abs(np.asarray(friction(probe))).max(axis=1)
        g = ca.vertcat(duration, h, ca.vec(tau), ca.vec(rigid)[np.flatnonzero(rev).tolist()],
                       y - e_pos + e_neg)

        # --- solver ------------------------------------------------------------------------
        self._solver = ca.nlpsol('fourier', 'ipopt', {'x': x, 'p': p, 'f': f, 'g': g},
                                 ipopt_options(max_iter, tol))
        self._aux = ca.Function('aux', [x], [w * ca.sum1(ca.fabs(y)), duration, ca.vec(tau),
                                             y])
        self._ne = e.numel()
        self.build_time = time.perf_counter() - t0

    def solve(self, req: SolveRequest) -> FourierResult:
        """Solve from the constant profile with the requested mean duration (cold start)."""
        K, n = self.K, self.n
        nc = 2 * self.order + 1
        beta = speed_bound(self.nodes.dq, req.velocity_limit)
        tau_max = np.tile(np.asarray(req.torque_limit, float), K)
        tau_rev = (np.asarray(req.torque_limit, float)[self._rev_joint]
                   - self._breakaway[self._rev_joint])
        lt, ut = (req.duration, req.duration) if req.duration > 0 else (0.0, np.inf)
        lbg = np.concatenate([[lt], np.full(K, req.min_theta_dot), -tau_max, -tau_rev,
                              np.zeros(n * K)])
        ubg = np.concatenate([[ut], np.sqrt(beta), tau_max, tau_rev, np.zeros(n * K)])
        lbx = np.concatenate([np.full(nc, -np.inf), np.zeros(self._ne)])
        ubx = np.full(nc + self._ne, np.inf)
        c0 = np.zeros(nc)
        mean = 2 * np.pi / req.duration if req.duration > 0 else 0.5 * np.sqrt(beta.min())
        c0[0] = min(mean, 0.95 * np.sqrt(beta.min()))
        x0 = np.concatenate([c0, np.zeros(self._ne)])
        y = np.asarray(self._aux(x0)[3]).ravel()
        x0[nc:] = np.concatenate([np.maximum(y, 0), np.maximum(-y, 0)]) + 1e-3
        with self._lock:
            t0 = time.perf_counter()
            sol = self._solver(x0=x0, p=[req.energy_weight, req.time_weight], lbx=lbx,
                               ubx=ubx, lbg=lbg, ubg=ubg)
            st = self._solver.stats()
            elapsed = time.perf_counter() - t0
        x = np.asarray(sol['x']).ravel()
        coeffs = x[:nc]
        energy, duration, tau, _ = (np.asarray(v).ravel() for v in self._aux(x))
        ok = bool(st['success'])
        stats = SolveStats(str(st['return_status']), ok, int(st['iter_count']), elapsed)
        try:
            profile = ThetaProfile.from_function(lambda th: fourier_theta_dot(coeffs, th),
                                                 self.n_profile)
        except ValueError:
            profile = None
            stats = SolveStats('invalid profile', False, stats.iterations, elapsed)
        return FourierResult(coeffs, profile, float(energy[0]), float(duration[0]),
                             np.abs(tau).reshape(-1, n).max(axis=0), stats)
