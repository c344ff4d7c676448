"""discrepancy: find the disagreement between model and measurements, name the missing effect,
add it, show the gap shrink on held-out data (DESIGN.md §8).

    ros2 run irb_identification discrepancy --bag DIR [--bag DIR ...] --model PATH --out DIR

Offline (no ROS graph). Exit code 0 on success (also when the answer is 'none'), 1 on bad input.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


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
    argv = list(sys.argv[1:] if args is None else args)
    if '--ros-args' in argv:
        argv = argv[:argv.index('--ros-args')]
    opts = _parser().parse_args(argv)
    from .bagio import BagError
    from .discrepancy_core.report import write_report
    from .discrepancy_core.workflow import WorkflowConfig, run_workflow, write_updated_model
    from irb_description.friction import FrictionMapError
    from .discrepancy_core.report import answer_line, data_line
    try:
        config = WorkflowConfig.from_yaml(opts.config or default_config_path())
        for b in opts.bag + opts.holdout_bag:
            if not Path(b).exists():
                raise ValueError(f'bag {b} does not exist')
        out = Path(opts.out)
        out.mkdir(parents=True, exist_ok=True)
        result = run_workflow(opts.bag, opts.model, config, opts.holdout_bag,
                              log=lambda s: print(f'discrepancy: {s}'))
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
