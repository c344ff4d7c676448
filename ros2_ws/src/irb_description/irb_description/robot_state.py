"""Joint states of all six joints and the transforms of every link (a robot_state_publisher in
numpy). No rclpy, no message types.

- ``six_joint_names()`` / ``six_joints(q, qd, tau)``: what /joint_states carries. The thesis's
  model actuates joints 1-3 and locks 4-6 (eq. 3.1); a state of joints 1-3 becomes six
  entries, 4-6 at their locked positions (``LOCKED_POSITION``) with speed and torque 0.
- ``JointStateReader`` / ``TfEncoder``: the state_publisher's 248 Hz path on serialized
  messages (CDR), without message objects: rclpy's conversions of a JointState and a
  six-transform TFMessage cost ~0.6 ms per state on the loaded 2-core machine, these ~0.03 ms.
- ``TfTree``: the URDF's joint tree. ``transforms(positions)`` gives each movable joint's
  parent -> child transform (translation, quaternion x y z w), ``static_transforms()`` the
  fixed joints', ``pose(positions, root, tip)`` a chain's 4x4 pose. Written here (30 lines of
  quaternion algebra over the URDF's joints) rather than with pinocchio: /tf wants each joint's
  parent -> child transform, which pinocchio gives only for its own joint frames, and this is
  faster for 7 joints (``benchmarks/bench_state_publisher.py``).
"""
from __future__ import annotations

import math
import struct
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

# position [rad] of the locked joints 4-6 (thesis eq. 3.1; the model's reduced pinocchio model
# locks them at pinocchio.neutral, 0 for revolute joints)
LOCKED_POSITION = 0.0
N_ACTUATED = 3


@lru_cache(maxsize=1)
def six_joint_names() -> tuple[str, ...]:
    """The names of all joints, in order (joint_1 .. joint_6, from config/kinematics.yaml)."""
    from .params import load_kinematics
    return tuple(load_kinematics().joint_names)


def locked_joint_names() -> tuple[str, ...]:
    """Joints locked in the simplified model (joint_4 .. joint_6)."""
    return six_joint_names()[N_ACTUATED:]


def six_joints(q, qd, tau) -> tuple[list, list, list]:
    """Position, velocity, effort lists of all six joints from those of joints 1-3 (each of
    length 3; a sequence of 6 is taken as it is). Joints 4-6: ``LOCKED_POSITION``, 0, 0."""
    n = len(six_joint_names())
    out = []
    for values, rest in ((q, LOCKED_POSITION), (qd, 0.0), (tau, 0.0)):
        v = [float(x) for x in values]
        if len(v) == N_ACTUATED:
            v += [rest] * (n - N_ACTUATED)
        elif len(v) != n:
            raise ValueError(f'expected {N_ACTUATED} or {n} values, got {len(v)}')
        out.append(v)
    return out[0], out[1], out[2]


# --- the URDF tree ------------------------------------------------------------------------------
MOVABLE = ('revolute', 'continuous', 'prismatic')


@dataclass(frozen=True)
class UrdfJoint:
    name: str
    type: str
    parent: str
    child: str
    xyz: tuple          # origin translation [m]
    quat: tuple         # origin rotation (x, y, z, w) from rpy
    axis: tuple         # unit axis in the child frame


def _floats(text: str | None, default: str) -> tuple:
    return tuple(float(v) for v in (text or default).split())


def quat_from_rpy(r: float, p: float, y: float) -> tuple:
    """URDF rpy (fixed axes x, y, z: R = Rz(y) Ry(p) Rx(r)) -> (x, y, z, w)."""
    cr, sr = math.cos(r / 2), math.sin(r / 2)
    cp, sp = math.cos(p / 2), math.sin(p / 2)
    cy, sy = math.cos(y / 2), math.sin(y / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def quat_mul(a: tuple, b: tuple) -> tuple:
    """Hamilton product a b of (x, y, z, w) quaternions."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def quat_matrix(q: tuple) -> np.ndarray:
    """(3, 3) rotation of a unit (x, y, z, w) quaternion."""
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def parse_urdf(text: str) -> list[UrdfJoint]:
    """The joints of a URDF text (ValueError naming what is wrong)."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ValueError(f'URDF is not valid XML: {exc}') from None
    joints = []
    for j in root.findall('joint'):
        name, kind = j.get('name', ''), j.get('type', '')
        parent, child = j.find('parent'), j.find('child')
        if parent is None or child is None:
            raise ValueError(f'URDF joint {name!r} has no parent or child')
        origin = j.find('origin')
        xyz = _floats(origin.get('xyz') if origin is not None else None, '0 0 0')
        rpy = _floats(origin.get('rpy') if origin is not None else None, '0 0 0')
        axis_el = j.find('axis')
        axis = np.array(_floats(axis_el.get('xyz') if axis_el is not None else None, '1 0 0'))
        if kind in MOVABLE:
            norm = float(np.linalg.norm(axis))
            if not norm > 0:
                raise ValueError(f'URDF joint {name!r} has a zero axis')
            axis = axis / norm
        elif kind != 'fixed':
            raise ValueError(f'URDF joint {name!r}: type {kind!r} not supported')
        joints.append(UrdfJoint(name, kind, parent.get('link'), child.get('link'), xyz,
                                quat_from_rpy(*rpy), tuple(float(a) for a in axis)))
    return joints


class TfTree:
    """The URDF's transforms: one (parent, child, (x, y, z), (qx, qy, qz, qw)) per joint."""

    def __init__(self, urdf_text: str):
        self.joints = parse_urdf(urdf_text)
        self.movable = [j for j in self.joints if j.type in MOVABLE]
        self.fixed = [j for j in self.joints if j.type == 'fixed']
        self.names = [j.name for j in self.movable]
        self._by_child = {j.child: j for j in self.joints}
        self._locked = set(locked_joint_names())

    def static_transforms(self) -> list[tuple]:
        """Transforms of the fixed joints (for /tf_static)."""
        return [(j.parent, j.child, j.xyz, j.quat) for j in self.fixed]

    def transforms(self, positions) -> list[tuple]:
        """Transforms of the movable joints at ``positions`` (in ``self.names`` order) [rad
        or m]."""
        out = []
        for j, q in zip(self.movable, positions):
            if j.type == 'prismatic':
                d = quat_matrix(j.quat) @ (np.array(j.axis) * q)
                out.append((j.parent, j.child, (j.xyz[0] + d[0], j.xyz[1] + d[1],
                                                j.xyz[2] + d[2]), j.quat))
                continue
            s, c = math.sin(0.5 * q), math.cos(0.5 * q)
            ax, ay, az = j.axis
            out.append((j.parent, j.child, j.xyz, quat_mul(j.quat, (ax * s, ay * s, az * s, c))))
        return out

    def pose(self, positions, root: str, tip: str) -> np.ndarray:
        """(4, 4) pose of ``tip`` in ``root`` at ``positions`` (``self.names`` order)."""
        local = {c: (t, q) for _, c, t, q in self.transforms(positions)}
        local.update({c: (t, q) for _, c, t, q in self.static_transforms()})
        T = np.eye(4)
        link = tip
        while link != root:
            j = self._by_child.get(link)
            if j is None:
                raise ValueError(f'no chain from {root!r} to {tip!r} in the URDF')
            t, q = local[link]
            A = np.eye(4)
            A[:3, :3] = quat_matrix(q)
            A[:3, 3] = t
            T = A @ T
            link = j.parent
        return T

    def positions(self, names, values) -> tuple[list | None, list[str]]:
        """(positions in ``self.names`` order, missing actuated joints) from a joint state's
        names and positions: a locked joint the state does not name sits at
        ``LOCKED_POSITION``; None with the missing names when a joint 1-3 is absent."""
        return self.positions_at(self.index(names), values)

    def index(self, names) -> list:
        """Per movable joint: its index in ``names``, or None (cache it while names repeat)."""
        idx = {n: i for i, n in enumerate(names)}
        return [idx.get(n) for n in self.names]

    def positions_at(self, index: list, values) -> tuple[list | None, list[str]]:
        """``positions`` with the indices of ``index``."""
        locked = self._locked
        out, missing = [], []
        for n, i in zip(self.names, index):
            if i is not None and i < len(values):
                out.append(float(values[i]))
            elif n in locked:
                out.append(LOCKED_POSITION)
            else:
                missing.append(n)
        return (None, missing) if missing else (out, [])


class Trace:
    """The TCP's recent trail: a point every ``sample_period_s`` of stamp time, the last
    ``duration_s`` kept; ``due(t)`` says when to publish (every 1 / ``rate_hz``)."""

    def __init__(self, duration_s: float, sample_period_s: float, rate_hz: float):
        from collections import deque
        if not (duration_s > 0 and sample_period_s > 0 and rate_hz > 0):
            raise ValueError('trace duration, sample period and rate must be > 0')
        self.points = deque(maxlen=max(2, int(round(duration_s / sample_period_s)) + 1))
        self.sample_period_s = sample_period_s
        self.publish_period_s = 1.0 / rate_hz
        self._last_sample = -math.inf
        self._last_publish = -math.inf

    def wants(self, t: float) -> bool:
        """True when a point at stamp ``t`` [s] should be added (time went back: restart)."""
        if t < self._last_sample:
            self.points.clear()
            self._last_sample = self._last_publish = -math.inf
        return t - self._last_sample >= self.sample_period_s

    def add(self, t: float, point) -> None:
        """Keep ``point`` (any object: the node stores ready-made message points, so that a
        publication only lists them) as the point at stamp ``t``."""
        self.points.append(point)
        self._last_sample = t

    def due(self, t: float) -> bool:
        if t - self._last_publish >= self.publish_period_s:
            self._last_publish = t
            return True
        return False


# --- serialized messages (CDR, XCDR1) ---------------------------------------------------------
# Encapsulation header (00 01 = little endian), then the fields, each aligned to its size
# counted from the end of the header; a string is uint32 length (with the NUL), bytes, NUL; a
# sequence uint32 count then its elements. The same bytes as rclpy's (tested).
_LE = b'\x00\x01\x00\x00'


class JointStateReader:
    """``read(data)`` -> (sec, nanosec, names, positions) of a serialized
    sensor_msgs/JointState; names a tuple (the same object while they do not change).
    ValueError when the data is not a well-formed JointState."""

    def __init__(self):
        self._raw = None
        self._names = ()

    def read(self, data: bytes):
        try:
            return self._read(data)
        except (struct.error, UnicodeDecodeError, IndexError) as exc:
            raise ValueError(f'malformed JointState: {exc}') from None

    def _read(self, data: bytes):
        if len(data) < 12 or data[0] != 0 or data[1] not in (0, 1):
            raise ValueError('not a plain CDR encapsulation')
        e = '<' if data[1] else '>'
        u32 = struct.Struct(e + 'I').unpack_from
        sec, nanosec = struct.unpack_from(e + 'iI', data, 4)
        o = 8 + 4 + u32(data, 12)[0]                     # after frame_id (payload offset)
        o += -o % 4
        (count,) = u32(data, 4 + o)
        start = o = o + 4
        for _ in range(count):
            o += -o % 4
            o += 4 + u32(data, 4 + o)[0]
        raw = data[4 + start:4 + o]
        if len(raw) != o - start:
            raise ValueError('truncated')
        if raw != self._raw:
            names, p = [], start
            for _ in range(count):
                p += -p % 4
                (n,) = u32(data, 4 + p)
                if n == 0 or data[4 + p + 3 + n] != 0:
                    raise ValueError('string without terminating NUL')
                names.append(data[4 + p + 4:4 + p + 3 + n].decode())
                p += 4 + n
            self._raw, self._names = raw, tuple(names)
        o += -o % 4
        (n,) = u32(data, 4 + o)
        o += 4
        if n:
            o += -o % 8
            if 4 + o + 8 * n > len(data):
                raise ValueError('truncated')
        return sec, nanosec, self._names, struct.unpack_from(f'{e}{n}d', data, 4 + o)


class TfEncoder:
    """tf2_msgs/TFMessage of fixed (parent, child) frames: ``encode(sec, nanosec,
    transforms)`` -> bytes, ``transforms`` as ``TfTree.transforms`` gives them (same frames,
    same order)."""

    def __init__(self, frames):
        self.frames = [(p, c) for p, c in frames]
        fmt, off = ['<4sI'], 4

        def align(n):
            nonlocal off
            pad = -off % n
            if pad:
                fmt.append(f'{pad}x')
                off += pad

        def string(b):
            nonlocal off
            align(4)
            fmt.append(f'I{len(b) + 1}s')
            off += 4 + len(b) + 1

        for parent, child in self.frames:
            align(4)
            fmt.append('iI')
            off += 8
            string(parent.encode())
            string(child.encode())
            align(8)
            fmt.append('7d')
            off += 56
        self._struct = struct.Struct(''.join(fmt))
        self._names = [(len(p.encode()) + 1, p.encode(), len(c.encode()) + 1, c.encode())
                       for p, c in self.frames]

    def encode(self, sec: int, nanosec: int, transforms) -> bytes:
        vals = [_LE, len(self.frames)]
        for (pn, pb, cn, cb), (_, _, t, q) in zip(self._names, transforms):
            vals += (sec, nanosec, pn, pb, cn, cb, t[0], t[1], t[2], q[0], q[1], q[2], q[3])
        return self._struct.pack(*vals)
