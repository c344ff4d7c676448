"""Benchmark: the trajectory-agnostic fit on 1 h of 1 kHz data (target <= 5 s).

    python ros2_ws/src/irb_identification/benchmarks/bench_fit_log.py [--hours 1] [--repeat 5]

Generates a friction log of continuous motion (sums of sines, no holds) with known friction
(asymmetric Coulomb, offset, Stribeck, viscous), 0.05 N m noise and 0.2 % outlier spikes, and
times ``sample_fit.fit_samples`` on it (wall and CPU time, every repeat; median and spread),
plus the pipeline's sweep detection that `identify --method auto` runs first. Prints JSON and
writes it to benchmarks/results/fit_log_<hours>h.json with the load average.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from irb_identification.pipeline import PipelineConfig, identify_joints
from irb_identification.sample_fit import fit_samples
from irb_identification.series import JointSeries

HERE = Path(__file__).resolve().parent
TRUTH = dict(offset=0.3, coulomb_positive=2.1, coulomb_negative=1.8, static=2.8,
             stribeck_velocity=0.06, viscous=1.2)


def make_log(hours: float, rate_hz: float = 1000.0, seed: int = 1):
    rng = np.random.default_rng(seed)
    n = int(hours * 3600 * rate_hz)
    t = np.arange(n) / rate_hz
    v = np.zeros(n)
    for amp, f in ((0.6, 0.05), (0.3, 0.13), (0.15, 0.31), (0.05, 0.9)):
        v += amp * np.sin(2 * np.pi * f * t + rng.uniform(0, 6))
    p = TRUTH
    e = np.exp(-(v / p['stribeck_velocity']) ** 2)
    tau = p['offset'] + p['viscous'] * v + np.where(
        v > 0, p['coulomb_positive'] * (1 - e) + p['static'] * e,
        -(p['coulomb_negative'] * (1 - e) + p['static'] * e))
    tau += 0.05 * rng.standard_normal(n)
    spikes = rng.random(n) < 0.002
    tau[spikes] += 5 * rng.standard_normal(spikes.sum())
    return t, v + 0.002 * rng.standard_normal(n), tau


def main(args=None):
    ap = argparse.ArgumentParser()
    ap.add_argument('--hours', type=float, default=1.0)
    ap.add_argument('--repeat', type=int, default=5)
    ap.add_argument('--out', default=None)
    opts = ap.parse_args(args)
    t, v, tau = make_log(opts.hours)
    walls, cpus = [], []
    for _ in range(opts.repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        fit = fit_samples(t, v, tau, 'bench')
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    series = JointSeries(t, ('bench',), np.cumsum(v)[:, None] * 1e-3, v[:, None], tau[:, None])
    w0 = time.perf_counter()
    res = identify_joints([series], ['log'], ['friction'], config=PipelineConfig())[0]
    auto_s = time.perf_counter() - w0
    errors = {k: getattr(fit, k) - TRUTH[k] for k in TRUTH}
    out = {
        'benchmark': 'sample_fit_1kHz', 'hours': opts.hours, 'samples': len(t),
        'fit_wall_s_median': round(float(np.median(walls)), 3),
        'fit_wall_s_min_max': [round(min(walls), 3), round(max(walls), 3)],
        'fit_cpu_s_median': round(float(np.median(cpus)), 3),
        'fit_wall_s_all': [round(x, 3) for x in walls],
        'identify_auto_pipeline_s': round(auto_s, 3), 'auto_method': res.method,
        'target_s': 5.0, 'pass': float(np.median(walls)) <= 5.0,
        'errors_vs_truth': {k: float(f'{x:.3g}') for k, x in errors.items()},
        'ci95': {k: float(f'{x:.3g}') for k, x in fit.ci95.items()},
        'load_average_1_5_15': list(os.getloadavg()),
        'machine': {'python': platform.python_version(), 'cpus': os.cpu_count(),
                    'processor': platform.machine(),
                    'openblas_threads': os.environ.get('OPENBLAS_NUM_THREADS', 'default')},
    }
    path = Path(opts.out) if opts.out else HERE / 'results' / f'fit_log_{opts.hours:g}h.json'
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=2) + '\n')
    print(json.dumps(out, indent=2))
    return out


if __name__ == '__main__':
    main()
