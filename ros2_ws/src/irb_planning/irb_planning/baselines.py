"""Baselines: trapezoidal TCP-speed profile and convex lower bounds on the mechanical and the
electrical energy (no ROS).

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

Electrical bound (``electrical`` given; every DC-bus mode)
---------------------------------------------------------
The electrical energy is int P dt = int P / theta_dot dtheta, P = P_sb + bus(sum_i P_ax,i)
(irb_description.electrical). Per unit theta, with y = tau Phi' (J/rad) and 1/sqrt(b):

    P_g / theta_dot  = max(y / eta_m, eta_g y)                      (exact; convex, up in y)
    P_cu / theta_dot = (k_mot tau+^2 + k_gen tau-^2) / sqrt(b)   for Phi' > 0 (swapped < 0)
    P_ax / theta_dot = drive(P_g/td + P_cu/td) + P_idle / sqrt(b),  drive(z) = max(z/eta_d,
                                                                                eta_d z)

k = R / (k_t N)^2 times 1/eta_m^2 (motoring) or eta_g^2 (generating). Motoring means
tau qd >= 0, i.e. tau >= 0 where Phi' > 0: so the efficiency switch inside tau_m is a switch
on the sign of tau at a point of known Phi', and the copper term is convex in tau without
relaxing it (tau+^2 / sqrt(b) and tau-^2 / sqrt(b) are jointly convex; stronger than the
(eta_g tau / N)^2 relaxation). Friction: tau lies in [tau_lo, tau_hi], tau_lo convex
(Coulomb + Stribeck exp(-u) + viscous with s <= sqrt b), tau_hi concave (Coulomb + the
envelope G_hat), as in the mechanical bound; y >= y_lo (its lower end), tau+ >= max(tau_lo,
0), tau- >= max(-tau_hi, 0); every function above is nondecreasing in these. drive and
P_idle / sqrt(b) are convex, and the three bus functions are convex and nondecreasing:
none: sum_i max(P_ax,i, 0); shared: max(sum_i P_ax,i, 0); regenerative: max(S, eta_r S). So
all three modes give convex problems (epigraph variables per axis and point, IPOPT finds the
global optimum), and the bound is valid for each. Quadrature: Simpson in theta on the
interior intervals (as the mechanical bound); on the two rest intervals 1/sqrt(b) is not
finite at the rest node, so there the bus is replaced by the unclipped sum (bus(S) >= S in
every mode), copper at the rest node by 0, and the idle power is charged with the rest
interval's time (the transcription's time law in b, convex); standby is P_sb T exactly.
With the transcription's rest rows (theta_ddot >= delta^2 / 2h at the rest nodes). Where it
is loose: the mechanical relaxation's (s below sqrt b at long durations), friction at low
joint speed (G_hat), the rest intervals (idle and copper there).
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


#: the electrical bound's time density (Simpson in theta) must carry this fraction of the
#: duration: the transcription's time law (4 pieces per interval) and Simpson's rule on
#: 1/sqrt(b) differ by ~1e-4 relative on its profiles; the margin keeps every one feasible
TIME_MARGIN = 1e-3


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
                 boundary: str = BOUNDARY_REST, max_iter: int = 1000, tol: float = 1e-9,
                 electrical=None, bus_mode: str = 'shared'):
        """``electrical``: an irb_description ElectricalModel of the n axes (None: the
        mechanical bound); ``bus_mode``: its DC-bus mode ('none', 'shared', 'regenerative').
        The electrical bound is the module docstring's "Electrical bound"."""
        t0 = time.perf_counter()
        if any(j.polynomial_positive is not None for j in friction_map.joints):
            raise ValueError('the convex bound needs a parametric friction map')
        if electrical is not None and bus_mode not in ('none', 'shared', 'regenerative'):
            raise ValueError(f'bus mode {bus_mode!r} unknown')
        self.nodes, self.mids, self.boundary = nodes, mids, boundary
        self.electrical, self.bus_mode = electrical, bus_mode
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
        # mechanical: epigraph e of |y| per point; electrical: its own variables (below)
        e = ca.SX.sym('e', n * (N + K)) if electrical is None else ca.SX(0, 1)
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
        el_lo, el_hi = [], []              # electrical: torque interval (n, points)
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
            # electrical: |tau_f| in [m_lo, m_hi], m_lo convex (Coulomb + Stribeck exp +
            # viscous with s <= sqrt b), m_hi concave (Coulomb + envelope G_hat)
            m_lo = ca.DM(np.tile(Fc[:, None], (1, dq.shape[1]))) + ca.DM(
                (Fs - Fc)[:, None] * np.ones_like(dq)) * ca.exp(-U) + ca.DM(
                Fv[:, None] * absdq) * S
            m_hi = ca.DM(np.tile(Fc[:, None], (1, dq.shape[1]))) + G_hat
            el_lo.append(rigid + ca.DM(pos) * m_lo - ca.DM(neg) * m_hi
                         - ca.DM(zero * Fs[:, None]))         # convex
            el_hi.append(rigid + ca.DM(pos) * m_hi - ca.DM(neg) * m_lo
                         + ca.DM(zero * Fs[:, None]))         # concave
        E_lo, E_hi = ca.vertcat(*lower_rows), ca.vertcat(*upper_rows)
        wn = np.zeros(N)
        wn[:-1] += dth / 6
        wn[1:] += dth / 6                          # Simpson weights dth/6 (1, 4, 1)
        W = ca.vertcat(ca.vec(ca.DM(np.tile(wn, (n, 1)))),
                       ca.vec(ca.DM(np.tile(4 * dth / 6, (n, 1)))))

        # --- objective: Simpson sum of the epigraph ---------------------------------------
        f = ca.dot(W, e) if electrical is None else 0
        duration = ca.sum1(sum(2 * D / J / (s_pieces[j] + s_pieces[j + 1])
                               for j in range(J)))

        # --- path constraints ------------------------------------------------------------
        # secant of s^2 on [delta, s_max]: b <= (delta + s_max) s - delta s_max (per solve)
        p = ca.SX.sym('p', xb.numel() + s_sub.numel())  # delta + s_max: free nodes, pieces
        collocation = b[1:] - b[:-1] - (a[:-1] + a[1:]) * D
        epi = [e - E_lo, e + E_hi] if electrical is None else []
        g_rows = [duration, b_mid, xs ** 2 - xb, s_sub ** 2 - b_sub, b_sub, collocation,
                  *epi, ca.vertcat(*tau_lo_rows), ca.vertcat(*tau_hi_rows),
                  xb - p[:xb.numel()] * xs, b_sub - p[xb.numel():] * s_sub]
        self._nel, self._nel_rows = 0, 0
        if electrical is not None:
            xe, f, el_rows = self._electrical(
                electrical, bus_mode, x, b, b_sub, ca.horzcat(*el_lo), ca.horzcat(*el_hi),
                dth)
            x = ca.vertcat(x, xe)
            g_rows += el_rows + [self._time_row]
            self._nel = xe.numel()
            self._nel_rows = sum(r.numel() for r in el_rows)
        self._sizes = [r.numel() for r in g_rows]
        self._solver = ca.nlpsol('bound', 'ipopt', {'x': x, 'p': p, 'f': f,
                                                    'g': ca.vertcat(*g_rows)},
                                 ipopt_options(max_iter, tol))
        self._ne = e.numel()
        self._dur = ca.Function('dur', [x], [duration])
        self._bafun = ca.Function('ba', [x], [b, a])
        self.build_time = time.perf_counter() - t0

    def _electrical(self, model, mode, x_base, b, b_sub, tau_lo, tau_hi, dth):
        """Variables, objective (without P_sb T) and rows (all >= 0) of the electrical
        bound; tau_lo (convex), tau_hi (concave) (n, P): the torque interval at the nodes,
        then the midpoints (module docstring, "Electrical bound")."""
        n, N = self.n, self.N
        K = N - 1
        P = N + K
        J = TIME_SUBSTEPS
        dq = np.hstack([self.nodes.dq.T, self.mids.dq.T])              # (n, P)
        pos, neg = dq > 0, dq < 0
        rest = self.boundary == BOUNDARY_REST
        rest_node = np.zeros(P, bool)
        if rest:
            rest_node[[0, N - 1]] = True
        v = lambda name: np.asarray(getattr(model, name), float)[:n]  # noqa: E731
        em, eg = v('gear_efficiency_motoring'), v('gear_efficiency_generating')
        ed = float(model.drive_efficiency)
        base = v('resistance') / (v('torque_constant') * v('gear_ratio')) ** 2
        k_mot, k_gen = base / em ** 2, base * eg ** 2       # copper per tau^2, motoring/gen.
        col = lambda a: np.tile(np.asarray(a, float)[:, None], (1, P))  # noqa: E731
        # copper k tau+^2 + k' tau-^2: the motoring side is where tau Phi' >= 0 (Phi' = 0:
        # motoring, P_j = 0 >= 0); none at a rest node (its 1/sqrt(b) is not finite: the
        # rest intervals are bounded without copper)
        k_plus = np.where(neg, col(k_gen), col(k_mot)) * ~rest_node
        k_minus = np.where(pos, col(k_gen), col(k_mot)) * ~rest_node
        b_all = ca.vertcat(b, b_sub[(J // 2 - 1) * K:(J // 2) * K])
        inv = ca.DM((~rest_node).astype(float)) / ca.sqrt(ca.fmax(b_all, 1e-12))
        rep = lambda row: ca.repmat(ca.reshape(row, 1, -1), n, 1)  # noqa: E731
        y_lo = ca.DM(np.where(pos, dq, 0.0)) * tau_lo + ca.DM(np.where(neg, dq, 0.0)) * tau_hi
        g = ca.SX.sym('g_el', n * P)          # gearbox output >= max(y/eta_m, eta_g y)
        tp = ca.SX.sym('tau_plus', n * P)     # >= max(tau, 0)
        tm = ca.SX.sym('tau_minus', n * P)    # >= max(-tau, 0)
        w = ca.SX.sym('w_el', n * P)          # drive input >= drive(g + copper)
        G, TP, TM, Wm = (ca.reshape(z, n, P) for z in (g, tp, tm, w))
        copper = (ca.DM(k_plus) * TP ** 2 + ca.DM(k_minus) * TM ** 2) * rep(inv)
        rows = [G - ca.DM(col(1 / em)) * y_lo, G - ca.DM(col(eg)) * y_lo, TP - tau_lo,
                TM + tau_hi, Wm - (G + copper) / ed, Wm - ed * (G + copper)]
        # Simpson weights of the interior intervals (bus, idle) and of the rest intervals
        interior = np.ones(K, bool)
        if rest:
            interior[[0, K - 1]] = False
        w_int, w_rest = np.zeros(P), np.zeros(P)
        for k in range(K):
            wk = w_int if interior[k] else w_rest
            wk[k] += dth[k] / 6
            wk[k + 1] += dth[k] / 6
            wk[N + k] += 4 * dth[k] / 6
        idx = np.flatnonzero(w_int > 0).tolist()
        idle = v('drive_idle_power')
        # time per unit theta rho >= 1/sqrt(b) at the interior points, and the rest
        # intervals' time t_r >= their time law, with sum rho + t_r >= T (rows below): the
        # relaxation may raise b far above s^2 (see "Where it is loose"), which alone would
        # shrink the idle (and standby-like) energy int P_idle / sqrt(b) far below P_idle T
        rho = ca.SX.sym('rho', len(idx))
        t_r = ca.SX.sym('t_rest', 1 if rest else 0)
        rows.append(rho - inv[idx])
        inv_i = ca.reshape(rho, 1, -1)
        if mode == 'none':
            V = ca.SX.sym('bus', n * len(idx))
            Vm = ca.reshape(V, n, len(idx))
            rows.append(Vm - Wm[:, idx] - ca.DM(idle[:, None]) * rep(rho))
            f = ca.dot(ca.DM(w_int[idx]), ca.transpose(ca.sum1(Vm)))
            v_lo = np.zeros(V.numel())
        else:
            V = ca.SX.sym('bus', len(idx))
            S = ca.transpose(ca.sum1(Wm[:, idx]) + float(idle.sum()) * inv_i)
            rows.append(V - S)
            if mode == 'regenerative':
                rows.append(V - float(model.regenerative_efficiency) * S)
                v_lo = np.full(V.numel(), -np.inf)
            else:
                v_lo = np.zeros(V.numel())
            f = ca.dot(ca.DM(w_int[idx]), V)
        # rest intervals: bus(sum of axes) >= the unclipped sum, copper >= 0 dropped at the
        # rest node, idle + its time (the transcription's time law, convex in b)
        f = f + ca.dot(ca.DM(w_rest), ca.transpose(ca.sum1(Wm)))
        t_total = ca.dot(ca.DM(w_int[idx]), rho)
        if rest:
            t_rest = 0
            for k in (0, K - 1):
                bk = [b[k]] + [b_sub[j * K + k] for j in range(J - 1)] + [b[k + 1]]
                sq = [ca.sqrt(ca.fmax(z, 1e-12)) for z in bk]
                t_rest = t_rest + sum(2 * dth[k] / J / (sq[j] + sq[j + 1]) for j in range(J))
            rows.append(t_r - t_rest)                   # t_r >= the rest intervals' time
            f = f + float(idle.sum()) * t_r[0]
            t_total = t_total + t_r[0]
        self._time_row = t_total                        # >= (1 - TIME_MARGIN) T (per solve)
        rows = [ca.vec(r) for r in rows]
        xe = ca.vertcat(g, tp, tm, w, V, rho, t_r)
        big = 1e6
        self._el_lbx = np.concatenate([np.full(n * P, -big), np.zeros(2 * n * P),
                                       np.full(n * P, -big), v_lo, np.zeros(len(idx)),
                                       np.zeros(t_r.numel())])
        self._el_ubx = np.concatenate([np.full(n * P, big), np.full(2 * n * P, 1e4),
                                       np.full(n * P, big), np.full(V.numel(), big),
                                       np.full(len(idx), big), np.full(t_r.numel(), big)])
        # a start that meets the rows: each variable at its row's right-hand side + margin
        ylo_f = ca.Function('el_start', [x_base], [y_lo, tau_lo, tau_hi, inv])
        n_idx = len(idx)

        t_rest_f = ca.Function('t_rest', [x_base], [t_rest if rest else 0.0])

        def start(x0, duration):
            yl, tl, th, iv = (np.asarray(z) for z in ylo_f(x0))
            iv = iv.ravel()
            tr0 = float(t_rest_f(x0)) if rest else 0.0
            rho0 = iv[idx]
            # scale the time density up so that it carries the whole duration
            scale = max(1.0, (duration - tr0) / max(float(w_int[idx] @ rho0), 1e-9)) * 1.01
            rho0 = rho0 * scale
            iv = iv.copy()
            iv[idx] = rho0
            g0 = np.maximum(yl / em[:, None], yl * eg[:, None]) + 1.0
            tp0, tm0 = np.maximum(tl, 0) + 1.0, np.maximum(-th, 0) + 1.0
            c0 = (k_plus * tp0 ** 2 + k_minus * tm0 ** 2) * iv[None, :]
            w0 = np.maximum((g0 + c0) / ed, ed * (g0 + c0)) + 1.0
            if mode == 'none':
                v0 = np.maximum(w0[:, idx] + idle[:, None] * iv[None, idx], 0) + 1.0
                v0 = v0.ravel(order='F')
            else:
                s0 = w0[:, idx].sum(axis=0) + idle.sum() * iv[idx]
                v0 = np.maximum(s0, 0) + 1.0 if mode == 'shared' else np.abs(s0) + 1.0
            assert v0.size == (n * n_idx if mode == 'none' else n_idx)
            return np.concatenate([np.clip(z.ravel(order='F'), -big, big)
                                   for z in (g0, tp0, tm0, w0)]
                                  + [v0, rho0, [tr0 * 1.01] if rest else []])
        self._electrical_start = start
        return xe, f, rows

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
        lba, uba = np.full(na, -np.inf), np.full(na, np.inf)
        if self.electrical is not None and self.boundary == BOUNDARY_REST:
            # the transcription's rest rows (leave / reach rest with theta_ddot >=
            # delta^2 / 2h): valid for every profile it can return; keeps the rest
            # intervals' time (in the electrical objective) finite
            h = np.diff(self.nodes.theta)
            lba[0], uba[-1] = lo / (2 * h[0]), -lo / (2 * h[-1])
        lbx = np.concatenate([np.full(nb, lo), lba, np.zeros(nb),
                              np.zeros(nsub), np.zeros(self._ne)])
        ubx = np.concatenate([ubb, uba, np.sqrt(ubb), s_sub_max,
                              np.full(self._ne, np.inf)])
        tau = np.tile(np.asarray(req.torque_limit, float), N + K)
        inf = np.full(n * (N + K), np.inf)
        s_max = np.sqrt(ubb)
        lbg = np.concatenate([[0.0], np.zeros(K), np.full(nb, -np.inf),
                              np.full(nsub, -np.inf), np.tile(lo_sub, TIME_SUBSTEPS - 1),
                              np.zeros(K), np.zeros(self._ne), np.zeros(self._ne),
                              -inf, -tau, np.full(nb, -np.inf), np.full(nsub, -np.inf),
                              np.zeros(self._nel_rows),
                              [(1 - TIME_MARGIN) * req.duration] if self._nel else []])
        ubg = np.concatenate([[req.duration], beta_m, np.zeros(nb), np.zeros(nsub),
                              np.full(nsub, np.inf), np.zeros(K), np.full(self._ne, np.inf),
                              np.full(self._ne, np.inf), tau, inf,
                              -req.min_theta_dot * s_max, -delta_sub * s_sub_max,
                              np.full(self._nel_rows, np.inf),
                              [np.inf] if self._nel else []])
        b0 = np.clip((2 * np.pi / req.duration) ** 2, lo, 0.95 * ubb)
        bn = np.concatenate([[0.0], b0, [0.0]]) if self.boundary == BOUNDARY_REST else \
            np.append(b0, b0[0])
        a0 = np.clip(linear_node_accelerations(self.nodes.theta, bn)[:na], lba, uba)
        x0 = np.concatenate([b0, a0, np.sqrt(b0),
                             np.full(nsub, 2 * np.pi / req.duration), np.full(self._ne, 1.0)])
        if self._nel:
            x0 = np.concatenate([x0, self._electrical_start(x0, req.duration)])
            lbx = np.concatenate([lbx, self._el_lbx])
            ubx = np.concatenate([ubx, self._el_ubx])
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
        energy = float(sol['f'])
        if self.electrical is not None:      # standby, outside the bus: P_sb T exactly
            energy += float(self.electrical.standby_power) * req.duration
        return BoundResult(energy, float(self._dur(x)), profile, stats)
