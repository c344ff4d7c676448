"""Constant-speed segments and the eq. 4.8 friction points. No rclpy.

``find_segments`` finds, per joint, the stretches where that joint moves at a constant speed
while the others stand still (the holds of eq. 4.1), trims their transients and averages speed
and torque over them (torque as a time average, so that samples the recorder dropped do not
bias it). A stretch that passes the local (rolling) constancy test but shows a stick-slip
signature over its whole length - the joint stops inside it, or its speed is not steady
within the tolerance - is rejected, and the rejection is returned with its reason for the
caller to report: its mean torque is not the friction at a constant speed. ``speed_points``
pairs the +c and -c segments of equal speed and applies eq. 4.8,
tau_f(c) = (tau_+ - tau_-) / 2, which cancels gravity because both holds cover the same
positions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .gaps import DEFAULT_SPLIT_S
from .series import JointSeries


@dataclass(frozen=True)
class SegmentConfig:
    """Detection settings.

    window_s [s]: rolling window for the constancy test; velocity_tol [rad/s] and
    velocity_rel_tol [-]: allowed rolling std of the speed, tol + rel_tol |v|; min_speed
    [rad/s]: slower is "standing still"; min_duration_s [s]: shortest usable hold (after
    trimming); trim_s [s] and trim_fraction [-]: cut from both ends of a hold; still_tol
    [rad/s]: mean speed allowed on the other joints (plus still_rel_tol |v|).
    Stick-slip rejection of a (trimmed) hold at mean speed c: stick_samples consecutive
    samples with v sign(c) < stick_fraction |c| [-] (the joint stops or turns back inside the
    hold), or a speed std over the whole hold above velocity_tol + velocity_rel_tol |c|.
    effort_lag_s [s]: the effort of a sample is the torque that acted at t - effort_lag_s on
    average (e.g. half a period when it is the mean applied torque of the period before the
    sample); the torque is then referred to the position q - v effort_lag_s. At constant speed
    c this matters where gravity varies with position: a slope g' [N m/rad] would otherwise
    bias eq. 4.8 by g' c effort_lag_s (like extra viscous friction).
    split_gap_s [s]: a step between samples at least this long (a gap of recorded data,
    default gaps.GapConfig's: more than 3 samples missing at 4.032 ms) ends a hold; the
    samples after it start a new one (no average across a gap; shorter gaps are bridged by
    the time-weighted mean).
    """

    window_s: float = 0.1
    velocity_tol: float = 0.006
    velocity_rel_tol: float = 0.03
    min_speed: float = 0.005
    min_duration_s: float = 0.15
    trim_s: float = 0.05
    trim_fraction: float = 0.15
    still_tol: float = 0.01
    still_rel_tol: float = 0.1
    stick_fraction: float = 0.25
    stick_samples: int = 3
    effort_lag_s: float = 0.0
    split_gap_s: float = DEFAULT_SPLIT_S


@dataclass(frozen=True)
class Segment:
    """One constant-speed hold of ``joint`` (index): times [s], mean/std speed [rad/s],
    mean (time average)/std torque [N m], mean model torque without friction [N m] (nan if
    not computed), samples, position range [rad], q_mean [rad]: the time-averaged position
    where the torque acted (minus effort_lag_s x speed), torque_slope [N m/rad]: the slope of
    torque over position within the hold (gravity)."""

    joint: int
    t_start: float
    t_end: float
    speed: float
    speed_std: float
    torque: float
    torque_std: float
    model_torque: float
    samples: int
    q_range: tuple[float, float]
    q_mean: float = float('nan')
    torque_slope: float = 0.0


@dataclass(frozen=True)
class Rejection:
    """A hold of ``joint`` (index) not used, from t_start to t_end [s] at mean speed
    [rad/s], and why (``reason``, one line with the numbers)."""

    joint: int
    t_start: float
    t_end: float
    speed: float
    reason: str


@dataclass(frozen=True)
class SpeedPoint:
    """A +c/-c pair: speed c > 0 [rad/s]; tau_plus, tau_minus mean torques [N m], both
    referred to the same position (see ``speed_points``);
    tau_f = (tau_plus - tau_minus) / 2 (eq. 4.8); per-sign friction f_pos = tau_f(+c) > 0 and
    f_neg = tau_f(-c) < 0 [N m] (model-compensated if a model torque was given, else +-tau_f);
    sem: standard error of tau_f [N m]; segments used on each side."""

    speed: float
    tau_plus: float
    tau_minus: float
    tau_f: float
    f_pos: float
    f_neg: float
    sem: float
    n_plus: int
    n_minus: int


def rolling_mean_std(x: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Centred rolling mean and std (N,) of x (N,) over ``w`` samples (edges use partial
    windows)."""
    c1 = np.concatenate([[0.0], np.cumsum(x)])
    c2 = np.concatenate([[0.0], np.cumsum(x * x)])
    n = len(x)
    lo = np.clip(np.arange(n) - w // 2, 0, n)
    hi = np.clip(np.arange(n) + (w - w // 2), 0, n)
    cnt = hi - lo
    mean = (c1[hi] - c1[lo]) / cnt
    var = np.maximum((c2[hi] - c2[lo]) / cnt - mean**2, 0.0)
    return mean, np.sqrt(var)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index pairs of the True runs of ``mask``."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def split_runs(runs: list[tuple[int, int]], starts: np.ndarray) -> list[tuple[int, int]]:
    """The [start, end) runs cut so that every index in ``starts`` (sorted: the first
    sample after a gap) begins a run."""
    out = []
    for a, b in runs:
        lo, hi = np.searchsorted(starts, [a + 1, b])
        edges = [a] + [int(x) for x in starts[lo:hi]] + [b]
        out.extend((x, y) for x, y in zip(edges[:-1], edges[1:]) if y > x)
    return out


def stick_slip(v: np.ndarray, config: SegmentConfig = SegmentConfig()) -> str | None:
    """Why the speeds v (k,) [rad/s] of one hold are not a steady constant speed (stick-slip
    signature, see SegmentConfig), or None if they are."""
    c = float(np.mean(v))
    tol = config.velocity_tol + config.velocity_rel_tol * abs(c)
    stuck = np.sign(c) * v < config.stick_fraction * abs(c)
    longest = max((b - a for a, b in _runs(stuck)), default=0)
    if longest >= config.stick_samples:
        return (f'the joint stops inside the hold ({int(stuck.sum())} samples '
                f'below {config.stick_fraction:g} x {abs(c):.4g} rad/s, longest run '
                f'{longest})')
    std = float(np.std(v))
    if std > tol:
        return f'speed not steady (std {std:.4g} > {tol:.4g} rad/s)'
    return None


def find_segments(series: JointSeries, joint: int, config: SegmentConfig = SegmentConfig(),
                  model_torque=None, rejected: list | None = None) -> list[Segment]:
    """Constant-speed holds of ``joint`` with the other joints still.

    ``model_torque``, optional: callable (q (k, n) [rad], qd (k, n) [rad/s]) -> (k, n) [N m],
    M qdd + C qd + g without friction at qdd = 0; its segment mean (over up to 50 samples)
    gives the model-compensated per-sign friction. ``rejected``, optional: a list that gets
    a ``Rejection`` for every hold dropped for a stick-slip signature.
    """
    t = series.t
    if len(t) < 3:
        return []
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        return []
    v = series.velocity[:, joint]
    tau = series.effort[:, joint]
    w = max(3, int(round(config.window_s / dt)))
    mean, std = rolling_mean_std(v, w)
    ok = ((np.abs(mean) > config.min_speed)
          & (std < config.velocity_tol + config.velocity_rel_tol * np.abs(mean))
          & np.isfinite(tau))
    # a sign change inside a run splits it
    ok &= np.concatenate([[True], np.sign(mean[1:]) == np.sign(mean[:-1])])
    others = [k for k in range(series.velocity.shape[1]) if k != joint]
    out = []
    for a, b in split_runs(_runs(ok), np.flatnonzero(np.diff(t) >= config.split_gap_s) + 1):
        dur = t[b - 1] - t[a]
        cut = config.trim_s + config.trim_fraction * dur
        # t is sorted: the trimmed hold by bisection (a mask over all of t per run made
        # long non-sweep logs, with thousands of short runs, quadratic)
        sel = np.arange(np.searchsorted(t, t[a] + cut, 'left'),
                        np.searchsorted(t, t[b - 1] - cut, 'right'))
        if len(sel) < 3 or t[sel[-1]] - t[sel[0]] < config.min_duration_s:
            continue
        vs = v[sel]
        c = float(vs.mean())
        if others:
            still = np.abs(series.velocity[sel][:, others].mean(axis=0))
            if np.any(still > config.still_tol + config.still_rel_tol * abs(c)):
                continue
        why = stick_slip(vs, config)
        if why is not None:
            if rejected is not None:
                rejected.append(Rejection(joint, float(t[sel[0]]), float(t[sel[-1]]), c, why))
            continue
        half = len(sel) // 2
        if abs(vs[:half].mean() - vs[half:].mean()) > (config.velocity_tol
                                                       + config.velocity_rel_tol * abs(c)):
            continue                     # drifting speed: not a hold
        qs = series.position[sel, joint]
        wt = time_weights(t[sel])
        q_avg = float(np.sum(wt * qs))
        dq = qs - q_avg
        sxx = float(np.sum(wt * dq * dq))
        tau_mean = float(np.sum(wt * tau[sel]))
        slope = float(np.sum(wt * dq * (tau[sel] - tau_mean)) / sxx) if sxx > 1e-18 else 0.0
        mt = np.nan
        if model_torque is not None:
            sub = np.linspace(0, len(sel) - 1, min(50, len(sel))).astype(int)
            qd_sub = series.velocity[sel[sub]]
            mts = model_torque(series.position[sel[sub]] - config.effort_lag_s * qd_sub,
                               qd_sub)[:, joint]
            mt = float(np.sum(time_weights(t[sel[sub]]) * mts))
        out.append(Segment(joint, float(t[sel[0]]), float(t[sel[-1]]), c, float(vs.std()),
                           tau_mean, float(tau[sel].std()), mt, len(sel),
                           (float(qs.min()), float(qs.max())),
                           q_avg - config.effort_lag_s * c, slope))
    return out


def time_weights(t: np.ndarray) -> np.ndarray:
    """Weights (k,) summing to 1 that turn samples at times t (k,) [s] into the time average
    of their piecewise-linear interpolation (trapezoidal rule). Equal to the plain mean's
    1/k (but half at both ends) for evenly spaced samples; a gap in the recording (dropped
    messages) does not shift the average towards the better-covered part of the hold, where
    gravity differs (eq. 4.8 needs both holds averaged over the same positions)."""
    t = np.asarray(t, float)
    if len(t) < 2 or not t[-1] > t[0]:
        return np.full(len(t), 1.0 / max(len(t), 1))
    d = np.diff(t)
    w = np.zeros(len(t))
    w[:-1] += d
    w[1:] += d
    return w / w.sum()


def speed_points(segments: list[Segment], rel_tol: float = 0.1
                 ) -> tuple[list[SpeedPoint], list[str]]:
    """Pair +c and -c segments whose |speed| agree within ``rel_tol``; apply eq. 4.8.

    Eq. 4.8 cancels gravity only if tau_+ and tau_- are taken at the same positions. The
    holds of eq. 4.1 cover the same stroke, but the detected (trimmed) segments need not:
    messages a recorder dropped at a segment's end shift it. Each side's mean torque is
    therefore moved along its own torque-over-position line (``torque_slope``) from its mean
    position to the common one, q_ref = (q_mean_+ + q_mean_-) / 2 (no change when both sides
    are centred alike). Returns the points (sorted by speed) and warnings for speeds seen
    with one sign only.
    """
    segs = sorted(segments, key=lambda s: abs(s.speed))
    clusters: list[list[Segment]] = []
    for s in segs:
        if clusters and abs(s.speed) <= abs(clusters[-1][0].speed) * (1 + rel_tol):
            clusters[-1].append(s)
        else:
            clusters.append([s])
    points, warnings = [], []
    for cl in clusters:
        pos = [s for s in cl if s.speed > 0]
        neg = [s for s in cl if s.speed < 0]
        c = float(np.mean([abs(s.speed) for s in cl]))
        if not pos or not neg:
            warnings.append(f'speed {c:.4g} rad/s seen only with sign '
                            f'{"+" if pos else "-"}: no eq. 4.8 point')
            continue
        lo = max(min(s.q_range[0] for s in pos), min(s.q_range[0] for s in neg))
        hi = min(max(s.q_range[1] for s in pos), max(s.q_range[1] for s in neg))
        span = min(max(s.q_range[1] for s in ss) - min(s.q_range[0] for s in ss)
                   for ss in (pos, neg))
        if hi - lo < 0.25 * span:      # partial overlap: the slope correction below copes
            warnings.append(f'speed {c:.4g} rad/s: the +c and -c holds cover different '
                            f'positions (overlap {max(hi - lo, 0.0):.3g} of {span:.3g} rad): '
                            'eq. 4.8 would not cancel gravity, no point')
            continue

        def wmean(ss, attr):
            w = np.array([s.samples for s in ss], float)
            return float(np.sum(w * np.array([getattr(s, attr) for s in ss])) / w.sum())

        tp, tm = wmean(pos, 'torque'), wmean(neg, 'torque')
        gp, gm = wmean(pos, 'model_torque'), wmean(neg, 'model_torque')
        if np.isfinite(gp) and np.isfinite(gm):
            f_pos, f_neg = tp - gp, tm - gm       # the model is taken at each side's positions
        qp, qm = wmean(pos, 'q_mean'), wmean(neg, 'q_mean')
        if np.isfinite(qp) and np.isfinite(qm):
            q_ref = 0.5 * (qp + qm)
            tp += wmean(pos, 'torque_slope') * (q_ref - qp)
            tm += wmean(neg, 'torque_slope') * (q_ref - qm)
        tau_f = 0.5 * (tp - tm)
        if not (np.isfinite(gp) and np.isfinite(gm)):
            f_pos, f_neg = tau_f, -tau_f

        def sem(ss):
            return float(np.sqrt(np.sum([s.torque_std**2 / s.samples for s in ss])) / len(ss))

        points.append(SpeedPoint(c, tp, tm, tau_f, f_pos, f_neg,
                                 0.5 * float(np.hypot(sem(pos), sem(neg))), len(pos), len(neg)))
    return points, warnings
