"""`ros2 run irb_bringup report --bag BAG [--plan FILE] [--out DIR]`: a report of any run.

Writes DIR/report.md with PNGs and summary.json: planned against measured TCP path, path
error along the path (camera and measured joints, the camera's noise floor marked), joint
tracking errors, commanded against measured torque, controller modes and TCP speed over
time, mechanical and electrical energy. BAG: a bag of the `recorder` (or of the main job;
its `<bag>_drive` sibling is read too). FILE: the plan file `plan` writes beside its plot
(plan.json), or a path YAML (what `plan --path-file` reads); default: the plan recorded in
the bag (/planned_path, /planned_trajectory). What the bag lacks is said in the report.
Exit 0 with a report, 1 if the bag or plan cannot be read (one line), 2 on bad arguments.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from irb_description.node_help import own_args


def parse_args(argv):
    p = argparse.ArgumentParser(prog='report', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog='example: ros2 run irb_bringup report --bag '
                                       'bags/my_run --plan plan.json --out runs/my_run')
    p.add_argument('--bag', required=True, help='bag directory (rosbag2 layout, MCAP)')
    p.add_argument('--plan', default='',
                   help="plan file of `plan` (.json) or path YAML; '' = the plan in the bag")
    p.add_argument('--out', default='',
                   help="output folder ('' = runs/report_<bag name> under the working "
                        'directory)')
    p.add_argument('--camera-noise-m', type=float, default=None,
                   help='[m] camera noise per axis for the noise floor (default: the '
                        "simulator's camera_noise_m)")
    p.add_argument('--title', default='', help="report title ('' = from the bag name)")
    return p.parse_args(argv)


def load_plan(name: str):
    """(plan mapping, path, source) of --plan: a plan file or a path YAML."""
    from irb_description.path import load_path_file, path_spec
    from irb_planning.plan_plot import read_plan_file
    if name.endswith('.json'):
        return read_plan_file(name), None, f'plan file {name}'
    path = load_path_file(name)
    return {'path': path_spec(path)}, path, f'path file {name} (no planned timing)'


def main(args=None) -> int:
    argv = own_args(args)
    a = parse_args(argv)
    t_start = time.monotonic()

    def progress(text):
        print(f'[report] {text}', flush=True)

    try:
        import numpy as np
        from irb_control.plant import PlantConfig
        from irb_description.model import RobotModel
        from irb_identification.bagio import BagError

        from .run_analysis import read_run, write_run_report
        plan, path, source = load_plan(a.plan) if a.plan else (None, None, '')
        bag = Path(a.bag)
        progress(f'reading {bag}')
        model = RobotModel.load()
        run = read_run(bag, model.joint_names, plan, source, progress)
        out = Path(a.out) if a.out else Path('runs') / f'report_{bag.resolve().name}'
        sigma = (PlantConfig().camera_noise_m if a.camera_noise_m is None
                 else float(a.camera_noise_m))
        md, f = write_run_report(run, model, out, sigma, a.title or f'Run {bag.name}', path,
                                 progress)
    except (BagError, ValueError, OSError) as exc:
        print(f'report: {exc}', file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 - a damaged bag ends with one line, not a trace
        print(f'report: bag {a.bag} unreadable ({type(exc).__name__}: {exc})', file=sys.stderr)
        return 1
    for s, at, d in run.gaps:
        progress(f'GAP: {s} misses {d:.3f} s from t = {at - run.window[0]:.3f} s')
    for line in f.lines + run.notes:
        progress(f'note: {line}')
    cam = ('' if f.cam_err is None or not f.cam_err.size
           else f', camera path error mean {1e3 * np.mean(f.cam_err):.3f} mm')
    progress(f'{f.duration:.2f} s window, {f.energy:.1f} J mechanical{cam}')
    progress(f'wrote {md} ({time.monotonic() - t_start:.0f} s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
