"""Plans as a trajectory controller plays them (issue 28): random requests over every path
type, with and without process constraints, each success played at 10 kHz by the tests'
independent player (test/played.py: quintic of the message's points on ns stamps, pinocchio
TCP rates and torques).

    python ros2_ws/src/irb_planning/benchmarks/bench_smooth.py [--n 200] [--grid 60]

Per request: a path type in turn (circle, line, arc, polyline, spline), its geometry drawn at
random in the reachable workspace (code 2 redraws), the time-optimal plan (T_min), then an
energy plan at a duration uniform in [1.2, 2.5] T_min, every other one with process
constraints (speed band 0.5 .. 2 x the mean TCP speed, |a| <= uniform [1, 4] m/s^2 or
twice the floor's centripetal acceleration, default ramps). Both plans are successes to check (or refusals to record).

Figures: per limit the worst played / limit ratio (goal <= 1.00); the smallest point spacing;
full-tolerance consistency (irb_description.trajectory_rules) of every message; reported vs
played peaks; the largest torque step between control samples (248 Hz, the holding torque
before the start and after the end included); periodic closed-spline plan time against the
same path at rest, same run.

Smoothness limits (issue 28): every energy request is planned twice, by the default planner
(jerk limits on) and by one with ``jerk_limits=False``: the energy cost of the limits
(energy on / off - 1), the torque steps between control samples of both, and per smoothness
limit the worst played / limit ratio (joint jerk and rigid-body torque rate from the
independent player's samples, TCP jerk from the planner's own played check). Path types in
turn: circle, line, arc, polyline, spline, and a closed spline planned periodic. The JSON is
rewritten after every draw (``partial``: true until the run ends) with the random state;
``--resume`` continues it (the planners' caches start empty again, so a resumed run's warm
starts differ from an uninterrupted one's; the draws are the same).
"""
import argparse
import importlib.util
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from _common import RESULTS, dump

from irb_description.trajectory_rules import worst_inconsistency
from irb_planning.planner import Planner, PlannerSettings, request_path
from irb_planning.request import ERROR_UNREACHABLE, PlanError, PlanRequest

_spec = importlib.util.spec_from_file_location(
    'played', Path(__file__).resolve().parents[1] / 'test' / 'played.py')
played = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(played)

CONTROL_PERIOD_S = 0.004032
TYPES = ('circle', 'line', 'arc', 'polyline', 'spline', 'periodic')


def draw(kind: str, rng) -> PlanRequest:
    """A random path request of ``kind`` (not yet checked for reachability)."""
    if kind == 'periodic':
        return replace(draw('spline', rng), closed=True, boundary='periodic')
    c = np.array([rng.uniform(0.45, 0.85), rng.uniform(-0.3, 0.3), rng.uniform(0.1, 0.6)])
    if kind == 'circle':
        return PlanRequest(center=c, radius=float(rng.uniform(0.05, 0.2)),
                           start_angle=float(rng.uniform(0, 2 * np.pi)),
                           direction=int(rng.choice([-1, 1])))
    if kind == 'line':
        d = rng.normal(size=3)
        d *= rng.uniform(0.15, 0.5) / np.linalg.norm(d)
        return PlanRequest(path_type='line', waypoints=np.array([c - d / 2, c + d / 2]))
    if kind == 'arc':
        return PlanRequest(path_type='arc', center=c, normal=rng.normal(size=3),
                           radius=float(rng.uniform(0.05, 0.2)),
                           start_angle=float(rng.uniform(0, 2 * np.pi)),
                           sweep=float(rng.choice([-1, 1]) * rng.uniform(1.0, 6.0)))
    k = int(rng.integers(4, 7))
    ang = np.sort(rng.uniform(0, 2 * np.pi, k))
    r = rng.uniform(0.08, 0.2, k)
    e1, e2 = np.linalg.qr(np.column_stack([rng.normal(size=3), rng.normal(size=3)]))[0].T
    way = c + (r * np.cos(ang))[:, None] * e1 + (r * np.sin(ang))[:, None] * e2
    closed = bool(rng.integers(0, 2))
    if kind == 'polyline':
        return PlanRequest(path_type='polyline', waypoints=way, closed=closed,
                           blend_radii=np.array([float(rng.uniform(0.01, 0.03))]))
    return PlanRequest(path_type='spline', waypoints=way, closed=closed)


def analyse(model, res, req, smooth=None, windows=None) -> dict:
    """The success played at 10 kHz: ratios to the limits, spacing, consistency, peaks."""
    tr, ver = res.trajectory, res.verification
    lim = model.limits
    p = played.play(model, tr['t'], tr['q'], tr['qd'], tr['qdd'], stride=2)
    ts = p.stamps
    out = {
        'points': int(ts.size), 'min_spacing_s': float(np.diff(ts).min()),
        'consistent_full_tolerance': worst_inconsistency(ts, tr['q'], tr['qd'], tr['qdd'])
        is None,
        'joint_speed_ratio': float((np.abs(p.qd).max(axis=0) / lim.velocity).max()),
        'torque_ratio': float((np.abs(p.tau).max(axis=0) / lim.torque).max()),
        'joint_accel_peak_rad_s2': float(np.abs(p.qdd).max()),
        # reported - played peak torque, as a share of the torque limit (worst joint)
        'reported_vs_played_torque': float(np.max(np.abs(ver.peak_torque - np.abs(p.tau).max(
            axis=0)) / lim.torque)),
        'energy_j': float(res.evaluation.energy),
    }
    # smoothness as played (independent player's samples, 10 kHz / stride 2)
    dt = np.diff(p.t)
    jerk = np.abs(np.diff(p.qdd, axis=0)) / dt[:, None]
    ti = p.t[p.idx]
    rigid = p.tau - model.friction.torque(p.qd[p.idx])
    rate = np.abs(np.diff(rigid, axis=0)) / np.diff(ti)[:, None]
    # the twin intervals around a blend end's curvature jump: reported apart
    out_j, out_r = np.ones(jerk.shape[0], bool), np.ones(rate.shape[0], bool)
    for lo, hi in (() if windows is None else windows):
        out_j &= ~((p.t[1:] > lo) & (p.t[:-1] < hi))
        out_r &= ~((ti[1:] > lo) & (ti[:-1] < hi))
    if not out_j.all():
        out['blend_end_joint_jerk_peak'] = float(jerk[~out_j].max())
        out['blend_end_torque_rate_peak'] = float(rate[~out_r].max())
    jerk, rate = jerk[out_j], rate[out_r]
    out['joint_jerk_peak'] = jerk.max(axis=0).tolist()
    out['torque_rate_peak'] = rate.max(axis=0).tolist()
    out['tcp_jerk_peak'] = float(ver.tcp_jerk_peak)
    if smooth is not None:
        out['joint_jerk_ratio'] = float((jerk.max(axis=0) / smooth.jerk).max())
        out['torque_rate_ratio'] = float((rate.max(axis=0) / smooth.torque_rate).max())
        out['tcp_jerk_ratio'] = float(ver.tcp_jerk_peak / smooth.tcp_jerk)
    if req.tcp_accel_max > 0:
        out['tcp_accel_ratio'] = float(p.tcp_accel.max() / req.tcp_accel_max)
        out['reported_vs_played_tcp_accel'] = float(
            abs(ver.tcp_accel_peak - p.tcp_accel.max()) / p.tcp_accel.max())
    if req.tcp_speed_max > 0:
        out['tcp_speed_ratio'] = float(p.tcp_speed.max() / req.tcp_speed_max)
    # torque steps between control samples, the holding torque before and after included
    c = played.play(model, tr['t'], tr['q'], tr['qd'], tr['qdd'], rate=1 / CONTROL_PERIOD_S)
    zero = np.zeros(3)
    hold = [model.inverse_dynamics(tr['q'][k], zero, zero) for k in (0, -1)]
    rest = req.boundary != 'periodic'
    tau = np.vstack([hold[0], c.tau, hold[1]]) if rest else c.tau
    steps = np.abs(np.diff(tau, axis=0))
    out['torque_step_nm'] = float(steps.max())
    out['torque_step_at_ends_nm'] = float(max(steps[0].max(), steps[-1].max())) if rest \
        else 0.0
    # the same without friction (its Coulomb level switches on when a joint starts to move,
    # whatever the plan)
    rig = c.tau - model.friction.torque(c.qd[c.idx])
    rig = np.vstack([hold[0], rig, hold[1]]) if rest else rig
    rsteps = np.abs(np.diff(rig, axis=0))
    out['rigid_torque_step_nm'] = float(rsteps.max())
    out['rigid_torque_step_at_ends_nm'] = float(max(rsteps[0].max(), rsteps[-1].max())) \
        if rest else 0.0
    return out


def band_for(req: PlanRequest, res, rng) -> dict:
    """Process constraints a motion of this duration can keep: the floor at half and the
    ceiling at twice the mean TCP speed, |a| <= uniform [1, 4] m/s^2 but at least twice
    the centripetal acceleration at the floor in the tightest bend (else the request is
    refused by its certificate, which is not what this measures), default ramps or 20 % of
    a short path."""
    path = request_path(req)
    length = path.length
    mean = length / res.evaluation.duration
    th = np.linspace(0.0, 2 * np.pi, 2001)
    kappa = float(np.max(np.linalg.norm(path.dd_point(th), axis=1)
                         / np.sum(path.d_point(th) ** 2, axis=1)))
    vmin = 0.5 * mean
    amax = max(float(rng.uniform(1.0, 4.0)), 2.0 * vmin ** 2 * kappa)
    ramp = min(vmin ** 2 / amax, 0.2 * length)
    return dict(tcp_speed_min=vmin, tcp_speed_max=2.0 * mean, tcp_accel_max=amax,
                tcp_ramp_length=ramp)


def periodic_vs_rest(planner, rng, count: int) -> list:
    """Closed splines planned at rest and periodic at the same duration: wall and CPU time."""
    rows = []
    while len(rows) < count:
        req = draw('spline', rng)
        req = replace(req, closed=True)
        try:
            t_min = planner.plan(replace(req, objective='time')).min_duration
        except PlanError:
            continue
        row = {}
        for b in ('rest', 'periodic'):        # each from scratch: problem built, T_min solved
            with planner._cache_lock:
                planner._cache.clear()
            r = replace(req, duration=1.5 * t_min, boundary='' if b == 'rest' else b)
            w, c = time.perf_counter(), time.process_time()
            try:
                planner.plan(r)
                ok = True
            except PlanError as exc:
                ok = exc.message[:200]
            row[b] = {'wall_s': time.perf_counter() - w, 'cpu_s': time.process_time() - c,
                      'ok': ok}
        rows.append(row)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--n', '--count', dest='count', type=int, default=200,
                    help='random requests (path draws)')
    ap.add_argument('--grid', type=int, default=60)
    ap.add_argument('--seed', type=int, default=28)
    ap.add_argument('--periodic', type=int, default=2, help='closed splines, rest/periodic')
    ap.add_argument('--name', default='smooth_jerk')
    ap.add_argument('--resume', action='store_true',
                    help='continue results/<name>.json (same seed and grid) after its last '
                         'draw: its rows, refusals and random state are read back')
    a = ap.parse_args()
    planner = Planner(settings=PlannerSettings(grid_size=a.grid, cache_size=2))
    plain = Planner(settings=PlannerSettings(grid_size=a.grid, cache_size=2,
                                             jerk_limits=False))
    smooth = planner.smooth_limits
    model = planner.model
    rng = np.random.default_rng(a.seed)
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    rows, refusals, unreachable, costs = [], [], 0, []
    start, periodic, runs = 0, None, []
    if a.resume:
        old_path = RESULTS / f'{a.name}.json'
        if not old_path.is_file():
            sys.exit(f'--resume: no {old_path}')
        old = json.loads(old_path.read_text())
        if old.get('seed') != a.seed or old.get('grid') != a.grid or 'rng_state' not in old:
            sys.exit(f'--resume: {old_path} has another seed or grid, or no random state')
        rows, refusals, costs = old['rows'], old['refusals'], old['energy_pairs']
        unreachable, start, periodic = (old['unreachable_redraws'], old['done'],
                                        old['periodic_closed_spline_vs_rest'])
        runs = old.get('runs', [])
        rng.bit_generator.state = old['rng_state']
        print(f'resuming {old_path} after draw {start}', file=sys.stderr)

    def worst(key, sel=lambda r: True):
        vals = [r[key] for r in rows if key in r and sel(r)]
        return max(vals) if vals else None

    def med(key, sel=lambda r: True):
        vals = [r[key] for r in rows if key in r and sel(r)]
        return float(np.median(vals)) if vals else None

    def write(done: int, partial: bool, periodic=None):
        on = lambda r: r.get('jerk', True)            # noqa: E731
        off = lambda r: not r.get('jerk', True)       # noqa: E731
        cost = [c['cost'] for c in costs]
        summary = {
            'settings': {'joint_jerk_limit_rad_s3': list(smooth.jerk),
                         'tcp_jerk_limit_m_s3': smooth.tcp_jerk,
                         'torque_rate_limit_nm_s': list(smooth.torque_rate)},
            'worst_played_over_limit': {k: worst(k, on) for k in (
                'joint_speed_ratio', 'torque_ratio', 'tcp_accel_ratio', 'tcp_speed_ratio',
                'joint_jerk_ratio', 'tcp_jerk_ratio', 'torque_rate_ratio')},
            'smallest_point_spacing_s': min(r['min_spacing_s'] for r in rows if on(r))
            if rows else None,
            'all_consistent_full_tolerance': all(r['consistent_full_tolerance'] for r in rows),
            'worst_reported_vs_played': {'torque': worst('reported_vs_played_torque', on),
                                         'tcp_accel': worst('reported_vs_played_tcp_accel',
                                                            on)},
            'torque_step_nm_with_jerk_limit': {
                'largest': worst('torque_step_nm', on),
                'largest_rigid': worst('rigid_torque_step_nm', on),
                'largest_rigid_at_rest_ends': worst('rigid_torque_step_at_ends_nm', on),
                'median': med('torque_step_nm', on)},
            'torque_step_nm_without': {
                'largest': worst('torque_step_nm', off),
                'largest_rigid': worst('rigid_torque_step_nm', off),
                'largest_rigid_at_rest_ends': worst('rigid_torque_step_at_ends_nm', off),
                'median': med('torque_step_nm', off)},
            'energy_cost_of_jerk_limit': {
                'pairs': len(cost), 'median': float(np.median(cost)) if cost else None,
                'worst': float(np.max(cost)) if cost else None,
                'best': float(np.min(cost)) if cost else None},
        }
        dump(a.name, {
            'command': ' '.join(sys.argv), 'count': a.count, 'done': done, 'partial': partial,
            'grid': a.grid, 'seed': a.seed, 'plans': len(rows), 'refusals': refusals,
            'unreachable_redraws': unreachable, 'summary': summary,
            'periodic_closed_spline_vs_rest': periodic, 'energy_pairs': costs,
            'wall_s': time.perf_counter() - t0, 'load_start': load0,
            'load_end': os.getloadavg(), 'rng_state': rng.bit_generator.state,
            'runs': runs + [{'from_draw': start, 'to_draw': done,
                             'wall_s': time.perf_counter() - t0, 'load_start': load0,
                             'load_end': os.getloadavg()}],
            'rows': rows})

    if not a.resume:          # first: in every partial JSON
        periodic = periodic_vs_rest(planner, rng, a.periodic)
    for i in range(start, a.count):
        kind = TYPES[i % len(TYPES)]
        while True:
            req = draw(kind, rng)
            try:
                opt = planner.plan(replace(req, objective='time'))
                break
            except PlanError as exc:
                if exc.code == ERROR_UNREACHABLE or 'unreachable' in exc.message:
                    unreachable += 1
                    continue
                refusals.append({'type': kind, 'objective': 'time', 'code': exc.code,
                                 'message': exc.message[:300]})
                opt = None
                break
        if opt is not None:
            rows.append({'type': kind, 'objective': 'time', 'process': False, 'jerk': True,
                         **analyse(model, opt, opt.request, smooth,
                                   planner._blend_windows(opt.profile, request_path(req)))})
            T = float(rng.uniform(1.2, 2.5)) * opt.min_duration
            req = replace(req, duration=T)
            process = i % 2 == 1
            if process:
                req = replace(req, **band_for(req, opt, rng))
            pair = {}
            for jerk, pl in ((True, planner), (False, plain)):
                try:
                    w = time.perf_counter()
                    res = pl.plan(req)
                    rows.append({'type': kind, 'objective': 'energy', 'process': process,
                                 'jerk': jerk, 'plan_wall_s': time.perf_counter() - w,
                                 # the plan's own report (limit_cost, on by default)
                                 **({'limit_cost_reported': res.limit_cost.cost,
                                     'limit_cost_solve_s': res.limit_cost.solve_time}
                                    if res.limit_cost is not None else {}),
                                 **analyse(model, res, req, smooth if jerk else None,
                                           pl._blend_windows(res.profile,
                                                             request_path(req)))})
                    pair[jerk] = res.evaluation.energy
                except PlanError as exc:
                    refusals.append({'type': kind, 'objective': 'energy', 'process': process,
                                     'jerk': jerk, 'code': exc.code,
                                     'message': exc.message[:300]})
            if len(pair) == 2:
                costs.append({'type': kind, 'process': process, 'energy_on_j': pair[True],
                              'energy_off_j': pair[False],
                              'cost': pair[True] / pair[False] - 1.0})
        print(f'{i + 1}/{a.count} {kind} done ({len(rows)} plans, {len(refusals)} refused)',
              file=sys.stderr)
        write(i + 1, True, periodic)            # after every draw: --resume loses none
    write(a.count, False, periodic)


if __name__ == '__main__':
    main()
