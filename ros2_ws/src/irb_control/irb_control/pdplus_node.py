"""`ros2 run irb_control pdplus`: the theta-driven PD+ controller (adapter over pd_plus).

/joint_states in -> PdPlusController.step -> /torque_command and /controller_state out, one
message each per sample. Profile from /planned_trajectory (latched) or the built-in default.

Threads: the control thread (executor: joint states, services, axis status) does nothing but
the step; plans are received, decoded and checked in a child process (plan_gate.py) whose
results a reader thread offers to the controller (pending until enable); a watchdog thread
judges the age of the last valid state on the steady clock. A state whose stamp is older than
the watchdog limit (or in the future) is never answered, and a stall of pdplus itself (the
control thread not run for longer than the limit) ends in a latched stop before anything is
answered.
"""
from __future__ import annotations

import dataclasses
import gc
import math
import operator
import queue
import threading
import time

import numpy as np
from irb_description.node_help import NodeSpec, Param, Topic
from irb_description.node_main import (declare_params, latched_qos, run_node, state_pub_qos,
                                       state_qos)
from irb_description.path import CirclePath, load_path_file
from irb_interfaces.msg import AxisStatus, ControllerState, PlanStatus
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from .cdr import ControllerStateEncoder, JointStateDecoder, JointStateEncoder
from .closed_loop import controller_friction
from .node_util import (REALTIME_PARAMS, GcWatch, LogThread, declare_realtime,
                        joint_model, short_switch_interval, spin_with)
from .pd_plus import (MODE_HOLD, MODE_NAMES, MODE_STOPPED, MOVING, ControllerConfig,
                      PdPlusController, SettleGate, Watchdog, ramp_duration)
from .plan_gate import GateConfig, PlanGate, profile_from_result
from .plant import POWER_MODES
from .profiles import (ProfileError, TimeTrajectory, default_circle_profile, dispose_sliced,
                       sine_trajectory)


_d = ControllerConfig()
_g = GateConfig()       # the plan gate's limits: irb_description.trajectory_rules (one source)
SPEC = NodeSpec(
    'pdplus', 'irb_control',
    'The theta-driven inverse-dynamics PD+ controller with friction feed-forward: answers each '
    '/joint_states with a /torque_command (stamped with the state it answers). Plans arrive on '
    '/planned_trajectory on the path they were planned on, are checked in a child process and '
    'wait, pending, for ~/enable; the verdict goes out on ~/plan_status. Nothing moves '
    'unless enabled; stops latch until ~/enable.',
    params=(
        Param('joints', 3, '', "3: the thesis's model (joints 4-6 locked; today's pdplus); 6: "
              'all six joints (irb_description six_axis_model; per-joint parameters of six '
              "values, config/pdplus_six_axis.yaml; builtin_profile 'none' or 'sine')"),
        Param('tcp_xyz', [0.0, 0.0, 0.0], 'm', 'joints 6: the TCP in tool0 the path is about '
              '(e.g. [0, 0, 0.1], the gluing nozzle)'),
        Param('kp', list(_d.kp), 'N m/rad', 'proportional gains'),
        Param('kd', list(_d.kd), 'N m s/rad', 'derivative gains'),
        Param('gain_design_inertia_kg_m2', list(_d.gain_design_inertia_kg_m2), 'kg m^2',
              'the inertia M_ii the gains were tuned for: where M_ii(q) is smaller, kp_i and '
              'kd_i scale by M_ii(q) / this (never above kp, kd); [] = constant gains',
              type='double[]'),
        Param('period_s', _d.period_s, 's', 'sample period'),
        Param('prediction_samples', _d.prediction_samples, 'samples', 'delay compensation'),
        Param('delay_prediction', _d.delay_prediction, '', "q, qd over the delay: "
              "'commanded' (with the accelerations of the commands in flight), 'reference' "
              "(with qdd_ref at t + delta, the thesis), 'auto' (reference on the thesis "
              "circle, else commanded)"),
        Param('ramp_min_duration_s', _d.ramp_min_duration_s, 's', 'ramp to the start '
              '(minimum; longer if the peak speed would exceed half the speed limit)'),
        Param('friction_mode', 'nominal', '', "friction feed-forward: 'none', 'nominal', "
              "'file'"),
        Param('friction_map_file', '', '', "friction-map YAML for mode 'file'"),
        Param('friction_blend_a', _d.friction_blend_a, 'rad/s', 'a of eq. 4.9'),
        Param('torque_limit_nm', [0.0], 'N m', 'torque limits (one per joint); [0.0] = the '
              'model limits'),
        Param('torque_rate_limit_nm_s', list(_d.torque_rate_limit_nm_s), 'N m/s',
              'torque rate limits'),
        Param('velocity_limit_fraction', _d.velocity_limit_fraction, '',
              'safe stop above this fraction of the speed limits'),
        Param('max_tracking_error_rad', list(_d.max_tracking_error_rad), 'rad',
              'safe stop above this joint error'),
        Param('ki', [], 'N m/(rad s)', 'joints 6: integral gains, one per joint; [] = none '
              '(PD+; with integral_limit_nm; doc/six_joint.md)', type='double[]'),
        Param('integral_limit_nm', [], 'N m', 'joints 6: bound of each integral torque',
              type='double[]'),
        Param('stribeck_measured', [], '', 'joints 6: per joint, the feed-forward\'s Stribeck '
              'term on the measured speed; [] = all on the reference blend', type='bool[]'),
        Param('stiction_prediction', _d.stiction_prediction, '', 'joints 6: the '
              'stribeck_measured joints\' speed carried over the delay by a stick-slip model of '
              'the commands in flight; only with friction_mode file (an identified map: '
              'off with a warning otherwise; doc/six_joint.md)'),
        Param('stiction_rest_speed_rad_s', _d.stiction_rest_speed_rad_s, 'rad/s',
              'stiction_prediction: a joint measured slower starts at rest'),
        Param('theta_max_lead_rad', _d.theta_max_lead_rad, 'rad', 'progress governor lead; '
              '0 = theta from the measurement only (thesis)'),
        Param('reference_mode', 'theta', '', "'theta' (theta-driven) or 'time' (q(t))"),
        Param('builtin_profile', 'circle', '', "used until a plan arrives: 'circle', 'sine' "
              "or 'none' (no motion and no command until /planned_trajectory arrives)"),
        Param('profile_duration_s', 10.0, 's', 'built-in circle: one circle in this time'),
        Param('min_theta_dot', 0.05, 'rad/s', 'floor of h(theta)'),
        Param('sine_joint', 1, '', 'built-in sine: joint 1..3 (1..6 with joints 6)'),
        Param('sine_peak_speed_rad_s', 0.5, 'rad/s', 'built-in sine: peak speed'),
        Param('sine_amplitude_rad', 0.3, 'rad', 'built-in sine: amplitude A of A(1 - cos wt)'),
        Param('sine_cycles', 1.0, '', 'built-in sine: number of periods'),
        Param('path_center', [0.6, 0.0, 0.13], 'm', 'circle centre (base_link)'),
        Param('path_radius', 0.15, 'm', 'circle radius'),
        Param('path_start_angle', 0.0, 'rad', 'circle start angle'),
        Param('path_direction', 1, '', 'circle direction: +1 counter-clockwise, -1 clockwise'),
        Param('path_file', '', '', "YAML path spec (irb_description.path.path_from_spec: "
              "line, arc, polyline, spline, circle); '' = the circle of the path_* parameters. "
              'The path of the built-in profile and of plans that carry no path of their '
              'own (a plan from the planner carries its path)'),
        Param('auto_enable', False, '', 'off: nothing moves until ~/enable. On: at start-up '
              'only, start moving once a profile exists, the joint states have been steady '
              'for auto_enable_settle_s and torque_command has a subscriber (once; later '
              'motions need ~/enable)'),
        Param('auto_enable_settle_s', 0.25, 's', 'auto_enable: joint states without a gap of '
              'more than 3 periods for this long first, and torque_command subscribed for '
              'this long (real time only; 0 with use_sim_time)'),
        Param('follow_sim_time', True, '', 'joint_states stamped in simulated time while '
              '/clock is published (a simulator in lockstep or paced mode): switch to '
              'use_sim_time:=true by itself (only while nothing moves)'),
        Param('watchdog_missed_samples', 3, 'samples', 'safe stop after this many missing '
              'samples'),
        Param('watchdog_sim_time_timeout_s', 1.0, 's', 'minimum watchdog timeout with '
              'use_sim_time (lockstep)'),
        Param('deadline_s', 0.002, 's', 'a step slower than this counts as a missed '
              'deadline'),
        Param('future_tolerance_s', 0.005, 's', "joint states stamped further in the future "
              "than this (against this node's clock) are refused"),
        Param('max_plan_points', 20000, '', 'plans with more points are refused'),
        Param('max_plan_acceleration_rad_s2', _g.max_acceleration, 'rad/s^2', 'plans with a '
              'faster joint acceleration are refused'),
        Param('plan_torque_fraction', _g.torque_fraction, '', 'plans whose feed-forward '
              'torque needs more than this fraction of a torque limit are refused'),
        Param('max_ramp_s', 10.0, 's', 'enable is refused when the ramp to the start would '
              'take longer'),
        Param('require_axis_status', True, '', 'enable only once the simulator or axis '
              'bridge has reported its status on axis_status, and never while it reports an '
              'error'),
        Param('executor', 'events', '', "'events' (EventsExecutor, spin_once loop) or "
              "'single'"),
        Param('gc_report_ms', 0.0, 'ms', 'diagnostic: log every garbage collection of the '
              'process longer than this (they hold the interpreter lock on whichever thread '
              'allocated, the control thread included); 0 = off'),
        *REALTIME_PARAMS),
    subscribes=(
        Topic('joint_states', 'sensor_msgs/JointState', 'q, qd of joint_1..3 (by name)'),
        Topic('planned_trajectory', 'trajectory_msgs/JointTrajectory', 'plans (latched): '
              'joints or [theta]; the path in header.frame_id (irb_description.plan_path)'),
        Topic('axis_status', 'irb_interfaces/AxisStatus', 'the drives (simulator or bridge)')),
    publishes=(
        Topic('torque_command', 'sensor_msgs/JointState', 'effort [N m], header.stamp = the '
              'answered state'),
        Topic('controller_state', 'irb_interfaces/ControllerState', 'mode, refs, errors, '
              'torques, every sample'),
        Topic('~/plan_status', 'irb_interfaces/PlanStatus', 'verdict on the latest plan '
              '(latched), by its stamp')),
    services=(Topic('~/enable', 'std_srvs/Trigger', 'start: ramp to the (pending) profile; '
                    'clears a latched stop'),
              Topic('~/stop', 'std_srvs/Trigger', 'latched safe stop'),
              Topic('~/hold', 'std_srvs/Trigger', 'controlled stop: a motion decelerates '
                    'along its own path/profile, then holds the pose, motors on (HOLD, no '
                    'latched error); refused while idle or stopped'),
              Topic('~/power_brakes', 'std_srvs/Trigger', 'power mode: brakes engaged, '
                    'motors off (only at rest: idle, or holding still); the drive\'s '
                    '<source>/power_brakes does it'),
              Topic('~/power_bus_off', 'std_srvs/Trigger', 'power mode: brakes, DC bus off '
                    '(at rest)'),
              Topic('~/power_hibernate', 'std_srvs/Trigger', 'power mode: hibernate (at '
                    'rest)'),
              Topic('~/power_hold', 'std_srvs/Trigger', 'power mode hold: drives on, the '
                    'pose the brakes held is held by the motors (its gravity torque acts '
                    'before the brakes open); enable is refused until then')),
    example='ros2 run irb_control pdplus    # then: ros2 run irb_bringup ctl enable\n'
            'ros2 run irb_control pdplus --ros-args -p builtin_profile:=none')


class PdPlusNode(Node):
    """Subscribes /joint_states and /planned_trajectory; publishes /torque_command
    (sensor_msgs/JointState, effort [N m], stamp = the answered state's stamp) and
    /controller_state; services ~/enable, ~/stop and ~/hold (std_srvs/Trigger)."""

    def __init__(self, **kwargs):
        super().__init__('pdplus', **kwargs)
        P = declare_params(self, [x for x in SPEC.params if x not in REALTIME_PARAMS])
        self.realtime = declare_realtime(self)       # (priority, cpus, latency): main
        self.P = P
        # log lines are written on a thread of their own (LogThread: 1-2 ms each in rclpy)
        self.log = LogThread(lambda: self.get_logger())
        self.gc_watch = (GcWatch(P['gc_report_ms'] * 1e-3, self.log.warn)
                         if P['gc_report_ms'] > 0 else None)
        self.model = joint_model(P['joints'], P['tcp_xyz'])
        n = self.model.nq
        if n == 6 and P['builtin_profile'] == 'circle':
            raise ValueError("joints 6: builtin_profile 'none' (plans only) or 'sine' (the "
                             'circle has no tool orientation)')
        try:
            self.path = (load_path_file(P['path_file']) if P['path_file'] else
                         CirclePath(np.array(P['path_center'], float), P['path_radius'],
                                    P['path_start_angle'], int(P['path_direction'])))
        except ValueError as exc:
            raise PathConfigError(str(exc)) from None
        tl = P['torque_limit_nm']
        cfg = ControllerConfig(
            kp=tuple(P['kp']), kd=tuple(P['kd']), period_s=P['period_s'],
            gain_design_inertia_kg_m2=(tuple(P['gain_design_inertia_kg_m2'])
                                       if len(P['gain_design_inertia_kg_m2']) else None),
            prediction_samples=P['prediction_samples'],
            delay_prediction=P['delay_prediction'],
            ramp_min_duration_s=P['ramp_min_duration_s'],
            friction_blend_a=P['friction_blend_a'],
            torque_limit_nm=None if len(tl) != n else tuple(tl),
            torque_rate_limit_nm_s=tuple(P['torque_rate_limit_nm_s']),
            velocity_limit_fraction=P['velocity_limit_fraction'],
            max_tracking_error_rad=tuple(P['max_tracking_error_rad']),
            theta_max_lead_rad=P['theta_max_lead_rad'],
            ki=tuple(P['ki']) or None, integral_limit_nm=tuple(P['integral_limit_nm']) or None,
            stribeck_measured=tuple(bool(x) for x in P['stribeck_measured']) or None,
            stiction_prediction=bool(P['stiction_prediction']),
            stiction_rest_speed_rad_s=P['stiction_rest_speed_rad_s'])
        if cfg.stiction_prediction and P['friction_mode'] != 'file':
            # the prediction trusts the map's breakaway levels: with the nominal map it made
            # the wrist worse than without it (0.74 against 0.44 deg, doc/six_joint.md)
            cfg = dataclasses.replace(cfg, stiction_prediction=False)
            self.log.warn("stiction_prediction is off: it needs an identified map of the "
                          "wrist (friction_mode 'file' with friction_map_file), not "
                          f"friction_mode {P['friction_mode']!r} (doc/six_joint.md)")
        friction = controller_friction(self.model, P['friction_mode'], P['friction_map_file'])
        self.ctrl = PdPlusController(self.model, self.path, cfg, friction)
        # profiles let go of (a plan replaced, the old motion at enable) are freed on a thread
        # of their own, in slices: dropped on the control thread, a 20 000-point profile held
        # the interpreter lock for 9-11 ms (one unanswered state at enable)
        self._retired: queue.SimpleQueue = queue.SimpleQueue()
        self.ctrl.retire = self._retired.put
        threading.Thread(target=self._dispose_loop, name='pdplus_dispose', daemon=True).start()
        self.time_driven = P['reference_mode'] == 'time'
        self._set_builtin_profile()
        sim_time = self.get_parameter('use_sim_time').value
        self.watchdog = Watchdog(cfg.period_s, P['watchdog_missed_samples'],
                                 P['watchdog_sim_time_timeout_s'] if sim_time else 0.0)
        self.missed = 0
        self._last_stamp: float | None = None
        # auto_enable waits for a steady stream and a matched command topic (at start-up DDS
        # discovery may still be going on: a ramp started then met a 17 ms gap or commands
        # nobody received, and ended in a safe stop)
        self._auto_enable_pending = bool(P['auto_enable'])
        self._settle = SettleGate(0.0 if sim_time else P['auto_enable_settle_s'], cfg.period_s)
        self._cmd_matched_at: float | None = None     # torque_command first seen subscribed
        self.pub_cmd = self.create_publisher(JointState, 'torque_command', state_pub_qos())
        self.pub_state = self.create_publisher(ControllerState, 'controller_state',
                                              state_pub_qos())
        self.create_subscription(JointState, 'joint_states', self.on_state_raw, state_qos(),
                                 raw=True)
        self.create_subscription(AxisStatus, 'axis_status', self.on_axis_status,
                                 latched_qos())
        self.pub_plan_status = self.create_publisher(PlanStatus, '~/plan_status',
                                                     latched_qos())
        self.plans_accepted = self.plans_refused = 0
        self.create_service(Trigger, '~/enable', self.on_enable)
        self.create_service(Trigger, '~/stop', self.on_stop)
        self.create_service(Trigger, '~/hold', self.on_hold)
        # power modes: pdplus asks the drive (simulator or bridge: <axis_status.source>/
        # power_<mode>) and follows it; None = never asked (the drive's own default)
        self.drive_mode: str | None = None
        self._drive_clients: dict = {}
        for mode in POWER_MODES:
            self.create_service(Trigger, f'~/power_{mode}',
                                lambda req, resp, mode=mode: self.on_power_mode(mode, resp))
        self._names = list(self.model.joint_names)
        self._last_q = None                     # the last measured pose (ramp check)
        self._last_qd = None                    # ... and speed (brakes only at rest)
        self._name_key: tuple | None = None     # names of the last joint state ...
        self._name_idx: tuple | None = None     # ... and the indices of joints 1-3 in them
        self._name_get = None                   # ... as an itemgetter (six joints)
        # the loop topics travel serialized (cdr.py): no message objects in the hot path
        self._decoder = JointStateDecoder()
        self._cmd_enc = JointStateEncoder(self._names, 0, 0, n)
        self._nan_in = _NAN3 if n == 3 else (math.nan,) * n     # a state without our joints
        self._state_enc = ControllerStateEncoder()
        self._deadline_s = float(P['deadline_s'])
        self._future_s = float(P['future_tolerance_s'])
        self.rejected_stale = 0             # states too old or from the future
        self._clock_probe_due = 0.0         # next look for a /clock publisher [steady s]
        self.axis: AxisStatus | None = None
        self.last_plan: dict | None = None  # the plan gate's latest outcome
        # one lock around every change of the controller: the step (control thread), the
        # watchdog (its thread), plans (the gate's reader thread), enable/stop (services)
        self._lock = threading.Lock()
        self._last_valid: float | None = None     # steady time of the last valid state
        self._closing = threading.Event()
        self._watch = threading.Thread(target=self._watch_loop, name='pdplus_watchdog',
                                       daemon=True)
        self._watch.start()
        self.gate = PlanGate(GateConfig(
            topic=self.resolve_topic_name('planned_trajectory'),
            namespace=self.get_namespace(), path_center=tuple(P['path_center']),
            path_radius=P['path_radius'], path_start_angle=P['path_start_angle'],
            path_direction=int(P['path_direction']), path_file=P['path_file'],
            time_driven=self.time_driven,
            min_theta_dot=P['min_theta_dot'],
            velocity_limit_fraction=P['velocity_limit_fraction'],
            max_points=int(P['max_plan_points']),
            max_acceleration=P['max_plan_acceleration_rad_s2'],
            torque_fraction=P['plan_torque_fraction'], friction_mode=P['friction_mode'],
            friction_map_file=P['friction_map_file'], joints=n,
            tcp_xyz=tuple(P['tcp_xyz']), domain_id=self.context.get_domain_id()),
            self.on_plan_result, self.on_gate_exit)
        self.get_logger().info(
            f"pdplus: {P['reference_mode']}-driven, friction {P['friction_mode']}"
            f" ({friction.source if friction else 'off'}), Kp {P['kp']}, Kd {P['kd']}")

    def _dispose_loop(self) -> None:
        while True:
            obj = self._retired.get()
            if obj is None:
                return
            dispose_sliced(obj)
            del obj

    def _set_builtin_profile(self) -> None:
        P = self.P
        if P['builtin_profile'] == 'sine':
            three = self.model if self.model.nq == 3 else joint_model(3)
            start = default_circle_profile(three, self.path, P['profile_duration_s'],
                                           P['min_theta_dot']).q[0]
            # six joints: the circle's start with the wrist at 0
            start = np.r_[start, np.zeros(self.model.nq - 3)]
            traj = sine_trajectory(start, int(P['sine_joint']) - 1, P['sine_peak_speed_rad_s'],
                                   P['sine_amplitude_rad'], P['sine_cycles'])
            self.ctrl.set_time_trajectory(traj)
            self.time_driven = True
        elif P['builtin_profile'] == 'circle':
            prof = default_circle_profile(self.model, self.path, P['profile_duration_s'],
                                          P['min_theta_dot'])
            if self.time_driven:
                rows = np.array([prof.sample(x) for x in prof.theta])
                prof = TimeTrajectory(prof.t - prof.t[0], rows[:, 2:5], rows[:, 5:8],
                                      rows[:, 8:11])
                self.ctrl.set_time_trajectory(prof)
            else:
                self.ctrl.set_path_profile(prof)
        elif P['builtin_profile'] == 'none':
            self.get_logger().info('no built-in profile: waiting for /planned_trajectory')
            return
        else:
            raise ValueError(f"builtin_profile must be 'circle', 'sine' or 'none', "
                             f"not {P['builtin_profile']!r}")

    # --- callbacks -----------------------------------------------------------------------
    def on_state_raw(self, data: bytes) -> None:
        """/joint_states as serialized bytes (the subscription is raw: no message object)."""
        t_in = time.perf_counter()
        try:
            sec, nanosec, names, position, velocity, _ = self._decoder.decode(data)
        except ValueError as exc:
            self.ctrl.step(math.nan, self._nan_in, self._nan_in)   # a rejected input
            self.log.warn(f'joint_states refused: {exc}', throttle_s=1.0)
            return
        q, qd = self._select(names, position, velocity)
        self._last_q, self._last_qd = q, qd
        self._on_sample(t_in, sec, nanosec, q, qd)

    def on_state(self, msg: JointState) -> None:
        """The same for a JointState message object."""
        t_in = time.perf_counter()
        q, qd = self._select(tuple(msg.name), msg.position, msg.velocity)
        self._last_q, self._last_qd = q, qd
        self._on_sample(t_in, msg.header.stamp.sec, msg.header.stamp.nanosec, q, qd)

    def _on_sample(self, t_in: float, sec: int, nanosec: int, q, qd) -> None:
        # hot path (248 Hz): the command goes out first, bookkeeping and the state message after
        stamp = sec + nanosec * 1e-9
        age = self._clock_s() - stamp
        if not -self._future_s <= age <= self.watchdog.timeout_s:
            # too old to answer (it waited somewhere longer than the watchdog limit) or from
            # the future: never answered, never counted as a deadline, the watchdog not fed
            self._refuse_stamp(stamp, age)
            return
        if self._auto_enable_pending:
            self._try_auto_enable(t_in)
        now = time.monotonic()              # CLOCK_MONOTONIC, as ROS's STEADY_TIME
        with self._lock:
            was = self.ctrl.mode
            if (was in MOVING or was == MODE_HOLD) and self._last_valid is not None \
                    and now - self._last_valid > self.watchdog.timeout_s:
                # pdplus itself (or its input) stalled: stop before answering anything
                self.ctrl.stop(f'stall: no valid joint_states processed for '
                               f'{now - self._last_valid:.4f} s')
            out = self.ctrl.step(stamp, q, qd)
        if out.publish:
            self.pub_cmd.publish(self._cmd_enc.encode(sec, nanosec, (), (), out.tau.tolist()))
        if not out.rejected_input:
            self._last_valid = now
            self.watchdog.feed(now)
            T = self.ctrl.config.period_s
            if self._last_stamp is not None and 1.5 * T < stamp - self._last_stamp < 1.0:
                self.missed += int(round((stamp - self._last_stamp) / T)) - 1
            self._last_stamp = stamp
        dt = time.perf_counter() - t_in
        if dt > self._deadline_s:
            self.missed += 1
        if out.mode != was:
            self._log_mode(was, out.mode, out.stop_reason)
        self.pub_state.publish(self._state_enc.encode(
            sec, nanosec, out.mode, out.stop_reason, float(out.theta),
            float(out.theta_predicted), float(out.theta_dot_ref),
            (out.q_ref.tolist(), out.qd_ref.tolist(), out.qdd_ref.tolist(),
             out.q_error.tolist(), out.qd_error.tolist(), out.tau_model.tolist(),
             out.tau_friction.tolist(), out.tau_feedback.tolist(), out.tau.tolist()),
            self.missed, self.ctrl.rejected_inputs + self.rejected_stale, dt))

    def _refuse_stamp(self, stamp: float, age: float) -> None:
        """A state too old or from the future: counted, and a hint that names the clocks.
        A simulator in lockstep/paced mode stamps in simulated time (/clock, from 0): while
        nothing moves, pdplus follows /clock by itself (use_sim_time) when it is published."""
        self.rejected_stale += 1
        sim_time = bool(self.get_parameter('use_sim_time').value)
        state_sim = stamp < _SIM_EPOCH_S           # simulated time starts at 0, system ~1.8e9
        now = time.monotonic()
        if state_sim and not sim_time and now >= self._clock_probe_due:
            self._clock_probe_due = now + 1.0
            if self.count_publishers('/clock') > 0 and self.P['follow_sim_time'] and \
                    self.ctrl.mode not in MOVING and self.ctrl.mode != MODE_HOLD:
                self._use_sim_time()
                return
        old = f'{age * 1e3:.1f} ms old' if age > 0 else f'{-age * 1e3:.1f} ms in the future'
        if state_sim and not sim_time:
            hint = ('state stamped in simulated time (/clock) but pdplus uses the system '
                    'clock: set use_sim_time:=true' + ('' if self.count_publishers('/clock')
                                                       else ' (no /clock is published yet)'))
        elif sim_time and not state_sim:
            hint = ('state stamped in system time but pdplus uses simulated time (/clock'
                    + (', none received yet' if self._clock_s() == 0.0 else '')
                    + '): set use_sim_time:=false, or run the simulator in lockstep')
        elif sim_time:
            hint = ('both in simulated time (/clock): the state waited longer than the '
                    'watchdog limit, or /clock and the states come from different simulators')
        else:
            hint = ('both in system time: the state waited longer than the watchdog limit '
                    '(a stall of pdplus or of the network), or the system clocks of the hosts '
                    'differ (synchronise them, e.g. chrony)')
        self.log.warn(f'joint_states stamped {stamp:.6f} s refused: {old}; {hint}',
                      throttle_s=1.0, key='stamp')

    def _use_sim_time(self) -> None:
        """Switch to simulated time (/clock), with the watchdog's simulated-time minimum and no
        settle time, as if started with use_sim_time:=true (only while nothing moves)."""
        from rclpy.parameter import Parameter
        self.set_parameters([Parameter('use_sim_time', value=True)])
        P, T = self.P, self.ctrl.config.period_s
        self.watchdog = Watchdog(T, P['watchdog_missed_samples'],
                                 P['watchdog_sim_time_timeout_s'])
        self._settle = SettleGate(0.0, T)
        self.log.info('joint_states are stamped in simulated time and /clock is '
                               'published (a simulator in lockstep): pdplus now uses /clock '
                               '(use_sim_time:=true)')

    def _clock_s(self) -> float:
        """The node's clock [s] (ROS time: system, or /clock with use_sim_time), against
        which a state's age is judged."""
        return self.get_clock().now().nanoseconds * 1e-9

    def _log_mode(self, was: int, mode: int, reason: str) -> None:
        # one call site per severity: rclpy refuses a severity change at the same site
        text = f'mode {MODE_NAMES[was]} -> {MODE_NAMES[mode]}' + (f': {reason}' if reason
                                                                 else '')
        if mode == MODE_STOPPED:
            self.log.error(text)
        else:
            self.log.info(text)

    def _try_auto_enable(self, now: float) -> None:
        """auto_enable (start-up only): enable once the joint states have arrived without a
        gap of more than 3 periods for auto_enable_settle_s (SettleGate), torque_command has a
        subscriber and a profile exists. ``now``: the sample's arrival [s, perf_counter]."""
        if not self._settle.feed(now) or self.ctrl.profile is None:
            return
        if self.pub_cmd.get_subscription_count() == 0:
            self._cmd_matched_at = None
            self.log.info('auto_enable: waiting for a subscriber of torque_command',
                          throttle_s=5.0)
            return
        # the writer sees the subscriber before the subscriber's side has matched this writer:
        # until then commands are dropped (a CI run: 4 commands of a whole ramp reached the
        # axis bridge, all late, and the axis computer latched a comm timeout); give the
        # other side auto_enable_settle_s too
        if self._cmd_matched_at is None:
            self._cmd_matched_at = now
        if now - self._cmd_matched_at < self._settle.settle_s:
            return
        ok, text = self._enable()
        if ok or 'axis' not in text:          # waiting for the axis status keeps it pending
            self._auto_enable_pending = False
        self.log.info(f'auto_enable: {text}', throttle_s=5.0, key='auto_enable')

    def _watch_loop(self) -> None:
        """The watchdog on a thread of its own: every half period, on the steady clock, the age
        of the last valid state while moving or holding; older than the limit -> latched stop
        (also when the control thread itself is stuck)."""
        period = 0.5 * self.ctrl.config.period_s
        while not self._closing.wait(period):
            now = time.monotonic()
            last = self._last_valid
            if (self.ctrl.mode in MOVING or self.ctrl.mode == MODE_HOLD) and last is not None \
                    and now - last > self.watchdog.timeout_s:
                with self._lock:
                    if self.ctrl.mode == MODE_STOPPED:
                        continue
                    self.ctrl.stop(f'watchdog: no valid joint_states for {now - last:.4f} s')
                self.log.error(f'safe stop: {self.ctrl.stop_reason}')
                self._publish_stopped()

    def _publish_stopped(self) -> None:
        s = ControllerState()
        s.header.stamp = self.get_clock().now().to_msg()
        s.mode = MODE_STOPPED
        s.stop_reason = self.ctrl.stop_reason
        s.missed_deadlines = self.missed
        s.rejected_inputs = self.ctrl.rejected_inputs + self.rejected_stale
        self.pub_state.publish(s)

    def on_plan_result(self, result: dict) -> None:
        """A plan the gate process checked (reader thread): offered to the controller, where it
        waits for enable; or the reason it was refused. Either way ~/plan_status says so."""
        if result.get('ok'):
            try:
                if self.time_driven != (result['kind'] == 'time'):
                    raise ProfileError(f"{'time' if self.time_driven else 'theta'}-driven mode "
                                       f"cannot use a {result['kind']} profile")
                # built in slices (no long hold of the interpreter lock: the control thread
                # runs between them), then frozen for the garbage collector as at start-up
                prof = profile_from_result(result, sliced=True)
                gc.freeze()
                with self._lock:
                    why = (self.ctrl.set_time_trajectory(prof) if self.time_driven
                           else self.ctrl.set_path_profile(prof, result.get('path'),
                                                           result.get('tracker')))
                if result.get('path') is not None:
                    why += f" (on its own {result.get('path_type', '')} path)"
            except ProfileError as exc:
                result = dict(result, ok=False, reason=str(exc))
        sm = result.get('summary', {})
        status = PlanStatus(accepted=bool(result.get('ok')), reason=result.get('reason', ''),
                            points=int(sm.get('points', result.get('points', 0))),
                            duration=float(sm.get('duration_s', 0.0)))
        sec, nanosec = result.get('stamp', (0, 0))
        status.plan_stamp.sec, status.plan_stamp.nanosec = int(sec), int(nanosec)
        if status.accepted:
            self.plans_accepted += 1
            self.get_logger().info(f'planned_trajectory accepted ({status.points} points, '
                                   f'{status.duration:.3f} s): {why}; it starts on ~/enable')
        else:
            self.plans_refused += 1
            self.get_logger().error(f'planned_trajectory refused: {status.reason}')
        status.accepted_count, status.refused_count = self.plans_accepted, self.plans_refused
        status.header.stamp = self.get_clock().now().to_msg()
        old, self.last_plan = self.last_plan, result
        if old is not None:
            self._retired.put(old)       # freed on the disposal thread
        self.pub_plan_status.publish(status)

    def on_gate_exit(self, text: str) -> None:
        self.get_logger().error(text)

    def on_axis_status(self, msg: AxisStatus) -> None:
        """The drives' status: an error while moving is a latched stop."""
        old, self.axis = self.axis, msg
        if msg.error and (old is None or not old.error):
            self.log.error(f'{msg.source}: error {msg.error:#x} ({msg.error_text}); '
                                    'enable is refused until it is reset')
        if msg.error and self.ctrl.mode != MODE_STOPPED:
            with self._lock:
                self.ctrl.stop(f'{msg.source} reports error {msg.error:#x}: {msg.error_text}')
            self._publish_stopped()

    def _enable(self) -> tuple[bool, str]:
        """Enable, after the checks that cannot wait for the ramp: the drives report no error
        (and report at all, with require_axis_status), the ramp from where the robot is to the
        start takes at most max_ramp_s."""
        if self.axis is None and self.P['require_axis_status']:
            return False, ('no axis status yet (simulator or axis_bridge on axis_status): '
                           'refusing to move')
        if self.axis is not None and self.axis.error:
            return False, (f'{self.axis.source} reports error {self.axis.error:#x} '
                           f'({self.axis.error_text}): reset it first')
        if self.drive_mode not in (None, 'hold'):
            return False, (f'the drives are in power mode {self.drive_mode}: ~/power_hold '
                           'first')
        with self._lock:
            prof = self.ctrl.profile
            if prof is not None and self._last_q is not None:
                need = ramp_duration(self._last_q, prof.q[0], self.model.limits.velocity,
                                     self.ctrl.config.ramp_min_duration_s,
                                     self.ctrl.config.ramp_speed_fraction)
                if need > self.P['max_ramp_s']:
                    return False, (f'the start of the profile is {need:.1f} s of ramp away '
                                   f"(> max_ramp_s = {self.P['max_ramp_s']} s)")
            ok, text = self.ctrl.enable()
        if ok:
            self._auto_enable_pending = False
            self.watchdog.reset()
            self._last_valid = None
        return ok, text

    def on_enable(self, request, response):
        self._auto_enable_pending = False
        response.success, response.message = self._enable()
        self.log.info(f'enable: {response.message}')
        return response

    def on_stop(self, request, response):
        self._auto_enable_pending = False          # a stop is never undone automatically
        with self._lock:
            self.ctrl.stop('stop service')
        self._publish_stopped()
        response.success, response.message = True, 'stopped (latched until enable)'
        self.log.warn('stop service: safe stop latched')
        return response

    def on_hold(self, request, response):
        """Controlled stop (PdPlusController.hold): the step decelerates the reference along
        itself and then holds; a latched stop is never cleared by it."""
        self._auto_enable_pending = False
        with self._lock:
            mode = self.ctrl.mode
            response.success, response.message = self.ctrl.hold()
        text = f'hold ({MODE_NAMES[mode]}): {response.message}'
        if response.success:
            self.log.info(text)
        else:
            self.log.warn(text)
        return response

    def on_power_mode(self, mode: str, response):
        """A power mode for the drives (issue 29): deeper modes only at rest (checked here,
        then the drive engages its brakes and pdplus stops commanding); hold: the drive powers
        up and pdplus holds the measured pose. The drive's answer arrives later (logged)."""
        self._auto_enable_pending = False
        ok, text = self._power_mode_request(mode)
        response.success, response.message = ok, text
        (self.log.info if ok else self.log.warn)(f'power_{mode}: {text}')
        return response

    def _power_mode_request(self, mode: str) -> tuple[bool, str]:
        if self.axis is None:
            return False, 'no axis status yet: no drive to switch'
        if mode != 'hold':
            with self._lock:
                qd = self._last_qd if self._last_qd is not None else self._nan_in
                ok, why = self.ctrl.motors_off(np.asarray(qd, float), dry_run=True)
            if not ok:
                return False, why
        elif self.drive_mode in (None, 'hold'):
            return True, 'the drives are in hold already'
        name = f'{self.axis.source}/power_{mode}'
        client = self._drive_clients.get(name)
        if client is None:
            client = self._drive_clients[name] = self.create_client(Trigger, name)
        if not client.service_is_ready():
            return False, f'the drive offers no {name} service'
        fut = client.call_async(Trigger.Request())
        fut.add_done_callback(lambda f: self._power_mode_done(mode, name, f))
        return True, f'{mode} requested from {name}'

    def _power_mode_done(self, mode: str, name: str, fut) -> None:
        """The drive's answer: on success pdplus follows (motors off: IDLE; hold: HOLD the
        measured pose)."""
        try:
            r = fut.result()
        except Exception as exc:  # noqa: BLE001 - a failed call is logged, nothing changes
            self.log.error(f'power_{mode}: {name} failed: {exc}')
            return
        if not r.success:
            self.log.error(f'power_{mode}: {name} refused: {r.message}')
            return
        with self._lock:
            if mode == 'hold':
                q = self._last_q
                ok, why = (self.ctrl.motors_on(np.asarray(q, float)) if q is not None
                           else (False, 'no joint state yet'))
            else:
                qd = self._last_qd if self._last_qd is not None else self._nan_in
                ok, why = self.ctrl.motors_off(np.asarray(qd, float))
            self.drive_mode = mode
        text = f'power mode {mode} ({name}: {r.message}); pdplus: {why}'
        (self.log.info if ok else self.log.error)(text)

    def destroy_node(self):
        if self.gc_watch is not None:
            self.gc_watch.close()
        self.log.flush(2.0)
        self._closing.set()
        self._retired.put(None)
        self.gate.stop()
        return super().destroy_node()

    def _select(self, names: tuple, position, velocity):
        """q, qd of joints 1-3 by name (the index lookup cached while the names repeat);
        by position when the message has no names; NaN (-> rejected) when a joint is
        missing."""
        if names is not self._name_key and names != self._name_key:
            self._name_key = names
            self._name_idx = idx = _joint_indices(names, self._names)
            # six joints: one C call per array (a generator over six indices costs ~4x)
            self._name_get = (operator.itemgetter(*idx) if idx is not None and len(idx) > 3
                              else None)
        idx = self._name_idx
        if idx is None:
            return self._nan_in, self._nan_in
        try:
            get = self._name_get
            if get is not None:       # six joints
                return get(position), get(velocity)
            i, j, k = idx
            return (position[i], position[j], position[k]), (velocity[i], velocity[j],
                                                             velocity[k])
        except IndexError:
            return self._nan_in, self._nan_in


_NAN3 = (math.nan, math.nan, math.nan)
#: stamps before this [s] are simulated time (/clock starts at 0), after it system time
_SIM_EPOCH_S = 1.0e8


def _joint_indices(names: tuple, joints: list[str]) -> tuple | None:
    """Indices of ``joints`` in ``names`` (0, 1, 2 when ``names`` is empty), None if one is
    missing."""
    if not names:
        return tuple(range(len(joints)))
    try:
        return tuple(names.index(n) for n in joints)
    except ValueError:
        return None


class PathConfigError(ValueError):
    """The configured path (path_file or the path_* circle) is not usable."""


def main(args=None):
    short_switch_interval()
    # a PathConfigError (a ValueError) ends in one line and exit 2 through run_node
    run_node(PdPlusNode, lambda node: spin_with(node.P['executor'], node.realtime)(node),
             args, spec=SPEC)


if __name__ == '__main__':
    main()
