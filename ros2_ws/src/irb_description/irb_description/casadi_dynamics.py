"""Inverse dynamics of the simplified model as CasADi expressions (for the planner).

PyPI's ``pin`` has no ``pinocchio.casadi``, so the recursive Newton-Euler algorithm is written
here once, over the joint placements, axes and inertias of the pinocchio model (nothing is
copied by hand), and tests check it against ``pinocchio.rnea`` to 1e-9 N m.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .model import RobotModel

_AXES = {'X': np.array([1.0, 0.0, 0.0]), 'Y': np.array([0.0, 1.0, 0.0]),
         'Z': np.array([0.0, 0.0, 1.0])}


def _joint_axis(joint) -> np.ndarray:
    name = joint.shortname()
    if name.startswith('JointModelR') and name[-1] in _AXES and len(name) == 12:
        return _AXES[name[-1]]
    if name == 'JointModelRevoluteUnaligned':
        return np.asarray(joint.extract().axis, float)
    raise NotImplementedError(f'joint type {name} is not a revolute joint')


def _rot(axis: np.ndarray, angle):
    """Rotation matrix about a unit ``axis`` by a symbolic ``angle`` (Rodrigues)."""
    K = ca.DM([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return ca.DM.eye(3) + ca.sin(angle) * K + (1 - ca.cos(angle)) * ca.mtimes(K, K)


def rnea_expression(model: RobotModel, q, qd, qdd):
    """tau = M(q) qdd + C(q, qd) qd + g(q) as a CasADi column (n,) of symbols q, qd, qdd."""
    m = model.model
    n = m.nq
    gravity = np.asarray(m.gravity.linear, float)
    R, p, z, inert = [], [], [], []
    for i in range(1, n + 1):
        placement = m.jointPlacements[i]
        axis = _joint_axis(m.joints[i])
        R.append(ca.mtimes(ca.DM(placement.rotation), _rot(axis, q[i - 1])))
        p.append(ca.DM(placement.translation))
        z.append(ca.DM(axis))
        inert.append(m.inertias[i])
    # forward recursion: velocities and accelerations in each joint frame
    w = ca.DM.zeros(3)
    dw = ca.DM.zeros(3)
    a = ca.DM(-gravity)           # base acceleration -g carries gravity into every link
    forces, moments = [], []
    for i in range(n):
        Rt = R[i].T
        a = ca.mtimes(Rt, a + ca.cross(dw, p[i]) + ca.cross(w, ca.cross(w, p[i])))
        w_parent = ca.mtimes(Rt, w)
        w = w_parent + z[i] * qd[i]
        dw = ca.mtimes(Rt, dw) + z[i] * qdd[i] + ca.cross(w_parent, z[i] * qd[i])
        c = ca.DM(np.asarray(inert[i].lever, float))
        Ic = ca.DM(np.asarray(inert[i].inertia, float))
        ac = a + ca.cross(dw, c) + ca.cross(w, ca.cross(w, c))
        F = inert[i].mass * ac
        forces.append(F)
        moments.append(ca.mtimes(Ic, dw) + ca.cross(w, ca.mtimes(Ic, w)) + ca.cross(c, F))
    # backward recursion: joint torques
    tau = [None] * n
    f_child = ca.DM.zeros(3)
    n_child = ca.DM.zeros(3)
    for i in reversed(range(n)):
        if i + 1 < n:
            f_in = ca.mtimes(R[i + 1], f_child)
            n_in = ca.mtimes(R[i + 1], n_child) + ca.cross(p[i + 1], f_in)
        else:
            f_in = ca.DM.zeros(3)
            n_in = ca.DM.zeros(3)
        f_child = forces[i] + f_in
        n_child = moments[i] + n_in
        tau[i] = ca.dot(z[i], n_child)
    return ca.vertcat(*tau)


def rnea_function(model: RobotModel) -> ca.Function:
    """CasADi Function ``rnea(q, qd, qdd) -> tau`` (all (n,), SI units), SX graph."""
    n = model.nq
    q, qd, qdd = ca.SX.sym('q', n), ca.SX.sym('qd', n), ca.SX.sym('qdd', n)
    return ca.Function('rnea', [q, qd, qdd], [rnea_expression(model, q, qd, qdd)],
                       ['q', 'qd', 'qdd'], ['tau'])

