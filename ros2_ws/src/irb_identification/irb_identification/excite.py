"""excite: run the discrepancy workflow's motions (circles at several speeds, multi-joint
sweeps) on the simulated plant offline and record one bag per run.

    ros2 run irb_identification excite --out bags/excite1 [--plan short|full] \
        [--plant PLANT_YAML] [--effect NAME[:SCALE] ...] [--model MAP_YAML] [--seed N] \
        [--effort-noise-white NM] [--effort-noise-coloured NM --effort-noise-tau S] \
        [--effort-quantum NM] [--torque-gain G] [--encoder-scale S] [--link-mass-error L:KG]

The plant is irb_control's (closed loop with the PD+ controller, 5 substeps, 3-sample delay,
encoder + 100 Hz camera); its friction and effects come from the plant YAML (default
irb_control config/plant.yaml), ``--effect`` adds effects at their moderate size (irb_control
plant_effects.MODERATE) times SCALE. The controller's feed-forward map is ``--model``
(default: the plant YAML's map). ``--out`` becomes a folder of complete bags, one per run
(``excite_00_<run>``, ...); ``discrepancy`` and ``identify`` take the folder as one --bag.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from irb_description.node_help import own_args


def _floats(text: str, what: str, n: int = 3) -> tuple:
    """'a' or 'a,b,c' -> (3,) floats; ValueError with a clear message."""
    try:
        v = [float(x) for x in str(text).split(',')]
    except ValueError:
        raise ValueError(f'{what}: not a number or a list of {n}: {text!r}') from None
    if len(v) == 1:
        v = v * n
    if len(v) != n:
        raise ValueError(f'{what}: expected 1 or {n} comma-separated values, got {text!r}')
    return tuple(v)


def parse_effect(item: str, names) -> tuple[str, float]:
    """'NAME' or 'NAME:SCALE' -> (name, scale); ValueError names the problem."""
    name, sep, scale = item.partition(':')
    if name not in names:
        raise ValueError(f'--effect {item!r}: unknown effect {name!r}; known: '
                         f'{", ".join(names)}')
    if not sep:
        return name, 1.0
    try:
        x = float(scale)
    except ValueError:
        raise ValueError(f'--effect {item!r}: scale {scale!r} is not a number') from None
    if not (x > 0 and x < 1e3):
        raise ValueError(f'--effect {item!r}: scale must be > 0 (and < 1000), got {scale}')
    return name, x


def main(args=None) -> int:
    argv = own_args(args)
    p = argparse.ArgumentParser(prog='excite', description=__doc__.split('\n\n')[0])
    p.add_argument('--out', required=True, help='directory for the bags (must not exist)')
    p.add_argument('--plan', default='short', help='plan name in config/excitation.yaml')
    p.add_argument('--plan-file', default=None, help='excitation YAML (default: package)')
    p.add_argument('--plant', default=None, help="plant YAML (friction_map + 'effects:')")
    p.add_argument('--effect', action='append', default=[],
                   help='extra effect NAME or NAME:SCALE at its moderate size (repeatable)')
    p.add_argument('--model', default=None, help='controller feed-forward friction map')
    p.add_argument('--seed', type=int, default=1)
    p.add_argument('--effort-noise-white', default='0', metavar='NM',
                   help='white noise std of the reported effort [N m] (one or 3 values)')
    p.add_argument('--effort-noise-coloured', default='0', metavar='NM',
                   help='coloured (first-order) noise std of the reported effort [N m]')
    p.add_argument('--effort-noise-tau', type=float, default=0.05, metavar='S',
                   help='correlation time of the coloured noise [s]')
    p.add_argument('--effort-quantum', type=float, default=0.0, metavar='NM',
                   help='resolution of the reported effort [N m] (0: none)')
    p.add_argument('--torque-gain', default='1', metavar='G',
                   help='drive torque = G x reported effort (one or 3 values; model error)')
    p.add_argument('--encoder-scale', default='1', metavar='S',
                   help='encoders report S x the joint position (one or 3 values)')
    p.add_argument('--link-mass-error', default=None, metavar='LINK:KG',
                   help='plant link 2 or 3 heavier by KG at its centre of mass (model error)')
    opts = p.parse_args(argv)
    from irb_control.plant import default_plant_yaml
    from irb_control.plant_effects import (EFFECT_NAMES, EffectsError, PlantEffects,
                                           load_plant_effects, moderate_effect)
    from irb_description.friction import FrictionMapError, load_friction_map
    from irb_description.model import RobotModel

    from .discrepancy_core.excitation import (EffortNoise, SensorErrors, load_plan,
                                              perturbed_model, run_plan, write_runs)
    out = Path(opts.out)
    if out.exists():
        print(f'excite: {out} exists; choose a new directory', file=sys.stderr)
        return 1
    plan_file = opts.plan_file or Path(__file__).resolve().parent.parent / 'config' / \
        'excitation.yaml'
    if not Path(plan_file).is_file() and opts.plan_file is None:
        from ament_index_python.packages import get_package_share_directory
        plan_file = Path(get_package_share_directory('irb_identification')) / 'config' / \
            'excitation.yaml'
    model = RobotModel.load()
    plant_yaml = opts.plant or default_plant_yaml()
    try:
        if not Path(plan_file).is_file():
            raise ValueError(f'plan file {plan_file} does not exist')
        plant_map = load_friction_map(plant_yaml, model.joint_names)
        effects = dict(load_plant_effects(plant_yaml).blocks)
        for item in opts.effect:
            name, scale = parse_effect(item, EFFECT_NAMES)
            effects.update(moderate_effect(name, scale).blocks)
        fx = PlantEffects(effects)
        ctrl_map = load_friction_map(opts.model, model.joint_names) if opts.model else plant_map
        plan = load_plan(plan_file, opts.plan)
        noise = EffortNoise(_floats(opts.effort_noise_white, '--effort-noise-white'),
                            _floats(opts.effort_noise_coloured, '--effort-noise-coloured'),
                            opts.effort_noise_tau, opts.effort_quantum)
        sensor = SensorErrors(_floats(opts.torque_gain, '--torque-gain'),
                              _floats(opts.encoder_scale, '--encoder-scale'))
        plant_model = None
        if opts.link_mass_error:
            link, sep, kg = opts.link_mass_error.partition(':')
            if link not in ('2', '3') or not sep:
                raise ValueError(f'--link-mass-error {opts.link_mass_error!r}: expected '
                                 'LINK:KG with LINK 2 or 3')
            dm = _floats(kg, '--link-mass-error KG', 1)[0]
            plant_model = perturbed_model(model, int(link), dm)
    except (EffectsError, FrictionMapError, KeyError, ValueError, OSError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f'excite: {msg}', file=sys.stderr)
        return 1
    print(f"excite: plan {opts.plan} ({len(plan)} runs), effects {fx.names() or 'none'}")
    try:
        runs = run_plan(model, plan, plant_map, ctrl_map, fx, opts.seed,
                        log=lambda s: print(f'excite: {s}'), effort_noise=noise,
                        sensor=sensor, plant_model=plant_model)
    except (RuntimeError, ValueError) as exc:
        print(f'excite: the simulated run failed: {exc} (effect too large for the '
              'controller?)', file=sys.stderr)
        return 1
    out.mkdir(parents=True)
    bags = write_runs(runs, out, model.joint_names,
                      custom_data={'effects': ','.join(fx.names()) or 'none',
                                   'seed': opts.seed})
    print(f'excite: {len(bags)} bags in {out} (a folder of bags: pass it as it is, '
          f'discrepancy --bag {out} reads them all)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
