"""sensor_msgs/JointState CDR <-> numpy arrays, vectorised. No rclpy.

A 248 Hz recorder writes ~150 000 JointState messages in ten minutes; deserialising them one
by one costs seconds. All messages of one publisher have the same byte layout (same joint
names, same array lengths), so they are stacked into an (N, L) byte matrix, the layout is read
once from the first row, checked against every row, and the float64 columns are viewed in
place. Rows whose layout differs fall back to the per-message parser.

CDR (XCDR1, little endian) layout of JointState after the 4-byte encapsulation header:
stamp.sec int32, stamp.nanosec uint32, frame_id string, name string[], then position,
velocity, effort float64[] (uint32 count, float64 aligned to 8 from the body start).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

JOINT_STATE = 'sensor_msgs/msg/JointState'
_BODY = 4          # encapsulation header bytes


class JointStateError(ValueError):
    """A JointState payload is malformed or lacks a required field."""


@dataclass(frozen=True)
class JointSeries:
    """Joint measurements sampled at times ``t``.

    t: (N,) [s] (header stamps, or log times where stamps are zero); names: joint names (n,);
    position (N, n) [rad]; velocity (N, n) [rad/s]; effort (N, n) [N m] (applied torque).
    """

    t: np.ndarray
    names: tuple[str, ...]
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    def select(self, joint_names: list[str]) -> 'JointSeries':
        """Columns reordered to ``joint_names``; JointStateError names a missing joint."""
        missing = [n for n in joint_names if n not in self.names]
        if missing:
            raise JointStateError(f'joint_states has no {missing} (has {list(self.names)})')
        idx = [self.names.index(n) for n in joint_names]
        return JointSeries(self.t, tuple(joint_names), self.position[:, idx],
                           self.velocity[:, idx], self.effort[:, idx])

    @staticmethod
    def concatenate(parts: list['JointSeries']) -> 'JointSeries':
        """Parts with equal names, stacked and sorted by time."""
        if not parts:
            raise JointStateError('no joint states')
        names = parts[0].names
        for p in parts[1:]:
            if p.names != names:
                raise JointStateError(f'joint names differ: {names} vs {p.names}')
        t = np.concatenate([p.t for p in parts])
        order = np.argsort(t, kind='stable')
        cat = [np.concatenate([getattr(p, f) for p in parts])[order]
               for f in ('position', 'velocity', 'effort')]
        return JointSeries(t[order], names, *cat)


@dataclass(frozen=True)
class _Layout:
    frame_id: str
    names: tuple[str, ...]
    fixed_end: int                 # bytes [_BODY + 8, fixed_end) are equal in same-layout rows
    offsets: tuple[int, int, int]  # byte offsets of the position/velocity/effort float data
    counts: tuple[int, int, int]
    count_pos: tuple[int, int, int]  # byte offsets of the three uint32 array counts


def _align(pos: int, n: int) -> int:
    """Align an absolute buffer offset to n bytes relative to the CDR body."""
    rel = pos - _BODY
    return _BODY + (rel + n - 1) // n * n


def _string(buf: bytes, pos: int) -> tuple[str, int]:
    pos = _align(pos, 4)
    (n,) = struct.unpack_from('<I', buf, pos)
    pos += 4
    if n == 0 or pos + n > len(buf):
        raise JointStateError('bad string length')
    return buf[pos:pos + n - 1].decode(), pos + n


def _layout(buf: bytes) -> _Layout:
    if len(buf) < _BODY + 8 or buf[1] != 1:
        raise JointStateError('not little-endian CDR')
    try:
        pos = _BODY + 8
        frame_id, pos = _string(buf, pos)
        pos = _align(pos, 4)
        (n_names,) = struct.unpack_from('<I', buf, pos)
        pos += 4
        names = []
        for _ in range(n_names):
            s, pos = _string(buf, pos)
            names.append(s)
        offsets, counts, count_pos = [], [], []
        fixed_end = pos
        for _ in range(3):
            pos = _align(pos, 4)
            count_pos.append(pos)
            (n,) = struct.unpack_from('<I', buf, pos)
            pos += 4
            if n:
                pos = _align(pos, 8)
            if pos + 8 * n > len(buf):
                raise JointStateError('array runs past the end')
            offsets.append(pos)
            counts.append(n)
            pos += 8 * n
            if len(offsets) == 1:
                fixed_end = offsets[0]
    except struct.error as exc:
        raise JointStateError(f'truncated JointState ({exc})') from exc
    return _Layout(frame_id, tuple(names), fixed_end, tuple(offsets), tuple(counts),
                   tuple(count_pos))


def _stamp_ns(rows: np.ndarray) -> np.ndarray:
    sec = rows[:, _BODY:_BODY + 4].copy().view('<i4')[:, 0].astype(np.int64)
    nsec = rows[:, _BODY + 4:_BODY + 8].copy().view('<u4')[:, 0].astype(np.int64)
    return sec * 1_000_000_000 + nsec


FIELDS = ('position', 'velocity', 'effort')


def decode_joint_states(data: list[bytes], log_t_ns: list[int] | np.ndarray,
                        require: tuple[str, ...] = FIELDS,
                        unnamed: tuple[str, ...] | list[str] | None = None,
                        keep_locked: bool = False) -> JointSeries:
    """JointSeries from CDR payloads (N,) and their log times [ns] (N,).

    Requires the same joint names in every message and, for each field of ``require``, that
    field with the names' length in at least one message; raises JointStateError otherwise
    (e.g. "no effort"). Fields not required and not carried are NaN (a torque command is a
    JointState with effort only: ``require=('effort',)``). ``unnamed``: joint names for
    messages without names (pdplus's /torque_command: effort of joints 1-3 in order).
    ``keep_locked``: keep joints 4-6 even where they stood still (the six-joint
    identification, six_joint.py); default: ``without_locked``.
    """
    if not data:
        raise JointStateError('no JointState messages')
    log_t = np.asarray(log_t_ns, np.int64)
    lengths = np.fromiter((len(d) for d in data), np.int64, len(data))
    first = _layout(data[0])
    names = first.names
    n = len(names)
    if n == 0:
        # pdplus's /torque_command carries effort only, without names: the joints in order
        counts = [c for c in first.counts if c]
        if not unnamed or not counts or counts[0] > len(unnamed):
            raise JointStateError('JointState without joint names')
        n = counts[0]
    out_names = names if names else tuple(unnamed[:n])
    stamps = np.empty(len(data), np.int64)
    out = np.full((3, len(data), n), np.nan)
    for length in np.unique(lengths):
        idx = np.flatnonzero(lengths == length)
        rows = np.frombuffer(b''.join(data[i] for i in idx), np.uint8).reshape(len(idx), length)
        lay = _layout(data[idx[0]])
        cols = np.r_[_BODY + 8:lay.fixed_end,
                     np.add.outer(lay.count_pos, np.arange(4)).ravel()]
        same = (np.all(rows[:, cols] == rows[0, cols], axis=1) if lay.names == names
                else np.zeros(len(idx), bool))
        stamps[idx] = _stamp_ns(rows)
        good = idx[same]
        for k, (off, cnt) in enumerate(zip(lay.offsets, lay.counts)):
            if cnt == n and len(good):
                out[k, good] = rows[same, off:off + 8 * n].copy().view('<f8')
        for i in idx[~same]:                      # different layout: one by one
            lay_i = _layout(data[i])
            if lay_i.names != names:
                raise JointStateError(f'joint names change within the topic: {names} vs '
                                      f'{lay_i.names}')
            for k, (off, cnt) in enumerate(zip(lay_i.offsets, lay_i.counts)):
                if cnt == n:
                    out[k, i] = np.frombuffer(data[i], '<f8', n, off)
    for k, field in enumerate(FIELDS):
        if field in require and np.all(np.isnan(out[k])):
            raise JointStateError(f'JointState messages carry no {field}')
    t = np.where(stamps > 0, stamps, log_t)
    if np.any(np.diff(t) < 0):
        order = np.argsort(t, kind='stable')
        t, out = t[order], out[:, order]
    s = JointSeries(t * 1e-9, out_names, out[0], out[1], out[2])
    return s if keep_locked else without_locked(s)


LOCKED_STILL_RAD = 1e-3     # a locked joint whose position spans less than this stood still


def without_locked(s: JointSeries) -> JointSeries:
    """The series without the joints the model locks (irb_description: joint_4 .. joint_6;
    /joint_states names all six joints, the model and the identification use joints 1-3)
    where such a joint stood still (position span < ``LOCKED_STILL_RAD``, or no position).
    A locked joint that moved stays in the series: it is data the readers must see."""
    from irb_description.robot_state import locked_joint_names
    locked = set(locked_joint_names())
    keep = []
    for i, name in enumerate(s.names):
        if name in locked:
            pos = s.position[:, i]
            pos = pos[np.isfinite(pos)]
            if not len(pos) or float(pos.max() - pos.min()) < LOCKED_STILL_RAD:
                continue
        keep.append(i)
    if len(keep) == len(s.names) or not keep:
        return s
    return JointSeries(s.t, tuple(s.names[i] for i in keep), s.position[:, keep],
                       s.velocity[:, keep], s.effort[:, keep])


def encode_joint_states(t_ns: np.ndarray, names: list[str], position: np.ndarray,
                        velocity: np.ndarray, effort: np.ndarray, frame_id: str = ''
                        ) -> list[bytes]:
    """CDR payloads (N,) of JointState messages; stamps t_ns (N,) [ns], arrays (N, n)."""
    from .bagio import serialize, typestore
    ts = typestore()
    JS = ts.types[JOINT_STATE]
    Header = ts.types['std_msgs/msg/Header']
    Time = ts.types['builtin_interfaces/msg/Time']
    n = len(names)
    one = np.zeros(n)
    template = serialize(JOINT_STATE, JS(
        header=Header(stamp=Time(sec=0, nanosec=0), frame_id=frame_id), name=list(names),
        position=one, velocity=one, effort=one))
    lay = _layout(template)
    N = len(t_ns)
    rows = np.tile(np.frombuffer(template, np.uint8), (N, 1))
    t_ns = np.asarray(t_ns, np.int64)
    rows[:, _BODY:_BODY + 4] = (t_ns // 1_000_000_000).astype('<i4').view(np.uint8).reshape(N, 4)
    rows[:, _BODY + 4:_BODY + 8] = (t_ns % 1_000_000_000).astype('<u4').view(
        np.uint8).reshape(N, 4)
    for off, arr in zip(lay.offsets, (position, velocity, effort)):
        arr = np.ascontiguousarray(np.asarray(arr, '<f8').reshape(N, n))
        rows[:, off:off + 8 * n] = arr.view(np.uint8).reshape(N, 8 * n)
    flat = rows.tobytes()
    L = len(template)
    return [flat[i * L:(i + 1) * L] for i in range(N)]


def read_joint_series(bag, topic: str = '/joint_states', keep_locked: bool = False
                      ) -> JointSeries:
    """JointSeries of ``topic`` in a bag; raises bagio.BagError / JointStateError naming the
    problem (missing bag or topic, corrupt file, wrong type, no effort ...)."""
    from .bagio import BagError, read_messages
    msgs = read_messages(bag, [topic])[topic]
    if msgs.msgtype != JOINT_STATE:
        raise BagError(f'bag {bag}: {topic} is {msgs.msgtype}, not {JOINT_STATE}')
    if not msgs.data:
        raise BagError(f'bag {bag}: {topic} has no messages')
    try:
        return decode_joint_states(msgs.data, msgs.t_ns, keep_locked=keep_locked)
    except JointStateError as exc:
        raise JointStateError(f'bag {bag}: {topic}: {exc}') from exc
