"""Benchmark: the bounded friction fit against an independent bounded fit, and its speed.

    python ros2_ws/src/irb_identification/benchmarks/bench_fit_constrained.py [--repeat 3]
        [--hours 1]

1. On every generated log of test/test_fit_constrained.py (top speed 0.005 rad/s, friction
   decreasing over the whole range, offset + asymmetry, coloured noise, irregular stamps,
   inertia residue): the map's RMS (identify's samples path, as the controller evaluates the
   map) and the RMS of the chosen parametric form and of the richest one, each divided by
   the RMS of scipy.optimize.least_squares with bounds on the same samples (the test's
   independent fit); the chosen model, the candidates' held-out RMS, the fit's time.
2. ``--hours`` of 1 kHz data (bench_fit_log.make_log: asymmetric Coulomb, offset, Stribeck,
   viscous, noise, spikes): wall and CPU time of ``sample_fit.fit_samples`` (median and
   spread over ``--repeat``; target <= 5 s per hour).

Prints JSON and writes benchmarks/results/fit_constrained.json with the load average.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def _load(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main(args=None):
    ap = argparse.ArgumentParser()
    ap.add_argument('--repeat', type=int, default=3)
    ap.add_argument('--hours', type=float, default=1.0)
    ap.add_argument('--out', default=str(HERE / 'results' / 'fit_constrained.json'))
    opts = ap.parse_args(args)
    from irb_identification.sample_fit import fit_samples
    tc = _load(HERE.parent / 'test' / 'test_fit_constrained.py', 'tfc')
    load0 = list(os.getloadavg())
    cases = {}
    for name, kw in tc.CASES.items():
        t, v, tau = tc.make_log(**kw)
        c0 = time.process_time()
        r = tc._identify(t, v, tau)
        cpu = time.process_time() - c0
        fit = r.sample
        use = np.abs(v) >= fit.v_min
        vv, yy = v[use], tau[use]
        lo, hi = fit.valid_range
        rms_map = float(np.sqrt(np.mean((yy - r.friction.torque(vv)) ** 2)))
        entry = {'samples': int(len(t)), 'samples_used': int(use.sum()),
                 'top_speed_rad_s': float(np.quantile(np.abs(v), 0.999)),
                 'v_min_rad_s': fit.v_min, 'model': fit.model,
                 'parametric_model': fit.parametric_model, 'degenerate': bool(r.degenerate),
                 'heldout_rms': {m: round(c['heldout_rms'], 6)
                                 for m, c in fit.candidates.items()},
                 'rms_map': rms_map, 'fit_cpu_s': round(cpu, 3), 'bounds_active':
                 fit.bounds_active}
        for form in dict.fromkeys([fit.parametric_model, 'asymmetric_stribeck']):
            c0 = time.process_time()
            rms_ind, _ = tc.independent_fit(vv, yy, form, lo, hi)
            entry[f'independent_{form}'] = {
                'rms': rms_ind, 'ours_rms': fit.candidates[form]['rms'],
                'ratio_ours_to_independent': fit.candidates[form]['rms'] / rms_ind,
                'cpu_s': round(time.process_time() - c0, 3)}
        entry['ratio_map_to_independent'] = rms_map / entry[
            f'independent_{fit.parametric_model}']['rms']
        cases[name] = entry
        print(f'{name}: map/independent {entry["ratio_map_to_independent"]:.5f}, model '
              f'{fit.model}', file=sys.stderr)
    from bench_fit_log import make_log
    t, v, tau = make_log(opts.hours)
    walls, cpus = [], []
    for _ in range(opts.repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        fit = fit_samples(t, v, tau, 'bench')
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    ratios = [c['ratio_map_to_independent'] for c in cases.values()]
    out = {
        'benchmark': 'fit_constrained', 'cases': cases,
        'ratio_map_to_independent_max': max(ratios),
        'all_within_2_percent': bool(max(ratios) <= 1.02),
        'long_log': {'hours': opts.hours, 'samples': int(len(t)), 'model': fit.model,
                     'wall_s_median': round(float(np.median(walls)), 3),
                     'wall_s_min_max': [round(min(walls), 3), round(max(walls), 3)],
                     'cpu_s_median': round(float(np.median(cpus)), 3),
                     'cpu_s_all': [round(x, 3) for x in cpus],
                     'target_s': 5.0 * opts.hours,
                     'pass_cpu': bool(np.median(cpus) <= 5.0 * opts.hours),
                     'pass_wall': bool(np.median(walls) <= 5.0 * opts.hours)},
        'load_average_1_5_15_start': load0, 'load_average_1_5_15_end': list(os.getloadavg()),
        'machine': {'python': platform.python_version(), 'cpus': os.cpu_count(),
                    'processor': platform.machine()},
    }
    text = json.dumps(out, indent=2)
    print(text)
    Path(opts.out).parent.mkdir(parents=True, exist_ok=True)
    Path(opts.out).write_text(text + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
