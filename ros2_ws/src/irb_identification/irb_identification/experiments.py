"""experiments: eq. 4.1 friction experiments, one joint at a time, one bag per run.

    ros2 run irb_identification experiments --ros-args -p mode:=offline
    ros2 run irb_identification experiments --ros-args -p mode:=ros   # simulator + pdplus up

offline: simulates the plant (irb_description model + a known friction map + PD tracking,
offline_sim.py) and writes the bags directly. ros: publishes each run's reference as a
time-driven trajectory_msgs/JointTrajectory (joint_1..3, positions/velocities/accelerations
every control period, time_from_start) on ``trajectory_topic`` for pdplus
(``reference_mode:=time``, ``friction_mode:=none``) and records the run with an in-process
recorder into <root>/<prefix>_<joint>_<speed>/.
"""
from __future__ import annotations

import sys
import time
from datetime import datetime
from pathlib import Path

import numpy as np
import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from .offline_sim import PERIOD_S, SimConfig, simulate, start_pose, write_run_bag
from .profiles import DEFAULT_SPEEDS, ConstantVelocityProfile, joint_reference
from .recorder_node import DEFAULT_TOPICS, RecorderNode
from .rosutil import default_bag_root


class ExperimentsNode(Node):
    """Parameters of the experiment series; ``run_offline`` / ``run_ros`` do the work."""

    def __init__(self, **kwargs):
        super().__init__('experiments', **kwargs)

        def param(name, default, text):
            return self.declare_parameter(name, default, ParameterDescriptor(
                description=text)).value

        self.mode = param('mode', 'offline', "'offline' (simulated plant) or 'ros'")
        self.joints = list(param('joints', ['joint_1', 'joint_2', 'joint_3'], 'joints to run'))
        self.speeds = list(param('speeds_rad_s', list(DEFAULT_SPEEDS), '[rad/s] hold speeds'))
        self.profile_kw = dict(
            accel=param('accel_rad_s2', 8.0, '[rad/s^2] ramp acceleration a1'),
            stroke_rad=param('stroke_rad', 0.8, '[rad] hold length, hold = stroke / speed'),
            hold_min_s=param('hold_min_s', 0.6, '[s] shortest hold'),
            hold_max_s=param('hold_max_s', 4.0, '[s] longest hold'),
            periods=param('periods', 1, 'back-and-forth periods per run'),
            settle_s=param('settle_s', 0.5, '[s] standstill before the first period'))
        self.center = np.array(param('center_rad', [0.0, 0.0, 0.0],
                                     '[rad] pose the moving joint is centred on'))
        root = param('root', '', "bag root; '' = $IRB_ROOT/bags or ./bags")
        self.root = Path(root) if root else default_bag_root()
        self.prefix = param('prefix', '', "bag name prefix; '' = friction_<date>_<time>") or \
            datetime.now().strftime('friction_%Y%m%d_%H%M%S')
        self.plant_map = param('plant_friction_file', '',
                               "offline plant friction map; '' = irb_description nominal")
        self.sim = SimConfig(
            velocity_noise=param('velocity_noise_rad_s', 0.002, '[rad/s] offline noise std'),
            effort_noise=param('effort_noise_nm', 0.5, '[N m] offline noise std'),
            seed=param('seed', 0, 'offline noise seed'))
        self.topic = param('trajectory_topic', '/planned_trajectory',
                           'ros mode: JointTrajectory topic of pdplus')
        self.record_topics = list(param('record_topics', DEFAULT_TOPICS,
                                        'ros mode: topics recorded per run'))
        self.margin = param('run_margin_s', 1.5,
                            '[s] ros mode: recorded beyond the profile (pdplus ramp-in)')
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
            run = simulate(self.model, friction, prof, j, q0, self.sim)
            bags.append(write_run_bag(run, self.root / name, self.model.joint_names,
                                      custom_data={'plant_friction': friction.source}))
            self.get_logger().info(f'{name}: {prof.duration:.1f} s, {len(run.t)} samples')
        return bags

    def trajectory(self, j, prof, q0):
        """The run's reference as a JointTrajectory sampled every control period."""
        from builtin_interfaces.msg import Duration
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
        t = np.arange(0.0, prof.duration + 1e-9, PERIOD_S)
        q, qd, qdd = joint_reference(prof, j, q0, t)
        msg = JointTrajectory(joint_names=list(self.model.joint_names))
        for k in range(len(t)):
            sec, nsec = divmod(int(round(t[k] * 1e9)), 1_000_000_000)
            msg.points.append(JointTrajectoryPoint(
                positions=q[k].tolist(), velocities=qd[k].tolist(),
                accelerations=qdd[k].tolist(), time_from_start=Duration(sec=sec, nanosec=nsec)))
        return msg

    def run_ros(self, executor) -> list[Path]:
        from trajectory_msgs.msg import JointTrajectory
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        pub = self.create_publisher(JointTrajectory, self.topic, QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        bags = []
        for j, prof, q0, name in self.runs():
            rec = RecorderNode(node_name='experiments_recorder', context=self.context,
                               parameter_overrides=[
                                   Parameter('root', value=str(self.root)),
                                   Parameter('name', value=name),
                                   Parameter('topics', value=self.record_topics),
                                   Parameter('recover_on_start', value=False)])
            executor.add_node(rec)
            pub.publish(self.trajectory(j, prof, q0))
            end = time.monotonic() + prof.duration + self.margin
            while rclpy.ok(context=self.context) and time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
            executor.remove_node(rec)
            rec.close()
            rec.destroy_node()
            bags.append(rec.bag_path)
        return bags


def main(args=None):
    rclpy.init(args=args)
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
        print('identify with:\n  ros2 run irb_identification identify '
              + ' '.join(f'--bag {b}' for b in bags) + ' --out friction_map.yaml')
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ValueError as exc:
        print(f'experiments: {exc}', file=sys.stderr)
        return 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
