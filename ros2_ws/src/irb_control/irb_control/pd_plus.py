"""theta-driven inverse-dynamics PD+ controller with friction compensation (thesis §4.3, §6.4).

Plain class, numpy in/out, no ROS imports. Per step (period T = 0.004032 s), from the measured
q, qd (n,) at time t [s] (n = the model's joints: 3 for the thesis's ``RobotModel``, the
hand-unrolled ``step``; 6 for ``irb_description.six_axis_model.SixJointModel``, ``_step_n``,
the same operations on n-vectors -- on three joints equal to ``step`` to the bit, tested):

1. theta = atan2 of FK(q) about the path centre (unwrapped, clamped to the profile), predicted
   ``prediction_samples`` (n = 3) samples ahead by integrating theta_dot = h(theta) (Euler, T).
   Progress governor (not in the thesis): the prediction starts from theta_v, which advances
   at h(theta_v) each period but is kept within [theta, theta + theta_max_lead_rad]. With the
   lead 0 this is the thesis's purely measured theta, which never leaves a pose where
   stiction holds the robot (thesis §6.1); a small lead (0.05 rad = 7.5 mm on the thesis
   circle) lets the feedback break stiction while the reference still waits for a robot that
   falls behind;
   q and qd are predicted over the same Delta = n T (``delay_prediction``): with the
   accelerations of the n commands still in flight (the reference accelerations they were
   computed for: those act on the plant during [t, t + Delta)), or, on the thesis circle,
   with the reference acceleration at t + Delta (the thesis's rule, kept there to the bit).
   The two agree where the reference acceleration is smooth; where it steps (a blend's end,
   a trapezoid's switch) the second mispredicts qd by the step times Delta for n samples
   (0.05 rad/s and 41 N m of wrong Kd torque on joint 1 through the 25 mm blends of the
   rectangle at 0.25 m/s: its 0.50 mm path error peaks came from that).
2. References q_ref, qd_ref, qdd_ref interpolated from the theta-profile at the predicted theta
   (or from q(t + Delta) of a time trajectory in the time-driven mode, or from the 0.5 s
   quintic ramp from the pose at enable to the start of the motion).
3. PD+ (eq. in DESIGN §5): tau = M(q) qdd_ref + C(q, qd) qd_ref + g(q) + tau_f(v)
   + Kp (q_ref - q) + Kd (qd_ref - qd), with v = alpha qd_ref + (1 - alpha) qd,
   alpha = exp(-qd_ref^2 / (2 a^2)), a = 0.25 rad/s (eq. 4.9-4.10).
4. Safety: non-finite or malformed inputs are rejected (no command for that sample); a
   non-finite torque, |qd| above the speed limit, q outside the position limits or a tracking
   error above ``max_tracking_error_rad`` latch the STOPPED state (no more commands: the drive
   brakes after its command timeout) until ``enable``; the command is rate limited and then
   clipped to the torque limits.

One explicit state machine (``TRANSITIONS``: every state x every event, with its reason; the
tests walk the whole table). A plan offered in any state is stored as the *pending* profile:
it never changes the reference of a running motion or of the hold, and never clears a latched
stop. Only ``enable`` (in IDLE, HOLD or STOPPED) takes the pending profile and starts the ramp
from where the robot is; the stop reason stays readable after the stop is cleared
(``last_stop_reason``). ``hold`` (a controlled stop, no latched error) lets a moving reference
decelerate along itself -- its progress rate falling smoothly from 1 to 0 -- and then holds
the pose it came to rest at (HOLD, motors on).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from irb_description.friction import FrictionMap, JointFriction
from irb_description.model import RobotModel
from irb_description.path import CirclePath, PathBase
from irb_description.path_tracking import PathTracker

from .profiles import PathProfile, TimeTrajectory

PERIOD_S = 0.004032
DELAY_PREDICTIONS = ('auto', 'commanded', 'reference')

# Modes, equal to the constants of irb_interfaces/msg/ControllerState
MODE_IDLE = 0
MODE_RAMP = 1
MODE_PATH = 2
MODE_TIME = 3
MODE_STOPPED = 4
MODE_HOLD = 5
MODE_NAMES = {MODE_IDLE: 'idle', MODE_RAMP: 'ramp', MODE_PATH: 'path', MODE_TIME: 'time',
              MODE_STOPPED: 'stopped', MODE_HOLD: 'hold'}
MOVING = (MODE_RAMP, MODE_PATH, MODE_TIME)
DITHER_MODES = (MODE_PATH, MODE_TIME, MODE_HOLD)     # where the stiction dither acts
_SLIDE_SUBSTEPS = 4          # substeps per period of the stiction prediction's joint model

# events of the state machine
EV_ENABLE = 'enable'          # operator (or the documented auto-enable at start-up)
EV_STOP = 'stop'              # operator stop, watchdog, fault, safety trip
EV_PLAN = 'plan'              # a validated plan is offered
EV_RAMP_DONE = 'ramp_done'    # the ramp reached the start of the profile
EV_MOTION_DONE = 'motion_done'  # the profile ended
EV_HOLD = 'hold'              # operator: controlled stop along the reference, then hold
EV_MOTORS_OFF = 'motors_off'  # the drives engaged their brakes on request (a deeper mode)
EV_MOTORS_ON = 'motors_on'    # the drives are back in hold: hold the pose they stand at
EVENTS = (EV_ENABLE, EV_STOP, EV_PLAN, EV_RAMP_DONE, EV_MOTION_DONE, EV_HOLD, EV_MOTORS_OFF,
          EV_MOTORS_ON)
_ARRIVE = 'PATH or TIME'      # the profile's own mode (theta- or time-driven)

#: (state, event) -> (next state, or None = refused and nothing changes; why)
TRANSITIONS = {
    (MODE_IDLE, EV_ENABLE): (MODE_RAMP, 'ramp from the current pose to the start'),
    (MODE_IDLE, EV_STOP): (MODE_STOPPED, 'stop latched'),
    (MODE_IDLE, EV_PLAN): (MODE_IDLE, 'stored as the pending profile'),
    (MODE_IDLE, EV_RAMP_DONE): (None, 'not ramping'),
    (MODE_IDLE, EV_MOTION_DONE): (None, 'not moving'),
    (MODE_RAMP, EV_ENABLE): (None, 'already running (ramp)'),
    (MODE_RAMP, EV_STOP): (MODE_STOPPED, 'stop latched'),
    (MODE_RAMP, EV_PLAN): (MODE_RAMP, 'stored as pending: the running motion is not changed'),
    (MODE_RAMP, EV_RAMP_DONE): (_ARRIVE, 'start of the profile reached'),
    (MODE_RAMP, EV_MOTION_DONE): (None, 'the ramp ends with ramp_done'),
    (MODE_PATH, EV_ENABLE): (None, 'already running (path)'),
    (MODE_PATH, EV_STOP): (MODE_STOPPED, 'stop latched'),
    (MODE_PATH, EV_PLAN): (MODE_PATH, 'stored as pending: the running motion is not changed'),
    (MODE_PATH, EV_RAMP_DONE): (None, 'not ramping'),
    (MODE_PATH, EV_MOTION_DONE): (MODE_HOLD, 'end of the path: hold the final pose'),
    (MODE_TIME, EV_ENABLE): (None, 'already running (time)'),
    (MODE_TIME, EV_STOP): (MODE_STOPPED, 'stop latched'),
    (MODE_TIME, EV_PLAN): (MODE_TIME, 'stored as pending: the running motion is not changed'),
    (MODE_TIME, EV_RAMP_DONE): (None, 'not ramping'),
    (MODE_TIME, EV_MOTION_DONE): (MODE_HOLD, 'end of the trajectory: hold the final pose'),
    (MODE_HOLD, EV_ENABLE): (MODE_RAMP, 'ramp from the held pose to the (pending) profile'),
    (MODE_HOLD, EV_STOP): (MODE_STOPPED, 'stop latched'),
    (MODE_HOLD, EV_PLAN): (MODE_HOLD, 'stored as pending: the hold is not changed'),
    (MODE_HOLD, EV_RAMP_DONE): (None, 'not ramping'),
    (MODE_HOLD, EV_MOTION_DONE): (None, 'already holding'),
    (MODE_STOPPED, EV_ENABLE): (MODE_RAMP, 'latched stop cleared by enable; ramp from the '
                                           'current pose'),
    (MODE_STOPPED, EV_STOP): (MODE_STOPPED, 'already stopped (the first reason is kept)'),
    (MODE_STOPPED, EV_PLAN): (MODE_STOPPED, 'stored as pending: a plan never clears a stop'),
    (MODE_STOPPED, EV_RAMP_DONE): (None, 'stopped'),
    (MODE_STOPPED, EV_MOTION_DONE): (None, 'stopped'),
    # hold: the motion decelerates along its own reference (same mode meanwhile), then HOLD
    (MODE_IDLE, EV_HOLD): (None, 'idle: no pose is held (motors off); enable starts a motion'),
    (MODE_RAMP, EV_HOLD): (MODE_HOLD, 'controlled stop along the ramp, then hold the pose'),
    (MODE_PATH, EV_HOLD): (MODE_HOLD, 'controlled stop along the path, then hold the pose'),
    (MODE_TIME, EV_HOLD): (MODE_HOLD, 'controlled stop along the trajectory, then hold the '
                                      'pose'),
    (MODE_HOLD, EV_HOLD): (MODE_HOLD, 'already holding'),
    (MODE_STOPPED, EV_HOLD): (None, 'stopped (latched): a hold never clears a stop; enable '
                                    'clears it'),
    # power modes: brakes only at rest (idle, or holding and measured at rest); back on, the
    # pose the brakes hold is held by the motors (the gravity torque acts before release)
    (MODE_IDLE, EV_MOTORS_OFF): (MODE_IDLE, 'motors off on the brakes'),
    (MODE_RAMP, EV_MOTORS_OFF): (None, 'moving (ramp): brakes only at rest; hold first'),
    (MODE_PATH, EV_MOTORS_OFF): (None, 'moving (path): brakes only at rest; hold first'),
    (MODE_TIME, EV_MOTORS_OFF): (None, 'moving (time): brakes only at rest; hold first'),
    (MODE_HOLD, EV_MOTORS_OFF): (MODE_IDLE, 'motors off on the brakes (from hold)'),
    (MODE_STOPPED, EV_MOTORS_OFF): (MODE_STOPPED, 'stopped: the brakes are engaged already'),
    (MODE_IDLE, EV_MOTORS_ON): (MODE_HOLD, 'motors on: hold the pose the brakes held'),
    (MODE_RAMP, EV_MOTORS_ON): (None, 'moving: the motors are on'),
    (MODE_PATH, EV_MOTORS_ON): (None, 'moving: the motors are on'),
    (MODE_TIME, EV_MOTORS_ON): (None, 'moving: the motors are on'),
    (MODE_HOLD, EV_MOTORS_ON): (MODE_HOLD, 'already holding'),
    (MODE_STOPPED, EV_MOTORS_ON): (None, 'stopped (latched): enable clears it'),
}


def friction_blend(qd_ref: np.ndarray, qd_meas: np.ndarray, a: float = 0.25) -> np.ndarray:
    """Friction-compensation input speed v (3,) [rad/s] (thesis eq. 4.9-4.10).

    v = alpha qd_ref + (1 - alpha) qd_meas, alpha = exp(-qd_ref^2 / (2 a^2)), a [rad/s].
    Near zero reference speed v follows the reference (the measured speed is unreliable there
    because of stiction); at high reference speed it follows the measurement.
    """
    qd_ref = np.asarray(qd_ref, float)
    alpha = np.exp(-qd_ref**2 / (2.0 * a * a))
    return alpha * qd_ref + (1.0 - alpha) * np.asarray(qd_meas, float)


def quintic_ramp(q0: np.ndarray, q1: np.ndarray, duration: float, t: float):
    """Rest-to-rest ramp q0 -> q1 (3,) [rad] in ``duration`` [s] at time t [s] since its start.

    s(u) = 10 u^3 - 15 u^4 + 6 u^5, u = t / duration; returns q, qd, qdd (3,) each.
    """
    u = min(max(t / duration, 0.0), 1.0)
    s = u**3 * (10 - 15 * u + 6 * u * u)
    ds = 30 * u * u * (1 - u) ** 2 / duration
    dds = 60 * u * (1 - u) * (1 - 2 * u) / duration**2
    d = np.asarray(q1, float) - np.asarray(q0, float)
    return q0 + s * d, ds * d, dds * d


def _halt_rate(halt: tuple, r: float) -> tuple:
    """A controlled stop (r_s, T_s, v_s) at reference time r [s]: the progress rate
    k = 1 - 3u^2 + 2u^3 (u = (r - r_s) / T_s in [0, 1]), dk/dt, the virtual time
    v_s + T_s (u - u^3 + u^4 / 2) (the integral of k) and u."""
    r_s, T_s, v_s = halt
    u = min(max((r - r_s) / T_s, 0.0), 1.0)
    return (1.0 - u * u * (3.0 - 2.0 * u), -6.0 * u * (1.0 - u) / T_s,
            v_s + T_s * (u - u ** 3 + 0.5 * u ** 4), u)


def _scaled(q, qd, qdd, k: float, k_dot: float) -> tuple:
    """References along the same curve run at the rate k: qd k, qdd k^2 + qd dk/dt."""
    return (q, [x * k for x in qd],
            [qdd[i] * k * k + qd[i] * k_dot for i in range(len(qd))])


def gain_scale(m_diag, design) -> np.ndarray:
    """Factor (n,) on kp_i and kd_i: min(1, M_ii(q) / design_i), design (n,) [kg m^2] the
    inertia the gains were tuned for (None: ones, constant gains). The controller applies the
    same rule in plain floats (``PdPlusController._gains``)."""
    m = np.asarray(m_diag, float)
    if design is None:
        return np.ones_like(m)
    return np.minimum(1.0, m / np.asarray(design, float))


def ramp_duration(q0: np.ndarray, q1: np.ndarray, velocity_limit: np.ndarray,
                  minimum: float = 0.5, speed_fraction: float = 0.5) -> float:
    """Ramp time [s]: ``minimum`` (0.5 s, thesis §6.4.4), longer if the quintic's peak speed
    1.875 |dq| / T would exceed ``speed_fraction`` of the speed limit."""
    need = 1.875 * np.abs(np.asarray(q1) - np.asarray(q0)) / (speed_fraction * velocity_limit)
    return float(max(minimum, np.max(need)))


@dataclass(frozen=True)
class ControllerConfig:
    """PD+ settings; arrays (n,) per joint (n = the model's joints; the defaults are the three
    axes'), SI units. ``None`` limits come from the model."""

    kp: tuple = (14000.0, 9000.0, 2500.0)         # [N m/rad]
    kd: tuple = (800.0, 500.0, 140.0)             # [N m s/rad]
    #: [kg m^2] the inertia M_ii the gains were tuned for (kp ~ M_ii w^2, kd ~ 2 zeta w M_ii
    #: at the thesis circle); where M_ii(q) is smaller, kp_i and kd_i are scaled by
    #: M_ii(q) / this (never above the configured gains); None = constant gains (thesis)
    gain_design_inertia_kg_m2: tuple | None = (22.0, 15.0, 4.0)
    period_s: float = PERIOD_S
    prediction_samples: int = 3
    ramp_min_duration_s: float = 0.5
    ramp_speed_fraction: float = 0.5
    friction_blend_a: float = 0.25                # a [rad/s], eq. 4.9
    torque_limit_nm: tuple | None = None          # default: model.limits.torque
    torque_rate_limit_nm_s: tuple = (20000.0, 20000.0, 10000.0)
    velocity_limit_fraction: float = 1.0          # of model.limits.velocity -> safe stop
    position_margin_rad: float = 0.0              # stop this far inside the position limits
    max_tracking_error_rad: tuple = (0.05, 0.05, 0.05)
    end_tolerance_rad: float = 1e-3               # theta_v within this of the end: hold
    #: controlled stop (``hold``): the reference's progress rate falls from 1 to 0 as
    #: 1 - 3u^2 + 2u^3 over T_s = max(hold_min_duration_s, 1.5 max_i |qd_ref_i| / a_i), a_i
    #: the motion's own peak acceleration of joint i (not below hold_min_deceleration)
    hold_min_duration_s: float = 0.2              # [s]
    hold_min_deceleration_rad_s2: float = 0.5     # [rad/s^2]
    theta_max_lead_rad: float = 0.05              # progress governor, 0 = pure thesis
    #: how q, qd are carried over the delay: 'commanded' (accelerations of the commands in
    #: flight), 'reference' (the reference acceleration at t + Delta, the thesis's rule), or
    #: 'auto' = 'reference' on the thesis's CirclePath, 'commanded' on every other path
    delay_prediction: str = 'auto'
    #: integral action (n joints, ``_step_n`` only; None = none, the thesis's PD+): per joint
    #: Ki [N m/(rad s)] on the predicted position error, its torque clamped to
    #: +-integral_limit_nm [N m] and not integrated while the command is limited in the
    #: error's direction (anti-windup); zero in IDLE/STOPPED, reset by enable, stop, motors
    #: off/on. For the wrist's stiction: a creeping joint that sticks off its reference is
    #: pushed through the breakaway by the integral instead of waiting for Kp e.
    ki: tuple | None = None                       # [N m/(rad s)]
    integral_limit_nm: tuple | None = None        # [N m]
    #: per joint, where the friction feed-forward's Stribeck hump (F_s - F_c) exp(-(v/v_s)^2)
    #: takes its speed: False = v of eq. 4.9 as the rest of the map (the thesis), True = the
    #: predicted measured speed (``_step_n`` only): the breakaway torque while the joint
    #: sticks, Coulomb as soon as it slides, as the friction itself (for creeping joints);
    #: None = False on every joint
    stribeck_measured: tuple | None = None
    #: stiction dither (n joints, ``_step_n`` only; None = none): a square wave of +-a_i
    #: [N m] per joint, period ``dither_period_samples`` (even, >= 2) controller samples,
    #: added to the command only while a command is published in PATH, TIME or HOLD (never
    #: in the ramp, IDLE or STOPPED; its phase restarts on enable, stop, motors off/on); it
    #: goes through the rate and torque limits like the rest of the command. The classical
    #: remedy for stick-slip: the joint's friction is averaged over the dither's swing.
    #: with ``stribeck_measured``: the measured speed the hump takes is carried over the
    #: delay by a one-joint stick-slip model of the commands still in flight (their torque
    #: beyond the model terms, the reference accelerations, M_ii, the controller's friction
    #: map; a joint measured below ``stiction_rest_speed_rad_s`` starts at rest): the hump
    #: switches off when the joint is predicted to have broken away, not 3 samples later
    stiction_prediction: bool = False
    stiction_rest_speed_rad_s: float = 0.003      # [rad/s]
    dither_amplitude_nm: tuple | None = None      # [N m]
    dither_period_samples: int = 2                # [samples]

    @property
    def joints(self) -> int:
        """The joint count of the per-joint arrays (the model must have as many)."""
        return len(self.kp)

    def __post_init__(self):
        n = len(np.atleast_1d(self.kp))
        for name in ('kp', 'kd', 'torque_rate_limit_nm_s', 'max_tracking_error_rad'):
            v = np.asarray(getattr(self, name), float)
            if v.shape != (n,) or not np.all(np.isfinite(v)) or np.any(v < 0):
                raise ValueError(f'{name} must be {n} finite numbers >= 0, got {v}')
        if self.gain_design_inertia_kg_m2 is not None:
            v = np.asarray(self.gain_design_inertia_kg_m2, float)
            if v.shape != (n,) or not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(f'gain_design_inertia_kg_m2 must be {n} finite numbers > 0 '
                                 f'or None, got {v}')
        if self.torque_limit_nm is not None:
            v = np.asarray(self.torque_limit_nm, float)
            if v.shape != (n,) or not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(f'torque_limit_nm must be {n} finite numbers > 0')
        for name in ('ki', 'integral_limit_nm'):
            v = getattr(self, name)
            if v is None:
                continue
            v = np.asarray(v, float)
            if v.shape != (n,) or not np.all(np.isfinite(v)) or np.any(v < 0):
                raise ValueError(f'{name} must be {n} finite numbers >= 0, got {v}')
        if self.stribeck_measured is not None and (
                len(self.stribeck_measured) != n
                or any(not isinstance(x, (bool, np.bool_)) for x in self.stribeck_measured)):
            raise ValueError(f'stribeck_measured must be {n} booleans, got '
                             f'{self.stribeck_measured}')
        if self.dither_amplitude_nm is not None:
            v = np.asarray(self.dither_amplitude_nm, float)
            if v.shape != (n,) or not np.all(np.isfinite(v)) or np.any(v < 0):
                raise ValueError(f'dither_amplitude_nm must be {n} finite numbers >= 0, got '
                                 f'{v}')
        if (not isinstance(self.dither_period_samples, (int, np.integer))
                or self.dither_period_samples < 2 or self.dither_period_samples % 2):
            raise ValueError(f'dither_period_samples must be an even integer >= 2, got '
                             f'{self.dither_period_samples!r}')
        if not (math.isfinite(self.stiction_rest_speed_rad_s)
                and self.stiction_rest_speed_rad_s >= 0):
            raise ValueError(f'stiction_rest_speed_rad_s must be >= 0, got '
                             f'{self.stiction_rest_speed_rad_s}')
        if self.stiction_prediction and not (self.stribeck_measured is not None
                                             and any(self.stribeck_measured)):
            raise ValueError('stiction_prediction needs stribeck_measured joints (it predicts '
                             'the speed their Stribeck term takes)')
        if (self.ki is None) != (self.integral_limit_nm is None):
            raise ValueError('ki and integral_limit_nm go together (the integral is bounded)')
        if self.delay_prediction not in DELAY_PREDICTIONS:
            raise ValueError(f'delay_prediction must be one of {DELAY_PREDICTIONS}, got '
                             f'{self.delay_prediction!r}')
        if not (self.period_s > 0 and self.prediction_samples >= 0
                and self.ramp_min_duration_s > 0 and self.friction_blend_a > 0
                and 0 < self.ramp_speed_fraction <= 1 and self.velocity_limit_fraction > 0):
            raise ValueError(f'invalid controller settings: {self}')


@dataclass
class ControlOutput:
    """Result of one step. ``publish`` False: send no command for this sample.

    tau (3,) [N m] is always finite (zeros when no command). The other fields are for the
    ControllerState message (NaN when not defined in the current mode).
    """

    publish: bool
    tau: np.ndarray
    mode: int
    stop_reason: str = ''
    theta: float = math.nan
    theta_predicted: float = math.nan
    theta_dot_ref: float = math.nan
    q_ref: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    qd_ref: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    qdd_ref: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    q_error: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    qd_error: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    tau_model: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    tau_friction: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    tau_feedback: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    rejected_input: bool = False


def _parametric_friction(friction: FrictionMap | None) -> list | None:
    """Per joint (F_c+, F_c-, hump+, hump-, v_s, F_v, tau_0) when every joint of ``friction``
    is purely parametric (JointFriction.parametric), else None (FrictionMap.torque is used).
    F_c+- = F_c, humps F_s - F_c and tau_0 = 0 for maps without asymmetry and offset."""
    if friction is None:
        return None
    out = []
    for j in friction.joints:
        if (type(j) is not JointFriction or j.polynomial_positive is not None
                or j.polynomial_negative is not None):
            return None
        hp, hn = j.humps()
        out.append((j.coulomb_positive, j.coulomb_negative, hp, hn, j.stribeck_velocity,
                    j.viscous, j.offset))
    return out


class Watchdog:
    """Stale-measurement detector on a monotonic clock.

    ``feed(now)`` on every valid sample; ``expired(now)`` is True once more than
    ``missed_samples`` periods (plus half a period) passed without one.
    """

    def __init__(self, period_s: float = PERIOD_S, missed_samples: int = 3,
                 minimum_timeout_s: float = 0.0):
        self.timeout_s = max((missed_samples + 0.5) * period_s, minimum_timeout_s)
        self.last: float | None = None

    def feed(self, now: float) -> None:
        self.last = now

    def reset(self) -> None:
        self.last = None

    def expired(self, now: float) -> bool:
        return self.last is not None and now - self.last > self.timeout_s


class SettleGate:
    """Has a sample stream been steady for ``settle_s`` [s]? (auto-enable at start-up)

    ``feed(now)`` on every sample's arrival [s, any monotonic clock] returns True once the
    samples have kept coming without a gap of more than ``max_gap_periods`` periods for at
    least ``settle_s``; a longer gap starts the count again.
    """

    def __init__(self, settle_s: float, period_s: float = PERIOD_S,
                 max_gap_periods: float = 3.0):
        self.settle_s = max(float(settle_s), 0.0)
        self.max_gap_s = max_gap_periods * period_s
        self.since: float | None = None
        self.last: float | None = None

    def feed(self, now: float) -> bool:
        if self.last is None or now - self.last > self.max_gap_s:
            self.since = now
        self.last = now
        return now - self.since >= self.settle_s


class PdPlusController:
    """The controller state machine; see the module docstring.

    IDLE --enable--> RAMP --> PATH (theta-driven) or TIME (time-driven) --> HOLD (end pose);
    any --stop/abort--> STOPPED (latched) --enable--> RAMP. The profile is set with
    ``set_path_profile`` or ``set_time_trajectory`` (only while not moving).
    """

    def __init__(self, model: RobotModel, path: PathBase, config: ControllerConfig =
                 ControllerConfig(), friction: FrictionMap | None = None):
        self.model = model.copy()
        self._pm, self._pd = self.model.model, self.model.data
        self.n = n = int(self._pm.nq)          # joints: 3 (thesis) or 6 (the whole arm)
        if config.joints != n:
            raise ValueError(f'the controller settings have {config.joints} joints, the model '
                             f'{n}')
        if friction is not None and len(friction.joints) != n:
            raise ValueError(f'the friction map has {len(friction.joints)} joints, the model '
                             f'{n}')
        self.path = path
        self.config = config
        self.friction = friction
        c = config
        self.kp = np.asarray(c.kp, float)
        self.kd = np.asarray(c.kd, float)
        self._m_design = (None if c.gain_design_inertia_kg_m2 is None
                          else [float(x) for x in c.gain_design_inertia_kg_m2])
        # integral action (ControllerConfig.ki): gains, clamp, the integral torque [N m]
        self._ki = None if c.ki is None else np.asarray(c.ki, float).tolist()
        self._i_lim = None if c.ki is None else np.asarray(c.integral_limit_nm,
                                                           float).tolist()
        self._integral = [0.0] * n
        # stiction dither (ControllerConfig.dither_amplitude_nm): amplitudes, sample counter
        self._dither = (None if c.dither_amplitude_nm is None
                        or not any(c.dither_amplitude_nm)
                        else [float(x) for x in c.dither_amplitude_nm])
        self._dither_k = 0
        self._hump_measured = (None if c.stribeck_measured is None
                               or not any(c.stribeck_measured)
                               else [bool(x) for x in c.stribeck_measured])
        lim = self.model.limits
        self.tau_max = lim.torque.copy() if c.torque_limit_nm is None else np.asarray(
            c.torque_limit_nm, float)
        self.rate_max = np.asarray(c.torque_rate_limit_nm_s, float) * c.period_s  # per step
        self.v_max = lim.velocity * c.velocity_limit_fraction
        self.q_lo = lim.lower + c.position_margin_rad
        self.q_hi = lim.upper - c.position_margin_rad
        self.e_max = np.asarray(c.max_tracking_error_rad, float)
        self.delta = c.prediction_samples * c.period_s
        #: called with a profile the controller lets go of (None: dropped here at once); a
        #: node frees it on another thread in slices (profiles.dispose_sliced)
        self.retire = None
        self.active: PathProfile | TimeTrajectory | None = None    # the running reference
        self.pending: PathProfile | TimeTrajectory | None = None   # offered, not yet enabled
        self.mode = MODE_IDLE
        self.stop_reason = ''
        self.last_stop_reason = ''
        self._hold = None            # (q, qd = 0, qdd = 0) frozen when HOLD is entered
        self.rejected_inputs = 0
        self._enable_requested = False
        self._prev_tau: np.ndarray | None = None
        self._halt_T: float | None = None     # hold requested: stop duration T_s [s] ...
        self._halt: tuple | None = None       # ... then (r_s, T_s, v_s) from the next step
        self._last_qd_ref = [0.0] * n         # the last command's reference speed
        self._theta = 0.0
        self._theta_v = 0.0
        self._t0 = 0.0
        self._ramp_from = np.zeros(n)
        self._ramp_to = np.zeros(n)
        self._lower = np.tril_indices(n, -1)    # strictly lower triangle (``_step_n``)
        # ``_step_n``'s model terms and friction: on three joints the operations of ``step``
        # (numpy's exp, crba + Coriolis matrix + gravity: the same result to the bit, tested);
        # on any other joint count the cheaper formulation of the same quantities (one
        # rounding apart: two RNEA passes, math.exp on floats; ``_model_terms_n``)
        self._fast = n != 3
        self._pm0 = pin.Model(self._pm)             # the same arm without gravity
        self._pm0.gravity.linear[:] = 0.0
        self._pd0 = self._pm0.createData()
        self._zero_a = np.zeros(n)
        # ``_model_terms_n``'s operands, filled in place each step (a slice assignment from a
        # list costs about a third of np.array(list); pinocchio keeps no reference to them)
        self._buf = np.zeros((4, n))
        self._ramp_T = c.ramp_min_duration_s
        self._two_pi = 2.0 * np.pi
        self.base_path = path            # the configured path: plans that carry none
        self.pending_path: PathBase | None = None
        self._pending_tracker = None
        self._use_path(path)
        self._friction_par = _parametric_friction(friction)
        self._stick_pred = bool(c.stiction_prediction and self._hump_measured is not None
                                and self._friction_par is not None)
        self._pred_flight: deque = deque(maxlen=max(c.prediction_samples, 1))
        self._hump_joints = [i for i in range(self.n) if self._hump_measured
                             and self._hump_measured[i]]
        self._slide_h = c.period_s / _SLIDE_SUBSTEPS
        if self._hump_measured is not None and friction is not None \
                and self._friction_par is None:
            raise ValueError('stribeck_measured needs a parametric friction map (no '
                             'polynomials)')
        n, T = c.prediction_samples, c.period_s
        # over [t, t + n T) the command j (0 = oldest) acts during [t + j T, t + (j + 1) T):
        # qd(t + Delta) = qd + T sum a_j, q(t + Delta) = q + Delta qd + T^2 sum (n - j - 1/2) a_j
        self._in_flight: deque = deque(maxlen=max(n, 1))
        self._w_pos = [T * T * (n - j - 0.5) for j in range(n)]

    def _use_path(self, path: PathBase, tracker: PathTracker | None = None) -> None:
        """Make ``path`` the one theta is estimated on (only while nothing runs: at start-up
        and when enable takes a pending profile with its path)."""
        c = self.config
        self.path = path
        self._circle = ((float(path.center[0]), float(path.center[1]), path.direction,
                         path.start_angle) if type(path) is CirclePath else None)
        # any other path: projection near the previous theta (irb_description.path_tracking)
        self._tracker = None if self._circle is not None else (
            tracker if tracker is not None and tracker.path is path else PathTracker(path))
        # delay compensation with the commands in flight: the reference accelerations of the
        # last n commands sent (oldest first), n = prediction_samples; empty after enable/stop
        dp = c.delay_prediction
        self._commanded = (dp == 'commanded' or (dp == 'auto' and self._circle is None)) \
            and c.prediction_samples > 0

    # --- commands ------------------------------------------------------------------------
    def _transition(self, event: str) -> tuple[int | None, str]:
        """Look ``event`` up in TRANSITIONS for the current state: (next state or None, why)."""
        nxt, why = TRANSITIONS[(self.mode, event)]
        if nxt == _ARRIVE:
            nxt = MODE_TIME if self.time_driven else MODE_PATH
        return nxt, why

    def set_path_profile(self, profile: PathProfile, path: PathBase | None = None,
                         tracker: PathTracker | None = None) -> str:
        """Offer a theta-profile (theta-driven mode) on ``path`` (None: the configured path;
        ``tracker``: a PathTracker of that path built elsewhere, to save building it here).
        ProfileError if it leaves the limits; else it becomes the pending profile, and its
        path the pending path (see the module docstring): enable switches to both at once."""
        return self._offer(profile, path, tracker)

    def set_time_trajectory(self, traj: TimeTrajectory) -> str:
        """Offer a time trajectory (time-driven mode); as ``set_path_profile``."""
        return self._offer(traj)

    def _offer(self, profile, path=None, tracker=None) -> str:
        profile.check_limits(self.model, self.config.velocity_limit_fraction)
        _, why = self._transition(EV_PLAN)
        if self.pending is not None and self.retire is not None:
            self.retire(self.pending)
        self.pending = profile
        self.pending_path = self.base_path if path is None else path
        self._pending_tracker = tracker
        return why

    @property
    def profile(self):
        """The profile the next enable runs: the pending one if any, else the active one."""
        return self.pending if self.pending is not None else self.active

    def enable(self) -> tuple[bool, str]:
        """Request motion: takes the pending profile, clears a latched stop (its reason stays
        in ``last_stop_reason``); the next valid sample starts the ramp from where the robot
        is. Refused while moving or without a profile."""
        nxt, why = self._transition(EV_ENABLE)
        if nxt is None:
            return False, why
        if self.profile is None:
            return False, 'no profile: plan one first (ros2 run irb_planning plan ...)'
        if self.pending is not None:
            if self.active is not None and self.retire is not None:
                self.retire(self.active)
            self.active, self.pending = self.pending, None
            if self.pending_path is not self.path:
                self._use_path(self.pending_path, self._pending_tracker)
            self.pending_path = self._pending_tracker = None
        self._enable_requested = True
        self._halt_T = self._halt = None
        self._in_flight.clear()
        self._pred_flight.clear()
        self._integral = [0.0] * self.n
        self._dither_k = 0
        self.stop_reason = ''
        self.mode = MODE_IDLE         # the ramp starts on the next valid sample
        return True, f'enabled: {why}'

    def stop(self, reason: str) -> None:
        """Latch STOPPED with ``reason`` (the first reason is kept); no command is sent until
        ``enable``."""
        if self.mode != MODE_STOPPED:
            self.stop_reason = reason
            self.last_stop_reason = reason
        self.mode = MODE_STOPPED
        self._enable_requested = False
        self._halt_T = self._halt = None
        self._prev_tau = None
        self._in_flight.clear()
        self._pred_flight.clear()
        self._integral = [0.0] * self.n
        self._dither_k = 0

    def hold(self) -> tuple[bool, str]:
        """Controlled stop (the ``hold`` event): a moving reference (ramp, path, time)
        decelerates along itself, its progress rate falling smoothly from 1 to 0 over T_s
        (``ControllerConfig.hold_min_duration_s``), then HOLD keeps the pose it stopped at,
        motors on; no stop is latched. Refused in IDLE and in STOPPED (a latched stop stays
        latched); in HOLD, or while already stopping, nothing changes. (ok, why)"""
        nxt, why = self._transition(EV_HOLD)
        if nxt is None:
            return False, why
        if self.mode == MODE_HOLD:
            return True, why
        if self._halt_T is not None or self._halt is not None:
            T_s = self._halt[1] if self._halt is not None else self._halt_T
            return True, f'already stopping (in {T_s:.2f} s from the request)'
        c = self.config
        if self.mode == MODE_RAMP:      # the quintic's peak acceleration 10/sqrt(3) |d| / T^2
            peak = 10.0 / math.sqrt(3.0) * np.abs(self._ramp_to - self._ramp_from) \
                / self._ramp_T ** 2
        else:
            peak = np.max(np.abs(self.active.qdd), axis=0)
        a = np.maximum(peak, c.hold_min_deceleration_rad_s2)
        self._halt_T = float(max(c.hold_min_duration_s,
                                 1.5 * np.max(np.abs(self._last_qd_ref) / a)))
        return True, f'{why}: decelerating in {self._halt_T:.2f} s'

    def motors_off(self, qd: np.ndarray, rest_speed: float = 0.01,
                   dry_run: bool = False) -> tuple[bool, str]:
        """The drives are to engage their brakes (a deeper power mode): only at rest -- idle,
        or holding with every measured |qd| (3,) [rad/s] below ``rest_speed`` -- then IDLE
        (no command, no stop reason); ``dry_run``: only whether it may. (ok, why)"""
        nxt, why = self._transition(EV_MOTORS_OFF)
        if nxt is None:
            return False, why
        if self.mode == MODE_HOLD and np.max(np.abs(qd)) >= rest_speed:
            return False, (f'not at rest (|qd| = {np.abs(qd).round(4).tolist()} rad/s >= '
                           f'{rest_speed}): brakes only at rest')
        if dry_run:
            return True, why
        if self.mode != MODE_STOPPED:
            self.mode = MODE_IDLE
            self._enable_requested = False
            self._halt_T = self._halt = None
            self._prev_tau = None
            self._in_flight.clear()
            self._pred_flight.clear()
            self._integral = [0.0] * self.n
            self._dither_k = 0
        return True, why

    def motors_on(self, q: np.ndarray) -> tuple[bool, str]:
        """The drives are back in hold: HOLD the measured pose q (3,) [rad] (the commands
        carry its gravity torque from the first one on, before the brakes open)."""
        nxt, why = self._transition(EV_MOTORS_ON)
        if nxt is None or self.mode == MODE_HOLD:
            return nxt is not None, why
        self.mode = MODE_HOLD
        self._hold = np.asarray(q, float).tolist()
        self._prev_tau = None
        self._in_flight.clear()
        self._pred_flight.clear()
        self._integral = [0.0] * self.n
        self._dither_k = 0
        return True, why

    @property
    def stopping(self) -> bool:
        """A hold was requested and the motion is decelerating towards it."""
        return self._halt_T is not None or self._halt is not None

    @property
    def time_driven(self) -> bool:
        """Whether the active (else the pending) profile is a time trajectory."""
        prof = self.active if self.active is not None else self.pending
        return isinstance(prof, TimeTrajectory)

    def start_pose(self) -> np.ndarray:
        """Joint position (3,) [rad] where the next motion starts (pending, else active)."""
        return self.profile.q[0].copy()

    # --- the step ------------------------------------------------------------------------
    def step(self, t: float, q: np.ndarray, qd: np.ndarray) -> ControlOutput:
        """One control step for the measurement q (3,) [rad], qd (3,) [rad/s] taken at t [s].

        The 3-vectors are handled as plain floats (far cheaper than 3-element numpy arrays);
        every operation is the element-wise one of the equations in the module docstring, in
        the same order, so the result is the same to the bit as the array formulation.
        """
        if (self.n != 3 or self._ki is not None or self._hump_measured
                or self._dither is not None):
            return self._step_n(t, q, qd)
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        if q.shape != (3,) or qd.shape != (3,) or not math.isfinite(t):
            return self._rejected()
        q0, q1, q2 = q.tolist()
        w0, w1, w2 = qd.tolist()
        isfinite = math.isfinite
        if not (isfinite(q0) and isfinite(q1) and isfinite(q2) and isfinite(w0)
                and isfinite(w1) and isfinite(w2)):
            return self._rejected()
        if self.mode == MODE_STOPPED:
            return ControlOutput(False, np.zeros(3), self.mode, self.stop_reason)
        # safety on the measurement
        # (gains and limits are public arrays: read them every step, as plain floats)
        vm, lo, hi = self.v_max.tolist(), self.q_lo.tolist(), self.q_hi.tolist()
        if abs(w0) > vm[0] or abs(w1) > vm[1] or abs(w2) > vm[2]:
            self.stop(f'speed limit: |qd| = {np.abs(qd).round(3).tolist()} rad/s')
        elif (q0 < lo[0] or q1 < lo[1] or q2 < lo[2] or q0 > hi[0] or q1 > hi[1]
              or q2 > hi[2]):
            self.stop(f'position limit: q = {q.round(4).tolist()} rad')
        if self.mode == MODE_STOPPED:
            return ControlOutput(False, np.zeros(3), self.mode, self.stop_reason)
        ref = self._reference(t, q)
        if ref is None:
            return ControlOutput(False, np.zeros(3), self.mode)
        q_ref, qd_ref, qdd_ref, theta, theta_p, theta_dot_ref = ref
        d = self.delta

        # delay compensation of the measurement, 'reference': q_p = q + d qd + d^2/2 qdd_ref,
        # qd_p = qd + d qdd_ref; 'commanded': the in-flight accelerations a_j instead (see
        # __init__; until n commands are out, as 'reference'); e = q_ref - q_p, de = qd_ref - qd_p
        fl = self._in_flight
        if self._commanded and len(fl) == self.config.prediction_samples:
            T = self.config.period_s
            sv0 = sv1 = sv2 = sp0 = sp1 = sp2 = 0.0
            for wj, (b0, b1, b2) in zip(self._w_pos, fl):
                sv0, sv1, sv2 = sv0 + b0, sv1 + b1, sv2 + b2
                sp0, sp1, sp2 = sp0 + wj * b0, sp1 + wj * b1, sp2 + wj * b2
            p0, p1, p2 = q0 + d * w0 + sp0, q1 + d * w1 + sp1, q2 + d * w2 + sp2
            u0, u1, u2 = w0 + T * sv0, w1 + T * sv1, w2 + T * sv2
        else:
            a0, a1, a2 = qdd_ref
            c2 = 0.5 * d * d
            p0, p1, p2 = q0 + d * w0 + c2 * a0, q1 + d * w1 + c2 * a1, q2 + d * w2 + c2 * a2
            u0, u1, u2 = w0 + d * a0, w1 + d * a1, w2 + d * a2
        e = [q_ref[0] - p0, q_ref[1] - p1, q_ref[2] - p2]
        de = [qd_ref[0] - u0, qd_ref[1] - u1, qd_ref[2] - u2]
        em = self.e_max.tolist()
        if abs(e[0]) > em[0] or abs(e[1]) > em[1] or abs(e[2]) > em[2]:
            self.stop(f'tracking error {np.abs(np.array(e)).round(4).tolist()} rad > '
                      f'{self.e_max.tolist()}')
            return ControlOutput(False, np.zeros(3), self.mode, self.stop_reason, theta,
                                 theta_p, theta_dot_ref)
        # model terms at the predicted state: M qdd_ref + C(q, qd) qd_ref + g (the products
        # in numpy, as before: its matrix-vector product rounds differently from a plain sum)
        q_p = np.array((p0, p1, p2))
        pm, pd = self._pm, self._pd
        (m00, m01, m02), (_, m11, m12), (_, _, m22) = pin.crba(pm, pd, q_p).tolist()
        # symmetric M from the upper triangle pinocchio fills (= np.triu(M) + np.triu(M, 1).T)
        M = np.array(((m00 + 0.0, m01 + 0.0, m02 + 0.0), (0.0 + m01, m11 + 0.0, m12 + 0.0),
                      (0.0 + m02, 0.0 + m12, m22 + 0.0)))
        qd_ref_a = np.array(qd_ref)
        qdd_ref_a = np.array(qdd_ref)
        Ma = (M @ qdd_ref_a).tolist()
        Cb = (pin.computeCoriolisMatrix(pm, pd, q_p, np.array((u0, u1, u2))) @ qd_ref_a).tolist()
        g = pin.computeGeneralizedGravity(pm, pd, q_p).tolist()
        tm = [Ma[0] + Cb[0] + g[0], Ma[1] + Cb[1] + g[1], Ma[2] + Cb[2] + g[2]]
        if self.friction is not None:
            tf = self._friction_torque(qd_ref, (u0, u1, u2))
        else:
            tf = [0.0, 0.0, 0.0]
        kp, kd = self._gains((m00, m11, m22))
        fb = [kp[0] * e[0] + kd[0] * de[0], kp[1] * e[1] + kd[1] * de[1],
              kp[2] * e[2] + kd[2] * de[2]]
        tau = [tm[0] + tf[0] + fb[0], tm[1] + tf[1] + fb[1], tm[2] + tf[2] + fb[2]]
        if not (isfinite(tau[0]) and isfinite(tau[1]) and isfinite(tau[2])):
            self.stop('non-finite torque computed')
            return ControlOutput(False, np.zeros(3), self.mode, self.stop_reason, theta,
                                 theta_p, theta_dot_ref)
        # rate limit around the previous command, then the torque limit (np.clip semantics:
        # min(max(x, lo), hi))
        prev = self._prev_tau.tolist() if self._prev_tau is not None else None
        r, tmax = self.rate_max.tolist(), self.tau_max.tolist()
        for i in range(3):
            x = tau[i]
            if prev is not None:
                x = min(max(x, prev[i] - r[i]), prev[i] + r[i])
            tau[i] = min(max(x, -tmax[i]), tmax[i])
        tau_a = np.array(tau)
        self._prev_tau = tau_a
        self._last_qd_ref = qd_ref
        if self._commanded:
            fl.append((qdd_ref[0], qdd_ref[1], qdd_ref[2]))
        return ControlOutput(True, tau_a, self.mode, '', theta, theta_p, theta_dot_ref,
                             np.array(q_ref), qd_ref_a, qdd_ref_a, np.array(e), np.array(de),
                             np.array(tm), np.array(tf), np.array(fb))

    def _gains(self, m_diag) -> tuple[list, list]:
        """kp, kd (lists of n floats) at the mass matrix's diagonal m_diag (n floats): the
        inertia-scheduled gains, kp_i and kd_i x min(1, M_ii / design_i) (``gain_scale``'s
        rule), so the loop's bandwidth (kp/M_ii, kd/M_ii) never exceeds the tuned one. With
        constant gains, M_11 = 9 kg m^2 at the part-exchange pose (22 at the circle) put joint
        1 at 2.4x its tuned bandwidth, beyond the ~1.6x the 3-sample delay allows: an 8.7 Hz
        limit cycle on the torque-rate limit (doc/gain_schedule.md)."""
        kp, kd = self.kp.tolist(), self.kd.tolist()
        md = self._m_design
        if md is not None:
            for i, m_ii in enumerate(m_diag):
                if m_ii < md[i]:
                    s_i = m_ii / md[i]
                    kp[i], kd[i] = kp[i] * s_i, kd[i] * s_i
        return kp, kd

    def _reference(self, t: float, q: np.ndarray):
        """The mode machine and the reference at t + Delta, shared by ``step`` and ``_step_n``
        (lists of n floats): None while IDLE without an enable (no command), else
        (q_ref, qd_ref, qdd_ref, theta, theta_p, theta_dot_ref)."""
        n = self.n
        prof = self.active          # the running reference: offered plans wait in pending
        if self.mode == MODE_IDLE:
            if not self._enable_requested or prof is None:
                return None
            self._enable_requested = False
            self._ramp_from = q.copy()
            self._ramp_to = prof.q[0].copy()
            self._ramp_T = ramp_duration(q, self._ramp_to, self.model.limits.velocity,
                                         self.config.ramp_min_duration_s,
                                         self.config.ramp_speed_fraction)
            self._t0 = t
            self.mode = MODE_RAMP
            self._prev_tau = None

        theta = theta_p = theta_dot_ref = math.nan
        d = self.delta
        tp = t + d
        time_driven = isinstance(prof, TimeTrajectory)
        halt = None     # a controlled stop (hold): (r_s, T_s, v_s), from the step after hold()
        if self._halt_T is not None or self._halt is not None:
            if self.mode not in MOVING:             # the motion ended by itself meanwhile
                self._halt_T = self._halt = None
            else:
                if self._halt is None:              # starts at this step's reference time
                    self._halt = (tp, self._halt_T, tp - self._t0)
                    self._halt_T = None
                halt = self._halt
        if self.mode == MODE_RAMP and halt is None and tp - self._t0 >= self._ramp_T:
            self.mode = self._transition(EV_RAMP_DONE)[0]
            self._t0 = self._t0 + self._ramp_T     # time origin of the profile
            self._theta = prof.theta_start if not time_driven else 0.0
            self._theta_v = self._theta
        if halt is not None:     # progress rate k (1 -> 0), its rate, the virtual time at tp
            k, k_dot, v_tp, u = _halt_rate(halt, tp)
        zero = [0.0] * n
        if self.mode == MODE_RAMP:
            q_ref, qd_ref, qdd_ref = (x.tolist() for x in quintic_ramp(
                self._ramp_from, self._ramp_to, self._ramp_T,
                tp - self._t0 if halt is None else v_tp))
            if halt is not None:
                q_ref, qd_ref, qdd_ref = _scaled(q_ref, qd_ref, qdd_ref, k, k_dot)
        elif self.mode == MODE_TIME:
            tau = tp - self._t0 if halt is None else v_tp
            row = prof.sample_list(tau)
            q_ref, qd_ref, qdd_ref = row[0:n], row[n:2 * n], row[2 * n:3 * n]
            if halt is not None:
                q_ref, qd_ref, qdd_ref = _scaled(q_ref, qd_ref, qdd_ref, k, k_dot)
            if tau >= prof.duration:
                self.mode = self._transition(EV_MOTION_DONE)[0]
                self._hold = prof.q[-1].tolist()
        elif self.mode == MODE_HOLD and (time_driven or prof is None):
            q_ref, qd_ref, qdd_ref = self._hold, zero, zero
        else:   # PATH or HOLD on a theta-profile
            raw = self._theta_of(q)
            # unwrap against the previous theta, clamp to the profile
            dth = (raw - self._theta + math.pi) % (2 * math.pi) - math.pi
            theta = min(max(self._theta + dth, prof.theta_start), prof.theta_end)
            self._theta = theta
            T = self.config.period_s
            # progress governor: theta_v runs on h(theta_v) but stays within
            # [theta, theta + theta_max_lead_rad]; 0 lead = theta from the measurement only
            if halt is None:
                tv = min(self._theta_v + T * prof.h(self._theta_v), prof.theta_end)
            else:        # a controlled stop: theta_v and the prediction advance at k h
                tv = min(self._theta_v + T * _halt_rate(halt, t)[0] * prof.h(self._theta_v),
                         prof.theta_end)
            tv = min(max(tv, theta), theta + self.config.theta_max_lead_rad)
            self._theta_v = tv
            th = tv
            for j in range(self.config.prediction_samples):
                kj = 1.0 if halt is None else _halt_rate(halt, t + (j + 1) * T)[0]
                th = min(th + T * kj * prof.h(th), prof.theta_end)
            theta_p = th
            if self.mode == MODE_HOLD or tv >= prof.theta_end - self.config.end_tolerance_rad:
                if self.mode != MODE_HOLD:
                    self.mode = self._transition(EV_MOTION_DONE)[0]
                    self._hold = prof.q[-1].tolist()
                q_ref, qd_ref, qdd_ref = self._hold, zero, zero
                theta_dot_ref = 0.0
            else:
                row = prof.sample_list(th)
                theta_dot_ref = row[0]
                q_ref, qd_ref, qdd_ref = row[2:2 + n], row[2 + n:2 + 2 * n], \
                    row[2 + 2 * n:2 + 3 * n]
                if halt is not None:
                    theta_dot_ref *= k
                    q_ref, qd_ref, qdd_ref = _scaled(q_ref, qd_ref, qdd_ref, k, k_dot)
        if halt is not None and u >= 1.0 and self.mode in MOVING:
            # the reference has come to rest on its own path: hold that pose, motors on
            self.mode = MODE_HOLD
            self._hold = list(q_ref)
            self._halt = None
            q_ref, qd_ref, qdd_ref = self._hold, zero, zero
        return q_ref, qd_ref, qdd_ref, theta, theta_p, theta_dot_ref

    def _nan_fields(self) -> dict:
        """ControlOutput's NaN reference fields for n joints ({} for 3: the defaults)."""
        if self.n == 3:
            return {}
        n = self.n
        return {k: np.full(n, np.nan) for k in ('q_ref', 'qd_ref', 'qdd_ref', 'q_error',
                                                  'qd_error', 'tau_model', 'tau_friction',
                                                  'tau_feedback')}

    def _step_n(self, t: float, q: np.ndarray, qd: np.ndarray) -> ControlOutput:
        """``step`` on n joints (the six-joint arm): the same operations, in the same order,
        on n-lists instead of unrolled floats (on three joints the same result to the bit as
        ``step``, tested); every change to ``step`` belongs here too. On n != 3 joints the
        model terms and the friction's exp take a cheaper formulation of the same quantities
        (``_model_terms_n``, ``_fast``: one rounding apart, tested in the closed loop)."""
        n = self.n
        R = range(n)
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        if q.shape != (n,) or qd.shape != (n,) or not math.isfinite(t):
            return self._rejected()
        ql = q.tolist()
        wl = qd.tolist()
        isfinite = math.isfinite
        if not (all(map(isfinite, ql)) and all(map(isfinite, wl))):
            return self._rejected()
        if self.mode == MODE_STOPPED:
            return ControlOutput(False, np.zeros(n), self.mode, self.stop_reason,
                                 **self._nan_fields())
        # safety on the measurement
        vm, lo, hi = self.v_max.tolist(), self.q_lo.tolist(), self.q_hi.tolist()
        if any([abs(w) > v for w, v in zip(wl, vm)]):
            self.stop(f'speed limit: |qd| = {np.abs(qd).round(3).tolist()} rad/s')
        elif any([x < y or x > z for x, y, z in zip(ql, lo, hi)]):
            self.stop(f'position limit: q = {q.round(4).tolist()} rad')
        if self.mode == MODE_STOPPED:
            return ControlOutput(False, np.zeros(n), self.mode, self.stop_reason,
                                 **self._nan_fields())
        ref = self._reference(t, q)
        if ref is None:
            return ControlOutput(False, np.zeros(n), self.mode, **self._nan_fields())
        q_ref, qd_ref, qdd_ref, theta, theta_p, theta_dot_ref = ref
        d = self.delta
        zero = [0.0] * n

        # delay compensation of the measurement (see ``step``)
        fl = self._in_flight
        if self._commanded and len(fl) == self.config.prediction_samples:
            T = self.config.period_s
            if len(fl) == 3:    # the default: the sums of ``step`` per joint, in its order
                w0, w1, w2 = self._w_pos
                b0, b1, b2 = fl
                p = [x + d * w + (((0.0 + w0 * y0) + w1 * y1) + w2 * y2)
                     for x, w, y0, y1, y2 in zip(ql, wl, b0, b1, b2)]
                uu = [w + T * (((0.0 + y0) + y1) + y2) for w, y0, y1, y2 in zip(wl, b0, b1, b2)]
            else:
                sv = [0.0] * n
                sp = [0.0] * n
                for wj, b in zip(self._w_pos, fl):
                    sv = [x + y for x, y in zip(sv, b)]
                    sp = [x + wj * y for x, y in zip(sp, b)]
                p = [x + d * w + y for x, w, y in zip(ql, wl, sp)]
                uu = [w + T * y for w, y in zip(wl, sv)]
        else:
            c2 = 0.5 * d * d
            p = [x + d * w + c2 * y for x, w, y in zip(ql, wl, qdd_ref)]
            uu = [w + d * y for w, y in zip(wl, qdd_ref)]
        e = [x - y for x, y in zip(q_ref, p)]
        de = [x - y for x, y in zip(qd_ref, uu)]
        em = self.e_max.tolist()
        if any([abs(x) > y for x, y in zip(e, em)]):
            self.stop(f'tracking error {np.abs(np.array(e)).round(4).tolist()} rad > '
                      f'{self.e_max.tolist()}')
            return ControlOutput(False, np.zeros(n), self.mode, self.stop_reason, theta,
                                 theta_p, theta_dot_ref, **self._nan_fields())
        # model terms at the predicted state: M qdd_ref + C(q, qd) qd_ref + g, M's diagonal
        tm, mdg = self._model_terms_n(p, uu, qd_ref, qdd_ref)
        pf = self._pred_flight
        if self.friction is not None:
            xs = uu
            if self._stick_pred and len(pf) == self.config.prediction_samples:
                xs = list(uu)
                for i in self._hump_joints:
                    xs[i] = self._predict_speed(i, wl[i], mdg[i], pf)
            tf = self._friction_torque_n(qd_ref, uu, xs)
        else:
            tf = zero
        kp, kd = self._gains(mdg)
        fb = [a * x + b * y for a, x, b, y in zip(kp, e, kd, de)]
        ki = self._ki
        if ki is not None:      # integral action: candidate, bounded to +-limit
            i_old = self._integral
            T = self.config.period_s
            lim = self._i_lim
            i_new = [min(max(i_old[i] + ki[i] * e[i] * T, -lim[i]), lim[i]) for i in R]
            fb = [fb[i] + i_new[i] for i in R]
        dith = self._dither
        if dith is not None and self.mode in DITHER_MODES:     # stiction dither: +-a_i
            k = self._dither_k
            P = self.config.dither_period_samples
            sg = 1.0 if k % P < P // 2 else -1.0
            tf = [tf[i] + sg * dith[i] for i in R]
            self._dither_k = k + 1
        tau = [x + y + z for x, y, z in zip(tm, tf, fb)]
        if not all(map(isfinite, tau)):
            self.stop('non-finite torque computed')
            return ControlOutput(False, np.zeros(n), self.mode, self.stop_reason, theta,
                                 theta_p, theta_dot_ref, **self._nan_fields())
        # rate limit around the previous command, then the torque limit
        prev = self._prev_tau.tolist() if self._prev_tau is not None else None
        r, tmax = self.rate_max.tolist(), self.tau_max.tolist()
        if ki is None:          # (np.clip semantics: min(max(x, lo), hi))
            if prev is not None:
                tau = [min(max(min(max(x, y - z), y + z), -m), m)
                       for x, y, z, m in zip(tau, prev, r, tmax)]
            else:
                tau = [min(max(x, -m), m) for x, m in zip(tau, tmax)]
        for i in (R if ki is not None else ()):
            x = tau[i]
            if prev is not None:
                x = min(max(x, prev[i] - r[i]), prev[i] + r[i])
            x = min(max(x, -tmax[i]), tmax[i])
            if ki is not None and x != tau[i] and (x - tau[i]) * e[i] < 0.0:
                # anti-windup: the command is limited in the error's direction, the
                # integral keeps its previous value (the torque is the limited one anyway)
                fb[i] -= i_new[i] - i_old[i]
                i_new[i] = i_old[i]
            tau[i] = x
        if ki is not None:
            self._integral = i_new
        tau_a = np.array(tau)
        self._prev_tau = tau_a
        self._last_qd_ref = qd_ref
        if self._commanded:
            fl.append(tuple(qdd_ref))
        if self._stick_pred:
            pf.append(([x - y for x, y in zip(tau, tm)], qdd_ref))
        # the eight reference/torque fields: rows of one new array (one conversion, not 8)
        q_r, qd_r, qdd_r, e_a, de_a, tm_a, tf_a, fb_a = np.array(
            (q_ref, qd_ref, qdd_ref, e, de, tm, tf, fb), dtype=float)
        return ControlOutput(True, tau_a, self.mode, '', theta, theta_p, theta_dot_ref,
                             q_r, qd_r, qdd_r, e_a, de_a, tm_a, tf_a, fb_a)

    def _model_terms_n(self, p: list, uu: list, qd_ref: list, qdd_ref: list
                       ) -> tuple[list, list]:
        """M(p) qdd_ref + C(p, uu) qd_ref + g(p) and M(p)'s diagonal (lists of n floats) at
        the predicted state p, uu.

        Three joints (``_fast`` False): as ``step`` computes them (crba, the Coriolis matrix
        and gravity, numpy's products; the same bits). Otherwise with two RNEA passes: C is
        linear in its velocity and pinocchio's C(q, v) w is the Christoffel form, symmetric
        in v and w, so with s = (uu + qd_ref) / 2, d = (uu - qd_ref) / 2
        C(q, s) s - C(q, d) d = C(q, uu) qd_ref, and
        rnea(p, s, qdd_ref) - rnea_without_gravity(p, d, 0) = M qdd_ref + C(p, uu) qd_ref + g
        (one rounding from the matrix formulation: ~1e-14 N m, tested), plus crba for the
        diagonal the gain schedule and the stiction prediction take (~10 us less on six
        joints than the Coriolis matrix and the products)."""
        pm, pd = self._pm, self._pd
        if self._fast:
            q_p, s_, d_, a_ = self._buf
            q_p[:] = p
            s_[:] = [0.5 * (x + y) for x, y in zip(uu, qd_ref)]
            d_[:] = [0.5 * (x - y) for x, y in zip(uu, qd_ref)]
            a_[:] = qdd_ref
            tm = (pin.rnea(pm, pd, q_p, s_, a_)
                  - pin.rnea(self._pm0, self._pd0, q_p, d_, self._zero_a)).tolist()
            return tm, pin.crba(pm, pd, q_p).diagonal().tolist()
        q_p = np.array(p)
        # symmetric M from the upper triangle pinocchio fills (= np.triu(M) + np.triu(M, 1).T,
        # +0.0 as there; np.triu itself costs ~50 us)
        M = pin.crba(pm, pd, q_p) + 0.0
        low = self._lower
        M[low] = M.T[low]
        Ma = (M @ np.array(qdd_ref)).tolist()
        Cb = (pin.computeCoriolisMatrix(pm, pd, q_p, np.array(uu)) @ np.array(qd_ref)).tolist()
        g = pin.computeGeneralizedGravity(pm, pd, q_p).tolist()
        return [x + y + z for x, y, z in zip(Ma, Cb, g)], M.diagonal().tolist()

    def _slide(self, i: int, v: float, u: float, a: float, m: float) -> float:
        """Joint i's speed v [rad/s] one period later under one command in flight: u [N m]
        its torque beyond the model terms, a [rad/s^2] the reference acceleration it was
        computed for, m [kg m^2] M_ii (``_predict_speed`` of one command)."""
        return self._predict_speed(i, v, m, ((u, a),), False)

    def _predict_speed(self, i: int, v: float, m: float, flight, lists: bool = True
                       ) -> float:
        """Joint i's speed v [rad/s] carried over the commands in ``flight`` (oldest first;
        each (u, a) as in ``_slide``, per-joint lists of which joint i's are taken, or with
        ``lists`` False joint i's floats), M_ii = m [kg m^2]: one period
        each in ``_SLIDE_SUBSTEPS`` semi-implicit stick-slip substeps of the controller's
        parametric friction (``stiction_prediction``); a speed below
        ``stiction_rest_speed_rad_s`` at a command's start is rest."""
        fcp, fcn, hp, hn, vs, fv, off = self._friction_par[i]
        s_pos, s_neg = fcp + hp, -(fcn + hn)           # the breakaway levels
        h = self._slide_h
        rest = self.config.stiction_rest_speed_rad_s
        exp = math.exp
        for u, a in flight:
            if lists:
                u, a = u[i], a[i]
            if abs(v) < rest:
                v = 0.0
                # (the first substep's test, ahead of the loop: a joint held at rest costs
                # no substep loop)
                if s_neg <= m * a + u - off <= s_pos:
                    continue
            for _ in range(_SLIDE_SUBSTEPS):
                if v == 0.0:
                    drive = m * a + u - off     # what friction must hold for the joint to rest
                    if s_neg <= drive <= s_pos:
                        break                   # at rest for the rest of this command
                    v = h * (drive - (s_pos if drive > 0.0 else s_neg)) / m
                    continue
                fr = (fcp + hp * exp(-(v / vs) ** 2) if v > 0.0
                      else -(fcn + hn * exp(-(v / vs) ** 2))) + fv * v + off
                vn = v + h * (a + (u - fr) / m)
                v = 0.0 if vn * v < 0.0 else vn
        return v

    def _rejected(self) -> ControlOutput:
        self.rejected_inputs += 1
        # no command for this sample: the drive keeps acting on the last one, so it is in
        # flight once more (as the plant's delay line repeats it)
        if self._commanded and self._in_flight:
            self._in_flight.append(self._in_flight[-1])
        if self._stick_pred and self._pred_flight:
            self._pred_flight.append(self._pred_flight[-1])
        n = self.n
        return ControlOutput(False, np.zeros(n), self.mode, self.stop_reason,
                             rejected_input=True, **self._nan_fields())

    def _theta_of(self, q: np.ndarray) -> float:
        """theta of FK(q): for the thesis's CirclePath atan2 about the centre
        (``float(path.theta_of(model.fk(q)))`` in plain floats with numpy's arctan2, the same
        value to the bit); for any other path the projection of the TCP onto the path within
        a window around the previous theta (``PathTracker``: continuous, never a jump to a
        distant part of the path that passes nearby)."""
        c = self._circle
        if c is None:
            return self._tracker.update(self.model.fk(q), self._theta)
        cx, cy, direction, start = c
        x, y, _ = self.model.fk(q).tolist()
        ang = float(np.arctan2(y - cy, x - cx))
        theta = (direction * (ang - start)) % self._two_pi
        return 0.0 if theta >= self._two_pi else theta

    def _friction_torque_n(self, qd_ref: list, qd_p, qd_hump=None) -> list:
        """``_friction_torque`` on n joints (the same operations per joint); ``qd_hump``: the
        speeds the ``stribeck_measured`` joints' hump takes (default qd_p)."""
        n = self.n
        a = self.config.friction_blend_a
        if self._fast:      # math.exp on floats (numpy's exp per scalar costs ~0.5 us each)
            c = 2.0 * a * a
            exp = math.exp
            v = [(al := exp(-(x * x) / c)) * x + (1.0 - al) * y for x, y in zip(qd_ref, qd_p)]
        else:               # numpy's array exp, as ``_friction_torque``
            alpha = np.exp(np.array([-(x * x) for x in qd_ref]) / (2.0 * a * a)).tolist()
            exp = np.exp
            v = [al * x + (1.0 - al) * y for al, x, y in zip(alpha, qd_ref, qd_p)]
        par = self._friction_par
        measured = self._hump_measured or [False] * n
        if qd_hump is None:
            qd_hump = qd_p
        if par is None:     # (stribeck_measured is refused with such maps at construction)
            return self.friction.torque(np.array(v)).tolist()
        out = []
        copysign, nan = math.copysign, math.nan
        for (fcp, fcn, hp, hn, vs, fv, off), x, xh, mi in zip(par, v, qd_hump, measured):
            xs = xh if mi else x
            e = float(exp(-((xs / vs) ** 2)))
            sg = 0.0 if x == 0.0 else (copysign(1.0, x) if x == x else nan)
            tf = (sg * (fcp + hp * e) if x > 0.0 else sg * (fcn + hn * e)) + fv * x
            out.append(tf + off if off else tf)
        return out

    def _friction_torque(self, qd_ref: list, qd_p: tuple) -> list:
        """tau_f(v), v = friction_blend(qd_ref, qd_p, a) (eq. 4.9-4.10), as 3 floats.

        The parametric maps of irb_description.friction in plain floats with numpy's exp on
        the same operands (same value to the bit); maps with polynomials use FrictionMap."""
        a = self.config.friction_blend_a
        # alpha = exp(-qd_ref^2 / (2 a^2)) on the 3-vector (numpy's array exp, as before)
        alpha = np.exp(np.array((-(qd_ref[0] * qd_ref[0]), -(qd_ref[1] * qd_ref[1]),
                                 -(qd_ref[2] * qd_ref[2]))) / (2.0 * a * a)).tolist()
        v = [alpha[i] * qd_ref[i] + (1.0 - alpha[i]) * qd_p[i] for i in range(3)]
        par = self._friction_par
        if par is None:
            return self.friction.torque(np.array(v)).tolist()
        out = []
        exp = np.exp
        for i in range(3):
            fcp, fcn, hp, hn, vs, fv, off = par[i]
            x = v[i]
            # (v / v_s)^2 with pow, as numpy's float64 scalar power does
            e = float(exp(-((x / vs) ** 2)))
            sg = 0.0 if x == 0.0 else (math.copysign(1.0, x) if x == x else math.nan)
            tf = (sg * (fcp + hp * e) if x > 0.0 else sg * (fcn + hn * e)) + fv * x
            out.append(tf + off if off else tf)
        return out
