"""Axis-computer torque protocol, version 3: packet layout, encode, decode (no ROS imports).

EGM-shaped UDP protocol with a torque payload (spec: doc/axis_protocol.md). The axis computer
is the clock master: every 4.032 ms it sends a STATE packet; the external controller answers
with a COMMAND packet carrying the same sequence number before the next cycle.
All fields little-endian, fixed layout, CRC-32 (zlib) over everything before the CRC field.
Version 2 adds a session id (random per start of the axis computer, echoed by every command)
and the supervision error bits; the sequence rules are in ``SequenceTracker``. Version 3 (issue
29) carries the drives' power mode: the command's two reserved bytes become ``brake_request``
and ``power_mode_request`` (same 80 bytes; 0 = no request, which is what every version-2
command holds), and the state grows by 4 bytes (``brakes_engaged``, ``power_mode``, 2
reserved). Both decoders take versions 2 and 3 (``SUPPORTED_VERSIONS``); a version-2 state
decodes with brakes_engaged = not motors_on and power_mode 0 (unknown).
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

VERSION = 3
SUPPORTED_VERSIONS = (2, 3)
N_JOINTS = 6
MAGIC_STATE = b'IRBS'
MAGIC_COMMAND = b'IRBC'
CYCLE_S = 0.004032

# status.mode and command.mode_request
MODE_IDLE = 0            # axis computer runs its own position control (motors may be on)
MODE_TORQUE = 1          # external torque references are applied
MODE_NAMES = {MODE_IDLE: 'idle', MODE_TORQUE: 'torque'}

# command.power_mode_request and state.power_mode (irb_description.power_modes.MODES)
POWER_NONE = 0           # command: no request; state: unknown (a version-2 peer)
POWER_MODES = {1: 'hold', 2: 'brakes', 3: 'bus_off', 4: 'hibernate'}
POWER_CODES = {name: code for code, name in POWER_MODES.items()}
# command.brake_request: the brakes as such (engage = the brakes mode, release = hold)
BRAKE_NONE, BRAKE_ENGAGE, BRAKE_RELEASE = 0, 1, 2

# status.error bit flags (latched by the axis computer until reset)
ERR_NONE = 0
ERR_COMM_TIMEOUT = 1 << 0      # too many cycles without a valid command: brakes engaged
ERR_BAD_COMMAND = 1 << 1       # a command was malformed or not finite
ERR_TORQUE_LIMIT = 1 << 2      # a command exceeded the axis computer's torque limit
ERR_POSITION_LIMIT = 1 << 3    # a joint left its position limits: brakes
ERR_SPEED_LIMIT = 1 << 4       # a joint exceeded its speed limit: brakes
ERROR_NAMES = {ERR_COMM_TIMEOUT: 'comm timeout', ERR_BAD_COMMAND: 'bad command',
               ERR_TORQUE_LIMIT: 'torque limit', ERR_POSITION_LIMIT: 'position limit',
               ERR_SPEED_LIMIT: 'speed limit'}


def error_text(error: int) -> str:
    """The error bits in words ('' for none)."""
    return ', '.join(name for bit, name in ERROR_NAMES.items() if error & bit) or (
        f'unknown error {error:#x}' if error else '')

_HEADER = struct.Struct('<4sHHIIQ')   # magic, version, size, seq, session, time [ns]
_STATE_BODY_V2 = struct.Struct(f'<{3 * N_JOINTS}dBBH')  # q, qd, tau, motors_on, mode, error
# version 3: + brakes_engaged, power_mode, reserved
_STATE_BODY = struct.Struct(f'<{3 * N_JOINTS}dBBHBBH')
# tau_ref, mode_request, reset, brake_request, power_mode_request (version 2: reserved uint16 0)
_COMMAND_BODY = struct.Struct(f'<{N_JOINTS}dBBBB')
_CRC = struct.Struct('<I')
STATE_SIZE = _HEADER.size + _STATE_BODY.size + _CRC.size
STATE_SIZE_V2 = _HEADER.size + _STATE_BODY_V2.size + _CRC.size
COMMAND_SIZE = _HEADER.size + _COMMAND_BODY.size + _CRC.size


class ProtocolError(ValueError):
    """A datagram is not a valid packet; ``reason`` is a short machine-readable key."""

    def __init__(self, reason: str, detail: str, seq: int | None = None,
                 session: int | None = None):
        super().__init__(f'{reason}: {detail}')
        self.reason = reason
        self.seq, self.session = seq, session     # known when the frame itself was valid


@dataclass
class StatePacket:
    """Axis computer -> controller. Arrays (6,): q [rad], qd [rad/s], tau [N m] measured."""

    seq: int
    stamp_ns: int
    q: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    qd: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    tau: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    motors_on: bool = True
    mode: int = MODE_TORQUE
    error: int = ERR_NONE
    session: int = 0
    brakes_engaged: bool = False
    power_mode: int = POWER_NONE         # POWER_MODES code; 0 = unknown (version 2)
    version: int = VERSION


@dataclass
class CommandPacket:
    """Controller -> axis computer: torque reference (6,) [N m] for cycle ``seq``."""

    seq: int
    stamp_ns: int
    tau_ref: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    mode_request: int = MODE_TORQUE
    reset: bool = False
    session: int = 0
    brake_request: int = BRAKE_NONE
    power_mode_request: int = POWER_NONE
    version: int = VERSION


def _finish(head_and_body: bytes) -> bytes:
    return head_and_body + _CRC.pack(zlib.crc32(head_and_body))


def encode_state(p: StatePacket) -> bytes:
    """STATE_SIZE bytes for ``p`` (STATE_SIZE_V2 for ``p.version`` 2: no power fields)."""
    common = (*np.asarray(p.q, float), *np.asarray(p.qd, float), *np.asarray(p.tau, float),
              int(bool(p.motors_on)), int(p.mode), int(p.error))
    if p.version == 2:
        body, size = _STATE_BODY_V2.pack(*common), STATE_SIZE_V2
    else:
        body, size = _STATE_BODY.pack(*common, int(bool(p.brakes_engaged)),
                                      int(p.power_mode), 0), STATE_SIZE
    return _finish(_HEADER.pack(MAGIC_STATE, int(p.version), size, p.seq & 0xFFFFFFFF,
                                p.session & 0xFFFFFFFF, p.stamp_ns) + body)


def encode_command(c: CommandPacket) -> bytes:
    """COMMAND_SIZE bytes for ``c``."""
    v2 = c.version == 2            # version 2: the two bytes are reserved (0)
    body = _COMMAND_BODY.pack(*np.asarray(c.tau_ref, float), int(c.mode_request),
                              int(bool(c.reset)), 0 if v2 else int(c.brake_request),
                              0 if v2 else int(c.power_mode_request))
    return _finish(_HEADER.pack(MAGIC_COMMAND, int(c.version), COMMAND_SIZE,
                                c.seq & 0xFFFFFFFF, c.session & 0xFFFFFFFF, c.stamp_ns) + body)


def _check(data: bytes, magic: bytes, sizes: dict) -> tuple[int, int, int, int]:
    """(seq, session, stamp, version) of a valid frame; ``sizes``: version -> size."""
    if len(data) < _HEADER.size:
        raise ProtocolError('size', f'{len(data)} bytes, expected {sizes[VERSION]}')
    got_magic, version, declared, seq, session, stamp = _HEADER.unpack_from(data)
    if got_magic != magic:
        raise ProtocolError('magic', f'{got_magic!r}, expected {magic!r}')
    if version not in SUPPORTED_VERSIONS:
        raise ProtocolError('version', f'{version}, expected one of {SUPPORTED_VERSIONS}')
    size = sizes[version]
    if len(data) != size:
        raise ProtocolError('size', f'{len(data)} bytes, expected {size}')
    if declared != size:
        raise ProtocolError('size', f'header says {declared} bytes, expected {size}')
    (crc,) = _CRC.unpack_from(data, size - _CRC.size)
    if crc != zlib.crc32(data[:size - _CRC.size]):
        raise ProtocolError('crc', 'checksum mismatch')
    return seq, session, stamp, version


def decode_state(data: bytes) -> StatePacket:
    """Parse and validate a STATE datagram; non-finite values raise ProtocolError('nan')."""
    seq, session, stamp, version = _check(data, MAGIC_STATE, {2: STATE_SIZE_V2, 3: STATE_SIZE})
    v = (_STATE_BODY_V2 if version == 2 else _STATE_BODY).unpack_from(data, _HEADER.size)
    arr = np.array(v[:3 * N_JOINTS], float)
    if not np.all(np.isfinite(arr)):
        raise ProtocolError('nan', 'non-finite joint value in state', seq, session)
    n, k = N_JOINTS, 3 * N_JOINTS
    motors_on = bool(v[k])
    brakes, power = (not motors_on, POWER_NONE) if version == 2 else (bool(v[k + 3]),
                                                                       int(v[k + 4]))
    return StatePacket(seq, stamp, arr[:n], arr[n:2 * n], arr[2 * n:], motors_on, v[k + 1],
                       v[k + 2], session, brakes, power, version)


def decode_command(data: bytes) -> CommandPacket:
    """Parse and validate a COMMAND datagram; non-finite torques raise ProtocolError('nan')."""
    seq, session, stamp, version = _check(data, MAGIC_COMMAND, {2: COMMAND_SIZE,
                                                               3: COMMAND_SIZE})
    v = _COMMAND_BODY.unpack_from(data, _HEADER.size)
    tau = np.array(v[:N_JOINTS], float)
    if not np.all(np.isfinite(tau)):
        raise ProtocolError('nan', 'non-finite torque in command', seq, session)
    n = N_JOINTS
    brake, power = (0, 0) if version == 2 else (v[n + 2], v[n + 3])
    return CommandPacket(seq, stamp, tau, v[n], bool(v[n + 1]), session, brake, power,
                         version)


def seq_newer(a: int, b: int) -> bool:
    """True when sequence number ``a`` is after ``b`` (uint32 with wrap-around, RFC 1982)."""
    diff = (a - b) & 0xFFFFFFFF
    return 0 < diff < 0x80000000


class SequenceTracker:
    """Which states to accept: sessions, serial-number arithmetic, a bounded window, resync.

    Within a session a state is accepted when its seq is 1 to ``window`` cycles after the last
    accepted one (RFC 1982 arithmetic with wrap-around); equal is a duplicate, older is stale,
    further ahead is a jump. A new session (the axis computer restarted, seq from 1 again) or a
    jump is adopted only after ``confirm`` consecutive states (seq + 1 each) of it: the
    resynchronisation handshake. One forged or stray packet, whatever its session or seq,
    therefore changes nothing, and a real restart costs ``confirm`` cycles.
    ``offer(session, seq)`` returns 'accept', 'resync' (accepted, a new reference adopted) or
    the rejection reason ('duplicate', 'stale', 'jump', 'session').
    """

    def __init__(self, window: int = 250, confirm: int = 3):
        self.window, self.confirm = window, confirm
        self.session: int | None = None
        self.seq: int | None = None
        self._candidate: tuple[int, int, int] | None = None   # (session, seq, count)

    def offer(self, session: int, seq: int) -> str:
        if self.session is None:
            self.session, self.seq = session, seq
            return 'resync'
        if session == self.session:
            step = (seq - self.seq) & 0xFFFFFFFF
            if step == 0:
                return 'duplicate'
            if step < 0x80000000 and step <= self.window:
                self.seq, self._candidate = seq, None
                return 'accept'
            reason = 'stale' if step >= 0x80000000 else 'jump'
        else:
            reason = 'session'
        c = self._candidate
        if c is not None and c[0] == session and ((seq - c[1]) & 0xFFFFFFFF) == 1:
            self._candidate = (session, seq, c[2] + 1)
        else:
            self._candidate = (session, seq, 1)
        if self._candidate[2] >= self.confirm:
            self.session, self.seq, self._candidate = session, seq, None
            return 'resync'
        return reason
