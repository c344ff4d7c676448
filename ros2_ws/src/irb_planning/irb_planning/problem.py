"""Path-projected dynamics and the pieces every CasADi formulation shares (no ROS).

Along a fixed path q = Phi(theta) the robot equation (thesis eq. 6.7) becomes, with
b = theta_dot^2 and a = theta_ddot (Verscheure et al. 2009),

    tau(theta) = m(theta) a + c(theta) b + g(theta) + tau_f(Phi'(theta) sqrt(b))

    m = M(Phi) Phi',  c = M(Phi) Phi'' + C(Phi, Phi') Phi',  g = g(Phi)      each (n,)

so the rigid-body part is affine in (a, b); only friction is not. The coefficients are
computed from an ``inverse_dynamics(q, qd, qdd)`` callable (toppra-style layering: the planner
never builds a robot model itself): g = ID(q, 0, 0), m = ID(q, 0, Phi') - g,
c = ID(q, Phi', Phi'') - g. The energy per unit theta is sum_i |tau_i Phi'_i| [J/rad], because
|tau_i qd_i| dt = |tau_i Phi'_i theta_dot| dtheta / theta_dot.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class PathDynamics:
    """Coefficients on a theta grid: theta (K,) [rad]; dq = Phi' (K, n) [rad/rad];
    m (K, n) [N m s^2/rad] (per rad/s^2 of theta_ddot), c (K, n) [N m s^2/rad^2]
    (per (rad/s)^2 of b), g (K, n) [N m]."""

    theta: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    m: np.ndarray
    c: np.ndarray
    g: np.ndarray

    def rigid_torque(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """m a + c b + g (K, n) [N m] for a, b (K,)."""
        return self.m * a[:, None] + self.c * b[:, None] + self.g


def path_dynamics(theta: np.ndarray, sample_path: Callable, inverse_dynamics: Callable
                  ) -> PathDynamics:
    """PathDynamics at ``theta`` (K,).

    sample_path(theta) -> JointPath-like (q, dq, ddq each (K, n));
    inverse_dynamics(q, qd, qdd) with (K, n) arrays -> tau (K, n) [N m], no friction.
    """
    jp = sample_path(np.asarray(theta, float))
    zero = np.zeros_like(jp.q)
    g = np.asarray(inverse_dynamics(jp.q, zero, zero), float)
    m = np.asarray(inverse_dynamics(jp.q, zero, jp.dq), float) - g
    c = np.asarray(inverse_dynamics(jp.q, jp.dq, jp.ddq), float) - g
    return PathDynamics(np.asarray(theta, float), jp.q, jp.dq, jp.ddq, m, c, g)


def casadi_inverse_dynamics(model) -> Callable:
    """Vectorised ID(q, qd, qdd) -> tau (K, n) from irb_description's CasADi RNEA.

    The planner uses this one (the evaluator uses pinocchio), so a wrong coefficient would
    show up as an optimiser/evaluator disagreement.
    """
    from irb_description.casadi_dynamics import rnea_function
    f = rnea_function(model)

    def inverse_dynamics(q, qd, qdd):
        q = np.atleast_2d(q)
        F = f.map(q.shape[0])
        return np.asarray(F(q.T, np.atleast_2d(qd).T, np.atleast_2d(qdd).T)).T
    return inverse_dynamics


def casadi_friction(friction_map, smoothing: float) -> Callable:
    """tau_f(v) for a CasADi matrix v (n, K) [rad/s] -> (n, K) [N m].

    Uses ``FrictionMap.casadi_torque`` (parametric Coulomb + viscous + Stribeck, sign(v)
    replaced by tanh(v / smoothing)). Along the path v_i = Phi'_i theta_dot has the sign of
    Phi'_i, so the tanh only matters within ``smoothing`` of a joint's reversal, where the
    power |tau_i v_i| is ~0 anyway.
    """
    def friction(v):
        return friction_map.casadi_torque([v[i, :] for i in range(v.shape[0])], smoothing)
    return friction


def speed_bound(dq: np.ndarray, velocity_limit: np.ndarray) -> np.ndarray:
    """Largest b = theta_dot^2 [rad^2/s^2] (K,) with |Phi'_i| theta_dot <= limit_i for all i."""
    with np.errstate(divide='ignore'):
        ratio = np.asarray(velocity_limit)[None, :] / np.abs(dq)
    return np.min(ratio, axis=1) ** 2


def effective_speed_limit(velocity_limit: np.ndarray, friction_map) -> np.ndarray:
    """min(joint speed limit, upper end of the friction map's valid range) (n,) [rad/s]."""
    return np.minimum(velocity_limit, friction_map.valid_range()[:, 1])


@dataclass(frozen=True)
class SolveStats:
    """Solver outcome: IPOPT return status, success, iterations, wall time [s]."""

    status: str
    success: bool
    iterations: int
    solve_time: float


#: MUMPS's fill-reducing ordering (IPOPT's mumps_pivot_order): 2 = AMF. On the 10-segment
#: polyline at N = 400, 20 ms per IPOPT iteration against 34 ms with the default (METIS
#: chosen automatically) and 24 ms with AMD, same iterations and optimum
#: (benchmarks/bench_linear_solvers.py, results/linear_solvers.json)
MUMPS_ORDERING = 2


def ipopt_options(max_iter: int = 500, tol: float = 1e-8, print_level: int = 0,
                  warm: bool = False, extra: dict | None = None) -> dict:
    """nlpsol options for IPOPT (quiet, exact Hessian, MUMPS); ``warm`` for warm starts."""
    ipopt = {'max_iter': int(max_iter), 'tol': float(tol), 'print_level': int(print_level),
             'sb': 'yes', 'acceptable_tol': max(1e-6, 100 * tol), 'acceptable_iter': 5,
             'mumps_pivot_order': MUMPS_ORDERING}
    if warm:
        ipopt.update({'warm_start_init_point': 'yes', 'warm_start_bound_push': 1e-8,
                      'warm_start_mult_bound_push': 1e-8, 'warm_start_slack_bound_push': 1e-8,
                      'mu_init': 1e-4})
    ipopt.update(extra or {})
    return {'ipopt': ipopt, 'print_time': False, 'error_on_fail': False}
