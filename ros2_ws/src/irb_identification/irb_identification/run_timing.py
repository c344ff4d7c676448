"""When an identification run (experiments, ROS mode) is over: on what happens, not on a clock.

No rclpy. The simulator may run in lockstep on simulated time (``/clock``), many times faster
than real time, so a run cannot be timed with the wall clock. ``RunMonitor`` follows pdplus's
``irb_interfaces/msg/ControllerState`` (its header stamp [s] and ``mode``) and the stamps of
the joint states the run's recorder has written::

    READY --start(t_pub)--> WAIT_START --RAMP/TIME stamped after t_pub--> RUNNING
    RUNNING --HOLD after TIME--> MARGIN --recorded joint state stamped >= t_hold + margin--> DONE
    any state after start --STOPPED--> FAILED (stop reason)
    WAIT_START --no start within start_timeout_s of simulated time after enabled()--> FAILED

Only a motion that starts after the trajectory was published counts: right after publishing,
pdplus still reports HOLD of the previous run (or runs something else). The caller makes sure
pdplus is not moving before it publishes (``is_moving``), so the motion that starts next is the
run's own. All times are the graph's (simulated) time from message stamps, so a slow machine
changes how long a run takes on the wall clock but not what is recorded.
The callers read stamps and modes from the recorder's serialized messages with
``header_stamp`` / ``controller_state_head`` below (plain CDR reads, no message types).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

# ControllerState modes: the constants of irb_interfaces/msg/ControllerState, the contract
# pdplus publishes (test_run_timing checks them against the generated message class)
MODE_IDLE, MODE_RAMP, MODE_PATH, MODE_TIME, MODE_STOPPED, MODE_HOLD = range(6)
MODE_NAMES = {MODE_IDLE: 'idle', MODE_RAMP: 'ramp', MODE_PATH: 'path', MODE_TIME: 'time',
              MODE_STOPPED: 'stopped', MODE_HOLD: 'hold'}

MOVING = (MODE_RAMP, MODE_PATH, MODE_TIME)

# run phases
READY = 'ready'
WAIT_START = 'wait_start'
RUNNING = 'running'
MARGIN = 'margin'
DONE = 'done'
FAILED = 'failed'


@dataclass
class RunMonitor:
    """One run's progress from controller states and recorded joint-state stamps.

    margin_s [s]: simulated time recorded after pdplus reaches HOLD; start_timeout_s [s]:
    simulated time after ``enabled`` within which pdplus must start (RAMP or TIME). Between
    publishing and enable pdplus checks the plan (its plan gate, wall-clock work while a
    lockstep simulator's time runs on): that wait is the caller's, bounded on the wall clock.
    Feed ``on_state`` with every controller state and ``on_recorded`` with the stamp of
    every recorded joint state (or the latest one); read ``phase``, ``error``, ``t_hold``.
    """

    margin_s: float = 1.5
    start_timeout_s: float = 5.0
    phase: str = READY
    mode: int | None = None            # latest controller mode seen
    t_state: float | None = None       # stamp [s] of the latest controller state
    t_recorded: float | None = None    # stamp [s] of the latest recorded joint state
    t_publish: float | None = None
    t_enable: float | None = None      # graph time when pdplus accepted enable
    t_start: float | None = None       # first RAMP/TIME after publishing
    t_time: float | None = None        # first TIME (the trajectory itself)
    t_hold: float | None = None
    error: str = ''

    @property
    def is_moving(self) -> bool:
        """pdplus is executing a motion (or nothing is known about it yet)."""
        return self.mode is None or self.mode in MOVING

    @property
    def finished(self) -> bool:
        return self.phase in (DONE, FAILED)

    @property
    def t_end(self) -> float | None:
        """Stamp [s] up to which the run must be recorded (None before HOLD)."""
        return None if self.t_hold is None else self.t_hold + self.margin_s

    def start(self, t_publish: float) -> None:
        """The run's trajectory was published when the graph's time was ``t_publish`` [s]."""
        if self.phase != READY:
            raise RuntimeError(f'start() in phase {self.phase}')
        self.t_publish = float(t_publish)
        self.phase = WAIT_START

    def enabled(self, t_enable: float) -> None:
        """pdplus accepted enable when the graph's time was ``t_enable`` [s]: the start
        timeout runs from here."""
        self.t_enable = float(t_enable)

    def fail(self, text: str) -> None:
        """End the run as failed with ``text`` (first failure wins)."""
        if self.phase != FAILED:
            self.phase = FAILED
            self.error = text

    def on_state(self, stamp: float, mode: int, stop_reason: str = '') -> None:
        """A controller state stamped ``stamp`` [s] with ``mode``."""
        if self.t_state is not None and stamp < self.t_state:
            return                                  # out of order: keep the newest
        self.t_state, self.mode = stamp, mode
        if self.phase in (READY, DONE, FAILED):
            return
        if mode == MODE_STOPPED and self.phase != WAIT_START:
            self.fail(f'pdplus stopped at t = {stamp:.3f} s: {stop_reason or "no reason"}')
            return
        if self.phase == WAIT_START:
            if stamp > self.t_publish and mode in (MODE_RAMP, MODE_TIME):
                self.t_start = stamp
                self.phase = RUNNING
            elif self.t_enable is not None and stamp - self.t_enable > self.start_timeout_s:
                self.fail(f'pdplus did not start the trajectory within {self.start_timeout_s}'
                          f' s of simulated time after enable (mode {MODE_NAMES.get(mode, mode)}'
                          + (f': {stop_reason}' if stop_reason else '')
                          + '; rejected? auto_enable off? see the pdplus log)')
                return
        if self.phase == RUNNING:
            if mode == MODE_TIME and self.t_time is None:
                self.t_time = stamp
            elif mode == MODE_HOLD and self.t_time is not None:
                self.t_hold = stamp
                self.phase = MARGIN
            elif mode not in (MODE_RAMP, MODE_TIME):
                self.fail(f'pdplus left the run in mode {MODE_NAMES.get(mode, mode)} '
                          f'at t = {stamp:.3f} s')
                return
        if self.phase == MARGIN:
            self._check_margin()

    def on_recorded(self, stamp: float) -> None:
        """The run's recorder wrote a joint state stamped ``stamp`` [s]."""
        if self.t_recorded is None or stamp > self.t_recorded:
            self.t_recorded = stamp
        if self.phase == MARGIN:
            self._check_margin()

    def _check_margin(self) -> None:
        if self.t_recorded is not None and self.t_recorded >= self.t_end:
            self.phase = DONE


def header_stamp(data: bytes) -> float:
    """Header stamp [s] of a serialized message whose first field is a std_msgs/Header.
    ValueError when the data is too short or not plain CDR."""
    if len(data) < 12 or data[0] != 0 or data[1] not in (0, 1):
        raise ValueError(f'not a serialized message with a header ({len(data)} bytes)')
    sec, nanosec = struct.unpack_from('<iI' if data[1] else '>iI', data, 4)
    return sec + nanosec * 1e-9


def controller_state_head(data: bytes) -> tuple[float, int, str]:
    """(stamp [s], mode, stop_reason) of a serialized irb_interfaces/ControllerState, without
    reading its arrays. ValueError when it is truncated or not plain CDR."""
    stamp = header_stamp(data)
    u32 = struct.Struct('<I' if data[1] else '>I').unpack_from
    try:
        (n,) = u32(data, 12)                        # frame_id length incl. NUL
        o = 12 + n                                  # payload offset of the mode (uint8)
        mode = data[4 + o]
        o += 1
        o += -o % 4                                 # stop_reason length, aligned to 4
        (m,) = u32(data, 4 + o)
        reason = data[4 + o + 4:4 + o + 4 + max(m - 1, 0)].decode('utf-8', 'replace')
    except (struct.error, IndexError) as exc:
        raise ValueError(f'truncated ControllerState ({len(data)} bytes)') from exc
    return stamp, int(mode), reason
