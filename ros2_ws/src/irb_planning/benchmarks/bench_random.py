"""Random reachable circles, durations and weights: every success executable, every refusal
specific, no failure of a valid request.

    python ros2_ws/src/irb_planning/benchmarks/bench_random.py [--count 500] [--grid 200]

Circles: centre x in [0.35, 0.9], y in [-0.4, 0.4], z in [-0.1, 0.8] m, radius [0.03, 0.3] m,
start angle anywhere (uniform in [0, 2 pi), and one in ten uniform in [-1e6, 1e6] rad), both
directions; circles whose joint motion leaves the workspace or the limits (code 2) are drawn
again until ``count`` reachable ones were planned. Per circle the time-optimal duration T_min
is planned first, then either a fixed duration log-uniform in [1.05 T_min, 60 s] (capped at
the slowest admissible motion) or, one in five, a free duration with a time weight
log-uniform in [1e-9, 10] J/s.

Every success is re-checked here at 5 kHz with 16 samples per segment by the independent check
(verify.py: own time integration, own DH kinematics, quintic playback of the message).
Figures: solved / refused (code, message) / failed (any other code, or a success the re-check
rejects: an "invalid success"), max TCP deviation as played, max time-law error.
"""
import argparse
import collections
import sys
import time

import numpy as np
from _common import dump

from irb_planning import request as rq
from irb_planning.planner import BOUNDARY_REST, Planner, PlannerSettings
from irb_planning.request import PlanError, PlanRequest
from irb_planning.verify import ArmKinematics, Circle, MapFriction, verify_plan


def recheck(planner, res):
    """The success re-checked at 5 kHz, 16 samples per segment."""
    tr, req, pr = res.trajectory, res.request, res.profile
    lim = planner.model.limits
    kin = ArmKinematics(velocity=lim.velocity, torque=lim.torque, **planner._kin)
    fm = planner.model.friction.to_dict()['friction_map']['joints']
    return verify_plan(tr['t'], tr['q'], tr['qd'], tr['qdd'],
                       (pr.theta, pr.theta_dot, pr.theta_ddot_nodes, pr.quadratic),
                       Circle(req.center, req.radius, req.start_angle, req.direction), kin,
                       planner.rigid_torque, MapFriction(fm, planner.model.joint_names),
                       req.boundary == BOUNDARY_REST, rate_hz=5000.0,
                       min_samples_per_segment=16)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--count', type=int, default=500)
    ap.add_argument('--grid', type=int, default=200)
    ap.add_argument('--seed', type=int, default=7)
    ap.add_argument('--name', default='random',
                    help='results/<name>.json (a partial re-run keeps the full one)')
    a = ap.parse_args()
    planner = Planner(settings=PlannerSettings(grid_size=a.grid, cache_size=2))
    rng = np.random.default_rng(a.seed)
    outcomes = collections.Counter()
    failures, refusals, dev, terr, times, rel_err, savings = [], [], [], [], [], [], []
    unreachable = 0
    i = 0
    t_start = time.perf_counter()
    while i < a.count:
        far = rng.uniform() < 0.1
        base = dict(center=np.array([rng.uniform(0.35, 0.9), rng.uniform(-0.4, 0.4),
                                     rng.uniform(-0.1, 0.8)]),
                    radius=rng.uniform(0.03, 0.3),
                    start_angle=rng.uniform(-1e6, 1e6) if far else rng.uniform(0, 2 * np.pi),
                    direction=int(rng.choice([-1, 1])))
        t0 = time.perf_counter()
        try:
            t_min = planner.plan(PlanRequest(objective='time', **base)).min_duration
        except PlanError as exc:
            if exc.code == rq.ERROR_UNREACHABLE:
                unreachable += 1
                continue
            failures.append((i, 'time-optimal', exc.code, exc.message))
            outcomes['failed'] += 1
            i += 1
            continue
        if rng.uniform() < 0.2:
            req = PlanRequest(duration=0.0, time_weight=float(10 ** rng.uniform(-9, 1)), **base)
        else:
            req = PlanRequest(duration=float(np.exp(rng.uniform(np.log(1.05 * t_min),
                                                                np.log(60.0)))), **base)
        try:
            res = planner.plan(req)
            ver = recheck(planner, res)
            dev.append(ver.max_path_deviation)
            terr.append(ver.max_time_error)
            if not ver.ok:
                failures.append((i, 'invalid success', req.duration, ver.problems))
                outcomes['invalid success'] += 1
            else:
                outcomes['solved'] += 1
            rel_err.append(abs(res.optimizer_energy / res.evaluation.energy - 1))
            if res.baseline.ok:
                savings.append(100 * (1 - res.verification.energy / res.baseline.energy))
        except PlanError as exc:
            refusals.append((i, exc.code, req.duration, exc.message))
            # a refusal is right only for a duration beyond the slowest admissible motion
            if exc.code == rq.ERROR_INFEASIBLE_DURATION and 'slowest motion' in exc.message:
                outcomes['refused: longer than the slowest motion'] += 1
            else:
                outcomes[f'failed (code {exc.code})'] += 1
                failures.append((i, 'refused valid', exc.code, req.duration, exc.message))
        times.append(time.perf_counter() - t0)
        i += 1
        if i % 10 == 0:
            print(f'[bench_random] {i}/{a.count} planned ({unreachable} unreachable drawn '
                  f'again), {dict(outcomes)}, {time.perf_counter() - t_start:.0f} s',
                  file=sys.stderr, flush=True)
    dump(a.name, {
        'count': a.count, 'grid': a.grid, 'seed': a.seed, 'outcomes': dict(outcomes),
        'unreachable_circles_redrawn': unreachable,
        'invalid_successes': outcomes['invalid success'],
        'failures': failures, 'refusals': refusals,
        'max_tcp_deviation_as_played_m': float(np.max(dev)) if dev else None,
        'max_time_law_error_rel': float(np.max(terr)) if terr else None,
        'optimizer_vs_evaluator_rel_error': {'median': float(np.median(rel_err)),
                                             'max': float(np.max(rel_err))},
        'saving_vs_feasible_trapezoid_pct': {
            'n': len(savings), 'min': float(np.min(savings)),
            'median': float(np.median(savings)), 'max': float(np.max(savings))},
        'seconds_per_request_incl_time_optimal': {'median': float(np.median(times)),
                                                  'max': float(np.max(times))},
        'total_s': time.perf_counter() - t_start})


if __name__ == '__main__':
    main()
