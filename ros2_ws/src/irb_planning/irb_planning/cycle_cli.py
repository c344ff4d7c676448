"""`ros2 run irb_planning cycle`: plan a work cycle within its takt (issue 29).

Reads a cycle YAML (ordered operations: motions along paths with optional process
constraints, fixed rest steps, waits; the takt), plans every motion's energy-duration front
on the electrical model (offline, no ROS graph; progress per plan; fronts cached on disk, so
a second run, e.g. at another --takt, plans nothing), chooses each motion's duration and each
station's power mode by the exact DP of ``irb_planning.cycle`` and prints the plan with its
certificate (discrete optimum, continuous lower bound, gap) and baselines A (time-optimal
motions, motors hold) and B (durations chosen, motors hold). Writes to --out:
cycle_plan.json (the whole cycle), motions/<name>.path.yaml and <name>.plan.json (the chosen
plan: duration, energy, trajectory points) and, unless --no-plots, cycle_timeline.png and
cycle_fronts.png. Exit 0 planned, 1 no plan within the takt or a motion refused, 2 bad
arguments or cycle file.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from irb_description.node_help import own_args

EXAMPLE = ('ros2 run irb_planning cycle --cycle $(ros2 pkg prefix irb_planning)/share/'
           'irb_planning/config/cycle_gluing.yaml --out cycle_out')


def parse_args(argv):
    p = argparse.ArgumentParser(prog='cycle', description=__doc__.splitlines()[0],
                                epilog='example: ' + EXAMPLE)
    p.add_argument('--cycle', required=True, help='cycle YAML (config/cycle_gluing.yaml shows '
                   'every key)')
    p.add_argument('--out', required=True, help='output directory (created)')
    p.add_argument('--takt', type=float, default=0.0,
                   help="[s] takt time; 0 = the file's takt_s")
    p.add_argument('--cache', default='',
                   help="directory of the front cache; '' = <out>/fronts")
    p.add_argument('--check-rate', type=float, default=1000.0,
                   help='[Hz] rate at which the planner plays and checks every plan (the '
                   'placement search\'s 1 kHz; the planner node plays at 10 kHz)')
    p.add_argument('--jobs', type=int, default=1,
                   help='processes planning the motions\' fronts at once (each builds its '
                   'own planner; 2 on a 2-core machine)')
    p.add_argument('--electrical', default='',
                   help="electrical-model YAML the plans and the power modes use ('' = "
                   "irb_description's config/electrical.yaml); e.g. the simulator's "
                   'irb_control config/plant_electrical.yaml to plan for that plant')
    p.add_argument('--limit-scaling', type=float, default=0.0,
                   help="fraction of the torque and speed limits the motions' plans use "
                   "(0 = the file's limit_scaling, else 1); 0.9 leaves pdplus the headroom "
                   'it asks of a plan (its plan_torque_fraction)')
    p.add_argument('--no-plots', action='store_true', help='write no PNG')
    return p.parse_args(argv)


def table(plan) -> str:
    """The plan as text: one row per item, totals, certificate, baselines."""
    s = plan.solution
    rows = [f'{"operation":28s} {"kind":8s} {"duration [s]":>12s} {"mode":9s} '
            f'{"energy [J]":>11s}']
    for c in s.choices:
        rows.append(f'{c["name"][:28]:28s} {c["kind"]:8s} {c["duration_s"]:12.3f} '
                    f'{c.get("mode") or "-":9s} {c["energy_j"]:11.1f}')
    a = plan.baseline_a['total_j']
    b = plan.baseline_b.total_j if plan.baseline_b else float('nan')
    rows += [f'cycle: {s.total_j:.1f} J in {s.takt_s:g} s; baseline A (time-optimal motions, '
             f'motors hold) {a:.1f} J, saving {100 * (1 - s.total_j / a):.2f} %; baseline B '
             f'(durations chosen, motors hold) {b:.1f} J, saving {100 * (1 - s.total_j / b):.2f}'
             ' %',
             f'certificate: discrete optimum {s.total_j:.2f} J (exact DP, time step '
             f'{s.step_s:g} s, {s.solve_time_s * 1e3:.0f} ms), continuous lower bound '
             f'{s.lower_bound_j:.2f} J, gap {s.gap_j:.2f} J ({100 * s.gap_rel:.3f} %)',
             f'planning time {plan.plan_time_s:.1f} s (fronts {plan.front_time_s:.1f} s)']
    return '\n'.join(rows)


def write_outputs(plan, out: Path, plots: bool, electrical: str = '') -> dict:
    """cycle_plan.json, the chosen motions' path and plan files, the PNGs; returns the
    JSON written."""
    import json

    import yaml
    from irb_description.path import PROCESS_KEY
    out.mkdir(parents=True, exist_ok=True)
    mdir = out / 'motions'
    mdir.mkdir(exist_ok=True)
    summary = plan.summary()
    ops = {op.name: op for op in plan.spec.operations}
    for c in summary['operations']:
        if c['kind'] != 'motion':
            continue
        op, front = ops[c['name']], plan.fronts[c['name']]
        rec = front.points[c['duration_s']]
        spec = dict(op.path)
        if op.process:
            spec[PROCESS_KEY] = dict(op.process)
        pfile = mdir / f'{op.name}.path.yaml'
        pfile.write_text(yaml.safe_dump(spec, default_flow_style=None))
        tfile = mdir / f'{op.name}.plan.json'
        tfile.write_text(json.dumps({
            'name': op.name, 'duration_s': rec['duration_s'], 'energy_j': rec['energy_j'],
            'objective': 'energy', 'energy_model': plan.energy_model,
            'path_file': pfile.name, 'trajectory': rec['trajectory']}))
        c['path_file'] = str(pfile)
        c['plan_file'] = str(tfile)
        c['replan'] = (f'ros2 run irb_planning plan --path-file {pfile} --duration '
                       f'{rec["duration_s"]:g} --energy-model {plan.energy_model}')
    summary['cycle_file'] = plan.spec.source
    summary['energy_model'] = plan.energy_model
    summary['electrical_config'] = str(electrical)   # '' = irb_description's electrical.yaml
    summary['limit_scaling'] = plan.spec.limit_scaling or 1.0
    summary['fronts'] = {n: {'durations_s': sorted(f.points),
                             'energies_j': [f.points[d]['energy_j'] for d in sorted(f.points)],
                             'time_optimal_s': f.fastest['duration_s'],
                             'time_optimal_j': f.fastest['energy_j'],
                             'refused': {str(k): v for k, v in f.refused.items()}}
                         for n, f in plan.fronts.items()}
    if plots:
        from .cycle_plot import plot_fronts, plot_timeline
        summary['timeline_png'] = str(plot_timeline(plan, out / 'cycle_timeline.png'))
        summary['fronts_png'] = str(plot_fronts(plan, out / 'cycle_fronts.png'))
    (out / 'cycle_plan.json').write_text(json.dumps(summary, indent=1, default=float))
    return summary


def main(args=None):
    argv = own_args(args)
    a = parse_args(argv)
    from .cycle import CycleError, load_cycle, plan_cycle
    try:
        spec = load_cycle(a.cycle)
        if a.takt < 0 or not a.check_rate > 0 or a.jobs < 1:
            raise CycleError('--takt must be >= 0, --check-rate > 0 and --jobs >= 1')
        if not 0 <= a.limit_scaling <= 1:
            raise CycleError('--limit-scaling must be in [0, 1] (0 = the file\'s)')
        if a.limit_scaling:
            from dataclasses import replace
            spec = replace(spec, limit_scaling=a.limit_scaling)
        if a.electrical and not Path(a.electrical).is_file():
            raise CycleError(f'--electrical: no file {a.electrical}')
    except CycleError as exc:
        print(f'cycle: {exc}', file=sys.stderr)
        return 2
    out = Path(a.out)
    from .cycle import front_settings
    from .planner import Planner
    try:
        planner = Planner(settings=front_settings(spec, play_rate_hz=a.check_rate,
                                                  evaluation_rate_hz=a.check_rate,
                                                  electrical_config=a.electrical))
        plan = plan_cycle(spec, planner, cache_dir=Path(a.cache) if a.cache
                          else out / 'fronts', progress=lambda s: print(s, flush=True),
                          takt_s=a.takt or None, jobs=a.jobs)
    except CycleError as exc:
        print(f'cycle: {exc}', file=sys.stderr)
        return 1
    except ValueError as exc:          # power-modes / electrical files
        print(f'cycle: {str(exc).splitlines()[0]}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    print(table(plan))
    try:
        summary = write_outputs(plan, out, not a.no_plots, a.electrical)
    except OSError as exc:
        print(f'cycle: cannot write to {out}: {exc.strerror}', file=sys.stderr)
        return 2
    print(f'written {out / "cycle_plan.json"}'
          + (f', {summary["timeline_png"]}, {summary["fronts_png"]}' if not a.no_plots else ''))
    return 0


if __name__ == '__main__':
    sys.exit(main())
