"""discrepancy: find the disagreement between model and measurements, name the missing effect,
add it, show the gap shrink on held-out data (DESIGN.md §8).

    ros2 run irb_identification discrepancy --bag DIR [--bag DIR ...] --model PATH --out DIR

Offline (no ROS graph). A --bag is a bag from the recorder, a main-job run bag (its ``_drive``
companion supplies /torque_command) or a folder of bags (excite's output). Measured q, qd and
effort come from /joint_states, commands from /torque_command, the TCP from /camera/tcp.
Gaps: every series is checked against the nominal 4.032 ms period; runs are analysed in
gap-free pieces and the report says what was missing (``data_quality``), or, with ``--gaps
refuse``, a gap is an error naming the bag, topic and gap. Exit code 0 on success (also when
the answer is 'none'), 1 on bad input or a refused gap.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from irb_description.node_help import own_args


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='discrepancy', description=__doc__.split('\n\n')[0])
    p.add_argument('--bag', action='append', required=True, help='measured bag (repeatable)')
    p.add_argument('--holdout-bag', action='append', default=[],
                   help='bags used only for the before/after check (default: alternate time '
                        'blocks of --bag)')
    p.add_argument('--model', required=True,
                   help="model file: friction-map YAML, optional 'effects:' section")
    p.add_argument('--out', required=True, help='output directory')
    p.add_argument('--config', default=None,
                   help='settings YAML (default: config/discrepancy.yaml of the package)')
    p.add_argument('--no-plots', action='store_true')
    p.add_argument('--gaps', default=None, choices=('segment', 'refuse'),
                   help="gaps in the joint states: 'segment' analyses the gap-free pieces and "
                   "says so in the report, 'refuse' stops with one line naming the bag, topic "
                   "and gap (default: the config's gaps.on_gap, segment)")
    return p


def default_config_path() -> Path | None:
    src = Path(__file__).resolve().parent.parent / 'config' / 'discrepancy.yaml'
    if src.is_file():
        return src
    try:
        from ament_index_python.packages import get_package_share_directory
        p = Path(get_package_share_directory('irb_identification')) / 'config' / \
            'discrepancy.yaml'
        return p if p.is_file() else None
    except Exception:
        return None


def main(args=None) -> int:
    argv = own_args(args)
    opts = _parser().parse_args(argv)
    from dataclasses import replace

    from .bagio import BagError
    from .readers import expand_bags, not_a_bag
    from .discrepancy_core.report import write_report
    from .discrepancy_core.workflow import WorkflowConfig, run_workflow, write_updated_model
    from irb_description.friction import FrictionMapError
    from .discrepancy_core.report import answer_line, data_line
    try:
        config = WorkflowConfig.from_yaml(opts.config or default_config_path())
        if opts.gaps:
            config = replace(config, gaps=replace(config.gaps, on_gap=opts.gaps))
        bags, holdout = expand_bags(opts.bag), expand_bags(opts.holdout_bag)
        for b in bags + holdout:
            why = not_a_bag(Path(b))
            if why:
                raise ValueError(why)
        out = Path(opts.out)
        if out.exists() and not out.is_dir():
            raise ValueError(f'--out {out} exists and is not a directory')
        result = run_workflow(bags, opts.model, config, holdout,
                              log=lambda s: print(f'discrepancy: {s}'))
        out.mkdir(parents=True, exist_ok=True)      # only for a result: no empty folder
    except (BagError, FrictionMapError, ValueError, OSError, TypeError, KeyError) as exc:
        print(f'discrepancy: {exc}', file=sys.stderr)
        return 1
    result.report['updated_model'] = str(write_updated_model(result, out / 'model_updated.yaml'))
    path = write_report(result, out, make_plots=not opts.no_plots)
    r = result.report
    print(f"discrepancy: {r['effect']}, confidence {r['confidence']:.2f}: {answer_line(r)}; "
          f"report {path}")
    print(f'discrepancy: {data_line(r)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
