"""Trajectory-agnostic friction fit on samples (any motion, not only eq. 4.1 sweeps). No rclpy.

Model (irb_description/friction.py, one breakaway level, Coulomb per sign, offset):

    tau_f(v) = tau_0 + F_v v + (F_c+ (1 - e) + F_s e)      v > 0,   e = exp(-(v / v_s)^2)
    tau_f(v) = tau_0 + F_v v - (F_c- (1 - e) + F_s e)      v < 0

For a fixed v_s it is linear in x = (tau_0, F_c+, F_c-, F_s, F_v), so v_s is found by variable
projection: the weighted least-squares solution for x is computed in closed form for each v_s
(a log-spaced grid, then a bounded scalar search) and the v_s with the least weighted residual
wins. Samples slower than ``v_min`` are not used (sticking/presliding: the torque there is not
a function of the speed). Weights, velocity-dependent: 1 / the robust residual variance of
the sample's (sign, log-speed bin), times Huber weights, both from iteratively reweighted
least squares (noisy speed ranges such as transients or stick-slip near reversal count less;
outliers such as spikes, collisions, dropped-sample glitches hardly at all). Balancing the
bins' total weights (``balance_floor``) is available but off: on eq. 4.1 sweeps it handed
the speeds between the holds, seen only on the ramps, as much weight as a whole hold and
biased F_c by +2 % and F_v by -1 % (joint 3, offline plant).

Intervals: the residuals of a log are correlated in time (filtering, unmodelled dynamics), so
the plain (J^T W J)^-1 s^2 is far too optimistic. The covariance is the cluster-robust
sandwich A^-1 B A^-1 over time blocks of ``block_s`` (A = J^T W J, B = sum over blocks of
g_b g_b^T with g_b the block's weighted score), with Student's t on (blocks - parameters)
degrees of freedom: honest for correlated and heteroscedastic residuals, and cheap.

Honesty checks (``SampleFit.problems``): a Stribeck velocity outside the measured speeds or
with an interval wider than itself is dropped (refit without Stribeck; then the offset and the
Coulomb asymmetry cannot be told apart: offset 0, levels per sign, said so in ``notes``); a
level or viscous coefficient that is negative or whose interval is wider than its value, and
a fitted curve that is negative (not dissipative) over the measured speeds, are problems: the
map entry is marked degenerate with the reasons.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats
from scipy.optimize import minimize_scalar

NAMES = ('offset', 'coulomb_positive', 'coulomb_negative', 'static', 'viscous',
         'stribeck_velocity')


class SampleFitError(ValueError):
    """Not enough usable samples; the message names the joint's speeds and the threshold."""


@dataclass(frozen=True)
class SampleFitConfig:
    """v_min [rad/s]: slower samples are not used; min_samples: fewest samples per sign
    above v_min; speed_bins: log-spaced |v| bins per sign for the balancing weights;
    balance_floor [-]: inf = no count balancing (default); else every bin the same total
    weight, bins below balance_floor x the average count capped;
    huber_k [-]: Huber threshold in robust scales (1.4826 MAD); irls_iterations;
    block_s [s]: time blocks of the cluster-robust covariance (fewer than min_blocks blocks:
    the span is cut into min_blocks); search_bins: fine log-speed bins per balancing bin, on
    whose weighted means v_s is searched (24 x 400: 0.05 % of speed each, 0.01 to 1 rad/s);
    stribeck: try the Stribeck term at all."""

    v_min: float = 0.01
    min_samples: int = 50
    speed_bins: int = 24
    huber_k: float = 2.0
    irls_iterations: int = 2
    block_s: float = 1.0
    min_blocks: int = 20
    search_bins: int = 400
    balance_floor: float = float('inf')
    stribeck: bool = True


@dataclass(frozen=True)
class SampleFit:
    """Fitted parameters (N m, N m s/rad, rad/s), 95 % half-widths (missing = not
    identified), residual RMS over the samples [N m] of this model and of
    the symmetric Coulomb + viscous + Stribeck model without offset (what the old fit had),
    samples used, valid speed range [rad/s], notes and problems (non-empty = degenerate)."""

    offset: float
    coulomb_positive: float
    coulomb_negative: float
    static: float
    viscous: float
    stribeck_velocity: float
    ci95: dict
    rmse: float
    rmse_symmetric: float
    samples: int
    blocks: int
    valid_range: tuple[float, float]
    stribeck_identified: bool
    offset_identified: bool
    notes: list = field(default_factory=list)
    problems: list = field(default_factory=list)

    @property
    def coulomb(self) -> float:
        return 0.5 * (self.coulomb_positive + self.coulomb_negative)

    def torque(self, v) -> np.ndarray:
        v = np.asarray(v, float)
        e = np.exp(-(v / self.stribeck_velocity) ** 2) if self.stribeck_identified else 0 * v
        pos = self.coulomb_positive * (1 - e) + self.static * e
        neg = self.coulomb_negative * (1 - e) + self.static * e
        return self.offset + self.viscous * v + np.where(v > 0, pos, np.where(v < 0, -neg, 0.0))


def _columns(v: np.ndarray, vs: float | None, cols=(0, 1, 2, 3, 4)) -> np.ndarray:
    """(k, N) regressors (rows, contiguous) of (tau_0, F_c+, F_c-, F_s, F_v)[cols];
    vs None = no Stribeck term."""
    pos = v > 0
    one_e = np.ones_like(v) if vs is None else -np.expm1(-np.square(v / vs))
    rows = {0: lambda: np.ones_like(v), 1: lambda: np.where(pos, one_e, 0.0),
            2: lambda: np.where(pos, 0.0, -one_e),
            3: lambda: np.where(pos, 1.0 - one_e, one_e - 1.0), 4: lambda: v}
    return np.stack([rows[c]() for c in cols])


def _wls(X: np.ndarray, y: np.ndarray, w: np.ndarray, cols) -> tuple[np.ndarray, float]:
    """x (5,) (zeros outside ``cols``) and the weighted RSS from regressors X (k, N) of the
    columns ``cols``, by the normal equations (k x k, scaled to unit diagonal)."""
    Xw = X * w
    A = Xw @ X.T
    b = Xw @ y
    d = np.sqrt(np.maximum(np.diag(A), 1e-300))
    sol = np.linalg.lstsq(A / np.outer(d, d), b / d, rcond=1e-12)[0] / d
    x = np.zeros(5)
    x[list(cols)] = sol
    # weighted RSS = y'Wy - 2 sol'b + sol'A sol (no N-long residual pass)
    rss = float(np.dot(w * y, y) - 2 * sol @ b + sol @ A @ sol)
    return x, max(rss, 0.0)


def balance_weights(v: np.ndarray, bins: int, v_min: float) -> np.ndarray:
    """Weights (N,) giving every (sign, log |v| bin) the same total, mean 1; bins holding
    fewer than 2 % of the average bin count are capped at 50 x the average weight."""
    speed = np.abs(v)
    hi = max(float(speed.max()), v_min * 1.0001)
    edges = np.geomspace(v_min, hi * 1.0001, bins + 1)
    k = np.clip(np.searchsorted(edges, speed, side='right') - 1, 0, bins - 1)
    k = k + bins * (v < 0)
    counts = np.bincount(k, minlength=2 * bins).astype(float)
    occupied = counts > 0
    avg = len(v) / occupied.sum()
    w_bin = np.zeros(2 * bins)
    w_bin[occupied] = avg / np.maximum(counts[occupied], 0.02 * avg)
    w = w_bin[k]
    return w / w.mean()


def _blocks(t: np.ndarray, block_s: float, min_blocks: int) -> np.ndarray:
    span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    size = block_s if span / block_s >= min_blocks else max(span / min_blocks, 1e-9)
    b = np.floor((t - t[0]) / size).astype(np.int64)
    _, inv = np.unique(b, return_inverse=True)
    return inv


def fit_samples(t: np.ndarray, v: np.ndarray, tau_f: np.ndarray, name: str = 'joint',
                config: SampleFitConfig = SampleFitConfig(), progress=None) -> SampleFit:
    """Fit the friction model to samples at times t (N,) [s], speeds v (N,) [rad/s] and
    friction torques tau_f (N,) [N m]. Raises SampleFitError when too few samples move."""
    t, v, y = (np.asarray(a, float) for a in (t, v, tau_f))
    ok = np.isfinite(t) & np.isfinite(v) & np.isfinite(y)
    use = ok & (np.abs(v) >= config.v_min)
    n_pos = int(np.count_nonzero(use & (v > 0)))
    n_neg = int(np.count_nonzero(use)) - n_pos
    if min(n_pos, n_neg) < config.min_samples:
        speed_all = np.abs(v[ok])
        seen = (f'{speed_all.min():.4g}..{speed_all.max():.4g} rad/s' if len(speed_all)
                else 'no finite samples')
        raise SampleFitError(
            f'{name}: {n_pos} samples above v_min = {config.v_min:g} rad/s with v > 0 and '
            f'{n_neg} with v < 0, need {config.min_samples} of each (|v| seen: {seen})')
    if not use.all():
        t, v, y = t[use], v[use], y[use]
    if np.any(np.diff(t) < 0):
        order = np.argsort(t, kind='stable')
        t, v, y = t[order], v[order], y[order]
    speed = np.abs(v)
    notes, problems = [], []
    all_cols = [0, 1, 2, 3, 4]
    # everything but the final solve and the intervals runs on weighted means over fine
    # log-speed bins (sufficient statistics: the model depends on v only and varies little
    # within a bin of 0.2 % in speed); the final x and the intervals use every sample
    nb = config.speed_bins * config.search_bins
    fine = np.geomspace(config.v_min, speed.max() * 1.0001, nb + 1)
    kbin = np.log(speed / config.v_min)
    kbin *= nb / np.log(fine[-1] / config.v_min)
    kbin = np.clip(kbin.astype(np.int64), 0, nb - 1)
    kbin += nb * (v < 0)
    counts = np.bincount(kbin, minlength=2 * nb)
    # balancing weights: every (sign, coarse log-speed bin) the same total (balance_weights)
    coarse = counts.reshape(2 * config.speed_bins, config.search_bins).sum(axis=1)
    occupied = coarse > 0
    avg = len(v) / occupied.sum()
    w_coarse = np.zeros(len(coarse))
    w_coarse[occupied] = avg / np.maximum(coarse[occupied], config.balance_floor * avg)
    wb = (w_coarse[kbin // config.search_bins] if np.isfinite(config.balance_floor)
          else np.ones(len(v)))
    wb /= wb.mean()
    c_speed = np.cumsum(counts[:nb] + counts[nb:])
    v_lo = float(fine[np.searchsorted(c_speed, 0.005 * len(v))])
    v_hi = float(fine[min(np.searchsorted(c_speed, 0.995 * len(v)) + 1, nb)])

    def binned(w):
        W = np.bincount(kbin, w, minlength=2 * nb)
        keep = W > 0
        W = W[keep]
        return (np.bincount(kbin, w * v, minlength=2 * nb)[keep] / W,
                np.bincount(kbin, w * y, minlength=2 * nb)[keep] / W, W)

    def solve_bins(b, vs):
        cols = [1, 2, 4] if vs is None else all_cols
        return _wls(_columns(b[0], vs, cols), b[1], b[2], cols)

    def best_vs(b):
        """Variable projection: v_s minimising the weighted RSS (grid, then refine)."""
        grid = np.geomspace(max(v_lo / 4, 1e-4), 2 * v_hi, 40)
        vals = [solve_bins(b, g)[1] for g in grid]
        i = int(np.argmin(vals))
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        res = minimize_scalar(lambda a: solve_bins(b, float(np.exp(a)))[1],
                              bounds=(np.log(lo), np.log(hi)), method='bounded',
                              options={'xatol': 1e-5})
        return float(np.exp(res.x))

    def fit_torque(x, vs):
        cols = all_cols if vs is not None else [1, 2, 4]
        return x[cols] @ _columns(v, vs, cols)

    # robust IRLS with v_s profiled at every iteration
    w = wb
    stride = slice(None, None, max(1, len(v) // 200_000))
    vs = h = scale = None
    for it in range(config.irls_iterations + 1):
        b = binned(w)
        vs = best_vs(b) if config.stribeck else None
        x, _ = solve_bins(b, vs)
        if it == config.irls_iterations:
            break
        r = y - fit_torque(x, vs)
        rs = r[stride]
        scale = 1.4826 * float(np.median(np.abs(rs - np.median(rs)))) + 1e-12
        h = np.minimum(1.0, config.huber_k * scale / np.maximum(np.abs(r), 1e-300))
        # velocity-dependent weights: 1 / (robust residual variance of the speed bin), so
        # noisier speed ranges (transients, stick-slip near reversal) count less
        cb = kbin // config.search_bins
        nbin = 2 * config.speed_bins
        var_b = (np.bincount(cb, h * r * r, minlength=nbin)
                 / np.maximum(np.bincount(cb, h, minlength=nbin), 1e-12))
        var_b = np.maximum(var_b, (0.25 * scale) ** 2)
        w = wb * h / var_b[cb]
        w /= w.mean()
        if progress:
            progress(f'{name}: robust iteration {it + 1}/{config.irls_iterations}, '
                     f'v_s {vs if vs is not None else float("nan"):.4g} rad/s, '
                     f'{int(np.count_nonzero(h < 1))} samples down-weighted')
    if h is not None:
        outliers = int(np.count_nonzero(h < 0.5))
        if outliers:
            notes.append(f'{outliers} of {len(v)} samples down-weighted below 1/2 as outliers '
                         f'(Huber, k = {config.huber_k:g} robust scales of {scale:.3g} N m)')
    blocks = _blocks(t, config.block_s, config.min_blocks)
    n_blocks = int(blocks.max()) + 1

    def solve_full(vs):
        """x on every sample, and its cluster-robust covariance (with v_s if given)."""
        cols = all_cols if vs is not None else [1, 2, 4]
        k = len(cols)
        J = np.empty((k + (vs is not None), len(v)))
        J[:k] = _columns(v, vs, cols)
        Jw = J[:k] * w
        A = Jw @ J[:k].T
        bvec = Jw @ y
        d = np.sqrt(np.maximum(np.diag(A), 1e-300))
        sol = np.linalg.lstsq(A / np.outer(d, d), bvec / d, rcond=1e-12)[0] / d
        x = np.zeros(5)
        x[cols] = sol
        r = y - sol @ J[:k]
        if vs is not None:       # d model / d v_s = sign(v) hump(v) e 2 v^2 / v_s^3
            hump = np.where(v > 0, x[3] - x[1], -(x[3] - x[2]))
            J[k] = hump * np.exp(-(v / vs) ** 2) * 2 * v * v / vs**3
            A = (J * w) @ J.T
        wr = w * r
        G = np.column_stack([np.bincount(blocks, J[k] * wr, minlength=n_blocks)
                             for k in range(J.shape[0])])
        B = G.T @ G * n_blocks / max(n_blocks - 1, 1)
        keys = [NAMES[c] for c in cols] + (['stribeck_velocity'] if vs is not None else [])
        try:
            Ai = np.linalg.inv(A)
        except np.linalg.LinAlgError:
            return x, {}
        cov = Ai @ B @ Ai
        q = stats.t.ppf(0.975, max(n_blocks - len(keys), 1))
        ci = {k: float(q * np.sqrt(max(cov[i, i], 0.0))) for i, k in enumerate(keys)}
        ip, ineg = keys.index('coulomb_positive'), keys.index('coulomb_negative')
        ci['coulomb'] = float(q * 0.5 * np.sqrt(max(
            cov[ip, ip] + cov[ineg, ineg] + 2 * cov[ip, ineg], 0.0)))     # (F_c+ + F_c-)/2
        return x, ci

    stribeck_ok = vs is not None
    if vs is not None:
        x, ci = solve_full(vs)
        why = None
        hump = x[3] - 0.5 * (x[1] + x[2])
        if not v_lo <= vs <= v_hi:
            why = (f'Stribeck velocity {vs:.4g} rad/s outside the measured speeds '
                   f'{v_lo:.4g}..{v_hi:.4g} rad/s')
        elif not ci.get('stribeck_velocity', np.inf) < vs:
            why = (f'Stribeck velocity {vs:.4g} ± {ci.get("stribeck_velocity", np.inf):.3g} '
                   'rad/s: interval wider than the value')
        elif hump < 0:
            why = (f'F_s = {x[3]:.4g} below the Coulomb level {0.5 * (x[1] + x[2]):.4g} N m '
                   '(an inverted dip: the low speeds do not pin the Stribeck term)')
        elif not ci.get('static', np.inf) < abs(hump):
            why = (f'Stribeck hump F_s - F_c = {hump:.4g} N m with F_s ± '
                   f'{ci.get("static", np.inf):.3g} N m: interval wider than the hump')
        if why:
            notes.append(why + ': Stribeck term dropped (F_s = F_c)')
            stribeck_ok = False
    if not stribeck_ok:
        vs = None
        x, ci = solve_full(None)
        notes.append('without a Stribeck region the offset and the Coulomb asymmetry cannot '
                     'be told apart: offset set to 0, the levels per sign carry both')
    fc_p, fc_n = float(x[1]), float(x[2])
    fs = float(x[3]) if stribeck_ok else 0.5 * (fc_p + fc_n)
    fit = SampleFit(offset=float(x[0]) if stribeck_ok else 0.0, coulomb_positive=fc_p,
                    coulomb_negative=fc_n, static=fs, viscous=float(x[4]),
                    stribeck_velocity=float(vs) if stribeck_ok else 0.05, ci95=ci,
                    rmse=0.0, rmse_symmetric=0.0, samples=len(v), blocks=n_blocks,
                    valid_range=(v_lo, v_hi), stribeck_identified=stribeck_ok,
                    offset_identified=stribeck_ok, notes=notes, problems=problems)
    # plain RMS over the samples; the symmetric model's from the same bins: the within-bin
    # spread is common to both, only the bin means' misfit differs
    r = y - fit.torque(v)
    rmse = float(np.sqrt(np.mean(r * r)))
    b = binned(np.ones_like(v))
    between = float(np.sum(b[2] * (b[1] - fit.torque(b[0])) ** 2) / len(v))
    rmse_sym = float(np.sqrt(max(rmse**2 - between, 0.0) + _symmetric_rmse(*b, vs) ** 2))
    # honesty checks -------------------------------------------------------------------
    checks = [('coulomb_positive', fc_p), ('coulomb_negative', fc_n), ('viscous', fit.viscous)]
    if stribeck_ok:
        checks.append(('static', fs))
    for key, val in checks:
        if val < 0:
            problems.append(f'{key} = {val:.4g} < 0 (friction only dissipates)')
        elif key in ci and ci[key] > abs(val):
            problems.append(f'{key} = {val:.4g} ± {ci[key]:.3g}: interval wider than the value')
    grid = np.geomspace(v_lo, v_hi, 200)
    diss_p = fit.torque(grid) - fit.offset
    diss_n = -(fit.torque(-grid) - fit.offset)
    if np.any(diss_p < 0) or np.any(diss_n < 0):
        problems.append('the fitted friction is negative (not dissipative) over part of '
                        f'{v_lo:.4g}..{v_hi:.4g} rad/s')
    return SampleFit(**{**fit.__dict__, 'rmse': rmse, 'rmse_symmetric': rmse_sym})


def _symmetric_rmse(v, y, w, vs) -> float:
    """Weighted RMS (over bins: ``w`` = counts) of the best symmetric model
    sign(v) (F_c + hump e) + F_v v (no offset, no asymmetry; v_s as fitted, or none)."""
    e = np.zeros_like(v) if vs is None else np.exp(-(v / vs) ** 2)
    sg = np.sign(v)
    X = np.column_stack([sg * (1 - e), sg * e, v]) if vs is not None else np.column_stack(
        [sg, v])
    X = np.ascontiguousarray(X.T)
    Xw = X * w
    sol = np.linalg.lstsq(Xw @ X.T, Xw @ y, rcond=None)[0]
    r = y - sol @ X
    return float(np.sqrt(np.sum(w * r * r) / np.sum(w)))


def binned_means(v: np.ndarray, tau_f: np.ndarray, v_min: float, bins: int = 40
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Mean speed and torque (m,) per (sign, log |v| bin) with at least 5 samples: the
    points the per-sign polynomials are fitted to (and the plots show)."""
    v, y = np.asarray(v, float), np.asarray(tau_f, float)
    ok = np.isfinite(v) & np.isfinite(y) & (np.abs(v) >= v_min)
    v, y = v[ok], y[ok]
    if not len(v):
        return np.zeros(0), np.zeros(0)
    edges = np.geomspace(v_min, np.abs(v).max() * 1.0001, bins + 1)
    k = np.clip(np.searchsorted(edges, np.abs(v), side='right') - 1, 0, bins - 1)
    k = k + bins * (v < 0)
    cnt = np.bincount(k, minlength=2 * bins)
    sv = np.bincount(k, v, minlength=2 * bins)
    sy = np.bincount(k, y, minlength=2 * bins)
    keep = cnt >= 5
    return sv[keep] / cnt[keep], sy[keep] / cnt[keep]
