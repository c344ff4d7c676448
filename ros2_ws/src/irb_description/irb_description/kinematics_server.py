"""`ros2 run irb_description kinematics_server`: serve inverse kinematics (SolveIk).

Thin adapter over ``RobotModel.ik``: points in, joint angles out, per-point reachability.
"""
from __future__ import annotations

import numpy as np
from irb_interfaces.srv import SolveIk
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectoryPoint

from .model import RobotModel, UnreachableError
from .node_main import run_node, spin_until_signal


class KinematicsServer(Node):
    """Service ``solve_ik`` (irb_interfaces/srv/SolveIk)."""

    def __init__(self):
        super().__init__('kinematics_server')
        self.declare_parameter('branch', 'elbow_up', _descriptor(
            "IK elbow branch: 'elbow_up' (thesis) or 'elbow_down'"))
        self.model = RobotModel.load()
        self.srv = self.create_service(SolveIk, 'solve_ik', self.on_request)
        self.get_logger().info(f'serving solve_ik for {self.model.joint_names}')

    def on_request(self, request, response):
        branch = self.get_parameter('branch').value
        response.joint_names = self.model.joint_names
        problems = []
        for k, pt in enumerate(request.points):
            try:
                q = self.model.ik(np.array([pt.x, pt.y, pt.z]), branch)
                ok = True
            except UnreachableError as exc:
                q = np.full(self.model.nq, np.nan)
                ok = False
                problems.append(f'point {k}: {exc}')
            response.solutions.append(JointTrajectoryPoint(positions=q.tolist()))
            response.reachable.append(ok)
        response.success = not problems
        response.message = ('; '.join(problems) if problems
                            else f'{len(request.points)} points solved')
        return response


def _descriptor(text: str):
    from rcl_interfaces.msg import ParameterDescriptor
    return ParameterDescriptor(description=text)


def _spin(node: KinematicsServer) -> None:
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spin_until_signal(executor)


def main(args=None):
    run_node(KinematicsServer, _spin, args)


if __name__ == '__main__':
    main()
