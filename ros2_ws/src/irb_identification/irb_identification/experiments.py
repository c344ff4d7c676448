"""experiments: eq. 4.1 friction experiments, one joint at a time, one bag per run.

    ros2 run irb_identification experiments --ros-args -p mode:=offline
    ros2 run irb_identification experiments --ros-args -p mode:=ros   # simulator + pdplus up

offline: simulates the plant (irb_description model + a known friction map + PD tracking,
offline_sim.py) and writes the bags directly. ros: publishes each run's reference as a
time-driven trajectory_msgs/JointTrajectory (joint_1..3, positions/velocities/accelerations
every control period, time_from_start) on ``trajectory_topic`` for pdplus
(``reference_mode:=time``, ``friction_mode:=none``) and records the run with an in-process
recorder into <root>/<prefix>_<joint>_<speed>/. A run is timed on what happens, not on the
wall clock (the simulator may run in lockstep, many times faster than real time): it starts
when pdplus, idle or holding, starts the published trajectory, and its bag is closed once the
recorder holds ``run_margin_s`` of simulated time after pdplus reached HOLD (run_timing.py).
"""
from __future__ import annotations

import sys
import time
from datetime import datetime
from pathlib import Path

import numpy as np
import rclpy
from irb_description.node_help import NodeSpec, Param, Topic, exit_if_help
from irb_description.node_main import init, running
from irb_description.stamps import sec_nanosec
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from .offline_sim import PERIOD_S, SimConfig, simulate, start_pose, write_run_bag
from .profiles import DEFAULT_SPEEDS, ConstantVelocityProfile, joint_reference
from .recorder_node import DEFAULT_TOPICS, RecorderNode
from .rosutil import default_bag_root
from .run_timing import FAILED, MODE_NAMES, RunMonitor, controller_state_head, header_stamp

DEFAULT_CENTER = (0.0, 0.5, -0.8)
"""Default pose [rad] the moving joint is centred on. Joints 2 and 3 set joint 1's inertia:
with the arm upright (0, 0, 0) it is 10 kg m^2, half of what pdplus's gains are tuned for on
the thesis circle (about 22), and joint 1 then oscillates at about 15 Hz under PD without
friction feed-forward (3-sample delay) - stick-slip below the Stribeck speed. Here it is
19 kg m^2, and the sweeps of joints 2 and 3 (up to 2 rad/s, +-0.85 rad) stay inside the
limits with the flange at least 0.2 m above the base plane."""


def joint_trajectory_msg(names: list[str], t: np.ndarray, q: np.ndarray, qd: np.ndarray,
                         qdd: np.ndarray) -> JointTrajectory:
    """A joint trajectory (N,) / (N, 3) as JointTrajectory."""
    msg = JointTrajectory(joint_names=list(names))
    for k, ti in enumerate(t):
        p = JointTrajectoryPoint(positions=q[k].tolist(), velocities=qd[k].tolist(),
                                 accelerations=qdd[k].tolist())
        p.time_from_start.sec, p.time_from_start.nanosec = sec_nanosec(float(ti))
        msg.points.append(p)
    return msg


SPEC = NodeSpec(
    'experiments', 'irb_identification',
    'Eq. 4.1 friction experiments, one joint at a time, one bag per (joint, speed). offline: '
    'simulates the plant and writes the bags; ros: publishes each run as a time-driven '
    'JointTrajectory for pdplus and records it with an in-process recorder, timed on '
    "pdplus's mode (works in lockstep on simulated time).",
    params=(
        Param('mode', 'offline', '', "'offline' (simulated plant) or 'ros'"),
        Param('joints', ['joint_1', 'joint_2', 'joint_3'], '', 'joints to run; naming any of '
              'joint_4..6 runs the six-joint arm (offline: irb_control six-joint plant; ros: '
              'trajectories of joint_1..6 for pdplus joints:=6)'),
        Param('speeds_rad_s', [float(c) for c in DEFAULT_SPEEDS], 'rad/s', 'hold speeds'),
        Param('accel_rad_s2', 8.0, 'rad/s^2', 'ramp acceleration a1 of eq. 4.1'),
        Param('stroke_rad', 0.8, 'rad', 'hold length: hold = stroke / speed'),
        Param('hold_min_s', 0.6, 's', 'shortest hold'),
        Param('hold_max_s', 4.0, 's', 'longest hold'),
        Param('periods', 1, '', 'back-and-forth periods per run'),
        Param('settle_s', 0.5, 's', 'standstill before the first period'),
        Param('center_rad', list(DEFAULT_CENTER), 'rad', 'pose the moving joint is centred on '
              '(the other joints stand there); 3 values (six joints: the wrist at 0) or 6'),
        Param('root', '', '', "bag root; '' = $IRB_ROOT/bags or ./bags"),
        Param('prefix', '', '', "bag name prefix; '' = friction_<date>_<time>"),
        Param('plant_friction_file', '', '', "offline plant friction map; '' = "
              'irb_description nominal'),
        Param('velocity_noise_rad_s', 0.002, 'rad/s', 'offline noise std'),
        Param('effort_noise_nm', 0.5, 'N m', 'offline noise std'),
        Param('seed', 0, '', 'offline noise seed'),
        Param('trajectory_topic', '/planned_trajectory', '', 'ros: JointTrajectory topic of '
              'pdplus'),
        Param('record_topics', list(DEFAULT_TOPICS), '', 'ros: topics recorded per run'),
        Param('run_margin_s', 1.5, 's', 'ros: simulated time recorded after pdplus reaches '
              'HOLD'),
        Param('controller_state_topic', '/controller_state', '', "ros: pdplus's "
              'ControllerState topic (runs are timed on it)'),
        Param('joint_states_topic', '/joint_states', '', 'ros: JointState topic (the recorded '
              'margin is checked on its stamps)'),
        Param('plan_status_topic', '/pdplus/plan_status', '', "ros: pdplus's verdict on each "
              'plan (latched)'),
        Param('enable_service', '/pdplus/enable', '', 'ros: the service that starts the '
              'accepted plan'),
        Param('start_timeout_s', 5.0, 's', 'ros: simulated time after enable within which '
              'pdplus must start the run'),
        Param('run_timeout_s', 120.0, 's', 'ros: wall-clock bound of one run (an error, never '
              'a hang)'),
    ),
    publishes=(Topic('/planned_trajectory', 'trajectory_msgs/JointTrajectory',
                     'ros: each run (latched)'),),
    subscribes=(Topic('/controller_state', 'irb_interfaces/ControllerState', 'ros: timing'),
                Topic('/pdplus/plan_status', 'irb_interfaces/PlanStatus', 'ros: verdict')),
    clients=(Topic('/pdplus/enable', 'std_srvs/Trigger', 'ros: start each run'),),
    example='ros2 run irb_identification experiments --ros-args -p mode:=offline '
            "-p joints:='[joint_2]'")


class RunError(RuntimeError):
    """A ROS-mode run failed (pdplus stopped, did not start, or the wall-clock bound hit)."""


class ExperimentsNode(Node):
    """Parameters of the experiment series; ``run_offline`` / ``run_ros`` do the work."""

    def __init__(self, **kwargs):
        super().__init__('experiments', **kwargs)

        from .rosutil import declare_params
        p = declare_params(self, SPEC.params)
        self.mode = p['mode']
        self.joints = list(p['joints'])
        self.speeds = list(p['speeds_rad_s'])
        self.profile_kw = dict(
            accel=p['accel_rad_s2'], stroke_rad=p['stroke_rad'], hold_min_s=p['hold_min_s'],
            hold_max_s=p['hold_max_s'], periods=p['periods'], settle_s=p['settle_s'])
        self.center = np.array(p['center_rad'])
        self.root = Path(p['root']) if p['root'] else default_bag_root()
        self.prefix = p['prefix'] or datetime.now().strftime('friction_%Y%m%d_%H%M%S')
        self.plant_map = p['plant_friction_file']
        self.sim = SimConfig(velocity_noise=p['velocity_noise_rad_s'],
                             effort_noise=p['effort_noise_nm'], seed=p['seed'])
        self.topic = p['trajectory_topic']
        self.record_topics = list(p['record_topics'])
        self.margin = p['run_margin_s']
        self.state_topic = p['controller_state_topic']
        self.js_topic = p['joint_states_topic']
        self.plan_status_topic = p['plan_status_topic']
        self.enable_service = p['enable_service']
        self.start_timeout = p['start_timeout_s']
        self.run_timeout = p['run_timeout_s']
        for t in (self.js_topic, self.state_topic):
            if t not in self.record_topics:
                self.record_topics.append(t)
        from .six_joint import SixJointIdentificationModel, six_joint_center, uses_wrist
        self.six = uses_wrist(self.joints)      # joints 4-6 asked for: the whole arm
        if self.six:
            self.model = SixJointIdentificationModel()
            self.center = six_joint_center(self.center)
        else:
            from irb_description.model import RobotModel
            self.model = RobotModel.load()
        unknown = [j for j in self.joints if j not in self.model.joint_names]
        if unknown:
            raise ValueError(f'unknown joints {unknown}, expected {self.model.joint_names}')

    def runs(self):
        """(joint index, profile, start pose, bag name) of every run."""
        for name in self.joints:
            j = self.model.joint_names.index(name)
            for c in self.speeds:
                prof = ConstantVelocityProfile.for_speed(float(c), **self.profile_kw)
                q0 = start_pose(self.model, j, prof, self.center)
                yield j, prof, q0, f'{self.prefix}_{name}_{c:.4f}'.replace('.', 'p')

    def run_offline(self) -> list[Path]:
        from irb_description.friction import load_friction_map
        friction = (load_friction_map(self.plant_map, self.model.joint_names)
                    if self.plant_map else self.model.friction)
        bags = []
        for j, prof, q0, name in self.runs():
            if self.six:       # irb_control's six-joint plant and PD+ (six_joint.py)
                from .six_joint import simulate_six
                run = simulate_six(self.model, friction, prof, j, q0, self.sim)
            else:
                run = simulate(self.model, friction, prof, j, q0, self.sim)
            bags.append(write_run_bag(run, self.root / name, self.model.joint_names,
                                      custom_data={'plant_friction': friction.source}))
            self.get_logger().info(f'{name}: {prof.duration:.1f} s, {len(run.t)} samples')
        return bags

    def trajectory(self, j, prof, q0):
        """The run's reference as a JointTrajectory sampled every control period."""
        t = np.arange(0.0, prof.duration + 1e-9, PERIOD_S)
        return joint_trajectory_msg(self.model.joint_names, t, *joint_reference(prof, j, q0, t))

    def run_ros(self, executor) -> list[Path]:
        """Every run through pdplus; RunError after all runs if any failed (the others'
        bags are kept), at once if a run hits the wall-clock bound."""
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        pub = self.create_publisher(JointTrajectory, self.topic, QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        from irb_interfaces.msg import PlanStatus
        self._plan_status = [None]
        self.create_subscription(PlanStatus, self.plan_status_topic,
                                 lambda m: self._plan_status.__setitem__(0, m), QoSProfile(
                                     depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                     durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self._enable = self.create_client(Trigger, self.enable_service)
        self._wait_controller_idle(executor)
        bags, failed = [], []
        for j, prof, q0, name in self.runs():
            try:
                bags.append(self._run_one(executor, pub, j, prof, q0, name))
            except RunError as exc:
                self.get_logger().error(str(exc))
                failed.append(str(exc))
        if failed:
            raise RunError(f'{len(failed)} of {len(failed) + len(bags)} runs failed: '
                           + '; '.join(failed))
        return bags

    def _spin_until(self, executor, cond, deadline: float, what: str) -> None:
        """spin_once until cond(); RunError naming ``what`` at the wall-clock ``deadline``."""
        while not cond():
            if not running(self.context):
                raise KeyboardInterrupt
            if time.monotonic() > deadline:
                raise RunError(f'{what}: no progress within run_timeout_s = '
                               f'{self.run_timeout} s of wall time')
            executor.spin_once(timeout_sec=0.05)

    def _wait_controller_idle(self, executor) -> None:
        """Before the first run: wait until pdplus reports a state and is not moving (it may
        still run its built-in profile, which would refuse the first trajectory)."""
        from irb_description.node_main import state_qos
        from irb_interfaces.msg import ControllerState
        mon = RunMonitor()
        seen = []

        def on_state(data):
            mon.on_state(*controller_state_head(data))
            if not seen or seen[-1] != mon.mode:
                seen.append(mon.mode)
        sub = self.create_subscription(ControllerState, self.state_topic, on_state,
                                       state_qos(), raw=True)
        try:
            self._spin_until(executor, lambda: mon.mode is not None and not mon.is_moving,
                             time.monotonic() + self.run_timeout,
                             f'waiting for pdplus on {self.state_topic} to be idle')
        finally:
            self.destroy_subscription(sub)
        if len(seen) > 1:
            self.get_logger().info(
                'pdplus was running another motion ('
                + ' -> '.join(MODE_NAMES.get(m, str(m)) for m in seen) + '): waited for it')

    def _enable_when_accepted(self, executor, stamp, deadline: float, name: str) -> None:
        """pdplus checks every plan and keeps it pending until enable: wait for its verdict on
        this plan (its stamp), then call enable; RunError if it refuses either."""
        verdict = self._plan_status
        self._spin_until(executor, lambda: (verdict[0] is not None
                                            and verdict[0].plan_stamp == stamp), deadline,
                         f'{name}: pdplus verdict on the plan ({self.plan_status_topic})')
        if not verdict[0].accepted:
            raise RunError(f'{name}: pdplus refused the plan: {verdict[0].reason}')
        self._spin_until(executor, self._enable.service_is_ready, deadline,
                         f'{name}: {self.enable_service} available')
        fut = self._enable.call_async(Trigger.Request())
        self._spin_until(executor, fut.done, deadline, f'{name}: {self.enable_service} answer')
        if not fut.result().success:
            raise RunError(f'{name}: pdplus refused to enable: {fut.result().message}')

    def _run_one(self, executor, pub, j, prof, q0, name) -> Path:
        """One run: recorder up and receiving, pdplus not moving -> publish -> RAMP/TIME ->
        HOLD -> ``run_margin_s`` of simulated time recorded -> bag closed."""
        mon = RunMonitor(margin_s=self.margin, start_timeout_s=self.start_timeout)

        def on_state(data):
            try:
                mon.on_state(*controller_state_head(data))
            except ValueError as exc:
                mon.fail(f'unreadable controller state: {exc}')

        def on_joint_state(data):
            try:
                mon.on_recorded(header_stamp(data))
            except ValueError as exc:
                mon.fail(f'unreadable joint state: {exc}')
        traj = self.trajectory(j, prof, q0)
        rec = RecorderNode(node_name='experiments_recorder', context=self.context,
                           taps={self.state_topic: on_state, self.js_topic: on_joint_state},
                           parameter_overrides=[
                               Parameter('root', value=str(self.root)),
                               Parameter('name', value=name),
                               Parameter('topics', value=self.record_topics),
                               Parameter('recover_on_start', value=False),
                               # log time = the graph's (simulated) time, as the stamps
                               Parameter('use_sim_time', value=bool(
                                   self.get_parameter('use_sim_time').value))])
        executor.add_node(rec)
        deadline = time.monotonic() + self.run_timeout
        try:
            counts = rec.counts
            self._spin_until(executor, lambda: (counts.get(self.js_topic, 0) > 0
                                                and counts.get(self.state_topic, 0) > 0
                                                and not mon.is_moving),
                             deadline, f'{name}: recorder receiving, pdplus not moving')
            mon.start(mon.t_state)
            traj.header.stamp = self.get_clock().now().to_msg()
            pub.publish(traj)
            self._enable_when_accepted(executor, traj.header.stamp, deadline, name)
            mon.enabled(mon.t_state)
            self._spin_until(executor, lambda: mon.finished, deadline,
                             f'{name}: run (phase {mon.phase})')
        finally:
            executor.remove_node(rec)
            rec.close()
            rec.destroy_node()
        if mon.phase == FAILED:
            raise RunError(f'{name}: {mon.error} (bag {rec.bag_path} kept)')
        self.get_logger().info(
            f'{name}: published at t = {mon.t_publish:.3f} s, pdplus moving '
            f'{mon.t_start:.3f}-{mon.t_hold:.3f} s (profile {prof.duration:.2f} s), recorded '
            f'to {mon.t_recorded:.3f} s (simulated time)')
        return rec.bag_path


def main(args=None):
    exit_if_help(args, SPEC)
    from irb_description.node_main import CONFIG_ERRORS
    init(args)
    node = None
    try:
        node = ExperimentsNode()
        if node.mode == 'offline':
            bags = node.run_offline()
        elif node.mode == 'ros':
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            bags = node.run_ros(executor)
        else:
            raise ValueError(f"mode must be 'offline' or 'ros', not {node.mode!r}")
        extra = (f" --joints {','.join(node.joints)} --effort-lag-s 0.0024192 "
                 '--complete-from nominal' if node.six else '')
        print('identify with:\n  ros2 run irb_identification identify '
              + ' '.join(f'--bag {b}' for b in bags) + extra + ' --out friction_map.yaml')
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (RunError, RuntimeError, *CONFIG_ERRORS) as exc:
        print(f'experiments: {exc}', file=sys.stderr)
        return 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
