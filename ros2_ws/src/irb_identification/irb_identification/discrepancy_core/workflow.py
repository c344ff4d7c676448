"""The discrepancy workflow end to end: bags + model -> report dict + updated model. No rclpy.

1. residuals of the nominal model on every bag (residuals.py), pooled (library.py);
2. localisation: residual RMS per joint over speed bins, position bins and runs;
3. the fit part (time blocks of ``block_s`` with even index, or the bags not given as
   hold-out) scores the library (selection.py);
4. the named effect is refitted on the fit part and written with the model's friction map as
   one YAML (``friction_map:`` + ``effects:``), loadable by the simulator
   (``plant_friction_file``) and by the controller (``friction_map_file``);
5. held-out part: residual RMS before/after per joint (torque), TCP and command channel.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from irb_control.plant_effects import PlantEffects, load_plant_effects, save_effects
from irb_description.friction import load_friction_map

from .bagdata import read_run
from .library import CHANNEL, COMMAND, TCP, TORQUE, Grids, contribution, pool
from .residuals import ResidualConfig, prepare_run
from .selection import select


@dataclass(frozen=True)
class WorkflowConfig:
    """Settings (config/discrepancy.yaml): residual filter, blocks, decision thresholds."""

    residual: ResidualConfig = ResidualConfig()
    grids: Grids = Grids()
    block_s: float = 1.0
    bic_threshold: float = 30.0
    min_confidence: float = 0.6
    min_fit_reduction: float = 0.25
    n_boot: int = 40
    seed: int = 0
    speed_bins: tuple = (0.0, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 3.0)

    @classmethod
    def from_yaml(cls, path: str | Path | None) -> 'WorkflowConfig':
        if not path:
            return cls()
        data = yaml.safe_load(Path(path).read_text()) or {}
        d = data.get('discrepancy', data)
        res = ResidualConfig(**d.get('residual', {}))
        grids = Grids(**{k: tuple(v) if isinstance(v, list) else v
                         for k, v in d.get('grids', {}).items()})
        keys = ('block_s', 'bic_threshold', 'min_confidence', 'min_fit_reduction', 'n_boot',
                'seed')
        kw = {k: d[k] for k in keys if k in d}
        if 'speed_bins' in d:
            kw['speed_bins'] = tuple(d['speed_bins'])
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


def _rms(a, axis=0):
    a = np.asarray(a, float)
    return np.sqrt(np.mean(a**2, axis=axis)) if a.size else np.full(3, np.nan)


def _channel_rms(P, corr: dict) -> dict:
    """RMS per channel of P's residuals minus the contributions in ``corr`` (channel -> arr)."""
    out = {}
    r = P.r - corr.get(TORQUE, 0.0)
    out['torque_nm'] = [float(_rms(r[P.mask[:, j], j])) if P.mask[:, j].any() else None
                        for j in range(3)]
    rt = P.r_tcp - corr.get(TCP, 0.0)
    out['tcp_m'] = float(np.sqrt(np.mean(np.sum(rt**2, axis=1)))) if len(rt) else None
    rc = P.r_cmd - corr.get(COMMAND, 0.0)
    out['command_nm'] = [float(x) for x in _rms(rc)] if len(rc) else None
    return out


def localise(P, speed_bins) -> dict:
    """Where the torque residual is large: RMS per joint over speed and position bins."""
    out = {}
    for j in range(3):
        m = P.mask[:, j]
        v, q, r = np.abs(P.qd[m, j]), P.q[m, j], P.r[m, j]
        sb = np.asarray(speed_bins)
        rms_v = [float(_rms(r[(v >= a) & (v < b)])) if np.any((v >= a) & (v < b)) else None
                 for a, b in zip(sb[:-1], sb[1:])]
        if len(q):
            qb = np.linspace(q.min(), q.max() + 1e-9, 7)
            rms_q = [float(_rms(r[(q >= a) & (q < b)])) if np.any((q >= a) & (q < b))
                     else None for a, b in zip(qb[:-1], qb[1:])]
        else:
            qb, rms_q = np.zeros(1), []
        out[f'joint_{j + 1}'] = {
            'rms_nm': float(_rms(r)) if len(r) else None,
            'mean_nm': float(np.mean(r)) if len(r) else None,
            'speed_bins_rad_s': sb.tolist(), 'rms_by_speed_nm': rms_v,
            'position_bins_rad': qb.tolist(), 'rms_by_position_nm': rms_q}
    worst = max(range(3), key=lambda j: out[f'joint_{j + 1}']['rms_nm'] or 0.0)
    wj = out[f'joint_{worst + 1}']
    k = int(np.nanargmax([x if x is not None else np.nan for x in wj['rms_by_speed_nm']]))
    out['largest'] = {'joint': worst + 1, 'speed_range_rad_s': wj['speed_bins_rad_s'][k:k + 2]}
    return out


def run_workflow(bags, model_path, config: WorkflowConfig = WorkflowConfig(),
                 holdout_bags=(), model=None, log=None) -> WorkflowResult:
    """Analyse ``bags`` (+ ``holdout_bags``) against the model file; see module docstring."""
    from irb_description.model import RobotModel
    t_start = time.perf_counter()
    model = model or RobotModel.load()
    fm, known, model_yaml = load_model_file(model_path, model.joint_names)
    all_bags = list(bags) + list(holdout_bags)
    runs = [read_run(b, model.joint_names) for b in all_bags]
    t_origin = min(r.t[0] for r in runs)
    channels = [prepare_run(r, model, fm, config.residual, t_origin) for r in runs]
    P = pool(channels, model, fm, config.block_s, config.grids, config.residual)
    # known effects of the model file: subtract their predictions
    for name, block in known.blocks.items():
        ch, pred = contribution(name, block, P)
        if ch == TORQUE:
            P.r = P.r - pred
        elif ch == TCP:
            P.r_tcp = P.r_tcp - pred
        else:
            P.r_cmd = P.r_cmd - pred
    blocks = np.unique(np.concatenate([P.block, P.cam_block, P.cmd_block]))
    if holdout_bags:
        n_fit = len(bags)
        fit_blocks = blocks[blocks // 10000 < n_fit]
    else:
        fit_blocks = blocks[(blocks % 10000) % 2 == 0]
    hold_blocks = np.setdiff1d(blocks, fit_blocks)
    F, H = P.subset(fit_blocks), P.subset(hold_blocks)
    if log:
        log(f'{len(runs)} runs, torque samples fit/held-out {len(F.r)}/{len(H.r)}, camera '
            f'{len(F.r_tcp)}/{len(H.r_tcp)}')
    sel = select(F, config.grids, config.bic_threshold, config.min_confidence,
                 config.n_boot, config.seed, config.min_fit_reduction)
    # held-out: before / after
    before = _channel_rms(H, {})
    corr = {}
    if sel.winner is not None:
        ch, pred = contribution(sel.effect, sel.winner.block, H)
        corr[ch] = pred
    after = _channel_rms(H, corr)
    candidates = [dict(rank=i + 1, **f.summary()) for i, f in enumerate(sel.ranked)]
    for c in candidates:
        c['bootstrap_wins'] = sel.wins.get(c['effect'], 0) / max(config.n_boot, 1)
    channel = CHANNEL.get(sel.effect)
    reduction = None
    if sel.winner is not None:
        if channel == TORQUE:
            js = sel.winner.joints or [0, 1, 2]
            b = np.sqrt(np.mean([before['torque_nm'][j] ** 2 for j in js]))
            a = np.sqrt(np.mean([after['torque_nm'][j] ** 2 for j in js]))
        elif channel == TCP:
            b, a = before['tcp_m'], after['tcp_m']
        else:
            b = np.sqrt(np.mean(np.square(before['command_nm'])))
            a = np.sqrt(np.mean(np.square(after['command_nm'])))
        reduction = float(1.0 - a / b) if b else None
    effects = dict(known.blocks)
    if sel.winner is not None:
        effects[sel.effect] = sel.winner.block
    report = {
        'effect': sel.effect,
        'joints': [j + 1 for j in sel.winner.joints] if sel.winner else [],
        'channel': channel,
        'parameters': sel.intervals if sel.winner else {},
        'confidence': sel.confidence,
        'rms_before': before, 'rms_after': after,
        'heldout_reduction': reduction,
        'candidates': candidates,
        'localisation': localise(F, config.speed_bins),
        'known_effects': known.names(),
        'model_in': str(model_path),
        'bags': [str(b) for b in bags], 'holdout_bags': [str(b) for b in holdout_bags],
        'split': 'holdout bags' if holdout_bags else f'alternate {config.block_s} s blocks',
        'samples': {'fit_torque': int(len(F.r)), 'heldout_torque': int(len(H.r)),
                    'fit_camera': int(len(F.r_tcp)), 'heldout_camera': int(len(H.r_tcp))},
        'decision': {'bic_threshold': config.bic_threshold,
                     'min_confidence': config.min_confidence,
                     'min_fit_reduction': config.min_fit_reduction, 'n_boot': config.n_boot},
        'units': {'torque': 'N m', 'tcp': 'm', 'command': 'N m', 'delta_bic': '-'},
    }
    res = WorkflowResult(report, channels, P, F, H, sel,
                         {'friction_yaml': model_yaml.get('friction_map'),
                          'effects': PlantEffects(effects)})
    report['run_time_s'] = time.perf_counter() - t_start
    return res


def write_updated_model(result: WorkflowResult, path: str | Path) -> Path:
    """friction_map (unchanged) + effects (known + named) in one YAML."""
    path = Path(path)
    save_effects(result.extra['effects'], path,
                 {'friction_map': result.extra['friction_yaml']})
    return path
