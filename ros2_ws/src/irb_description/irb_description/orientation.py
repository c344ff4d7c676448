"""Tool-orientation laws along paths, and the six joint angles along a path (no ROS).

A law gives the tool's rotation R(theta) (N, 3, 3) in base_link at the path parameter theta
of ``path.PathBase`` (theta in [0, 2 pi], proportional to arc length); with the path's point
it makes the TCP pose T(theta) (``tool_poses``). Laws:

* ``FixedOrientation``: one rotation all along (e.g. the tool pointing down);
* ``PathFrame``: a frame tied to the path: tool z along the plane's normal (``approach``
  'against': z = -n, the nozzle pointing into the surface whose normal n faces the robot),
  tool x along the path's tangent (``x_mode`` 'tangent') or a fixed direction projected into
  the plane (``x_mode`` 'fixed': the tool does not spin about its own axis);
* ``KeyframeSlerp``: spherical-linear interpolation between rotations at given theta
  (scipy's ``Slerp``), constant before the first and after the last keyframe. ``easing``
  'smooth' (the default) runs each segment's slerp fraction along the quintic smootherstep
  6u^5 - 15u^4 + 10u^3 of theta: the rotation's rate and its derivative are zero at every
  keyframe, so the joints' path is twice differentiable there and a jerk-limited motion passes
  a keyframe at speed; 'linear' is plain slerp (constant rate between keyframes, a step of
  the rate at each inner keyframe: the joints' speeds would step at a path speed > 0).

``joint_path6`` solves the closed-form IK (``six_axis``) at every sample in one
configuration, keeps the joints continuous (2 pi shifts of q1, q3, q4, q6 chosen sample to
sample; at the wrist singularity q4 is kept from the previous sample) and refuses a path that
leaves the workspace, a joint limit or jumps. ``pose_errors`` measures position and
orientation error of joint angles against the wanted poses with the thesis's DH kinematics
(``dh.py``), which shares nothing with ``six_axis``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from .dh import dh_forward
from .path import ArcPath, CirclePath, LinePath, PathBase, PolylinePath, SplinePath
from .six_axis import (CONFIGURATIONS, TWO_PI, SixAxisKinematics, UnreachablePoseError,
                       pose, rotation_error)


def _unit(v, what):
    v = np.asarray(v, float)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if not (np.all(np.isfinite(n)) and np.all(n > 1e-12)):
        raise ValueError(f'{what} must be finite and non-zero')
    return v / n


def frame_from_axes(z, x_hint) -> np.ndarray:
    """Rotation(s) (..., 3, 3) with columns (x, y, z): z the unit of ``z``, x the unit of
    ``x_hint`` projected perpendicular to z, y = z x x. ValueError when x_hint is along z."""
    z = _unit(z, 'tool z axis')
    x_hint = np.broadcast_to(np.asarray(x_hint, float), z.shape)
    x = x_hint - np.sum(x_hint * z, axis=-1, keepdims=True) * z
    x = _unit(x, 'tool x axis (the x hint is parallel to the tool z axis)')
    return np.stack([x, np.cross(z, x), z], axis=-1)


class OrientationLaw:
    """Interface: ``rotation(theta)`` -> (N, 3, 3) for theta (N,) [rad]."""

    def rotation(self, theta) -> np.ndarray:   # pragma: no cover - interface
        raise NotImplementedError


@dataclass(frozen=True)
class FixedOrientation(OrientationLaw):
    """The same tool rotation R (3, 3) at every theta."""

    R: np.ndarray

    def __post_init__(self):
        R = np.asarray(self.R, float)
        if R.shape != (3, 3) or np.abs(R.T @ R - np.eye(3)).max() > 1e-9 or \
                np.linalg.det(R) < 0:
            raise ValueError('FixedOrientation needs a (3, 3) rotation matrix')
        object.__setattr__(self, 'R', R)

    @classmethod
    def from_axes(cls, z, x_hint=(1.0, 0.0, 0.0)) -> 'FixedOrientation':
        """Tool z along ``z``, tool x along ``x_hint`` projected (``frame_from_axes``)."""
        return cls(frame_from_axes(np.asarray(z, float), np.asarray(x_hint, float)))

    def rotation(self, theta) -> np.ndarray:
        theta = np.atleast_1d(np.asarray(theta, float))
        return np.broadcast_to(self.R, theta.shape + (3, 3)).copy()


def path_normal(path: PathBase, normal=None) -> np.ndarray:
    """Unit normal of the plane of ``path``: given, or the circle's (+z) / arc's normal, or
    the plane through a polyline's or spline's waypoints (least squares; ValueError when
    they are collinear or not in one plane within 1e-9 m). Sign: towards +z (base up) or,
    for a vertical plane, as the fit gives it; a line has no plane (give ``normal``)."""
    if normal is not None:
        return _unit(normal, 'normal')
    if isinstance(path, CirclePath):
        return np.array([0.0, 0.0, 1.0])
    if isinstance(path, ArcPath):
        return np.asarray(path.normal, float)
    if isinstance(path, LinePath):
        raise ValueError('a line has no plane: give the normal of the surface')
    if isinstance(path, (PolylinePath, SplinePath)):
        pts = np.asarray(path.waypoints, float)
    else:
        pts = path.point(np.linspace(0.0, TWO_PI, 64))
    c = pts - pts.mean(axis=0)
    _, sv, vt = np.linalg.svd(c)
    if sv[1] <= 1e-9 * max(sv[0], 1e-300):
        raise ValueError('the path is a straight line: give the normal of the surface')
    if sv[2] > 1e-9 * np.sqrt(len(pts)):
        raise ValueError(f'the path is not planar (out-of-plane spread {sv[2]:.2e} m): '
                         'give the normal of the surface')
    n = vt[2]
    return -n if n[2] < 0 else n


@dataclass(frozen=True)
class PathFrame(OrientationLaw):
    """Tool frame tied to ``path``: z = -n ('against', the default) or +n ('along') with n
    the plane's normal (``path_normal``); x along the tangent (``x_mode`` 'tangent') or
    along ``x_ref`` projected into the plane (``x_mode`` 'fixed', default x_ref = base x,
    base y if that is along n)."""

    path: PathBase
    normal: np.ndarray | None = None
    approach: str = 'against'
    x_mode: str = 'tangent'
    x_ref: np.ndarray | None = None

    def __post_init__(self):
        if self.approach not in ('against', 'along'):
            raise ValueError(f"approach must be 'against' or 'along', not {self.approach!r}")
        if self.x_mode not in ('tangent', 'fixed'):
            raise ValueError(f"x_mode must be 'tangent' or 'fixed', not {self.x_mode!r}")
        n = path_normal(self.path, self.normal)
        z = -n if self.approach == 'against' else n
        object.__setattr__(self, '_z', z)
        if self.x_mode == 'fixed':
            ref = self.x_ref
            if ref is None:
                ref = (1.0, 0.0, 0.0) if abs(n[0]) < 0.9 else (0.0, 1.0, 0.0)
            object.__setattr__(self, '_R_fixed', frame_from_axes(z, ref))

    @property
    def tool_z(self) -> np.ndarray:
        return self._z.copy()

    def rotation(self, theta) -> np.ndarray:
        theta = np.atleast_1d(np.asarray(theta, float))
        if self.x_mode == 'fixed':
            return np.broadcast_to(self._R_fixed, theta.shape + (3, 3)).copy()
        t = self.path.d_point(theta)
        return frame_from_axes(np.broadcast_to(self._z, t.shape), t)


EASINGS = ('smooth', 'linear')


class KeyframeSlerp(OrientationLaw):
    """Slerp between rotations ``rotations`` (K, 3, 3) at increasing ``thetas`` (K,) [rad]
    (K >= 2); the first / last rotation before / after the keyframes; ``easing`` (module
    docstring) 'smooth' or 'linear'."""

    def __init__(self, thetas, rotations, easing: str = 'smooth'):
        if easing not in EASINGS:
            raise ValueError(f'easing must be one of {list(EASINGS)}, got {easing!r}')
        self.easing = easing
        th = np.asarray(thetas, float)
        R = np.asarray(rotations, float)
        if th.ndim != 1 or th.size < 2 or np.any(np.diff(th) <= 0) or \
                not np.all(np.isfinite(th)):
            raise ValueError('keyframe thetas must be >= 2 finite increasing values')
        if R.shape != (th.size, 3, 3):
            raise ValueError(f'rotations must be ({th.size}, 3, 3), got {R.shape}')
        self.thetas, self.rotations = th, R
        self._slerp = Slerp(th, Rotation.from_matrix(R))

    def rotation(self, theta) -> np.ndarray:
        th = np.clip(np.atleast_1d(np.asarray(theta, float)), self.thetas[0], self.thetas[-1])
        if self.easing == 'smooth':
            k = np.clip(np.searchsorted(self.thetas, th, side='right') - 1, 0,
                        self.thetas.size - 2)
            lo, span = self.thetas[k], np.diff(self.thetas)[k]
            u = (th - lo) / span
            th = np.clip(lo + span * u ** 3 * (10.0 + u * (-15.0 + 6.0 * u)),
                         self.thetas[0], self.thetas[-1])          # round-off at the ends
        return self._slerp(th).as_matrix()

    @property
    def inner_keyframes(self) -> np.ndarray:
        """The keyframes' theta strictly inside (0, 2 pi) [rad]."""
        return self.thetas[(self.thetas > 0.0) & (self.thetas < 2 * np.pi)]


#: key of a path mapping's optional orientation block (``orientation_from_spec``)
ORIENTATION_KEY = 'orientation'
LAWS = ('fixed', 'path_normal', 'slerp')


def _rotation_spec(entry, what) -> np.ndarray:
    """A rotation from {rpy: [r, p, y]} (URDF fixed-axis, rad) or {z: [..], x: [..]}."""
    from .six_axis import rpy_matrix
    if not isinstance(entry, dict):
        raise ValueError(f'{what}: a mapping with rpy [rad] or z and x (tool axes in base_link)')
    if 'rpy' in entry and set(entry) <= {'rpy', 'theta'}:
        rpy = np.asarray(entry['rpy'], float)
        if rpy.shape != (3,) or not np.all(np.isfinite(rpy)):
            raise ValueError(f'{what}: rpy must be 3 finite numbers [rad]')
        return rpy_matrix(rpy)
    if 'z' in entry and set(entry) <= {'z', 'x', 'theta'}:
        return frame_from_axes(np.asarray(entry['z'], float),
                               np.asarray(entry.get('x', [1.0, 0.0, 0.0]), float))
    raise ValueError(f'{what}: give rpy [rad] or z (and x), got keys {sorted(entry)}')


def orientation_from_spec(spec: dict, path: PathBase) -> OrientationLaw:
    """A law from a plain mapping (a path file's ``orientation`` block):

    law 'fixed': rpy [rad] (URDF convention, R = Rz Ry Rx) or z (and x) tool axes;
    'path_normal': normal (optional), approach ('against'), x_mode ('tangent'), x_ref;
    'slerp': keyframes [{theta [rad], rpy or z/x}, ...] (theta increasing, >= 2), easing
    ('smooth', the default, or 'linear': ``KeyframeSlerp``).
    ValueError with one line naming what is wrong.
    """
    if not isinstance(spec, dict):
        raise ValueError('an orientation spec must be a mapping with a "law"')
    law = spec.get('law')
    known = {'fixed': {'rpy', 'z', 'x'}, 'path_normal': {'normal', 'approach', 'x_mode', 'x_ref'},
             'slerp': {'keyframes', 'easing'}}
    if law not in known:
        raise ValueError(f'orientation law must be one of {list(LAWS)}, got {law!r}')
    extra = set(spec) - known[law] - {'law'}
    if extra:
        raise ValueError(f'orientation law {law!r} takes {sorted(known[law])}, '
                         f'not {sorted(extra)}')
    try:
        if law == 'fixed':
            return FixedOrientation(_rotation_spec({k: v for k, v in spec.items()
                                                    if k != 'law'}, 'fixed'))
        if law == 'path_normal':
            def vec(key):
                return None if spec.get(key) is None else np.asarray(spec[key], float)
            return PathFrame(path, vec('normal'), spec.get('approach', 'against'),
                             spec.get('x_mode', 'tangent'), vec('x_ref'))
        frames = spec.get('keyframes')
        if not isinstance(frames, list) or len(frames) < 2:
            raise ValueError('slerp needs keyframes: a list of >= 2 {theta, rpy or z/x}')
        thetas = []
        for i, f in enumerate(frames):
            if not isinstance(f, dict) or 'theta' not in f:
                raise ValueError(f'keyframe {i} needs theta [rad]')
            thetas.append(float(f['theta']))
        return KeyframeSlerp(thetas, [_rotation_spec(f, f'keyframe {i}')
                                      for i, f in enumerate(frames)],
                             spec.get('easing', 'smooth'))
    except (TypeError, ValueError) as exc:
        raise ValueError(f'orientation {law}: {exc}') from None


def tool_poses(path: PathBase, law: OrientationLaw, theta) -> np.ndarray:
    """TCP poses (N, 4, 4) in base_link: the path's point and the law's rotation at theta."""
    theta = np.atleast_1d(np.asarray(theta, float))
    return pose(law.rotation(theta), path.point(theta))


@dataclass(frozen=True)
class JointPath6:
    """The six joints along a path: theta (N,), q (N, 6) [rad], the wanted TCP poses
    T (N, 4, 4), the configuration kept, and where the wrist / shoulder was singular (N,).
    dq, ddq (N, 6): dq/dtheta, d2q/dtheta2 by central differences of the IK (or None)."""

    theta: np.ndarray
    q: np.ndarray
    T: np.ndarray
    configuration: tuple[str, str, str]
    wrist_singular: np.ndarray
    shoulder_singular: np.ndarray
    dq: np.ndarray | None = None
    ddq: np.ndarray | None = None


def _continuous(kin: SixAxisKinematics, q: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Shift q1, q3, q4, q6 by 2 pi per sample to the value nearest the previous sample, the
    first nearest ``start``."""
    q = q.copy()
    for j in (0, 2, 3, 5):
        col = q[:, j]
        col = np.concatenate([[start[j]], col])
        steps = np.diff(col)
        col = start[j] + np.concatenate([[0.0], np.cumsum(steps - TWO_PI * np.round(
            steps / TWO_PI))])
        q[:, j] = col[1:]
    return q


def joint_path6(kin: SixAxisKinematics, path: PathBase, law: OrientationLaw, theta,
                configuration=None, seed=None, max_step: float = np.pi / 4,
                derivatives: bool = False, h: float = 1e-4,
                wrist_switch: bool = False) -> JointPath6:
    """The six joint angles along ``path`` with ``law`` at theta (N,) (increasing).

    ``configuration`` (shoulder, elbow, wrist) kept all along; default: the one of the
    solution nearest ``seed`` at the first sample, or without a seed the first of
    ``six_axis.CONFIGURATIONS`` that solves the whole path. The first sample's 2 pi
    representatives are those nearest ``seed`` (else nearest 0 inside the limits), then each
    sample the one nearest the previous. Raises UnreachablePoseError naming theta and the
    point when a sample is unreachable, a joint leaves its limits or a joint steps by more
    than ``max_step`` [rad] between two samples (a configuration change, e.g. passing the
    wrist singularity with the wrist flag kept). ``wrist_switch``: shoulder and elbow kept,
    the wrist flag chosen sample by sample nearest the previous joints, so a path through
    q5 = 0 stays continuous (``configuration`` then reads (shoulder, elbow, 'switch')).
    ``derivatives``: dq/dtheta and d2q/dtheta2 by central differences of step ``h`` [rad]
    through the same solution.
    """
    theta = np.atleast_1d(np.asarray(theta, float))
    if theta.ndim != 1 or theta.size < 1 or np.any(np.diff(theta) <= 0):
        raise ValueError('theta must be increasing values')
    T = tool_poses(path, law, theta)
    if configuration is not None:
        cfgs = [tuple(configuration)]
    elif seed is not None:
        cfgs = [kin.ik_nearest(T[0], seed).configuration]
    else:
        cfgs = list(CONFIGURATIONS)
    errors = []
    for cfg in cfgs:
        try:
            q, wr, sh = _solve_path(kin, T, theta, cfg, seed, max_step, wrist_switch)
        except UnreachablePoseError as exc:
            errors.append(str(exc))
            continue
        dq = ddq = None
        if derivatives:
            dq, ddq = _derivatives(kin, path, law, theta, q, cfg, h, wrist_switch)
        name = (cfg[0], cfg[1], 'switch') if wrist_switch else cfg
        return JointPath6(theta, q, T, name, wr, sh, dq, ddq)
    raise UnreachablePoseError(errors[0] if len(errors) == 1 else
                               'no configuration solves the whole path: ' + errors[0])


def _other_wrist(cfg):
    return (cfg[0], cfg[1], 'flip' if cfg[2] == 'noflip' else 'noflip')


def _nearest_turn(q, ref):
    """q (N, 6) shifted joint by joint by whole turns to the value nearest ref (N, 6)."""
    return q - TWO_PI * np.round((q - ref) / TWO_PI)


def _pick_wrist(qa, qb, start):
    """Sample by sample the one of two wrist solutions nearest the previous sample."""
    out = np.empty_like(qa)
    prev = start
    for k in range(qa.shape[0]):
        a = _nearest_turn(qa[k], prev)
        b = _nearest_turn(qb[k], prev)
        prev = out[k] = a if np.sum((a - prev) ** 2) <= np.sum((b - prev) ** 2) else b
    return out


def _solve_path(kin, T, theta, cfg, seed, max_step, wrist_switch=False):
    ref = np.zeros(6) if seed is None else np.asarray(seed, float)
    r = kin.ik_config(T, cfg, ref, check_limits=False)
    if not np.all(r.reachable):
        k = int(np.argmin(r.reachable))
        raise UnreachablePoseError(
            f'configuration {cfg}: theta = {theta[k]:.4f} rad, point '
            f'{np.round(T[k, :3, 3], 4).tolist()} m is outside the workspace')
    q = r.q.copy()
    # first sample: the representative nearest the seed inside the limits
    first = kin.ik_config(T[:1], cfg, ref)
    start = first.q[0] if first.within_limits[0] else q[0]
    if wrist_switch:
        q = _pick_wrist(q, kin.ik_config(T, _other_wrist(cfg), ref, check_limits=False).q,
                        start)
    q = _continuous(kin, q, start)
    # wrist singular samples: keep q4 from the previous sample (defined split of q4 + q6)
    for k in np.flatnonzero(r.wrist_singular):
        prev = q[k - 1] if k > 0 else start
        # flip and noflip coincide here: either configuration gives the same joints
        q[k] = kin.ik_config(T[k:k + 1], cfg, prev, check_limits=False).q[0]
    if np.any(r.wrist_singular):
        q = _continuous(kin, q, start)      # the samples after them follow the new q6
    step = np.abs(np.diff(q, axis=0))
    if np.any(step > max_step):
        k, j = np.unravel_index(int(np.argmax(step)), step.shape)
        raise UnreachablePoseError(
            f'configuration {cfg}: {kin.joint_names[j]} jumps by '
            f'{np.degrees(step[k, j]):.1f} deg between theta = {theta[k]:.4f} and '
            f'{theta[k + 1]:.4f} rad near {np.round(T[k, :3, 3], 4).tolist()} m (a singularity '
            'or a configuration change)')
    # limits at the samples and between them: a joint with curvature q'' rises at most
    # |q''| dtheta^2 / 8 above its chord (as path.check_joint_path)
    def envelope(q):
        if q.shape[0] <= 2:
            return q, q
        h = np.diff(theta)[:, None]
        ddq = np.zeros_like(q)
        ddq[1:-1] = 2 * ((q[2:] - q[1:-1]) / h[1:] - (q[1:-1] - q[:-2]) / h[:-1]) / (
            h[1:] + h[:-1])
        bulge = np.maximum(np.abs(ddq[:-1]), np.abs(ddq[1:])) * h**2 / 8
        return (np.vstack([q, np.maximum(q[:-1], q[1:]) + bulge]),
                np.vstack([q, np.minimum(q[:-1], q[1:]) - bulge]))
    hi, lo = envelope(q)
    # the whole path's 2 pi shift of q1, q3, q4, q6 that keeps it inside the limits,
    # nearest the start chosen above
    for j in (0, 2, 3, 5):
        kmin = np.ceil((kin.lower[j] - lo[:, j].min()) / TWO_PI - 1e-12)
        kmax = np.floor((kin.upper[j] - hi[:, j].max()) / TWO_PI + 1e-12)
        if kmin <= kmax:
            shift = TWO_PI * np.clip(np.round((start[j] - q[0, j]) / TWO_PI), kmin, kmax)
            q[:, j] += shift
            hi[:, j] += shift
            lo[:, j] += shift
    out = (hi > kin.upper + 1e-12) | (lo < kin.lower - 1e-12)
    if np.any(out):
        row = int(np.argmax(out.any(axis=1)))
        k = row if row < q.shape[0] else row - q.shape[0]     # a segment: its first sample
        bad = [kin.joint_names[j] for j in np.flatnonzero(out[row])]
        raise UnreachablePoseError(
            f'configuration {cfg}: {bad} outside their limits at or after theta = '
            f'{theta[k]:.4f} rad, point {np.round(T[k, :3, 3], 4).tolist()} m '
            f'(q = {np.degrees(q[k]).round(1).tolist()} deg)')
    return q, r.wrist_singular.copy(), r.shoulder_singular.copy()


def _derivatives(kin, path, law, theta, q, cfg, h, wrist_switch=False):
    """Central differences of the IK at theta +- h, each sample's solution continued from q."""
    def at(th):
        T = tool_poses(path, law, th)
        # nearest 2 pi representative to the centre sample, joint by joint
        qa = _nearest_turn(kin.ik_config(T, cfg, q, check_limits=False).q, q)
        if not wrist_switch:
            return qa
        qb = _nearest_turn(kin.ik_config(T, _other_wrist(cfg), q, check_limits=False).q, q)
        a_near = np.sum((qa - q) ** 2, axis=1) <= np.sum((qb - q) ** 2, axis=1)
        return np.where(a_near[:, None], qa, qb)
    # near the ends the stencil is shifted inside [0, 2 pi] (paths are not evaluated
    # outside it), then carried back to theta to first order
    shift = np.clip(h - theta, 0.0, None) - np.clip(theta + h - TWO_PI, 0.0, None)
    c = theta + shift
    qm, q0, qp = at(c - h), at(c) if np.any(shift) else q, at(c + h)
    dq = (qp - qm) / (2 * h)
    ddq = (qp - 2 * q0 + qm) / h**2
    dq = dq - shift[:, None] * ddq          # first order back to theta at the ends
    return dq, ddq


def pose_errors(kin: SixAxisKinematics, q, T_wanted) -> tuple[np.ndarray, np.ndarray]:
    """Position error [m] and orientation error [rad] (N,) of joint angles q (N, 6) against
    wanted TCP poses (N, 4, 4), through the thesis's DH kinematics (``dh.dh_forward``, which
    shares no code with ``six_axis``) and the TCP offset ``kin.tcp``."""
    k = kin.kinematics
    q = np.atleast_2d(np.asarray(q, float))
    T_wanted = np.asarray(T_wanted, float).reshape(-1, 4, 4)
    T = np.array([dh_forward(qi, k.dh_a, k.dh_alpha, k.dh_d, k.dh_offset) for qi in q])
    T = T @ kin.tcp
    pos = np.linalg.norm(T[:, :3, 3] - T_wanted[:, :3, 3], axis=1)
    ori = rotation_error(T_wanted[:, :3, :3], T[:, :3, :3])
    return pos, ori
