"""Plan time with and without the smoothness limits (issue 28), same run.

    python ros2_ws/src/irb_planning/benchmarks/bench_jerk_time.py [--grid 60] [--repeat 1]
        [--name jerk_time] [--only NAME ...]

Standard requests (the thesis circle at 1.5 x T_min, a 0.6 m line in 3 s, the blended
polyline of the tests in 3 s, the main job's rectangle with its gluing band in 8 s, a closed
spline periodic in 3 s), each planned by a fresh ``Planner`` (problem build, time-optimal
duration, energy plan and its checks: what a first request costs) with ``jerk_limits`` on
(default) and off, alternating on/off so both see the same load. Per plan: wall and CPU
time of the process [s], IPOPT iterations, the energy [J], and the load average. The JSON
goes to results/<name>.json.

``--cost``: the price of reporting the cost of the limits (``limit_cost``, on by default):
each request also planned with the limits on and ``limit_cost=False``; per plan the extra
solve's time and iterations, the reported cost against the full figure of two planners
(played energy with the limits / without - 1, the same run).
"""
import argparse
import os
import time
from dataclasses import replace

import numpy as np
from _common import dump

from irb_description.path import path_spec, rectangle_path
from irb_planning.planner import Planner, PlannerSettings
from irb_planning.request import PlanError, PlanRequest

WAY = [[0.55, -0.25, 0.25], [0.8, -0.2, 0.3], [0.85, 0.05, 0.4], [0.7, 0.2, 0.35],
       [0.55, 0.15, 0.3]]
RECT = path_spec(rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025))


def requests(grid: int) -> dict:
    """name -> PlanRequest (duration 0: 1.5 x the time-optimal duration)."""
    return {
        'circle_1.5Tmin': PlanRequest(grid_size=grid, duration=0.0),
        'line_0.6m_3s': PlanRequest(path_type='line', grid_size=grid, duration=3.0,
                                    waypoints=np.array([[0.7, -0.3, 0.3], [0.7, 0.3, 0.3]])),
        'polyline_3s': PlanRequest(path_type='polyline', waypoints=np.asarray(WAY, float),
                                   blend_radii=np.array([0.03, 0.05, 0.02]), grid_size=grid,
                                   duration=3.0),
        'rectangle_band_8s': PlanRequest(
            path_type='polyline', waypoints=np.asarray(RECT['waypoints'], float),
            blend_radii=np.asarray(RECT['blend_radii'], float), closed=True, grid_size=grid,
            duration=8.0, tcp_speed_min=0.09, tcp_speed_max=0.15, tcp_ramp_length=0.04,
            tcp_accel_max=1.0),
        'spline_periodic_3s': PlanRequest(path_type='spline', waypoints=np.asarray(WAY, float),
                                          closed=True, boundary='periodic', grid_size=grid,
                                          duration=3.0),
    }


def one(req: PlanRequest, jerk: bool, grid: int, cost: bool = True) -> dict:
    """A fresh planner: time-optimal plan, then the request (1.5 T_min if duration 0)."""
    planner = Planner(settings=PlannerSettings(grid_size=grid, jerk_limits=jerk,
                                               limit_cost=cost))
    w0, c0 = time.perf_counter(), time.process_time()
    out = {'jerk_limits': jerk, 'limit_cost': cost, 'load_before': os.getloadavg()[0]}
    try:
        t = planner.plan(replace(req, objective='time', duration=0.0))
        out['t_min'] = t.min_duration
        out['time_plan_wall_s'] = time.perf_counter() - w0
        if t.limit_cost is not None:
            out['time_cost'] = {'cost': t.limit_cost.cost, 'solve_s': t.limit_cost.solve_time,
                                'iterations': t.limit_cost.iterations}
        duration = req.duration or 1.5 * t.min_duration
        r = planner.plan(replace(req, duration=duration))
        out.update(energy=r.evaluation.energy, duration=duration, iterations=r.iterations,
                   solve_time_s=r.solve_time, ok=bool(r.verification.ok),
                   notes=[n for n in r.notes if 'tighten' in n])
        if r.limit_cost is not None:
            out['energy_cost'] = {'cost': r.limit_cost.cost,
                                  'with_j': r.limit_cost.with_limits,
                                  'without_j': r.limit_cost.without_limits,
                                  'solve_s': r.limit_cost.solve_time,
                                  'iterations': r.limit_cost.iterations}
    except PlanError as exc:
        out.update(refused=exc.code, message=exc.message)
    out['wall_s'] = time.perf_counter() - w0
    out['cpu_s'] = time.process_time() - c0
    out['load_after'] = os.getloadavg()[0]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--grid', type=int, default=60)
    ap.add_argument('--repeat', type=int, default=1)
    ap.add_argument('--name', default='jerk_time')
    ap.add_argument('--only', nargs='*', default=None)
    ap.add_argument('--cost', action='store_true',
                    help='also plan with limit_cost off (the price of reporting the cost)')
    args = ap.parse_args()
    reqs = requests(args.grid)
    rows = {}
    for name, req in reqs.items():
        if args.only and name not in args.only:
            continue
        rows[name] = []
        for _ in range(args.repeat):
            for jerk, cost in ((True, True), (False, True)) + (
                    ((True, False),) if args.cost else ()):
                rows[name].append(one(req, jerk, args.grid, cost))
                print(name, rows[name][-1], flush=True)
    summary = {}
    for name, rs in rows.items():
        on = [r['cpu_s'] for r in rs if r['jerk_limits'] and r['limit_cost']]
        off = [r['cpu_s'] for r in rs if not r['jerk_limits']]
        summary[name] = {'cpu_on_s': float(np.median(on)), 'cpu_off_s': float(np.median(off)),
                         'ratio': float(np.median(on) / np.median(off))}
        quiet = [r['cpu_s'] for r in rs if r['jerk_limits'] and not r['limit_cost']]
        if quiet:
            summary[name]['cpu_on_without_limit_cost_s'] = float(np.median(quiet))
        rep = [r for r in rs if 'energy_cost' in r]
        plain = [r['energy'] for r in rs if not r['jerk_limits'] and 'energy' in r]
        if rep:
            summary[name]['extra_solve_s'] = float(np.median(
                [r['energy_cost']['solve_s'] + r.get('time_cost', {}).get('solve_s', 0.0)
                 for r in rep]))
            summary[name]['reported_energy_cost'] = float(np.median(
                [r['energy_cost']['cost'] for r in rep]))
            if plain:
                summary[name]['two_planner_energy_cost'] = float(
                    np.median([r['energy'] for r in rep]) / np.median(plain) - 1.0)
    dump(args.name, {'grid': args.grid, 'repeat': args.repeat, 'rows': rows,
                     'summary': summary})


if __name__ == '__main__':
    main()
