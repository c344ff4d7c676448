"""Scoring the candidate library against the residual: BIC, block bootstrap, decision.

For each candidate effect and each joint j of its channel the residual y (the nominal model's
error) is regressed on the effect's columns X (library.py), weighted least squares with sample
weights w (1, or block-bootstrap counts):

    beta = argmin sum w (y - X beta)^2,  RSS1 = sum w (y - X beta)^2,  RSS0 = sum w y^2
    dBIC_j = n_eff,j ln(RSS1 / RSS0) + k_j ln(n_eff,j)

with k_j the amplitudes plus one per profiled scale and n_eff = n / tau_int the effective
sample size (tau_int = 1 + 2 sum rho_k, the integrated autocorrelation time of the fitted
residual: SG smoothing and slow model errors make neighbouring samples far from independent;
the plain n would make every wiggle "significant"). A candidate's score is the sum of its
joints' negative dBIC_j (joints with dBIC_j >= 0 are left out of the effect) plus the penalty
of shared scales; link-side effects (TCP channel) choose their joint subset by BIC; time_delay
profiles the delay on the command channel. Lower is better; an effect is named when its score
is below -``bic_threshold``, it cuts the fit residual RMS of its joints by at least
``min_fit_reduction`` (an effect-size floor: the clean-data residual has small deterministic
structure, e.g. from filtering, that BIC alone calls significant) and it wins at least
``min_confidence`` of the block-bootstrap replicates, each decided by the same rule (scales
and joint sets fixed at the full-data fit, the delay re-profiled; blocks of ``block_s``).
The confidence of 'none' is the fraction of replicates where nothing passes.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
from irb_control.plant_effects import EFFECT_NAMES, effect_to_dict

from .library import (CHANNEL, COMMAND, PER_JOINT_SCALE, SHARED_SCALE, TCP, TORQUE, Grids,
                      Pooled, tcp_columns, to_block, torque_columns)

CMD_FLOOR_NM = 1e-3
#: nonlinear scales profiled on a grid (fixed in bootstrap refits, so reported without CI)
GRID_SCALES = {'velocity_rad_s', 'exponent', 'time_constant_s', 't0_s', 'period_rad',
               'torque_smoothing_nm', 'offset_m'}


@dataclass
class CandidateFit:
    """Result for one effect: score (dBIC, lower = better), joints, block (parameters),
    coef/scales (for refits), per-joint dBIC and RSS, n_eff, rms reduction on the fit data."""

    name: str
    channel: str
    score: float
    joints: list
    block: object
    coef: dict
    scales: dict
    per_joint: dict = field(default_factory=dict)
    fit_reduction: float = 0.0

    def summary(self) -> dict:
        return {'effect': self.name, 'channel': self.channel, 'delta_bic': float(self.score),
                'joints': [int(j) + 1 for j in self.joints],
                'parameters': effect_to_dict(self.block),
                'fit_rms_reduction': float(self.fit_reduction), 'per_joint': self.per_joint}


def tau_int(r: np.ndarray, max_lag: int = 300) -> float:
    """Integrated autocorrelation time of a series r (n,) (>= 1), summed to the first lag
    where the autocorrelation drops below 0.05."""
    r = np.asarray(r, float)
    r = r - r.mean()
    n = len(r)
    var = float(r @ r)
    if n < 4 or var <= 0:
        return 1.0
    f = np.fft.rfft(r, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[:min(max_lag, n - 1) + 1] / var
    s = 0.0
    for k in range(1, len(ac)):
        if ac[k] < 0.05:
            break
        s += ac[k]
    return max(1.0, 1.0 + 2.0 * s)


def _wls(X, y, w):
    sw = np.sqrt(w)
    beta, *_ = np.linalg.lstsq(X * sw[:, None], y * sw, rcond=None)
    res = y - X @ beta
    return beta, float(np.sum(w * res**2)), res


def _dbic(n_eff, rss1, rss0, k):
    if rss0 <= 0 or n_eff < 2:
        return 0.0
    return n_eff * np.log(max(rss1, 1e-300) / rss0) + k * np.log(n_eff)


@dataclass
class Weights:
    """Sample weights of the three channels (1 = as measured, counts = bootstrap)."""

    tau: np.ndarray
    cam: np.ndarray
    cmd: np.ndarray

    @classmethod
    def ones(cls, P: Pooled) -> 'Weights':
        return cls(np.ones(len(P.r)), np.ones(len(P.r_tcp)), np.ones(len(P.r_cmd)))

    @classmethod
    def bootstrap(cls, P: Pooled, rng) -> 'Weights':
        blocks = np.unique(np.concatenate([P.block, P.cam_block, P.cmd_block]))
        draw = rng.choice(blocks, size=len(blocks), replace=True)
        ids, counts = np.unique(draw, return_counts=True)
        cnt = dict(zip(ids.tolist(), counts.tolist()))
        f = np.vectorize(lambda b: cnt.get(int(b), 0), otypes=[float])
        return cls(f(P.block) if len(P.block) else np.empty(0),
                   f(P.cam_block) if len(P.cam_block) else np.empty(0),
                   f(P.cmd_block) if len(P.cmd_block) else np.empty(0))


def _tau_scales(name, grids):
    key = PER_JOINT_SCALE.get(name) or SHARED_SCALE.get(name)
    return list(getattr(grids, key)) if key else [None]


def fit_torque(name: str, P: Pooled, w: np.ndarray, grids: Grids, fixed: CandidateFit | None
               = None, tau_ratio: dict | None = None) -> CandidateFit:
    """Torque-channel candidate (see module docstring). ``fixed``: keep its scales/joints."""
    per_joint_scale = name in PER_JOINT_SCALE
    shared = name in SHARED_SCALE
    scales_try = _tau_scales(name, grids)
    if fixed is not None:
        scales_try = [fixed.scales.get('shared')] if shared else scales_try
    masks = [P.mask[:, j] & (w > 0) for j in range(3)]
    if name == 'payload_mass':
        return _fit_payload(P, w, grids, fixed, tau_ratio)
    best = None
    for s_shared in (scales_try if shared else [None]):
        coef, scales, pj, total, rss = {}, {}, {}, 0.0, {}
        for j in range(3):
            m = masks[j]
            if m.sum() < 20:
                continue
            y, ww = P.r[m, j], w[m]
            rss0 = float(np.sum(ww * y**2))
            cands = ([fixed.scales.get(j, scales_try[0])] if (fixed is not None
                     and per_joint_scale) else (scales_try if per_joint_scale
                                                else [s_shared]))
            fits = []
            for s in cands:
                X = torque_columns(name, P, j, s)[m]
                beta, rss1, res = _wls(X, y, ww)
                fits.append((rss1, s, beta, res, X.shape[1]))
            if per_joint_scale and fixed is None and len(cands) > 2:
                # refine the profiled scale between the coarse neighbours of the best one
                i = int(np.argmin([f[0] for f in fits]))
                lo, hi = cands[max(i - 1, 0)], cands[min(i + 1, len(cands) - 1)]
                for s in np.geomspace(lo, hi, 25)[1:-1]:
                    X = torque_columns(name, P, j, float(s))[m]
                    beta, rss1, res = _wls(X, y, ww)
                    fits.append((rss1, float(s), beta, res, X.shape[1]))
            rss1, s, beta, res, p = min(fits, key=lambda f: f[0])
            if tau_ratio is not None and (name, j) in tau_ratio:
                n_eff = float(ww.sum()) / tau_ratio[(name, j)]
            else:
                n_eff = len(y) / tau_int(res)
            k = p + (1 if per_joint_scale else 0)
            d = _dbic(n_eff, rss1, rss0, k)
            pj[j] = {'delta_bic': float(d), 'n': int(len(y)), 'n_eff': float(n_eff),
                     'rss0': rss0, 'rss1': rss1, 'coef': beta.tolist(),
                     'scale': None if s is None else float(s)}
            rss[j] = (rss0, rss1)
            in_effect = d < 0 if fixed is None else j in fixed.joints
            if in_effect:
                coef[j] = beta
                scales[j] = s
                total += d
        if shared and coef:
            n_all = sum(pj[j]['n_eff'] for j in coef)
            total += np.log(max(n_all, 2.0))
            scales['shared'] = s_shared
        if best is None or total < best[0]:
            best = (total, coef, scales, pj, rss)
    total, coef, scales, pj, rss = best
    if shared and 'shared' not in scales:
        scales['shared'] = scales_try[0]
    red = _reduction([rss[j] for j in coef])
    return CandidateFit(name, TORQUE, float(total), sorted(coef), to_block(name, coef, scales),
                        coef, scales, pj, red)


def _reduction(pairs):
    if not pairs:
        return 0.0
    r0 = sum(a for a, _ in pairs)
    r1 = sum(b for _, b in pairs)
    return float(1.0 - np.sqrt(r1 / r0)) if r0 > 0 else 0.0


def _fit_payload(P, w, grids, fixed, tau_ratio):
    zs = [fixed.scales['shared']] if fixed is not None else list(grids.payload_offset_z)
    masks = [P.mask[:, j] & (w > 0) for j in range(3)]
    rss0 = [float(np.sum(w[m] * P.r[m, j] ** 2)) for j, m in enumerate(masks)]
    n = [int(m.sum()) for m in masks]
    sig2 = [max(rss0[j] / max(n[j], 1), 1e-12) for j in range(3)]
    best = None
    for z in zs:
        U = P.payload_unit[z]
        num = sum(float(np.sum(w[m] * U[m, j] * P.r[m, j])) / sig2[j]
                  for j, m in enumerate(masks))
        den = sum(float(np.sum(w[m] * U[m, j] ** 2)) / sig2[j] for j, m in enumerate(masks))
        mass = num / den if den > 0 else 0.0
        rss1 = [float(np.sum(w[m] * (P.r[m, j] - mass * U[m, j]) ** 2))
                for j, m in enumerate(masks)]
        score = sum(n[j] * np.log(max(rss1[j], 1e-300) / rss0[j]) for j in range(3)
                    if rss0[j] > 0)
        if best is None or score < best[0]:
            best = (score, z, mass, rss1)
    _, z, mass, rss1 = best
    pj, total, joints, n_all = {}, 0.0, [], 0.0
    for j, m in enumerate(masks):
        res = P.r[m, j] - mass * P.payload_unit[z][m, j]
        key = ('payload_mass', j)
        n_eff = (float(w[m].sum()) / tau_ratio[key] if tau_ratio and key in tau_ratio
                 else n[j] / tau_int(res))
        d = _dbic(n_eff, rss1[j], rss0[j], 0)
        pj[j] = {'delta_bic': float(d), 'n': n[j], 'n_eff': float(n_eff), 'rss0': rss0[j],
                 'rss1': rss1[j], 'coef': [float(mass)], 'scale': float(z)}
        total += d
        n_all += n_eff
        if d < -10:
            joints.append(j)
    total += 2 * np.log(max(n_all, 2.0))      # mass and the profiled offset
    coef, scales = {'all': np.array([mass])}, {'shared': z}
    return CandidateFit('payload_mass', TORQUE, float(total), joints,
                        to_block('payload_mass', coef, scales), coef, scales, pj,
                        _reduction(list(zip(rss0, rss1))))


def fit_tcp(name: str, P: Pooled, w: np.ndarray, grids: Grids, fixed: CandidateFit | None
            = None, tau_ratio: dict | None = None) -> CandidateFit:
    """Link-side candidate on the camera residual: joint subset and scale by BIC."""
    M = len(P.r_tcp)
    if M < 20 or np.sum(w > 0) < 20:
        return CandidateFit(name, TCP, 0.0, [], to_block(name, {}, {'shared': 2.0}), {},
                            {'shared': 2.0})
    y = P.r_tcp.reshape(-1)
    ww = np.repeat(w, 3)
    rss0 = float(np.sum(ww * y**2))
    scales = ([fixed.scales['shared']] if fixed is not None else
              (list(grids.backlash_smoothing) if name == 'backlash' else [None]))
    subsets = ([tuple(fixed.joints)] if fixed is not None else
               [s for k in (1, 2, 3) for s in combinations(range(3), k)])
    best = None
    for s in scales:
        X = tcp_columns(name, P, s)
        for sub in subsets:
            if not sub:
                continue
            beta, rss1, res = _wls(X[:, list(sub)], y, ww)
            best_c = (rss1, s, sub, beta, res)
            if best is None or _prelim(best_c, rss0, M) < _prelim(best, rss0, M):
                best = best_c
    if best is None:
        return CandidateFit(name, TCP, 0.0, [], to_block(name, {}, {'shared': 2.0}), {},
                            {'shared': 2.0})
    rss1, s, sub, beta, res = best
    key = (name, 'tcp')
    n_eff = (3 * float(w.sum()) / tau_ratio[key] if tau_ratio and key in tau_ratio
             else 3 * M / np.mean([tau_int(res.reshape(-1, 3)[:, i]) for i in range(3)]))
    k = len(sub) + (1 if name == 'backlash' else 0)
    d = _dbic(n_eff, rss1, rss0, k)
    coef = {j: np.array([beta[i]]) for i, j in enumerate(sub)}
    sc = {'shared': s if s is not None else 2.0}
    pj = {'tcp': {'delta_bic': float(d), 'n': int(3 * M), 'n_eff': float(n_eff),
                  'rss0': rss0, 'rss1': rss1, 'coef': beta.tolist(),
                  'scale': None if s is None else float(s)}}
    return CandidateFit(name, TCP, float(d), list(sub), to_block(name, coef, sc), coef, sc,
                        pj, _reduction([(rss0, rss1)]))


def _prelim(c, rss0, M):
    rss1, s, sub, *_ = c
    return 3 * M * np.log(max(rss1, 1e-300) / rss0) / 10 + len(sub) * np.log(3 * M / 10)


def fit_delay(P: Pooled, w: np.ndarray, grids: Grids, fixed: CandidateFit | None = None,
              tau_ratio: dict | None = None) -> CandidateFit:
    """Extra command-to-effort delay d (profiled on the grid) on the command channel."""
    name = 'time_delay'
    K = len(P.r_cmd)
    if K < 20:
        return CandidateFit(name, COMMAND, 0.0, [], to_block(name, {}, {'shared': 0.0}), {},
                            {'shared': 0.0})
    floor = CMD_FLOOR_NM**2 * float(w.sum())
    r = P.eff[None] - P.cmd_pred                      # (D, K, 3)
    rss = np.einsum('k,dkj->dj', w, r**2)             # (D, 3)
    k = int(np.argmin(rss.sum(axis=1)))      # cheap: re-profiled in the bootstrap too
    d_s = float(P.delays[k])
    pj, total, joints = {}, 0.0, []
    n_all = 0.0
    for j in range(3):
        key = (name, j)
        n_eff = (float(w.sum()) / tau_ratio[key] if tau_ratio and key in tau_ratio
                 else K / tau_int(r[k, :, j]))
        rss0, rss1 = max(float(rss[0, j]), floor), max(float(rss[k, j]), floor)
        d = _dbic(n_eff, rss1, rss0, 0)
        pj[j] = {'delta_bic': float(d), 'n': K, 'n_eff': float(n_eff), 'rss0': rss0,
                 'rss1': rss1, 'coef': [d_s], 'scale': d_s}
        total += d
        n_all += n_eff
        if d < -10:
            joints.append(j)
    total += np.log(max(n_all, 2.0))
    sc = {'shared': d_s}
    red = _reduction([(max(float(rss[0, j]), floor), max(float(rss[k, j]), floor))
                      for j in range(3)])
    return CandidateFit(name, COMMAND, float(total) if k > 0 else 0.0, joints,
                        to_block(name, {}, sc), {}, sc, pj, red)


def fit_candidate(name: str, P: Pooled, w: Weights | None = None, grids: Grids = Grids(),
                  fixed: CandidateFit | None = None, tau_ratio: dict | None = None
                  ) -> CandidateFit:
    """Score one effect of EFFECT_NAMES on the pooled data."""
    w = w or Weights.ones(P)
    ch = CHANNEL[name]
    if ch == TORQUE:
        return fit_torque(name, P, w.tau, grids, fixed, tau_ratio)
    if ch == TCP:
        return fit_tcp(name, P, w.cam, grids, fixed, tau_ratio)
    return fit_delay(P, w.cmd, grids, fixed, tau_ratio)


def _tau_ratios(fit: CandidateFit) -> dict:
    """n / n_eff of the full-data fit, reused by the bootstrap refits."""
    out = {}
    for j, d in fit.per_joint.items():
        if d.get('n_eff'):
            out[(fit.name, j)] = d['n'] / d['n_eff'] / (3 if j == 'tcp' else 1)
    return out


@dataclass
class Selection:
    """Ranked candidates, the decision and its bootstrap support."""

    ranked: list
    effect: str
    winner: CandidateFit | None
    confidence: float
    wins: dict
    intervals: dict


def select(P: Pooled, grids: Grids = Grids(), bic_threshold: float = 30.0,
           min_confidence: float = 0.6, n_boot: int = 40, seed: int = 0,
           min_fit_reduction: float = 0.2) -> Selection:
    """Fit every candidate, rank by score, bootstrap the ranking, decide (or 'none')."""
    fits = [fit_candidate(n, P, grids=grids) for n in EFFECT_NAMES]
    ranked = sorted(fits, key=lambda f: f.score)
    top = ranked[0]
    rng = np.random.default_rng(seed)
    wins = {n: 0 for n in EFFECT_NAMES}
    wins['none'] = 0
    params = []
    ratios = {}
    for f in fits:
        ratios.update(_tau_ratios(f))
    for _ in range(n_boot):
        w = Weights.bootstrap(P, rng)
        bf = [fit_candidate(f.name, P, w, grids, fixed=f, tau_ratio=ratios) for f in fits]
        b = min(bf, key=lambda f: f.score)
        named = b.score < -bic_threshold and b.fit_reduction >= min_fit_reduction
        wins[b.name if named else 'none'] += 1
        if b.name == top.name:
            params.append(effect_to_dict(b.block))
    support = wins[top.name] / max(n_boot, 1)
    passes = (top.score < -bic_threshold and support >= min_confidence
              and top.fit_reduction >= min_fit_reduction)
    effect = top.name if passes else 'none'
    confidence = support if effect != 'none' else wins['none'] / max(n_boot, 1)
    intervals = {}
    if params:
        for key, v0 in effect_to_dict(top.block).items():
            if key in GRID_SCALES:
                # profiled on a grid and held fixed in the bootstrap: no interval
                intervals[key] = {'value': v0, 'ci95': None, 'profiled_on_grid': True}
                continue
            arr = np.array([p[key] for p in params], float)
            lo, hi = np.nanpercentile(arr, [2.5, 97.5], axis=0)
            intervals[key] = {'value': v0, 'ci95': [np.asarray(lo).tolist(),
                                                    np.asarray(hi).tolist()]}
    return Selection(ranked, effect, top if passes else None, float(confidence), wins,
                     intervals)
