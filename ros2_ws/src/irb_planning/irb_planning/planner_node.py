"""`ros2 run irb_planning planner`: serve PlanPath and PlaceTask, latch the latest plan.

Thin adapter over ``planner.Planner`` and ``placement.search``: parameters ->
PlannerSettings, request message -> PlanRequest / search arguments, result -> response +
latched topics. Each service runs in its own callback group under a MultiThreadedExecutor,
so a solve never blocks the node's other callbacks (CasADi releases the GIL while IPOPT
runs).

``place_task`` (a search of minutes) has its own ``Planner`` (same model, settings and
friction-map directories, its own small cache): its dozens of placements are each a new
problem and would otherwise push ``plan_path``'s cached problems and warm starts out of the
shared LRU cache, and both would queue on one pinocchio lock. Its callback group is
reentrant: a second request while a search runs is answered at once with ERROR_BUSY (a
non-blocking lock), not queued behind it. Destroying the node stops a running search at its
next plan (the progress callback raises), so Ctrl-C never waits for minutes.
"""
from __future__ import annotations

import dataclasses
import os
import threading
import time
import traceback

import numpy as np
from irb_description.node_help import NodeSpec, Param, Topic
from irb_description.node_main import run_node, spin_until_signal
from irb_description.plan_path import path_frame_id
from irb_interfaces.msg import PathSpec
from irb_interfaces.srv import PlaceTask, PlanPath
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

from . import messages
from .placement import (PLACEMENT_MIN_DURATION_CHECK_FACTOR, placement_request, plot_map,
                        search, task_fixed_electrical_energy)
from .planner import Planner, PlannerSettings, request_error_code
from .request import PlanError, validate

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
    'play_rate_hz': ('play_rate_hz', 'the independent check plays the trajectory message by '
                     'quintic interpolation at this rate (>= 8 samples per interval); the '
                     'reported peaks are the played ones [Hz]'),
    'min_point_spacing_s': ('min_point_spacing_s', 'smallest interval between two points of '
                            'the trajectory message (closer points are dropped) [s]'),
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
    'curvature_grid_share': ('curvature_grid_share', 'share of a spline path\'s grid nodes '
                             'placed by its curvature, with a node at every knot (0 = the '
                             'uniform grid) [-]'),
    'electrical_smoothing_w': ('electrical_smoothing_w', 'eps of the smoothed |.| in the '
                               'electrical NLP objective [W]'),
    'electrical_config': ('electrical_config', "electrical-model YAML ('' = irb_description "
                          "config/electrical.yaml) [-]"),
    'jerk_limits': ('jerk_limits', 'smoothness limits on: joint jerk, TCP jerk and torque '
                    'rate kept as played, rest-to-rest plans start and end at the static '
                    'torque [-]'),
    'joint_jerk_limit_rad_s3': ('joint_jerk_limit_rad_s3', 'joint jerk limit per joint '
                                '[rad/s^3]'),
    'tcp_jerk_limit_m_s3': ('tcp_jerk_limit_m_s3', 'limit of the TCP jerk magnitude [m/s^3]'),
    'torque_rate_limit_nm_s': ('torque_rate_limit_nm_s', 'rate of the rigid-body torque '
                               'per joint [N m/s]'),
    'limit_cost': ('limit_cost', 'report the cost of the smoothness limits in every energy '
                   'and time plan (one more solve without the jerk rows, warm-started from '
                   'the plan); false saves that time [-]'),
}
#: directories friction maps may be read from ([] = irb_description share, runs/, bags/)
MAP_DIRS = 'friction_map_dirs'
#: place_task parameter -> (default, description with unit)
PLACE_PARAMETERS = {
    'place_grid_points': ([3, 3, 3], 'map points along x, y, z when a place_task request '
                          'says 0 [-]'),
    'place_coarse_grid_size': (40, 'theta nodes of each map point when the request says 0 '
                               '[-]'),
    'place_refine': (2, 'best map points re-planned on the full grid when the request says '
                     '0 [-]'),
    'place_min_step_m': (0.025, 'end of the compass search for the centre when the request '
                         'says 0 [m]'),
    'place_min_tilt_step_rad': (0.0349, 'end of the compass search for the tilts when the '
                                'request says 0 [rad]'),
    'place_max_points': (1000, 'most map points (x * y * z * orientations) a request may ask '
                         'for [-]'),
    'place_default_starts': (1, 'compass searches from distinct starts when the request says '
                             '0 (1: from the best re-planned map point only) [-]'),
    'place_max_starts': (16, 'most starts a request may ask for (each start is a compass '
                         'search of tens of plans) [-]'),
    'place_cache_size': (2, "built problems the search's own planner keeps (each placement "
                         'is a new problem) [-]'),
    'place_map_dir': ('', "directory the map PNG of each search is written to; '' = none "
                      '[-]'),
}


def _param(name: str, default, text: str) -> Param:
    """A Param from a description whose trailing '[unit]' is the unit ('[-]': none)."""
    body, _, unit = text.rstrip().rpartition(' [')
    if not body or not unit.endswith(']'):
        return Param(name, default, '', text)
    unit = unit[:-1]
    return Param(name, default, '' if unit == '-' else unit, body)


SPEC = NodeSpec(
    'planner', 'irb_planning',
    'Energy-optimal motion along a path (CasADi/IPOPT on a theta grid) as a service: every '
    'answer is a plan checked as a controller plays it, or a refusal with its reason; also '
    'the placement search of a task (place_task).',
    params=tuple(_param(n, getattr(PlannerSettings(), f), t) for n, (f, t) in
                 PARAMETERS.items())
    + (Param(MAP_DIRS, [''], '', "directories friction-map files may be read from; [''] = "
             'the share of irb_description and runs/, bags/ of $IRB_ROOT (or the working '
             'directory)'),)
    + tuple(_param(n, d, t) for n, (d, t) in PLACE_PARAMETERS.items()),
    publishes=(Topic('planned_trajectory', 'trajectory_msgs/JointTrajectory',
                     'the latest plan (latched)'),
               Topic('planned_theta_profile', 'std_msgs/Float64MultiArray',
                     'its theta profile (latched)'),
               Topic('planned_path', 'irb_interfaces/PathSpec', 'its path (latched)')),
    services=(Topic('plan_path', 'irb_interfaces/PlanPath', 'plan a motion along a path'),
              Topic('place_task', 'irb_interfaces/PlaceTask',
                    'search where to place a task (minutes)')),
    example='ros2 run irb_planning planner --ros-args --params-file '
            '$(ros2 pkg prefix irb_planning)/share/irb_planning/config/planner.yaml\n'
            'ros2 run irb_planning plan --duration 10 --grid 60')


class _Stopped(Exception):
    """The node is being destroyed: end the running search."""


class _StoppablePlanner:
    """The search's planner, refusing to start another plan once ``stop`` is set (the
    search lets anything but PlanError through, so the search ends there)."""

    def __init__(self, planner: Planner, stop: threading.Event):
        self.planner, self.stop = planner, stop

    def plan(self, request):
        if self.stop.is_set():
            raise _Stopped()
        return self.planner.plan(request)

    def bound(self, request, duration):
        if self.stop.is_set():
            raise _Stopped()
        return self.planner.bound(request, duration)


class PlannerNode(Node):
    """Service ``plan_path``; latched ``/planned_trajectory``, ``/planned_theta_profile``,
    ``/planned_path``."""

    def __init__(self, **kwargs):
        super().__init__('planner', **kwargs)
        defaults = PlannerSettings()
        for name, (fieldname, text) in PARAMETERS.items():
            value = getattr(defaults, fieldname)
            self.declare_parameter(name, list(value) if isinstance(value, tuple) else value,
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
        self.place = {name: self.declare_parameter(name, default, ParameterDescriptor(
            description=text, read_only=True)).value
            for name, (default, text) in PLACE_PARAMETERS.items()}
        if len(self.place['place_grid_points']) != 3:
            raise ValueError('place_grid_points must be 3 numbers (x, y, z)')
        if not 1 <= self.place['place_default_starts'] <= self.place['place_max_starts']:
            raise ValueError('place_default_starts must be in [1, place_max_starts]')
        self.place_planner = Planner(self.planner.model.copy(), dataclasses.replace(
            settings, cache_size=int(self.place['place_cache_size']),
            min_duration_check_factor=PLACEMENT_MIN_DURATION_CHECK_FACTOR,
            # the search's dozens of map plans are played at the evaluator's rate (>= 8
            # samples per interval): at 10 kHz a 10 s plan cost 2.8 s CPU instead of 1.1
            play_rate_hz=settings.evaluation_rate_hz,
            # nor the extra solve of each plan's cost of the smoothness limits (the search
            # compares plans; the re-planned answer of plan_path reports it)
            limit_cost=False))
        self._place_lock = threading.Lock()
        self._place_state = ''            # what the running search is doing (for ERROR_BUSY)
        self._stopping = threading.Event()
        self.place_srv = self.create_service(PlaceTask, 'place_task', self.on_place,
                                             callback_group=ReentrantCallbackGroup())
        self.get_logger().info(
            f'serving plan_path and place_task ({dataclasses.asdict(settings)}, '
            f'{self.place}); friction maps from {[str(d) for d in self.planner.map_dirs]}')

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
        # the path the plan was planned on travels with it (irb_description.plan_path): the
        # controller follows the plan on that path, whatever path it was started with
        response.trajectory.header.frame_id = path_frame_id(result.request.path_spec())
        self.pub_traj.publish(response.trajectory)
        self.pub_theta.publish(messages.theta_profile_msg(result))
        self.pub_path.publish(messages.path_msg(result.request))
        self.get_logger().info(response.message)
        return response

    def _fail(self, response, code, message, what='plan'):
        response.success = False
        response.error_code = int(code)
        response.message = message
        self.get_logger().warning(f'{what} refused (code {code}): {message}')
        return response

    # --- place_task -----------------------------------------------------------------------
    def _place_args(self, request) -> dict:
        """The search's arguments from the request, checked; PlanError(code, message)."""
        p = self.place
        defaults = dict(n=list(p['place_grid_points']),
                        coarse_grid=p['place_coarse_grid_size'], refine=p['place_refine'],
                        min_step=p['place_min_step_m'],
                        min_tilt_step=p['place_min_tilt_step_rad'],
                        starts=p['place_default_starts'])
        try:
            args = messages.place_task_from_msg(request, defaults)
        except ValueError as exc:
            raise PlanError(PlaceTask.Response.ERROR_INVALID_REQUEST, str(exc)) from None
        region = args['region']
        points = int(np.prod(args['n'])) * region.orientations().shape[0]
        if points > p['place_max_points']:
            raise PlanError(PlaceTask.Response.ERROR_INVALID_REQUEST,
                            f'{points} map points asked for, at most {p["place_max_points"]} '
                            '(parameter place_max_points)')
        if args['starts'] > p['place_max_starts']:
            raise PlanError(PlaceTask.Response.ERROR_INVALID_REQUEST,
                            f'{args["starts"]} starts asked for, at most '
                            f'{p["place_max_starts"]} (parameter place_max_starts)')
        # the planner's own checks of the task (radius, direction, energy model, grids) on
        # the placed circle, for both grids, and the friction map, before the first plan
        pl, s = self.place_planner, self.place_planner.settings
        centre = 0.5 * (np.asarray(region.lo) + np.asarray(region.hi))
        for grid in (args['coarse_grid'], args['task'].grid_size):
            validate(dataclasses.replace(placement_request(args['task'], centre),
                                         grid_size=grid), s.grid_size, s.max_grid_size)
        pl.friction_map(args['task'].friction_map)
        return args

    def on_place(self, request, response):
        try:
            args = self._place_args(request)
        except PlanError as exc:
            return self._fail(response, exc.code, exc.message, 'placement')
        except Exception:  # noqa: BLE001 - the node must keep serving
            self.get_logger().error(traceback.format_exc())
            return self._fail(response, PlaceTask.Response.ERROR_INVALID_REQUEST,
                              'the request could not be read (details in the planner log)',
                              'placement')
        if not self._place_lock.acquire(blocking=False):
            return self._fail(response, PlaceTask.Response.ERROR_BUSY,
                              'a placement search is already running '
                              f'({self._place_state}); ask again when it has finished',
                              'placement')
        try:
            return self._place(args, response)
        except _Stopped:
            return self._fail(response, PlaceTask.Response.ERROR_SOLVER,
                              'the planner node is shutting down; search stopped', 'placement')
        except Exception:  # noqa: BLE001 - the node must keep serving
            self.get_logger().error(traceback.format_exc())
            return self._fail(response, PlaceTask.Response.ERROR_SOLVER,
                              'internal error of the placement search (details in the '
                              'planner log); please report it', 'placement')
        finally:
            self._place_state = ''
            self._place_lock.release()

    def _place(self, args, response):
        log = self.get_logger()

        def progress(line: str) -> None:
            self._place_state = line
            log.info(f'place_task: {line}')

        task = args['task']
        log.info(f'place_task: {args["n"]} centres x {args["region"].orientations().shape[0]}'
                 f' orientations, {task.energy_model or "mechanical"} energy, '
                 f'{task.duration:g} s, {args["starts"]} start(s)'
                 + (', convex bounds' if args['bounds'] else ''))
        self._place_state = 'starting'
        res = search(_StoppablePlanner(self.place_planner, self._stopping),
                     progress=progress, **args)
        png = self._write_map(res)
        response.map_png = png
        # the analytic electrical cap: what every plan of this duration draws (placement.py)
        fixed = task_fixed_electrical_energy(self.place_planner, task)
        if res.best_center is None:
            refused = sorted(set(res.reasons.values()))
            messages.fill_place_map(response, res, fixed)
            return self._fail(response, PlaceTask.Response.ERROR_UNREACHABLE,
                              f'no point of the region could be planned ({len(res.reasons)} '
                              f'refused: {"; ".join(refused[:2])})', 'placement')
        nodes = self.place_planner.node_samples(res.best_plan)
        messages.fill_place_response(response, res, nodes, fixed)
        response.message = (
            f'best placement centre {np.round(res.best_center, 4).tolist()} m, rotation '
            f'{np.degrees(res.best_rotation):.1f} deg, tilt '
            f'{np.round(np.degrees(res.best_tilt), 2).tolist()} deg: {res.best_energy:.2f} J '
            f'({res.measure}); {len(res.reasons)} of {res.energy.size} map points refused; '
            f'lower bound {res.region_lower_bound:.2f} J over {res.cells_covered}/'
            f'{res.cells_total} cells, possible improvement <= '
            f'{res.possible_improvement_pct:.2f} %; {res.evaluations} plans, '
            f'{res.wall_time:.1f} s' + _evidence_text(response))
        log.info(f'place_task: {response.message}')
        return response

    def _write_map(self, res) -> str:
        """The map PNG in place_map_dir ('' = none); '' and a warning if it cannot be
        written (the answer does not depend on it)."""
        folder = self.place['place_map_dir']
        if not folder or np.all(np.isnan(res.energy)):
            return ''
        name = os.path.join(folder, time.strftime('placement_%Y%m%d_%H%M%S')
                            + f'_{time.time_ns() % 1000000:06d}.png')
        try:
            os.makedirs(folder, exist_ok=True)
            return plot_map(name, res)
        except OSError as exc:
            self.get_logger().warning(f'place_task: map PNG not written to {name}: '
                                      f'{exc.strerror}')
            return ''

    @property
    def place_running(self) -> bool:
        """True while a placement search runs."""
        return self._place_lock.locked()

    def destroy_node(self):
        self._stopping.set()               # a running search ends at its next plan
        return super().destroy_node()


def _evidence_text(resp) -> str:
    """The multi-start and bound part of the answer's one-line message ('' without)."""
    text = ''
    if len(resp.end_energy) > 1:
        text += (f'; {len(resp.end_energy)} starts, spread {resp.multistart_spread_pct:.2f} %')
    if np.isfinite(resp.grid_bound_floor):
        text += (f'; convex bounds >= {resp.grid_bound_floor:.2f} J at the planned map points '
                 f'({resp.bound_gap_pct:.2f} % below the best)')
    return text


def _spin(node: PlannerNode) -> None:
    # plan_path, a running search, the immediate ERROR_BUSY answers and parameter services
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    spin_until_signal(executor)


def main(args=None):
    run_node(PlannerNode, _spin, args, spec=SPEC)


if __name__ == '__main__':
    main()
