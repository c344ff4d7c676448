"""`ros2 run irb_planning plan`: call the plan_path service, print a summary, write a plot.

    ros2 run irb_planning plan --duration 10 [--objective energy] [--plot plan.png]
    ros2 run irb_planning plan --path-file rectangle.yaml --duration 6

``--path-file``: a YAML mapping of a path (irb_description.path.path_from_spec), e.g.

    type: polyline
    waypoints: [[0.55, -0.15, 0.25], [0.85, -0.15, 0.3], [0.85, 0.15, 0.3]]
    blend_radii: [0.03]
    closed: false
    process: {tcp_speed_max: 0.15, tcp_speed_min: 0.09, tcp_accel_max: 1.0}   # optional

(types circle, arc, line, polyline, spline; the circle options are used without it). The
optional ``process`` block holds the process constraints (irb_description.path
``process_from_spec``); the --tcp-* options override its values.

When a controller listens (a node publishes ``irb_interfaces/PlanStatus``, as pdplus does on
``~/plan_status``), ``plan`` waits for its verdict on this plan (matched by the plan's stamp)
and prints it: pdplus checks the plan on the path it was planned on and keeps it pending for
``~/enable``. With no controller it only prints the plan, as before.

Exit code 0 on success, 1 if the planner refused (its error code and message are printed),
2 if the service did not answer, 3 if a controller refused the plan (its reason is printed),
4 if a controller listens but gave no verdict within ``--verdict-timeout``.
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import rclpy
from geometry_msgs.msg import Point
from irb_interfaces.msg import PathSpec
from irb_interfaces.srv import PlanPath

from .costs import time_weight
from .messages import path_msg_from_spec
from .plan_plot import save_plan_outputs
from .planner import limit_cost_from_message
from .service_call import call_service


def parse_args(argv):
    p = argparse.ArgumentParser(prog='plan', description=__doc__.splitlines()[0])
    p.add_argument('--center', type=float, nargs=3, default=[0.6, 0.0, 0.13],
                   metavar=('X', 'Y', 'Z'), help='circle centre [m] (thesis 0.6 0 0.13)')
    p.add_argument('--radius', type=float, default=0.15, help='[m]')
    p.add_argument('--start-angle', type=float, default=0.0, help='[rad]')
    p.add_argument('--direction', type=int, default=1, choices=(1, -1))
    p.add_argument('--path-file', default='',
                   help='YAML path spec (type, waypoints, ...); replaces the circle options')
    p.add_argument('--objective', default='energy',
                   help='energy | time | trapezoid | fourier')
    p.add_argument('--duration', type=float, default=10.0, help='[s], 0 = free')
    p.add_argument('--time-weight', type=float, default=0.0, help='[J/s] when duration 0')
    p.add_argument('--order', type=int, default=7, help='Fourier order 3, 5, 7')
    p.add_argument('--grid', type=int, default=0, help='theta nodes, 0 = planner default')
    p.add_argument('--limit-scaling', type=float, default=0.0, help='(0, 1], 0 = 1')
    p.add_argument('--friction-map', default='', help="friction-map YAML, '' = nominal")
    p.add_argument('--boundary', default='', help="'' = rest, or periodic")
    p.add_argument('--energy-price', type=float, default=0.0,
                   help='[currency/kWh]; with --machine-hour-cost sets --time-weight')
    p.add_argument('--machine-hour-cost', type=float, default=0.0, help='[currency/h]')
    p.add_argument('--energy-model', default='',
                   help="mechanical | electrical_none | electrical_shared | "
                        "electrical_regenerative ('' = mechanical)")
    for name, unit, what in (
            ('speed-max', 'm/s', 'TCP speed ceiling'),
            ('speed-min', 'm/s', 'TCP speed floor away from the rest ends'),
            ('accel-max', 'm/s^2', 'bound on |TCP acceleration|'),
            ('ramp-length', 'm', 'arc length at each rest end free of the floor (0 = '
             'speed-min^2 / accel-max)')):
        p.add_argument(f'--tcp-{name}', type=float, default=None,
                       help=f'[{unit}] {what}; 0 = none (default: the path file\'s process '
                       'block, else none)')
    p.add_argument('--service', default='plan_path')
    p.add_argument('--timeout', type=float, default=120.0, help='[s]')
    p.add_argument('--plot', default='plan.png',
                   help="PNG path, '' = no plot; the plan file goes beside it (.json)")
    p.add_argument('--verdict-timeout', type=float, default=30.0,
                   help='[s] wait this long for the verdict of a listening controller '
                        '(pdplus ~/plan_status); 0 = do not wait')
    p.add_argument('--plan-status', default='',
                   help="the controller's PlanStatus topic to wait on (e.g. "
                        "/pdplus/plan_status); '' = every one in the graph")
    return p.parse_args(argv)


def read_path_file(name: str) -> PathSpec:
    """PathSpec from a YAML path file; ValueError with one line saying why not."""
    from irb_description.path import read_path_spec
    spec = read_path_spec(name)
    try:
        return path_msg_from_spec(spec)
    except (ValueError, TypeError, IndexError) as exc:
        raise ValueError(f'path file {name}: {exc}') from None


def read_path_process(name: str) -> dict:
    """The process constraints {field: value} of a YAML path file's optional ``process``
    block ({} without one); ValueError with one line saying why not."""
    from irb_description.path import process_from_spec, read_path_spec
    try:
        return process_from_spec(read_path_spec(name))
    except ValueError as exc:
        raise ValueError(f'path file {name}: {exc}') from None


def build_request(a) -> PlanPath.Request:
    req = PlanPath.Request()
    process = {}
    if a.path_file:
        req.path = read_path_file(a.path_file)
        process = read_path_process(a.path_file)
    else:
        req.path = PathSpec(type=PathSpec.TYPE_CIRCLE,
                            center=Point(x=a.center[0], y=a.center[1], z=a.center[2]),
                            radius=a.radius, start_angle=a.start_angle, direction=a.direction)
    req.objective, req.duration, req.time_weight = a.objective, a.duration, a.time_weight
    if a.energy_price > 0:
        req.time_weight = time_weight(a.energy_price, a.machine_hour_cost)
    req.fourier_order = a.order if a.objective == 'fourier' else 0
    req.grid_size, req.limit_scaling = a.grid, a.limit_scaling
    req.friction_map, req.boundary = a.friction_map, a.boundary
    req.energy_model = a.energy_model
    for field in ('tcp_speed_max', 'tcp_speed_min', 'tcp_accel_max', 'tcp_ramp_length'):
        value = getattr(a, field)
        setattr(req, field, float(process.get(field, 0.0) if value is None else value))
    return req


def summary(resp: PlanPath.Response) -> str:
    rows = [('', 'plan', 'trapezoid'),
            ('duration [s]', f'{resp.duration:.3f}', f'{resp.baseline_duration:.3f}'),
            ('energy [J]', f'{resp.energy:.2f}', f'{resp.baseline_energy:.2f}'),
            ('peak torque [N m]', ' '.join(f'{x:.1f}' for x in resp.peak_torque),
             ' '.join(f'{x:.1f}' for x in resp.baseline_peak_torque)),
            ('feasible', 'yes', 'yes' if resp.baseline_feasible else 'NO')]
    for k, mode in enumerate(resp.electrical_bus_modes):
        base = (f'{resp.baseline_electrical_energy[k]:.1f}'
                if len(resp.baseline_electrical_energy) > k else '-')
        rows.insert(3 + k, (f'electrical {mode} [J]', f'{resp.electrical_energy[k]:.1f}', base))
    saving = 100 * (1 - resp.energy / resp.baseline_energy) if resp.baseline_energy else 0
    lines = [f'{r[0]:<28}{r[1]:>22}{r[2]:>22}' for r in rows]
    lines += [f'saving vs trapezoid: {saving:.2f} % (mechanical)']
    for k, mode in enumerate(resp.electrical_bus_modes):
        if len(resp.baseline_electrical_energy) > k and resp.baseline_electrical_energy[k]:
            ratio = resp.electrical_energy[k] / resp.baseline_electrical_energy[k]
            lines.append(f'saving vs trapezoid, electrical {mode}: {100 * (1 - ratio):.2f} %')
    if np.isfinite(resp.tcp_speed_peak) and resp.tcp_speed_peak > 0:
        lines.append(f'TCP as played: speed {resp.tcp_speed_low:.4g} (away from the rest '
                     f'ends) .. {resp.tcp_speed_peak:.4g} m/s, |acceleration| <= '
                     f'{resp.tcp_accel_peak:.4g} m/s^2')
    if resp.electrical_bus_modes:
        lines.append(f'objective energy model: {resp.energy_model or "mechanical"}; copper '
                     f'{resp.copper_energy:.1f} J, standby {resp.standby_energy:.1f} J')
    cost = limit_cost_from_message(resp.message)
    if cost is not None:
        lines.append(cost['note'])
    lines += [
              f'optimiser energy {resp.optimizer_energy:.2f} J, time-optimal duration '
              f'{resp.min_duration:.3f} s, solver {resp.solver_status}, '
              f'{resp.iterations} iterations, {1000 * resp.solve_time:.0f} ms',
              resp.message]
    return '\n'.join(lines)


PLAN_STATUS_TYPE = 'irb_interfaces/msg/PlanStatus'
#: how long to look for a listening controller before printing the plan as before [s]
DISCOVERY_GRACE_S = 1.0


def wait_for_verdict(stamp, timeout: float, context=None, only: str = '') -> int:
    """The verdict of every controller that publishes a PlanStatus (``only``: on that topic)
    on the plan of ``stamp`` (builtin_interfaces/Time): 0 when all accepted it or no
    controller listens, 3 when one refused it (its reason printed), 4 when one gave no
    verdict within ``timeout`` [s]."""
    from irb_description.node_main import latched_qos
    from irb_interfaces.msg import PlanStatus
    from rclpy.executors import SingleThreadedExecutor
    node = rclpy.create_node('plan_cli_verdict', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        def listening():
            return sorted(name for name, types in node.get_topic_names_and_types()
                          if PLAN_STATUS_TYPE in types and node.count_publishers(name) > 0
                          and (not only or name == only))
        topics = listening()
        grace = time.monotonic() + DISCOVERY_GRACE_S      # a controller just discovered
        while not topics and time.monotonic() < grace:
            executor.spin_once(timeout_sec=0.05)
            topics = listening()
        if not topics:
            print('no controller listens (no plan_status): the plan is published only')
            return 0
        key = (stamp.sec, stamp.nanosec)
        verdicts = {}

        def on_status(topic, msg):
            if (msg.plan_stamp.sec, msg.plan_stamp.nanosec) == key:
                verdicts[topic] = msg
        for topic in topics:
            node.create_subscription(PlanStatus, topic,
                                     lambda m, t=topic: on_status(t, m), latched_qos())
        deadline = time.monotonic() + timeout
        while len(verdicts) < len(topics) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=min(0.1, max(deadline - time.monotonic(), 0.0)))
        refused = missing = False
        for topic in topics:
            v = verdicts.get(topic)
            if v is None:
                print(f'{topic}: no verdict on this plan within {timeout:g} s', file=sys.stderr)
                missing = True
            elif v.accepted:
                print(f'{topic}: plan accepted ({v.points} points, {v.duration:.3f} s); it '
                      'starts on enable')
            else:
                print(f'{topic}: plan refused: {v.reason}', file=sys.stderr)
                refused = True
        return 3 if refused else 4 if missing else 0
    finally:
        executor.shutdown()
        node.destroy_node()


def main(args=None):
    argv = rclpy.utilities.remove_ros_args(args if args is not None else sys.argv)[1:]
    a = parse_args(argv)
    try:
        request = build_request(a)
    except ValueError as exc:
        print(f'plan: {exc}', file=sys.stderr)
        return 1

    def answered(resp) -> int:
        if not resp.success:
            print(f'planner refused (error {resp.error_code}): {resp.message}')
            return 1
        print(summary(resp))
        if a.plot:
            print(save_plan_outputs(a.plot, resp, request.path, a.objective))
        if a.verdict_timeout <= 0:
            return 0
        return wait_for_verdict(resp.trajectory.header.stamp, a.verdict_timeout,
                                only=a.plan_status)
    return call_service(PlanPath, a.service, request, a.timeout, 'plan_cli', answered, args)


if __name__ == '__main__':
    sys.exit(main())
