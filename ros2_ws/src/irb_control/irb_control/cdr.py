"""Serialized (CDR) JointState and ControllerState for the 248 Hz loop, without message objects.

rclpy converts every message between its Python class and C on publish and on take; for a
JointState that is a few hundred Python operations (the array setters check each value), and
at 248 Hz on a shared 2-core machine, where the caches are cold at each wake-up, that costs
about a quarter of the state -> command round trip. The loop topics therefore travel as
serialized bytes: ``Publisher.publish(bytes)`` and ``create_subscription(..., raw=True)``.
The bytes are the same on the wire as rclpy's (the DDS/ROS 2 serialization of rmw_fastrtps
and rmw_cyclonedds): XCDR version 1 (plain CDR), a 4-byte encapsulation header
(00 01 00 00 = little endian, 00 00 00 00 = big endian), then the fields in order, each
aligned to its size (8 for float64 and uint64) counted from the end of the header; a string is
a uint32 length including the terminating NUL, then the bytes and the NUL; a sequence is a
uint32 count, then its elements (no alignment when it is empty). Padding bytes are written as
zeros and ignored when reading; trailing bytes are ignored.

No rclpy here: plain ``struct``. Checked against ``rclpy.serialization`` in
``test/test_cdr.py``.
"""
from __future__ import annotations

import struct

LE_HEADER = b'\x00\x01\x00\x00'

_I32 = 'i32'
_U32 = 'u32'
_U8 = 'u8'
_U64 = 'u64'
_F64 = 'f64'
_STR = 'str'
_F64S = 'f64[]'
_STRS = 'str[]'

# std_msgs/Header: stamp (sec int32, nanosec uint32), frame_id
_HEADER = (_I32, _U32, _STR)
JOINT_STATE = _HEADER + (_STRS, _F64S, _F64S, _F64S)
CONTROLLER_STATE = _HEADER + (_U8, _STR, _F64, _F64, _F64) + (_F64S,) * 9 + (_U64, _U64, _F64)


def _layout(schema: tuple, sizes: tuple) -> struct.Struct:
    """struct (little endian, explicit padding) of one message of ``schema``.

    ``sizes``, in field order: the byte length (without NUL) of each string, the count of each
    sequence, for a string sequence its count followed by each string's byte length. The
    values to pack: numbers as they are, a string as (length + 1, bytes), a sequence as
    (count, *elements), a string sequence as (count, length + 1, bytes, ...).
    """
    fmt = ['<4s']
    off = 0
    it = iter(sizes)

    def align(n: int) -> None:
        nonlocal off
        pad = -off % n
        if pad:
            fmt.append(f'{pad}x')
            off += pad

    def string() -> None:
        nonlocal off
        align(4)
        n = next(it) + 1
        fmt.append(f'I{n}s')
        off += 4 + n

    for t in schema:
        if t in (_I32, _U32):
            align(4)
            fmt.append('i' if t == _I32 else 'I')
            off += 4
        elif t == _U8:
            fmt.append('B')
            off += 1
        elif t in (_U64, _F64):
            align(8)
            fmt.append('Q' if t == _U64 else 'd')
            off += 8
        elif t == _STR:
            string()
        elif t == _F64S:
            align(4)
            n = next(it)
            fmt.append('I')
            off += 4
            if n:
                align(8)
                fmt.append(f'{n}d')
                off += 8 * n
        elif t == _STRS:
            align(4)
            n = next(it)
            fmt.append('I')
            off += 4
            for _ in range(n):
                string()
        else:
            raise ValueError(f'unknown field type {t!r}')
    return struct.Struct(''.join(fmt))


class JointStateEncoder:
    """sensor_msgs/JointState with fixed ``names``, frame_id and sequence lengths.

    ``encode(sec, nanosec, position, velocity, effort)`` -> bytes; each sequence must have the
    length given here (0 = empty, pass ``()``).
    """

    def __init__(self, names, n_position: int, n_velocity: int, n_effort: int,
                 frame_id: str = ''):
        fid = frame_id.encode()
        enc = [n.encode() for n in names]
        sizes = (len(fid), len(enc), *(len(b) for b in enc), n_position, n_velocity, n_effort)
        self._struct = _layout(JOINT_STATE, sizes)
        self._names = (len(fid) + 1, fid, len(enc),
                       *(x for b in enc for x in (len(b) + 1, b)))
        self._n = (n_position, n_velocity, n_effort)
        self._pack = self._struct.pack

    def encode(self, sec: int, nanosec: int, position=(), velocity=(), effort=()) -> bytes:
        np_, nv, ne = self._n
        if len(position) != np_ or len(velocity) != nv or len(effort) != ne:
            raise ValueError(f'sequence lengths must be {self._n}')
        return self._pack(LE_HEADER, sec, nanosec, *self._names, np_, *position, nv,
                          *velocity, ne, *effort)


class JointStateDecoder:
    """``decode(data)`` -> (sec, nanosec, names, position, velocity, effort) of a serialized
    sensor_msgs/JointState; names a tuple of str (the same object as long as the names do not
    change), the sequences tuples of float. ValueError when the data is not a well-formed
    JointState (truncated, unknown encapsulation, invalid UTF-8)."""

    def __init__(self):
        self._names_raw: bytes | None = None
        self._names: tuple = ()
        self._struct = {}

    def _fmt(self, e: str, n: int) -> struct.Struct:
        key = (e, n)
        s = self._struct.get(key)
        if s is None:
            s = self._struct[key] = struct.Struct(f'{e}{n}d')
        return s

    def decode(self, data: bytes):
        try:
            return self._decode(data)
        except (struct.error, UnicodeDecodeError, IndexError) as exc:
            raise ValueError(f'malformed JointState: {exc}') from None

    def _decode(self, data: bytes):
        if len(data) < 4 or data[0] != 0 or data[1] not in (0, 1):
            raise ValueError('not a plain CDR encapsulation')
        e = '<' if data[1] else '>'
        u32 = struct.Struct(e + 'I').unpack_from
        sec, nanosec = struct.unpack_from(e + 'iI', data, 4)
        o = 8                                       # payload offset (header at 4)
        (n,) = u32(data, 4 + o)
        o += 4 + n                                  # frame_id
        o += -o % 4
        (count,) = u32(data, 4 + o)
        start = o + 4
        o = start
        for _ in range(count):                      # names: only walked
            o += -o % 4
            (n,) = u32(data, 4 + o)
            o += 4 + n
        raw = data[4 + start:4 + o]
        if len(raw) != o - start:
            raise ValueError('truncated')
        if raw != self._names_raw:
            names = []
            p = start
            for _ in range(count):
                p += -p % 4
                (n,) = u32(data, 4 + p)
                if n == 0 or data[4 + p + 4 + n - 1] != 0:
                    raise ValueError('string without terminating NUL')
                names.append(data[4 + p + 4:4 + p + 4 + n - 1].decode())
                p += 4 + n
            self._names, self._names_raw = tuple(names), raw
        seqs = []
        for _ in range(3):
            o += -o % 4
            (n,) = u32(data, 4 + o)
            o += 4
            if n:
                o += -o % 8
                if 4 + o + 8 * n > len(data):
                    raise ValueError('truncated')
                seqs.append(self._fmt(e, n).unpack_from(data, 4 + o))
                o += 8 * n
            else:
                seqs.append(())
        return sec, nanosec, self._names, seqs[0], seqs[1], seqs[2]


class JointSelector:
    """Joints picked by name from a decoded JointState (``/joint_states`` names all six joints,
    the loop needs joints 1-3). ``select(names, seq)`` -> the values of ``joints`` in ``seq``;
    the index lookup is cached while the names repeat (the decoder returns the same names
    object then). A message without names is read by position (the first ``len(joints)``).
    ValueError naming the missing joints, or a sequence shorter than its names."""

    def __init__(self, joints):
        self.joints = tuple(joints)
        self._names: tuple | None = None
        self._idx: tuple | None = None
        self._missing = ''

    def indices(self, names: tuple) -> tuple:
        if names is not self._names and names != self._names:
            self._names = names
            if not names:
                self._idx, self._missing = tuple(range(len(self.joints))), ''
            else:
                missing = [j for j in self.joints if j not in names]
                self._idx = None if missing else tuple(names.index(j) for j in self.joints)
                self._missing = (f'joint_states without {", ".join(missing)} (it names '
                                 f'{", ".join(names)})' if missing else '')
        if self._idx is None:
            raise ValueError(self._missing)
        return self._idx

    def select(self, names: tuple, seq) -> tuple:
        idx = self.indices(names)
        try:
            return tuple(seq[i] for i in idx)
        except IndexError:
            raise ValueError(f'joint_states with {len(seq)} values for '
                             f'{len(names) or len(self.joints)} joints') from None


class ControllerStateEncoder:
    """irb_interfaces/ControllerState: ``encode(sec, nanosec, mode, stop_reason, theta,
    theta_predicted, theta_dot_ref, arrays, missed_deadlines, rejected_inputs,
    step_duration)`` -> bytes, ``arrays`` the 9 float64[] fields in message order (q_ref,
    qd_ref, qdd_ref, q_error, qd_error, tau_model, tau_friction, tau_feedback, tau_command).
    """

    def __init__(self, frame_id: str = ''):
        self._fid = frame_id.encode()
        self._structs = {}

    def encode(self, sec, nanosec, mode, stop_reason, theta, theta_predicted, theta_dot_ref,
               arrays, missed_deadlines, rejected_inputs, step_duration) -> bytes:
        reason = stop_reason.encode() if stop_reason else b''
        lengths = tuple(len(a) for a in arrays)
        key = (len(reason), lengths)
        s = self._structs.get(key)
        if s is None:
            if len(lengths) != 9:
                raise ValueError('ControllerState has 9 float64[] fields')
            s = self._structs[key] = _layout(CONTROLLER_STATE,
                                             (len(self._fid), len(reason), *lengths))
        vals = [LE_HEADER, sec, nanosec, len(self._fid) + 1, self._fid, mode, len(reason) + 1,
                reason, theta, theta_predicted, theta_dot_ref]
        for a in arrays:
            vals.append(len(a))
            vals.extend(a)
        vals += (missed_deadlines, rejected_inputs, step_duration)
        return s.pack(*vals)
