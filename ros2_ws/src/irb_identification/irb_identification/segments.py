"""Constant-speed segments and the eq. 4.8 friction points. No rclpy.

``find_segments`` finds, per joint, the stretches where that joint moves at a constant speed
while the others stand still (the holds of eq. 4.1), trims their transients and averages speed
and torque over them. ``speed_points`` pairs the +c and -c segments of equal speed and applies
eq. 4.8, tau_f(c) = (tau_+ - tau_-) / 2, which cancels gravity because both holds cover the
same positions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .series import JointSeries


@dataclass(frozen=True)
class SegmentConfig:
    """Detection settings.

    window_s [s]: rolling window for the constancy test; velocity_tol [rad/s] and
    velocity_rel_tol [-]: allowed rolling std of the speed, tol + rel_tol |v|; min_speed
    [rad/s]: slower is "standing still"; min_duration_s [s]: shortest usable hold (after
    trimming); trim_s [s] and trim_fraction [-]: cut from both ends of a hold; still_tol
    [rad/s]: mean speed allowed on the other joints (plus still_rel_tol |v|).
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


@dataclass(frozen=True)
class Segment:
    """One constant-speed hold of ``joint`` (index): times [s], mean/std speed [rad/s],
    mean/std torque [N m], mean model torque without friction [N m] (nan if not computed),
    samples, position range [rad]."""

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


@dataclass(frozen=True)
class SpeedPoint:
    """A +c/-c pair: speed c > 0 [rad/s]; tau_plus, tau_minus mean torques [N m];
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


def _rolling(x: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Centred rolling mean and std over ``w`` samples (edges use partial windows)."""
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


def find_segments(series: JointSeries, joint: int, config: SegmentConfig = SegmentConfig(),
                  model_torque=None) -> list[Segment]:
    """Constant-speed holds of ``joint`` with the other joints still.

    ``model_torque``, optional: callable (q (k, n) [rad], qd (k, n) [rad/s]) -> (k, n) [N m],
    M qdd + C qd + g without friction at qdd = 0; its segment mean (over up to 50 samples)
    gives the model-compensated per-sign friction.
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
    mean, std = _rolling(v, w)
    ok = ((np.abs(mean) > config.min_speed)
          & (std < config.velocity_tol + config.velocity_rel_tol * np.abs(mean))
          & np.isfinite(tau))
    # a sign change inside a run splits it
    ok &= np.concatenate([[True], np.sign(mean[1:]) == np.sign(mean[:-1])])
    others = [k for k in range(series.velocity.shape[1]) if k != joint]
    out = []
    for a, b in _runs(ok):
        dur = t[b - 1] - t[a]
        cut = config.trim_s + config.trim_fraction * dur
        sel = np.flatnonzero((t >= t[a] + cut) & (t <= t[b - 1] - cut))
        if len(sel) < 3 or t[sel[-1]] - t[sel[0]] < config.min_duration_s:
            continue
        vs = v[sel]
        c = float(vs.mean())
        if others:
            still = np.abs(series.velocity[sel][:, others].mean(axis=0))
            if np.any(still > config.still_tol + config.still_rel_tol * abs(c)):
                continue
        half = len(sel) // 2
        if abs(vs[:half].mean() - vs[half:].mean()) > (config.velocity_tol
                                                       + config.velocity_rel_tol * abs(c)):
            continue                     # drifting speed: not a hold
        qs = series.position[sel, joint]
        mt = np.nan
        if model_torque is not None:
            sub = sel[np.linspace(0, len(sel) - 1, min(50, len(sel))).astype(int)]
            mt = float(np.mean(model_torque(series.position[sub],
                                            series.velocity[sub])[:, joint]))
        out.append(Segment(joint, float(t[sel[0]]), float(t[sel[-1]]), c, float(vs.std()),
                           float(tau[sel].mean()), float(tau[sel].std()), mt, len(sel),
                           (float(qs.min()), float(qs.max()))))
    return out


def speed_points(segments: list[Segment], rel_tol: float = 0.1
                 ) -> tuple[list[SpeedPoint], list[str]]:
    """Pair +c and -c segments whose |speed| agree within ``rel_tol``; apply eq. 4.8.

    Returns the points (sorted by speed) and warnings for speeds seen with one sign only.
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

        def wmean(ss, attr):
            w = np.array([s.samples for s in ss], float)
            return float(np.sum(w * np.array([getattr(s, attr) for s in ss])) / w.sum())

        tp, tm = wmean(pos, 'torque'), wmean(neg, 'torque')
        tau_f = 0.5 * (tp - tm)
        gp, gm = wmean(pos, 'model_torque'), wmean(neg, 'model_torque')
        if np.isfinite(gp) and np.isfinite(gm):
            f_pos, f_neg = tp - gp, tm - gm
        else:
            f_pos, f_neg = tau_f, -tau_f

        def sem(ss):
            return float(np.sqrt(np.sum([s.torque_std**2 / s.samples for s in ss])) / len(ss))

        points.append(SpeedPoint(c, tp, tm, tau_f, f_pos, f_neg,
                                 0.5 * float(np.hypot(sem(pos), sem(neg))), len(pos), len(neg)))
    return points, warnings
