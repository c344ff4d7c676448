"""identify: friction maps from constant-speed experiment bags (thesis §4.2, eq. 4.8).

    ros2 run irb_identification identify --bag bags/a --bag bags/b --out friction_map.yaml

Offline (no ROS graph needed). Exit code 0: every joint identified; 2: some joints (map has
the others, or all with --fill-nominal); 1: nothing identified or no usable bag.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .bagio import BagError
from .friction_fit import FitConfig, IdentificationError, friction_map, identify_series
from .segments import SegmentConfig
from .series import JointStateError, read_joint_series


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='identify', description=__doc__.split('\n\n')[0])
    p.add_argument('--bag', action='append', required=True, help='bag directory (repeatable)')
    p.add_argument('--out', required=True, help='friction-map YAML to write')
    p.add_argument('--topic', default='/joint_states', help='JointState topic (effort = tau)')
    p.add_argument('--plots', default=None,
                   help='directory for <joint>.png figures (default: next to --out)')
    p.add_argument('--no-plots', action='store_true')
    p.add_argument('--poly-order', type=int, default=7, choices=(0, 5, 6, 7),
                   help='polynomial order per sign, 0 = pick 5-7 by leave-one-out')
    p.add_argument('--min-speeds', type=int, default=4, help='fewest speeds per joint')
    p.add_argument('--model-compensation', action='store_true',
                   help='per-sign points = torque - model M qdd + C qd + g (keeps asymmetry)')
    p.add_argument('--fill-nominal', action='store_true',
                   help='write joints that fail with the nominal friction of irb_description')
    p.add_argument('--effort-lag-s', type=float, default=0.0,
                   help='[s] the effort of a sample is the torque that acted this long before '
                   'it (e.g. 0.002016 = half a period for the mean torque of the period '
                   'before the sample); corrects eq. 4.8 where gravity varies with position')
    p.add_argument('--json', default=None, help='also write a JSON report here')
    return p


def main(args=None) -> int:
    argv = list(sys.argv[1:] if args is None else args)
    if '--ros-args' in argv:
        argv = argv[:argv.index('--ros-args')]
    opts = _parser().parse_args(argv)
    from irb_description.model import RobotModel
    model = RobotModel.load()
    series, labels, problems = [], [], []
    for bag in opts.bag:
        try:
            series.append(read_joint_series(bag, opts.topic))
            labels.append(Path(bag).name)
        except (BagError, JointStateError) as exc:
            problems.append(str(exc))
            print(f'identify: skipping: {exc}', file=sys.stderr)
    if not series:
        print('identify: no usable bag', file=sys.stderr)
        return 1
    config = FitConfig(poly_order=opts.poly_order, min_speeds=opts.min_speeds,
                       segments=SegmentConfig(effort_lag_s=opts.effort_lag_s))
    results = identify_series(series, model.joint_names, config,
                              model=model if opts.model_compensation else None, labels=labels)
    source = 'identified from ' + ', '.join(Path(b).name for b in opts.bag)
    try:
        fmap = friction_map(results, source, model.friction if opts.fill_nominal else None)
    except IdentificationError as exc:
        print(f'identify: {exc}', file=sys.stderr)
        return 1
    out = Path(opts.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fmap.save(out)
    report = {'out': str(out), 'bags': opts.bag, 'problems': problems,
              'effort_lag_s': opts.effort_lag_s, 'joints': {}}
    plot_dir = None if opts.no_plots else Path(opts.plots) if opts.plots else out.parent
    for r in results:
        entry = {'speeds': len(r.points), 'error': r.error, 'warnings': r.warnings,
                 'rejected_segments': [{'bag': label, 'speed_rad_s': x.speed,
                                        't_start_s': x.t_start, 't_end_s': x.t_end,
                                        'reason': x.reason} for label, x in r.rejected]}
        if r.parametric is not None:
            pf = r.parametric
            entry.update(coulomb=pf.coulomb, static=pf.static,
                         stribeck_velocity=pf.stribeck_velocity, viscous=pf.viscous,
                         ci95=pf.ci95, rmse=pf.rmse, valid_range=list(r.friction.valid_range))
        if plot_dir is not None:
            from .plots import plot_joint
            plot_dir.mkdir(parents=True, exist_ok=True)
            entry['plot'] = str(plot_joint(r, plot_dir / f'{out.stem}_{r.name}.png'))
        report['joints'][r.name] = entry
        status = r.error or (f'F_c {pf.coulomb:.3f} N m, F_v {pf.viscous:.3f} N m s/rad, '
                             f'{len(r.points)} speeds')
        if r.rejected:
            status += f' ({len(r.rejected)} hold(s) rejected: stick-slip signature)'
        print(f'identify: {r.name}: {status}')
        for w in r.warnings:
            print(f'identify: warning: {w}', file=sys.stderr)
    if opts.json:
        Path(opts.json).write_text(json.dumps(report, indent=2))
    print(f'identify: wrote {out}')
    failed = [r.name for r in results if r.error]
    return 2 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
