"""Resident memory of a planner over many mixed requests (the service's workload in one process).

    python ros2_ws/src/irb_planning/benchmarks/bench_memory.py [--requests 1000]

Mix (seeded): 30 % new random circles (energy, 2-15 s), 35 % repeats of the last 20 circles
with any objective (energy, time, trapezoid, Fourier), 15 % the thesis circle at drifting
durations, 5 % the thesis circle at grid 1000 (the largest the default max_grid_size allows),
15 % invalid requests (NaN, direction 0, friction map outside the allowed directories, grid
2000). RSS (/proc/self/status VmRSS) after every request; the planner's defaults
(cache_size 8, memory_limit_mib 450). Goal: <= 500 MiB after 1000 requests.
"""
import argparse
import collections
import sys
import time

import numpy as np
from _common import dump

from irb_planning.planner import Planner, resident_mib
from irb_planning.request import PlanError, PlanRequest


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--requests', type=int, default=1000)
    a = ap.parse_args()
    rss0 = resident_mib()
    planner = Planner()
    rss_planner = resident_mib()
    rng = np.random.default_rng(11)
    circles = []
    outcomes = collections.Counter()
    rss, times = [], []
    t_start = time.perf_counter()
    for i in range(a.requests):
        u = rng.uniform()
        if u < 0.30 or not circles:
            c = dict(center=np.array([rng.uniform(0.4, 0.85), rng.uniform(-0.35, 0.35),
                                      rng.uniform(0.0, 0.7)]),
                     radius=rng.uniform(0.04, 0.25), direction=int(rng.choice([-1, 1])),
                     start_angle=rng.uniform(0, 6.3))
            circles = (circles + [c])[-20:]
            req = PlanRequest(duration=rng.uniform(2, 15), **c)
            kind = 'new circle'
        elif u < 0.65:
            c = circles[rng.integers(len(circles))]
            obj = rng.choice(['energy', 'time', 'trapezoid', 'fourier'])
            kw = dict(objective=str(obj), duration=rng.uniform(2, 15))
            if obj == 'fourier':
                kw['fourier_order'] = int(rng.choice([3, 5, 7]))
            req = PlanRequest(**kw, **c)
            kind = f'repeat {obj}'
        elif u < 0.80:
            req = PlanRequest(duration=rng.uniform(2, 15))
            kind = 'thesis circle'
        elif u < 0.85:
            req = PlanRequest(duration=rng.uniform(2, 15), grid_size=1000)
            kind = 'grid 1000'
        else:
            req = [PlanRequest(radius=float('nan'), duration=3.0),
                   PlanRequest(direction=0, duration=3.0),
                   PlanRequest(friction_map='/etc/hostname', duration=3.0),
                   PlanRequest(grid_size=2000, duration=3.0)][rng.integers(4)]
            kind = 'invalid'
        t0 = time.perf_counter()
        try:
            planner.plan(req)
            outcomes[f'{kind}: solved'] += 1
        except PlanError as exc:
            outcomes[f'{kind}: refused code {exc.code}'] += 1
        times.append(time.perf_counter() - t0)
        rss.append(resident_mib())
        if (i + 1) % 25 == 0:
            print(f'[bench_memory] {i + 1}/{a.requests}: RSS {rss[-1]:.0f} MiB (max '
                  f'{max(rss):.0f}), {len(planner._cache)} problems cached, '
                  f'{time.perf_counter() - t_start:.0f} s', file=sys.stderr, flush=True)
    dump('memory', {
        'requests': a.requests, 'outcomes': dict(sorted(outcomes.items())),
        'rss_mib': {'python_with_imports': rss0, 'fresh_planner': rss_planner,
                    'after_all_requests': rss[-1], 'max': max(rss),
                    'median_last_100': float(np.median(rss[-100:]))},
        'goal_mib': 500.0,
        'rss_every_25_requests_mib': [round(x, 1) for x in rss[24::25]],
        'seconds_per_request': {'median': float(np.median(times)), 'max': float(max(times))},
        'total_s': time.perf_counter() - t_start})


if __name__ == '__main__':
    main()
