"""The IRB 1600 model: pinocchio kinematics and dynamics of the simplified 3-DOF robot.

``RobotModel`` is loaded once (frozen parameters) and keeps its own pinocchio ``Data`` as a
workspace, so one instance must not be shared between threads (use ``copy()``).
Joints 4-6 are locked at 0 (thesis eq. 3.1); the TCP is the flange origin (tool0) in that pose.
Robot equation (eq. 3.10): M(q) qdd + C(q, qd) qd + g(q) + tau_f(qd) = tau. No ROS imports.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from .friction import FrictionMap, nominal_friction_map
from .params import Dynamics, Kinematics, load_dynamics, load_kinematics, urdf_path

TCP_FRAME = 'tool0'
N_ACTUATED = 3


class UnreachableError(ValueError):
    """A Cartesian point has no inverse-kinematics solution inside the joint limits."""


@dataclass(frozen=True)
class Limits:
    """Limits of the actuated joints, each (3,): position [rad], speed [rad/s], torque [N m]."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    torque: np.ndarray


#: rows per call of pinocchio's batched RNEA (``RobotModel.inverse_dynamics_batch``): about
#: 1.5 ms each on this machine
RNEA_CHUNK_ROWS = 2048


def batched_rnea(model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """RNEA of the pinocchio ``model`` for every row of (M, nv) arrays -> (M, nv) [N m]:
    ``rneaInParallel`` on one thread (a model pool copied at the call), in chunks of
    RNEA_CHUNK_ROWS (the call holds the interpreter lock; other threads get it back between
    chunks)."""
    q, qd, qdd = (np.atleast_2d(np.asarray(x, float)) for x in (q, qd, qdd))
    nv = model.nv
    out = np.empty((q.shape[0], nv))
    pool = pin.ModelPool(model, 1)
    for a in range(0, q.shape[0], RNEA_CHUNK_ROWS):
        b = a + RNEA_CHUNK_ROWS
        tau = pin.rneaInParallel(1, pool, *(np.asfortranarray(x[a:b].T)
                                            for x in (q, qd, qdd)))
        out[a:b] = np.asarray(tau).reshape(nv, -1).T
    return out


class RobotModel:
    """Simplified IRB 1600 (3 actuated joints) with full six-joint kinematics available."""

    def __init__(self, kinematics: Kinematics, dynamics: Dynamics, urdf: Path):
        self.kinematics = kinematics
        self.dynamics = dynamics
        self.urdf = Path(urdf)
        self.full = pin.buildModelFromUrdf(str(self.urdf))
        locked = [self.full.getJointId(n) for n in kinematics.joint_names[N_ACTUATED:]]
        self.model = pin.buildReducedModel(self.full, locked, pin.neutral(self.full))
        self.data = self.model.createData()
        self._full_data = self.full.createData()
        self._tcp = self.model.getFrameId(TCP_FRAME)
        self.joint_names = list(kinematics.joint_names[:N_ACTUATED])
        n = N_ACTUATED
        self.limits = Limits(kinematics.lower[:n].copy(), kinematics.upper[:n].copy(),
                             kinematics.velocity[:n].copy(), dynamics.torque_limit[:n].copy())
        self.friction: FrictionMap = nominal_friction_map(dynamics.friction, self.joint_names)
        # Geometry of the arm plane used by the closed-form IK (from the URDF joint origins).
        j2, j3 = kinematics.joints[1].xyz, kinematics.joints[2].xyz
        self._shoulder = np.array([j2[0], j2[2]])         # joint 2 (radial, height) [m]
        self._a2 = float(np.linalg.norm(j3))              # upper arm, joint 2 -> 3 [m]
        wrist = sum(j.xyz for j in kinematics.joints[3:]) + kinematics.tool0_xyz
        self._l3 = float(np.linalg.norm(wrist))           # joint 3 -> TCP [m]

    @classmethod
    def load(cls) -> 'RobotModel':
        """The model from irb_description's config/ and urdf/ (installed or source tree)."""
        return cls(load_kinematics(), load_dynamics(), urdf_path())

    def copy(self) -> 'RobotModel':
        """Independent instance (own workspace) for another thread."""
        return RobotModel(self.kinematics, self.dynamics, self.urdf)

    @property
    def nq(self) -> int:
        return self.model.nq

    # --- kinematics --------------------------------------------------------------------
    def fk(self, q: np.ndarray) -> np.ndarray:
        """TCP position (3,) [m] in base_link for joint angles q (3,) [rad]."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, float))
        return self.data.oMf[self._tcp].translation.copy()

    def fk_full(self, q6: np.ndarray) -> np.ndarray:
        """Pose (4, 4) of tool0 in base_link for all six joints q6 (6,) [rad]."""
        pin.framesForwardKinematics(self.full, self._full_data, np.asarray(q6, float))
        return self._full_data.oMf[self.full.getFrameId(TCP_FRAME)].homogeneous.copy()

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Linear TCP Jacobian (3, 3) [m/rad], d p / d q, in base_link axes."""
        q = np.asarray(q, float)
        J = pin.computeFrameJacobian(self.model, self.data, q, self._tcp,
                                     pin.LOCAL_WORLD_ALIGNED)
        return J[:3, :].copy()

    def tcp_drift(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """dJ/dt qd (3,) [m/s^2]: TCP acceleration at joint speeds qd with zero qdd."""
        q, qd = np.asarray(q, float), np.asarray(qd, float)
        pin.forwardKinematics(self.model, self.data, q, qd, np.zeros(self.nq))
        acc = pin.getFrameClassicalAcceleration(self.model, self.data, self._tcp,
                                                pin.LOCAL_WORLD_ALIGNED)
        return acc.linear.copy()

    def ik(self, p: np.ndarray, branch: str = 'elbow_up', check_limits: bool = True
           ) -> np.ndarray:
        """Joint angles (3,) [rad] placing the TCP at p (3,) [m] (thesis §3.2).

        q1 = atan2(y, x) (eq. 3.7); q3 from the law of cosines in the arm plane; q2 from the
        resulting triangle. ``branch`` 'elbow_up' (the thesis's, q3 in [-pi/2, pi/2]) or
        'elbow_down'. Raises UnreachableError outside the workspace or the joint limits.
        """
        p = np.asarray(p, float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise UnreachableError(f'point must be 3 finite numbers, got {p!r}')
        return self.ik_many(p[None, :], branch, check_limits)[0]

    def ik_many(self, p: np.ndarray, branch: str = 'elbow_up', check_limits: bool = True
                ) -> np.ndarray:
        """``ik`` for points p (M, 3) [m] at once -> q (M, 3) [rad]; UnreachableError naming
        the first point that has no solution (or needs a joint outside its limits)."""
        p = np.atleast_2d(np.asarray(p, float))
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        q1 = np.arctan2(y, x)
        r = np.hypot(x, y) - self._shoulder[0]
        s = z - self._shoulder[1]
        a2, l3 = self._a2, self._l3
        k = (a2**2 + l3**2 - r**2 - s**2) / (2.0 * a2 * l3)   # = sin(q3)
        out = ~(np.abs(k) <= 1.0)
        if np.any(out):
            j = int(np.argmax(out))
            raise UnreachableError(
                f'point {p[j].tolist()} is {np.hypot(r[j], s[j]):.4f} m from joint 2, outside '
                f'[{abs(a2 - l3):.4f}, {a2 + l3:.4f}] m')
        if branch == 'elbow_up':
            q3 = np.arcsin(k)
        elif branch == 'elbow_down':
            q3 = -np.pi - np.arcsin(k)
        else:
            raise ValueError(f"branch must be 'elbow_up' or 'elbow_down', not {branch!r}")
        A = a2 - l3 * np.sin(q3)
        B = l3 * np.cos(q3)
        q2 = np.arctan2(A * r - B * s, B * r + A * s)
        q = np.stack([q1, q2, q3], axis=1)
        if check_limits:
            bad = (q < self.limits.lower - 1e-12) | (q > self.limits.upper + 1e-12)
            if np.any(bad):
                j = int(np.argmax(bad.any(axis=1)))
                names = [n for n, b in zip(self.joint_names, bad[j]) if b]
                raise UnreachableError(
                    f'point {p[j].tolist()} needs {names} outside their limits '
                    f'(q = {np.degrees(q[j]).round(2).tolist()} deg)')
        return q

    def arm_derivatives(self, q: np.ndarray, p1: np.ndarray, p2: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Joint derivatives along a TCP curve, closed form (vectorised, no pinocchio).

        q (M, 3) [rad] on the curve, p1 = dp/ds, p2 = d2p/ds2 (M, 3) of the TCP; returns
        dq/ds, d2q/ds2 (M, 3): q1 from the cylindrical coordinates of p (q1 = atan2(y, x)),
        q2, q3 from the arm plane, where (rho - shoulder_r, z - shoulder_z) =
        (a2 sin q2 + l3 cos(q2 + q3), a2 cos q2 - l3 sin(q2 + q3)) (the closed-form IK
        inverted; equal to J^-1 p' and J^-1 (p'' - J' q') of pinocchio's Jacobian, tested).
        Singular where rho = 0 (on the base axis) or cos q3 = 0 (arm stretched or folded).
        """
        q, p1, p2 = (np.atleast_2d(np.asarray(v, float)) for v in (q, p1, p2))
        q1, q2, q3 = q[:, 0], q[:, 1], q[:, 2]
        a2, l3 = self._a2, self._l3
        rho = a2 * np.sin(q2) + l3 * np.cos(q2 + q3) + self._shoulder[0]
        x, y = rho * np.cos(q1), rho * np.sin(q1)
        xd, yd, zd = p1[:, 0], p1[:, 1], p1[:, 2]
        xdd, ydd, zdd = p2[:, 0], p2[:, 1], p2[:, 2]
        u = x * xd + y * yd
        rho_d = u / rho
        rho_dd = (xd**2 + yd**2 + x * xdd + y * ydd - rho_d**2) / rho
        w = x * yd - y * xd
        q1_d = w / rho**2
        q1_dd = (x * ydd - y * xdd) / rho**2 - 2.0 * q1_d * rho_d / rho
        S, C = np.sin(q2 + q3), np.cos(q2 + q3)
        # planar Jacobian d(r, s)/d(q2, q3) and its inverse (det = -a2 l3 cos q3)
        j11, j12 = a2 * np.cos(q2) - l3 * S, -l3 * S
        j21, j22 = -a2 * np.sin(q2) - l3 * C, -l3 * C
        det = j11 * j22 - j12 * j21

        def solve(br, bs):
            return (j22 * br - j12 * bs) / det, (-j21 * br + j11 * bs) / det
        q2_d, q3_d = solve(rho_d, zd)
        q23_d = q2_d + q3_d
        dr = -a2 * np.sin(q2) * q2_d**2 - l3 * C * q23_d**2
        ds = -a2 * np.cos(q2) * q2_d**2 + l3 * S * q23_d**2
        q2_dd, q3_dd = solve(rho_dd - dr, zdd - ds)
        return (np.stack([q1_d, q2_d, q3_d], axis=1),
                np.stack([q1_dd, q2_dd, q3_dd], axis=1))

    # --- dynamics (no friction; see .friction) ------------------------------------------
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q) (3, 3) [kg m^2]."""
        M = pin.crba(self.model, self.data, np.asarray(q, float))
        return np.triu(M) + np.triu(M, 1).T

    def coriolis(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """C(q, qd) qd (3,) [N m]."""
        q, qd = np.asarray(q, float), np.asarray(qd, float)
        return (pin.nonLinearEffects(self.model, self.data, q, qd)
                - pin.computeGeneralizedGravity(self.model, self.data, q))

    def coriolis_matrix(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """C(q, qd) (3, 3) [N m s/rad] (pinocchio's Christoffel-consistent choice)."""
        return pin.computeCoriolisMatrix(self.model, self.data, np.asarray(q, float),
                                         np.asarray(qd, float)).copy()

    def gravity(self, q: np.ndarray) -> np.ndarray:
        """g(q) (3,) [N m]."""
        return pin.computeGeneralizedGravity(self.model, self.data, np.asarray(q, float)).copy()

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """M qdd + C qd + g (3,) [N m] by RNEA, without friction."""
        return pin.rnea(self.model, self.data, np.asarray(q, float), np.asarray(qd, float),
                        np.asarray(qdd, float)).copy()

    def inverse_dynamics_batch(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
                               ) -> np.ndarray:
        """``inverse_dynamics`` of every row of (M, n) arrays -> (M, n) [N m], equal to it row
        by row: pinocchio's batched RNEA (``rneaInParallel`` on one thread, a model pool copied
        from this model at the call), about 4 times faster than a Python loop over rows. In
        chunks of RNEA_CHUNK_ROWS (a few milliseconds each): the call holds the interpreter
        lock, and a node's other threads get it back between chunks."""
        return batched_rnea(self.model, q, qd, qdd)

    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """qdd (3,) [rad/s^2] = M^-1 (tau - C qd - g) by ABA, tau without friction."""
        return pin.aba(self.model, self.data, np.asarray(q, float), np.asarray(qd, float),
                       np.asarray(tau, float)).copy()

    def inverse_dynamics_with_friction(self, q, qd, qdd, friction: FrictionMap | None = None
                                       ) -> np.ndarray:
        """tau (3,) [N m] of eq. 3.10 with the nominal (or given) friction map."""
        fm = friction or self.friction
        return self.inverse_dynamics(q, qd, qdd) + fm.torque(np.asarray(qd, float))
