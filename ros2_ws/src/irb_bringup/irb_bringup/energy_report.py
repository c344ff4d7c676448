"""The main job's energy story: electrical energy of executed runs, the best placement, per
cycle and per year (no ROS imports).

Electrical energy of a run: the simulator publishes ``electrical_power`` (sensor_msgs/
JointState) with every joint state: per axis the power drawn from the DC bus [W] under the
joint names, and the robot's total from the grid [W] for each DC-bus mode under
``total_none``, ``total_shared``, ``total_regenerative`` (standby included), from the plant's
own electrical parameters (irb_control config/plant_electrical.yaml). Inside the run's path
window (MODE_PATH, the same window as the mechanical energy) E_mode = int P_mode dt
(trapezoidal rule on the message stamps).

Duty cycle: one cycle is one lap of the task (the path window); per year
E_year = E_cycle x cycles_per_hour x hours_per_year, in kWh (1 kWh = 3.6e6 J) and times the
energy price. Standby between cycles (idle time of each hour) is not in these figures.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from irb_description.electrical import BUS_MODES

from .run_report import check_gap, path_window, saving_percent

JOINT_STATE = 'sensor_msgs/msg/JointState'
J_PER_KWH = 3.6e6


@dataclass
class ElectricalRun:
    """One executed run's electrical power in its path window: t (N,) [s] from the path start,
    total power per bus mode {mode: (N,)} [W], axis power (N, n) [W] (from the DC bus, without
    standby), energy per bus mode {mode: J}, standby energy [J], duration [s]."""

    label: str
    bag: str
    t: np.ndarray
    total: dict
    axis_power: np.ndarray
    energy: dict = field(default_factory=dict)
    standby: float = float('nan')
    duration: float = float('nan')
    standby_power: float = float('nan')

    def cycle_energy(self, mode: str, cycle_s: float) -> float:
        """Energy of one cycle of ``cycle_s`` [s] (the planned duration) [J]: the measured
        energy without the standby of the path window, plus standby x cycle_s. The path
        window (controller in MODE_PATH) differs between runs of the same planned duration
        by up to 0.15 s (how fast each leaves rest), and 270 W of standby made that 1.7 %."""
        return self.energy[mode] - self.standby + self.standby_power * float(cycle_s)


def electrical_figures(bag: str | Path, label: str, standby_power_w: float,
                       window: tuple[float, float] | None = None) -> ElectricalRun:
    """The electrical power and energy of a run's path phase from the bag's
    ``/electrical_power``; ``window``: (start, end) [s] of the path phase (None: from the
    bag's own /controller_state, run_report.path_window); raises ValueError
    (bagio.BagError) naming the problem."""
    from irb_identification.bagio import read_messages, typestore
    t0, t1 = window if window is not None else path_window(bag)
    store = typestore([JOINT_STATE])
    raw = read_messages(bag, ['/electrical_power'])['/electrical_power']
    msgs = [store.deserialize_cdr(d, raw.msgtype) for d in raw.data]
    if not msgs:
        raise ValueError(f'bag {bag}: /electrical_power has no messages')
    stamps = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in msgs])
    order = np.argsort(stamps, kind='stable')
    stamps = stamps[order]
    msgs = [msgs[i] for i in order]
    check_gap(stamps, t0, t1, '/electrical_power', bag)
    inside = (stamps >= t0) & (stamps <= t1)
    if inside.sum() < 2:
        raise ValueError(f'bag {bag}: no electrical_power samples in the path window')
    names = list(msgs[0].name)
    missing = [f'total_{m}' for m in BUS_MODES if f'total_{m}' not in names]
    if missing:
        raise ValueError(f'bag {bag}: electrical_power lacks {missing} (has {names})')
    eff = np.array([np.asarray(m.effort, float) for m, ok in zip(msgs, inside) if ok])
    t = stamps[inside] - t0
    total = {m: eff[:, names.index(f'total_{m}')] for m in BUS_MODES}
    axes = [i for i, n in enumerate(names) if not n.startswith('total_')]
    return ElectricalRun(label, str(bag), t, total, eff[:, axes],
                         {m: float(np.trapezoid(p, t)) for m, p in total.items()},
                         float(standby_power_w) * float(t[-1] - t[0]), float(t[-1] - t[0]),
                         float(standby_power_w))


def check_duty(duty: dict, cycle_s: float) -> None:
    """ValueError if the duty cycle is malformed or does not fit an hour."""
    for key in ('cycles_per_hour', 'hours_per_year', 'price_per_kwh'):
        v = duty.get(key)
        if not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0:
            raise ValueError(f'duty_cycle.{key} must be a number >= 0, got {v!r}')
    if duty['hours_per_year'] > 8760:
        raise ValueError(f'duty_cycle.hours_per_year {duty["hours_per_year"]} > 8760')
    if duty['cycles_per_hour'] * cycle_s > 3600.0:
        raise ValueError(f'duty_cycle: {duty["cycles_per_hour"]} cycles of {cycle_s:g} s do '
                         'not fit in an hour')


def per_year(energy_j: float, duty: dict) -> dict:
    """Energy per cycle [J, kWh], per year [kWh] and its cost [currency/year]."""
    kwh = energy_j / J_PER_KWH
    year = kwh * float(duty['cycles_per_hour']) * float(duty['hours_per_year'])
    return {'cycle_j': float(energy_j), 'cycle_kwh': kwh, 'year_kwh': year,
            'year_cost': year * float(duty['price_per_kwh'])}


def plot_electrical(runs: list[ElectricalRun], mode: str, path: Path) -> str:
    """PNG: the robot's electrical power (bus mode ``mode``) over the cycle, one line a run,
    and the mechanical-side motor share (sum of the axis powers) dashed."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(8, 3.8))
    for r in runs:
        line, = ax.plot(r.t, r.total[mode], label=f'{r.label}: {r.energy[mode]:.0f} J')
        ax.plot(r.t, r.axis_power.sum(axis=1), '--', color=line.get_color(), lw=0.8,
                label=f'{r.label}: axes only (no standby)')
    ax.set(xlabel='time from path start [s]', ylabel='electrical power [W]',
           title=f'Electrical power from the grid, DC bus "{mode}" (plant parameters)')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


def _f(x: float, fmt: str = '.1f') -> str:
    return '–' if x is None or x != x else format(x, fmt)


def _pct(opt: float, base: float) -> str:
    return _f(saving_percent(opt, base)) + ' %'


def electrical_section(runs: dict, mech: dict, planned: dict, mode: str, plot: str,
                       rel, cycle_s: float) -> list[str]:
    """Markdown of the electrical energy: ``runs`` {label: ElectricalRun} executed, ``mech``
    {label: executed mechanical J}, ``planned`` {name: {'mechanical': J, 'none': J, ...}}
    (the planner's own electrical model), ``mode`` the plant's bus mode, ``cycle_s`` the
    planned duration [s]."""
    opt, trap = runs['energy_ff'], runs['trapezoid_ff']
    rows = [f'| {name} | {r.duration:.2f} | {mech[k]:.1f} | '
            + ' | '.join(f'{r.energy[m]:.1f}' for m in BUS_MODES)
            + f' | {r.standby:.0f} | {r.cycle_energy(mode, cycle_s):.1f} |'
            for k, name, r in (
                ('energy_ff', 'energy-optimal timing, thesis placement', opt),
                ('trapezoid_ff', 'trapezoid, thesis placement', trap),
                *([('best_energy_ff', 'energy-optimal timing, best placement',
                    runs['best_energy_ff'])] if 'best_energy_ff' in runs else []))]
    sav = ' / '.join(f'{m} {_pct(opt.cycle_energy(m, cycle_s), trap.cycle_energy(m, cycle_s))}'
                     for m in BUS_MODES)
    motors = {k: {m: r.energy[m] - r.standby for m in BUS_MODES} for k, r in runs.items()}
    same = all(max(r.energy.values()) - min(r.energy.values()) < 1e-6 for r in runs.values())
    low = min(float(r.axis_power.min()) for r in runs.values())
    regen = ('All three bus modes give the same figures here: no axis fed power back to the '
             'DC bus on these motions (copper, gear and drive losses exceed the generated '
             f'power; lowest axis power {low:.1f} W), so a shared or regenerative bus would '
             'save nothing on them.' if same else '')
    prow = [f'| {name} | {_f(v.get("mechanical"))} | '
            + ' | '.join(_f(v.get(m)) for m in BUS_MODES) + ' |' for name, v in planned.items()]
    return [
        '## Electrical energy (executed, simulated plant)', '',
        'From the simulator\'s `electrical_power` recorded in each bag (plant parameters, '
        'irb_control config/plant_electrical.yaml, on purpose not the planner\'s), integrated '
        f'over the path window; the plant\'s DC bus is `{mode}`, the other modes are the same '
        'run under the other bus topologies. Standby (controller, fans, brakes released) is '
        'included. Per cycle: the measured energy without the path window\'s standby, plus '
        f'standby for the planned {cycle_s:g} s (the windows of runs of the same planned '
        'duration differ by up to 0.15 s, how fast each leaves rest: at '
        f'{opt.standby_power:.0f} W that alone would be ~1.5 %).', '',
        '| run | path window [s] | mechanical ∫Σ\\|τq̇\\|dt [J] | electrical, bus none [J] | '
        f'shared [J] | regenerative [J] | of which standby [J] | per {cycle_s:g} s cycle, '
        f'bus {mode} [J] |',
        '|---|---|---|---|---|---|---|---|', *rows, '',
        f'**Electrical saving per cycle of the optimal timing against the trapezoid (same '
        f'duration, thesis placement): {sav}**; without standby (motors, gears, drives, the '
        f'drives\' idle power over each path window; bus `{mode}`): '
        f'{_pct(motors["energy_ff"][mode], motors["trapezoid_ff"][mode])} '
        f'({motors["energy_ff"][mode]:.1f} vs {motors["trapezoid_ff"][mode]:.1f} J). {regen}',
        '',
        'Planned (the planner\'s electrical model, irb_description config/electrical.yaml; '
        'independent check of the trajectory as played):', '',
        '| plan | mechanical [J] | electrical none [J] | shared [J] | regenerative [J] |',
        '|---|---|---|---|---|', *prow, '',
        f'![electrical power]({rel(plot)})', '']


def placement_section(p: dict, plot: str | None, rel) -> list[str]:
    """Markdown of the placement search; ``p`` the summary's ``placement`` block."""
    lo, hi = p['region_lo_m'], p['region_hi_m']
    size = ' x '.join(f'{h - l:.2f}' for l, h in zip(lo, hi))
    head = ['## Best placement of the circle inside the region', '',
            f'Region for the circle\'s centre: box {lo} .. {hi} m ({size} m) around the '
            f'thesis centre {p["thesis_center_m"]} m, horizontal circle, radius '
            f'{p["radius_m"]} m, {p["duration_s"]:g} s. Search (irb_planning.placement): '
            f'grid {p["grid"]} of centres planned energy-optimally ({p["measure"]} energy) on '
            f'{p["coarse_grid"]} θ nodes, the best {p["refine"]} re-planned on the full grid, '
            f'then a compass search down to {p["min_step_m"]} m; {p["evaluations"]} plans in '
            f'{p["wall_time_s"]:.0f} s.', '']
    if p.get('error'):
        return head + [f'**No placement found: {p["error"]}**', '',
                       f'Unreachable grid points: {p["unreachable"]} of {p["grid_points"]}.',
                       *[f'- {r}' for r in p.get('reasons', [])], '']
    base = p['trapezoid_thesis']
    best = p['best']
    exe = p.get('executed') or {}
    lines = head + [
        f'**Best centre {np.round(best["center_m"], 3).tolist()} m**; unreachable grid '
        f'points: {p["unreachable"]} of {p["grid_points"]} (shown as red crosses in the map):',
        '', *[f'- {r}' for r in p.get('reasons', [])], '',
        '| plan (same duration) | mechanical [J] | electrical none [J] | shared [J] | '
        'regenerative [J] |', '|---|---|---|---|---|',
        *[f'| {name} | {_f(v["mechanical"])} | '
          + ' | '.join(_f(v[m]) for m in BUS_MODES) + ' |'
          for name, v in (('trapezoid, thesis placement (planned)', base),
                          ('energy-optimal, thesis placement (planned)', p['optimal_thesis']),
                          ('energy-optimal, best placement (planned)', best))], '',
        f'**Best placement + optimal timing against the trapezoid at the thesis placement: '
        f'{_pct(best["mechanical"], base["mechanical"])} mechanical, '
        + ', '.join(f'{_pct(best[m], base[m])} electrical {m}' for m in BUS_MODES)
        + ' (planned).**', '']
    worse = [m for m in BUS_MODES if best[m] > p['optimal_thesis'][m]]
    if p['measure'] == 'mechanical' and worse:
        lines += [f'The search minimised the mechanical energy; its best centre draws more '
                  f'electrical energy than the optimal timing at the thesis placement (bus '
                  f'{", ".join(worse)}: the losses, not the mechanical work, set that '
                  'figure), so for the electricity bill the search must run on the electrical '
                  'model (`placement.energy_model: electrical_<bus>`, about 4 x the time per '
                  'plan).', '']
    if exe:
        lines += [f'Executed on the simulator (bag `{exe["bag"]}`, pdplus following the '
                  f'circle at the best centre, identified compensation): {exe["mechanical"]:.1f}'
                  f' J mechanical, {exe["electrical"]:.1f} J electrical per cycle (bus '
                  f'`{exe["mode"]}`), against the executed trapezoid at the thesis placement: '
                  f'{_pct(exe["mechanical"], exe["trapezoid_mechanical"])} mechanical, '
                  f'{_pct(exe["electrical"], exe["trapezoid_electrical"])} electrical; camera '
                  f'path error mean {exe["path_error_mean_mm"]:.3f} mm.', '']
    else:
        lines += ['Not executed on the simulator: the figures above are the planner\'s, '
                  'independently checked on the trajectory as played.', '']
    cert = p['certificate']
    if cert['cells_covered']:
        lines += [f'Certificate (the search\'s grid + measured Lipschitz bound over the '
                  f'{cert["cells_covered"]} of {cert["cells_total"]} grid cells whose corners '
                  f'are all reachable): no centre there below {cert["lower_bound_j"]:.1f} J, '
                  f'i.e. at most {cert["possible_improvement_pct"]:.1f} % better than the '
                  'best found.', '']
    else:
        lines += [f'Certificate: none of the {cert["cells_total"]} grid cells has all its '
                  'corners reachable, so the search claims no bound over the region (a finer '
                  'grid, e.g. irb_planning `place`, gives one).', '']
    lines += evidence_lines(p)
    if plot:
        lines += [f'![placement map]({rel(plot)})', '']
    return lines


def evidence_lines(p: dict) -> list[str]:
    """Markdown of the search's evidence (``placement_study``'s ``evidence``): the
    multi-start spread, what the convex bounds rule out at the planned points, and the
    electrical cap that holds over the whole region."""
    ev = p.get('evidence') or {}
    if not ev:
        return []
    lines = []
    ends = [s for s in ev['starts'] if np.isfinite(s['end_energy'])]
    if len(ev['starts']) > 1:
        lines += [f'Multi-start: compass searches from {len(ev["starts"])} starts (the coarse '
                  f'map\'s local minima first) ended at '
                  + ', '.join(f'{np.round(s["end_center_m"], 3).tolist()} m '
                              f'({s["end_energy"]:.2f} J)' for s in ends)
                  + f'; none below the best, the others at most {ev["spread_pct"]:.2f} % above '
                  'it: the best is the lowest of the basins this grid resolves (evidence, not '
                  'a bound: a basin narrower than the grid spacing would be missed).', '']
    if np.isfinite(ev['grid_bound_floor_j']):
        lines += [f'Convex lower bound of every timing (irb_planning `Planner.bound`) at each '
                  f'of the {ev["bound_points"]} planned map points and at the best placement: '
                  f'at least {ev["grid_bound_floor_j"]:.2f} J ({ev["measure"]}), so **no '
                  f'timing at any of them saves more than '
                  f'{ev["max_saving_any_timing_pct"]:.1f} %** against the trapezoid at the '
                  f'thesis placement ({ev["reference_j"]:.2f} J). A claim at those points '
                  'only: between them the bounds are as steep as the energies.', '']
    elif ev.get('bounds_requested'):
        lines += ['Convex lower bounds: none for this friction map. The relaxation knows only '
                  'the parametric friction, and the map has polynomial branches that the plans '
                  'use, so a bound from its parametric part would not bound them (irb_planning '
                  'README, placement evidence, has them for the nominal map).', '']
    cap = ev['electrical_cap_pct']
    lines += [f'Electrical cap, for the whole region: every {p["duration_s"]:g} s plan pays '
              f'the standby and drive idle energy {ev["fixed_electrical_j"]:.0f} J in every '
              'bus mode whatever its placement and timing (irb_planning '
              '`placement.fixed_electrical_energy`: the rest is the net work on the arm, >= 0 '
              'over a closed rest-to-rest cycle), so **no placement or timing saves more than '
              + ', '.join(f'{cap[m]:.1f} % ({m})' for m in BUS_MODES)
              + '** of the electrical energy against the trapezoid at the thesis placement.',
              '']
    return lines


def duty_section(duty: dict, rows: list[tuple], measure: str) -> list[str]:
    """Markdown of the per-cycle / per-year figures; rows (name, per_year(electrical),
    per_year(mechanical))."""
    base = rows[0][1]
    cur = duty.get('currency', 'EUR')
    return [
        '## Per cycle and per year', '',
        f'Duty cycle: {duty["cycles_per_hour"]:g} cycles per hour, {duty["hours_per_year"]:g} '
        f'hours per year, {duty["price_per_kwh"]:g} {cur}/kWh; one cycle = one lap of the '
        f'circle (standby between cycles not included). Electrical: {measure}.', '',
        '| motion | electrical per cycle [J] | [kWh] | per year [kWh] | cost per year '
        f'[{cur}] | saving per year [{cur}] | mechanical per year [kWh] |',
        '|---|---|---|---|---|---|---|',
        *[f'| {name} | {e["cycle_j"]:.1f} | {e["cycle_kwh"]:.6f} | {e["year_kwh"]:.1f} | '
          f'{e["year_cost"]:.2f} | {base["year_cost"] - e["year_cost"]:.2f} | '
          f'{m["year_kwh"]:.2f} |' for name, e, m in rows], '']


def plan_figures(result) -> dict:
    """{'mechanical': J, 'none': J, 'shared': J, 'regenerative': J} of a PlanResult, from
    its independent check of the trajectory as played (placement.plan_energy per model)."""
    from irb_planning.placement import plan_energy
    return {'mechanical': plan_energy(result, 'mechanical'),
            **{m: plan_energy(result, f'electrical_{m}') for m in BUS_MODES}}


def placement_study(cfg: dict, friction_map: str | Path, plot_dir: Path, progress,
                    bus_mode: str) -> dict:
    """Phase 6 of the main job, in process (irb_planning's Planner with ``friction_map``,
    the identified map; '' or None: the nominal one): the thesis circle planned
    energy-optimally and as the trapezoid (and, if ``cfg['electrical_objective']``,
    minimising the electrical energy of bus ``bus_mode``), then ``placement.search`` over the
    config's region; the map PNG in ``plot_dir``. Returns the summary's ``placement`` block
    (with ``error`` if no placement is reachable); ValueError on a malformed region."""
    import time
    from dataclasses import replace

    from irb_planning.placement import (PLACEMENT_MIN_DURATION_CHECK_FACTOR, Region,
                                        fixed_electrical_energy, placement_request, plot_map,
                                        search)
    from irb_planning.planner import Planner, PlannerSettings
    from irb_planning.request import PlanError, PlanRequest
    pl = cfg['placement']
    region = Region(np.asarray(pl['lo_m'], float), np.asarray(pl['hi_m'], float))
    n = tuple(int(k) for k in pl['n'])
    if len(n) != 3 or min(n) < 1:
        raise ValueError(f'placement.n must be 3 integers >= 1, got {pl["n"]}')
    center = np.asarray(cfg['center_m'], float)
    t0 = time.perf_counter()
    planner = Planner(settings=PlannerSettings(friction_map_dirs=(
        (str(Path(friction_map).resolve().parent),) if friction_map else ()),
        min_duration_check_factor=PLACEMENT_MIN_DURATION_CHECK_FACTOR,
        limit_cost=False))      # the search's many plans: no cost-of-the-limits solve
    task = PlanRequest(radius=float(cfg['radius_m']), direction=1,
                       duration=float(cfg['circle_duration_s']),
                       grid_size=int(cfg['planner_grid']),
                       friction_map=str(friction_map) if friction_map else '',
                       energy_model=str(pl.get('energy_model', 'mechanical')))
    at_thesis = placement_request(task, center)
    out = {'region_lo_m': np.asarray(pl['lo_m'], float).tolist(),
           'region_hi_m': np.asarray(pl['hi_m'], float).tolist(),
           'thesis_center_m': center.tolist(), 'radius_m': float(cfg['radius_m']),
           'duration_s': float(cfg['circle_duration_s']), 'grid': list(n),
           'grid_points': int(np.prod(n)), 'coarse_grid': int(pl['coarse_grid']),
           'refine': int(pl['refine']), 'min_step_m': float(pl['min_step_m']),
           'measure': task.energy_model,
           'optimal_thesis': plan_figures(planner.plan(at_thesis)),
           'trapezoid_thesis': plan_figures(planner.plan(replace(at_thesis,
                                                                 objective='trapezoid')))}
    progress(f'   thesis placement planned: optimal {out["optimal_thesis"]["mechanical"]:.2f} J'
             f', trapezoid {out["trapezoid_thesis"]["mechanical"]:.2f} J mechanical '
             f'({time.perf_counter() - t0:.0f} s)')
    if cfg.get('electrical_objective'):
        model = f'electrical_{bus_mode}'
        try:
            out['electrical_objective'] = {'energy_model': model, **plan_figures(
                planner.plan(replace(at_thesis, energy_model=model)))}
        except PlanError as exc:
            out['electrical_objective'] = {'energy_model': model, 'error': exc.message}
        progress(f'   thesis placement, optimal for the electrical model ({model}): '
                 + (f'{out["electrical_objective"][bus_mode]:.1f} J electrical'
                    if bus_mode in out['electrical_objective']
                    else out['electrical_objective']['error'])
                 + f' ({time.perf_counter() - t0:.0f} s)')
    res = search(planner, task, region, n, int(pl['coarse_grid']), int(pl['refine']),
                 float(pl['min_step_m']), progress=lambda s: progress(f'   {s}'),
                 bounds=bool(pl.get('bounds', False)), starts=int(pl.get('starts', 1)))
    out.update(evaluations=int(res.evaluations) + 2 + bool(cfg.get('electrical_objective')),
               wall_time_s=time.perf_counter() - t0, unreachable=len(res.reasons),
               reasons=[f'{np.round([res.xs[i], res.ys[j], res.zs[k]], 3).tolist()} m: {r}'
                        for (i, j, k, _), r in sorted(res.reasons.items())],
               certificate={'lower_bound_j': float(res.region_lower_bound),
                            'possible_improvement_pct': float(res.possible_improvement_pct),
                            'cells_covered': int(res.cells_covered),
                            'cells_total': int(res.cells_total)})
    if res.best_center is None:
        out['error'] = (f'no reachable placement in the region: all {out["grid_points"]} grid '
                        'points refused' if len(res.reasons) == out['grid_points']
                        else 'no map point could be re-planned on the full grid')
        return out
    plot_dir.mkdir(parents=True, exist_ok=True)
    out['plot'] = plot_map(str(plot_dir / 'placement.png'), res,
                           f'{res.measure} energy of the optimal {task.duration:g} s circle '
                           'over the region (red x: unreachable)')
    out['best'] = {'center_m': np.asarray(res.best_center, float).tolist(),
                   'search_energy_j': float(res.best_energy), **plan_figures(res.best_plan)}
    out['evidence'] = search_evidence(res, out, fixed_electrical_energy(
        planner.electrical, task.duration))
    out['evidence']['bounds_requested'] = bool(pl.get('bounds', False))
    return out


def search_evidence(res, out: dict, fixed_electrical_j: float) -> dict:
    """The summary's ``evidence`` of a search ``res`` (irb_planning PlacementResult):
    per start its end and energy, the spread [%], the convex bounds' floor over the planned
    points [J] (NaN without bounds) and the largest saving any timing there could reach
    against the trapezoid at the thesis placement in the search's measure [%], the fixed
    electrical energy [J] and the electrical cap per bus mode [%] (module docs of
    irb_planning.placement)."""
    measure = res.measure or 'mechanical'
    key = 'mechanical' if measure == 'mechanical' else measure.split('_', 1)[1]
    ref = float(out['trapezoid_thesis'][key])
    floor = float(res.grid_bound_floor)
    if np.isfinite(res.best_lower_bound):
        floor = min(floor, float(res.best_lower_bound))
    bound_points = (int(np.isfinite(res.lower_bounds).sum())
                    if res.lower_bounds is not None else 0)
    return {'starts': [{'start_center_m': s['start_center'],
                        'end_center_m': s['end_center'],
                        'end_energy': float(s['end_energy'])} for s in res.starts],
            'spread_pct': float(res.multistart_spread_pct), 'measure': measure,
            'reference_j': ref, 'grid_bound_floor_j': floor, 'bound_points': bound_points,
            'max_saving_any_timing_pct': 100 * (1 - floor / ref),
            'fixed_electrical_j': float(fixed_electrical_j),
            'electrical_cap_pct': {m: 100 * (1 - fixed_electrical_j
                                             / out['trapezoid_thesis'][m])
                                   for m in BUS_MODES}}
