"""A fake axis computer: the simulated plant behind the torque protocol (no ROS, no sockets).

Per cycle: ``begin_cycle()`` measures the plant and returns the STATE datagram(s) to send (with
the configured faults applied), ``on_datagram()`` takes the controller's answers, and
``end_cycle()`` applies the answer (or counts a miss) and advances the plant one period.
External control is engaged by the first valid command (until then the robot idles on its
brakes, as an EGM session waits for its first answer). It supervises like the real one, every
fault engaging the brakes and latching its error bit until a command with reset = 1 from the
bound controller: ``miss_limit`` consecutive cycles without a valid command (ERR_COMM_TIMEOUT),
a malformed or non-finite command for the current cycle, an unknown mode request or a torque
for the locked joints 4-6 (ERR_BAD_COMMAND), a torque over the limit (ERR_TORQUE_LIMIT), a joint
outside its position limits (ERR_POSITION_LIMIT) or over its speed limit (ERR_SPEED_LIMIT).
``mode_request`` 0 leaves external control (brakes, no error). Only datagrams from the bound
controller (address and port) are looked at, and only with this session's id (random per
start).
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from .axis_protocol import (BRAKE_ENGAGE, BRAKE_NONE, BRAKE_RELEASE, ERR_BAD_COMMAND,
                            ERR_COMM_TIMEOUT, ERR_NONE, ERR_POSITION_LIMIT, ERR_SPEED_LIMIT,
                            ERR_TORQUE_LIMIT, MODE_IDLE, MODE_TORQUE, N_JOINTS, POWER_CODES,
                            POWER_MODES, VERSION, ProtocolError, StatePacket, decode_command,
                            encode_state, error_text)
from .plant import Plant

FAULT_KINDS = ('drop', 'delay', 'duplicate', 'reorder', 'corrupt', 'nan')


@dataclass(frozen=True)
class FaultConfig:
    """Per-cycle probabilities of each fault on the outgoing STATE packet.

    drop: not sent; delay: sent ``delay_s`` [s] late; duplicate: sent twice; reorder: held back
    and sent after the next cycle's packet; corrupt: one byte flipped; nan: q carries a NaN.
    """

    drop: float = 0.0
    delay: float = 0.0
    delay_s: float = 0.006
    duplicate: float = 0.0
    reorder: float = 0.0
    corrupt: float = 0.0
    nan: float = 0.0
    seed: int = 0

    def __post_init__(self):
        for k in FAULT_KINDS:
            if not 0.0 <= getattr(self, k) <= 1.0:
                raise ValueError(f'fault probability {k} must be in [0, 1]')
        if not self.delay_s >= 0.0:
            raise ValueError('delay_s must be >= 0')


class FakeAxisCore:
    """Plant + protocol + fault injection + the robot's reaction to missing commands."""

    def __init__(self, plant: Plant, faults: FaultConfig = FaultConfig(), miss_limit: int = 3,
                 torque_limit: np.ndarray | None = None, controller: tuple | None = None,
                 session: int | None = None, speed_margin: float = 1.05,
                 transition_s=None, version: int = VERSION):
        if miss_limit < 1:
            raise ValueError('miss_limit must be >= 1')
        self.plant = plant
        #: (from, to) -> duration [s] of a power-mode change (default: at once)
        self.transition_s = transition_s or (lambda a, b: 0.0)
        self.version = int(version)      # of the states sent (2 for a version-2 controller)
        self.faults = faults
        self.miss_limit = miss_limit
        self.torque_limit = (np.asarray(torque_limit, float) if torque_limit is not None
                             else plant.model.limits.torque)
        self.rng = np.random.default_rng(faults.seed)
        self.controller = controller        # (address, port) commands are taken from
        lim = plant.model.limits
        self.q_lo, self.q_hi = lim.lower, lim.upper
        self.v_max = lim.velocity * speed_margin
        self.session = (int(np.random.default_rng().integers(1, 2 ** 32)) if session is None
                        else int(session))
        self.seq = 0
        self.error = ERR_NONE
        self.engaged = False
        self.misses = 0
        self.missed_total = 0
        self.injected: Counter = Counter()
        self.rejected: Counter = Counter()
        self.events: list[str] = []
        self._command: np.ndarray | None = None
        self._held_back: bytes | None = None

    @property
    def latched(self) -> bool:
        return self.error != ERR_NONE

    def _state_packet(self, nan: bool) -> StatePacket:
        y = self.plant.measure()
        q = np.zeros(N_JOINTS)
        qd = np.zeros(N_JOINTS)
        tau = np.zeros(N_JOINTS)
        q[:3], qd[:3], tau[:3] = y.q, y.qd, y.tau
        if nan:
            q[0] = np.nan
        return StatePacket(self.seq, int(round(y.t * 1e9)), q, qd, tau,
                           motors_on=not self.plant.braked,
                           mode=MODE_TORQUE if self.engaged else MODE_IDLE, error=self.error,
                           session=self.session, brakes_engaged=self.plant.braked,
                           power_mode=POWER_CODES[self.plant.power_mode],
                           version=self.version)

    def begin_cycle(self) -> list[tuple[float, bytes]]:
        """Start cycle ``seq + 1``: datagrams to send as (offset [s] from now, bytes)."""
        self.seq = (self.seq + 1) & 0xFFFFFFFF
        self._command = None
        f, r = self.faults, self.rng.random(len(FAULT_KINDS))
        hit = {k: r[i] < getattr(f, k) for i, k in enumerate(FAULT_KINDS)}
        for k, v in hit.items():
            if v:
                self.injected[k] += 1
        data = encode_state(self._state_packet(hit['nan']))
        if hit['corrupt']:
            b = bytearray(data)
            b[24 + int(self.rng.integers(0, 144))] ^= 0xFF
            data = bytes(b)
        out: list[tuple[float, bytes]] = []
        if self._held_back is not None:            # the packet held back last cycle
            out.append((0.0, self._held_back))
            self._held_back = None
        if hit['drop']:
            return out
        if hit['reorder']:
            self._held_back = data
            return out
        offset = f.delay_s if hit['delay'] else 0.0
        out.insert(0, (offset, data))
        if hit['duplicate']:
            out.append((offset, data))
        return out

    def on_datagram(self, data: bytes, source: tuple | None = None) -> bool:
        """Take a COMMAND datagram from ``source`` (address, port); True when it is the valid
        answer to the current cycle."""
        if self.controller is not None and source is not None and \
                tuple(source) != tuple(self.controller):
            self.rejected['foreign_peer'] += 1
            return False
        try:
            cmd = decode_command(data)
        except ProtocolError as exc:
            self.rejected[exc.reason] += 1
            if (exc.seq == self.seq and exc.session == self.session and self.engaged
                    and not self.latched):
                self._latch(ERR_BAD_COMMAND, f'malformed command for this cycle ({exc})')
            return False
        if cmd.session != self.session:
            self.rejected['wrong_session'] += 1
            return False
        if cmd.seq != self.seq:
            self.rejected['wrong_seq'] += 1
            return False
        if cmd.reset and self.latched:
            self.events.append(f'seq {self.seq}: reset received, error '
                               f'{self.error:#x} ({error_text(self.error)}) cleared')
            self.error = ERR_NONE
            self.misses = 0
            self.plant.clear_error()
        if self.latched:
            self.rejected['latched'] += 1
            return False
        want = (POWER_MODES.get(cmd.power_mode_request)
                or {BRAKE_ENGAGE: 'brakes', BRAKE_RELEASE: 'hold'}.get(cmd.brake_request))
        if (cmd.power_mode_request and cmd.power_mode_request not in POWER_MODES) or \
                cmd.brake_request not in (BRAKE_NONE, BRAKE_ENGAGE, BRAKE_RELEASE):
            self.rejected['bad_power_request'] += 1
            self._latch(ERR_BAD_COMMAND, f'unknown power mode request '
                        f'{cmd.power_mode_request} / brake request {cmd.brake_request}')
            return False
        if want is not None and want not in (self.plant.power_mode, self.plant.mode_target):
            ok, text = self.plant.request_power_mode(
                want, self.transition_s(self.plant.power_mode, want))
            self.events.append(f'seq {self.seq}: power mode {want} requested: {text}')
        if self.plant.motors_off_requested:
            # the motors are off on request: no torque is applied, nothing is missed
            self.engaged = False
            self.rejected['motors_off'] += 1
            return False
        if cmd.mode_request == MODE_IDLE:
            if self.engaged:
                self._leave('the controller requested idle')
            self.rejected['idle_requested'] += 1
            return False
        if cmd.mode_request != MODE_TORQUE:
            self.rejected['bad_mode'] += 1
            self._latch(ERR_BAD_COMMAND, f'unknown mode request {cmd.mode_request}')
            return False
        if np.any(cmd.tau_ref[3:] != 0.0):
            self.rejected['wrist_torque'] += 1
            self._latch(ERR_BAD_COMMAND, 'torque for the locked joints 4-6 '
                        f'{cmd.tau_ref[3:].tolist()}')
            return False
        tau = cmd.tau_ref[:3]
        if np.any(np.abs(tau) > self.torque_limit):
            self.rejected['torque_limit'] += 1
            self._latch(ERR_TORQUE_LIMIT, f'torque {np.round(tau, 1).tolist()} N m over the '
                        'limit')
            return False
        self._command = tau.copy()
        self.engaged = True
        return True

    def _leave(self, why: str) -> None:
        """Leave external control without an error: brakes on, idle."""
        self.engaged = False
        q, t = self.plant.state.q.copy(), self.plant.state.t
        self.plant.reset(q, t=t)
        self.events.append(f'seq {self.seq}: {why}: brakes engaged (no error)')

    def _latch(self, flag: int, why: str) -> None:
        self.error |= flag
        self.engaged = False
        q, t = self.plant.state.q.copy(), self.plant.state.t
        self.plant.reset(q, t=t)          # brakes on, zero torque, command pipeline emptied
        self.events.append(f'seq {self.seq}: {why}: brakes engaged, error {self.error:#x} '
                           'latched until reset')

    def end_cycle(self) -> None:
        """Apply this cycle's command (or count a miss), advance the plant one period, and
        supervise the joints (position and speed limits) whatever the commands."""
        if self._command is not None:
            self.misses = 0
            self.plant.command(self._command)
        elif self.engaged and not self.latched:
            self.misses += 1
            self.missed_total += 1
            if self.misses >= self.miss_limit:
                self._latch(ERR_COMM_TIMEOUT, f'{self.misses} cycles without a command')
        self.plant.step()
        q, qd = self.plant.state.q, self.plant.state.qd
        if not self.latched:
            out = (q < self.q_lo) | (q > self.q_hi)
            if np.any(out):
                self._latch(ERR_POSITION_LIMIT, f'joint {int(np.argmax(out)) + 1} at '
                            f'{q[np.argmax(out)]:.3f} rad outside its limits')
            elif np.any(np.abs(qd) > self.v_max):
                i = int(np.argmax(np.abs(qd) - self.v_max))
                self._latch(ERR_SPEED_LIMIT, f'joint {i + 1} at {qd[i]:.3f} rad/s over its '
                            'speed limit')
