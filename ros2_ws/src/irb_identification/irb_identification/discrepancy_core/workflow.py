"""The discrepancy workflow end to end: bags + model -> report dict + updated model. No rclpy.

1. residuals of the nominal model on every bag (residuals.py; the smoothing window adapts to
   fast reversals), pooled (library.py); effects (``effects:``) and model errors
   (``model_errors:``) the model file already has are subtracted;
2. the fit part (time blocks of ``block_s`` with even index, or the bags not given as
   hold-out) feeds the forward selection (forward.py) over the candidates of terms.py: the 11
   physical effects not yet in the model, the model-error candidates, and refits of the known
   effects; each step adds the best eligible candidate with a joint refit of everything
   selected, until the next one is not significant on the held-out part or not supported by
   the block bootstrap;
3. what remains is compared with the noise floor per channel block (configured clean-data
   floor combined with the effort noise measured in the bags): blocks above
   ``unexplained_ratio`` x floor are reported as ``unexplained`` with where (speed, position,
   time, run);
4. the named terms are written with the model as one YAML: ``friction_map:`` (+ fitted
   Coulomb/viscous levels), ``effects:`` (known + named + refitted), ``model_errors:`` (torque
   gain, encoder scale, link inertial changes), loadable by the simulator
   (``plant_friction_file``) and the controller (``friction_map_file``);
5. held-out part: residual RMS before/after for every block (all joints and channels) and one
   noise-normalised reduction over all of them.
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from irb_control.plant_effects import (EFFECT_NAMES, PlantEffects, effect_to_dict,
                                       load_plant_effects, save_effects)
from irb_description.friction import load_friction_map

from ..gaps import GapConfig
from .bagdata import read_run, run_pieces
from .forward import Decision, final_fit, forward_select
from .library import INERTIAL_LINKS, TCP, TORQUE, Grids, contribution, pool, to_block
from .residuals import ResidualConfig, prepare_run
from .selection import GRID_SCALES
from .terms import MODEL_ERRORS, build_term, make_blocks, restrict


@dataclass(frozen=True)
class WorkflowConfig:
    """Settings (config/discrepancy.yaml): residual filter, blocks, decision thresholds."""

    residual: ResidualConfig = ResidualConfig()
    grids: Grids = Grids()
    block_s: float = 1.0
    bic_threshold: float = 30.0
    min_confidence: float = 0.6
    min_fit_reduction: float = 0.25
    min_excess_reduction: float = 0.5
    min_excess: float = 0.5
    n_boot: int = 40
    seed: int = 0
    speed_bins: tuple = (0.0, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 3.0)
    heldout_threshold: float = 10.0
    max_effects: int = 4
    unexplained_ratio: float = 3.0
    noise_floor: dict = field(default_factory=lambda: {
        'torque_nm': [0.25, 0.25, 0.15], 'tcp_m': 4.0e-5, 'command_nm': [1e-3, 1e-3, 1e-3]})
    gaps: GapConfig = field(default_factory=GapConfig)

    @classmethod
    def from_yaml(cls, path: str | Path | None) -> 'WorkflowConfig':
        if not path:
            return cls()
        data = yaml.safe_load(Path(path).read_text()) or {}
        d = data.get('discrepancy', data)
        res = ResidualConfig(**d.get('residual', {}))
        grids = Grids(**{k: tuple(v) if isinstance(v, list) else v
                         for k, v in d.get('grids', {}).items()})
        keys = ('block_s', 'bic_threshold', 'min_confidence', 'min_fit_reduction',
                'min_excess_reduction', 'min_excess', 'n_boot',
                'seed', 'heldout_threshold', 'max_effects', 'unexplained_ratio',
                'noise_floor')
        kw = {k: d[k] for k in keys if k in d}
        if 'speed_bins' in d:
            kw['speed_bins'] = tuple(d['speed_bins'])
        if 'gaps' in d:
            kw['gaps'] = GapConfig(**d['gaps'])
        return cls(res, grids, **kw)


@dataclass
class WorkflowResult:
    report: dict
    channels: list
    pooled: object
    fit: object
    holdout: object
    selection: object
    extra: dict = field(default_factory=dict)


def load_model_file(path: str | Path, joint_names):
    """(friction map, known effects, raw YAML dict) of a model file (friction map YAML with an
    optional ``effects:`` section)."""
    fm = load_friction_map(path, joint_names)
    effects = load_plant_effects(path)
    return fm, effects, yaml.safe_load(Path(path).read_text())


def _floors(config, P, excitation: bool = False) -> dict:
    """Noise floor per channel block: the configured clean-data floor combined with the
    measured effort noise (torque: after the smoother; command: raw). With ``excitation``
    the torque channel's clean-data part is at least this excitation's own smoothing bias
    (what the smoother does to the model's torque on these motions, residuals.prepare_run):
    a fast excitation leaves more in a clean residual than the plans the configured floor
    was set on. That floor decides only `none` against `unexplained` (clean `fast` plan:
    residual 3.1 x the configured floor, 1.6 x its own); weights, scores and the
    partial-fit test keep the configured one (with the higher floor a position-dependent
    tight spot on `fast` was named as a Stribeck hump that explains 23 % of it)."""
    nf = config.noise_floor
    en = np.asarray(P.noise.get('effort_nm', np.zeros(3)), float)
    raw = np.asarray(P.noise.get('effort_raw_nm', np.zeros(3)), float)
    sb = np.asarray(P.noise.get('smoothing_bias_nm', np.zeros(3)), float)
    if not excitation:
        sb = np.zeros(3)
    return {'torque': [float(np.hypot(max(nf['torque_nm'][j], sb[j]), en[j]))
                       for j in range(3)],
            'tcp': float(nf['tcp_m']),
            'command': [float(np.hypot(nf['command_nm'][j], raw[j])) for j in range(3)]}


def block_to_coef(name: str, block) -> dict:
    """Coefficients (joint -> array, 'all' for payload) of a known block in the library's
    linear parametrisation (the inverse of library.to_block)."""
    a = {'torque_offset': 'offset_nm', 'coulomb_asymmetry': 'delta_nm',
         'rotor_inertia': 'armature_kgm2', 'stribeck': 'static_increase_nm',
         'viscous_nonlinear': 'coefficient',
         'viscous_temperature_drift': 'cold_extra_viscous_nms_rad'}
    if name in a:
        v = getattr(block, a[name])
        return {j: np.array([v[j]]) for j in range(3)}
    if name == 'cogging':
        return {j: np.array([block.amplitude_nm[j] * np.cos(block.phase_rad[j]),
                             block.amplitude_nm[j] * np.sin(block.phase_rad[j])])
                for j in range(3)}
    if name == 'payload_mass':
        return {'all': np.array([block.mass_kg])}
    if name == 'backlash':
        return {j: np.array([-block.half_width_rad[j]]) for j in range(3)}
    if name == 'joint_elasticity':
        return {j: np.array([-1.0 / block.stiffness_nm_rad[j]]) for j in range(3)}
    return {}


def known_scales(name: str, block) -> dict:
    if name == 'stribeck':
        return {j: block.velocity_rad_s[j] for j in range(3)}
    if name == 'cogging':
        return {j: block.period_rad[j] for j in range(3)}
    if name == 'viscous_nonlinear':
        return {'shared': block.exponent}
    if name == 'viscous_temperature_drift':
        return {'shared': block.time_constant_s}
    if name == 'payload_mass':
        return {'shared': block.offset_m[2]}
    if name == 'backlash':
        return {'shared': block.torque_smoothing_nm}
    if name == 'joint_elasticity':
        return {'shared': None}
    return {}


def term_coef(t, values) -> dict:
    """joint (or 'all') -> coefficient array of a fitted term."""
    values = np.asarray(values, float)
    return {g: values[idx] for g, idx in t.groups.items()}


def model_error_dict(name: str, t, values) -> dict:
    """Parameters of a model-error term in the ``model_errors:`` YAML style (per joint 3
    values, 0 for joints not selected)."""
    c = term_coef(t, values)
    per = [float(c[j][0]) if j in c else 0.0 for j in range(3)]
    if name == 'torque_gain':
        return {'gain': [1.0 + x for x in per]}
    if name == 'encoder_scale':
        return {'scale_error': per}
    if name == 'encoder_offset':
        return {'offset_rad': per}
    if name == 'coulomb_level':
        return {'delta_coulomb_nm': per}
    if name == 'viscous_level':
        return {'delta_viscous_nms_rad': per}
    d = _inertial_values(t, values)
    return {'delta_mass_kg': d['mass_kg'], 'delta_first_moment_kgm': [
        d[f'first_moment_{a}_kgm'] for a in 'xyz']}


def _inertial_values(t, values) -> dict:
    d = {k: 0.0 for k in ('mass_kg', 'first_moment_x_kgm', 'first_moment_y_kgm',
                          'first_moment_z_kgm')}
    for lab, v in zip(t.labels, np.asarray(values, float)):
        d[lab.split('.', 1)[1]] = float(v)
    return d


def model_error_values(name: str, params: dict, t) -> np.ndarray:
    """Inverse of model_error_dict on the groups of term t (to subtract a known error)."""
    if name == 'torque_gain':
        per = [g - 1.0 for g in params['gain']]
    elif name == 'encoder_scale':
        per = params['scale_error']
    elif name == 'encoder_offset':
        per = params['offset_rad']
    elif name in ('coulomb_level', 'viscous_level'):
        per = next(iter(params.values()))
    else:
        d = {'mass_kg': params['delta_mass_kg']}
        d.update({f'first_moment_{a}_kgm': x for a, x in zip('xyz',
                                                             params['delta_first_moment_kgm'])})
        return np.array([d[lab.split('.', 1)[1]] for lab in t.labels], float)
    out = np.zeros(t.p)
    for j, idx in t.groups.items():
        out[idx] = per[j]
    return out


def _combine_refit(name, known_block, t, delta):
    """Known block + fitted change (same scales) as one block."""
    c0 = block_to_coef(name, known_block)
    dc = term_coef(t, delta)
    if name == 'time_delay':
        return to_block(name, {}, {'shared': t.scales['shared']})
    coef = {g: c0.get(g, 0.0) + dc.get(g, 0.0) for g in set(c0) | set(dc)}
    sc = known_scales(name, known_block)
    return to_block(name, coef, sc)


def plausibility_check(model, fm, record_s: float, stroke: np.ndarray, known: dict):
    """Function (term, values) -> (bad groups -> reason, flags) for forward_select."""
    Fc = np.array([j.coulomb for j in fm.joints])
    Fs = np.array([j.static for j in fm.joints])
    Fv = np.array([j.viscous for j in fm.joints])
    mass = {2: model.model.inertias[2].mass, 3: model.model.inertias[3].mass}

    def check(t, values):
        c = term_coef(t, values)
        name = t.name
        bad, flags = {}, []
        if t.kind == 'refit' and name in known and name != 'time_delay':
            c0 = block_to_coef(name, known[name])
            c = {g: c0.get(g, 0.0) + v for g, v in c.items()}
        for g, v in c.items():
            j = g
            x = float(v[0])
            if name == 'rotor_inertia' and x < -0.02:
                bad[g] = f'negative armature {x:.3g} kg m^2 on joint {j + 1}'
            elif name == 'viscous_temperature_drift' and x < 0:
                bad[g] = f'negative cold viscous {x:.3g} N m s/rad on joint {j + 1}'
            elif name == 'stribeck' and x < -Fs[j]:
                bad[g] = f'dF_s {x:.3g} < -F_s on joint {j + 1}'
            elif name == 'coulomb_level' and Fc[j] + x < 0:
                bad[g] = f'negative Coulomb level on joint {j + 1}'
            elif name == 'viscous_level' and Fv[j] + x < 0:
                bad[g] = f'negative viscous level on joint {j + 1}'
            elif name == 'coulomb_asymmetry' and abs(x) > Fc[j]:
                bad[g] = f'asymmetry {x:.3g} N m larger than F_c on joint {j + 1}'
            elif name == 'viscous_nonlinear':
                n = t.scales['shared']
                if Fv[j] + x * 3.0 ** (n - 1) < 0:
                    bad[g] = f'total viscous friction negative at 3 rad/s on joint {j + 1}'
            elif name == 'backlash' and x > 0:
                bad[g] = f'negative backlash on joint {j + 1}'
            elif name == 'joint_elasticity' and x > 0:
                bad[g] = f'negative stiffness on joint {j + 1}'
            elif name == 'torque_gain' and abs(x) > 0.3:
                bad[g] = f'torque gain {1 + x:.3g} on joint {j + 1}'
            elif name == 'encoder_scale' and abs(x) > 0.1:
                bad[g] = f'encoder scale error {x:.3g} on joint {j + 1}'
            elif name == 'encoder_offset' and abs(x) > 0.1:
                bad[g] = f'encoder offset {x:.3g} rad on joint {j + 1}'
            elif name == 'payload_mass' and x < 0:
                bad[g] = f'negative payload mass {x:.3g} kg'
            elif name == 'time_delay' and not 0.5 <= x <= 1.5:
                bad[g] = f'delay response coefficient {x:.3g} (1 expected)'
            elif name in INERTIAL_LINKS:
                m0 = mass[INERTIAL_LINKS[name]]
                d = _inertial_values(t, v)
                x = d['mass_kg']
                fm1 = float(np.linalg.norm([d[f'first_moment_{a}_kgm'] for a in 'xyz']))
                if m0 + x < 0 or fm1 > 1.5 * max(m0 + x, 1e-9):
                    bad[g] = f'{name}: mass {m0 + x:.3g} kg, first moment change ' \
                             f'{fm1:.3g} kg m'
        if name == 'viscous_temperature_drift' and t.scales.get('shared', 0) > 2 * record_s:
            bad = {g: f'time constant {t.scales["shared"]:g} s longer than twice the record '
                      f'{record_s:.0f} s' for g in c}
        if name == 'cogging':
            for g in c:
                if t.scales.get(g, 0) > stroke[g] / 2:
                    bad[g] = (f'cogging period {t.scales[g]:.3g} rad longer than half the '
                              f'stroke {stroke[g]:.3g} rad of joint {g + 1}')
        return bad, flags
    return check


def localise_blocks(B, e_after: dict, hold_rows: dict, P, floors: dict, speed_bins,
                    ratio: float) -> dict:
    """Where the held-out residual after the named effects is above ``ratio`` x its floor:
    per block RMS vs floor, and for torque blocks the speed bin, position bin and run with the
    largest RMS."""
    out = {}
    for cb in B.keys:
        m = hold_rows[cb]
        if not m.any():
            continue
        r = e_after[cb][m]
        rms = float(np.sqrt(np.mean(r**2)))
        fl = floors[cb]
        item = {'rms': rms, 'floor': fl, 'ratio': rms / fl, 'above': rms > ratio * fl}
        tb = B.tb[cb][m]
        runs = tb // 10000
        by_run = {int(k): float(np.sqrt(np.mean(r[runs == k] ** 2))) for k in np.unique(runs)}
        item['largest_run'] = max(by_run, key=by_run.get)
        item['rms_by_run'] = by_run
        if cb[0] == TORQUE:
            rows = B.rows[cb][m]
            j = cb[1]
            v = np.abs(P.qd[rows, j])
            q = P.q[rows, j]
            sb = np.asarray(speed_bins)
            rv = [(float(np.sqrt(np.mean(r[(v >= a) & (v < b)] ** 2))), [float(a), float(b)])
                  for a, b in zip(sb[:-1], sb[1:]) if np.any((v >= a) & (v < b))]
            qb = np.linspace(q.min(), q.max() + 1e-9, 7)
            rq = [(float(np.sqrt(np.mean(r[(q >= a) & (q < b)] ** 2))), [float(a), float(b)])
                  for a, b in zip(qb[:-1], qb[1:]) if np.any((q >= a) & (q < b))]
            item['mean'] = float(np.mean(r))
            if rv:
                item['largest_speed_bin_rad_s'] = max(rv)[1]
            if rq:
                item['largest_position_bin_rad'] = max(rq)[1]
            t = P.t_global[rows]
            tq = np.linspace(t.min(), t.max() + 1e-9, 6)
            rt = [(float(np.sqrt(np.mean(r[(t >= a) & (t < b)] ** 2))), [float(a), float(b)])
                  for a, b in zip(tq[:-1], tq[1:]) if np.any((t >= a) & (t < b))]
            if rt:
                item['largest_time_bin_s'] = max(rt)[1]
        out[_cb_name(cb)] = item
    return out


def _cb_name(cb) -> str:
    return f'{cb[0]}_joint_{cb[1] + 1}' if cb[1] is not None else cb[0]


def data_quality(checks, n_runs: int, n_pieces: int) -> dict:
    """The report's ``data_quality``: complete or not, one entry per checked series, and one
    note per series with gaps or duplicates (what the CLI prints and report.md lists)."""
    joint = [c for c in checks if c.topic == '/joint_states']
    notes = [c.summary() for c in checks if not c.clean]
    return {'complete': all(c.clean for c in checks),
            'joint_states_complete': all(c.clean for c in joint),
            'runs': n_runs, 'pieces_analysed': n_pieces,
            'missing_joint_states': int(sum(c.missing for c in joint)),
            'series': [c.as_dict() for c in checks], 'notes': notes}


def verdict(named: list[dict], last, residual_above_floor: bool,
            n_boot: int) -> tuple[str, float, dict | None]:
    """The answer from the named effects and the last selection step: the names joined
    ('+'), else 'ambiguous' when the last step stopped on bootstrap support (replicates split
    between candidates that are not aliases), else 'unexplained' (residual above the floor)
    or 'none'. Returns (effect, confidence, ambiguous details or None)."""
    n_boot = max(n_boot, 1)
    ambiguous = None
    if last is not None and last.added is None and last.best is not None and \
            last.stop_reason.startswith(f'{last.best}: bootstrap support'):
        ambiguous = {'best': last.best, 'aliases': last.aliases, 'support': last.support,
                     'wins': {k: v / n_boot for k, v in last.wins.items()}}
    if named:
        effect = '+'.join(n['effect'] if n['kind'] != 'refit' else f"refit:{n['effect']}"
                          for n in named)
        return effect, min(n['confidence'] for n in named), ambiguous
    if ambiguous:
        return 'ambiguous', ambiguous['support'], ambiguous
    none_frac = (last.wins.get('none', 0) / n_boot) if last else 1.0
    return ('unexplained' if residual_above_floor else 'none'), float(none_frac), None


def run_workflow(bags, model_path, config: WorkflowConfig = WorkflowConfig(),
                 holdout_bags=(), model=None, log=None, runs=None) -> WorkflowResult:
    """Analyse ``bags`` (+ ``holdout_bags``) against the model file; see module docstring.
    ``runs``: the RunData of the bags if already in memory (benchmark: no bag round trip)."""
    from irb_description.model import RobotModel
    t_start = time.perf_counter()
    model = model or RobotModel.load()
    bags, holdout_bags = [str(b) for b in bags], [str(b) for b in holdout_bags]
    same = sorted({str(Path(b).resolve()) for b in bags} & {str(Path(b).resolve())
                                                              for b in holdout_bags})
    if same:
        raise ValueError(f'bag(s) given both as --bag and --holdout-bag: {same}')
    fm, known, model_yaml = load_model_file(model_path, model.joint_names)
    known_errors = (model_yaml or {}).get('model_errors') or {}
    if not isinstance(known_errors, dict) or set(known_errors) - set(MODEL_ERRORS):
        raise ValueError(f'{model_path}: model_errors must map names of {MODEL_ERRORS}')
    all_bags = list(bags) + list(holdout_bags)
    labels = list(all_bags) if runs is None else [r.name for r in runs]
    if runs is None:
        runs = [read_run(b, model.joint_names) for b in all_bags]
    # gaps and duplicates: each run cut at gaps into pieces analysed as runs of their own
    pieces, checks, n_fit_pieces = [], [], 0
    for i, (r, label) in enumerate(zip(runs, labels)):
        ps, cs = run_pieces(r, config.gaps, str(label))
        pieces += ps
        checks += cs
        if i < len(bags):
            n_fit_pieces += len(ps)
    quality = data_quality(checks, len(runs), len(pieces))
    if log:
        for line in quality['notes']:
            log(line)
    runs = pieces
    t_origin = min(r.t[0] for r in runs)
    channels = [prepare_run(r, model, fm, config.residual, t_origin,
                            config.grids.delay_max_s) for r in runs]
    P = pool(channels, model, fm, config.block_s, config.grids, config.residual)
    P.noise['effort_raw_nm'] = np.sqrt(np.mean([np.square(c.extra['effort_noise_raw_nm'])
                                                for c in channels], axis=0))
    # known effects of the model file: subtract their predictions
    for name, block in known.blocks.items():
        ch, pred = contribution(name, block, P)
        if ch == TORQUE:
            P.r = P.r - pred
        elif ch == TCP:
            P.r_tcp = P.r_tcp - pred
        else:
            P.r_cmd = P.r_cmd - pred
    floors = _floors(config, P)
    B = make_blocks(P, floors)
    if not any(cb[0] == TORQUE for cb in B.keys):
        raise ValueError('no usable samples: no joint moves faster than v_min '
                         f'{config.residual.v_min} rad/s for long enough (at rest friction '
                         'is indeterminate); record motion (excite) first')
    fit_all = {cb: np.ones(len(B.rows[cb]), bool) for cb in B.keys}
    for name, params in known_errors.items():
        t = build_term(name, P, B, B.y, fit_all, config.grids)
        if t is not None:
            vals = model_error_values(name, params, t)
            for cb, X in t.cols.items():
                B.y[cb] = B.y[cb] - X @ vals
    blocks = np.unique(np.concatenate([P.block, P.cam_block, P.cmd_block]))
    if holdout_bags:
        fit_blocks = blocks[blocks // 10000 < n_fit_pieces]
    else:
        fit_blocks = blocks[(blocks % 10000) % 2 == 0]
    hold_blocks = np.setdiff1d(blocks, fit_blocks)
    record_s = float(P.t_global.max() - P.t_global.min()) if len(P.t_global) else 0.0
    stroke = np.array([np.ptp(P.q[P.mask[:, j], j]) if P.mask[:, j].any() else 0.0
                       for j in range(3)])
    known_delay = known.get('time_delay')
    kd = known_delay.extra_delay_s if known_delay is not None else 0.0
    names = [n for n in EFFECT_NAMES if n not in known.blocks] + list(MODEL_ERRORS)

    def make_candidates(e, fitrow, selected):
        out = []
        for n in names:
            if n in selected:
                continue
            t = build_term(n, P, B, e, fitrow, config.grids, 'model_error' if n in
                           MODEL_ERRORS else 'effect', known_delay_s=kd, record_s=record_s,
                           stroke=stroke)
            if t is not None:
                out.append(t)
        for n, block in known.blocks.items():
            if f'refit:{n}' in selected:
                continue
            fixed = None if n == 'time_delay' else known_scales(n, block)
            t = build_term(n, P, B, e, fitrow, config.grids, 'refit', fixed_scales=fixed,
                           known_delay_s=kd, record_s=record_s, stroke=stroke)
            if t is not None:
                t.known = block
                out.append(t)
        return out

    def rebuild(t, e, fitrow):
        nt = build_term(t.name, P, B, e, fitrow, config.grids, t.kind, joints=t.joints,
                        known_delay_s=kd, record_s=record_s, stroke=stroke,
                        fixed_scales=None if t.kind != 'refit' or t.name == 'time_delay'
                        else known_scales(t.name, t.known))
        if nt is None or set(t.groups) - set(nt.groups):
            return None
        nt = restrict(nt, list(t.groups))
        if nt is not None:
            nt.known = t.known
        return nt

    check = plausibility_check(model, fm, record_s, stroke, known.blocks)
    dec = Decision(bic_threshold=config.bic_threshold,
                   heldout_threshold=config.heldout_threshold,
                   min_confidence=config.min_confidence,
                   min_fit_reduction=config.min_fit_reduction,
                   min_excess_reduction=config.min_excess_reduction,
                   min_excess=config.min_excess, n_boot=config.n_boot, seed=config.seed,
                   max_terms=config.max_effects)
    if log:
        log(f'{len(runs)} runs, {len(B.keys)} channel blocks, fit/held-out time blocks '
            f'{len(fit_blocks)}/{len(hold_blocks)}')
    fr = forward_select(B, B.y, fit_blocks, hold_blocks, make_candidates, check, dec, log,
                        rebuild)
    partial = _demote_partial_fits(config, B, fr, fit_blocks, hold_blocks)
    report = _report(config, B, P, fr, known, fm, model_yaml, model_path, bags, holdout_bags,
                     fit_blocks, hold_blocks, channels)
    report['partial_fits'] = partial
    report['data_quality'] = quality
    effects, friction_yaml, errors = _updated_model(fr, known, model_yaml, known_errors)
    res = WorkflowResult(report, channels, P, None, None, fr,
                         {'friction_yaml': friction_yaml, 'effects': PlantEffects(effects),
                          'model_errors': errors, 'blocks': B, 'hold_blocks': hold_blocks})
    report['run_time_s'] = time.perf_counter() - t_start
    return res


def _demote_partial_fits(config, B, fr, fit_blocks, hold_blocks) -> list:
    """A named term whose main block (where its contribution is largest) stays above
    ``unexplained_ratio`` x floor on the held-out part, and which explains less there than
    remains, is a partial fit of something no candidate describes (e.g. Coulomb level for a
    position-dependent tight spot): it is taken out (not named, not written) and listed.
    The rest are refitted jointly."""
    hold = {cb: np.isin(B.tb[cb], hold_blocks) for cb in B.keys}

    def ms(x, cb):
        m = hold[cb]
        return float(np.mean(x[m] ** 2)) if m.any() else 0.0
    out, keep = [], []
    for t in fr.selected:
        c = fr.per_term[t.key()]
        main = max(c, key=lambda cb: ms(c[cb], cb) / B.floor[cb] ** 2)
        after = ms(B.y[main] - fr.contributions[main], main)
        before = ms(B.y[main] - fr.contributions[main] + c[main], main)
        still = np.sqrt(after) > config.unexplained_ratio * B.floor[main]
        if t.kind != 'refit' and still and before - after < after:
            out.append({'effect': t.key(), 'block': _cb_name(main),
                        'explained_rms': float(np.sqrt(max(before - after, 0.0))),
                        'remaining_rms': float(np.sqrt(after)),
                        'floor': float(B.floor[main])})
        else:
            keep.append(t)
    if out:
        all_tb = np.unique(np.concatenate([B.tb[cb] for cb in B.keys]))
        fin = final_fit(B, B.y, keep, np.isin(all_tb, fit_blocks), config.n_boot,
                        np.random.default_rng(config.seed + 1))
        fr.selected = keep
        fr.beta, fr.ci, fr.contributions, fr.per_term, fr.boot = fin
    return out


def _updated_model(fr, known, model_yaml, known_errors):
    effects = dict(known.blocks)
    friction_yaml = copy.deepcopy((model_yaml or {}).get('friction_map'))
    errors = copy.deepcopy(known_errors)
    for t in fr.selected:
        v = fr.beta[t.key()]
        if t.kind == 'refit':
            effects[t.name] = _combine_refit(t.name, t.known, t, v)
        elif t.kind == 'effect':
            effects[t.name] = to_block(t.name, term_coef(t, v), dict(t.scales))
        elif t.name in ('coulomb_level', 'viscous_level') and friction_yaml:
            d = model_error_dict(t.name, t, v)
            jn = list(friction_yaml['joints'])
            for j, name in enumerate(jn[:3]):
                jj = friction_yaml['joints'][name]
                if t.name == 'coulomb_level':
                    jj['coulomb'] = float(jj['coulomb'] + d['delta_coulomb_nm'][j])
                    jj['static'] = float(jj['static'] + d['delta_coulomb_nm'][j])
                else:
                    jj['viscous'] = float(jj['viscous'] + d['delta_viscous_nms_rad'][j])
            friction_yaml['source'] = f"{friction_yaml.get('source', '')} + discrepancy " \
                                      f"{t.name}"
        else:
            new = model_error_dict(t.name, t, v)
            old = errors.get(t.name)
            if old and t.name == 'torque_gain':
                new = {'gain': [a * b for a, b in zip(old['gain'], new['gain'])]}
            elif old and t.name in ('encoder_scale', 'encoder_offset'):
                key = next(iter(new))
                new = {key: [a + b for a, b in zip(old[key], new[key])]}
            elif old:
                new = {'delta_mass_kg': old['delta_mass_kg'] + new['delta_mass_kg'],
                       'delta_first_moment_kgm': [a + b for a, b in zip(
                           old['delta_first_moment_kgm'], new['delta_first_moment_kgm'])]}
            errors[t.name] = new
    return effects, friction_yaml, errors


def _params_of(t, v, ci, boot=None) -> dict:
    """Parameters of a named term: for a physical effect (or a refit) its irb_control block
    fields (value, bootstrap 95 % interval of the mapped value; grid scales without), for a
    model error the fitted coefficients by label."""
    if t.kind in ('effect', 'refit'):
        def block(vals):
            if t.kind == 'refit':
                return effect_to_dict(_combine_refit(t.name, t.known, t, vals))
            return effect_to_dict(to_block(t.name, term_coef(t, vals), dict(t.scales)))
        d = block(v)
        bs = [block(b) for b in boot] if boot is not None and len(boot) else []
        out = {}
        for k, val in d.items():
            if k in GRID_SCALES or not bs:
                out[k] = {'value': val, 'ci95': None, 'profiled_on_grid': k in GRID_SCALES}
                continue
            arr = np.array([b[k] for b in bs], float).reshape(len(bs), -1)
            lo, hi = np.array(val, float).reshape(-1).copy(), np.array(val, float).reshape(-1)
            hi = hi.copy()
            for i in range(arr.shape[1]):         # e.g. stiffness inf on unselected joints
                col = arr[:, i][np.isfinite(arr[:, i])]
                if len(col):
                    lo[i], hi[i] = np.percentile(col, [2.5, 97.5])
            shape = np.shape(val)
            out[k] = {'value': val, 'ci95': [lo.reshape(shape).tolist(),
                                             hi.reshape(shape).tolist()]}
        return out
    out = {}
    for i, lab in enumerate(t.labels):
        item = {'value': float(v[i])}
        if ci is not None:
            item['ci95'] = [float(ci[0][i]), float(ci[1][i])]
        out[lab] = item
    for k, s in t.scales.items():
        if s is not None:
            out[f'scale[{k + 1 if isinstance(k, int) else k}]'] = {
                'value': float(s), 'ci95': None, 'profiled_on_grid': True}
    return out


def _report(config, B, P, fr, known, fm, model_yaml, model_path, bags, holdout_bags,
            fit_blocks, hold_blocks, channels) -> dict:
    hold_rows = {cb: np.isin(B.tb[cb], hold_blocks) for cb in B.keys}
    if not any(m.any() for m in hold_rows.values()):
        hold_rows = {cb: np.ones(len(B.rows[cb]), bool) for cb in B.keys}
    e_after = {cb: B.y[cb] - fr.contributions[cb] for cb in B.keys}

    def ms(e, cb):
        m = hold_rows[cb]
        return float(np.mean(e[cb][m] ** 2)) if m.any() else 0.0
    before = {_cb_name(cb): float(np.sqrt(ms(B.y, cb))) for cb in B.keys}
    after = {_cb_name(cb): float(np.sqrt(ms(e_after, cb))) for cb in B.keys}
    nb = sum(ms(B.y, cb) / B.floor[cb] ** 2 for cb in B.keys)
    na = sum(ms(e_after, cb) / B.floor[cb] ** 2 for cb in B.keys)
    reduction = float(1 - np.sqrt(na / nb)) if fr.selected and nb > 0 else None
    # share of the explained (held-out, noise-normalised) residual, in selection order
    shares, prev = [], dict(B.y)
    cum = {cb: np.zeros(len(B.rows[cb])) for cb in B.keys}
    for t in fr.selected:
        for cb, c in fr.per_term[t.key()].items():
            cum[cb] = cum[cb] + c
        cur = {cb: B.y[cb] - cum[cb] for cb in B.keys}
        shares.append(sum((ms(prev, cb) - ms(cur, cb)) / B.floor[cb] ** 2 for cb in B.keys))
        prev = cur
    tot = sum(max(s, 0.0) for s in shares) or 1.0
    named = []
    for i, t in enumerate(fr.selected):
        st = next(x for x in fr.steps if x.added == t.key())
        row = next(r for r in st.candidates if r['effect'] == t.key())
        named.append({
            'effect': t.name, 'kind': t.kind, 'order': i + 1,
            'refit_of_known': t.kind == 'refit',
            'joints': [j + 1 for j in t.joints], 'channel': t.channel,
            'delta_bic': row['delta_bic'], 'heldout_delta_bic': st.heldout_delta,
            'confidence': st.support, 'share_of_explained': max(shares[i], 0.0) / tot,
            'indistinguishable_from': st.aliases,
            'parameters': _params_of(t, fr.beta[t.key()], fr.ci.get(t.key()),
                                     fr.boot.get(t.key())),
            'flags': fr.flags.get(t.key(), [])})
    # none vs unexplained: against what a clean plant leaves on THIS excitation
    cf = _floors(config, P, excitation=True)
    clean_floor = {cb: (cf[cb[0]][cb[1]] if cb[1] is not None else cf[cb[0]])
                   for cb in B.keys}
    loc = localise_blocks(B, e_after, hold_rows, P, clean_floor, config.speed_bins,
                          config.unexplained_ratio)
    above = {k: v for k, v in loc.items() if v['above']}
    last = fr.steps[-1] if fr.steps else None
    effect, confidence, ambiguous = verdict(named, last, bool(above), config.n_boot)
    unexplained = None
    if above:
        unexplained = {
            'blocks': above,
            'summary': '; '.join(
                f"{k}: RMS {v['rms']:.3g} = {v['ratio']:.1f} x floor"
                + (f", largest at |v| in {v['largest_speed_bin_rad_s']} rad/s, q in "
                   f"{[round(x, 2) for x in v['largest_position_bin_rad']]} rad, t in "
                   f"{[round(x, 1) for x in v['largest_time_bin_s']]} s"
                   if 'largest_speed_bin_rad_s' in v else f", largest in run "
                                                          f"{v['largest_run']}")
                for k, v in above.items()),
            'why_not_named': last.stop_reason if last else ''}
    first_step = fr.steps[0] if fr.steps else None
    candidates = [dict(rank=i + 1, **r) for i, r in enumerate(first_step.candidates)] \
        if first_step else []
    smoothing = [{'run': c.name, 'window_s': c.extra['window_s'],
                  'reversal_interval_s': c.extra['reversal_interval_s'],
                  'adapted': c.extra['window_adapted']} for c in channels]
    report = {
        'effect': effect,
        'effects': named,
        'joints': sorted({j for n in named for j in n['joints']}),
        'channel': '+'.join(sorted({n['channel'] for n in named})) or None,
        'parameters': named[0]['parameters'] if len(named) == 1 else
        {n['effect']: n['parameters'] for n in named},
        'confidence': float(confidence),
        'unexplained': unexplained,
        'ambiguous': ambiguous,
        'rms_before': before, 'rms_after': after, 'noise_floor': {
            _cb_name(cb): B.floor[cb] for cb in B.keys},
        'excitation_floor': {_cb_name(cb): clean_floor[cb] for cb in B.keys},
        'heldout_reduction': reduction,
        'steps': [{'added': s.added, 'support': s.support, 'wins': s.wins,
                   'heldout_delta_bic': s.heldout_delta, 'stop_reason': s.stop_reason,
                   'candidates': s.candidates} for s in fr.steps],
        'candidates': candidates,
        'n_eff': {_cb_name(cb): float(v) for cb, v in fr.n_eff.items()},
        'localisation': loc,
        'smoothing': smoothing,
        'known_effects': known.names(),
        'known_model_errors': sorted(((model_yaml or {}).get('model_errors') or {})),
        'model_in': str(model_path),
        'bags': [str(b) for b in bags], 'holdout_bags': [str(b) for b in holdout_bags],
        'split': 'holdout bags' if holdout_bags else f'alternate {config.block_s} s blocks',
        'samples': {_cb_name(cb): int(len(B.rows[cb])) for cb in B.keys},
        'decision': {'bic_threshold': config.bic_threshold,
                     'heldout_threshold': config.heldout_threshold,
                     'min_confidence': config.min_confidence,
                     'min_fit_reduction': config.min_fit_reduction,
                     'min_excess_reduction': config.min_excess_reduction,
                     'min_excess': config.min_excess, 'n_boot': config.n_boot,
                     'measured_white_noise': {_cb_name(cb): v for cb, v in B.white.items()},
                     'unexplained_ratio': config.unexplained_ratio},
        'units': {'torque': 'N m', 'tcp': 'm', 'command': 'N m', 'delta_bic': '-'},
    }
    return report


def write_updated_model(result: WorkflowResult, path: str | Path) -> Path:
    """friction_map (+ fitted friction levels) + effects (known + named) + model_errors."""
    path = Path(path)
    extra = {'friction_map': result.extra['friction_yaml']}
    save_effects(result.extra['effects'], path, extra)
    if result.extra.get('model_errors'):
        data = yaml.safe_load(path.read_text())
        data['model_errors'] = result.extra['model_errors']
        path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path
