"""Benchmark of the discrepancy workflow: effects x sizes x seeds, plus clean data.

    python ros2_ws/src/irb_identification/benchmarks/bench_discrepancy.py \
        [--sizes 0.25 0.5 1 2] [--seeds 3] [--clean-seeds 20] [--plan short] [--effects ...]

For every case: simulate the excitation plan on irb_control's plant with one hidden effect at
size x its moderate size (irb_control.plant_effects.MODERATE; for elasticity the stiffness is
divided by the size), write the bags, run the workflow against the nominal model (the plant's
friction map, no effects), record the named effect, confidence, held-out residual reduction
and run time. Writes benchmarks/results/discrepancy.json and prints a Markdown table.
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np


def main(args=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--sizes', type=float, nargs='+', default=[0.25, 0.5, 1.0, 2.0])
    p.add_argument('--seeds', type=int, default=3)
    p.add_argument('--clean-seeds', type=int, default=20)
    p.add_argument('--plan', default='short')
    p.add_argument('--effects', nargs='+', default=None)
    p.add_argument('--n-boot', type=int, default=20)
    p.add_argument('--out', default=str(Path(__file__).parent / 'results' / 'discrepancy.json'))
    opts = p.parse_args(args)
    from irb_control.plant import default_plant_yaml
    from irb_control.plant_effects import EFFECT_NAMES, moderate_effect
    from irb_description.friction import load_friction_map
    from irb_description.model import RobotModel

    from irb_identification.discrepancy import default_config_path
    from irb_identification.discrepancy_core.excitation import load_plan, run_plan, write_runs
    from irb_identification.discrepancy_core.workflow import WorkflowConfig, run_workflow

    model = RobotModel.load()
    plant_yaml = default_plant_yaml()
    fm = load_friction_map(plant_yaml, model.joint_names)
    plan = load_plan(default_config_path().parent / 'excitation.yaml', opts.plan)
    base = WorkflowConfig.from_yaml(default_config_path())
    config = WorkflowConfig(base.residual, base.grids, base.block_s, base.bic_threshold,
                            base.min_confidence, base.min_fit_reduction, opts.n_boot,
                            base.seed, base.speed_bins)
    effects = opts.effects or list(EFFECT_NAMES)
    cases = [('none', 0.0, 100 + s) for s in range(opts.clean_seeds)]
    cases += [(e, size, 1 + s) for e in effects for size in opts.sizes
              for s in range(opts.seeds)]
    rows = []
    for i, (effect, size, seed) in enumerate(cases):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            fx = None if effect == 'none' else moderate_effect(effect, size)
            try:
                runs = run_plan(model, plan, fm, fm, fx, seed=seed)
            except RuntimeError as exc:       # e.g. the PD+ safe-stops with a large delay
                rows.append({'effect': effect, 'size': size, 'seed': seed,
                             'named': 'excitation_failed', 'correct': False,
                             'confidence': None, 'heldout_reduction': None, 'top3': [],
                             'error': str(exc), 'simulate_s': 0.0, 'workflow_s': 0.0})
                print(f'[{i + 1}/{len(cases)}] {effect} x{size:g} seed {seed}: {exc}')
                continue
            bags = write_runs(runs, Path(tmp), model.joint_names)
            t1 = time.perf_counter()
            rep = run_workflow(bags, plant_yaml, config, model=model).report
            t2 = time.perf_counter()
        row = {'effect': effect, 'size': size, 'seed': seed, 'named': rep['effect'],
               'correct': rep['effect'] == effect, 'confidence': rep['confidence'],
               'heldout_reduction': rep['heldout_reduction'],
               'top3': [(c['effect'], round(c['delta_bic'], 1)) for c in rep['candidates'][:3]],
               'simulate_s': t1 - t0, 'workflow_s': t2 - t1}
        rows.append(row)
        red = rep['heldout_reduction']
        print(f"[{i + 1}/{len(cases)}] {effect:26s} x{size:<5g} seed {seed:3d} -> "
              f"{rep['effect']:26s} conf {rep['confidence']:.2f} red "
              f"{red if red is None else round(red, 2)}  {t2 - t0:.1f} s", flush=True)
    summary = {}
    for effect in ['none'] + effects:
        for size in ([0.0] if effect == 'none' else opts.sizes):
            sel = [r for r in rows if r['effect'] == effect and r['size'] == size]
            red = [r['heldout_reduction'] for r in sel if r['correct']
                   and r['heldout_reduction'] is not None]
            summary[f'{effect}@{size:g}'] = {
                'effect': effect, 'size': size, 'n': len(sel),
                'correct_rate': float(np.mean([r['correct'] for r in sel])),
                'named': dict(Counter(r['named'] for r in sel)),
                'median_heldout_reduction': float(np.median(red)) if red else None,
                'min_heldout_reduction': float(np.min(red)) if red else None,
                'mean_workflow_s': float(np.mean([r['workflow_s'] for r in sel]))}
    clean = [r for r in rows if r['effect'] == 'none']
    out = {'plan': opts.plan, 'sizes': opts.sizes, 'seeds': opts.seeds,
           'false_positive_rate_clean': float(np.mean([not r['correct'] for r in clean]))
           if clean else None,
           'summary': summary, 'cases': rows}
    Path(opts.out).parent.mkdir(parents=True, exist_ok=True)
    Path(opts.out).write_text(json.dumps(out, indent=1))
    print('\n| effect | size | n | correct | named | median held-out reduction | workflow s |')
    print('|---|---|---|---|---|---|---|')
    for s in summary.values():
        med = s['median_heldout_reduction']
        print(f"| {s['effect']} | {s['size']:g} | {s['n']} | {100 * s['correct_rate']:.0f} % | "
              f"{s['named']} | {'-' if med is None else f'{100 * med:.0f} %'} | "
              f"{s['mean_workflow_s']:.1f} |")
    print(f"\nfalse positives on clean data: {out['false_positive_rate_clean']}")
    print(f'written {opts.out}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
