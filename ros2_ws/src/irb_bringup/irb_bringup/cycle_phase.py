"""The main job's work-cycle phase (issue 29): the gluing cycle planned with irb_planning's
cycle planner (motion durations from each motion's energy-duration front, each wait's power
mode, an exact DP with its certificate) against baseline A (time-optimal motions, motors hold
while waiting) and B (durations chosen, motors hold), per cycle and per year; energy per cycle
against the takt and the saving's sensitivity to each power-mode parameter. Offline on the
electrical model; the cycle's motions are planned in process. No rclpy."""
from __future__ import annotations

from pathlib import Path


def cycle_file(cfg_cycle: dict) -> Path:
    """The cycle YAML: the config's ``file``, or irb_planning's config/cycle_gluing.yaml."""
    if cfg_cycle.get('file'):
        return Path(cfg_cycle['file'])
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('irb_planning')) / 'config' / 'cycle_gluing.yaml'


def glue_matches_rectangle(spec, rect: dict) -> str:
    """'' if the cycle's first motion is the job's gluing rectangle (same waypoints, blends,
    band), else why not: the cycle file repeats the rectangle's geometry (a path mapping), and
    the study must be about the contour the job runs."""
    import numpy as np
    from irb_description.path import PROCESS_KEY

    from .thesis_run import rectangle_spec
    ref = rectangle_spec(rect)
    band = ref.pop(PROCESS_KEY, {})
    op = spec.motions[0]
    got = dict(op.path)
    if got.get('type') != ref['type'] or np.shape(got.get('waypoints')) != np.shape(
            ref['waypoints']):
        return f'its first motion {op.name!r} is not the rectangle ({got.get("type")})'
    if not np.allclose(got['waypoints'], ref['waypoints'], atol=1e-9) or not np.allclose(
            got.get('blend_radii', []), ref.get('blend_radii', []), atol=1e-12):
        return f'its first motion {op.name!r} has other corners or blends than the rectangle'
    if {k: float(v) for k, v in (op.process or {}).items()} != band:
        return f'its first motion {op.name!r} has another process band ({op.process} vs {band})'
    return ''


def run_cycle_phase(cfg_cycle: dict, rect: dict, duty: dict, out: Path, log) -> dict:
    """Plan the cycle, write cycle/cycle_plan.json and the PNGs; the study's figures (dict,
    JSON-ready). Raises ValueError (one line) on a cycle that does not fit."""
    import numpy as np
    from irb_planning.cycle import front_settings, load_cycle, plan_cycle
    from irb_planning.cycle_cli import write_outputs
    from irb_planning.cycle_study import (plot_sweep, plot_tornado, section_gluing,
                                          section_sweep, section_tornado)
    from irb_planning.planner import Planner
    path = cycle_file(cfg_cycle)
    spec = load_cycle(path)
    why = glue_matches_rectangle(spec, rect)
    if why:
        raise ValueError(f'cycle {path}: {why} (thesis_run.yaml rectangle)')
    # the fronts' planner settings (no cost-of-the-limits solve, warm starts along a front)
    planner = Planner(settings=front_settings(spec))
    plan = plan_cycle(spec, planner, cache_dir=out / 'fronts', progress=lambda s: log(f'   {s}'),
                      jobs=int(cfg_cycle.get('jobs', 1)))
    out.mkdir(parents=True, exist_ok=True)
    written = write_outputs(plan, out, plots=True)
    duty_y = {'hours_per_year': float(duty['hours_per_year']),
              'price_per_kwh': float(duty['price_per_kwh']), 'currency': duty['currency']}
    study = section_gluing(plan, duty_y)
    lo, hi, step = (float(v) for v in cfg_cycle.get('takt_sweep_s', [14.0, 60.0, 1.0]))
    sweep = section_sweep(plan, list(np.arange(lo, hi + 1e-9, step)))
    tornado = section_tornado(plan, spec.takt_s)
    plot_sweep(sweep, spec.takt_s, out / 'cycle_energy_vs_takt.png')
    plot_tornado(tornado, out / 'cycle_tornado.png')
    return {'file': str(path), 'study': study, 'sweep': sweep, 'tornado': tornado,
            'plan_json': str(out / 'cycle_plan.json'),
            'pngs': {'timeline': written.get('timeline_png'),
                     'fronts': written.get('fronts_png'),
                     'energy_vs_takt': str(out / 'cycle_energy_vs_takt.png'),
                     'tornado': str(out / 'cycle_tornado.png')}}


def cycle_section(cycle: dict, report_dir: Path) -> list[str]:
    """Markdown lines of the work-cycle study for the main report."""
    import os
    s = cycle['study']
    rel = {k: os.path.relpath(v, report_dir) for k, v in cycle['pngs'].items() if v}
    y = s['per_year']
    cur = y['plan']['currency']
    modes = ', '.join(f'{c["name"]}: {c["mode"]} {c["duration_s"]:.2f} s'
                      for c in s['operations'] if c['kind'] == 'station')
    motions = ', '.join(f'{c["name"]} {c["duration_s"]:.2f} s'
                        for c in s['operations'] if c['kind'] == 'motion')
    needs = ', '.join(f'{k} {v:.4g}' for k, v in s['parameter_for_goal'].items()
                      if v is not None) or 'none of the parameters within its range'
    top = cycle['tornado']['rows'][:3]
    lines = [
        '## Work cycle: durations and power modes within the takt', '',
        f'The gluing cycle of `{Path(cycle["file"]).name}` (this rectangle, a move to the '
        'part-exchange pose, the part exchange, a wait for the line, the move back) at a '
        f'takt of {s["takt_s"]:g} s, planned by irb_planning\'s `cycle` on the electrical '
        'model: each motion\'s duration from its energy-duration front, each wait\'s power '
        'mode (hold, brakes, bus_off, hibernate; transitions included), an exact DP with a '
        'certificate. Offline: the cycle is not executed on the simulator here; '
        '`ros2 run irb_bringup cycle_run` executes a cycle plan on the simulator and measures '
        'it (irb_bringup benchmarks/RESULTS.md: this plan needs 671 of 700 N m at joint 1 in '
        'its fastest move, more than pdplus accepts; executed at 0.6 of the limits with '
        'moves of at least 1 s, 100 cycles measured +2.4 % over plan, no stop).', '',
        '| | J per cycle | kWh/year | cost/year |', '|---|---|---|---|',
        f'| A: fastest motions, motors hold | {s["baseline_a_j"]:.1f} | '
        f'{y["baseline_a"]["kwh_per_year"]:.0f} | {y["baseline_a"]["cost_per_year"]:.1f} '
        f'{cur} |',
        f'| B: durations chosen, motors hold | {s["baseline_b_j"]:.1f} | '
        f'{y["baseline_b"]["kwh_per_year"]:.0f} | {y["baseline_b"]["cost_per_year"]:.1f} '
        f'{cur} |',
        f'| **plan: durations and modes** | **{s["energy_j"]:.1f}** | '
        f'**{y["plan"]["kwh_per_year"]:.0f}** | **{y["plan"]["cost_per_year"]:.1f} {cur}** |',
        '',
        f'Saving {s["saving_vs_a_percent"]:.1f} % against A (goal {s["goal_percent"]:g} %: '
        f'{"met" if s["goal_met"] else "not met"}) and {s["saving_vs_b_percent"]:.1f} % '
        f'against B. Motions: {motions}; waits: {modes}. Certificate: the DP\'s optimum is '
        f'{s["gap_percent"]:.2f} % above a continuous lower bound ({s["lower_bound_j"]:.1f} J). '
        f'Ceiling at this takt with every wait in bus_off and free transitions: '
        f'{s["ceiling_all_rest_in_bus_off_percent"]:.1f} %. The goal would be reached with '
        f'{needs}.', '',
        'Most of the result rests on: ' + '; '.join(
            f'{r["parameter"]} ({r["low"]:g}-{r["high"]:g}: '
            f'{r["saving_low_percent"]:.1f}-{r["saving_high_percent"]:.1f} %)' for r in top)
        + '. Every mode parameter is an assumption of this robot class except hibernate\'s '
        'cut (irb_description config/power_modes.yaml names the source of each).', '']
    for key, title in (('energy_vs_takt', 'energy per cycle against the takt'),
                       ('timeline', 'the planned cycle'), ('tornado', 'sensitivity'),
                       ('fronts', 'energy-duration fronts')):
        if key in rel:
            lines += [f'![{title}]({rel[key]})', '']
    lines += [f'Plan of the whole cycle: `{os.path.relpath(cycle["plan_json"], report_dir)}`'
              ' (each motion\'s plan file and the command to re-plan it).', '']
    return lines
