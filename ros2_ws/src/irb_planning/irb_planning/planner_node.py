"""`ros2 run irb_planning planner`: serve PlanPath and latch the latest plan.

Thin adapter over ``planner.Planner``: parameters -> PlannerSettings, request message ->
PlanRequest, result -> response + latched topics. The service runs in its own callback group
under a MultiThreadedExecutor, so a solve never blocks the node's other callbacks (CasADi
releases the GIL while IPOPT runs).
"""
from __future__ import annotations

import dataclasses
import traceback

from irb_description.node_main import run_node, spin_until_signal
from irb_interfaces.msg import PathSpec
from irb_interfaces.srv import PlanPath
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

from . import messages
from .planner import Planner, PlannerSettings, request_error_code
from .request import PlanError

#: parameter name -> (PlannerSettings field, description with unit)
PARAMETERS = {
    'grid_size': ('grid_size', 'theta grid nodes N when the request says 0 [-]'),
    'min_theta_dot_rad_s': ('min_theta_dot_rad_s',
                            'delta: theta_dot >= delta inside the path [rad/s]'),
    'friction_smoothing_rad_s': ('friction_smoothing_rad_s',
                                 'eps of tanh(v/eps) replacing sign(v) in the NLP [rad/s]'),
    'abs_smoothing_j_rad': ('abs_smoothing_j_rad',
                            '0: exact |.| by variable split; > 0: sqrt(y^2+eps^2) [J/rad]'),
    'constraint_margin': ('constraint_margin',
                          'fraction of each speed/torque limit kept free in the NLP [-]'),
    'max_iterations': ('max_iterations', 'IPOPT max_iter [-]'),
    'tolerance': ('tolerance', 'IPOPT tol [-]'),
    'warm_start': ('warm_start', 'warm-start IPOPT from the last solution when close [-]'),
    'trapezoid_ramp_fraction': ('trapezoid_ramp_fraction',
                                'trapezoid baseline: each ramp as a fraction of T [-]'),
    'evaluation_rate_hz': ('evaluation_rate_hz', 'resampling rate of the check [Hz]'),
    'cache_size': ('cache_size', 'built problems kept (least recently used dropped) [-]'),
    'memory_limit_mib': ('memory_limit_mib', 'built problems are dropped (least recently used '
                         'first) while the resident memory exceeds this [MiB]'),
    'max_grid_size': ('max_grid_size', 'largest grid_size a request may ask for [-]'),
    'path_tolerance_m': ('path_tolerance_m', 'largest TCP deviation of the trajectory message '
                         'played by quintic interpolation (else more points) [m]'),
    'max_trajectory_points': ('max_trajectory_points', 'points of the trajectory message at '
                              'most [-]'),
    'adapt_rounds': ('adapt_rounds', 're-solves with a limit tightened by the excess the exact '
                     'check measured [-]'),
    'path_check_samples': ('path_check_samples', 'theta samples of the along-path joint check '
                           '[-]'),
    'electrical_smoothing_w': ('electrical_smoothing_w', 'eps of the smoothed |.| in the '
                               'electrical NLP objective [W]'),
    'electrical_config': ('electrical_config', "electrical-model YAML ('' = irb_description "
                          "config/electrical.yaml) [-]"),
}
#: directories friction maps may be read from ([] = irb_description share, runs/, bags/)
MAP_DIRS = 'friction_map_dirs'


class PlannerNode(Node):
    """Service ``plan_path``; latched ``/planned_trajectory``, ``/planned_theta_profile``,
    ``/planned_path``."""

    def __init__(self, **kwargs):
        super().__init__('planner', **kwargs)
        defaults = PlannerSettings()
        for name, (fieldname, text) in PARAMETERS.items():
            self.declare_parameter(name, getattr(defaults, fieldname),
                                   ParameterDescriptor(description=text, read_only=True))
        dirs = self.declare_parameter(MAP_DIRS, Parameter.Type.STRING_ARRAY, ParameterDescriptor(
            description='directories friction-map files may be read from; empty = the share '
                        'of irb_description and runs/, bags/ of $IRB_ROOT (or the working '
                        'directory); relative names are looked up in them in order',
            read_only=True)).value or []
        settings = PlannerSettings(**{f: self.get_parameter(n).value
                                      for n, (f, _) in PARAMETERS.items()},
                                   friction_map_dirs=tuple(d for d in dirs if d))
        self.planner = Planner(settings=settings)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                             reliability=ReliabilityPolicy.RELIABLE)
        self.pub_traj = self.create_publisher(JointTrajectory, 'planned_trajectory', latched)
        self.pub_theta = self.create_publisher(Float64MultiArray, 'planned_theta_profile',
                                               latched)
        self.pub_path = self.create_publisher(PathSpec, 'planned_path', latched)
        self.srv = self.create_service(PlanPath, 'plan_path', self.on_request,
                                       callback_group=MutuallyExclusiveCallbackGroup())
        self.get_logger().info(
            f'serving plan_path ({dataclasses.asdict(settings)}); friction maps from '
            f'{[str(d) for d in self.planner.map_dirs]}')

    def on_request(self, request, response):
        try:
            result = self.planner.plan(messages.request_from_msg(request))
            nodes = self.planner.node_samples(result)
        except PlanError as exc:
            return self._fail(response, exc.code, exc.message)
        except Exception as exc:  # noqa: BLE001 - the node must keep serving
            self.get_logger().error(traceback.format_exc())
            return self._fail(response, request_error_code(exc),
                              'internal error of the planner while planning this request '
                              '(details in the planner log); please report it')
        messages.fill_response(response, result, nodes)
        # a unique stamp per plan: the controller's verdict (pdplus ~/plan_status.plan_stamp)
        # names the plan it is about; for a joint-trajectory controller a stamp of 'now' means
        # 'start now', as a zero stamp does
        response.trajectory.header.stamp = self.get_clock().now().to_msg()
        self.pub_traj.publish(response.trajectory)
        self.pub_theta.publish(messages.theta_profile_msg(result))
        self.pub_path.publish(messages.path_msg(result.request))
        self.get_logger().info(response.message)
        return response

    def _fail(self, response, code, message):
        response.success = False
        response.error_code = int(code)
        response.message = message
        self.get_logger().warning(f'plan refused (code {code}): {message}')
        return response


def _spin(node: PlannerNode) -> None:
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    spin_until_signal(executor)


def main(args=None):
    run_node(PlannerNode, _spin, args)


if __name__ == '__main__':
    main()
