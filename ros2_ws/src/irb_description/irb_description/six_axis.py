"""The IRB 1600 with all six joints: forward and closed-form inverse kinematics (no ROS).

Geometry from config/kinematics.yaml (the URDF joint origins of ROS-Industrial's
abb_irb1600_support irb1600_6_12): every frame is parallel to base_link at q = 0; joint 1
about z, joints 2 and 3 about y (positive tilts the arm forward / the forearm down), joints 4
and 6 about the forearm (x), joint 5 about y; axes 4, 5, 6 meet in the wrist centre (the
origin of joint 5), tool0 is link_6 turned by +90 deg about y (its z out of the flange).

``SixAxisKinematics.fk`` is a numpy product of the joint transforms (vectorised over poses);
``ik`` enumerates the closed-form solutions of an ortho-parallel arm with a spherical wrist
(shoulder front/back x elbow up/down x wrist noflip/flip), with the joint limits applied and
the two singularities handled explicitly:

* wrist (|sin q5| < ``wrist_tol``): only q4 + q6 is defined; q4 is kept at the reference
  (the seed's q4, else 0), q5 and q6 are solved exactly for it, ``wrist_singular`` is set;
* shoulder (wrist centre within ``shoulder_tol`` of axis 1): q1 is the reference (the seed's
  q1, else 0), ``shoulder_singular`` is set.

Configuration flags are functions of q (``configuration``), so they also name the branch of
any measured joint vector: shoulder 'front' when the wrist centre is ahead of axis 1 in the
arm's plane, elbow 'up' when the elbow is on the + branch of the law of cosines (q3 in
[-90, 90] deg on this arm, the thesis's branch), wrist 'noflip' when sin q5 >= 0.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from .params import Kinematics, load_kinematics

SHOULDERS = ('front', 'back')
ELBOWS = ('up', 'down')
WRISTS = ('noflip', 'flip')
#: the eight configurations, (shoulder, elbow, wrist)
CONFIGURATIONS = tuple(itertools.product(SHOULDERS, ELBOWS, WRISTS))
TWO_PI = 2.0 * np.pi


class UnreachablePoseError(ValueError):
    """A pose has no inverse-kinematics solution (outside the workspace or the joint limits)."""


def rot_x(a):
    """Rotation matrices about x, (..., 3, 3) for angles a (...)."""
    a = np.asarray(a, float)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1),
                     np.stack([z, s, c], -1)], -2)


def rot_y(a):
    """Rotation matrices about y, (..., 3, 3)."""
    a = np.asarray(a, float)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1),
                     np.stack([-s, z, c], -1)], -2)


def rot_z(a):
    """Rotation matrices about z, (..., 3, 3)."""
    a = np.asarray(a, float)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1),
                     np.stack([z, z, o], -1)], -2)


def rpy_matrix(rpy) -> np.ndarray:
    """URDF rpy (fixed x, then y, then z) -> R = Rz(y) Ry(p) Rx(r), (3, 3)."""
    r, p, y = np.asarray(rpy, float)
    return rot_z(y) @ rot_y(p) @ rot_x(r)


def pose(R, p) -> np.ndarray:
    """Homogeneous transform(s) (..., 4, 4) from R (..., 3, 3) and p (..., 3)."""
    R, p = np.asarray(R, float), np.asarray(p, float)
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def inv_pose(T) -> np.ndarray:
    """Inverse of homogeneous transform(s) (..., 4, 4)."""
    T = np.asarray(T, float)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    return pose(Rt, -(Rt @ T[..., :3, 3, None])[..., 0])


def rotation_error(R_a, R_b) -> np.ndarray:
    """Angle [rad] of R_a^T R_b, (...,): the orientation error between two rotations,
    accurate for small angles too (atan2 of the skew part and the trace)."""
    E = np.swapaxes(np.asarray(R_a, float), -1, -2) @ np.asarray(R_b, float)
    w = np.stack([E[..., 2, 1] - E[..., 1, 2], E[..., 0, 2] - E[..., 2, 0],
                  E[..., 1, 0] - E[..., 0, 1]], -1)
    tr = E[..., 0, 0] + E[..., 1, 1] + E[..., 2, 2]
    return np.arctan2(0.5 * np.linalg.norm(w, axis=-1), 0.5 * (tr - 1.0))


@dataclass(frozen=True)
class IKSolution:
    """One inverse-kinematics solution: q (6,) [rad] and its configuration.

    ``within_limits``: every joint inside its position limits (``q`` is then the
    representative inside the limits, 2 pi shifts of q1, q3, q4, q6 considered);
    ``wrist_singular`` / ``shoulder_singular`` / ``elbow_singular``: the pose was within the
    tolerance of that singularity and the defined choice of the module doc was applied.
    """

    q: np.ndarray
    shoulder: str
    elbow: str
    wrist: str
    within_limits: bool = True
    wrist_singular: bool = False
    shoulder_singular: bool = False
    elbow_singular: bool = False

    @property
    def configuration(self) -> tuple[str, str, str]:
        return (self.shoulder, self.elbow, self.wrist)


@dataclass(frozen=True)
class ConfigIK:
    """``SixAxisKinematics.ik_config`` for N poses: q (N, 6) [rad] (NaN where ``reachable`` is
    False) and the per-pose flags (N,) of the one configuration asked for."""

    q: np.ndarray
    reachable: np.ndarray
    within_limits: np.ndarray
    wrist_singular: np.ndarray
    shoulder_singular: np.ndarray
    elbow_singular: np.ndarray
    configuration: tuple[str, str, str] = field(default=('front', 'up', 'noflip'))


class SixAxisKinematics:
    """Forward and closed-form inverse kinematics of the six-joint arm.

    ``tcp`` (4, 4): the tool centre point in tool0 (default identity: the TCP is tool0);
    ``fk`` and ``ik`` then speak of the TCP. Tolerances: ``wrist_tol`` on |sin q5|,
    ``shoulder_tol`` [m] on the wrist centre's distance from axis 1, ``elbow_tol`` on the
    law-of-cosines argument's distance from +-1 (the stretched or folded arm).
    """

    def __init__(self, kinematics: Kinematics | None = None, tcp=None,
                 wrist_tol: float = 1e-9, shoulder_tol: float = 1e-9,
                 elbow_tol: float = 1e-12):
        k = kinematics or load_kinematics()
        self.kinematics = k
        self.joint_names = k.joint_names
        self.lower, self.upper = k.lower.copy(), k.upper.copy()
        self.velocity = k.velocity.copy()
        self.tcp = np.eye(4) if tcp is None else np.asarray(tcp, float).copy()
        if self.tcp.shape != (4, 4) or not np.all(np.isfinite(self.tcp)):
            raise ValueError('tcp must be a finite (4, 4) homogeneous transform')
        self._tcp_inv = inv_pose(self.tcp)
        self.wrist_tol, self.shoulder_tol, self.elbow_tol = wrist_tol, shoulder_tol, elbow_tol
        axes = [tuple(np.round(j.axis, 12)) for j in k.joints]
        if axes != [(0, 0, 1), (0, 1, 0), (0, 1, 0), (1, 0, 0), (0, 1, 0), (1, 0, 0)]:
            raise ValueError(f'joint axes {axes} are not z, y, y, x, y, x: this closed-form '
                             'inverse kinematics does not apply')
        o = [j.xyz for j in k.joints]
        lateral = [o[1][1], o[2][1], o[3][1], o[4][1], o[4][2], o[5][1], o[5][2]]
        if np.max(np.abs(lateral)) > 1e-12 or np.linalg.norm(o[0]) > 1e-12:
            raise ValueError('the arm has lateral offsets or a base offset: not an '
                             'ortho-parallel arm with a spherical wrist')
        self._origins = [np.asarray(v, float) for v in o]
        self._tool0 = pose(rpy_matrix(k.tool0_rpy), k.tool0_xyz)   # tool0 in link_6
        self._tool0_inv = inv_pose(self._tool0)
        self._shoulder = np.array([o[1][0], o[1][2]])               # joint 2 (radial, up)
        self._u = np.array([o[2][0], o[2][2]])                      # joint 2 -> 3 at q = 0
        self._f = np.array([o[3][0] + o[4][0], o[3][2]])            # joint 3 -> wrist centre
        self._d6 = float(o[5][0])                                   # wrist centre -> link_6
        u, f = self._u, self._f
        self._A = float(u @ f)
        self._B = float(u[0] * f[1] - u[1] * f[0])
        self._K = float(np.hypot(self._A, self._B))
        self._phi = float(np.arctan2(self._B, self._A))

    # --- forward kinematics -----------------------------------------------------------
    def link_poses(self, q) -> list[np.ndarray]:
        """Poses (N, 4, 4) of link_1 ... link_6 in base_link for q (N, 6) (or (6,))."""
        q = np.atleast_2d(np.asarray(q, float))
        rots = (rot_z, rot_y, rot_y, rot_x, rot_y, rot_x)
        T = np.broadcast_to(np.eye(4), (q.shape[0], 4, 4))
        out = []
        for i in range(6):
            T = T @ pose(rots[i](q[:, i]), np.broadcast_to(self._origins[i], (q.shape[0], 3)))
            out.append(T)
        return out

    def fk_tool0(self, q) -> np.ndarray:
        """Pose of tool0 (4, 4) for q (6,), or (N, 4, 4) for q (N, 6)."""
        q = np.asarray(q, float)
        T = self.link_poses(q)[-1] @ self._tool0
        return T[0] if q.ndim == 1 else T

    def fk(self, q) -> np.ndarray:
        """Pose of the TCP (4, 4) for q (6,), or (N, 4, 4) for q (N, 6)."""
        return self.fk_tool0(q) @ self.tcp

    def wrist_centre(self, q) -> np.ndarray:
        """Wrist centre (origin of joint 5) (3,) or (N, 3) [m]."""
        q = np.asarray(q, float)
        p = self.link_poses(q)[4][:, :3, 3]
        return p[0] if q.ndim == 1 else p

    # --- configuration of a joint vector ----------------------------------------------
    def configuration(self, q) -> tuple[str, str, str]:
        """(shoulder, elbow, wrist) of a joint vector q (6,) (module doc)."""
        q = np.asarray(q, float)
        wc = self.wrist_centre(q)
        radial = np.cos(q[0]) * wc[0] + np.sin(q[0]) * wc[1]
        shoulder = 'front' if radial >= 0.0 else 'back'
        elbow = 'up' if np.sin(q[2] - self._phi) >= 0.0 else 'down'
        wrist = 'noflip' if np.sin(q[4]) >= 0.0 else 'flip'
        return shoulder, elbow, wrist

    # --- inverse kinematics -----------------------------------------------------------
    def _check_poses(self, T) -> np.ndarray:
        T = np.asarray(T, float)
        single = T.ndim == 2
        T = T[None] if single else T
        if T.shape[-2:] != (4, 4) or not np.all(np.isfinite(T)):
            raise UnreachablePoseError('pose must be finite (4, 4) homogeneous transform(s)')
        R = T[:, :3, :3]
        err = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(axis=(1, 2))
        if np.any(err > 1e-6) or np.any(np.linalg.det(R) < 0):
            j = int(np.argmax(err))
            raise UnreachablePoseError(f'pose {j}: the rotation part is not a rotation '
                                       f'(|R^T R - I| = {err[j]:.2e})')
        return T

    def ik_config(self, T, configuration=('front', 'up', 'noflip'), q_ref=None,
                  check_limits: bool = True) -> ConfigIK:
        """Closed-form IK of one configuration for poses T (N, 4, 4) (or (4, 4)) of the TCP.

        q_ref (6,) or (N, 6): reference for the singular choices and for the 2 pi
        representative of q1, q3, q4, q6 (nearest to it inside the limits; without q_ref the
        one nearest 0). Unreachable poses give NaN rows and ``reachable`` False; with
        ``check_limits`` a reachable pose with no representative inside the limits has
        ``within_limits`` False (its q then the canonical angles in (-pi, pi]).
        """
        shoulder, elbow, wrist = configuration
        if shoulder not in SHOULDERS or elbow not in ELBOWS or wrist not in WRISTS:
            raise ValueError(f'configuration must be (shoulder in {SHOULDERS}, elbow in '
                             f'{ELBOWS}, wrist in {WRISTS}), got {configuration!r}')
        T = self._check_poses(T)
        n = T.shape[0]
        ref = (np.zeros((n, 6)) if q_ref is None
               else np.broadcast_to(np.asarray(q_ref, float), (n, 6)))
        signs = np.array([[1.0 if shoulder == 'front' else -1.0,
                           1.0 if elbow == 'up' else -1.0,
                           1.0 if wrist == 'noflip' else -1.0]])
        q, reach, inside, wr, sh, el = self._solve(T, np.repeat(signs, n, axis=0), ref)
        within = reach & (inside if check_limits else True)
        return ConfigIK(q, reach, within, wr, sh, el, (shoulder, elbow, wrist))

    def _solve(self, T, signs, ref):
        """Vectorised core: TCP poses T (N, 4, 4), signs (N, 3) of (shoulder front, elbow up,
        wrist noflip) as +-1, reference ref (N, 6) -> q (N, 6) and the flags (N,)."""
        T0 = T @ self._tcp_inv                     # tool0
        T6 = T0 @ self._tool0_inv                  # link_6
        R6 = T6[:, :3, :3]
        wc = T6[:, :3, 3] - self._d6 * R6[:, :, 0]
        x, y, z = wc[:, 0], wc[:, 1], wc[:, 2]
        rho = np.hypot(x, y)
        sh_sing = rho < self.shoulder_tol
        back = signs[:, 0] < 0
        q1 = np.where(sh_sing, ref[:, 0], np.arctan2(y, x)) + np.where(back, np.pi, 0.0)
        # arm-plane coordinates (radial, up) of the wrist centre relative to joint 2
        r = np.where(sh_sing, 0.0, signs[:, 0] * rho) - self._shoulder[0]
        s = z - self._shoulder[1]
        u, f = self._u, self._f
        kk = 0.5 * (r**2 + s**2 - u @ u - f @ f) / self._K     # = cos(q3 - phi)
        reachable = np.abs(kk) <= 1.0 + self.elbow_tol
        el_sing = reachable & (np.abs(kk) >= 1.0 - self.elbow_tol)
        q3 = self._phi + signs[:, 1] * np.arccos(np.clip(kk, -1.0, 1.0))
        # q2: R(q2) (u + R(q3) f) = (r, s), rotation about y in the (radial, up) plane
        c3, s3 = np.cos(q3), np.sin(q3)
        v_r = u[0] + f[0] * c3 + f[1] * s3
        v_s = u[1] - f[0] * s3 + f[1] * c3
        q2 = np.arctan2(v_s * r - v_r * s, v_r * r + v_s * s)
        # wrist: R_3^T R_6 = Rx(q4) Ry(q5) Rx(q6)
        R3 = rot_z(q1) @ rot_y(q2 + q3)
        M = np.swapaxes(R3, -1, -2) @ R6
        sb = np.hypot(M[:, 1, 0], M[:, 2, 0])
        flip = signs[:, 2] < 0
        q5 = signs[:, 2] * np.arctan2(sb, M[:, 0, 0])
        q4 = np.arctan2(M[:, 1, 0], -M[:, 2, 0]) + np.where(flip, np.pi, 0.0)
        q6 = np.arctan2(M[:, 0, 1], M[:, 0, 2]) + np.where(flip, np.pi, 0.0)
        wr_sing = reachable & (sb < self.wrist_tol)
        if np.any(wr_sing):
            # keep q4 at the reference; solve Ry(q5) Rx(q6) = Rx(-q4) M exactly for it
            i = np.flatnonzero(wr_sing)
            q4s = ref[i, 3]
            Ms = rot_x(-q4s) @ M[i]
            q4[i] = q4s
            q5[i] = np.arctan2(-Ms[:, 2, 0], Ms[:, 0, 0])
            q6[i] = np.arctan2(-Ms[:, 1, 2], Ms[:, 1, 1])
        q = np.stack([q1, q2, q3, q4, q5, q6], axis=1)
        q = np.where(reachable[:, None], q, np.nan)
        q, inside = self._representative(q, ref)
        return q, reachable, inside & reachable, wr_sing, sh_sing & reachable, el_sing

    def ik_one(self, T, configuration=('front', 'up', 'noflip'), q_ref=None
               ) -> tuple[list[float] | None, bool, bool]:
        """``ik_config`` for one pose in plain floats (no numpy per step: for a control loop).

        Returns (q as 6 floats, within_limits, wrist_singular), or (None, False, False) when
        the pose is out of reach. Same branches, singular choices and 2 pi representatives as
        ``ik_config`` (tested equal); the pose is not checked for being a rotation.
        """
        import math
        sh, el, wr = configuration
        if sh not in SHOULDERS or el not in ELBOWS or wr not in WRISTS:
            raise ValueError(f'not a configuration: {configuration!r}')
        ref = [0.0] * 6 if q_ref is None else [float(v) for v in q_ref]
        M = (np.asarray(T, float) @ self._tcp_inv @ self._tool0_inv).tolist()
        x6, y6, z6 = M[0][0], M[1][0], M[2][0]
        d6 = self._d6
        x, y, z = M[0][3] - d6 * x6, M[1][3] - d6 * y6, M[2][3] - d6 * z6
        rho = math.hypot(x, y)
        sh_sing = rho < self.shoulder_tol
        q1 = ref[0] if sh_sing else math.atan2(y, x)
        sign = 1.0
        if sh == 'back':
            q1 += math.pi
            sign = -1.0
        r = (0.0 if sh_sing else sign * rho) - float(self._shoulder[0])
        s_ = z - float(self._shoulder[1])
        ur, us = float(self._u[0]), float(self._u[1])
        fr, fs = float(self._f[0]), float(self._f[1])
        kk = 0.5 * (r * r + s_ * s_ - ur * ur - us * us - fr * fr - fs * fs) / self._K
        if abs(kk) > 1.0 + self.elbow_tol:
            return None, False, False
        acos = math.acos(max(-1.0, min(1.0, kk)))
        q3 = self._phi + (acos if el == 'up' else -acos)
        c3, s3 = math.cos(q3), math.sin(q3)
        v_r = ur + fr * c3 + fs * s3
        v_s = us - fr * s3 + fs * c3
        q2 = math.atan2(v_s * r - v_r * s_, v_r * r + v_s * s_)
        # M3 = (Rz(q1) Ry(q23))^T R6, element by element
        c1, s1 = math.cos(q1), math.sin(q1)
        c23, s23 = math.cos(q2 + q3), math.sin(q2 + q3)
        R3 = ((c1 * c23, -s1, c1 * s23), (s1 * c23, c1, s1 * s23), (-s23, 0.0, c23))
        W = [[sum(R3[k][i] * M[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
        sb = math.hypot(W[1][0], W[2][0])
        if sb < self.wrist_tol:
            q4 = ref[3]
            c4, s4 = math.cos(q4), math.sin(q4)
            # rows of Rx(-q4) W
            w0 = W[0]
            w1 = [c4 * W[1][j] + s4 * W[2][j] for j in range(3)]
            w2 = [-s4 * W[1][j] + c4 * W[2][j] for j in range(3)]
            q5 = math.atan2(-w2[0], w0[0])
            q6 = math.atan2(-w1[2], w1[1])
        else:
            q5 = math.atan2(sb, W[0][0])
            q4 = math.atan2(W[1][0], -W[2][0])
            q6 = math.atan2(W[0][1], W[0][2])
            if wr == 'flip':
                q5, q4, q6 = -q5, q4 + math.pi, q6 + math.pi
        q = [q1, q2, q3, q4, q5, q6]
        inside = True
        for j in range(6):
            v = (q[j] + math.pi) % TWO_PI - math.pi
            lo, hi = float(self.lower[j]), float(self.upper[j])
            kmin = math.ceil((lo - v) / TWO_PI - 1e-12)
            kmax = math.floor((hi - v) / TWO_PI + 1e-12)
            if kmin <= kmax:
                v += TWO_PI * min(max(round((ref[j] - v) / TWO_PI), kmin), kmax)
            else:
                inside = False
            q[j] = v
        return q, inside, sb < self.wrist_tol

    def _representative(self, q, ref):
        """Shift q1, q3, q4, q6 by multiples of 2 pi to the value inside the limits nearest
        the reference; q2 and q5 (ranges under 2 pi) only wrapped to (-pi, pi]."""
        q = np.array(q)
        q = (q + np.pi) % TWO_PI - np.pi        # canonical (-pi, pi] (NaN stays NaN)
        out = q.copy()
        inside = np.ones(q.shape[0], bool)
        for j in range(6):
            lo, hi = self.lower[j], self.upper[j]
            kmin = np.ceil((lo - q[:, j]) / TWO_PI - 1e-12)
            kmax = np.floor((hi - q[:, j]) / TWO_PI + 1e-12)
            ok = kmin <= kmax
            kbest = np.round((ref[:, j] - q[:, j]) / TWO_PI)
            k = np.clip(kbest, kmin, kmax)
            out[:, j] = np.where(ok, q[:, j] + TWO_PI * np.where(ok, k, 0.0), q[:, j])
            inside &= ok
        return out, inside

    def _all(self, T, q_ref, configurations):
        T = np.asarray(T, float)
        if T.shape != (4, 4):
            raise UnreachablePoseError(f'pose must be (4, 4), got shape {T.shape}')
        T = self._check_poses(T)
        n = len(configurations)
        signs = np.array([[1.0 if c[0] == 'front' else -1.0, 1.0 if c[1] == 'up' else -1.0,
                           1.0 if c[2] == 'noflip' else -1.0] for c in configurations])
        ref = np.zeros((n, 6)) if q_ref is None else np.broadcast_to(
            np.asarray(q_ref, float), (n, 6))
        return self._solve(np.repeat(T, n, axis=0), signs, ref)

    def ik(self, T, q_ref=None, check_limits: bool = True) -> list[IKSolution]:
        """All closed-form solutions (up to 8, one per configuration, in the order of
        ``CONFIGURATIONS``; where two configurations give the same q at a singularity, once)
        for one TCP pose T (4, 4); with ``check_limits`` only those inside the joint limits.
        Empty list: the pose is unreachable (or outside the limits)."""
        q, reach, inside, wr, sh, el = self._all(T, q_ref, CONFIGURATIONS)
        out: list[IKSolution] = []
        for i, cfg in enumerate(CONFIGURATIONS):
            if not reach[i] or (check_limits and not inside[i]):
                continue
            if any(np.abs(s.q - q[i]).max() <= 1e-12 for s in out):
                continue     # at a singularity two configurations give the same q
            out.append(IKSolution(q[i].copy(), *cfg, bool(inside[i]), bool(wr[i]),
                                  bool(sh[i]), bool(el[i])))
        return out

    def ik_nearest(self, T, seed, configuration=None, weights=None) -> IKSolution:
        """The solution nearest ``seed`` (6,) (weighted Euclidean distance in joint space;
        each joint's 2 pi shift nearest the seed inside the limits), optionally only of
        ``configuration``. Raises UnreachablePoseError when there is none."""
        seed = np.asarray(seed, float)
        w = np.ones(6) if weights is None else np.asarray(weights, float)
        cfgs = CONFIGURATIONS if configuration is None else (tuple(configuration),)
        for c in cfgs:
            if c not in CONFIGURATIONS:
                raise ValueError(f'not a configuration: {c!r}')
        q, reach, inside, wr, sh, el = self._all(T, seed, cfgs)
        ok = reach & inside
        if not np.any(ok):
            where = 'in any configuration' if configuration is None else (
                f'in configuration {tuple(configuration)}')
            raise UnreachablePoseError(
                f'pose at {np.round(np.asarray(T)[:3, 3], 4).tolist()} m has no solution '
                f'inside the joint limits {where}')
        d = np.where(ok, np.sum(w * (np.nan_to_num(q) - seed) ** 2, axis=1), np.inf)
        i = int(np.argmin(d))
        return IKSolution(q[i].copy(), *cfgs[i], True, bool(wr[i]), bool(sh[i]), bool(el[i]))

    def within_limits(self, q) -> np.ndarray:
        """True where every joint of q (..., 6) is inside its position limits."""
        q = np.asarray(q, float)
        return np.all((q >= self.lower - 1e-12) & (q <= self.upper + 1e-12), axis=-1)
