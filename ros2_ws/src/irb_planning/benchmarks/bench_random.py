"""Random circles and durations: each solved without a limit violation at 1 kHz, or refused.

    python ros2_ws/src/irb_planning/benchmarks/bench_random.py [--count 200] [--grid 200]

Circles: centre x in [0.35, 0.9], y in [-0.4, 0.4], z in [-0.1, 0.8] m, radius [0.03, 0.3] m,
random start angle and direction; duration uniform in [0.5, 10] s. Requests that are refused
must carry UNREACHABLE or INFEASIBLE_DURATION with a message; any other outcome is a failure.
"""
import argparse
import collections
import time

import numpy as np
from _common import dump

from irb_planning import request as rq
from irb_planning.planner import Planner, PlannerSettings
from irb_planning.request import PlanError, PlanRequest


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--count', type=int, default=200)
    ap.add_argument('--grid', type=int, default=200)
    a = ap.parse_args()
    planner = Planner(settings=PlannerSettings(grid_size=a.grid, cache_size=2))
    rng = np.random.default_rng(7)
    outcomes = collections.Counter()
    failures, rel_err, savings, times = [], [], [], []
    for i in range(a.count):
        req = PlanRequest(center=np.array([rng.uniform(0.35, 0.9), rng.uniform(-0.4, 0.4),
                                           rng.uniform(-0.1, 0.8)]),
                          radius=rng.uniform(0.03, 0.3), start_angle=rng.uniform(0, 6.28),
                          direction=int(rng.choice([-1, 1])), duration=rng.uniform(0.5, 10))
        t0 = time.perf_counter()
        try:
            r = planner.plan(req)
            ev = r.evaluation
            if not ev.ok:
                failures.append((i, 'violation', ev.violations))
            rel_err.append(abs(r.optimizer_energy / ev.energy - 1))
            if r.baseline.ok:
                savings.append(100 * (1 - ev.energy / r.baseline.energy))
            outcomes['solved'] += 1
        except PlanError as exc:
            outcomes[f'refused code {exc.code}'] += 1
            if exc.code not in (rq.ERROR_UNREACHABLE, rq.ERROR_INFEASIBLE_DURATION):
                failures.append((i, exc.code, exc.message))
        times.append(time.perf_counter() - t0)
    dump('random', {
        'count': a.count, 'grid': a.grid, 'outcomes': dict(outcomes),
        'failures': failures,
        'optimizer_vs_evaluator_rel_error': {'median': float(np.median(rel_err)),
                                             'max': float(np.max(rel_err))},
        'saving_vs_feasible_trapezoid_pct': {
            'n': len(savings), 'min': float(np.min(savings)),
            'median': float(np.median(savings)), 'max': float(np.max(savings))},
        'seconds_per_request': {'median': float(np.median(times)),
                                'max': float(np.max(times))}})


if __name__ == '__main__':
    main()
