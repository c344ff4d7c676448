"""excite: run the discrepancy workflow's motions (circles at several speeds, multi-joint
sweeps) on the simulated plant offline and record one bag per run.

    ros2 run irb_identification excite --out bags/excite1 [--plan short|full] \
        [--plant PLANT_YAML] [--effect NAME[:SCALE] ...] [--model MAP_YAML] [--seed N]

The plant is irb_control's (closed loop with the PD+ controller, 5 substeps, 3-sample delay,
encoder + 100 Hz camera); its friction and effects come from the plant YAML (default
irb_control config/plant.yaml), ``--effect`` adds effects at their moderate size (irb_control
plant_effects.MODERATE) times SCALE. The controller's feed-forward map is ``--model``
(default: the plant YAML's map).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def main(args=None) -> int:
    argv = list(sys.argv[1:] if args is None else args)
    if '--ros-args' in argv:
        argv = argv[:argv.index('--ros-args')]
    p = argparse.ArgumentParser(prog='excite', description=__doc__.split('\n\n')[0])
    p.add_argument('--out', required=True, help='directory for the bags (must not exist)')
    p.add_argument('--plan', default='short', help='plan name in config/excitation.yaml')
    p.add_argument('--plan-file', default=None, help='excitation YAML (default: package)')
    p.add_argument('--plant', default=None, help="plant YAML (friction_map + 'effects:')")
    p.add_argument('--effect', action='append', default=[],
                   help='extra effect NAME or NAME:SCALE at its moderate size (repeatable)')
    p.add_argument('--model', default=None, help='controller feed-forward friction map')
    p.add_argument('--seed', type=int, default=1)
    opts = p.parse_args(argv)
    from irb_control.plant import default_plant_yaml
    from irb_control.plant_effects import (EffectsError, PlantEffects, load_plant_effects,
                                           moderate_effect)
    from irb_description.friction import load_friction_map
    from irb_description.model import RobotModel

    from .discrepancy_core.excitation import load_plan, run_plan, write_runs
    out = Path(opts.out)
    if out.exists():
        print(f'excite: {out} exists; choose a new directory', file=sys.stderr)
        return 1
    plan_file = opts.plan_file or Path(__file__).resolve().parent.parent / 'config' / \
        'excitation.yaml'
    if not Path(plan_file).is_file():
        from ament_index_python.packages import get_package_share_directory
        plan_file = Path(get_package_share_directory('irb_identification')) / 'config' / \
            'excitation.yaml'
    model = RobotModel.load()
    plant_yaml = opts.plant or default_plant_yaml()
    try:
        plant_map = load_friction_map(plant_yaml, model.joint_names)
        effects = dict(load_plant_effects(plant_yaml).blocks)
        for item in opts.effect:
            name, _, scale = item.partition(':')
            effects.update(moderate_effect(name, float(scale or 1.0)).blocks)
        ctrl_map = load_friction_map(opts.model, model.joint_names) if opts.model else plant_map
        plan = load_plan(plan_file, opts.plan)
    except (EffectsError, KeyError, ValueError, OSError) as exc:
        print(f'excite: {exc}', file=sys.stderr)
        return 1
    fx = PlantEffects(effects)
    print(f"excite: plan {opts.plan} ({len(plan)} runs), effects {fx.names() or 'none'}")
    runs = run_plan(model, plan, plant_map, ctrl_map, fx, opts.seed,
                    log=lambda s: print(f'excite: {s}'))
    out.mkdir(parents=True)
    bags = write_runs(runs, out, model.joint_names,
                      custom_data={'effects': ','.join(fx.names()) or 'none',
                                   'seed': opts.seed})
    print(f'excite: {len(bags)} bags in {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
