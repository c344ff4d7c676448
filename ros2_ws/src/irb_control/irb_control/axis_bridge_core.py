"""Bridge logic between the axis computer's UDP packets and ROS (no ROS, no sockets).

``BridgeCore`` decides, for every datagram and every controller command, what the node does:
publish a state, reply with a command, reject and count, or report link loss/recovery.
Times are seconds of a monotonic clock supplied by the caller.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from .axis_protocol import (CYCLE_S, MODE_IDLE, MODE_TORQUE, CommandPacket, ProtocolError,
                            SequenceTracker, StatePacket, decode_state, encode_command)


@dataclass
class BridgeStats:
    """Counters of the bridge; ``rejected`` maps a reason to its count."""

    states: int = 0             # valid state packets accepted and published
    commands_sent: int = 0
    late_commands: int = 0      # controller commands that arrived too late and were dropped
    unanswered: int = 0         # accepted states that got no command before the next one
    link_losses: int = 0
    resyncs: int = 0            # sessions or sequence jumps adopted after confirmation
    rejected: Counter = field(default_factory=Counter)   # size/magic/version/crc/nan/dup/stale


class BridgeCore:
    """State in, command out, with sequence checks and link supervision.

    A command is sent only for the newest accepted state, and only while that state is younger
    than ``max_command_age_s`` (one cycle by default): the bridge never sends a command older
    than one cycle. Which states are accepted is ``axis_protocol.SequenceTracker``'s rule
    (session id, bounded window, resynchronisation after ``resync_confirm`` consecutive states
    of a restarted axis computer); rejections are counted by reason. Commands echo the
    session of the state they answer.
    """

    def __init__(self, link_timeout_s: float = 0.1, max_command_age_s: float = CYCLE_S,
                 seq_window: int = 250, resync_confirm: int = 3):
        self.link_timeout_s = link_timeout_s
        self.max_command_age_s = max_command_age_s
        self.seq = SequenceTracker(seq_window, resync_confirm)
        self.stats = BridgeStats()
        self.last_state: StatePacket | None = None
        self._last_state_time: float | None = None
        self._answered = True
        self._reset_pending = False
        self.link_up = False

    def request_reset(self) -> None:
        """Commands carry reset = 1 until a state reports no error: a single reset command
        could be dropped or answer the wrong cycle, and the latched error would stay."""
        self._reset_pending = True

    def on_datagram(self, data: bytes, now: float) -> tuple[StatePacket | None, str | None]:
        """Validate a datagram. Returns (state to publish or None, link event or None).

        The event is 'up' for the first valid state, 'recovered' after a loss and 'resync'
        when the axis computer restarted (new session) or its sequence jumped.
        """
        try:
            state = decode_state(data)
        except ProtocolError as exc:
            self.stats.rejected[exc.reason] += 1
            return None, None
        verdict = self.seq.offer(state.session, state.seq)
        if verdict not in ('accept', 'resync'):
            self.stats.rejected[verdict] += 1
            return None, None
        resync = verdict == 'resync' and self.last_state is not None
        if not self._answered:
            self.stats.unanswered += 1
        event = 'resync' if resync else None
        if not self.link_up:
            event = 'up' if self.stats.link_losses == 0 else 'recovered'
            self.link_up = True
        if resync:
            self.stats.resyncs += 1
        self.last_state, self._last_state_time, self._answered = state, now, False
        if state.error == 0:
            self._reset_pending = False
        self.stats.states += 1
        return state, event

    def on_command(self, tau_ref: np.ndarray, now: float, stamp_ns: int = 0) -> bytes | None:
        """Controller command (6,) [N m] -> datagram for the newest state, or None if too late.

        Non-finite torques are never sent (counted as rejected 'command_nan').
        """
        tau = np.asarray(tau_ref, float)
        if tau.shape != (6,) or not np.all(np.isfinite(tau)):
            self.stats.rejected['command_nan'] += 1
            return None
        if (self.last_state is None or self._answered
                or now - self._last_state_time > self.max_command_age_s):
            self.stats.late_commands += 1
            return None
        self._answered = True
        self.stats.commands_sent += 1
        return encode_command(CommandPacket(self.last_state.seq, stamp_ns, tau, MODE_TORQUE,
                                            self._reset_pending, self.last_state.session))

    def reset_command(self, now: float) -> bytes | None:
        """A reset-only answer to the newest state while a reset is pending and that state
        reports a latched error: zero torque, ``mode_request`` idle, reset = 1. After a fault
        the controller is stopped and sends no commands, so a reset carried only by its commands
        would never reach the axis computer (and the controller refuses to enable while the
        error is latched). The axis computer clears the error and stays on its brakes; the next
        torque command engages again. None when nothing is to be sent."""
        st = self.last_state
        if (not self._reset_pending or st is None or st.error == 0 or self._answered
                or now - self._last_state_time > self.max_command_age_s):
            return None
        self._answered = True
        self.stats.commands_sent += 1
        return encode_command(CommandPacket(st.seq, 0, np.zeros(6), MODE_IDLE, True,
                                            st.session))

    def check_link(self, now: float) -> str | None:
        """'lost' once when no valid state arrived for ``link_timeout_s``, else None."""
        if self.link_up and (self._last_state_time is None
                             or now - self._last_state_time > self.link_timeout_s):
            self.link_up = False
            self.stats.link_losses += 1
            return 'lost'
        return None
