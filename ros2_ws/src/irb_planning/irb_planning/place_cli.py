"""`ros2 run irb_planning place`: energy-optimal placement of a circle task (offline, no ROS
graph): grid over a box for the centre x rotations x tilts of the plane, refinement,
certificate, energy map PNG."""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from .placement import Region, plot_map, search
from .request import ENERGY_MODELS, PlanRequest


def parse_args(argv):
    p = argparse.ArgumentParser(prog='place', description=__doc__.splitlines()[0])
    p.add_argument('--lo', type=float, nargs=3, default=[0.4, -0.4, -0.17],
                   metavar=('X', 'Y', 'Z'), help='region corner, centre [m]')
    p.add_argument('--hi', type=float, nargs=3, default=[0.8, 0.4, 0.43],
                   metavar=('X', 'Y', 'Z'), help='region corner, centre [m]')
    p.add_argument('--n', type=int, nargs=3, default=[3, 3, 3], help='grid points per axis')
    p.add_argument('--rotations', type=float, nargs='+', default=[0.0],
                   help='rotations about z [deg] (start-angle offsets)')
    p.add_argument('--tilt-x', type=float, nargs='+', default=[0.0], metavar='DEG',
                   help='tilts of the circle plane about the base x axis [deg] (grid values; '
                   'the refinement stays within their range)')
    p.add_argument('--tilt-y', type=float, nargs='+', default=[0.0], metavar='DEG',
                   help='tilts of the circle plane about the base y axis [deg]')
    p.add_argument('--min-tilt-step', type=float, default=2.0,
                   help='compass search end for the tilts [deg]')
    p.add_argument('--radius', type=float, default=0.15, help='[m]')
    p.add_argument('--direction', type=int, default=1, choices=(1, -1))
    p.add_argument('--duration', type=float, default=10.0, help='[s]')
    p.add_argument('--energy-model', default='mechanical', choices=list(ENERGY_MODELS))
    p.add_argument('--coarse-grid', type=int, default=40, help='theta nodes of the map')
    p.add_argument('--grid', type=int, default=0, help='theta nodes of refinement, 0 = default')
    p.add_argument('--refine', type=int, default=2, help='best map points re-planned')
    p.add_argument('--min-step', type=float, default=0.025, help='compass search end [m]')
    p.add_argument('--plot', default='placement.png', help="PNG path, '' = no plot")
    p.add_argument('--json', default='', help='write the result as JSON here')
    return p.parse_args(argv)


def main(args=None):
    argv = list(sys.argv[1:] if args is None else args)
    if '--ros-args' in argv:
        argv = argv[:argv.index('--ros-args')]
    a = parse_args(argv)
    try:
        region = Region(np.array(a.lo), np.array(a.hi), tuple(np.radians(a.rotations)),
                        tuple(np.radians(a.tilt_x)), tuple(np.radians(a.tilt_y)))
        if a.duration <= 0 or min(a.n) < 1 or not a.min_tilt_step > 0:
            raise ValueError('duration and --min-tilt-step must be > 0 and every --n >= 1')
    except ValueError as exc:
        print(f'place: {exc}', file=sys.stderr)
        return 2
    from .planner import Planner
    planner = Planner()
    task = PlanRequest(radius=a.radius, direction=a.direction, duration=a.duration,
                       energy_model=a.energy_model, grid_size=a.grid)
    try:
        res = search(planner, task, region, tuple(a.n), a.coarse_grid, a.refine, a.min_step,
                     progress=lambda s: print(s, flush=True),
                     min_tilt_step=np.radians(a.min_tilt_step))
    except KeyboardInterrupt:
        return 130
    if res.best_center is None:
        print('no reachable placement in the region', file=sys.stderr)
        return 1
    if a.plot:
        print('plot:', plot_map(a.plot, res))
    if a.json:
        out = dict(best_center=res.best_center.tolist(),
                   best_rotation_deg=float(np.degrees(res.best_rotation)),
                   best_tilt_deg=np.degrees(res.best_tilt).tolist(),
                   best_energy_j=res.best_energy, measure=res.measure,
                   region_lower_bound_j=res.region_lower_bound,
                   possible_improvement_pct=res.possible_improvement_pct,
                   cells_covered=res.cells_covered, cells_total=res.cells_total,
                   lipschitz_j_m=res.lipschitz.tolist(), evaluations=res.evaluations,
                   wall_time_s=res.wall_time, refused={str(k): v for k, v in
                                                       res.reasons.items()})
        with open(a.json, 'w', encoding='utf-8') as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
