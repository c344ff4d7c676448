"""Direct transcription on a theta-grid in b = theta_dot^2 and a = theta_ddot, IPOPT.

After Verscheure et al. (2009), with a second-order (trapezoidal) collocation of b' = 2 a.
Grid: N nodes theta_0 = 0 < ... < theta_{N-1} = 2 pi, N-1 intervals of length h_k. b_k and a_k
at the nodes are the decision variables; on interval k, theta_ddot is linear in theta and b
quadratic, b(theta_k + s) = b_k + 2 a_k s + (a_{k+1} - a_k) s^2 / h_k, which closes exactly
when b_{k+1} - b_k = (a_k + a_{k+1}) h_k (collocation rows). A first-order scheme (b linear,
a constant per interval) leaves the torque no way to stay at 0 across an interval, so near
the time-optimal duration its optimum chatters and N = 200 -> 1000 moved E by ~1 %; this one
moves it by < 0.2 % (benchmarks/bench_timing.py).

    minimise     w_E E + w_T T
    E = sum_k h_k / 6 sum_i (|y_i(theta_k)| + 4 |y_i(mid_k)| + |y_i(theta_k+1)|)   [J]
        y_i = tau_i Phi'_i (power per unit theta, J/rad), Simpson's rule
    T = the profile's time law (profile.TIME_SUBSTEPS pieces per interval)       [s]
    tau(theta) = m a + c b + g + tau_f(Phi' sqrt b)      (problem.PathDynamics)
    s.t.  T = T_req (fixed duration) or T free (time-energy trade-off, w_T = time weight)
          theta_dot >= delta everywhere inside the path, between the samples too:
            b - max(0, a_{k+1} - a_k) h_k / 64 >= delta^2 at the nodes and the three
            quarter points of every interval (on a quarter piece a convex quadratic dips at
            most b'' (h/4)^2 / 8 = (a_{k+1} - a_k) h / 64 below its end values; written as two
            linear rows); on a rest interval b(s) >= delta^2 s / h (leaving rest takes at most
            twice the time at delta): a_0 >= delta^2 / (2 h_0), a_{N-1} <= -delta^2 / (2 h).
            The plain rows b >= delta^2 at the quarter points are implied and not built
            unless a TCP speed band needs them (``band_rows``): where a_{k+1} >= a_k the dip
            rows hold them, where a_{k+1} < a_k the quadratic is concave and its minimum is
            at the nodes, bounded below as variables; on a rest interval b(0) = 0 and
            b'(0) > 0 (convex: b rises; concave: minimum at the nodes), the same mirrored
            at the end. Without them the KKT system of the 10-segment polyline at N = 400
            has 2394 fewer rows (1197 inequalities and their slacks, of 20 600): a warm
            solve takes 0.89x the time (paired median of 12 requests, 0.81-1.00, the same
            iterations and energies to 7e-7; bench_paths.py --paired-band-rows 12).
          b <= speed bound at nodes and midpoints; |tau| <= tau_max at every node and midpoint
          boundary 'rest': b_0 = b_{N-1} = 0;  'periodic': b_0 = b_{N-1}, a_0 = a_{N-1}
          process constraints (``TcpPath`` given, request fields > 0), p' = dp/dtheta:
            TCP speed |p'| sqrt(b) <= v_max: b <= v_max^2 / |p'|^2, a bound on b at the
              nodes, midpoints and quarter points (linear in b; the quarter-point rows exist
              only in problems built with ``band_rows``, as a request with a band gets);
            TCP speed >= v_min away from the rest ends (every interval reaching past
              tcp_ramp_length of arc length from both ends; all of a periodic path): the same
              as a lower bound, also on the dip rows, so it holds between the samples too;
            |TCP acceleration| = |p'' b + p' a| <= a_max at the nodes, midpoints and the
              other side of every piece end: the Euclidean norm (frame-independent, the one
              number a process and a controller care about, and since theta is proportional
              to arc length p' is normal to p'', so it is sqrt(tangential^2 + centripetal^2)
              and a per-axis box would allow sqrt(3) times more in a diagonal direction);
              written as the convex quadratic row |p'' b + p' a|^2 <= a_max^2. These rows
              exist only in problems built with ``accel_rows`` (the default problem is the
              same NLP as without process constraints, bit for bit).

|y| is exact: epigraph variables e >= +-y with sum e minimised (no bias at the optimum), or,
if ``abs_smoothing`` eps > 0, sqrt(y^2 + eps^2), whose bias is at most 2 pi n eps [J]. The
energy reported is always recomputed with the exact |y|. The result is a quadratic
``ThetaProfile`` (node accelerations included), sampled exactly by the evaluator.

Electrical objective (``electrical`` = an irb_description ElectricalModel of the n axes, and a
DC-bus mode): E_el = sum_k over the two halves of interval k of dt_half (P(a) + P(b)) / 2,
the trapezoidal rule in time of the total electrical power P (standby included) at the nodes
and midpoints, dt_half from the same time law as T (finite at rest ends, where the copper
losses of holding are paid). P is the model's CasADi form with ``electrical_smoothing`` eps
[W] for IPOPT; the reported electrical energy uses eps = 0. The mechanical epigraph stays in
the objective with weight 1e-6 so that its variables remain determined.

The NLP is built once per (path, grid, boundary, friction, energy model, acceleration rows);
duration, weights, delta, the limits and the process constraints are parameters or bounds,
so a new request only re-solves (warm-started from the last solution). No ROS imports.

Smoothness limits (``jerk`` = a ``JerkPath``, issue 28). On interval k theta_ddot is linear in
theta, so the path jerk is d theta_ddot / dt = kappa_k theta_dot (kappa_k = (a_{k+1} - a_k) /
h_k), and the joint jerk is exactly
    d3q/dt3 = Phi^(3) theta_dot^3 + 3 Phi'' theta_dot theta_ddot + Phi' d3theta/dt3
            = sqrt(b) (Phi^(3) b + 3 Phi'' a + Phi' kappa_k);
the TCP jerk likewise with p', p'', p^(3). Rows |d3q_i/dt3| <= J_i and |d3p/dt3| <= J_tcp
(linear rows: an octagon in the osculating plane and the binormal) at both ends and the
midpoint of every interval (each node from both sides). A rest-to-rest problem then has a =
0 at its rest nodes and cubic rest intervals (profile.py: constant path jerk from rest,
theta ~ t^3, b_1 = 1.5 a_1 h, time 3 h / sqrt(b_1)): the torque starts and ends at the
static torque. Where the path's curvature jumps (a circular blend's end) the joint and TCP
accelerations jump by (Phi''+ - Phi''-) b and (p''+ - p''-) b: no motion exactly on the
path has a finite jerk there at b > 0, so the rows hold on each side
and the jump itself is the message's (two points 1 ms apart, planner.message_points).
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, replace
from typing import Callable

import casadi as ca
import numpy as np

from .problem import PathDynamics, SolveStats, ipopt_options, speed_bound
from .profile import TIME_SUBSTEPS, ThetaProfile, linear_node_accelerations, quadratic_b

BOUNDARY_REST = 'rest'
BOUNDARY_PERIODIC = 'periodic'
BOUNDARIES = (BOUNDARY_REST, BOUNDARY_PERIODIC)

#: weight of the energy in a minimum-time solve (keeps the epigraph variables determined)
TIME_OBJECTIVE_ENERGY_WEIGHT = 1e-5


@dataclass(frozen=True)
class SolveRequest:
    """What changes between solves of one built problem.

    duration T_req [s] (0 = free); time_weight w_T [J/s]; energy_weight w_E [-] (1 for
    energy, ~0 for minimum time); min_theta_dot delta [rad/s]; velocity_limit and
    torque_limit (n,) [rad/s], [N m] (already scaled / with margin).
    """

    duration: float
    time_weight: float
    energy_weight: float
    min_theta_dot: float
    velocity_limit: np.ndarray
    torque_limit: np.ndarray
    tcp_speed_max: float = 0.0     # [m/s], 0 = none (the planner applies its margin)
    tcp_speed_min: float = 0.0     # [m/s], 0 = none; away from the rest ends
    tcp_accel_max: float = 0.0     # [m/s^2], 0 = none (needs a problem with accel_rows)
    tcp_ramp_length: float = 0.0   # [m] of arc length at each rest end free of tcp_speed_min
    jerk_limit: np.ndarray | None = None   # (n,) [rad/s^3]; None = none (needs ``jerk`` rows)
    tcp_jerk_max: float = 0.0      # [m/s^3], 0 = none

    @property
    def process_key(self) -> tuple:
        return (self.tcp_speed_max, self.tcp_speed_min, self.tcp_accel_max,
                self.tcp_ramp_length)


@dataclass(frozen=True)
class TcpPath:
    """The path in task space on the grid: p' and p'' [m/rad, m/rad^2] at the nodes (N, 3),
    the midpoints (K, 3) and the other side of the piece-end nodes (S, 3; the indices are
    the transcription's ``sides``), arc length of the nodes sigma (N,) [m]."""

    d1_nodes: np.ndarray
    d2_nodes: np.ndarray
    d1_mids: np.ndarray
    d2_mids: np.ndarray
    d1_sides: np.ndarray
    d2_sides: np.ndarray
    sigma: np.ndarray


#: the tcp_speed_min floor over a rest ramp, v >= v_min (d / r)^RAMP_SPEED_EXPONENT: 2/3 is
#: the speed of a constant-jerk start (v ~ t^2, d ~ t^3), which the jerk limits allow
RAMP_SPEED_EXPONENT = 2.0 / 3.0


@dataclass(frozen=True)
class JerkPath:
    """The path's derivatives for the jerk rows, at three points of every interval (0: just
    after its start node, 1: midpoint, 2: just before its end node; each on the interval's own
    side of a piece end): dq, ddq, dddq (3, K, n) [rad/rad^k], tcp d1, d2, d3 (3, K, 3)
    [m/rad^k]."""

    dq: np.ndarray
    ddq: np.ndarray
    dddq: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    d3: np.ndarray


def _frame_components(d1, d2, d3):
    """p', p'', p^(3) (K, 3) in the path frame: (A, B, C) (K, 3), column j the component
    along e_j of p^(3), p'', p' (e_1 = p' / |p'|, e_2 the unit part of p'' normal to it or
    any unit normal where there is none, e_3 = e_1 x e_2)."""
    e1 = d1 / np.linalg.norm(d1, axis=1, keepdims=True)
    nrm = d2 - (d2 * e1).sum(axis=1, keepdims=True) * e1
    size = np.linalg.norm(nrm, axis=1, keepdims=True)
    other = np.where(np.abs(e1[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    alt = np.cross(e1, other)
    e2 = np.where(size > 1e-9, nrm / np.maximum(size, 1e-300), alt)
    e2 /= np.linalg.norm(e2, axis=1, keepdims=True)
    e3 = np.cross(e1, e2)
    E = np.stack([e1, e2, e3], axis=2)                   # (K, 3 xyz, 3 frame)
    comp = lambda v: np.einsum('kx,kxj->kj', v, E)       # noqa: E731
    return comp(d3), comp(d2), comp(d1)


@dataclass(frozen=True)
class TranscriptionResult:
    """profile; energy [J] and duration [s] of the optimiser's own quadrature (exact |y|);
    peak torque (n,) [N m] at the nodes; stats."""

    profile: ThetaProfile
    energy: float
    duration: float
    peak_torque: np.ndarray
    stats: SolveStats
    electrical_energy: float = float('nan')   # [J], own quadrature, electrical model only


def _within(u, v, rel: float) -> bool:
    """Every element of u within a relative distance rel of v's (v nonzero)."""
    return bool(np.all(np.abs(np.asarray(u, float) / np.asarray(v, float) - 1.0) <= rel))


def _close_process(u: tuple, v: tuple, rel: float) -> bool:
    """Process constraints (SolveRequest.process_key) field by field the same, or both set
    (> 0) and within a relative distance ``rel``."""
    return all(a == b or (a > 0 and b > 0 and abs(a / b - 1.0) <= rel) for a, b in zip(u, v))


class Transcription:
    """The (a, b) NLP on one path and grid; ``solve`` is thread safe (one solve at a time)."""

    def __init__(self, nodes: PathDynamics, mids: PathDynamics, friction: Callable,
                 boundary: str = BOUNDARY_REST, abs_smoothing: float = 0.0,
                 max_iter: int = 500, tol: float = 1e-8, warm_start: bool = True,
                 sides: tuple | None = None, electrical=None, bus_mode: str = 'shared',
                 electrical_smoothing: float = 0.5, tcp: TcpPath | None = None,
                 accel_rows: bool = False, band_rows: bool = False,
                 jerk: JerkPath | None = None, warm_max_iter: int = 40,
                 warm_window: float = 0.2, warm_from_time_optimal: bool = False,
                 resolve_mu_init: float = 0.0, mumps_permuting_scaling: int = -1):
        """``sides``: optional (node indices (S,), PathDynamics at them): the other side of
        nodes where the path's curvature jumps (a polyline's piece ends; Phi' is continuous
        there, Phi'' is not). Their torques get rows too, so the limits hold on both sides.
        ``tcp``: the path in task space, for process constraints (speed band as bounds);
        ``accel_rows``: build the |TCP acceleration| rows too (needs ``tcp``); ``band_rows``:
        build the rows of b at the three quarter points of every interval, which only a TCP
        speed band needs (without one they are implied: module docstring); ``warm_max_iter``:
        the warm solver's iteration cap (a warm solve that reaches it is repeated cold);
        ``warm_window``: how far (relative) a request's duration and limits may be from the
        last solve's for a warm start (``_close_to_last``); ``warm_from_time_optimal``: a
        fixed-duration request right after a time-optimal solve starts from that solution
        played at its duration (``_time_optimal_start``); ``resolve_mu_init`` > 0: IPOPT's
        initial barrier parameter for a warm re-solve at the last solve's own duration (the
        planner's re-solve after its check tightened a limit or a process bound by < 1 %;
        0: the warm solver's 1e-4); ``mumps_permuting_scaling`` >= 0: IPOPT's option of that
        name for every solver of this problem (MUMPS ICNTL(6); -1: IPOPT's default, 7 =
        automatic choice; cycle.FRONT_MUMPS_PERMUTING_SCALING)."""
        if boundary not in BOUNDARIES:
            raise ValueError(f'boundary must be one of {BOUNDARIES}, not {boundary!r}')
        self.nodes, self.mids, self.boundary = nodes, mids, boundary
        self.tcp, self.accel_rows = tcp, bool(accel_rows and tcp is not None)
        self.band_rows = bool(band_rows)
        self.jerk = jerk
        self.cubic_rest = jerk is not None and boundary == BOUNDARY_REST
        # the ramp floor on b = v^2: (d / r)^(4/3) with cubic rest ends, else (d / r)^1
        self._ramp_power = 2 * RAMP_SPEED_EXPONENT if self.cubic_rest else 1.0
        self.abs_smoothing = float(abs_smoothing)
        self._lock = threading.Lock()
        self._last = None
        self.use_warm_start = warm_start
        t0 = time.perf_counter()
        N = nodes.theta.size
        n = nodes.dq.shape[1]
        K = N - 1
        dth = np.diff(nodes.theta)
        self.N, self.n = N, n

        # --- decision variables: b and a at the nodes, epigraph variables e -----------
        if boundary == BOUNDARY_REST:
            xb = ca.SX.sym('b', N - 2)
            b = ca.vertcat(0, xb, 0)                 # at rest at both ends
            xa = ca.SX.sym('a', N)
            a = xa
        else:
            xb = ca.SX.sym('b', N - 1)
            b = ca.vertcat(xb, xb[0])                # b_{N-1} = b_0
            xa = ca.SX.sym('a', N - 1)
            a = ca.vertcat(xa, xa[0])                # a_{N-1} = a_0
        use_epi = self.abs_smoothing <= 0
        n_y = n * (N + K)                            # power samples: nodes, then midpoints
        # y = e_pos - e_neg with e_pos, e_neg >= 0: |y| = e_pos + e_neg at the optimum
        e = ca.SX.sym('e', 2 * n_y) if use_epi else ca.SX.zeros(0)
        x = ca.vertcat(xb, xa, e)
        p = ca.SX.sym('p', 2)                        # (w_E, w_T)
        self._nb, self._na, self._ne = xb.numel(), xa.numel(), e.numel()

        # --- b on the time-law pieces and at the midpoints (affine in b, a) --------------
        D = ca.DM(dth)
        J = TIME_SUBSTEPS
        b_sub = [quadratic_b(b[:-1], a[:-1], a[1:], D, D * (j / J)) for j in range(1, J)]
        a_mid = 0.5 * (a[:-1] + a[1:])
        if self.cubic_rest:      # constant path jerk from / to rest: b = b_1 (s / h)^(4/3)
            def ends(v, first, last):
                return ca.vertcat(first, v[1:K - 1], last)
            b_sub = [ends(b_sub[j - 1], b[1] * (j / J) ** (4 / 3),
                          b[N - 2] * (1 - j / J) ** (4 / 3)) for j in range(1, J)]
            a_mid = ends(a_mid, a[1] * 0.5 ** (1 / 3), a[N - 2] * 0.5 ** (1 / 3))
        b_mid = b_sub[J // 2 - 1]
        safe_sqrt = lambda v: ca.sqrt(ca.fmax(v, 1e-12))  # noqa: E731  (rows may dip < 0)
        sb = ca.sqrt(b)
        pts = [sb[:-1]] + [safe_sqrt(bj) for bj in b_sub] + [sb[1:]]
        pieces = [2 * D / J / (pts[j] + pts[j + 1]) for j in range(J)]
        if self.cubic_rest:      # exact: 3 h / sqrt(b_1), the pieces t ~ s^(1/3)
            t0_, t1_ = 3 * dth[0] / safe_sqrt(b[1]), 3 * dth[-1] / safe_sqrt(b[N - 2])
            w = [((j + 1) ** (1 / 3) - j ** (1 / 3)) / J ** (1 / 3) for j in range(J)]
            pieces = [ends(pc, t0_ * w[j], t1_ * w[J - 1 - j])
                      for j, pc in enumerate(pieces)]
        duration = ca.sum1(sum(pieces))

        # --- dynamics: torque along the path, affine in (a, b) apart from friction ------
        rep = lambda row: ca.repmat(ca.reshape(row, 1, -1), n, 1)  # noqa: E731
        rigid_n = ca.DM(nodes.m.T) * rep(a) + ca.DM(nodes.c.T) * rep(b) + ca.DM(nodes.g.T)
        rigid_m = (ca.DM(mids.m.T) * rep(a_mid) + ca.DM(mids.c.T) * rep(b_mid)
                   + ca.DM(mids.g.T))
        tau_n = rigid_n + friction(ca.DM(nodes.dq.T) * rep(sb))
        tau_m = rigid_m + friction(ca.DM(mids.dq.T) * rep(safe_sqrt(b_mid)))
        # Where joint i reverses inside interval k (or starts/stops), friction sweeps through
        # its breakaway value F0_i between the samples: there |rigid torque| <= tau_max - F0
        # at both nodes and the midpoint of the interval.
        sgn_n, sgn_m = np.sign(nodes.dq.T), np.sign(mids.dq.T)
        rev = (sgn_n[:, :-1] != sgn_n[:, 1:]) | (sgn_m != sgn_n[:, :-1])
        if boundary == BOUNDARY_REST:            # starting from / stopping at v = 0
            rev[:, 0] = rev[:, -1] = True
        joint, interval = np.nonzero(rev)
        self._rev_joint = joint
        probe = ca.DM(np.array([[0.01, -0.01]] * n))
        self._breakaway = np.abs(np.asarray(friction(probe))).max(axis=1)
        flat = lambda i, k: (k * n + i).tolist()  # noqa: E731  (column-major vec index)
        rev_rows = ca.vertcat(ca.vec(rigid_n)[flat(joint, interval)],
                              ca.vec(rigid_m)[flat(joint, interval)],
                              ca.vec(rigid_n)[flat(joint, interval + 1)])
        # power per unit theta [J/rad] at the nodes and midpoints, (n (N + K),)
        y = ca.vertcat(ca.vec(tau_n * ca.DM(nodes.dq.T)), ca.vec(tau_m * ca.DM(mids.dq.T)))
        wn = np.zeros(N)
        wn[:-1] += dth / 6
        wn[1:] += dth / 6                          # Simpson weights dth/6 (1, 4, 1)
        W = ca.vertcat(ca.vec(ca.DM(np.tile(wn, (n, 1)))),
                       ca.vec(ca.DM(np.tile(4 * dth / 6, (n, 1)))))

        # --- objective -------------------------------------------------------------------
        energy_exact = ca.dot(W, ca.fabs(y))
        if use_epi:
            e_pos, e_neg = e[:n_y], e[n_y:]
            energy = ca.dot(W, e_pos + e_neg)
        else:
            energy = ca.dot(W, ca.sqrt(y ** 2 + self.abs_smoothing ** 2))
        self.electrical, self.bus_mode = electrical, bus_mode
        if electrical is not None:
            qd_n = ca.DM(nodes.dq.T) * rep(sb)
            qd_m = ca.DM(mids.dq.T) * rep(safe_sqrt(b_mid))
            dt1, dt2 = sum(pieces[:J // 2]), sum(pieces[J // 2:])   # the halves of each k

            def el_energy(eps):
                pn = ca.transpose(electrical.casadi_power(tau_n, qd_n, bus_mode, eps))
                pm = ca.transpose(electrical.casadi_power(tau_m, qd_m, bus_mode, eps))
                return ca.sum1(dt1 * (pn[:-1] + pm) / 2 + dt2 * (pm + pn[1:]) / 2)
            el_exact = el_energy(0.0)
            f = p[0] * (el_energy(float(electrical_smoothing)) + 1e-6 * energy) \
                + p[1] * duration
        else:
            el_exact = ca.SX(float('nan'))
            f = p[0] * energy + p[1] * duration

        # --- path constraints (rows; bounds are set per solve) ---------------------------
        wc = np.ones(K)
        if self.cubic_rest:
            wc[0] = wc[-1] = 1.5                     # b_1 = 1.5 a_1 h (a = 0 at rest)
        collocation = b[1:] - b[:-1] - (a[:-1] + a[1:]) * ca.DM(dth * wc)   # = 0 (exact)
        # theta_dot >= delta between the samples: b at the 5 points of an interval minus the
        # largest dip of a convex quadratic between them (rows >= delta^2, interior intervals)
        dip = (a[1:] - a[:-1]) * D / (4 * TIME_SUBSTEPS ** 2)
        dip_rows = ca.vertcat(*[bj - dip for bj in [b[:-1]] + b_sub + [b[1:]]])
        quarter = ca.vertcat(*b_sub) if self.band_rows else ca.SX(0, 1)
        g_rows = [duration, collocation, quarter, b_mid, ca.vec(tau_n),
                  ca.vec(tau_m), rev_rows, dip_rows]
        if use_epi:
            g_rows += [y - e_pos + e_neg]            # = 0
        self._n_side = 0
        if sides is not None and len(sides[0]):
            idx, sd = np.asarray(sides[0], int), sides[1]
            a_s, b_s = a[idx.tolist()], b[idx.tolist()]
            tau_s = (ca.DM(sd.m.T) * rep(a_s) + ca.DM(sd.c.T) * rep(b_s) + ca.DM(sd.g.T)
                     + friction(ca.DM(sd.dq.T) * rep(ca.sqrt(b_s))))
            g_rows += [ca.vec(tau_s)]                # |tau| <= limit on the other side too
            self._n_side = idx.size
        self._n_acc = 0
        if self.accel_rows:                          # |p'' b + p' a|^2 <= a_max^2
            acc = [ca.DM(tcp.d2_nodes.T) * ca.repmat(ca.reshape(b, 1, -1), 3, 1)
                   + ca.DM(tcp.d1_nodes.T) * ca.repmat(ca.reshape(a, 1, -1), 3, 1),
                   ca.DM(tcp.d2_mids.T) * ca.repmat(ca.reshape(b_mid, 1, -1), 3, 1)
                   + ca.DM(tcp.d1_mids.T) * ca.repmat(ca.reshape(a_mid, 1, -1), 3, 1)]
            if sides is not None and len(sides[0]):
                acc.append(ca.DM(tcp.d2_sides.T) * ca.repmat(ca.reshape(b_s, 1, -1), 3, 1)
                           + ca.DM(tcp.d1_sides.T) * ca.repmat(ca.reshape(a_s, 1, -1), 3, 1))
            acc_rows = ca.vertcat(*[ca.transpose(ca.sum1(r ** 2)) for r in acc])
            g_rows += [acc_rows]
            self._n_acc = acc_rows.numel()
        self._n_jerk = self._n_tcp_jerk = 0
        self._binormal = []       # |p^(3)| along the binormal at the jerk rows' points
        if jerk is not None:
            kap = (a[1:] - a[:-1]) / D
            b3 = [b[:-1], b_mid, b[1:]]
            a3 = [a[:-1], a_mid, a[1:]]
            sq3 = [safe_sqrt(v) for v in b3]
            # path jerk kappa sqrt(b); constant on the cubic rest intervals
            tj = [kap * sq for sq in sq3]
            if self.cubic_rest:
                j0 = a[1] * safe_sqrt(b[1]) / (3 * dth[0])
                j1 = -a[N - 2] * safe_sqrt(b[N - 2]) / (3 * dth[-1])
                tj = [ends(v, j0, j1) for v in tj]
            qj, pj = [], []
            for m in range(3):
                bb, aa, sq, tt = (rep(v) for v in (b3[m], a3[m], sq3[m], tj[m]))
                qj.append(ca.vec(ca.DM(jerk.dddq[m].T) * bb * sq
                                 + 3 * ca.DM(jerk.ddq[m].T) * sq * aa
                                 + ca.DM(jerk.dq[m].T) * tt))
                # TCP: components in the path frame (tangent T, normal N, binormal B); a
                # row for |.|^2 made IPOPT take > 10x the iterations. Rows T, N, (T + N) /
                # sqrt 2, (T - N) / sqrt 2 (an octagon in the osculating plane) and B, bounds
                # in _bounds: the norm stays within J_tcp. (Each component within
                # J_tcp / sqrt 3 refused closed splines whose motions within J_tcp exist,
                # issue 28: bench_floor_certificate.py.)
                A, B, C = _frame_components(jerk.d1[m], jerk.d2[m], jerk.d3[m])
                rep3 = lambda row: ca.repmat(ca.reshape(row, 1, -1), 3, 1)  # noqa: E731
                fr = (ca.DM(A.T) * rep3(b3[m]) * rep3(sq3[m])
                      + 3 * ca.DM(B.T) * rep3(sq3[m]) * rep3(a3[m])
                      + ca.DM(C.T) * rep3(tj[m]))
                r2 = 1 / np.sqrt(2)
                pj.append(ca.vec(ca.vertcat(fr[0, :], fr[1, :], r2 * (fr[0, :] + fr[1, :]),
                                            r2 * (fr[0, :] - fr[1, :]), fr[2, :])))
                # the binormal component is p^(3)_B b^(3/2) (p'' and p' have none)
                self._binormal.append(np.abs(A[:, 2]))
            g_rows += [ca.vertcat(*qj), ca.vertcat(*pj)]
            self._n_jerk, self._n_tcp_jerk = 3 * K * n, 15 * K
        g = ca.vertcat(*g_rows)
        self._rows = np.cumsum([0] + [r.numel() for r in g_rows])

        # --- solver ------------------------------------------------------------------------
        nlp = {'x': x, 'p': p, 'f': f, 'g': g}
        self._ipopt_extra = ({'mumps_permuting_scaling': int(mumps_permuting_scaling)}
                             if mumps_permuting_scaling >= 0 else {})
        self._solver_cold = ca.nlpsol('transcription', 'ipopt', nlp,
                                      ipopt_options(max_iter, tol, extra=self._ipopt_extra))
        # warm solver (capped iterations, then a cold solve takes over): built on the first
        # request that can use it; each IPOPT instance holds ~25-40 MiB at N = 200
        self._nlp, self._max_iter, self._tol = nlp, max_iter, tol
        self._warm_max_iter = int(warm_max_iter)
        self._warm_window = float(warm_window)
        self._warm_from_time_optimal = bool(warm_from_time_optimal)
        self._resolve_mu_init = float(resolve_mu_init)
        self._solver_resolve = None
        self._solver_warm = None
        self._aux = ca.Function('aux', [x], [energy_exact, duration, ca.vec(tau_n),
                                             ca.vec(tau_m), y, el_exact])
        self._ba = ca.Function('ba', [x], [b, a])
        self.build_time = time.perf_counter() - t0

    # ------------------------------------------------------------------------------------
    def _bounds(self, req: SolveRequest):
        N, K = self.N, self.N - 1
        if not self.band_rows and (req.tcp_speed_max > 0 or req.tcp_speed_min > 0):
            raise ValueError('a TCP speed band needs a problem built with band_rows')
        beta_n = speed_bound(self.nodes.dq, req.velocity_limit)
        beta_m = speed_bound(self.mids.dq, req.velocity_limit)
        lo = req.min_theta_dot ** 2
        if self.boundary == BOUNDARY_REST:
            lbb, ubb = np.full(N - 2, lo), beta_n[1:-1]
        else:
            lbb, ubb = np.full(N - 1, lo), beta_n[:-1]
        lba, uba = np.full(self._na, -np.inf), np.full(self._na, np.inf)
        if self.cubic_rest:
            # theta_ddot = 0 at rest (no torque step); b_1 >= delta^2 bounds the rest time
            lba[0] = uba[0] = lba[-1] = uba[-1] = 0.0
        elif self.boundary == BOUNDARY_REST:
            # leave and reach rest no slower than b(s) = delta^2 s / h (finite, short time)
            h = np.diff(self.nodes.theta)
            lba[0] = lo / (2 * h[0])
            uba[-1] = -lo / (2 * h[-1])
        # process constraints: a cap and a floor on b (inf / 0 where none: the same numbers)
        cap_n, cap_m, floor_n, floor_k, a_rest = self._tcp_bounds(req)
        if self.boundary == BOUNDARY_REST and not self.cubic_rest:   # leave / reach rest at
            lba[0] = max(lba[0], a_rest[0])         # least as fast as the ramp floor rises
            uba[-1] = min(uba[-1], -a_rest[1])
        beta_m = np.minimum(beta_m, cap_m)
        if self.boundary == BOUNDARY_REST:
            lbb = np.maximum(lbb, floor_n[1:-1])
            ubb = np.minimum(ubb, cap_n[1:-1])
        else:
            lbb = np.maximum(lbb, floor_n[:-1])
            ubb = np.minimum(ubb, cap_n[:-1])
        lbx = np.concatenate([lbb, lba, np.zeros(self._ne)])
        ubx = np.concatenate([ubb, uba, np.full(self._ne, np.inf)])
        if req.duration > 0:
            lt, ut = req.duration, req.duration
        else:
            lt, ut = 0.0, np.inf
        # b >= delta^2 inside the path; on a rest interval only >= 0
        lo_sub = np.full(K, lo)
        if self.boundary == BOUNDARY_REST:
            lo_sub[0] = lo_sub[-1] = 0.0
        n_sub = TIME_SUBSTEPS - 1
        n_quarter = n_sub if self.band_rows else 0
        tau_lim = np.asarray(req.torque_limit, float)
        tau_n, tau_m = np.tile(tau_lim, N), np.tile(tau_lim, K)
        tau_rev = np.tile(tau_lim[self._rev_joint] - self._breakaway[self._rev_joint], 3)
        lo_dip = np.full(K, lo)
        if self.boundary == BOUNDARY_REST:
            lo_dip[0] = lo_dip[-1] = -np.inf      # the rest intervals have their own rows
        # the speed floor at each row's own point (rest: never the first or last interval)
        floor_q, floor_dip = self._floor_points(req, floor_n)
        lo_q = np.maximum(lo_sub[None, :], floor_q)                 # (n_sub, K)
        lo_dip = np.where(floor_dip > 0, np.maximum(lo_dip[None, :], floor_dip),
                          lo_dip[None, :])                          # (n_sub + 2, K)
        lbg = [[lt], np.zeros(K), lo_q[:n_quarter].ravel(), floor_k, -tau_n, -tau_m,
               -tau_rev, lo_dip.ravel()]
        ubg = [[ut], np.zeros(K), np.tile(cap_m, n_quarter), beta_m, tau_n, tau_m, tau_rev,
               np.full((n_sub + 2) * K, np.inf)]
        if self._ne:
            lbg += [np.zeros(self._ne // 2)]
            ubg += [np.zeros(self._ne // 2)]
        if self._n_side:
            lbg += [-np.tile(tau_lim, self._n_side)]
            ubg += [np.tile(tau_lim, self._n_side)]
        if req.tcp_accel_max > 0 and not self._n_acc:
            raise ValueError('tcp_accel_max needs a problem built with accel_rows')
        if self._n_acc:
            lbg += [np.full(self._n_acc, -np.inf)]
            ubg += [np.full(self._n_acc, req.tcp_accel_max ** 2 if req.tcp_accel_max > 0
                            else np.inf)]
        if self._n_jerk:
            jl = (np.full(self.n, np.inf) if req.jerk_limit is None
                  else np.asarray(req.jerk_limit, float))
            jl = np.tile(jl, 3 * K)
            pl = np.tile(self._tcp_jerk_bounds(req, ubx[:self._nb], beta_m), 3 * K)
            lbg += [-jl, -pl]
            ubg += [jl, pl]
        elif req.jerk_limit is not None or req.tcp_jerk_max > 0:
            raise ValueError('jerk limits need a problem built with jerk rows')
        return lbx, ubx, np.concatenate(lbg), np.concatenate(ubg)

    def _tcp_jerk_bounds(self, req: SolveRequest, ub_b: np.ndarray, ub_mid: np.ndarray
                         ) -> np.ndarray:
        """Bounds (5,) of the TCP jerk rows of one point (T, N, the two diagonals, B) such
        that |jerk| <= tcp_jerk_max: the binormal component p^(3)_B b^(3/2) depends on b
        only, so its largest value at the caps on b (``ub_b`` of the free node values,
        ``ub_mid`` at the midpoints) bounds it: R_B = min(that, J / sqrt 3); the octagon in
        the osculating plane gets the apothem cos(pi / 8) sqrt(J^2 - R_B^2). A planar path
        (B = 0) keeps 0.924 J per direction instead of J / sqrt 3 = 0.577 J per component."""
        J = req.tcp_jerk_max
        if not J > 0:
            return np.full(5, np.inf)
        if self.boundary == BOUNDARY_REST:
            ub = np.concatenate([[0.0], ub_b, [0.0]])
        else:
            ub = np.append(ub_b, ub_b[0])
        caps = [ub[:-1], ub_mid, ub[1:]]
        with np.errstate(invalid='ignore'):
            need = max(float(np.nanmax(bn * np.maximum(c, 0.0) ** 1.5))
                       for bn, c in zip(self._binormal, caps))
        r_b = min(need * (1 + 1e-6) + 1e-9 * J, J / np.sqrt(3))
        r_tn = np.cos(np.pi / 8) * np.sqrt(J ** 2 - r_b ** 2)
        return np.array([r_tn, r_tn, r_tn, r_tn, r_b])

    def _tcp_bounds(self, req: SolveRequest):
        """The process constraints as bounds on b: cap at the nodes (N,) and midpoints (K,)
        from tcp_speed_max; floor at the nodes (N,) and per interval (K,) from
        tcp_speed_min: all along a periodic path; on a rest-to-rest one beyond
        tcp_ramp_length from both ends, and over the ramps rising as a constant-acceleration
        start / stop would, v^2 >= v_min^2 d / r (d the distance to the nearer rest end), so
        that a plan cannot creep through its lead-in / lead-out (the energy optimum did: 0.7 s
        at each end of the 8 s rectangle); per interval the larger value of its two nodes
        (holds between the samples through the quarter-point and dip rows); the rest
        intervals get it through theta_ddot at the rest nodes, a_rest (2,) [rad/s^2].
        inf / 0 where there is none."""
        N, K = self.N, self.N - 1
        cap_n, cap_m = np.full(N, np.inf), np.full(K, np.inf)
        floor_n, floor_k, a_rest = np.zeros(N), np.zeros(K), np.zeros(2)
        if req.tcp_speed_max <= 0 and req.tcp_speed_min <= 0:
            return cap_n, cap_m, floor_n, floor_k, a_rest
        if self.tcp is None:
            raise ValueError('TCP speed bounds need the path in task space (tcp)')
        s1n = np.sum(self.tcp.d1_nodes ** 2, axis=1)          # |p'|^2 [m^2/rad^2]
        s1m = np.sum(self.tcp.d1_mids ** 2, axis=1)
        if req.tcp_speed_max > 0:
            cap_n, cap_m = req.tcp_speed_max ** 2 / s1n, req.tcp_speed_max ** 2 / s1m
        if req.tcp_speed_min > 0:
            sig = self.tcp.sigma
            v2 = req.tcp_speed_min ** 2
            if self.boundary == BOUNDARY_REST:
                r = req.tcp_ramp_length
                frac = self._ramp_fraction(sig, r)
                frac[0] = frac[-1] = 0.0              # b = 0 at the rest nodes
                floor_n = v2 * frac ** self._ramp_power / s1n
                fk = self._ramp_fraction(0.5 * (sig[:-1] + sig[1:]), r)  # at the midpoints
                fk[0] = fk[-1] = 0.0                  # the rest intervals: a_rest
                floor_k = v2 * fk ** self._ramp_power / s1m
                a_rest = v2 / (2 * r * np.sqrt(s1n[[0, -1]]))
            else:
                floor_k = v2 / s1m
                floor_n = v2 / s1n
        return cap_n, cap_m, floor_n, floor_k, a_rest

    @staticmethod
    def _ramp_fraction(sigma: np.ndarray, ramp: float) -> np.ndarray:
        """The floor's fraction of v_min^2 at arc lengths ``sigma`` [m] of a rest-to-rest
        path: d / ramp, d the distance to the nearer rest end, at most 1."""
        length = float(sigma[-1]) if sigma.ndim == 1 else float(np.max(sigma))
        return np.clip(np.minimum(sigma, length - sigma) / ramp, 0.0, 1.0)

    def _floor_points(self, req: SolveRequest, floor_n: np.ndarray):
        """The speed floor on b at the rows' own points: (n_sub, K) at the quarter points
        j / TIME_SUBSTEPS of every interval, and (n_sub + 2, K) for the dip rows of the
        points j = 0 .. TIME_SUBSTEPS (each the floor's smallest value over the pieces next
        to its point: the dip row bounds b between the points). Over the ramps the floor
        rises with the distance from the rest end, so each row gets the value where it
        is: a bound per interval (the larger of its nodes', issue 28) shifted the ramp by a
        grid interval and refused the constant-acceleration start the ramp is meant for.
        Zero where there is no floor (the rest intervals, no tcp_speed_min)."""
        K, J = self.N - 1, TIME_SUBSTEPS
        if req.tcp_speed_min <= 0:
            return np.zeros((J - 1, K)), np.zeros((J + 1, K))
        sig = self.tcp.sigma
        frac_j = np.arange(J + 1)[:, None] / J
        sig_p = sig[None, :-1] + np.diff(sig)[None, :] * frac_j        # (J + 1, K)
        s1 = np.sum(self.tcp.d1_mids ** 2, axis=1)[None, :]           # |p'|^2, constant
        v2 = req.tcp_speed_min ** 2
        if self.boundary == BOUNDARY_REST:
            full = np.concatenate([sig_p.ravel(), sig[-1:]])
            frac = self._ramp_fraction(full, req.tcp_ramp_length)[:-1].reshape(sig_p.shape)
            frac[:, 0] = frac[:, -1] = 0.0
        else:
            frac = np.ones_like(sig_p)
        fp = v2 * frac ** self._ramp_power / s1
        lo_nb = np.minimum(fp, np.vstack([fp[:1], fp[:-1]]))
        lo_nb = np.minimum(lo_nb, np.vstack([fp[1:], fp[-1:]]))
        return fp[1:-1], lo_nb

    def initial_guess(self, req: SolveRequest, lbx, ubx) -> np.ndarray:
        """b constant at the requested mean speed (clipped to the bounds), a from b, e = |y|."""
        nb, na = self._nb, self._na
        if req.duration > 0:
            b0 = (2 * np.pi / req.duration) ** 2
        else:
            b0 = 0.25 * np.min(ubx[:nb])
        if self.cubic_rest:
            # jerk rows: leave and reach rest smoothly, b = b0 sin^2 over 15 % of the path
            # at each end (a = b' / 2 = 0 at rest), b0 raised for the time the ramps lose
            th = self.nodes.theta
            r = 0.15 * 2 * np.pi
            w = np.sin(0.5 * np.pi * np.clip(np.minimum(th, th[-1] - th) / r, 0, 1)) ** 2
            dw = np.where((th < r), 1.0, np.where(th[-1] - th < r, -1.0, 0.0)) * (
                0.5 * np.pi / r) * np.sin(np.pi * np.clip(np.minimum(th, th[-1] - th) / r,
                                                          0, 1))
            b0 *= 1.4
            xb = np.clip(b0 * w[1:-1], lbx[:nb], 0.95 * ubx[:nb])
            b = np.concatenate([[0.0], xb, [0.0]])
            a = 0.5 * b0 * dw
            a[0] = a[-1] = 0.0
        else:
            xb = np.clip(np.full(nb, b0), lbx[:nb], 0.95 * ubx[:nb])
            if self.boundary == BOUNDARY_REST:
                b = np.concatenate([[0.0], xb, [0.0]])
            else:
                b = np.append(xb, xb[0])
            # node a consistent with b on average (the collocation rows are met by the solver)
            a = linear_node_accelerations(self.nodes.theta, b)[:na]
        return self._with_epigraph(np.concatenate([xb, a, np.zeros(self._ne)]), 1e-3)

    def _with_epigraph(self, x: np.ndarray, push: float = 0.0) -> np.ndarray:
        """x with its epigraph variables set to (max(y, 0), max(-y, 0)) + push of its own
        (b, a) (in place; their rows y - e_pos + e_neg = 0 then hold)."""
        if self._ne:
            y = np.asarray(self._aux(x)[4]).ravel()
            x[self._nb + self._na:] = np.concatenate([np.maximum(y, 0.0),
                                                      np.maximum(-y, 0.0)]) + push
        return x

    def _close_to_last(self, req: SolveRequest) -> bool:
        """Warm starts pay off only near the last solution (IPOPT's dual warm start is
        unreliable after large changes): same weights, speed floor and process constraints,
        duration and every speed and torque limit within 20 % (``warm_window``) of the last
        ones. The limits
        may differ: the planner's re-solve after its exact check tightens one joint's limit
        by a few per cent, and the next request starts from the nominal limits again; with
        identical limits required, every polyline plan in bench_paths.py was two cold solves.
        The process constraints likewise: each the same, or both set and within 20 % (the
        re-solve after the check tightened a TCP speed or acceleration bound by < 1 %; on the
        gluing rectangle every front point was two cold solves of 40-115 iterations).
        A warm solve that fails is repeated cold (``solve``)."""
        if self._last is None:
            return False
        last = self._last[3]
        w = self._warm_window
        same = (last.energy_weight == req.energy_weight
                and last.time_weight == req.time_weight
                and self._near(last, req))
        if req.duration > 0 and last.duration > 0:
            return same and _within(req.duration, last.duration, w)
        return same and req.duration == last.duration

    def _near(self, last: SolveRequest, req: SolveRequest) -> bool:
        """Same speed floor; limits and process constraints within ``warm_window``."""
        w = self._warm_window
        return (last.min_theta_dot == req.min_theta_dot
                and _within(req.velocity_limit, last.velocity_limit, w)
                and _within(req.torque_limit, last.torque_limit, w)
                and _close_process(last.process_key, req.process_key, w))

    def _time_optimal_start(self, req: SolveRequest) -> np.ndarray | None:
        """With ``warm_from_time_optimal``: the last solution, if it was time-optimal (the
        planner's min_duration solve before every first plan on a problem), played at
        ``req``'s fixed duration (as ``_time_scaled``), when that is within ``warm_window``
        of its own and the limits are near (``_near``); else None. A primal start only: the
        time objective's multipliers do not fit the energy objective. At a duration just
        above the time-optimal one the energy optimum is nearly that profile (cycle_ten's
        first front points: 24-25 instead of 47-51 iterations on the gluing rectangle and
        the move to the circle, 37 for 37 on the circle)."""
        if not self._warm_from_time_optimal or self._last is None or not req.duration > 0:
            return None
        x, _, _, last = self._last
        if last.duration != 0 or not last.time_weight > 0 or not self._near(last, req):
            return None
        t_last = float(np.asarray(self._aux(x)[1]).ravel()[0])
        if not (t_last > 0 and _within(req.duration, t_last, self._warm_window)):
            return None
        y = x.copy()
        y[:self._nb + self._na] *= (t_last / req.duration) ** 2
        return self._with_epigraph(y)

    def _time_scaled(self, x: np.ndarray, last: SolveRequest, req: SolveRequest) -> np.ndarray:
        """The last solution played at the new fixed duration: theta(t) -> theta(t k) with
        k = T_last / T_req scales b = theta_dot^2 and a = theta_ddot by k^2, which keeps the
        collocation rows exact and meets the duration row exactly (the time law is
        homogeneous of degree -1/2 in (b, a)); the epigraph variables are set to |y| of the
        scaled point so that their rows hold too. IPOPT then starts on a point that breaks
        no equality row, instead of one that misses the new duration (10-segment polyline,
        N = 400, 8 warm re-solves of the transcription with durations drifting <= 5 %: 27-54
        -> 22-34 iterations)."""
        if not (req.duration > 0 and last.duration > 0) or req.duration == last.duration:
            return x
        x = x.copy()
        x[:self._nb + self._na] *= (last.duration / req.duration) ** 2
        return self._with_epigraph(x)

    @property
    def last_request(self) -> SolveRequest | None:
        """The request of the last successful solve (None before one)."""
        last = self._last
        return None if last is None else last[3]

    def solve_without_jerk(self, req: SolveRequest) -> TranscriptionResult:
        """``req`` on this problem without its jerk rows (joint jerk and, through it, the
        torque rate; TCP jerk): the reference of the limits' cost (planner.LimitCost).
        Warm-started from the last solution, normally the plan's own, which is feasible here
        (the rows only go): IPOPT starts on the plan and descends. The rest ends keep theta_ddot
        = 0 and their constant-jerk intervals (the problem's structure). The last solution
        stays the warm start of the next request (the plan's, inside the jerk rows)."""
        saved = self._last
        try:
            # the warm (primal-dual) solver if this problem has one (13-22 iterations on the
            # thesis circle); else the cold one from the plan (26-54 iterations; building the
            # warm one for it cost ~12 s at N = 200)
            return self.solve(replace(req, jerk_limit=None, tcp_jerk_max=0.0),
                              warm=self._solver_warm is not None,
                              start=None if saved is None else saved[0])
        finally:
            with self._lock:
                self._last = saved

    def _sibling_solver(self, name: str, options: dict):
        """Another IPOPT instance of this NLP (other options) that reuses the cold solver's
        derivative functions (objective gradient, constraint Jacobian, Lagrangian Hessian)
        instead of deriving them again: the same functions, so the same numbers; building
        the warm solver of a jerk-limited problem at N = 100 took 1.9-5 s with its own
        derivatives and 0.3-1.2 s with these (cycle fronts, issue 29)."""
        cold = self._solver_cold
        opts = dict(options, grad_f=cold.get_function('nlp_grad_f'),
                    jac_g=cold.get_function('nlp_jac_g'),
                    hess_lag=cold.get_function('nlp_hess_l'))
        return ca.nlpsol(name, 'ipopt', self._nlp, opts)

    def solve(self, req: SolveRequest, warm: bool | None = None,
              start: np.ndarray | None = None) -> TranscriptionResult:
        """Solve for ``req``; warm start from the previous solution when there is one.
        ``start``: the cold solver's initial point instead of ``initial_guess`` (a primal
        start only: no second IPOPT instance is built for it)."""
        with self._lock:
            lbx, ubx, lbg, ubg = self._bounds(req)
            if np.any(lbx > ubx) or np.any(lbg > ubg):
                # bounds that contradict each other (a TCP speed floor above what the joint
                # speed limits allow somewhere): infeasible, IPOPT's word for it, unsolved
                nan = float('nan')
                return TranscriptionResult(None, nan, nan, np.full(self.n, nan),
                                           SolveStats('Infeasible_Problem_Detected', False,
                                                      0, 0.0))
            p = [req.energy_weight, req.time_weight]
            use_warm = self.use_warm_start if warm is None else warm
            t0 = time.perf_counter()
            warm_point, resolve = None, False
            if use_warm and self._close_to_last(req):
                resolve = self._resolve_mu_init > 0 and req.duration == self._last[3].duration
                x0, lam_x, lam_g = self._last[:3]
                x0 = self._time_scaled(x0, self._last[3], req)
                # a row now unbounded (the jerk rows of solve_without_jerk) has no multiplier
                lam_g = np.where(np.isinf(lbg) & np.isinf(ubg), 0.0, lam_g)
                warm_point = (x0, lam_x, lam_g)
            elif use_warm:
                x0 = self._time_optimal_start(req)
                if x0 is not None:
                    warm_point = (x0, np.zeros(lbx.size), np.zeros(lbg.size))
            if warm_point is not None:
                if resolve and self._solver_resolve is None:
                    # the same duration, bounds moved by < 1 %: the last point is nearly
                    # optimal, a small barrier keeps it (glue of cycle_ten: 15-18 instead
                    # of 28-45 iterations, the same energies to 1e-8 relative)
                    self._solver_resolve = self._sibling_solver(
                        'transcription_resolve',
                        ipopt_options(min(self._max_iter, self._warm_max_iter), self._tol,
                                      warm=True, extra={'mu_init': self._resolve_mu_init,
                                                        **self._ipopt_extra}))
                if not resolve and self._solver_warm is None:
                    self._solver_warm = self._sibling_solver(
                        'transcription_warm',
                        ipopt_options(min(self._max_iter, self._warm_max_iter), self._tol,
                                      warm=True, extra=self._ipopt_extra))
                solver = self._solver_resolve if resolve else self._solver_warm
                x0, lam_x, lam_g = warm_point
                sol = solver(x0=np.clip(x0, lbx, ubx), p=p, lbx=lbx, ubx=ubx,
                             lbg=lbg, ubg=ubg, lam_x0=lam_x, lam_g0=lam_g)
                stats = solver.stats()
                if not stats['success']:
                    use_warm = False
            else:
                use_warm = False
            iters = stats['iter_count'] if use_warm else 0
            if not use_warm:
                x0 = (self.initial_guess(req, lbx, ubx) if start is None
                      else np.clip(start, lbx, ubx))
                sol = self._solver_cold(x0=x0, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
                stats = self._solver_cold.stats()
                iters += stats['iter_count']
            if not stats['success']:
                # IPOPT's monotone barrier update can stall on the flat, nearly degenerate
                # problems of long durations (b pressed onto delta^2 almost everywhere; seen:
                # 'Infeasible_Problem_Detected' at 59 s between solved 58 and 59.5 s); the
                # adaptive update solves them. Built for the retry only, then released.
                fallback = self._sibling_solver(
                    'transcription_adaptive',
                    ipopt_options(self._max_iter, self._tol,
                                  extra={'mu_strategy': 'adaptive', **self._ipopt_extra}))
                x0 = (self.initial_guess(req, lbx, ubx) if start is None
                      else np.clip(start, lbx, ubx))
                sol = fallback(x0=x0, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
                stats = fallback.stats()
                iters += stats['iter_count']
                del fallback
            elapsed = time.perf_counter() - t0
            x = np.asarray(sol['x']).ravel()
            ok = bool(stats['success'])
            if ok:
                self._last = (x, np.asarray(sol['lam_x']).ravel(),
                              np.asarray(sol['lam_g']).ravel(), req)
        energy, duration, tau_n, tau_m, _, e_el = (np.asarray(v).ravel()
                                                   for v in self._aux(x))
        b, a = (np.asarray(v).ravel() for v in self._ba(x))
        b = np.maximum(b, 0.0)
        if self.boundary == BOUNDARY_REST:
            b[0] = b[-1] = 0.0
        peak = np.maximum(np.abs(tau_n).reshape(-1, self.n).max(axis=0),
                          np.abs(tau_m).reshape(-1, self.n).max(axis=0))
        stats_out = SolveStats(str(stats['return_status']), ok, int(iters), elapsed)
        profile = None
        if ok:                  # a failed solve keeps IPOPT's own status as the reason
            try:
                profile = ThetaProfile(self.nodes.theta, np.sqrt(b), a)
            except ValueError as exc:
                stats_out = SolveStats(f'invalid profile: {exc}', False, int(iters), elapsed)
        return TranscriptionResult(profile, float(energy[0]), float(duration[0]), peak,
                                   stats_out, float(e_el[0]))
