"""Benchmark: maps from simulated sweeps, sweep (eq. 4.8) and samples methods, vs the plant.

    python ros2_ws/src/irb_identification/benchmarks/bench_fit_sweeps.py \\
        [--base /path/to/an/older/ros2_ws/src]   # also run an older checkout's code

Simulates eq. 4.1 sweeps of joints 1-3 on the offline plant (irb_description's nominal
friction, velocity noise 0.002 rad/s, effort noise 0.5 N m) at 4 speeds (0.05, 0.2, 0.6, 1.2
rad/s) and at profiles.DEFAULT_SPEEDS, identifies them with `--method auto` (sweeps: eq. 4.8)
and `--method samples` (total torque, the model subtracted), and prints per joint the RMS and
the largest error of the map against the plant's friction over the map's valid range. With
``--base`` the same bags are identified by that source tree's irb_identification /
irb_description (for before/after comparisons). Writes results/fit_sweeps.json.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
SETS = {'speeds_4': [0.05, 0.2, 0.6, 1.2], 'default': None}


def make_bags(root: Path) -> None:
    from irb_description.model import RobotModel

    from irb_identification.offline_sim import SimConfig, run_experiments
    from irb_identification.profiles import DEFAULT_SPEEDS
    model = RobotModel.load()
    for name, speeds in SETS.items():
        (root / name).mkdir(parents=True, exist_ok=True)
        run_experiments(model, model.friction, [0, 1, 2], speeds or list(DEFAULT_SPEEDS),
                        root / name, config=SimConfig(velocity_noise=0.002, effort_noise=0.5,
                                                      seed=3), log=lambda s: None)


def evaluate(root: Path) -> dict:
    """Per set/method/joint: method used, RMS and max error [N m] against the plant."""
    import numpy as np
    from irb_description.model import RobotModel

    from irb_identification.pipeline import PipelineConfig, identify_joints
    from irb_identification.series import read_joint_series
    model = RobotModel.load()
    out = {}
    for name in SETS:
        bags = sorted((root / name).iterdir())
        series = [read_joint_series(str(b), '/joint_states') for b in bags]
        for method in ('auto', 'samples'):
            res = identify_joints(series, [b.name for b in bags], ['total'] * len(series),
                                  None, None, model, PipelineConfig(method=method))
            for r in res:
                key = f'{name}/{method}/{r.name}'
                if r.friction is None:
                    out[key] = {'error': r.error}
                    continue
                truth = model.friction.joints[model.joint_names.index(r.name)]
                lo, hi = r.friction.valid_range
                v = np.geomspace(lo, hi, 300)
                v = np.r_[v, -v]
                err = np.abs(r.friction.torque(v) - truth.torque(v))
                out[key] = {'method': r.method, 'rms_err_nm': float(np.sqrt(np.mean(err**2))),
                            'max_err_nm': float(err.max()), 'degenerate': bool(r.degenerate),
                            'coulomb': r.friction.coulomb, 'viscous': r.friction.viscous,
                            'model': getattr(r.sample, 'model', None)}
    return out


def main(args=None):
    ap = argparse.ArgumentParser()
    ap.add_argument('--base', default=None, help='an older ros2_ws/src to compare with')
    ap.add_argument('--evaluate', default=None, help=argparse.SUPPRESS)
    ap.add_argument('--out', default=str(HERE / 'results' / 'fit_sweeps.json'))
    opts = ap.parse_args(args)
    if opts.evaluate:                          # child: evaluate with whatever is on the path
        print(json.dumps(evaluate(Path(opts.evaluate))))
        return 0
    root = Path(tempfile.mkdtemp(prefix='fit_sweeps_'))
    make_bags(root)
    result = {'benchmark': 'fit_sweeps', 'current': evaluate(root),
              'load_average_1_5_15': list(os.getloadavg())}
    if opts.base:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            [str(Path(opts.base) / 'irb_identification'), str(Path(opts.base) / 'irb_description'),
             os.environ.get('PYTHONPATH', '')]))
        res = subprocess.run([sys.executable, __file__, '--evaluate', str(root)], env=env,
                             capture_output=True, text=True, check=True)
        result['base'] = json.loads(res.stdout)
        result['base_source'] = opts.base
    text = json.dumps(result, indent=1)
    print(text)
    Path(opts.out).write_text(text + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
