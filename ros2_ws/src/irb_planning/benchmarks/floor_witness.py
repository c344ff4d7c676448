"""An independent search for a motion along a closed spline that keeps a TCP speed band, the
TCP acceleration bound, the TCP and joint jerk limits and the joint speed limits (issue 28):
a witness that a refusal of such a request is false. Shares nothing with the planner's
transcription: the curve is rebuilt from the waypoints (scipy's periodic CubicSpline on chord
length, as irb_description's SplinePath defines it), its Frenet quantities are exact
(kappa, dkappa/ds, torsion from the spline's own derivatives), the joints come from the
model's closed-form IK and arm_derivatives, their third derivative by a central difference
in arc length.

Motion: speed v(s) > 0 along arc length s, tangential acceleration a(s) = dv/dt and its rate
w(s) = da/dt, periodic; dv/ds = a / v and da/ds = w / v (trapezoidal rule on a uniform
s grid). The TCP jerk in the Frenet frame is exactly

    (w - kappa^2 v^3) T + (3 kappa v a + kappa_s v^3) N + kappa tau v^3 B,

the joint jerk q_sss v^3 + 3 q_ss v a + q_s w. An NLP (CasADi/IPOPT) minimises the peak
|TCP jerk| subject to v_min <= v <= v_max, a^2 + (kappa v^2)^2 <= a_max^2, the joint jerk and
speed limits. A local optimum: a value <= the limit proves a motion exists (checked again
below in the time domain); a value above it proves nothing. The torque and its rate are
evaluated on the result (pinocchio's RNEA, the model's friction), not constrained.

``time_domain_check`` plays the witness independently: u(t) of the spline integrated by
DOP853, the TCP from the spline, jerk and acceleration by finite differences in time.
"""
from __future__ import annotations

import numpy as np


def geometry(model, waypoints: np.ndarray, n: int) -> dict:
    """The closed spline through ``waypoints`` (K, 3) [m] at n uniform arc-length samples."""
    from scipy.interpolate import CubicSpline
    w = np.asarray(waypoints, float)
    pts = np.vstack([w, w[:1]])
    u = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    sp = CubicSpline(u, pts, bc_type='periodic')
    uu = np.linspace(0.0, u[-1], 400001)
    sp1 = np.linalg.norm(sp(uu, 1), axis=1)
    sig = np.concatenate([[0.0], np.cumsum(0.5 * (sp1[1:] + sp1[:-1]) * np.diff(uu))])
    length = float(sig[-1])
    s = np.linspace(0.0, length, n, endpoint=False)
    us = np.interp(s, sig, uu)
    d1, d2, d3 = sp(us, 1), sp(us, 2), sp(us, 3)
    n1 = np.linalg.norm(d1, axis=1)
    c = np.cross(d1, d2)
    cn = np.linalg.norm(c, axis=1)
    kappa = cn / n1 ** 3
    dc = np.cross(d1, d3)
    kappa_s = ((np.einsum('ij,ij->i', c, dc) / cn) / n1 ** 3
               - 3 * cn * np.einsum('ij,ij->i', d1, d2) / n1 ** 5) / n1
    torsion = np.einsum('ij,ij->i', c, d3) / cn ** 2
    t = d1 / n1[:, None]
    p_ss = (d2 - t * np.einsum('ij,ij->i', t, d2)[:, None]) / n1[:, None] ** 2
    q = model.ik_many(sp(us))
    q_s, q_ss = model.arm_derivatives(q, t, p_ss)
    h = length / n
    q_sss = (np.roll(q_ss, -1, 0) - np.roll(q_ss, 1, 0)) / (2 * h)
    return {'s': s, 'length': length, 'kappa': kappa, 'kappa_s': kappa_s,
            'torsion': torsion, 'q': q, 'q_s': q_s, 'q_ss': q_ss, 'q_sss': q_sss,
            'spline': sp, 'u_knots': u, 'u_table': uu, 'sigma_table': sig}


def witness(model, geo: dict, v_min: float, v_max: float, a_max: float,
            joint_jerk: np.ndarray, v_floor_margin: float = 1.0, max_iter: int = 600) -> dict:
    """The speed profile of least peak |TCP jerk| found (see module docstring); IPOPT stops
    after ``max_iter`` iterations (then ``solved`` is False: no witness)."""
    import casadi as ca
    s, k, ks, tau = geo['s'], geo['kappa'], geo['kappa_s'], geo['torsion']
    q_s, q_ss, q_sss = geo['q_s'], geo['q_ss'], geo['q_sss']
    n = s.size
    h = geo['length'] / n
    vel = model.limits.velocity
    opti = ca.Opti()
    v, a, w, peak = opti.variable(n), opti.variable(n), opti.variable(n), opti.variable()
    nxt = list(range(1, n)) + [0]
    vm = 0.5 * (v + v[nxt])
    opti.subject_to(vm * (v[nxt] - v) == 0.5 * h * (a + a[nxt]))
    opti.subject_to(vm * (a[nxt] - a) == 0.5 * h * (w + w[nxt]))
    jt, jn, jb = w - k ** 2 * v ** 3, 3 * k * v * a + ks * v ** 3, k * tau * v ** 3
    opti.subject_to(jt ** 2 + jn ** 2 + jb ** 2 <= peak ** 2)
    opti.subject_to(a ** 2 + k ** 2 * v ** 4 <= a_max ** 2)
    opti.subject_to(opti.bounded(v_min * v_floor_margin, v, v_max))
    for j in range(q_s.shape[1]):
        qddd = q_sss[:, j] * v ** 3 + 3 * q_ss[:, j] * v * a + q_s[:, j] * w
        opti.subject_to(opti.bounded(-joint_jerk[j], qddd, joint_jerk[j]))
        opti.subject_to(opti.bounded(-vel[j], q_s[:, j] * v, vel[j]))
    opti.minimize(peak)
    opti.set_initial(v, 0.5 * (v_min + v_max) if v_max > 0 else 2 * v_min)
    opti.set_initial(a, 0.0)
    opti.set_initial(w, 0.0)
    opti.set_initial(peak, 1e3)
    opti.solver('ipopt', {'print_time': False},
                {'print_level': 0, 'max_iter': max_iter, 'tol': 1e-8, 'sb': 'yes'})
    try:
        sol = opti.solve()
        ok = True
    except RuntimeError:
        sol, ok = opti.debug, False
    V, A, W = sol.value(v), sol.value(a), sol.value(w)
    qd = q_s * V[:, None]
    qdd = q_ss * V[:, None] ** 2 + q_s * A[:, None]
    qddd = q_sss * V[:, None] ** 3 + 3 * q_ss * (V * A)[:, None] + q_s * W[:, None]
    rigid = model.inverse_dynamics_batch(geo['q'], qd, qdd)
    torque = rigid + model.friction.torque(qd)
    rate = (np.roll(rigid, -1, 0) - np.roll(rigid, 1, 0)) / (2 * h) * V[:, None]
    return {'solved': ok, 'tcp_jerk_peak': float(sol.value(peak)), 'v': V, 'a': A, 'w': W,
            'speed_range': (float(V.min()), float(V.max())),
            'tcp_accel_peak': float(np.sqrt(A ** 2 + k ** 2 * V ** 4).max()),
            'joint_jerk_peak': np.abs(qddd).max(axis=0),
            'joint_speed_ratio': float((np.abs(qd).max(axis=0) / vel).max()),
            'torque_ratio': float((np.abs(torque).max(axis=0) / model.limits.torque).max()),
            'torque_rate_peak': np.abs(rate).max(axis=0),
            'period_s': float(np.sum(h / (0.5 * (V + np.roll(V, -1)))))}


def time_domain_check(model, geo: dict, wit: dict, rate: float = 1000.0,
                      periods: float = 2.5) -> dict:
    """Play the witness in time (module docstring): peaks over ``periods`` periods at
    ``rate`` [Hz]: TCP speed range, |acceleration|, |jerk| (third difference), joint jerk
    (third difference of the IK)."""
    from scipy.integrate import solve_ivp
    from scipy.interpolate import CubicSpline
    sp, u_end = geo['spline'], geo['u_knots'][-1]
    length = geo['length']
    s_of_u = CubicSpline(geo['u_table'], geo['sigma_table'])
    s = geo['s']
    v_of_s = CubicSpline(np.append(s, length), np.append(wit['v'], wit['v'][0]),
                         bc_type='periodic')

    def rhs(_t, x):
        um = x[0] % u_end
        return [v_of_s(s_of_u(um)) / np.linalg.norm(sp(um, 1))]
    t_end = periods * wit['period_s']
    sol = solve_ivp(rhs, (0.0, t_end), [0.0], method='DOP853', rtol=1e-13, atol=1e-15,
                    dense_output=True)
    t = np.arange(0.0, t_end, 1.0 / rate)
    p = sp(sol.sol(t)[0] % u_end)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) * rate
    acc = np.linalg.norm(np.diff(p, 2, axis=0), axis=1) * rate ** 2
    jerk = np.linalg.norm(np.diff(p, 3, axis=0), axis=1) * rate ** 3
    q = model.ik_many(p)
    return {'rate_hz': rate, 'speed_range': (float(speed.min()), float(speed.max())),
            'tcp_accel_peak': float(acc.max()), 'tcp_jerk_peak': float(jerk.max()),
            'joint_jerk_peak': (np.abs(np.diff(q, 3, axis=0)).max(axis=0)
                                * rate ** 3).tolist()}
