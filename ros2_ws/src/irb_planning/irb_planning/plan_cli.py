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

Exit code 0 on success, 1 if the planner refused (its error code and message are printed),
2 if the service did not answer.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import rclpy
from geometry_msgs.msg import Point
from irb_interfaces.msg import PathSpec
from irb_interfaces.srv import PlanPath

from .costs import time_weight
from .messages import path_msg_from_spec
from .plan_plot import save_plan_outputs
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
    lines += [
              f'optimiser energy {resp.optimizer_energy:.2f} J, time-optimal duration '
              f'{resp.min_duration:.3f} s, solver {resp.solver_status}, '
              f'{resp.iterations} iterations, {1000 * resp.solve_time:.0f} ms',
              resp.message]
    return '\n'.join(lines)


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
        return 0
    return call_service(PlanPath, a.service, request, a.timeout, 'plan_cli', answered, args)


if __name__ == '__main__':
    sys.exit(main())
