"""Identification from joint-state series: one code path for `identify` and the node. No rclpy.

``identify_joints`` takes JointSeries (one per bag or stream), the torque kind of each
(``friction``: the effort is the friction torque; ``total``: the joint torque, from which the
rigid-body model's M q_dd + C q_d + g is subtracted), optional measured accelerations, a
joint selection and a name mapping (bag name -> model/map name), and per joint chooses:

* ``sweep``: the thesis's eq. 4.8 points from constant-speed holds (segments.py,
  friction_fit.identify_series), when the data are sweeps: at least ``min_speeds`` +c/-c
  pairs and the holds cover at least ``sweep_hold_fraction`` of the time the joint moves;
* ``samples``: the trajectory-agnostic fit on every sample (sample_fit.fit_samples).

``method`` forces one. The result per joint is a friction_fit.JointResult with ``method``,
``warnings``, ``error`` and ``degenerate`` (honesty-check failures); ``report_entry`` turns
it into the JSON report's entry.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from irb_description.friction import JointFriction

from .friction_fit import FitConfig, IdentificationError, JointResult, identify_series
from .gaps import GapConfig, GapError, check_series
from .sample_fit import (SampleFitConfig, SampleFitError, binned_means, fit_samples,
                         resolve_v_min)
from .series import JointSeries

METHODS = ('auto', 'sweep', 'samples')


@dataclass(frozen=True)
class PipelineConfig:
    """method: auto | sweep | samples; sweep_hold_fraction [-]: share of the moving time in
    accepted holds above which data count as sweeps; accel_window_s [s]: Savitzky-Golay
    window for q_dd where no acceleration was measured (total torque only);
    accel_check_window_s [s], accel_tolerance [rad/s^2]: where q_dd over the short window
    differs from q_dd over the long one by more than accel_tolerance + 10 %, the acceleration
    is not resolved (a step in q_dd: ramps, impacts) and M q_dd cannot be subtracted there:
    those samples are left out of a total-torque fit (counted in the notes). gaps: how
    gaps and duplicates in the series are found and treated (gaps.GapConfig): duplicates
    are dropped, q_dd is computed per stretch between gaps (any missing sample),
    holds end at such gaps (fit.segments.split_gap_s), every joint's warnings say what was
    missing, and on_gap 'refuse' raises gaps.GapError."""

    method: str = 'auto'
    fit: FitConfig = field(default_factory=FitConfig)
    samples: SampleFitConfig = field(default_factory=SampleFitConfig)
    sweep_hold_fraction: float = 0.3
    accel_window_s: float = 0.05
    accel_check_window_s: float = 0.02
    accel_tolerance: float = 0.5
    gaps: GapConfig = field(default_factory=GapConfig)


def rename(series: JointSeries, name_map: dict[str, str]) -> JointSeries:
    """The series with joints renamed by ``name_map`` (bag name -> new name)."""
    return JointSeries(series.t, tuple(name_map.get(n, n) for n in series.names),
                       series.position, series.velocity, series.effort)


def acceleration(t: np.ndarray, v: np.ndarray, window_s: float,
                 split_s: float | None = None) -> np.ndarray:
    """q_dd (N, n) [rad/s^2] from speeds v (N, n) at irregular times t (N,): v resampled to
    the median step, Savitzky-Golay derivative (order 2, ``window_s``), interpolated back.
    With ``split_s`` [s], separately on each stretch between steps at least that long (no
    derivative across a gap in the data)."""
    if split_s is not None and len(t) > 1:
        cut = np.flatnonzero(np.diff(t) >= split_s) + 1
        if len(cut):
            edges = np.concatenate([[0], cut, [len(t)]])
            out = np.zeros_like(v, dtype=float)
            for a, b in zip(edges[:-1], edges[1:]):
                if b - a >= 2:
                    out[a:b] = acceleration(t[a:b], v[a:b], window_s)
            return out
    return _acceleration(t, v, window_s)


def _acceleration(t: np.ndarray, v: np.ndarray, window_s: float) -> np.ndarray:
    from scipy.signal import savgol_filter
    if len(t) < 5:
        return np.zeros_like(v)
    steps = np.diff(t)
    steps = steps[steps > 0]
    if not len(steps):
        return np.zeros_like(v)
    dt = float(np.median(steps))
    grid = np.arange(t[0], t[-1] + 0.5 * dt, dt)
    win = max(5, int(round(window_s / dt)) | 1)
    out = np.empty_like(v)
    for k in range(v.shape[1]):
        vg = np.interp(grid, t, v[:, k])
        if len(vg) <= win:
            out[:, k] = np.gradient(v[:, k], t)
            continue
        ag = savgol_filter(vg, win, 2, deriv=1, delta=dt)
        out[:, k] = np.interp(t, grid, ag)
    return out


def rigid_body_torque(model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                      rows: np.ndarray) -> np.ndarray:
    """M q_dd + C q_d + g (N, n) [N m] of the model at ``rows`` (others nan)."""
    out = np.full(q.shape, np.nan)
    idx = np.flatnonzero(rows)
    out[idx] = model.inverse_dynamics_batch(q[idx], qd[idx], qdd[idx])
    return out


def identify_joints(series_list: list[JointSeries], labels: list[str], torque_kinds: list[str],
                    joints: list[str] | None = None, name_map: dict[str, str] | None = None,
                    model=None, config: PipelineConfig = PipelineConfig(),
                    accelerations: list[JointSeries | None] | None = None,
                    model_compensation: bool = False, progress=None,
                    checks: list | None = None) -> list[JointResult]:
    """Identify ``joints`` (names after ``name_map``; None = the model's joints when the
    series has them and more, e.g. the six joints of /joint_states with 4-6 locked; else
    every joint of the series).

    Every series is checked for gaps and duplicates first (``config.gaps``): ``checks``, if
    given, gets one gaps.SeriesCheck per series, and each joint's result carries a warning
    per series with gaps (a result from data with gaps says so).

    Raises IdentificationError (one line) when names do not fit: the selection names a joint
    the data lack, the series disagree on their joints, or a ``total`` torque needs the
    rigid-body model for joints it does not know.
    """
    if config.method not in METHODS:
        raise IdentificationError(f'method {config.method!r}: one of {", ".join(METHODS)}')
    name_map = dict(name_map or {})
    series_list = [rename(s, name_map) for s in series_list]
    series_list, gap_notes = check_gaps(series_list, labels, config.gaps)
    if checks is not None:
        checks.extend(gap_notes)
    accelerations = [None if a is None else rename(a, name_map)
                     for a in (accelerations or [None] * len(series_list))]
    names = series_list[0].names
    for s, label in zip(series_list[1:], labels[1:]):
        if set(s.names) != set(names):
            raise IdentificationError(f'{label} has joints {list(s.names)}, {labels[0]} has '
                                      f'{list(names)}: identify them separately')
    if not joints and model is not None and set(model.joint_names) < set(names):
        joints = list(model.joint_names)     # e.g. joint_1..joint_6 with 4-6 locked: 1-3
    joints = list(joints) if joints else list(names)
    missing = [j for j in joints if j not in names]
    if missing:
        shown = ', '.join(f'{b} -> {m}' for b, m in name_map.items()) or 'none'
        raise IdentificationError(f'{labels[0]}: no joint {", ".join(missing)}; joints found: '
                                  f'{", ".join(names)} (name mapping: {shown})')
    total = 'total' in torque_kinds
    if total:
        known = list(model.joint_names) if model is not None else []
        lacking = [n for n in known if n not in names]
        foreign = [j for j in joints if j not in known]
        if model is None or lacking or foreign:
            raise IdentificationError(
                f'{labels[torque_kinds.index("total")]}: the torque is total, so the '
                f'rigid-body model is subtracted, and it knows only {", ".join(known)} (all '
                f'needed); the data have {", ".join(names)}. Map the names with --map-joint '
                'BAG_NAME:MODEL_NAME, or, for another robot, import the friction torque '
                '(--torque-kind friction)')
    # sweep candidates: eq. 4.8 on the holds (cheap; needs no model unless compensating)
    sweep = {}
    if config.method in ('auto', 'sweep'):
        kinds_ok = [s for s in series_list]
        res = identify_series(kinds_ok, joints, config.fit,
                              model=model if (model_compensation and total) else None,
                              labels=labels)
        sweep = {r.name: r for r in res}
    results = []
    tau_f_cache = {}
    for j in joints:
        v_min_j = _v_min(series_list, j, config.samples)
        moving = sum(_moving_time(s, j, v_min_j) for s in series_list)
        sw = sweep.get(j)
        # sweeps: the holds are most of the motion (then eq. 4.8's answer, or its error,
        # e.g. too few speeds, stands: a fit on the ramps between holds is no better)
        is_sweep = (sw is not None and sw.hold_time_s > 0
                    and sw.hold_time_s >= config.sweep_hold_fraction * moving)
        if config.method == 'sweep' or (config.method == 'auto' and is_sweep):
            note = (f'{j}: method sweep (eq. 4.8): {len(sw.points)} speeds, holds '
                    f'{sw.hold_time_s:.1f} s of {moving:.1f} s moving')
            if sw.error and config.method == 'auto':
                note += ' (use --method samples to fit every sample instead)'
            results.append(replace(sw, method='sweep', warnings=[note] + list(sw.warnings)))
            continue
        still = _not_moved(series_list, j, joints, config.samples)
        if still:
            results.append(JointResult(j, [], method='samples', error=still))
            continue
        why = ('forced by --method samples' if config.method == 'samples' else
               f'not sweeps (holds {sw.hold_time_s if sw else 0:.1f} s of {moving:.1f} s '
               'moving)')
        if progress:
            progress(f'{j}: method samples ({why})')
        if not tau_f_cache and total:
            tau_f_cache.update(_friction_torques(series_list, accelerations, model, config,
                                                 progress))
        t_all, v_all, f_all = [], [], []
        offset = 0.0
        for k, s in enumerate(series_list):
            col = s.names.index(j)
            tf = tau_f_cache[k][:, col] if total else s.effort[:, col]
            t_all.append(s.t - s.t[0] + offset)
            offset = t_all[-1][-1] + 10.0          # bags never share a time block
            v_all.append(tau_f_cache[('v', k)][:, col] if total else s.velocity[:, col])
            f_all.append(tf)
        t, v, f = (np.concatenate(a) for a in (t_all, v_all, f_all))
        if total and tau_f_cache.get('unresolved'):
            why += (f'; {tau_f_cache["unresolved"]} samples left out where q_dd is not '
                    'resolved (steps in acceleration)')
        try:
            fit = fit_samples(t, v, f, j, config.samples, progress)
        except SampleFitError as exc:
            results.append(JointResult(j, [], method='samples', error=str(exc),
                                       warnings=[f'{j}: method samples ({why})']))
            continue
        results.append(_sample_result(j, fit, v, f, config, why))
    notes = [f'data with gaps: {c.summary()}' for c in gap_notes if not c.clean]
    if notes:
        results = [replace(r, warnings=list(r.warnings) + notes) for r in results]
    return results


def _period(t: np.ndarray, gaps: GapConfig) -> float:
    from .gaps import period_of
    return period_of(t, gaps)[0]


def check_gaps(series_list: list[JointSeries], labels: list[str], gaps: GapConfig,
               topic: str = '/joint_states') -> tuple[list[JointSeries], list]:
    """(series without duplicates, one gaps.SeriesCheck per series). GapError (one line:
    bag, topic, gap) when gaps.on_gap is 'refuse' and a series has a gap (the methods here
    use every stretch, however short: gaps.min_segment_s does not apply)."""
    out, checks = [], []
    gaps = replace(gaps, min_segment_s=0.0)
    for s, label in zip(series_list, labels):
        chk, keep, _ = check_series(s.t, label, topic, gaps)
        checks.append(chk)
        out.append(s if keep.all() else JointSeries(
            s.t[keep], s.names, s.position[keep], s.velocity[keep], s.effort[keep]))
    return out, checks


def _v_min(series_list: list[JointSeries], joint: str, config: SampleFitConfig) -> float:
    """The slowest speed the samples method uses for ``joint`` (relative to its top speed,
    sample_fit.resolve_v_min), over all series."""
    v = np.concatenate([s.velocity[:, s.names.index(joint)] for s in series_list])
    return resolve_v_min(v, config)[0]


def _not_moved(series_list: list[JointSeries], joint: str, joints: list[str],
               config: SampleFitConfig) -> str | None:
    """Why ``joint`` did not move on its own (its top speed below v_min_fraction x the
    fastest selected joint's: carried by the others' motion, noise), or None."""
    tops = {}
    for n in joints:
        v = np.abs(np.concatenate([s.velocity[:, s.names.index(n)] for s in series_list]))
        v = v[np.isfinite(v)]
        tops[n] = float(np.quantile(v, config.top_quantile)) if len(v) else 0.0
    fastest = max(tops, key=tops.get)
    if tops[joint] < config.v_min_fraction * tops[fastest]:
        return (f'{joint}: not moved on its own: top speed {tops[joint]:.3g} rad/s is below '
                f'{config.v_min_fraction:g} x that of {fastest} ({tops[fastest]:.3g} rad/s); '
                f'select it alone (--joints {joint}) to fit it anyway')
    return None


def _moving_time(s: JointSeries, joint: str, v_min: float) -> float:
    col = s.names.index(joint)
    if len(s.t) < 2:
        return 0.0
    dt = np.diff(s.t, append=s.t[-1])
    dt = np.minimum(dt, 5 * float(np.median(np.diff(s.t))))
    return float(np.sum(dt[np.abs(s.velocity[:, col]) >= v_min]))


def _friction_torques(series_list, accelerations, model, config, progress) -> dict:
    """effort - (M q_dd + C q_d + g) (N, n) per series, in the series' joint order."""
    out = {}
    idx_model = None
    for k, (s, acc) in enumerate(zip(series_list, accelerations)):
        # q_dd never across a missing sample (bridging even 1-3 of them by interpolating
        # the speed moved joint 3's samples fit from Coulomb 9.01 to 9.57 N m, see
        # doc/readers.md)
        split = replace(config.gaps, bridge_samples=0).split_s(_period(s.t, config.gaps))
        idx_model = [s.names.index(n) for n in model.joint_names]
        q, qd = s.position[:, idx_model], s.velocity[:, idx_model]
        if acc is not None:
            a = acc.select(list(s.names))
            qdd = np.column_stack([np.interp(s.t, a.t, a.position[:, c])
                                   for c in range(len(s.names))])[:, idx_model]
            if not np.all(np.isfinite(qdd)):
                qdd = acceleration(s.t, qd, config.accel_window_s, split)
        else:
            qdd = acceleration(s.t, qd, config.accel_window_s, split)
        floor = np.array([_v_min(series_list, n, config.samples) for n in model.joint_names])
        rows = np.any((np.abs(qd) >= floor) & (qd != 0), axis=1)
        if acc is None:
            short = acceleration(s.t, qd, config.accel_check_window_s, split)
            steady = np.all(np.abs(short - qdd) <= config.accel_tolerance
                            + 0.1 * np.abs(qdd), axis=1)
        else:
            steady = np.ones(len(s.t), bool)
        if progress:
            progress(f'rigid-body torque on {int(rows.sum())} samples')
        lag = config.fit.segments.effort_lag_s       # torque acted at t - lag: at q - qd lag
        rb = rigid_body_torque(model, q - lag * qd if lag else q, qd, qdd, rows)
        tf = np.full(s.effort.shape, np.nan)
        tf[:, idx_model] = s.effort[:, idx_model] - rb
        tf[~steady] = np.nan
        out[k] = tf
        # the speed the torque acted at: v(t - lag) = v - lag q_dd
        out[('v', k)] = s.velocity.copy()
        if lag:
            out[('v', k)][:, idx_model] -= lag * qdd
        out['unresolved'] = out.get('unresolved', 0) + int(np.count_nonzero(rows & ~steady))
    return out


def _sample_result(name: str, fit, v: np.ndarray, f: np.ndarray, config: PipelineConfig,
                   why: str) -> JointResult:
    warnings = [f'{name}: method samples ({why}): {fit.samples} samples, {fit.blocks} '
                'time blocks for the intervals'] + [f'{name}: {n}' for n in fit.notes]
    vb, fb = binned_means(v, f, fit.v_min)
    poly_p, poly_n = fit.poly_positive, fit.poly_negative
    if poly_p is None:
        warnings.append(f'{name}: model {fit.model} chosen over per-sign polynomials by '
                        'held-out error: parametric model only')
    s_ok = fit.stribeck_identified
    jf = JointFriction(
        coulomb=fit.coulomb, static=fit.static if s_ok else fit.coulomb,
        stribeck_velocity=fit.stribeck_velocity, viscous=fit.viscous,
        valid_range=tuple(float(x) for x in fit.valid_range), polynomial_positive=poly_p,
        polynomial_negative=poly_n, ci95=dict(fit.ci95),
        coulomb_positive=fit.coulomb_positive, coulomb_negative=fit.coulomb_negative,
        static_positive=fit.static if s_ok else None,
        static_negative=fit.static if s_ok else None, offset=fit.offset,
        degenerate_reason='; '.join(fit.problems), fit_report=fit.report())
    return JointResult(name, [], friction=jf, warnings=warnings, method='samples', sample=fit,
                       degenerate=list(fit.problems), binned=(vb, fb))


def report_entry(r: JointResult) -> dict:
    """The JSON report's entry of one joint."""
    entry = {'method': r.method, 'error': r.error, 'warnings': list(r.warnings),
             'degenerate': bool(r.degenerate), 'degenerate_reasons': list(r.degenerate)}
    if r.method == 'sweep':
        entry.update(speeds=len(r.points), hold_time_s=r.hold_time_s, rejected_segments=[
            {'bag': label, 'speed_rad_s': x.speed, 't_start_s': x.t_start, 't_end_s': x.t_end,
             'reason': x.reason} for label, x in r.rejected])
        if r.parametric is not None:
            pf = r.parametric
            entry.update(coulomb=pf.coulomb, static=pf.static,
                         stribeck_velocity=pf.stribeck_velocity, viscous=pf.viscous,
                         ci95=pf.ci95, rmse=pf.rmse)
    elif r.sample is not None:
        fit = r.sample
        entry.update(
            offset=fit.offset, coulomb_positive=fit.coulomb_positive,
            coulomb_negative=fit.coulomb_negative, coulomb=fit.coulomb, static=fit.static,
            stribeck_velocity=fit.stribeck_velocity if fit.stribeck_identified else None,
            viscous=fit.viscous, ci95=fit.ci95, rmse=fit.rmse,
            rmse_symmetric_no_offset=fit.rmse_symmetric, samples=fit.samples,
            blocks=fit.blocks, stribeck_identified=fit.stribeck_identified,
            offset_identified=fit.offset_identified, fit=fit.report())
    if r.friction is not None:
        entry['valid_range'] = list(r.friction.valid_range)
    return entry


def summary_line(r: JointResult) -> str:
    """One log line per joint with the fitted figures."""
    if r.error:
        return r.error
    j = r.friction
    ci = j.ci95

    def pm(key, val, unit):
        return f'{val:.4g} ± {ci[key]:.2g} {unit}' if key in ci else f'{val:.4g} {unit}'
    method = r.method + (f', {r.sample.model}' if r.sample is not None else '')
    text = (f'{r.name} [{method}]: F_c+ {pm("coulomb_positive", j.coulomb_positive, "N m")}'
            f', F_c- {pm("coulomb_negative", j.coulomb_negative, "N m")}, '
            if not j.symmetric else f'{r.name} [{method}]: F_c '
            f'{pm("coulomb", j.coulomb, "N m")}, ')
    text += (f'F_s {pm("static", j.static, "N m")}, v_s '
             f'{pm("stribeck_velocity", j.stribeck_velocity, "rad/s")}, ' if j.static != j.coulomb
             else 'no Stribeck term, ')
    text += f'F_v {pm("viscous", j.viscous, "N m s/rad")}'
    if j.offset:
        text += f', offset {pm("offset", j.offset, "N m")}'
    if r.degenerate:
        text += ' -- DEGENERATE: ' + '; '.join(r.degenerate)
    return text


__all__ = ['PipelineConfig', 'identify_joints', 'check_gaps', 'GapError', 'report_entry',
           'summary_line',
           'IdentificationError', 'acceleration']
