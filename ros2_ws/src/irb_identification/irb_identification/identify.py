"""identify: friction maps from bags of any motion (thesis §4.2 sweeps, or any trajectory).

    ros2 run irb_identification identify --bag bags/a [--bag bags/b] --out friction_map.yaml \\
        [--json report.json] [--method auto|sweep|samples] [--torque-kind auto|friction|total]
        [--joints a,b] [--map-joint BAG_NAME:MODEL_NAME ...]

Offline (no ROS graph needed). ``--bag`` takes a bag, a main-job run bag (its ``_drive``
companion is read with it) or a folder of bags (excite's output). Every joint-state series is
checked against the nominal 4.032 ms period: duplicates are dropped, holds and derivatives
stop at gaps longer than ``--gap-bridge-samples`` missing samples, and the output says what
was missing (``data_quality`` in the JSON, the map's ``source``, one line per series); with
``--gaps refuse`` any gap is an error naming the bag, topic and gap. Exit code 0: every joint
identified with a trusted fit; 2: some joints failed or are marked degenerate (the map says
which, with the reason); 1: nothing identified, no usable bag, a refused gap, or bad names.
``--json`` is written in every case.

Joints 4-6 (issue 30): ``--joints`` naming any of joint_4 .. joint_6 reads the six joints of
/joint_states (also the ones that stood still) and subtracts the six-joint model's rigid-body
torque (irb_description ``SixJointModel``; six_joint.py); ``--complete-from MAP|nominal`` adds
the joints not identified here, so that pdplus ``joints:=6`` can load the map.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import yaml

from irb_description.friction import FrictionMapError
from irb_description.node_help import own_args

from .bagio import BagError
from .friction_fit import (FitConfig, IdentificationError, complete_map, complete_source,
                           friction_map)
from .gaps import ON_GAP, GapConfig, GapError
from .pipeline import (METHODS, PipelineConfig, check_gaps, identify_joints, report_entry,
                       summary_line)
from .readers import expand_bags, read_joint_states
from .sample_fit import SampleFitConfig
from .segments import SegmentConfig
from .series import JointStateError

TORQUE_KIND_KEY = 'irb_identification.torque_kind'
ACCEL_TOPIC = '/joint_accelerations'


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='identify', description=__doc__.split('\n\n')[0])
    p.add_argument('--bag', action='append', required=True, help='bag directory (repeatable)')
    p.add_argument('--out', required=True, help='friction-map YAML to write')
    p.add_argument('--topic', default='/joint_states', help='JointState topic (effort = tau)')
    p.add_argument('--plots', default=None,
                   help='directory for <joint>.png figures (default: next to --out)')
    p.add_argument('--no-plots', action='store_true')
    p.add_argument('--method', default='auto', choices=METHODS,
                   help='sweep = eq. 4.8 on constant-speed holds; samples = fit on every '
                   'sample; auto = sweep when the data are sweeps')
    p.add_argument('--torque-kind', default='auto', choices=('auto', 'friction', 'total'),
                   help='effort is the friction torque or the total joint torque; auto = the '
                   "bag's custom_data (import_log writes it), else total")
    p.add_argument('--joints', default='', help='comma-separated joints to identify '
                   '(names after --map-joint; default all)')
    p.add_argument('--map-joint', action='append', default=[], metavar='BAG_NAME:NAME',
                   help="rename a bag joint (e.g. onto the model's joint_2, for total torque "
                   'and for maps the controller loads); repeatable')
    p.add_argument('--v-min', type=float, default=0.0,
                   help='[rad/s] samples method: absolute floor of the slowest sample used '
                   '(default 0: only --v-min-fraction)')
    p.add_argument('--v-min-fraction', type=float, default=0.02,
                   help='samples method: samples slower than this fraction of the top speed '
                   '(99.9 %% quantile of |v|) are not used (the report says what was used)')
    p.add_argument('--poly-order', type=int, default=7, choices=(0, 5, 6, 7),
                   help='polynomial order per sign, 0 = pick 5-7 by leave-one-out')
    p.add_argument('--min-speeds', type=int, default=4, help='fewest speeds per joint (sweep)')
    p.add_argument('--model-compensation', action='store_true',
                   help='sweep: per-sign points = torque - model M qdd + C qd + g')
    p.add_argument('--fill-nominal', action='store_true',
                   help='write joints that fail with the nominal friction of irb_description')
    p.add_argument('--complete-from', default='', metavar='MAP|nominal',
                   help="add the model's joints not identified here from this friction map "
                   "('nominal' = irb_description's), so that the map has every joint the "
                   'controller loads (e.g. --joints joint_4,joint_5,joint_6 --complete-from '
                   'the joints 1-3 map: a map pdplus joints:=6 reads)')
    p.add_argument('--effort-lag-s', type=float, default=0.0,
                   help='[s] sweep: the effort of a sample is the torque that acted this long '
                   'before it (see README)')
    gaps = GapConfig()
    p.add_argument('--gaps', default=gaps.on_gap, choices=ON_GAP,
                   help='segment: analyse around gaps in the joint states (holds and '
                   'derivatives stop at long gaps; the output says what was missing); '
                   'refuse: any gap is an error naming the bag, topic and gap')
    p.add_argument('--period-s', type=float, default=gaps.period_s,
                   help='[s] nominal sample period the stamps are checked against')
    p.add_argument('--gap-bridge-samples', type=int, default=gaps.bridge_samples,
                   help='[samples] gaps of at most this many missing samples are bridged; '
                   'longer ones end holds and derivatives')
    p.add_argument('--json', default=None, help='also write a JSON report here (always)')
    return p


def bag_torque_kind(bag: str) -> str | None:
    """The torque kind import_log stored in the bag's metadata, or None."""
    try:
        info = yaml.safe_load((Path(bag) / 'metadata.yaml').read_text())
        return (info['rosbag2_bagfile_information'].get('custom_data') or {}).get(
            TORQUE_KIND_KEY)
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        return None


def _read_accel(bag: str):
    from .readers import joint_series, read_topics, topic_sources
    if ACCEL_TOPIC not in topic_sources(bag):
        return None
    msgs, src = read_topics(bag, [ACCEL_TOPIC])
    m = msgs[ACCEL_TOPIC]
    return joint_series(m, src[ACCEL_TOPIC], ('position',)) if m.data else None


def main(args=None) -> int:
    argv = own_args(args)
    opts = _parser().parse_args(argv)
    report = {'out': opts.out, 'bags': opts.bag, 'problems': [], 'joints': {},
              'effort_lag_s': opts.effort_lag_s, 'method_requested': opts.method,
              'ok': False}

    def finish(code: int, message: str | None = None) -> int:
        if message:
            print(f'identify: {message}', file=sys.stderr)
            report['error'] = message
        report['exit_code'] = code
        if opts.json:
            Path(opts.json).parent.mkdir(parents=True, exist_ok=True)
            Path(opts.json).write_text(json.dumps(report, indent=2, default=float))
        return code

    name_map = {}
    for spec in opts.map_joint:
        a, sep, b = spec.partition(':')
        if not sep or not a or not b:
            return finish(1, f'--map-joint {spec!r}: expected BAG_NAME:NAME')
        name_map[a] = b
    try:
        gaps = GapConfig(period_s=opts.period_s, bridge_samples=opts.gap_bridge_samples,
                         on_gap=opts.gaps)
    except ValueError as exc:
        return finish(1, str(exc))
    from .six_joint import SixJointIdentificationModel, uses_wrist
    joints = [j.strip() for j in opts.joints.split(',') if j.strip()]
    six = uses_wrist(joints)     # joint_4 .. joint_6 asked for: the six-joint model
    if six:
        model = SixJointIdentificationModel()
    else:
        from irb_description.model import RobotModel
        model = RobotModel.load()
    report['model_joints'] = list(model.joint_names)
    try:
        base = complete_source(opts.complete_from, model)
    except FrictionMapError as exc:
        return finish(1, f'--complete-from: {exc}')
    series, labels, kinds, accels, bags_read = [], [], [], [], []
    bags = [str(b) for b in expand_bags(opts.bag)]
    report['bags'] = bags
    for bag in bags:
        try:
            s = read_joint_states(bag, opts.topic, keep_locked=six)
            accel = _read_accel(bag)
        except (BagError, JointStateError) as exc:
            report['problems'].append(str(exc))
            print(f'identify: skipping: {exc}', file=sys.stderr)
            continue
        series.append(s)
        labels.append(Path(bag).name)
        bags_read.append(bag)
        kinds.append(opts.torque_kind if opts.torque_kind != 'auto'
                     else bag_torque_kind(bag) or 'total')
        accels.append(accel)
    report['torque_kinds'] = dict(zip(labels, kinds))
    if not series:
        return finish(1, 'no usable bag: ' + '; '.join(report['problems']))
    config = PipelineConfig(
        method=opts.method,
        fit=FitConfig(poly_order=opts.poly_order, min_speeds=opts.min_speeds,
                      segments=SegmentConfig(effort_lag_s=opts.effort_lag_s,
                                             split_gap_s=gaps.split_s())),
        samples=SampleFitConfig(v_min=opts.v_min, v_min_fraction=opts.v_min_fraction),
        gaps=gaps)
    try:
        series, checks = check_gaps(series, bags_read, gaps, opts.topic)
    except GapError as exc:
        return finish(1, str(exc))
    report['complete_data'] = all(c.clean for c in checks)
    report['data_quality'] = [c.as_dict() for c in checks]
    for c in checks:
        if not c.clean:
            print(f'identify: data with gaps: {c.summary()}', file=sys.stderr)
    try:
        results = identify_joints(series, labels, kinds, joints or None, name_map, model,
                                  config, accels, opts.model_compensation,
                                  progress=lambda m: print(f'identify: {m}', flush=True))
    except IdentificationError as exc:
        return finish(1, str(exc))
    for r in results:
        report['joints'][r.name] = report_entry(r)
        print(f'identify: {summary_line(r)}')
        for w in r.warnings:
            print(f'identify: note: {w}', file=sys.stderr)
    source = 'identified from ' + ', '.join(labels)
    gappy = [c for c in checks if not c.clean]
    if gappy:
        source += (' (DATA WITH GAPS: ' + '; '.join(
            f'{Path(c.bag).name} {c.missing} samples missing in {len(c.gaps)} gap(s), '
            f'largest {c.largest().length_s:.3f} s' if c.gaps else
            f'{Path(c.bag).name} {c.duplicates} duplicates dropped' for c in gappy) + ')')
    fill = None
    if opts.fill_nominal:
        fill = model.friction
        if any(r.name not in fill.joint_names for r in results if r.friction is None):
            fill = None
            report['problems'].append('--fill-nominal: only for the model joint names')
    try:
        fmap = friction_map(results, source, fill)
    except IdentificationError as exc:
        return finish(1, str(exc))
    if base is not None:
        fmap = complete_map(fmap, base, model.joint_names)
        report['completed_from'] = base.source
    out = Path(opts.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fmap.save(out)
    plot_dir = None if opts.no_plots else Path(opts.plots) if opts.plots else out.parent
    if plot_dir is not None:
        from .plots import plot_joint
        plot_dir.mkdir(parents=True, exist_ok=True)
        for r in results:
            safe = re.sub(r'[^A-Za-z0-9_.-]+', '_', r.name)
            report['joints'][r.name]['plot'] = str(
                plot_joint(r, plot_dir / f'{out.stem}_{safe}.png'))
    failed = [r.name for r in results if r.error]
    degenerate = [r.name for r in results if r.degenerate]
    trusted = [r.name for r in results if not r.error and not r.degenerate]
    report.update(ok=not failed and not degenerate, failed=failed, degenerate=degenerate,
                  identified=trusted)
    print(f'identify: wrote {out}' + (f' (degenerate, not for use: {", ".join(degenerate)})'
                                      if degenerate else ''))
    if not trusted:
        return finish(1, 'no joint has a trusted fit: ' + '; '.join(
            (r.error or '; '.join(r.degenerate)) for r in results))
    return finish(2 if failed or degenerate else 0)


if __name__ == '__main__':
    sys.exit(main())
