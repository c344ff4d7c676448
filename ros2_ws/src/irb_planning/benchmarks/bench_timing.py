"""Solve times at N = 200 (cold incl. construction, warm median) and grid convergence.

    python ros2_ws/src/irb_planning/benchmarks/bench_timing.py

cold: a fresh Planner, first energy request (builds the path data, the NLP, solves the
time-optimal problem, then the energy problem, then the 1 kHz check). warm: 30 requests on the
built problem with durations drifting by up to 5 % per request (solver time only, and the
whole plan() call with the evaluator).

Grid convergence: energy of the plan at N = 200, 400, 1000 at 1.1 T_min, 1, 3, 10 s (the same
duration for every N). The energy of each returned trajectory is taken by the evaluator at
20 kHz, where it has converged (< 0.001 % from 50 kHz): at 1 kHz the evaluator itself is off
by up to 0.13 % at 0.69 s with N = 1000, whose grid intervals (0.7 ms) are shorter than its
sample period. The service's 1 kHz figures are kept beside them (energy_1khz_J).
"""
import time

import numpy as np
from _common import dump

from irb_planning.planner import Planner, PlannerSettings
from irb_planning.request import PlanRequest

CONVERGENCE_RATE_HZ = 20000.0   # evaluator rate for the grid-convergence energies


def main():
    out = {}
    t0 = time.perf_counter()
    planner = Planner(settings=PlannerSettings(grid_size=200))
    t1 = time.perf_counter()
    r = planner.plan(PlanRequest(duration=3.0))
    t2 = time.perf_counter()
    out['cold'] = {'model_load_s': t1 - t0, 'first_plan_incl_build_s': t2 - t1,
                   'energy_solve_s': r.solve_time}
    rng = np.random.default_rng(0)
    T = 3.0
    solve, total, iters = [], [], []
    for _ in range(30):
        T = float(np.clip(T * rng.uniform(0.95, 1.05), 1.0, 10.0))
        a = time.perf_counter()
        r = planner.plan(PlanRequest(duration=T))
        total.append(time.perf_counter() - a)
        solve.append(r.solve_time)
        iters.append(r.iterations)
    out['warm'] = {'median_solve_s': float(np.median(solve)), 'max_solve_s': float(max(solve)),
                   'median_plan_call_s': float(np.median(total)),
                   'median_iterations': float(np.median(iters))}
    conv = {}
    # a planner with a higher iteration cap: at N = 1000 the time-optimal problem (bang-bang
    # theta_ddot) needs ~650 IPOPT iterations
    fine = Planner(settings=PlannerSettings(grid_size=200, max_iterations=2000))
    t_min = fine.plan(PlanRequest(duration=3.0)).min_duration
    for T in (1.1 * t_min, 1.0, 3.0, 10.0):
        es = {}
        for N in (200, 400, 1000):
            rr = fine.plan(PlanRequest(duration=T, grid_size=N))
            es[N] = {'energy_J': fine.evaluate(rr, CONVERGENCE_RATE_HZ).energy,
                     'optimizer_J': rr.optimizer_energy,
                     'energy_1khz_J': rr.evaluation.energy, 'solve_s': rr.solve_time}
        es['change_200_to_1000_pct'] = 100 * (es[200]['energy_J'] / es[1000]['energy_J'] - 1)
        es['change_200_to_1000_at_1khz_pct'] = 100 * (
            es[200]['energy_1khz_J'] / es[1000]['energy_1khz_J'] - 1)
        conv[f'{T:.3f}s'] = es
        print(f'T = {T:.3f} s: N 200 -> 1000 changes E by {es["change_200_to_1000_pct"]:+.3f} %',
              flush=True)
    out['grid_convergence'] = conv
    out['grid_convergence_evaluation_rate_hz'] = CONVERGENCE_RATE_HZ
    dump('timing', out)


if __name__ == '__main__':
    main()
