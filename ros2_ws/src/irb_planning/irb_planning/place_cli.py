"""`ros2 run irb_planning place`: energy-optimal placement of a circle task: grid over a box for
the centre x rotations x tilts of the plane, refinement, certificate, energy map PNG.

Offline (default, no ROS graph: the search runs here, progress per plan) or, with ``--node``,
as a client of the planner node's ``place_task`` service (the search runs in the node, which
logs the progress; this waits up to ``--timeout`` s, prints the summary and writes the same
PNG and JSON from the answer). ``--starts K`` and ``--bounds`` ask for the global evidence
(multi-start compass searches, convex lower bounds at the map points), printed in both modes
with the nearest-point coverage and, on an electrical model, the fixed electrical energy.
Exit code 0 on success, 1 if the search (or the service) refused or found nothing reachable,
2 on bad arguments or no answer.
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from irb_description.node_help import own_args

from .placement import (PLACEMENT_MIN_DURATION_CHECK_FACTOR, Region, bound_gap_pct,
                        coverage, plot_map, search, task_fixed_electrical_energy)
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
    p.add_argument('--starts', type=int, default=0, metavar='K',
                   help='compass searches from K distinct starts (the coarse map\'s local '
                   'minima first); 0 = 1 offline, the node\'s place_default_starts with '
                   '--node (which refuses more than place_max_starts, 16)')
    p.add_argument('--bounds', action='store_true',
                   help='also the convex lower bound of every timing at each planned map '
                   'point and at the best placement (one bound solve per point)')
    p.add_argument('--start-angle', type=float, default=0.0,
                   help='start point of the circle in its own plane [rad]')
    p.add_argument('--friction-map', default='', help="friction-map YAML ('' = nominal; "
                   '--node only: the node reads it from its friction_map_dirs)')
    p.add_argument('--plot', default='placement.png', help="PNG path, '' = no plot")
    p.add_argument('--json', default='', help='write the result as JSON here')
    p.add_argument('--node', action='store_true',
                   help='ask the planner node (service --service) instead of searching here')
    p.add_argument('--service', default='place_task', help='--node: the PlaceTask service')
    p.add_argument('--timeout', type=float, default=900.0,
                   help='--node: longest wait for the answer [s]')
    return p.parse_args(argv)


def result_json(res, fixed_electrical: float = float('nan')) -> dict:
    """The JSON of a search result (offline and --node alike), with the evidence."""
    cov = res.energy_coverage or {}
    evidence = dict(
        starts=[{k: v for k, v in r.items() if k != 'result'} for r in res.starts],
        multistart_spread_pct=res.multistart_spread_pct,
        grid_bound_floor_j=res.grid_bound_floor, best_lower_bound_j=res.best_lower_bound,
        bound_gap_pct=bound_gap_pct(res),
        covered_share=cov.get('covered_fraction', float('nan')),
        refused_share=cov.get('uncovered_fraction', float('nan')),
        fixed_electrical_energy_j=float(fixed_electrical))
    return dict(evidence, best_center=(None if res.best_center is None
                             else np.asarray(res.best_center, float).tolist()),
                best_rotation_deg=float(np.degrees(res.best_rotation)),
                best_tilt_deg=np.degrees(res.best_tilt).tolist(),
                best_energy_j=res.best_energy, measure=res.measure,
                region_lower_bound_j=res.region_lower_bound,
                possible_improvement_pct=res.possible_improvement_pct,
                cells_covered=res.cells_covered, cells_total=res.cells_total,
                lipschitz_j_m=(None if res.lipschitz is None
                               else np.asarray(res.lipschitz, float).tolist()),
                evaluations=res.evaluations, wall_time_s=res.wall_time,
                refused={str(k): v for k, v in res.reasons.items()})


def evidence_lines(res, fixed_electrical: float = float('nan')) -> list[str]:
    """The global evidence of a result, one line each: every compass search's start, end
    and energy, the multi-start spread, the convex bound floor, the nearest-point coverage
    and (electrical models) the fixed electrical energy."""
    def where(c, o=None):
        text = f'[{c[0]:.4f}, {c[1]:.4f}, {c[2]:.4f}] m'
        if o is not None and (o[0] or o[1] or o[2]):
            text += (f' rotation {np.degrees(o[0]):.1f} deg tilt ({np.degrees(o[1]):.2f}, '
                     f'{np.degrees(o[2]):.2f}) deg')
        return text
    lines = []
    for i, r in enumerate(res.starts):
        head = (f'start {i + 1}/{len(res.starts)} {where(r["start_center"])} (coarse '
                f'{r["coarse_energy"]:.2f} J'
                + (', local minimum of the map' if r.get('local_minimum') else '') + ')')
        if r.get('end_center') is None:
            lines.append(head + ': refused on the full grid')
        else:
            lines.append(f'{head} -> end {where(r["end_center"], r["end_orientation"])}: '
                         f'{r["end_energy"]:.2f} J')
    ended = sum(1 for r in res.starts if np.isfinite(r['end_energy']))
    if len(res.starts) > 1:
        lines.append(f'multi-start: {ended} of {len(res.starts)} starts ended within '
                     f'{res.multistart_spread_pct:.2f} % of the best {res.best_energy:.2f} J '
                     '(evidence, not a bound: a basin narrower than the grid is missed)')
    else:
        lines.append('multi-start: one start (--starts K for more)')
    if np.isfinite(res.grid_bound_floor):
        lines.append(f'convex bounds: every timing at every planned map point costs >= '
                     f'{res.grid_bound_floor:.2f} J, at most {bound_gap_pct(res):.2f} % below '
                     f'the best (coarse theta grid; no claim between the points); at the best '
                     f'placement >= {res.best_lower_bound:.2f} J')
    else:
        lines.append('convex bounds: not computed (--bounds)')
    cov = res.energy_coverage or coverage([res.xs, res.ys, res.zs], res.energy)
    lines.append(f'coverage: {100 * cov["covered_fraction"]:.1f} % of the box is nearest to '
                 f'a reachable map point, {100 * cov["uncovered_fraction"]:.1f} % to a '
                 'refused one (no claim there)')
    if np.isfinite(fixed_electrical):
        share = (f' ({100 * fixed_electrical / res.best_energy:.1f} % of the best)'
                 if np.isfinite(res.best_energy) else '')
        lines.append(f'electrical: standby + drive idle energy {fixed_electrical:.2f} J at '
                     f'this duration{share}: no placement or timing draws less')
    return lines


def write_outputs(a, res, fixed_electrical: float = float('nan')) -> None:
    """The PNG (--plot) and the JSON (--json) of a result."""
    if a.plot and not np.all(np.isnan(res.energy)):
        print('plot:', plot_map(a.plot, res))
    if a.json:
        with open(a.json, 'w', encoding='utf-8') as f:
            json.dump(result_json(res, fixed_electrical), f, indent=1)
        print('json:', a.json)


def build_request(a, region: Region):
    """PlaceTask.Request from the arguments (angles already in radians in ``region``)."""
    from geometry_msgs.msg import Point
    from irb_interfaces.msg import PathSpec
    from irb_interfaces.srv import PlaceTask
    req = PlaceTask.Request()
    req.path = PathSpec(type=PathSpec.TYPE_CIRCLE, radius=a.radius,
                        start_angle=a.start_angle, direction=a.direction)
    req.duration, req.energy_model, req.friction_map = a.duration, a.energy_model, \
        a.friction_map
    req.grid_size, req.coarse_grid_size = a.grid, a.coarse_grid
    req.lo = Point(x=a.lo[0], y=a.lo[1], z=a.lo[2])
    req.hi = Point(x=a.hi[0], y=a.hi[1], z=a.hi[2])
    req.rotations = [float(x) for x in region.rotations]
    req.tilt_x = [float(x) for x in region.tilt_x]
    req.tilt_y = [float(x) for x in region.tilt_y]
    req.grid_points = [int(k) for k in a.n]
    req.refine, req.min_step = a.refine, a.min_step
    req.min_tilt_step = float(np.radians(a.min_tilt_step))
    req.starts, req.bounds = a.starts, a.bounds
    return req


def summary(resp) -> str:
    """The placement, the certificate and the plan's table (the plan client's)."""
    from .plan_cli import summary as plan_summary
    c = resp.best_center
    lines = [f'best placement: centre [{c.x:.4f}, {c.y:.4f}, {c.z:.4f}] m, rotation '
             f'{np.degrees(resp.best_rotation):.1f} deg, tilt ({np.degrees(resp.best_tilt_x):.2f}'
             f', {np.degrees(resp.best_tilt_y):.2f}) deg: {resp.best_energy:.2f} J '
             f'({resp.energy_model})',
             f'map: {len(resp.map_energy)} points, '
             f'{sum(1 for r in resp.map_reason if r)} refused; lower bound '
             f'{resp.region_lower_bound:.2f} J over {resp.cells_covered}/{resp.cells_total} '
             f'fully reachable cells, possible improvement <= '
             f'{resp.possible_improvement_pct:.2f} %; {resp.evaluations} plans, '
             f'{resp.search_time:.1f} s in the node'
             + (f'; node map PNG {resp.map_png}' if resp.map_png else ''),
             'plan at the best placement:', plan_summary(resp)]
    return '\n'.join(lines)


def ask_node(a, region: Region, args=None) -> int:
    """--node: call the service, print, write the outputs; the exit code."""
    from irb_interfaces.srv import PlaceTask

    from .messages import placement_from_msg
    from .service_call import call_service
    request = build_request(a, region)

    def answered(resp) -> int:
        if not resp.success:
            print(f'placement refused (error {resp.error_code}): {resp.message}')
            if len(resp.map_energy):               # nothing reachable: the map says why
                res = placement_from_msg(resp)
                res.measure = a.energy_model
                write_outputs(a, res)
            return 1
        print(summary(resp))
        res = placement_from_msg(resp)
        print('\n'.join(evidence_lines(res, resp.fixed_electrical_energy)))
        write_outputs(a, res, resp.fixed_electrical_energy)
        return 0
    return call_service(PlaceTask, a.service, request, a.timeout, 'place_cli', answered, args,
                        asking=f'asking {a.service} (the node logs the progress; waiting up '
                               f'to {a.timeout:g} s)')


def main(args=None):
    argv = own_args(args)
    a = parse_args(argv)
    try:
        region = Region(np.array(a.lo), np.array(a.hi), tuple(np.radians(a.rotations)),
                        tuple(np.radians(a.tilt_x)), tuple(np.radians(a.tilt_y)))
        if a.duration <= 0 or min(a.n) < 1 or not a.min_tilt_step > 0 or a.starts < 0:
            raise ValueError('duration and --min-tilt-step must be > 0, every --n >= 1 and '
                             '--starts >= 0')
    except ValueError as exc:
        print(f'place: {exc}', file=sys.stderr)
        return 2
    if a.node:
        return ask_node(a, region, args)
    from .planner import Planner, PlannerSettings
    planner = Planner(settings=PlannerSettings(
        min_duration_check_factor=PLACEMENT_MIN_DURATION_CHECK_FACTOR,
        play_rate_hz=PlannerSettings().evaluation_rate_hz,    # as the node's search
        limit_cost=False))      # the search's many plans: no cost-of-the-limits solve
    task = PlanRequest(radius=a.radius, direction=a.direction, duration=a.duration,
                       energy_model=a.energy_model, grid_size=a.grid,
                       start_angle=a.start_angle, friction_map=a.friction_map)
    try:
        res = search(planner, task, region, tuple(a.n), a.coarse_grid, a.refine, a.min_step,
                     progress=lambda s: print(s, flush=True),
                     min_tilt_step=np.radians(a.min_tilt_step), starts=max(a.starts, 1),
                     bounds=a.bounds)
    except KeyboardInterrupt:
        return 130
    fixed = task_fixed_electrical_energy(planner, task)
    write_outputs(a, res, fixed)       # also when nothing is reachable: the JSON says why
    if res.best_center is None:
        print('no reachable placement in the region', file=sys.stderr)
        return 1
    print('\n'.join(evidence_lines(res, fixed)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
