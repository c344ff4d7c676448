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
from .node_help import NodeSpec, Param, Topic
from .node_main import declare_params, run_node, spin_until_signal

SPEC = NodeSpec(
    'kinematics_server', 'irb_description',
    'Serves the closed-form inverse kinematics of the simplified model (thesis section 3.2): '
    'TCP points in base_link -> joint angles of joints 1-3, with per-point reachability.',
    params=(Param('branch', 'elbow_up', '', "IK elbow branch: 'elbow_up' (the thesis's) or "
                  "'elbow_down'"),),
    services=(Topic('solve_ik', 'irb_interfaces/srv/SolveIk', 'TCP points (base_link, m) -> '
                    'joint angles (rad), per-point reachability'),),
    example='ros2 run irb_description kinematics_server --ros-args -p branch:=elbow_up',
)


class KinematicsServer(Node):
    """Service ``solve_ik`` (irb_interfaces/srv/SolveIk)."""

    def __init__(self):
        super().__init__('kinematics_server')
        declare_params(self, SPEC.params)
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


def _spin(node: KinematicsServer) -> None:
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spin_until_signal(executor)


def main(args=None):
    run_node(KinematicsServer, _spin, args, spec=SPEC)


if __name__ == '__main__':
    main()
