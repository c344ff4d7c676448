"""Execution and measurement of a planned work cycle (issue 29 item 4; no rclpy).

A cycle plan (``ros2 run irb_planning cycle --out D``: D/cycle_plan.json and the motions'
plan files) becomes a timed sequence of steps, repeated every takt:

    motion    send the motion's plan to pdplus (ahead of time: it waits pending), enable,
              wait until pdplus holds at the motion's end;
    station   at rest (rest steps merged): in the plan's power mode -- request the mode at
              once, request hold back so that the hold transition ends when the station
              ends, wait until the station's planned end in the cycle; a hold station waits.

Times are offsets from the cycle's start (the first motion's enable); a station ends at its
planned offset, so whatever the plan does not contain (pdplus's ramp from hold to the plan's
start, the latency of a request) is taken out of the following station, not added to the
cycle.

The measured energy is the simulator's ``electrical_power`` (``total_<bus>`` of the plan's
DC-bus mode, standby included), one sample per period holding for that period, summed over
each window (``window_energy``); a gap in the series is an error, never a smaller energy.
Each step is compared with the plan three ways (``compare_cycle``):

    planned     the plan's own figure (planner's electrical model, planned durations);
    predicted   the same step re-evaluated as it was executed (the executed durations and
                request times, the ramp at the hold power) on the PLANT's electrical model
                (the simulator's parameters): the plan's motion trajectory on the plant
                model, the stations' modes with the plant's standby and drive idle;
    measured    the integral of electrical_power over the step's window.

so that measured - planned splits into named terms: ``electrical_parameters`` (plant vs
planner model at the planned timing), ``timing`` (executed vs planned durations: ramps,
request latency, taken out of the stations) and ``execution`` (measured - predicted: the
plant's friction and the controller's tracking against the plan's torques, the modes'
transitions as the drive does them).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

MOTION, STATION = 'motion', 'station'
HOLD = 'hold'


class CycleRunError(ValueError):
    """A plan or a series that cannot be used; the message is one line."""


# --- the plan ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class PlanStep:
    """One step of the planned cycle: kind (MOTION, STATION), name, planned duration [s] and
    energy [J]; a motion's plan file, path spec (no process block), trajectory (t, q, qd,
    tau arrays); a station's power mode and hold power at its pose [W]."""

    kind: str
    name: str
    duration_s: float
    energy_j: float
    mode: str = HOLD
    holding_power_w: float = 0.0
    plan_file: str = ''
    path_spec: dict = field(default_factory=dict)
    trajectory: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def q_start(self) -> np.ndarray:
        return np.asarray(self.trajectory['q'][0], float)

    @property
    def q_end(self) -> np.ndarray:
        return np.asarray(self.trajectory['q'][-1], float)


@dataclass(frozen=True)
class CyclePlanRun:
    """A cycle plan as executed: takt [s], DC-bus mode of its energy model, total planned
    energy [J], steps (starting with a motion), the cycle file and power-modes file."""

    takt_s: float
    bus: str
    energy_j: float
    steps: tuple
    cycle_file: str = ''
    power_modes_file: str = ''
    source: str = ''
    electrical_config: str = ''      # the planner's electrical model ('' = irb_description's)

    @property
    def motions(self) -> list:
        return [s for s in self.steps if s.kind == MOTION]

    def offsets(self) -> list:
        """Planned start offset of each step in the cycle [s]."""
        out, t = [], 0.0
        for s in self.steps:
            out.append(t)
            t += s.duration_s
        return out


def load_plan(path) -> CyclePlanRun:
    """Read ``cycle_plan.json`` (or the directory holding it) and the motions' plan files;
    CycleRunError (one line) if they cannot be used."""
    p = Path(path)
    f = p / 'cycle_plan.json' if p.is_dir() else p
    try:
        data = json.loads(f.read_text())
    except OSError as exc:
        raise CycleRunError(f'cannot read the cycle plan {f}: {exc.strerror} (write one '
                            'with: ros2 run irb_planning cycle --cycle C --out D)') from None
    except ValueError as exc:
        raise CycleRunError(f'cycle plan {f} is not JSON: {exc}') from None
    try:
        takt = float(data['takt_s'])
        ops = list(data['operations'])
        model = str(data.get('energy_model', 'electrical_shared'))
    except (KeyError, TypeError, ValueError):
        raise CycleRunError(f'{f} is not a cycle plan (needs takt_s, operations, '
                            'energy_model: the output of irb_planning cycle)') from None
    if not model.startswith('electrical_'):
        raise CycleRunError(f'{f}: energy_model {model!r} is not electrical_<bus>')
    steps = []
    for c in ops:
        kind = c.get('kind')
        if kind == MOTION:
            pf = Path(c.get('plan_file', ''))
            if not pf.is_absolute() or not pf.is_file():
                pf = f.parent / 'motions' / f'{c["name"]}.plan.json'
            try:
                pj = json.loads(pf.read_text())
                spec_file = pf.parent / pj['path_file']
                import yaml
                spec = yaml.safe_load(spec_file.read_text())
                tr = {k: np.asarray(pj['trajectory'][k], float) for k in ('t', 'q', 'qd', 'qdd')}
                tr['tau'] = np.asarray(pj['trajectory']['tau'], float)
            except (OSError, KeyError, ValueError, TypeError) as exc:
                raise CycleRunError(f'{f}: motion {c.get("name")}: its plan file {pf} '
                                    f'cannot be used ({type(exc).__name__}: '
                                    f'{str(exc)[:100]})') from None
            spec = {k: v for k, v in spec.items() if k != 'process'}
            steps.append(PlanStep(MOTION, str(c['name']), float(c['duration_s']),
                                  float(c['energy_j']), plan_file=str(pf), path_spec=spec,
                                  trajectory=tr))
        elif kind == STATION:
            steps.append(PlanStep(STATION, str(c['name']), float(c['duration_s']),
                                  float(c['energy_j']), mode=str(c.get('mode') or HOLD),
                                  holding_power_w=float(c['holding_power_w'])))
        else:
            raise CycleRunError(f'{f}: operation {c.get("name")!r} of unknown kind {kind!r}')
    if not steps or not any(s.kind == MOTION for s in steps):
        raise CycleRunError(f'{f}: the plan has no motion')
    k0 = next(i for i, s in enumerate(steps) if s.kind == MOTION)
    steps = steps[k0:] + steps[:k0]
    total = sum(s.duration_s for s in steps)
    if abs(total - takt) > 1e-6:
        raise CycleRunError(f'{f}: the steps last {total:.6f} s, not the takt {takt:g} s')
    pm_file = ''
    cf = data.get('cycle_file', '')
    if cf and Path(cf).is_file():
        try:
            import yaml
            pm_file = str((yaml.safe_load(Path(cf).read_text()) or {}).get('power_modes')
                          or '')
        except (OSError, ValueError):
            pm_file = ''
    return CyclePlanRun(takt, model.split('_', 1)[1], float(data['energy_j']), tuple(steps),
                        str(cf), pm_file, str(f), str(data.get('electrical_config', '') or ''))


# --- the timed sequence -----------------------------------------------------------------------
@dataclass(frozen=True)
class Action:
    """One thing the executor does, at ``t_s`` [s] after the cycle's start (or as soon as the
    previous action is done, if later): 'send' (motion plan ``step`` to pdplus), 'enable'
    (start motion ``step``, wait until it holds at its end), 'mode' (request power mode
    ``mode`` from pdplus), 'wait' (until t_s), 'released' (wait until the brakes are
    released and pdplus holds)."""

    kind: str
    step: int
    t_s: float = 0.0
    mode: str = ''


def schedule(plan: CyclePlanRun, modes) -> list:
    """The actions of one cycle (``modes``: irb_description PowerModes, for the hold
    transitions' durations). Each motion's plan is sent while the step before it runs."""
    steps, offs = plan.steps, plan.offsets()
    n = len(steps)
    acts = []
    for i, s in enumerate(steps):
        if s.kind == MOTION:
            acts.append(Action('enable', i, offs[i]))
            nxt = next((j for j in list(range(i + 1, n)) + list(range(0, i + 1))
                        if steps[j].kind == MOTION), i)
            acts.append(Action('send', nxt, offs[i]))
            continue
        end = offs[i] + s.duration_s
        if s.mode != HOLD:
            t_out = modes.transition(s.mode, HOLD).duration_s
            acts.append(Action('mode', i, offs[i], s.mode))
            acts.append(Action('mode', i, end - t_out, HOLD))
            acts.append(Action('released', i, end - t_out))
        acts.append(Action('wait', i, end))
    return acts


# --- the measured series ----------------------------------------------------------------------
def window_energy(t: np.ndarray, p: np.ndarray, t0: float, t1: float, period_s: float
                  ) -> float:
    """Energy [J] of the power samples p (W) stamped t (s; each holding for one period) in the
    window [t0, t1): whole samples inside plus the partial ones at the edges. CycleRunError
    if the window is not covered or has a gap of more than 1.5 periods."""
    t = np.asarray(t, float)
    p = np.asarray(p, float)
    if t1 < t0:
        raise CycleRunError(f'window [{t0:.4f}, {t1:.4f}) s ends before it starts')
    if t1 == t0:
        return 0.0
    i0 = int(np.searchsorted(t, t0, side='right')) - 1
    i1 = int(np.searchsorted(t, t1, side='left'))
    if i0 < 0 or t[-1] + period_s < t1 - 1e-9:
        raise CycleRunError(f'electrical_power does not cover [{t0:.4f}, {t1:.4f}) s '
                            f'(samples {t[0] if t.size else math.nan:.4f} .. '
                            f'{t[-1] if t.size else math.nan:.4f} s)')
    ts = t[i0:i1]
    gaps = np.diff(ts)
    if gaps.size and gaps.max() > 1.5 * period_s:
        k = int(np.argmax(gaps))
        raise CycleRunError(f'electrical_power has a gap of {gaps[k]:.4f} s at '
                            f'{ts[k]:.4f} s: energy not measured')
    ends = np.minimum(np.append(ts[1:], ts[-1] + period_s), t1)
    starts = np.maximum(ts, t0)
    return float(np.sum(p[i0:i1] * np.clip(ends - starts, 0.0, None)))


def first_gap(t: np.ndarray, period_s: float) -> tuple[float, float] | None:
    """(start, length) [s] of the first gap of more than 1.5 periods in stamps t, or None."""
    d = np.diff(np.asarray(t, float))
    k = np.flatnonzero(d > 1.5 * period_s)
    return None if not k.size else (float(t[k[0]]), float(d[k[0]]))


# --- predictions --------------------------------------------------------------------------
def resample_energy(traj: dict, electrical, bus: str, rate_hz: float = 1000.0) -> float:
    """Electrical energy [J] of a plan's trajectory points (t, q, qd, tau) on ``electrical``,
    interpolated linearly at ``rate_hz`` and integrated (trapezoid)."""
    t = np.asarray(traj['t'], float)
    tt = np.linspace(t[0], t[-1], max(int((t[-1] - t[0]) * rate_hz) + 1, 2))
    qd = np.column_stack([np.interp(tt, t, c) for c in np.asarray(traj['qd'], float).T])
    tau = np.column_stack([np.interp(tt, t, c) for c in np.asarray(traj['tau'], float).T])
    return electrical.energy(tt, tau, qd, bus)


@dataclass
class Models:
    """What predictions need: the planner's and the plant's electrical models (3 axes), the
    power modes on each, and the gravity torque g(q) [N m] of the model."""

    planner_electrical: object
    plant_electrical: object
    planner_modes: object
    plant_modes: object
    gravity: object

    def hold_power(self, q, plant: bool = True) -> float:
        from irb_description.power_modes import holding_power_w
        e = self.plant_electrical if plant else self.planner_electrical
        return holding_power_w(e, np.asarray(self.gravity(np.asarray(q, float)), float))


def load_models(power_modes_file: str = '', plant_electrical_file: str = '',
                planner_electrical_file: str = '') -> Models:
    """The planner's electrical model (the given file, else irb_description's
    config/electrical.yaml), the plant's (irb_control config/plant_electrical.yaml or the
    given file), power modes on both."""
    from irb_description.electrical import load_electrical
    from irb_description.model import RobotModel
    from irb_description.power_modes import load_power_modes
    model = RobotModel.load()
    n = len(model.joint_names)
    nom = load_electrical(Path(planner_electrical_file) if planner_electrical_file
                          else None).axes(n)
    if plant_electrical_file:
        pf = Path(plant_electrical_file)
    else:
        from ament_index_python.packages import get_package_share_directory
        pf = Path(get_package_share_directory('irb_control')) / 'config' / \
            'plant_electrical.yaml'
    plant = load_electrical(pf).axes(n)
    pm = power_modes_file or None
    return Models(nom, plant, load_power_modes(pm, electrical=nom),
                  load_power_modes(pm, electrical=plant), model.gravity)


def station_prediction(modes, mode: str, hold_w: float, t0: float, t1: float,
                       t_mode: float | None, t_hold: float | None) -> float:
    """Energy [J] of a station [t0, t1) on ``modes``: hold until the mode request t_mode,
    the transition in, the mode, the transition out from the hold request t_hold, hold
    until t1 (hold: hold_w (t1 - t0))."""
    if mode == HOLD or t_mode is None or t_hold is None:
        return hold_w * (t1 - t0)
    tin = modes.transition(HOLD, mode, hold_w)
    tout = modes.transition(mode, HOLD, hold_w)
    dwell = max(t_hold - t_mode - tin.duration_s, 0.0)
    after = max(t1 - t_hold - tout.duration_s, 0.0)
    return (hold_w * max(t_mode - t0, 0.0) + tin.energy_j + modes.power_w(mode) * dwell
            + tout.energy_j + hold_w * after)


def motion_before(steps, i: int) -> PlanStep:
    """The motion before step i (cyclically): a station's pose is its end."""
    n = len(steps)
    return next(steps[(i - k) % n] for k in range(1, n + 1) if steps[(i - k) % n].kind == MOTION)


def plan_predictions(plan: CyclePlanRun, models: Models) -> list:
    """Per step, at the planned timing: the plan's energy re-evaluated on the planner's model
    (motions: its trajectory points; a check of the quadrature) and on the plant's."""
    out = []
    steps = plan.steps
    for i, s in enumerate(steps):
        if s.kind == MOTION:
            e_nom = resample_energy(s.trajectory, models.planner_electrical, plan.bus)
            e_pl = resample_energy(s.trajectory, models.plant_electrical, plan.bus)
            out.append({'planner_model_j': e_nom, 'plant_model_j': s.energy_j + e_pl - e_nom})
        else:
            prev = motion_before(steps, i)
            hp = models.hold_power(prev.q_end, plant=True)
            hn = models.hold_power(prev.q_end, plant=False)
            e_pl = (models.plant_modes.wait_energy_j(s.mode, s.duration_s, hp))
            e_nom = (models.planner_modes.wait_energy_j(s.mode, s.duration_s, hn))
            out.append({'planner_model_j': e_nom, 'plant_model_j': e_pl,
                        'holding_power_plant_w': hp, 'holding_power_planner_w': hn})
    return out


# --- the comparison -------------------------------------------------------------------------
@dataclass
class StepEvents:
    """What the executor saw of one step in one cycle, in simulated time [s]: the step's
    window [t0, t1); motions: the path's start (ramp before it); stations: the times the mode
    and hold were requested (None: not requested) and the brake release."""

    t0: float
    t1: float
    t_path: float | None = None
    t_mode: float | None = None
    t_hold: float | None = None


def compare_cycle(plan: CyclePlanRun, models: Models, preds: list, events: list,
                  t_cycle: tuple, series_t, series_p, period_s: float) -> dict:
    """One executed cycle against its plan: per step planned / predicted (plant model, as
    executed) / measured [J] and the terms; the cycle's totals over [t_cycle) (a window of
    one takt)."""
    rows = []
    steps = plan.steps
    for i, (s, ev, pr) in enumerate(zip(steps, events, preds)):
        meas = window_energy(series_t, series_p, ev.t0, ev.t1, period_s)
        d_exec = ev.t1 - ev.t0
        if s.kind == MOTION:
            ramp = (ev.t_path - ev.t0) if ev.t_path is not None else 0.0
            path_s = d_exec - ramp
            hp0 = models.hold_power(s.q_start)
            hp1 = models.hold_power(s.q_end)
            # the path as planned on the plant model, the ramp and any time after the path
            # (until the next step starts) at the plant's hold power of the poses
            extra = max(path_s - s.duration_s, 0.0)
            predicted = pr['plant_model_j'] + hp0 * ramp + hp1 * extra
            ramp_j = (window_energy(series_t, series_p, ev.t0, ev.t_path, period_s)
                      if ev.t_path is not None else 0.0)
            row = {'ramp_s': ramp, 'ramp_measured_j': ramp_j, 'path_s': path_s,
                   'path_measured_j': meas - ramp_j}
        else:
            prev = motion_before(steps, i)
            hp = models.hold_power(prev.q_end)
            predicted = station_prediction(models.plant_modes, s.mode, hp, ev.t0, ev.t1,
                                           ev.t_mode, ev.t_hold)
            row = {'mode': s.mode, 'holding_power_plant_w': hp,
                   'mode_requested_after_s': (ev.t_mode - ev.t0) if ev.t_mode else None,
                   'hold_requested_before_end_s': (ev.t1 - ev.t_hold) if ev.t_hold else None}
        row.update({'name': s.name, 'kind': s.kind, 'planned_s': s.duration_s,
                    'executed_s': d_exec, 'planned_j': s.energy_j,
                    'plant_model_planned_timing_j': pr['plant_model_j'],
                    'predicted_j': predicted, 'measured_j': meas,
                    'terms_j': {'electrical_parameters': pr['plant_model_j'] - s.energy_j,
                                'timing': predicted - pr['plant_model_j'],
                                'execution': meas - predicted},
                    'measured_vs_planned_percent': 100 * (meas / s.energy_j - 1)
                    if s.energy_j else None})
        rows.append(row)
    total = window_energy(series_t, series_p, t_cycle[0], t_cycle[1], period_s)
    pred = sum(r['predicted_j'] for r in rows)
    plant_planned = sum(p['plant_model_j'] for p in preds)
    return {'t0_s': t_cycle[0], 't1_s': t_cycle[1], 'measured_j': total,
            'planned_j': plan.energy_j, 'predicted_j': pred,
            'steps_measured_j': sum(r['measured_j'] for r in rows),
            'measured_vs_planned_percent': 100 * (total / plan.energy_j - 1),
            'measured_vs_predicted_percent': 100 * (total / pred - 1),
            'terms_j': {'electrical_parameters': plant_planned - plan.energy_j,
                        'timing': pred - plant_planned, 'execution': total - pred},
            'steps': rows}


def sag_at_release(t, q, t_release: float, t_end: float, settle_s: float = 0.0
                   ) -> np.ndarray:
    """Largest |q - q(t_release)| per joint [rad] over (t_release, t_end] in the joint
    series t (N,), q (N, 3): the pose the brakes held against the pose once the motors
    hold it."""
    t = np.asarray(t, float)
    q = np.asarray(q, float)
    i0 = int(np.searchsorted(t, t_release, side='right')) - 1
    i1 = int(np.searchsorted(t, t_end, side='right'))
    if i0 < 0 or i1 <= i0 + 1:
        raise CycleRunError(f'joint_states do not cover the brake release at '
                            f'{t_release:.4f} s')
    return np.max(np.abs(q[i0 + 1:i1] - q[i0]), axis=0)


def summarise(cycles: list, plan: CyclePlanRun, sags: list, stops: list, goal_pct: float = 2.0
              ) -> dict:
    """Figures over the executed cycles: measured vs planned per cycle (median, worst), the
    terms' medians, per-step medians, the largest sag, the stops."""
    if not cycles:
        return {'cycles': 0, 'stops': len(stops)}
    dev = np.array([c['measured_vs_planned_percent'] for c in cycles])
    devp = np.array([c['measured_vs_predicted_percent'] for c in cycles])
    worst = int(np.argmax(np.abs(dev)))
    terms = {k: float(np.median([c['terms_j'][k] for c in cycles]))
             for k in cycles[0]['terms_j']}
    steps = []
    for i, s in enumerate(plan.steps):
        rs = [c['steps'][i] for c in cycles]
        steps.append({'name': s.name, 'kind': s.kind, 'planned_j': s.energy_j,
                      'measured_median_j': float(np.median([r['measured_j'] for r in rs])),
                      'predicted_median_j': float(np.median([r['predicted_j'] for r in rs])),
                      'executed_median_s': float(np.median([r['executed_s'] for r in rs])),
                      'planned_s': s.duration_s,
                      'terms_median_j': {k: float(np.median([r['terms_j'][k] for r in rs]))
                                         for k in rs[0]['terms_j']}})
    sag = np.array(sags) if sags else np.zeros((0, 3))
    return {'cycles': len(cycles), 'takt_s': plan.takt_s, 'planned_j': plan.energy_j,
            'measured_median_j': float(np.median([c['measured_j'] for c in cycles])),
            'measured_vs_planned_percent': {'median': float(np.median(dev)),
                                            'worst': float(dev[worst]),
                                            'worst_cycle': worst},
            'measured_vs_predicted_percent': {'median': float(np.median(devp)),
                                              'worst': float(devp[np.argmax(np.abs(devp))])},
            'goal_percent': goal_pct, 'goal_met': bool(np.max(np.abs(dev)) <= goal_pct),
            'terms_median_j': terms, 'steps': steps,
            'sag_at_release_mrad': {'releases': int(sag.shape[0]),
                                    'max_per_joint': (sag.max(axis=0) * 1e3).tolist()
                                    if sag.size else None,
                                    'max': float(sag.max() * 1e3) if sag.size else None,
                                    'goal_mrad': 0.1,
                                    'goal_met': bool(sag.size == 0 or sag.max() <= 1e-4)},
            'stops': len(stops), 'stop_reasons': stops}


def markdown(result: dict) -> str:
    """The result as a short Markdown report."""
    s = result['summary']
    lines = [f'# Cycle run: {result.get("plan", "")}', '',
             f'{s["cycles"]} cycles of {s.get("takt_s", 0):g} s executed on the simulator '
             f'({result.get("sim_mode", "")}); {s["stops"]} latched stops. Load '
             f'{result.get("load", "")}.', '']
    if not s['cycles']:
        return '\n'.join(lines + ['No cycle completed.', ''])
    mp = s['measured_vs_planned_percent']
    lines += [f'Energy per cycle: planned {s["planned_j"]:.1f} J, measured median '
              f'{s["measured_median_j"]:.1f} J: {mp["median"]:+.2f} % (worst {mp["worst"]:+.2f} '
              f'%, cycle {mp["worst_cycle"]}); goal +-{s["goal_percent"]:g} %: '
              f'{"met" if s["goal_met"] else "NOT met"}. Against the plan re-evaluated on the '
              f'plant\'s electrical model as executed: '
              f'{s["measured_vs_predicted_percent"]["median"]:+.2f} % (median).', '',
              'Terms of measured - planned per cycle (median, J): '
              + ', '.join(f'{k} {v:+.1f}' for k, v in s['terms_median_j'].items()) + '.', '',
              '| step | kind | planned s | executed s | planned J | predicted J | measured J |'
              ' electrical params J | timing J | execution J |',
              '|---|---|---|---|---|---|---|---|---|---|']
    for r in s['steps']:
        t = r['terms_median_j']
        lines.append(f'| {r["name"]} | {r["kind"]} | {r["planned_s"]:.3f} | '
                     f'{r["executed_median_s"]:.3f} | {r["planned_j"]:.1f} | '
                     f'{r["predicted_median_j"]:.1f} | {r["measured_median_j"]:.1f} | '
                     f'{t["electrical_parameters"]:+.1f} | {t["timing"]:+.1f} | '
                     f'{t["execution"]:+.1f} |')
    sg = s['sag_at_release_mrad']
    lines += ['', f'Sag at brake release: {sg["releases"]} releases, largest '
              + (f'{sg["max"]:.4f} mrad (per joint '
                 f'{[round(x, 4) for x in sg["max_per_joint"]]})' if sg['max'] is not None
                 else 'n/a')
              + f'; goal <= {sg["goal_mrad"]} mrad: {"met" if sg["goal_met"] else "NOT met"}.',
              '']
    if s['stop_reasons']:
        lines += ['Stops: ' + '; '.join(s['stop_reasons']), '']
    if result.get('png'):
        lines += [f'![planned vs measured]({Path(result["png"]).name})', '']
    return '\n'.join(lines)


def plot(result: dict, out: Path) -> Path:
    """Planned / predicted / measured energy per step (medians) and per cycle."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    s = result['summary']
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.5))
    names = [r['name'] for r in s['steps']]
    x = np.arange(len(names))
    w = 0.27
    a1.bar(x - w, [r['planned_j'] for r in s['steps']], w, label='planned')
    a1.bar(x, [r['predicted_median_j'] for r in s['steps']], w,
           label='predicted (plant model, as executed)')
    a1.bar(x + w, [r['measured_median_j'] for r in s['steps']], w, label='measured')
    a1.set_xticks(x, names, rotation=15)
    a1.set_ylabel('energy per step [J] (median over cycles)')
    a1.legend(fontsize=8)
    cyc = result['cycles']
    k = np.arange(len(cyc))
    a2.plot(k, [c['measured_j'] for c in cyc], 'o-', label='measured')
    a2.plot(k, [c['predicted_j'] for c in cyc], 's--', label='predicted (plant model)')
    a2.axhline(s['planned_j'], color='k', label='planned')
    for f in (1 - s['goal_percent'] / 100, 1 + s['goal_percent'] / 100):
        a2.axhline(s['planned_j'] * f, color='k', ls=':', lw=0.8)
    a2.set_xlabel('cycle')
    a2.set_ylabel('energy per cycle [J]')
    a2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
