"""`ros2 run irb_control simulator`: the simulated IRB 1600 (thin adapter over plant.Plant).

Publishes /joint_states every period (real time) or as fast as the controller answers
(lockstep, with /clock), the camera's TCP point at 100 Hz, and applies /torque_command.
With each state it publishes ``electrical_power`` (sensor_msgs/JointState, same stamp): per
axis the power drawn from the DC bus [W] in ``effort`` under the joint names, then the robot's
total for each DC-bus mode under ``total_none``, ``total_shared``, ``total_regenerative``
(standby included), from the plant's own electrical parameters (config/plant_electrical.yaml,
irb_description.electrical), the applied torque and the true joint speed.
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PointStamped
from irb_description.electrical import BUS_MODES, load_electrical
from irb_description.node_help import NodeSpec, Param, Topic
from irb_description.node_main import (declare_params, latched_qos, run_node, running,
                                       state_pub_qos, state_qos)
from irb_description.robot_state import six_joint_names, six_joints
from irb_description.stamps import sec_nanosec
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from irb_interfaces.msg import AxisStatus
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from .cdr import JointStateDecoder, JointStateEncoder
from .node_util import (REALTIME_PARAMS, LogThread, apply_realtime, declare_realtime,
                        fifo_refusal, joint_model, make_executor, short_switch_interval)
from .plant import (POWER_MODES, Plant, PlantConfig, config_path, default_plant_yaml,
                    load_plant_brakes, load_plant_friction)
from .plant_effects import load_plant_effects


def _stamp(t: float) -> Time:
    sec, nanosec = sec_nanosec(t)
    return Time(sec=sec, nanosec=nanosec)


def _seconds(stamp: Time) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


MODES = ('auto', 'realtime', 'paced', 'lockstep')
_d = PlantConfig()
SPEC = NodeSpec(
    'simulator', 'irb_control',
    'The simulated IRB 1600 (joints 1-3 actuated, 4-6 locked; joints:=6 all six, issue 30): '
    'publishes joint_states every '
    'period and applies the torque_command answering the latest one; brakes and latched '
    'errors as the axis computer. mode auto: real time on the steady clock where the host '
    'grants SCHED_FIFO (realtime_priority > 0), else lockstep on /clock paced at 1x wall '
    'clock (pdplus switches to /clock by itself).',
    params=(
        Param('mode', 'auto', '', "'auto' (realtime where realtime_priority is granted, else "
              "paced), 'realtime' (one step per period on the steady clock, stamps = ROS "
              "time), 'paced' (lockstep on /clock at lockstep_rate x wall clock: no deadline "
              "can be missed) or 'lockstep' (as fast as the controller answers)"),
        Param('lockstep_rate', 1.0, '', "paced: simulated seconds per wall-clock second"),
        Param('joints', 3, '', "3: the thesis (joints 4-6 locked at 0, today's plant); 6: the "
              'whole arm (irb_description six_axis_model, the six joints of the plant '
              'friction file, its brakes torque_nm + wrist_torque_nm)'),
        Param('tcp_xyz', [0.0, 0.0, 0.0], 'm', 'joints 6: the TCP in tool0 the camera sees '
              '(e.g. [0, 0, 0.1], the gluing nozzle)'),
        Param('period_s', _d.period_s, 's', 'sample period'),
        Param('substeps', _d.substeps, '', 'integration substeps per period; 0: 5 with '
              'joints 3 (the thesis plant), 10 with joints 6 (plant.DEFAULT_SUBSTEPS)'),
        Param('delay_samples', _d.delay_samples, 'samples', 'command-to-effect delay'),
        Param('initial_positions', list(_d.initial_q), 'rad', 'start pose of joints 1-3 '
              '(brakes on); joints 6: six values, or three with the wrist at 0'),
        Param('command_timeout_s', _d.command_timeout_s, 's', 'once commanded, no command '
              'answering the latest state for longer: brakes, error latched until ~/reset'),
        Param('encoder_resolution_rad', _d.encoder_resolution_rad, 'rad', 'encoder quantum '
              '(arm side)'),
        Param('position_noise_rad', _d.position_noise_rad, 'rad', 'encoder noise std'),
        Param('velocity_noise_rad_s', _d.velocity_noise_rad_s, 'rad/s', 'speed noise std'),
        Param('camera_period_s', _d.camera_period_s, 's', 'camera sample period'),
        Param('camera_noise_m', _d.camera_noise_m, 'm', 'camera noise std per axis'),
        Param('seed', _d.seed, '', 'noise seed'),
        Param('plant_friction_file', '', '', "plant friction YAML; '' = config/plant.yaml"),
        Param('plant_effects_file', '', '', "YAML with an 'effects:' section; '' = the plant "
              'friction file (no section: no effects)'),
        Param('plant_electrical_file', '', '', "plant electrical parameters YAML ('' = "
              "config/plant_electrical.yaml); 'none' = do not publish electrical_power"),
        Param('status_period_s', 0.1, 's', 'axis_status at least this often (and on change)'),
        Param('lockstep_wait_s', 0.5, 's', 'lockstep/paced: wall time to wait for the command '
              'answering a state before stepping without it (3 such steps: brakes); below '
              "pdplus's simulated-time watchdog (1 s)"),
        Param('stats_path', '', '', "write loop statistics JSON here at exit ('' = no)"),
        Param('stats_per_state', False, '', 'stats_path: also every state (steady-clock time '
              'it went out, latency of its answer or null): the benchmarks\' windows'),
        Param('executor', 'events', '', "'events' (EventsExecutor, lower latency) or "
              "'single'"),
        *REALTIME_PARAMS),
    subscribes=(Topic('torque_command', 'sensor_msgs/JointState',
                      'effort [N m] of joint_1..3 (joints 6: joint_1..6), header.stamp = the '
                      'answered state'),),
    publishes=(
        Topic('joint_states', 'sensor_msgs/JointState',
              'q [rad], qd [rad/s], applied torque [N m], every period'),
        Topic('electrical_power', 'sensor_msgs/JointState',
              'per-axis and total DC-bus power [W] in effort, same stamp'),
        Topic('camera/tcp', 'geometry_msgs/PointStamped', 'TCP [m], 100 Hz'),
        Topic('axis_status', 'irb_interfaces/AxisStatus', 'drives: brakes, latched errors'),
        Topic('/clock', 'rosgraph_msgs/Clock', 'simulated time (paced and lockstep)')),
    services=(Topic('~/reset', 'std_srvs/Trigger', 'clear a latched error'),
              Topic('~/power_hold', 'std_srvs/Trigger', 'drives on (brakes open once a '
                    'command has acted for the brake release time)'),
              Topic('~/power_brakes', 'std_srvs/Trigger', 'brakes engaged, power stages off'),
              Topic('~/power_bus_off', 'std_srvs/Trigger', 'brakes engaged, DC bus off'),
              Topic('~/power_hibernate', 'std_srvs/Trigger', 'controller hibernating, bus off, '
                    'brakes engaged (each change takes its transition time of '
                    'irb_description power_modes.yaml; the mode powers are in '
                    'electrical_power)')),
    example='ros2 run irb_control simulator\n'
            'ros2 run irb_control simulator --ros-args -p mode:=realtime -p '
            'realtime_priority:=20')


class SimulatorNode(Node):
    """Plant in a node; ``run()`` is its loop (real time on the steady clock, or lockstep)."""

    def __init__(self, **kwargs):
        super().__init__('simulator', **kwargs)
        p = declare_params(self, [x for x in SPEC.params if x not in REALTIME_PARAMS])
        self.realtime = declare_realtime(self)       # (priority, cpus, latency): _spin
        self.p = p
        self.log = LogThread(lambda: self.get_logger())      # lines of the hot path
        if p['mode'] not in MODES:
            raise ValueError(f"mode must be one of {MODES}, not {p['mode']!r}")
        if not p['lockstep_rate'] > 0:
            raise ValueError(f"lockstep_rate must be > 0, not {p['lockstep_rate']}")
        self.mode = p['mode']
        if self.mode == 'auto':
            # the real-time loop only where the host schedules it in time: without SCHED_FIFO
            # a 2-core machine at load 1.3 latched a watchdog stop 1.3 s after enabling
            why = fifo_refusal(self.realtime[0])
            self.mode = 'realtime' if not why else 'paced'
            if why:
                self.get_logger().info(
                    f'mode auto: no real-time priority ({why}): simulated time on /clock, '
                    f"paced at {p['lockstep_rate']:g}x wall clock, every state answered "
                    '(pdplus follows /clock by itself); real time: -p mode:=realtime -p '
                    'realtime_priority:=20')
        model = joint_model(p['joints'], p['tcp_xyz'])
        self.joint_names = model.joint_names
        ffile = p['plant_friction_file'] or str(default_plant_yaml())
        _, friction = load_plant_friction(ffile, model.joint_names)
        q0 = list(p['initial_positions'])
        if p['joints'] == 6 and len(q0) == 3:
            q0 += [0.0, 0.0, 0.0]
        self.config = PlantConfig(
            period_s=p['period_s'], substeps=p['substeps'], delay_samples=p['delay_samples'],
            initial_q=tuple(q0), command_timeout_s=p['command_timeout_s'],
            encoder_resolution_rad=p['encoder_resolution_rad'],
            position_noise_rad=p['position_noise_rad'],
            velocity_noise_rad_s=p['velocity_noise_rad_s'],
            camera_period_s=p['camera_period_s'], camera_noise_m=p['camera_noise_m'],
            seed=p['seed'], **load_plant_brakes(ffile, p['joints']))
        effects = load_plant_effects(p['plant_effects_file'] or ffile)
        self.plant = Plant(model, friction, self.config, effects)
        self.lockstep = self.mode in ('lockstep', 'paced')
        efile = p['plant_electrical_file'] or str(config_path('plant_electrical.yaml'))
        self.electrical = (None if efile == 'none'
                           else load_electrical(Path(efile)).axes(len(self.joint_names)))
        self.pub_power = (self.create_publisher(JointState, 'electrical_power', state_pub_qos())
                          if self.electrical is not None else None)
        # the drives' power modes (irb_description.power_modes, on the plant's own electrical
        # model): their input power in electrical_power, their transition times in the plant
        from irb_description.power_modes import load_power_modes
        self.power_modes = (load_power_modes(electrical=self.electrical)
                            if self.electrical is not None else None)
        for mode in POWER_MODES:
            self.create_service(Trigger, f'~/power_{mode}',
                                lambda req, resp, mode=mode: self.on_power_mode(mode, resp))
        self._power_names = list(self.joint_names) + [f'total_{m}' for m in BUS_MODES]
        self.pub_state = self.create_publisher(JointState, 'joint_states', state_pub_qos())
        # the camera's 100 Hz like the loop topics: a reliable reader (the recorder) that is
        # busy for a moment (subscribing, a disk flush) must not lose samples (was depth 50:
        # 0.5 s, and a fresh-clone CI lost one at the recorder's start)
        self.pub_cam = self.create_publisher(PointStamped, 'camera/tcp', state_pub_qos())
        self.pub_clock = (self.create_publisher(Clock, '/clock', qos_profile_sensor_data)
                          if self.lockstep else None)
        self.create_subscription(JointState, 'torque_command', self.on_command_raw,
                                 state_qos(), raw=True)
        # the drives' status, as the axis computer reports it; errors latch until ~/reset
        self.pub_status = self.create_publisher(AxisStatus, 'axis_status', latched_qos())
        self.create_service(Trigger, '~/reset', self.on_reset)
        self._status_key = None
        self._status_due = 0.0
        # the loop topics travel serialized (cdr.py): no message objects in the hot path
        # /joint_states names all six joints, 4-6 at their locked values (irb_description)
        self._state_enc = JointStateEncoder(six_joint_names(), 6, 6, 6)
        self._decoder = JointStateDecoder()
        self._effort_names: tuple | None = None  # names of the last command ...
        self._effort_idx: list | None = None     # ... and the indices of joints 1-3 in it
        # loop statistics: state publish time per stamp, latency of the matching command
        self._sent: dict[int, float] = {}
        self._newest_key: int | None = None
        self._per_state = [] if p['stats_per_state'] and p['stats_path'] else None
        self._answered_k = -1
        self._k = 0
        self.latencies: list[float] = []
        self.stale_commands = 0               # commands that did not answer the latest state
        self.tick_late: list[float] = []      # [s] how late each state went out (real time)
        self.missed = 0
        self.missed_run = 0
        self.max_missed_run = 0
        self.t_wall0 = time.monotonic()
        self.get_logger().info(
            f"simulator: {self.mode}, T = {p['period_s']} s, "
            f"{self.plant.config.substeps} substeps, delay "
            f"{p['delay_samples']} samples, plant friction {ffile}, effects "
            f"{effects.names() or 'none'}")

    # --- command -------------------------------------------------------------------------
    def on_command_raw(self, data: bytes) -> None:
        """/torque_command as serialized bytes (the subscription is raw: no message object)."""
        now = time.monotonic()
        try:
            sec, nanosec, names, _, _, effort = self._decoder.decode(data)
        except ValueError as exc:
            self.get_logger().warn(f'torque_command refused: {exc}', throttle_duration_sec=1.0)
            return
        self._apply_command(now, sec, nanosec, names, effort)

    def on_command(self, msg: JointState) -> None:
        """The same for a JointState message object."""
        now = time.monotonic()
        self._apply_command(now, msg.header.stamp.sec, msg.header.stamp.nanosec,
                            tuple(msg.name), msg.effort)

    def _apply_command(self, now: float, sec: int, nanosec: int, names: tuple, effort) -> None:
        tau = self._effort(names, effort)
        if tau is None:
            self.get_logger().warn(f'torque_command without efforts for joints 1-'
                                   f'{len(self.joint_names)}: ignored',
                                   throttle_duration_sec=1.0)
            return
        key = sec * 1_000_000_000 + nanosec
        t_sent = self._sent.pop(key, None)
        if t_sent is None:
            # not the answer to the latest state (as the axis computer, which applies only
            # the command carrying the current cycle's sequence number): a late or stale
            # command never acts on the robot (a pdplus frozen and resumed answers old states)
            self.stale_commands += 1
            newest = self._newest_key
            self.log.warn(
                f'torque_command refused ({self.stale_commands} so far): it answers the state '
                f'stamped {sec}.{nanosec:09d}, '
                + (f'{(newest - key) * 1e-6:.1f} ms older than the newest state sent'
                   if newest is not None and key < newest else 'not the newest state sent'),
                throttle_s=1.0, key='stale')
            return
        self.plant.command(tau)
        self.latencies.append(now - t_sent)
        if self._per_state:
            self._per_state[-1][1] = round((now - t_sent) * 1e3, 4)
        self._answered_k = self._k

    def _effort(self, names: tuple, effort) -> np.ndarray | None:
        """``_effort_by_name`` with the index lookup cached for repeated joint names."""
        if names and len(effort) == len(names) and (names is self._effort_names
                                                    or names == self._effort_names):
            i = self._effort_idx
            if len(i) != 3:
                return np.array([effort[j] for j in i], float)
            return np.array((effort[i[0]], effort[i[1]], effort[i[2]]), float)
        tau = _effort_by_name(names, effort, self.joint_names)
        if tau is not None and names and len(names) == len(effort):
            idx = {n: i for i, n in enumerate(names)}
            self._effort_names = names
            self._effort_idx = [idx[n] for n in self.joint_names]
        return tau

    def on_reset(self, request, response):
        """Clear a latched error (as the axis computer's reset): commands are taken again."""
        was = self.plant.clear_error()
        response.success = True
        response.message = f'error cleared: {was}' if was else 'no error latched'
        self.get_logger().info(f'reset: {response.message}')
        self._status(force=True)
        return response

    def on_power_mode(self, mode: str, response):
        """The drives' power mode (as the axis computer's mode interface): the change takes
        the transition time of power_modes.yaml in simulated time; logged."""
        pl = self.plant
        dur = (self.power_modes.transition(pl.power_mode, mode).duration_s
               if self.power_modes is not None and mode != pl.power_mode else 0.0)
        response.success, response.message = pl.request_power_mode(mode, dur)
        (self.get_logger().info if response.success else self.get_logger().warn)(
            f'power mode {mode}: {response.message}')
        self._status(force=True)
        return response

    def _mode_power(self, tau) -> float | None:
        """Input power [W] of the drives while not in plain hold: a deeper mode's, or a
        transition's energy spread over its duration; None in hold (the electrical model)."""
        pl, pm = self.plant, self.power_modes
        if pm is None:
            return None
        if pl.mode_target is not None:
            from irb_description.power_modes import holding_power_w
            hp = holding_power_w(self.electrical, tau)
            tr = pm.transition(pl.power_mode, pl.mode_target, hp)
            return tr.energy_j / tr.duration_s if tr.duration_s > 0 else pm.power_w(
                pl.mode_target, hp)
        if pl.power_mode == 'hold':
            return None
        return pm.power_w(pl.power_mode)

    def _status(self, force: bool = False) -> None:
        """axis_status on every change of brakes/error and every status_period_s."""
        p = self.plant
        key = (p.braked, p.error)
        now = time.monotonic()
        if not force and key == self._status_key and now < self._status_due:
            return
        self._status_key, self._status_due = key, now + self.p['status_period_s']
        m = AxisStatus(motors_on=not p.braked, brakes_engaged=p.braked,
                       error=1 if p.error else 0, error_text=p.error, source='simulator')
        m.header.stamp = self.get_clock().now().to_msg()
        self.pub_status.publish(m)

    # --- loop ----------------------------------------------------------------------------
    def _publish_state(self, stamp: Time) -> None:
        y = self.plant.measure()
        sec, nanosec = stamp.sec, stamp.nanosec
        data = self._state_enc.encode(sec, nanosec, *six_joints(y.q, y.qd, y.tau))
        key = sec * 1_000_000_000 + nanosec
        self._sent = {key: time.monotonic()}      # only the latest state can be answered
        self._newest_key = key
        if self._per_state is not None:
            self._per_state.append([self._sent[key], None])
        self.pub_state.publish(data)
        if self.pub_power is not None:
            e, qd = self.electrical, self.plant.state.qd
            other = self._mode_power(y.tau)
            if other is None:
                pax = e.axis_power(y.tau, qd)
                tot = [float(e.power(y.tau, qd, m)) for m in BUS_MODES]
            else:       # a deeper power mode or a transition: the mode's input power
                pax = np.zeros(len(self.joint_names))
                tot = [float(other)] * len(BUS_MODES)
            msg = JointState(name=self._power_names, effort=pax.tolist() + tot)
            msg.header.stamp = stamp
            self.pub_power.publish(msg)

    def _after_step(self, stamp_of) -> None:
        self._status()
        for t, text in self.plant.events:
            self.get_logger().warn(f'[t = {t:.3f} s] {text}')
        self.plant.events.clear()
        for t, pt in self.plant.take_camera():
            m = PointStamped()
            m.header.stamp = stamp_of(t)
            m.header.frame_id = 'base_link'
            m.point.x, m.point.y, m.point.z = (float(v) for v in pt)
            self.pub_cam.publish(m)

    def _count_deadline(self) -> None:
        """Called at each tick: was the state of the previous tick answered in time?"""
        if self._k == 0 or self.plant.braked:
            return      # nobody is controlling the robot: nothing to miss
        if self._answered_k == self._k:
            self.missed_run = 0
        else:
            self.missed += 1
            self.missed_run += 1
            self.max_missed_run = max(self.max_missed_run, self.missed_run)

    def run(self, executor) -> None:
        """Loop until shutdown."""
        T = self.config.period_s
        if self.lockstep:
            paced, rate = self.mode == 'paced', self.p['lockstep_rate']
            wall0 = time.monotonic() - self.plant.state.t / rate
            while running(self.context):
                t = self.plant.state.t
                stamp = _stamp(t)
                self.pub_clock.publish(Clock(clock=stamp))
                self._publish_state(stamp)
                # nobody answers while the drives are switched off on purpose: no wait
                deadline = time.monotonic() + (0.0 if self.plant.motors_off_requested
                                               else self.p['lockstep_wait_s'])
                if self.plant.motors_off_requested:
                    # no command is awaited, but requests are: without this a lockstep
                    # simulator in a deeper power mode never served ~/power_hold (cycle_run)
                    executor.spin_once(timeout_sec=0.0)
                while self._answered_k != self._k and running(self.context):
                    left = deadline - time.monotonic()
                    if left <= 0:
                        break
                    executor.spin_once(timeout_sec=left)
                self._count_deadline()
                self.plant.step()
                self._k += 1
                self._after_step(_stamp)
                if paced:       # simulated time runs at lockstep_rate x the wall clock
                    due = wall0 + self.plant.state.t / rate
                    if time.monotonic() - due > 0.1:         # fell behind: no sprint after
                        wall0 = time.monotonic() - self.plant.state.t / rate
                    while running(self.context) and time.monotonic() < due:
                        executor.spin_once(timeout_sec=due - time.monotonic())
            return
        t0_ros = self.get_clock().now().nanoseconds * 1e-9
        next_tick = time.monotonic()
        while running(self.context):
            now = time.monotonic()
            if now < next_tick:
                executor.spin_once(timeout_sec=next_tick - now)
                continue
            if self._k > 0:
                self._count_deadline()
                self.plant.step()
            self._k += 1
            # camera points and log lines first: the state goes out last so that nothing
            # delays the reception of its command (the latency the loop is measured by)
            self._after_step(lambda t: _stamp(t0_ros + t))
            stamp = self.get_clock().now().to_msg()
            self._publish_state(stamp)
            self.tick_late.append(time.monotonic() - next_tick)
            next_tick += T
            if time.monotonic() - next_tick > 10 * T:       # fell far behind: resynchronise
                next_tick = time.monotonic() + T

    def destroy_node(self):
        """Write the statistics (after run_node has stopped listening to further Ctrl-C, so a
        second one cannot cut this short), then destroy."""
        if self.p['stats_path']:
            try:
                Path(self.p['stats_path']).write_text(json.dumps(self.stats(), indent=2))
            except OSError as exc:
                self.get_logger().error(f"statistics not written to {self.p['stats_path']}: "
                                        f'{exc.strerror}')
        return super().destroy_node()

    def stats(self) -> dict:
        lat = np.array(self.latencies) * 1e3
        q = (lambda p: float(np.percentile(lat, p))) if lat.size else (lambda p: math.nan)
        return {'mode': self.mode, 'steps': self._k, 'answered': int(lat.size),
                'latency_ms': {'p50': q(50), 'p99': q(99), 'max': float(lat.max())
                               if lat.size else math.nan},
                'missed_deadlines': self.missed, 'max_consecutive_missed': self.max_missed_run,
                'stale_commands_ignored': self.stale_commands,
                'state_publish_late_ms': _percentiles(np.array(self.tick_late) * 1e3),
                'sim_time_s': self.plant.state.t,
                'wall_time_s': time.monotonic() - self.t_wall0,
                'energy_j': self.plant.state.energy,
                **({'per_state_monotonic_s_latency_ms': self._per_state}
                   if self._per_state is not None else {})}


def _percentiles(x: np.ndarray) -> dict | None:
    """p50/p99/max and the count of values above one period (4.032 ms) of ``x`` [ms]."""
    if not x.size:
        return None
    return {'p50': float(np.percentile(x, 50)), 'p99': float(np.percentile(x, 99)),
            'max': float(x.max()), 'over_one_period': int(np.sum(x > 4.032))}


def _effort_by_name(msg_names, effort, names: list[str]) -> np.ndarray | None:
    """Efforts of ``names`` by name (when the message names each effort), else the first
    ones; None when too few or a joint is missing."""
    if len(effort) < len(names):
        return None
    if msg_names and len(msg_names) == len(effort):
        idx = {n: i for i, n in enumerate(msg_names)}
        if not all(n in idx for n in names):
            return None
        return np.array([effort[idx[n]] for n in names], float)
    return np.array(effort[:len(names)], float)


def _spin(node: SimulatorNode) -> None:
    executor = make_executor(node.p['executor'])
    executor.add_node(node)
    apply_realtime(*node.realtime[:2], logger=node.get_logger(),
                   cpu_latency_us=node.realtime[2])
    try:
        node.run(executor)
    finally:
        executor.shutdown()


def main(args=None):
    short_switch_interval()
    run_node(SimulatorNode, _spin, args, spec=SPEC)


if __name__ == '__main__':
    main()
