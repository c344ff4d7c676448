"""Baselines: trapezoidal TCP-speed profile and the convex lower bound on the energy (no ROS).

The time-optimal profile is ``transcription.Transcription`` with the objective T (energy
weight ~0): same grid, same exact friction, same limits, so "shorter than the time-optimal
duration" means exactly "infeasible for the energy problem".

Convex lower bound
------------------
Split the power per unit theta of joint i into y = x + d: x = (m a + c b + g)_i Phi'_i is affine
in (a, b) and d = tau_f,i Phi'_i >= 0 is the friction dissipation (a passive friction map;
parametric Coulomb F_c, breakaway F_s >= F_c, viscous F_v, Stribeck speed v_s). With
v = Phi' sqrt(b) and u = v^2 / v_s^2 = Phi'^2 b / v_s^2:

    d = F_c |Phi'| + |Phi'| G(u),   G(u) = (F_s - F_c) exp(-u) + F_v v_s sqrt(u)

Introduce s <= sqrt(b) (s^2 <= b, convex). Then |y| = max(y, -y) >= l with

    l = max( x + F_c |Phi'| + (F_s - F_c) exp(-u) |Phi'| + F_v Phi'^2 s ,
             -x - F_c |Phi'| - |Phi'| Ghat(u) )

where Ghat >= G is the concave envelope (least concave majorant) of G on u >= 0, computed once
per joint (``stribeck_envelope``): G itself where G is concave, the bitangent line across the
Stribeck dip (for the nominal map u in [0.01, ~95], i.e. |v| < ~0.5 rad/s; above that the
braking branch is exact). The first branch is convex in (b, s) (exp(-k b) convex), the second
too (Ghat(k b) concave). The duration T = sum 2 dth / (sqrt b_k + sqrt b_{k+1}) is relaxed to
sum 2 dth / (s_k + s_{k+1}) <= T_req (convex, >= the true T), the torque limits to what the
friction interval implies, the speed limits and theta_dot >= delta are kept, and

    b_k <= (delta + s_max,k) s_k - delta s_max,k     (secant of s^2 on [delta, s_max,k])

with s_max,k = sqrt(speed bound) couples b back to s from above (without it the relaxation
could raise b, i.e. store kinetic energy, for free while s, which pays the viscous term and the
time, stays low). Every feasible point of the transcription (s = sqrt b) is feasible here with
objective <= its energy, so the global optimum of this convex problem (IPOPT finds it) is a
lower bound on the energy of any profile on this grid and quadrature. Where it is loose: (i)
the secant is wide (s_max is set by the joint speed limits, 3-10 x the speeds of a slow
profile), so at long durations the relaxation still stores kinetic energy it need not pay
for; (ii) braking at |v| < ~0.5 rad/s (F_s-like envelope instead of the real Coulomb +
Stribeck friction). It ignores the tanh smoothing of the optimiser's friction and holds for
the parametric map only (not for polynomial maps).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from .problem import PathDynamics, SolveStats, ipopt_options, speed_bound
from .profile import TIME_SUBSTEPS, ThetaProfile, linear_node_accelerations, quadratic_b
from .transcription import BOUNDARY_REST, SolveRequest


def stribeck_envelope(delta_f: float, viscous: float, stribeck_velocity: float
                      ) -> tuple[float, float, float]:
    """Concave envelope of G(u) = delta_f exp(-u) + viscous v_s sqrt(u) on u >= 0.

    Returns (u1, u2, margin): Ghat = G outside [u1, u2] and the chord of G through u1, u2
    (plus ``margin`` >= 0, covering the grid the hull is found on) inside. (0, 0, 0) if G is
    concave (no Stribeck dip). delta_f = F_s - F_c [N m], viscous [N m s/rad], v_s [rad/s].
    """
    def G(u):
        return delta_f * np.exp(-u) + viscous * stribeck_velocity * np.sqrt(u)
    u = np.concatenate([[0.0], np.geomspace(1e-9, 1e4, 100001)])
    y = G(u)
    hull = []
    for i in range(u.size):                       # upper hull, monotone chain
        while len(hull) >= 2:
            i1, i2 = hull[-2], hull[-1]
            if (y[i2] - y[i1]) * (u[i] - u[i1]) <= (y[i] - y[i1]) * (u[i2] - u[i1]):
                hull.pop()
            else:
                break
        hull.append(i)
    gaps = [(a, b) for a, b in zip(hull[:-1], hull[1:]) if b - a > 1]
    if not gaps:
        return 0.0, 0.0, 0.0
    a, b = max(gaps, key=lambda ab: u[ab[1]] - u[ab[0]])
    if len(gaps) > 1:      # one dip expected; more would need a piecewise envelope
        a, b = gaps[0][0], gaps[-1][1]
    u1, u2 = float(u[a]), float(u[b])
    slope = (y[b] - y[a]) / (u2 - u1)
    uu = np.union1d(np.geomspace(u1, u2, 200001), np.linspace(u1, u2, 200001))
    margin = max(0.0, float(np.max(G(uu) - (y[a] + slope * (uu - u1))))) + 1e-12
    return u1, u2, margin


def trapezoid_profile(duration: float, ramp_fraction: float = 0.1, n: int = 401
                      ) -> ThetaProfile:
    """Trapezoidal TCP speed along the path, rest to rest, in ``duration`` T [s].

    Constant acceleration for ramp_fraction * T, cruise, constant deceleration for the same
    time (what a robot's own path planner does). On a circle TCP speed = r theta_dot, so theta
    has the same profile: cruise theta_dot_c = 2 pi / (T (1 - ramp_fraction)). During a ramp
    b = theta_dot^2 is linear in theta, so the profile is exact on the nodes (``n`` uniform
    nodes plus the two ramp ends).
    """
    if not (duration > 0 and np.isfinite(duration)):
        raise ValueError(f'duration must be > 0, got {duration!r}')
    if not 0 < ramp_fraction <= 0.5:
        raise ValueError(f'ramp_fraction must be in (0, 0.5], got {ramp_fraction!r}')
    t_r = ramp_fraction * duration
    v_c = 2 * np.pi / (duration - t_r)
    th_r = 0.5 * v_c * t_r
    theta = np.union1d(np.linspace(0.0, 2 * np.pi, n), [th_r, 2 * np.pi - th_r])
    b = v_c ** 2 * np.minimum(1.0, np.minimum(theta, 2 * np.pi - theta) / th_r)
    return ThetaProfile(theta, np.sqrt(np.maximum(b, 0.0)))


@dataclass(frozen=True)
class BoundResult:
    """Lower bound [J] on the energy at duration [s]; profile of the relaxation; stats."""

    energy: float
    duration: float
    profile: ThetaProfile | None
    stats: SolveStats


class EnergyBound:
    """The convex relaxation above on the transcription's grid (Simpson, same points)."""

    def __init__(self, nodes: PathDynamics, mids: PathDynamics, friction_map,
                 boundary: str = BOUNDARY_REST, max_iter: int = 1000, tol: float = 1e-9):
        t0 = time.perf_counter()
        if any(j.polynomial_positive is not None for j in friction_map.joints):
            raise ValueError('the convex bound needs a parametric friction map')
        self.nodes, self.mids, self.boundary = nodes, mids, boundary
        N = nodes.theta.size
        n = nodes.dq.shape[1]
        K = N - 1
        self.N, self.n = N, n
        dth = np.diff(nodes.theta)
        Fc = np.array([j.coulomb for j in friction_map.joints])
        Fs = np.array([j.static for j in friction_map.joints])
        Fv = np.array([j.viscous for j in friction_map.joints])
        vs = np.array([j.stribeck_velocity for j in friction_map.joints])
        env = [stribeck_envelope(Fs[i] - Fc[i], Fv[i], vs[i]) for i in range(n)]

        def g_hat(u, i):
            """Concave majorant of (F_s - F_c) exp(-u) + F_v v_s sqrt(u) (joint i)."""
            G = (Fs[i] - Fc[i]) * ca.exp(-u) + Fv[i] * vs[i] * ca.sqrt(u)
            u1, u2, margin = env[i]
            if u2 <= u1:
                return G
            g1 = (Fs[i] - Fc[i]) * np.exp(-u1) + Fv[i] * vs[i] * np.sqrt(u1)
            g2 = (Fs[i] - Fc[i]) * np.exp(-u2) + Fv[i] * vs[i] * np.sqrt(u2)
            chord = g1 + (g2 - g1) / (u2 - u1) * (u - u1) + margin
            return ca.if_else(ca.logic_and(u > u1, u < u2), chord, G)

        # --- decision variables: b, a (as in the transcription), s <= sqrt(b), e ----------
        J = TIME_SUBSTEPS
        if boundary == BOUNDARY_REST:
            xb, xs = ca.SX.sym('b', N - 2), ca.SX.sym('s', N - 2)
            b, s = ca.vertcat(0, xb, 0), ca.vertcat(0, xs, 0)
            xa = ca.SX.sym('a', N)
            a = xa
        else:
            xb, xs = ca.SX.sym('b', N - 1), ca.SX.sym('s', N - 1)
            b, s = ca.vertcat(xb, xb[0]), ca.vertcat(xs, xs[0])
            xa = ca.SX.sym('a', N - 1)
            a = ca.vertcat(xa, xa[0])
        s_sub = ca.SX.sym('s_sub', (J - 1) * K)      # s at the time-law pieces, <= sqrt(b)
        e = ca.SX.sym('e', n * (N + K))
        x = ca.vertcat(xb, xa, xs, s_sub, e)
        self._nb, self._na, self._nsub = xb.numel(), xa.numel(), s_sub.numel()
        D = ca.DM(dth)
        b_sub = ca.vertcat(*[quadratic_b(b[:-1], a[:-1], a[1:], D, D * (j / J))
                             for j in range(1, J)])
        s_pieces = [s[:-1]] + [s_sub[j * K:(j + 1) * K] for j in range(J - 1)] + [s[1:]]
        b_mid = b_sub[(J // 2 - 1) * K:(J // 2) * K]
        s_mid = s_pieces[J // 2]

        # --- dynamics at the nodes and midpoints (columns = points) ----------------------
        rep = lambda row: ca.repmat(ca.reshape(row, 1, -1), n, 1)  # noqa: E731
        pts = [  # (PathDynamics, a, b, s at its points)
            (nodes, a, b, s),
            (mids, 0.5 * (a[:-1] + a[1:]), b_mid, s_mid)]
        lower_rows, upper_rows, tau_lo_rows, tau_hi_rows = [], [], [], []
        for dyn, ap, bp, sp in pts:
            dq = dyn.dq.T                                            # (n, points)
            rigid = (ca.DM(dyn.m.T) * rep(ap) + ca.DM(dyn.c.T) * rep(bp) + ca.DM(dyn.g.T))
            xr = rigid * ca.DM(dq)
            absdq, dq2 = np.abs(dq), dq ** 2
            sq = rep(ca.sqrt(ca.fmax(bp, 1e-12)))
            S = rep(sp)
            U = ca.DM(dq2 / vs[:, None] ** 2) * rep(bp)             # (v / v_s)^2
            stribeck = ca.DM((Fs - Fc)[:, None] * absdq) * ca.exp(-U)  # convex in b
            d_lo = ca.DM(Fc[:, None] * absdq) + ca.DM(Fv[:, None] * dq2) * S + stribeck
            # concave in b: Coulomb + |Phi'| * concave envelope of (Stribeck + viscous)
            G_hat = ca.vertcat(*[g_hat(U[i, :], i) for i in range(n)])
            d_hi = ca.DM(Fc[:, None] * absdq) + ca.DM(absdq) * G_hat
            lower_rows.append(ca.vec(xr + d_lo))      # e >= x + d_lo
            upper_rows.append(ca.vec(xr + d_hi))      # e >= -(x + d_hi)
            pos, neg = (dq > 0).astype(float), (dq < 0).astype(float)
            zero = 1.0 - pos - neg
            fv_dq = ca.DM(Fv[:, None] * dq)
            f_lo = (ca.DM(pos * Fc[:, None]) + ca.DM(pos) * fv_dq * S
                    + ca.DM(-neg * Fs[:, None]) + ca.DM(neg) * fv_dq * sq
                    - ca.DM(zero * Fs[:, None]))
            f_hi = (ca.DM(pos * Fs[:, None]) + ca.DM(pos) * fv_dq * sq
                    + ca.DM(-neg * Fc[:, None]) + ca.DM(neg) * fv_dq * S
                    + ca.DM(zero * Fs[:, None]))
            tau_lo_rows.append(ca.vec(rigid + f_lo))  # <= tau_max
            tau_hi_rows.append(ca.vec(rigid + f_hi))  # >= -tau_max
        E_lo, E_hi = ca.vertcat(*lower_rows), ca.vertcat(*upper_rows)
        wn = np.zeros(N)
        wn[:-1] += dth / 6
        wn[1:] += dth / 6                          # Simpson weights dth/6 (1, 4, 1)
        W = ca.vertcat(ca.vec(ca.DM(np.tile(wn, (n, 1)))),
                       ca.vec(ca.DM(np.tile(4 * dth / 6, (n, 1)))))

        # --- objective: Simpson sum of the epigraph ---------------------------------------
        f = ca.dot(W, e)
        duration = ca.sum1(sum(2 * D / J / (s_pieces[j] + s_pieces[j + 1])
                               for j in range(J)))

        # --- path constraints ------------------------------------------------------------
        # secant of s^2 on [delta, s_max]: b <= (delta + s_max) s - delta s_max (per solve)
        p = ca.SX.sym('p', xb.numel() + s_sub.numel())  # delta + s_max: free nodes, pieces
        collocation = b[1:] - b[:-1] - (a[:-1] + a[1:]) * D
        g_rows = [duration, b_mid, xs ** 2 - xb, s_sub ** 2 - b_sub, b_sub, collocation,
                  e - E_lo, e + E_hi, ca.vertcat(*tau_lo_rows), ca.vertcat(*tau_hi_rows),
                  xb - p[:xb.numel()] * xs, b_sub - p[xb.numel():] * s_sub]
        self._sizes = [r.numel() for r in g_rows]
        self._solver = ca.nlpsol('bound', 'ipopt', {'x': x, 'p': p, 'f': f,
                                                    'g': ca.vertcat(*g_rows)},
                                 ipopt_options(max_iter, tol))
        self._ne = e.numel()
        self._dur = ca.Function('dur', [x], [duration])
        self._bafun = ca.Function('ba', [x], [b, a])
        self.build_time = time.perf_counter() - t0

    def solve(self, req: SolveRequest) -> BoundResult:
        """Lower bound for the fixed duration req.duration (> 0) and the request's limits."""
        nb, na, nsub, n, N, K = self._nb, self._na, self._nsub, self.n, self.N, self.N - 1
        beta_n = speed_bound(self.nodes.dq, req.velocity_limit)
        beta_m = speed_bound(self.mids.dq, req.velocity_limit)
        ubb = beta_n[1:-1] if self.boundary == BOUNDARY_REST else beta_n[:-1]
        lo = req.min_theta_dot ** 2
        lo_sub = np.full(K, lo)
        if self.boundary == BOUNDARY_REST:
            lo_sub[0] = lo_sub[-1] = 0.0
        # b at a piece end <= 9/8 max(b_k, b_mid, b_k+1) (quadratic through the three
        # values); at the midpoint b <= beta_m directly
        beta_all = np.concatenate([[0.0], ubb, [0.0]]) if self.boundary == BOUNDARY_REST \
            else np.append(ubb, ubb[0])
        beta_int = 9.0 / 8.0 * np.maximum(np.maximum(beta_all[:-1], beta_all[1:]), beta_m)
        J = TIME_SUBSTEPS
        s_sub_max = np.sqrt(np.concatenate([beta_m if j == J // 2 else beta_int
                                            for j in range(1, J)]))
        delta_sub = np.sqrt(np.tile(lo_sub, J - 1))
        lbx = np.concatenate([np.full(nb, lo), np.full(na, -np.inf), np.zeros(nb),
                              np.zeros(nsub), np.zeros(self._ne)])
        ubx = np.concatenate([ubb, np.full(na, np.inf), np.sqrt(ubb), s_sub_max,
                              np.full(self._ne, np.inf)])
        tau = np.tile(np.asarray(req.torque_limit, float), N + K)
        inf = np.full(n * (N + K), np.inf)
        s_max = np.sqrt(ubb)
        lbg = np.concatenate([[0.0], np.zeros(K), np.full(nb, -np.inf),
                              np.full(nsub, -np.inf), np.tile(lo_sub, TIME_SUBSTEPS - 1),
                              np.zeros(K), np.zeros(n * (N + K)), np.zeros(n * (N + K)),
                              -inf, -tau, np.full(nb, -np.inf), np.full(nsub, -np.inf)])
        ubg = np.concatenate([[req.duration], beta_m, np.zeros(nb), np.zeros(nsub),
                              np.full(nsub, np.inf), np.zeros(K), inf, inf, tau, inf,
                              -req.min_theta_dot * s_max, -delta_sub * s_sub_max])
        b0 = np.clip((2 * np.pi / req.duration) ** 2, lo, 0.95 * ubb)
        bn = np.concatenate([[0.0], b0, [0.0]]) if self.boundary == BOUNDARY_REST else \
            np.append(b0, b0[0])
        a0 = linear_node_accelerations(self.nodes.theta, bn)[:na]
        x0 = np.concatenate([b0, a0, np.sqrt(b0),
                             np.full(nsub, 2 * np.pi / req.duration), np.full(self._ne, 1.0)])
        t0 = time.perf_counter()
        p = np.concatenate([req.min_theta_dot + s_max, delta_sub + s_sub_max])
        sol = self._solver(x0=x0, p=p, lbx=lbx, ubx=ubx, lbg=lbg,
                           ubg=ubg)
        st = self._solver.stats()
        elapsed = time.perf_counter() - t0
        x = np.asarray(sol['x']).ravel()
        b, a = (np.asarray(v).ravel() for v in self._bafun(x))
        try:
            profile = ThetaProfile(self.nodes.theta, np.sqrt(np.maximum(b, 0.0)), a)
        except ValueError:
            profile = None
        stats = SolveStats(str(st['return_status']), bool(st['success']),
                           int(st['iter_count']), elapsed)
        return BoundResult(float(sol['f']), float(self._dur(x)), profile, stats)
