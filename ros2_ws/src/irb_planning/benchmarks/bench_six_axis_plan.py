#!/usr/bin/env python3
"""Six-axis plans along every path type with every orientation law, played (issue 30).

For each path (line, arc, circle, rectangle with blends, spline) and law (fixed, path_normal
-- fixed x on the rectangle -- and slerp over three keyframes), with the 0.10 m nozzle:
the six-axis problem (``six_axis_plan``), its time-optimal duration and the energy-optimal plan
at T = max(length / 0.25 m/s, 1.2 t_min); each plan's message played by the independent check
(``six_axis_check``: quintic per joint at 10 kHz, own DH kinematics): the largest position and
orientation error, at the points and as played, peak torques and speeds, energy. Goals: 0.1 mm
and 0.05 deg as played.

Planning time: per path, the six-axis plan (problem build + time-optimal + energy at T, a new
problem every repeat) against the three-axis planner's (``Planner.plan`` energy at the same T
on the same path with the wrist locked, a new Planner every repeat, so nothing is cached),
both on the same grid, interleaved in the same run; median and spread of ``--repeats``.

    python ros2_ws/src/irb_planning/benchmarks/bench_six_axis_plan.py [--grid 200]
        [--repeats 3] [--out six_axis_plan]
"""
import argparse
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _common import dump  # noqa: E402

SPEED = 0.25            # [m/s] mean TCP speed of the energy plans (the tracking speed)


def path_specs():
    from irb_description.path import rectangle_path
    u = np.array([1.0, 0.0, -0.3]) / np.hypot(1.0, 0.3)
    v = np.array([0.0, 1.0, 0.0])
    c = np.array([0.65, 0.0, 0.35])
    rect = rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025)
    return {
        'line': dict(type='line', waypoints=[[0.55, -0.25, 0.25], [0.75, 0.2, 0.45]]),
        'arc': dict(type='arc', center=[0.65, 0.1, 0.35], normal=[0.0, -0.3, 1.0],
                    radius=0.1, start_angle=0.5, sweep=4.0),
        'circle': dict(type='circle', center=[0.6, 0.0, 0.13], radius=0.15),
        'rectangle': dict(type='polyline', waypoints=rect.waypoints.tolist(),
                          blend_radii=rect.blend_radii.tolist(), closed=True),
        'spline': dict(type='spline', waypoints=[(c + a * u + b * v).tolist() for a, b in
                                                 [(-0.1, -0.15), (0.0, -0.05), (0.08, 0.05),
                                                  (0.0, 0.12), (-0.1, 0.15)]]),
    }


def law_specs(name):
    """The three laws as path-file blocks (rpy in URDF convention)."""
    down = [np.pi, 0.0, 0.0]
    slerp = {'law': 'slerp', 'keyframes': [
        {'theta': 0.0, 'rpy': down},
        {'theta': float(np.pi), 'rpy': [np.pi, 0.4, 0.0]},       # tilted 0.4 rad about y
        {'theta': float(2 * np.pi), 'rpy': [np.pi + 0.3, 0.0, 0.6]}]}
    normal = {'law': 'path_normal', 'x_mode': 'fixed' if name == 'rectangle' else 'tangent'}
    if name == 'line':
        normal['normal'] = [0.0, 0.0, 1.0]
    return {'fixed': {'law': 'fixed', 'rpy': [np.pi, 0.2, 0.0]}, 'path_normal': normal,
            'slerp': slerp}


def three_axis_request(spec, duration, grid):
    from irb_planning.request import PlanRequest
    keys = {k: v for k, v in spec.items() if k != 'type'}
    arrays = {k: np.asarray(v, float) for k, v in keys.items()
              if k in ('center', 'normal', 'waypoints', 'blend_radii')}
    keys.update(arrays)
    return PlanRequest(path_type=spec['type'], objective='energy', duration=duration,
                       grid_size=grid, **keys)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--grid', type=int, default=200, help='theta nodes of both planners')
    p.add_argument('--repeats', type=int, default=3, help='timing repeats per path')
    p.add_argument('--paths', nargs='*', default=None, help='subset of the path names')
    p.add_argument('--out', default='six_axis_plan', help='results/<out>.json')
    a = p.parse_args(argv)
    from irb_description.path import path_from_spec
    from irb_planning.planner import Planner
    from irb_planning.six_axis_plan import SixAxisPlanError, SixAxisPlanner, task_from_spec

    six = SixAxisPlanner()
    cases, timing = [], []
    load = [os.getloadavg()[0]]
    for name, spec in path_specs().items():
        if a.paths and name not in a.paths:
            continue
        length = path_from_spec(spec).length
        duration = None
        for law_name, law in law_specs(name).items():
            path, lw = task_from_spec({**spec, 'orientation': law})
            row = {'path': name, 'law': law_name, 'length_m': length}
            t0 = time.perf_counter()
            try:
                prob = six.problem(path, lw, a.grid)
                t_min, out = six.min_duration(prob)
                T = max(length / SPEED, 1.2 * t_min)
                plan = six.plan(prob, 'energy', T)
            except SixAxisPlanError as exc:
                row['refused'] = str(exc)
                cases.append(row)
                print(f'{name:10s} {law_name:12s} refused: {exc}', file=sys.stderr)
                continue
            tchk = out[3]
            c = plan.check
            row.update(
                configuration=list(prob.configuration), grid=a.grid,
                wall_s=time.perf_counter() - t0, min_duration_s=t_min, duration_s=T,
                energy_j=plan.energy, optimizer_energy_j=plan.optimizer_energy,
                points=len(plan.trajectory['t']), played_samples=c.samples,
                played_position_error_mm=c.position_error * 1e3,
                played_orientation_error_deg=float(np.degrees(c.orientation_error)),
                point_position_error_mm=c.point_position_error * 1e3,
                point_orientation_error_deg=float(np.degrees(c.point_orientation_error)),
                peak_torque_nm=c.peak_torque.tolist(), peak_speed_rad_s=c.peak_speed.tolist(),
                peak_accel_rad_s2=c.peak_accel.tolist(),
                time_optimal_peak_accel_rad_s2=tchk.peak_accel.tolist(),
                time_optimal_played_position_error_mm=tchk.position_error * 1e3,
                time_optimal_played_orientation_error_deg=float(
                    np.degrees(tchk.orientation_error)),
                time_optimal_problems=tchk.problems, notes=plan.notes,
                within_goals=bool(c.position_error <= 1e-4
                                  and np.degrees(c.orientation_error) <= 0.05))
            duration = duration or T
            cases.append(row)
            print(f'{name:10s} {law_name:12s} t_min {t_min:6.3f} s  T {T:6.3f} s  '
                  f'E {plan.energy:8.2f} J  played {c.position_error * 1e3:.5f} mm '
                  f'{np.degrees(c.orientation_error):.6f} deg  points {row["points"]}  '
                  f'({row["wall_s"]:.1f} s)', file=sys.stderr)
            load.append(os.getloadavg()[0])
        if duration is None:
            continue
        # planning time: six-axis (path_normal law) against three-axis, same path, same T
        path, lw = task_from_spec({**spec, 'orientation': law_specs(name)['path_normal']})
        t6, t3, e3, parts6, parts3 = [], [], None, [], []
        for _ in range(a.repeats):
            planner6 = SixAxisPlanner()
            t0 = time.perf_counter()
            try:
                pl6 = planner6.plan(planner6.problem(path, lw, a.grid), 'energy', duration)
                t6.append(time.perf_counter() - t0)
                parts6.append({'build_s': pl6.build_time, 'energy_solve_s': pl6.solve_time,
                               'energy_iterations': pl6.iterations})
            except SixAxisPlanError as exc:
                print(f'{name}: six-axis timing refused: {exc}', file=sys.stderr)
            planner3 = Planner()
            t0 = time.perf_counter()
            try:
                r3 = planner3.plan(three_axis_request(spec, duration, a.grid))
                t3.append(time.perf_counter() - t0)
                e3 = r3.evaluation.energy
                parts3.append({'energy_solve_s': r3.solve_time,
                               'energy_iterations': r3.iterations})
            except Exception as exc:  # noqa: BLE001 - a refusal is a result here
                print(f'{name}: three-axis refused: {exc}', file=sys.stderr)
            load.append(os.getloadavg()[0])
        med = lambda x: statistics.median(x) if x else None  # noqa: E731
        timing.append({'path': name, 'duration_s': duration, 'grid': a.grid,
                       'six_axis_s': t6, 'three_axis_s': t3, 'six_axis_median_s': med(t6),
                       'three_axis_median_s': med(t3),
                       'ratio_median': (med(t6) / med(t3)) if t6 and t3 else None,
                       'three_axis_energy_j': e3, 'six_axis_parts': parts6,
                       'three_axis_parts': parts3})
        print(f'{name:10s} timing six {med(t6)} s, three {med(t3)} s', file=sys.stderr)
    ok = [c for c in cases if 'refused' not in c]
    dump(a.out, {
        'what': 'six-axis energy plans played by the independent check, per path and law; '
                'six-axis vs three-axis planning time',
        'tcp': 'nozzle 0.10 m on tool0', 'speed_m_s': SPEED,
        'goals': {'played_position_error_mm': 0.1, 'played_orientation_error_deg': 0.05},
        'worst_played_position_error_mm': max(c['played_position_error_mm'] for c in ok)
        if ok else None,
        'worst_played_orientation_error_deg': max(c['played_orientation_error_deg']
                                                  for c in ok) if ok else None,
        'all_within_goals': bool(ok) and all(c['within_goals'] for c in ok)
        and len(ok) == len(cases),
        'load_1min': {'min': min(load), 'max': max(load)},
        'limits_sources': six.limits.sources,
        'cases': cases, 'timing': timing})


if __name__ == '__main__':
    main()
