"""Work cycles with power modes (issue 29, items 3 and 5, offline on the electrical model).

Sections (all by default; ``--section`` to pick):
  gluing   the main job's gluing cycle (config/cycle_gluing.yaml: the tilted rectangle, a move
           to the part-exchange pose, a 6 s part exchange, a wait, the move back) at its takt:
           the plan against baseline A (time-optimal motions, motors hold while waiting) and
           baseline B (durations chosen by the same DP, motors hold), per cycle and per year;
           the saving's ceiling at this takt and the mode parameter that sets it;
  sweep    energy per cycle against the takt for the three (same fronts, DP per takt);
  tornado  the saving's sensitivity to each mode parameter over a plausible range;
  ten      a cycle of 10 operations (benchmarks/cycle_ten.yaml): wall time of the planning,
           cold (empty front cache, --jobs processes; --cold-runs of them, median) and warm
           (fronts cached), with the load and the CPU seconds of every front (the figure a
           shared machine's load does not inflate); under --ten-key (default 'ten').
Prints JSON and writes results/cycle.json (sections not run keep their last results); PNGs
to results/ (cycle_*.png).

    python ros2_ws/src/irb_planning/benchmarks/bench_cycle.py [--cache DIR] [--jobs 2]
        [--section ten --cold-runs 3 --ten-key ten_<name>]
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import RESULTS, dump  # noqa: E402
from irb_planning.cycle_study import (plot_sweep, plot_tornado, section_gluing,  # noqa: E402
                                      section_sweep, section_tornado)

PKG = HERE.parent
GLUING = PKG / 'config' / 'cycle_gluing.yaml'
TEN = HERE / 'cycle_ten.yaml'
SECTIONS = ('gluing', 'sweep', 'tornado', 'ten')
GOAL_TEN_S = 30.0           # [s] issue 29: a cycle of 10 operations planned in <= 30 s

def load_text() -> str:
    try:
        return ' '.join(f'{x:.2f}' for x in os.getloadavg())
    except OSError:
        return 'n/a'


def make_planner(spec, **overrides):
    from irb_planning.cycle import front_settings
    from irb_planning.planner import Planner
    return Planner(settings=front_settings(spec, play_rate_hz=1000.0,
                                           evaluation_rate_hz=1000.0, **overrides))


def section_ten(cache_root: Path, jobs: int, cold: bool, cold_runs: int = 1,
                front_points: int = 0, mumps_permuting_scaling: int | None = None) -> dict:
    from dataclasses import replace
    from irb_planning.cycle import load_cycle, plan_cycle
    spec = load_cycle(TEN)
    if front_points:
        spec = replace(spec, front_points=front_points)
    over = ({} if mumps_permuting_scaling is None
            else {'mumps_permuting_scaling': mumps_permuting_scaling})
    out = {'operations': len(spec.operations), 'motions': len(spec.motions), 'jobs': jobs,
           'takt_s': spec.takt_s, 'front_points': spec.front_points,
           'mumps_permuting_scaling': make_planner(spec, **over).settings.mumps_permuting_scaling}
    cache = cache_root / 'ten'
    runs = []
    for k in range(cold_runs if cold else 0):
        cold_dir = Path(tempfile.mkdtemp(prefix='cycle_ten_cold_'))
        runs.append(('cold' if k == 0 else f'cold_{k + 1}', cold_dir, jobs))
    runs.append(('warm', cache, 1))
    for tag, cdir, j in runs:
        load0 = load_text()
        t0 = time.perf_counter()
        cpu0 = time.process_time()
        plan = plan_cycle(spec, make_planner(spec, **over), cache_dir=cdir,
                          progress=lambda s: print(s, file=sys.stderr, flush=True), jobs=j)
        wall = time.perf_counter() - t0
        procs = {}              # per planning process: its fronts' CPU, its whole CPU
        for f in plan.fronts.values():
            pr = procs.setdefault(f.pid, {'fronts': [], 'fronts_cpu_s': 0.0,
                                          'process_cpu_s': 0.0})
            pr['fronts'].append(f.name)
            pr['fronts_cpu_s'] += f.cpu_s
            pr['process_cpu_s'] = max(pr['process_cpu_s'], f.process_cpu_s)
        # CPU: this process, and the fronts' planning in whichever process planned them
        # (the machine is shared: CPU seconds are the figure load does not inflate)
        out[tag] = {'wall_s': wall, 'front_s': plan.front_time_s,
                    'cpu_main_s': time.process_time() - cpu0,
                    'cpu_fronts_s': float(sum(f.cpu_s for f in plan.fronts.values())),
                    'front_cpu_s': {k: f.cpu_s for k, f in plan.fronts.items()},
                    # the busier process's CPU bounds the wall on 2 free cores (with --jobs 1
                    # it is this process, started before the clock: its process CPU is not
                    # the run's)
                    'processes': list(procs.values()),
                    'busier_process_cpu_s': max(p['process_cpu_s'] for p in procs.values()),
                    'dp_s': plan.solution.solve_time_s, 'load_before': load0,
                    'load_after': load_text(), 'jobs': j, 'energy_j': plan.solution.total_j,
                    'gap_percent': 100 * plan.solution.gap_rel,
                    'saving_vs_a_percent': 100 * (1 - plan.solution.total_j
                                                  / plan.baseline_a['total_j']),
                    'goal_s': GOAL_TEN_S, 'goal_met': bool(wall <= GOAL_TEN_S)}
        if tag.startswith('cold'):
            shutil.copytree(cdir, cache, dirs_exist_ok=True)
            shutil.rmtree(cdir, ignore_errors=True)
    colds = [v for k, v in out.items() if k.startswith('cold')]
    if colds:
        out['cold_wall_median_s'] = float(np.median([v['wall_s'] for v in colds]))
        out['cold_cpu_median_s'] = float(np.median([v['cpu_fronts_s'] + v['cpu_main_s']
                                                    for v in colds]))
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--section', nargs='+', choices=SECTIONS, default=list(SECTIONS))
    p.add_argument('--cache', default=str(Path(tempfile.gettempdir()) / 'irb_cycle_fronts'),
                   help='front cache directory (kept between runs)')
    p.add_argument('--jobs', type=int, default=2, help='processes for the cold fronts')
    p.add_argument('--no-cold', action='store_true',
                   help='ten: skip the cold run (empty cache)')
    p.add_argument('--cold-runs', type=int, default=1,
                   help='ten: cold runs, each with an empty cache (median reported)')
    p.add_argument('--front-points', type=int, default=0,
                   help="ten: front points per motion instead of cycle_ten.yaml's")
    p.add_argument('--mumps-permuting-scaling', type=int, default=None,
                   help="ten: IPOPT's mumps_permuting_scaling for the fronts instead of "
                        "cycle.FRONT_MUMPS_PERMUTING_SCALING (-1: IPOPT's default, for A/B)")
    p.add_argument('--ten-key', default='ten',
                   help='ten: the key of results/cycle.json its figures go to (another key '
                        'keeps the last ones beside them)')
    p.add_argument('--takts', type=float, nargs=3, default=[14.0, 120.0, 1.0],
                   metavar=('FROM', 'TO', 'STEP'), help='sweep [s]')
    a = p.parse_args(argv)
    import yaml
    from irb_planning.cycle import load_cycle, plan_cycle
    cache = Path(a.cache)
    result = {'load_start': load_text(), 'cpus': os.cpu_count()}
    RESULTS.mkdir(exist_ok=True)
    if {'gluing', 'sweep', 'tornado'} & set(a.section):
        spec = load_cycle(GLUING)
        duty = yaml.safe_load(GLUING.read_text())['duty']
        t0 = time.perf_counter()
        plan = plan_cycle(spec, make_planner(spec), cache_dir=cache / 'gluing',
                          progress=lambda s: print(s, file=sys.stderr, flush=True),
                          jobs=a.jobs)
        result['gluing_plan_wall_s'] = time.perf_counter() - t0
        takt = spec.takt_s
        if 'gluing' in a.section:
            result['gluing'] = section_gluing(plan, duty)
            from irb_planning.cycle_plot import plot_fronts, plot_timeline
            plot_timeline(plan, RESULTS / 'cycle_timeline.png')
            plot_fronts(plan, RESULTS / 'cycle_fronts.png')
        if 'sweep' in a.section:
            lo, hi, st = a.takts
            result['sweep'] = section_sweep(plan, list(np.arange(lo, hi + 1e-9, st)))
            plot_sweep(result['sweep'], takt, RESULTS / 'cycle_energy_vs_takt.png')
        if 'tornado' in a.section:
            result['tornado'] = section_tornado(plan, takt)
            plot_tornado(result['tornado'], RESULTS / 'cycle_tornado.png')
    if 'ten' in a.section:
        result[a.ten_key] = section_ten(cache, a.jobs, not a.no_cold, a.cold_runs,
                                        a.front_points, a.mumps_permuting_scaling)
    result['load_end'] = load_text()
    old = RESULTS / 'cycle.json'          # keep what this run did not measure again
    if old.is_file():
        import json
        kept = json.loads(old.read_text())
        for key, value in kept.items():
            result.setdefault(key, value)
    if 'ten' in a.section:
        result[f'{a.ten_key}_load'] = [result['load_start'], result['load_end']]
    dump('cycle', result)
    return 0


if __name__ == '__main__':
    sys.exit(main())
