"""Trajectory-agnostic friction fit on samples (any motion, not only eq. 4.1 sweeps). No rclpy.

Model (irb_description/friction.py: one breakaway level F_s, Coulomb level per sign, offset),
with e = exp(-(v / v_s)^2):

    tau_f(v) = tau_0 + F_v v + (F_c+ (1 - e) + F_s e)      v > 0
    tau_f(v) = tau_0 + F_v v - (F_c- (1 - e) + F_s e)      v < 0

written with F_c = (F_c+ + F_c-)/2, a = (F_c+ - F_c-)/2 and the hump h = F_s - F_c as

    tau_f(v) = tau_0 + sign(v) (F_c + h e) + F_v v + a (1 - e),

which for a fixed v_s is linear in x = (tau_0, F_c, h, F_v, a). The physically valid fit is
one bounded least-squares problem (doc/friction_fit.md):

    min over x, v_s of  sum_i (tau_i - tau_f(v_i))^2
    subject to  F_c >= 0,  h = F_s - F_c >= 0,  F_v >= 0,  v_s in [v_lo, v_hi]

(tau_0 and a free; v_lo..v_hi the 0.5 %..99.5 % quantiles of the speeds used). At a fixed v_s
the bounded linear problem in x is solved exactly (its Gram matrix is at most 5 x 5: every
choice of active bounds, the best feasible one is the optimum of the convex problem); v_s by a
log-spaced scan of the data's speed support and a bounded refinement around the best three
local minima (multi-start). Nothing is fitted freely and then refused for its sign.

Candidates (nested, cheapest first): ``coulomb_viscous`` (F_c, F_v), ``offset`` (+ tau_0, the
same as per-sign levels without Stribeck), ``stribeck`` (+ h, v_s), ``asymmetric_stribeck``
(+ a), and ``polynomials`` (one polynomial of order 5-7 per sign, least squares). The model is
chosen by k-fold held-out RMS over time blocks (every ``folds``-th block of ``block_s`` held
out in turn): the simplest candidate whose held-out squared error exceeds the best one's by
at most 2 standard errors of the paired per-fold differences (or ``select_tol``). Without
polynomials chosen the map is the parametric model alone; with them, the polynomials inside
the valid range and the best parametric candidate outside it.

Weights (``weights='speed_variance'``, default): 1 / the residual variance of each (sign,
log-speed bin) of a first plain fit, clipped to 0.1..10 x the median (noisier speed ranges
count less), times Huber weights (k = 2 robust scales) of that fit's residuals (spikes,
transients hardly count): a weighted bounded least-squares problem. Guard:
if the weighted optimum's plain RMS exceeds the plain bounded optimum's by more than
``plain_guard`` (1 %), the plain one is used (said in ``notes``); ``weights='none'`` fits
plain least squares. Held-out scores are plain RMS either way.

Everything runs on sufficient statistics over fine log-speed bins (count, sum of torque and of
its square per (fold, sign, bin); the model varies by far less than the noise inside a bin of
0.2 % speed), so 1 h of 1 kHz data costs a few passes over the samples.

``v_min``: samples slower than max(v_min_fraction x the top speed (the ``top_quantile`` of
|v|), v_min floor) are not used (sticking, presliding, sign of a noisy zero speed).

Refusal (``SampleFit.problems``, the map entry marked degenerate) only when (1) the bounded
optimum fits clearly worse than the unbounded one of the same model (RMS ratio above
``worse_ratio``: the report states the ratio and what the freedom captured, e.g. a negative
viscous slope: effort that holds more than friction), or (2) no friction is resolved (the
dissipative torque at the top speed is within its own 95 % interval of zero, e.g. every
dissipative parameter on its bound 0). Bounds that are active otherwise are named in
``notes`` with what they mean (e.g. v_s at the top of the data: friction decreasing over the
whole measured range).

Intervals: cluster-robust sandwich A^-1 B A^-1 over time blocks of ``block_s`` for the free
parameters (those not on a bound), Student's t on (blocks - parameters) degrees of freedom.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
from numpy.polynomial import Polynomial
from scipy import stats
from scipy.optimize import minimize_scalar

NAMES = ('offset', 'coulomb_positive', 'coulomb_negative', 'static', 'viscous',
         'stribeck_velocity')
LINEAR = ('offset', 'coulomb', 'hump', 'viscous', 'asymmetry')     # x, at a fixed v_s
LOWER_ZERO = (False, True, True, True, False)                      # F_c, h, F_v >= 0
MODELS = {      # name: (indices into x, with a Stribeck term)
    'coulomb_viscous': ((1, 3), False),
    'offset': ((0, 1, 3), False),
    'stribeck': ((0, 1, 2, 3), True),
    'asymmetric_stribeck': ((0, 1, 2, 3, 4), True),
}
SYMMETRIC = ((1, 2, 3), True)            # sign(v) (F_c + h e) + F_v v: rmse_symmetric
CANDIDATES = tuple(MODELS) + ('polynomials',)


class SampleFitError(ValueError):
    """Not enough usable samples; the message names the joint's speeds and the threshold."""


@dataclass(frozen=True)
class SampleFitConfig:
    """v_min [rad/s]: absolute floor of the slowest sample used; v_min_fraction [-]: the
    slowest sample used is this fraction of the top speed (the ``top_quantile`` of |v|), or
    the floor if higher; min_samples: fewest samples per sign above v_min; speed_bins: fine
    log-speed bins per sign (sufficient statistics); block_s [s]: time blocks of the
    held-out folds and the cluster-robust covariance (fewer than min_blocks blocks: the
    span is cut into min_blocks); folds: k of the k-fold held-out error; select_tol [-]:
    the simplest candidate whose held-out squared error exceeds the best one's by at most 2
    standard errors of the paired fold differences or this fraction is chosen;
    worse_ratio [-]: a bounded optimum whose RMS exceeds the unbounded one's by more is
    refused (degenerate); models: candidates tried (subset of CANDIDATES); poly_orders:
    polynomial orders tried; vs_grid: log-spaced v_s values of the scan; stribeck: False
    leaves out the Stribeck candidates; weights: 'speed_variance' or 'none' (module
    docstring); variance_bins: (sign, log-speed) bins of the variance weights; huber_k [-]:
    Huber threshold in robust scales (1.4826 MAD) of those weights (inf = none); plain_guard
    [-]: largest plain-RMS excess of the weighted optimum over the plain one."""

    v_min: float = 0.0
    v_min_fraction: float = 0.02
    top_quantile: float = 0.999
    min_samples: int = 50
    speed_bins: int = 600
    block_s: float = 1.0
    min_blocks: int = 20
    folds: int = 5
    select_tol: float = 0.001
    worse_ratio: float = 1.10
    models: tuple = CANDIDATES
    poly_orders: tuple = (5, 6, 7)
    vs_grid: int = 24
    stribeck: bool = True
    weights: str = 'speed_variance'
    variance_bins: int = 48
    huber_k: float = 2.0
    plain_guard: float = 0.01


@dataclass(frozen=True)
class SampleFit:
    """Fitted parameters (N m, N m s/rad, rad/s) of the chosen parametric model, 95 %
    half-widths (missing = on a bound or not in the model), RMS over the samples [N m] of
    the chosen model (``rmse``), of the parametric one (``rmse_parametric``), of its unbounded
    counterpart (``rmse_unbounded``) and of the symmetric model without offset; ``model``
    and ``candidates`` ({name: {heldout_rms, rms, parameters}}); samples used, v_min and the
    rule that gave it, valid speed range [rad/s], bounds active, polynomials per sign (only
    when ``model == 'polynomials'``), notes and problems (non-empty = degenerate)."""

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
    model: str = 'asymmetric_stribeck'
    parametric_model: str = 'asymmetric_stribeck'
    candidates: dict = field(default_factory=dict)
    v_min: float = 0.0
    v_min_rule: str = ''
    rmse_parametric: float = float('nan')
    rmse_unbounded: float = float('nan')
    bounds_active: list = field(default_factory=list)
    poly_positive: tuple | None = None
    poly_negative: tuple | None = None
    folds: int = 0

    @property
    def coulomb(self) -> float:
        return 0.5 * (self.coulomb_positive + self.coulomb_negative)

    def torque(self, v) -> np.ndarray:
        """The parametric model's tau_f(v) [N m]."""
        v = np.asarray(v, float)
        e = np.exp(-(v / self.stribeck_velocity) ** 2) if self.stribeck_identified else 0 * v
        pos = self.coulomb_positive * (1 - e) + self.static * e
        neg = self.coulomb_negative * (1 - e) + self.static * e
        return self.offset + self.viscous * v + np.where(v > 0, pos, np.where(v < 0, -neg, 0.0))

    def report(self) -> dict:
        """What the fit did, for the JSON report and the map's ``fit`` entry."""
        return {'model': self.model, 'parametric_model': self.parametric_model,
                'selection': f'{self.folds}-fold held-out RMS over time blocks',
                'candidates': self.candidates, 'v_min': self.v_min,
                'v_min_rule': self.v_min_rule, 'rmse': self.rmse,
                'rmse_parametric': self.rmse_parametric,
                'rmse_unbounded': self.rmse_unbounded,
                'bounded_to_unbounded': (self.rmse_parametric / self.rmse_unbounded
                                         if self.rmse_unbounded > 0 else 1.0),
                'bounds_active': list(self.bounds_active)}


# --- the bounded linear problem at a fixed v_s ------------------------------------------
def _columns(v: np.ndarray, vs: float | None, cols) -> np.ndarray:
    """(k, N) regressors of x[cols] at speeds v; vs None = no Stribeck term (e = 0)."""
    s = np.sign(v)
    e = np.zeros_like(v) if vs is None else np.exp(-np.square(v / vs))
    make = {0: lambda: np.ones_like(v), 1: lambda: s, 2: lambda: s * e, 3: lambda: v,
            4: lambda: 1.0 - e}
    return np.stack([make[c]() for c in cols])


def bounded_lsq(A: np.ndarray, b: np.ndarray, yy: float, lower_zero) -> tuple[np.ndarray,
                                                                                 float]:
    """min_x yy - 2 b'x + x'A x subject to x[i] >= 0 where ``lower_zero[i]``: the exact
    optimum (convex: for every set of active bounds the stationary point with those
    variables at 0 is computed, in one batched solve; the best feasible one is the optimum).
    A (k, k) positive semi-definite. Returns x (k,) and the cost (>= 0)."""
    k = len(b)
    d = np.sqrt(np.maximum(np.diag(A), 1e-300))
    As, bs = A / np.outer(d, d), b / d
    lz = np.asarray(lower_zero, bool)
    try:                              # the unbounded optimum, if feasible, is the answer
        x = np.linalg.solve(As, bs)
        if not lz.any() or x[lz].min() >= 0.0:
            return x / d, max(float(yy - bs @ x), 0.0)
    except np.linalg.LinAlgError:
        pass
    fixed = _subsets(tuple(bool(z) for z in lz))          # (S, k), fewest fixed first
    free = ~fixed
    M = np.where(free[:, :, None] & free[:, None, :], As, 0.0)
    M[:, np.arange(k), np.arange(k)] += fixed              # fixed variables: x_i = 0
    rhs = np.where(free, bs, 0.0)
    try:
        X = np.linalg.solve(M, rhs[:, :, None])[:, :, 0]
    except np.linalg.LinAlgError:
        X = np.stack([np.linalg.lstsq(m, r, rcond=1e-12)[0] for m, r in zip(M, rhs)])
    feasible = np.all((X >= -1e-12) | ~lz, axis=1)
    X = np.where(lz, np.maximum(X, 0.0), X)
    cost = yy - 2 * X @ bs + np.einsum('si,ij,sj->s', X, As, X)
    cost[~feasible] = np.inf
    i = int(np.argmin(cost))
    if not np.isfinite(cost[i]):
        return np.zeros(k), float(yy)
    return X[i] / d, max(float(cost[i]), 0.0)


_SUBSETS = {}


def _subsets(lower_zero: tuple) -> list:
    """Every set of bounds that may be active (bool masks of the fixed variables), fewest
    first."""
    if lower_zero not in _SUBSETS:
        bounded = [i for i, z in enumerate(lower_zero) if z]
        out = []
        for r in range(len(bounded) + 1):
            for fixed in combinations(bounded, r):
                m = np.zeros(len(lower_zero), bool)
                m[list(fixed)] = True
                out.append(m)
        _SUBSETS[lower_zero] = np.array(out)
    return _SUBSETS[lower_zero]


@dataclass
class _Stats:
    """Per-bin sufficient statistics: mean speed vbar (m,), counts n (m,), torque sums
    sy (m,), total of squared torques yy."""

    vbar: np.ndarray
    n: np.ndarray
    sy: np.ndarray
    yy: float

    def model_cost(self, m: np.ndarray) -> float:
        """Sum of squared residuals of a model with values m (m,) at the bins."""
        return float(self.yy - 2 * m @ self.sy + (self.n * m) @ m)


def _fit_linear(st: _Stats, cols, vs, bounded=True):
    X = _columns(st.vbar, vs, cols)
    A = (X * st.n) @ X.T
    b = X @ st.sy
    lz = [LOWER_ZERO[c] and bounded for c in cols]
    xs, cost = bounded_lsq(A, b, st.yy, lz)
    x = np.zeros(5)
    x[list(cols)] = xs
    return x, cost


def _fit_model(st: _Stats, cols, stribeck: bool, v_lo: float, v_hi: float, grid_n: int,
               bounded=True):
    """(x (5,), v_s or None, cost): the best fit of the model over v_s in [v_lo, v_hi]."""
    if not stribeck:
        x, cost = _fit_linear(st, cols, None, bounded)
        return x, None, cost
    grid = np.geomspace(v_lo, v_hi, grid_n)
    costs = np.array([_fit_linear(st, cols, g, bounded)[1] for g in grid])
    n = len(grid)
    minima = [i for i in range(n) if costs[i] <= costs[max(i - 1, 0)]
              and costs[i] <= costs[min(i + 1, n - 1)]]
    best_vs, best_cost = float(grid[int(np.argmin(costs))]), float(np.min(costs))
    for i in sorted(minima, key=lambda i: costs[i])[:2]:         # multi-start
        lo, hi = np.log(grid[max(i - 1, 0)]), np.log(grid[min(i + 1, n - 1)])
        if hi <= lo:
            continue
        res = minimize_scalar(lambda a: _fit_linear(st, cols, float(np.exp(a)), bounded)[1],
                              bounds=(lo, hi), method='bounded', options={'xatol': 1e-4})
        if res.fun < best_cost:
            best_vs, best_cost = float(np.exp(res.x)), float(res.fun)
    x, cost = _fit_linear(st, cols, best_vs, bounded)
    return x, best_vs, cost


def _model_values(v, x, vs):
    """tau_f at speeds v of the linear parameters x (5,) and v_s (None: no Stribeck)."""
    out = np.sign(v) * x[1] + v * x[3] + (x[0] + x[4])
    if vs is not None and (x[2] != 0 or x[4] != 0):
        e = np.exp(-np.square(v / vs))
        out += e * (np.sign(v) * x[2] - x[4])
    return out


def _fit_poly(st: _Stats, order: int):
    """Per-sign least-squares polynomials (numpy Polynomial, domain-scaled) or None."""
    out = []
    for sel in (st.vbar > 0, st.vbar < 0):
        keep = sel & (st.n > 0)
        if np.count_nonzero(keep) < order + 2:
            return None
        ybar = st.sy[keep] / st.n[keep]
        out.append(Polynomial.fit(st.vbar[keep], ybar, order, w=np.sqrt(st.n[keep])))
    return out


def _poly_values(v, polys):
    return np.where(v > 0, polys[0](v), polys[1](v))


def resolve_v_min(v: np.ndarray, config: SampleFitConfig) -> tuple[float, str]:
    """The slowest speed used [rad/s] for speeds v (finite) and the rule that gave it."""
    speed = np.abs(np.asarray(v, float))
    speed = speed[np.isfinite(speed)]
    top = float(np.quantile(speed, config.top_quantile)) if len(speed) else 0.0
    rel = config.v_min_fraction * top
    pct = f'{100 * config.top_quantile:g}'
    if config.v_min > rel:
        return float(config.v_min), (f'the floor v_min = {config.v_min:g} rad/s (above '
                                     f'{config.v_min_fraction:g} x the top speed {top:.4g} '
                                     f'rad/s, the {pct} % quantile of |v|)')
    return rel, (f'{config.v_min_fraction:g} x the top speed {top:.4g} rad/s (the {pct} % '
                 f'quantile of |v|; floor v_min = {config.v_min:g} rad/s)')


def _support(counts, nb, N, lo_edge, top_edge) -> tuple[float, float]:
    """The 0.5 % and 99.5 % quantiles of the speeds used [rad/s] from the counts (2 nb,)
    of the fine bins (both signs)."""
    c_speed = np.cumsum(counts[:nb] + counts[nb:])
    edges = lo_edge * np.exp(np.arange(nb + 1) * np.log(top_edge / lo_edge) / nb)
    v_lo = float(edges[np.searchsorted(c_speed, 0.005 * N)])
    v_hi = float(edges[min(np.searchsorted(c_speed, 0.995 * N) + 1, nb)])
    return v_lo, max(v_hi, v_lo * 1.001)


def _blocks(t: np.ndarray, block_s: float, min_blocks: int) -> np.ndarray:
    span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    size = block_s if span / block_s >= min_blocks else max(span / min_blocks, 1e-9)
    b = np.floor((t - t[0]) / size).astype(np.int64)      # t sorted: b non-decreasing
    return np.concatenate([[0], np.cumsum(np.diff(b) > 0)]).astype(np.int64)


def fit_samples(t: np.ndarray, v: np.ndarray, tau_f: np.ndarray, name: str = 'joint',
                config: SampleFitConfig = SampleFitConfig(), progress=None) -> SampleFit:
    """Fit the friction model to samples at times t (N,) [s], speeds v (N,) [rad/s] and
    friction torques tau_f (N,) [N m]. Raises SampleFitError when too few samples move."""
    t, v, y = (np.asarray(a, float) for a in (t, v, tau_f))
    ok = np.isfinite(t) & np.isfinite(v) & np.isfinite(y)
    v_min, rule = resolve_v_min(v[ok], config)
    use = ok & (np.abs(v) >= v_min) & (v != 0)
    n_pos = int(np.count_nonzero(use & (v > 0)))
    n_neg = int(np.count_nonzero(use)) - n_pos
    if min(n_pos, n_neg) < config.min_samples:
        speed_all = np.abs(v[ok])
        seen = (f'{speed_all.min():.4g}..{speed_all.max():.4g} rad/s' if len(speed_all)
                else 'no finite samples')
        raise SampleFitError(
            f'{name}: {n_pos} samples above v_min = {v_min:g} rad/s with v > 0 and '
            f'{n_neg} with v < 0, need {config.min_samples} of each (|v| seen: {seen}; '
            f'v_min: {rule})')
    if not use.all():
        t, v, y = t[use], v[use], y[use]
    if np.any(np.diff(t) < 0):
        order = np.argsort(t, kind='stable')
        t, v, y = t[order], v[order], y[order]
    N = len(v)
    speed = np.abs(v)
    notes, problems = [f'v_min {v_min:.4g} rad/s: {rule}; {N} samples used'], []
    # sufficient statistics per (fold, sign, fine log-speed bin) -------------------------
    nb = config.speed_bins
    lo_edge = max(v_min, float(speed.min()))
    top_edge = float(speed.max()) * 1.0001
    kbin = np.log(np.maximum(speed, lo_edge) / lo_edge)
    kbin *= nb / max(np.log(top_edge / lo_edge), 1e-12)
    kbin = np.clip(kbin.astype(np.int64), 0, nb - 1)
    kbin += nb * (v < 0)
    blocks = _blocks(t, config.block_s, config.min_blocks)
    n_blocks = int(blocks.max()) + 1
    k = max(2, min(config.folds, n_blocks))
    fold = blocks % k
    key = fold * (2 * nb) + kbin
    cnt = np.bincount(key, minlength=k * 2 * nb).reshape(k, 2 * nb).astype(float)
    sv = np.bincount(key, v, minlength=k * 2 * nb).reshape(k, 2 * nb)
    sy = np.bincount(key, y, minlength=k * 2 * nb).reshape(k, 2 * nb)
    syy = np.bincount(key, y * y, minlength=k * 2 * nb).reshape(k, 2 * nb)
    v_lo, v_hi = _support(cnt.sum(axis=0), nb, N, lo_edge, top_edge)
    occ = cnt.sum(axis=0) > 0
    cnt, sv, sy, syy = cnt[:, occ], sv[:, occ], sy[:, occ], syy[:, occ]
    vbar = sv.sum(axis=0) / cnt.sum(axis=0)
    plain = _Stats(vbar, cnt.sum(axis=0), sy.sum(axis=0), float(syy.sum()))
    w_bin = np.ones(len(vbar))
    h = None                                       # Huber weights per sample
    ac, ay, ayy = cnt, sy, syy                     # (weighted) statistics per (fold, bin)
    if config.weights == 'speed_variance':
        # 1 / residual variance of the (sign, coarse log-speed bin) of a first plain fit,
        # times Huber weights of its residuals (spikes, transients hardly count)
        x0, vs0, _ = _fit_model(plain, *MODELS['asymmetric_stribeck'], v_lo, v_hi,
                                config.vs_grid)
        m0 = _model_values(vbar, x0, vs0)
        if np.isfinite(config.huber_k):
            r0 = y - _model_values(v, x0, vs0)
            rs = r0[::max(1, N // 200_000)]
            scale = 1.4826 * float(np.median(np.abs(rs - np.median(rs)))) + 1e-12
            h = np.minimum(1.0, config.huber_k * scale / np.maximum(np.abs(r0), 1e-300))
            del r0
            size = k * 2 * nb
            ac = np.bincount(key, h, minlength=size).reshape(k, 2 * nb)[:, occ]
            hy = h * y
            ay = np.bincount(key, hy, minlength=size).reshape(k, 2 * nb)[:, occ]
            ayy = np.bincount(key, hy * y, minlength=size).reshape(k, 2 * nb)[:, occ]
            del hy
            down = int(np.count_nonzero(h < 0.5))
            if down:
                notes.append(f'{down} of {N} samples weighted below 1/2 as outliers (Huber, '
                             f'k = {config.huber_k:g} robust scales of {scale:.3g} N m)')
        n_b = ac.sum(axis=0)
        sse_b = ayy.sum(axis=0) - 2 * m0 * ay.sum(axis=0) + n_b * m0 * m0
        coarse = (np.flatnonzero(occ) * config.variance_bins) // nb
        n_c = np.bincount(coarse, n_b)
        var_c = np.bincount(coarse, sse_b) / np.maximum(n_c, 1e-12)
        var_c = np.clip(var_c, *(np.median(var_c[n_c > 0]) * np.array([0.1, 10.0]))
                        + 1e-300)
        w_bin = 1.0 / var_c[coarse]
        w_bin /= (w_bin @ n_b) / N
        notes.append('weights: 1 / the residual variance of each (sign, log-speed bin) '
                     f'({config.variance_bins // 2} bins per sign) of a first plain fit'
                     + (', times Huber weights' if h is not None else ''))
    A_n, A_y, A_yy = ac.sum(axis=0), ay.sum(axis=0), ayy.sum(axis=0)
    total = _Stats(vbar, w_bin * A_n, w_bin * A_y, float(w_bin @ A_yy))
    train = [_Stats(vbar, w_bin * (A_n - ac[f]), w_bin * (A_y - ay[f]),
                    float(w_bin @ (A_yy - ayy[f]))) for f in range(k)]
    held = [_Stats(vbar, cnt[f], sy[f], float(syy[f].sum())) for f in range(k)]   # plain
    # candidates: held-out RMS over the folds, then the fit on everything -----------------
    models = [m for m in config.models if m in CANDIDATES
              and (config.stribeck or m not in ('stribeck', 'asymmetric_stribeck'))]
    if not models:
        models = ['offset']
    cand, fits, polys, fold_sse = {}, {}, {}, {}
    for m in models:
        if m == 'polynomials':
            best = None
            for order in config.poly_orders:
                sse = np.zeros(k)
                for f in range(k):
                    p = _fit_poly(train[f], order)
                    if p is None:
                        sse[:] = np.inf
                        break
                    sse[f] = held[f].model_cost(_poly_values(vbar, p))
                if best is None or sse.sum() < best[0].sum():
                    best = (sse, order)
            if best is None or not np.all(np.isfinite(best[0])):
                continue
            p = _fit_poly(total, best[1])
            grid = np.geomspace(v_lo, v_hi, 200)
            if np.any(p[0](grid) < p[1](-grid)):
                notes.append(f'polynomials (order {best[1]}) left out: torque at +v below the '
                             'torque at -v somewhere in the valid range (not dissipative)')
                continue
            polys = {'order': best[1], 'p': p}
            fold_sse[m] = best[0]
            cand[m] = {'heldout_rms': float(np.sqrt(best[0].sum() / N)),
                       'rms': float(np.sqrt(plain.model_cost(_poly_values(vbar, p)) / N)),
                       'parameters': 2 * (best[1] + 1), 'order': best[1]}
            continue
        cols, strib = MODELS[m]
        sse = np.zeros(k)
        for f in range(k):
            x, vs, _ = _fit_model(train[f], cols, strib, v_lo, v_hi, config.vs_grid)
            sse[f] = held[f].model_cost(_model_values(vbar, x, vs))
        x, vs, cost = _fit_model(total, cols, strib, v_lo, v_hi, config.vs_grid)
        fits[m] = (x, vs, cost)
        fold_sse[m] = sse
        cand[m] = {'heldout_rms': float(np.sqrt(max(sse.sum(), 0.0) / N)),
                   'rms': float(np.sqrt(plain.model_cost(_model_values(vbar, x, vs)) / N)),
                   'parameters': len(cols) + strib}
        if progress:
            progress(f'{name}: candidate {m}: held-out RMS {cand[m]["heldout_rms"]:.4g} N m')
    chosen = _select([m for m in CANDIDATES if m in cand], fold_sse, config.select_tol)
    pmodel = _select([m for m in CANDIDATES if m in fits], fold_sse, config.select_tol)
    for m in cand:
        d = fold_sse[m] - fold_sse[chosen]
        cand[m]['heldout_excess_over_chosen'] = float(d.sum() / max(fold_sse[chosen].sum(),
                                                                     1e-300))
    notes.append(f'model {chosen} by {k}-fold held-out RMS over time blocks (the simplest '
                 'not worse than the best by 2 standard errors of the paired fold '
                 f'differences or {100 * config.select_tol:g} %): ' + ', '.join(
                     f'{m} {cand[m]["heldout_rms"]:.4g}' for m in CANDIDATES if m in cand)
                 + ' N m' + ('' if chosen == pmodel else
                             f'; outside the valid range the parametric {pmodel}'))
    cols, strib = MODELS[pmodel]
    x, vs, cost = fits[pmodel]
    w_sample = None
    if config.weights != 'none':
        # guard: the weighted optimum must fit (plain RMS) as well as the plain one
        xp, vsp, cost_p = _fit_model(plain, cols, strib, v_lo, v_hi, config.vs_grid)
        excess = np.sqrt(plain.model_cost(_model_values(vbar, x, vs)) / max(cost_p, 1e-300))
        if excess > 1 + config.plain_guard:
            notes.append(f'the weighted fit is {100 * (excess - 1):.2g} % above the plain '
                         'least-squares RMS: the plain fit is used')
            x, vs, cost, total = xp, vsp, cost_p, plain
        else:
            pos = np.cumsum(occ) - 1
            w_sample = w_bin[pos[kbin]] if h is None else w_bin[pos[kbin]] * h
    if not strib:
        notes.append('without a Stribeck term the offset and the Coulomb asymmetry cannot '
                     'be told apart: offset set to 0, the levels per sign carry both')
    # the same model without bounds: how much do the bounds cost? -----------------------
    xu, vsu, cost_u = _fit_model(total, cols, strib, v_lo, v_hi, config.vs_grid,
                                 bounded=False)
    ratio = float(np.sqrt(cost / cost_u)) if cost_u > 0 else 1.0     # in the objective
    rms_c = np.sqrt(plain.model_cost(_model_values(vbar, x, vs)) / N)
    rms_u = np.sqrt(plain.model_cost(_model_values(vbar, xu, vsu)) / N)
    active = []
    meaning = {1: ('F_c = 0 on its bound (no level left at the top speeds: the Stribeck hump '
                   'carries the friction at low speed)' if strib else
                   'F_c = 0 on its bound (no Coulomb level: the torque goes to 0 with the '
                   'speed)'),
               2: 'F_s = F_c on its bound (no Stribeck hump)',
               3: 'F_v = 0 on its bound (no torque growth with speed over the measured '
                  'speeds: friction flat or decreasing)'}
    for c in cols:
        if LOWER_ZERO[c] and x[c] == 0.0:
            active.append(LINEAR[c])
            notes.append(meaning[c])
    if strib and vs >= v_hi * (1 - 1e-6):
        active.append('stribeck_velocity_max')
        notes.append(f'v_s = {vs:.4g} rad/s on the top of the data\'s speeds: the friction '
                     'decreases over the whole measured range (a Stribeck region wider than '
                     'the data); outside the valid range the map is an extrapolation')
    elif strib and vs <= v_lo * (1 + 1e-6):
        active.append('stribeck_velocity_min')
        notes.append(f'v_s = {vs:.4g} rad/s on the slowest speed used: the hump is narrower '
                     'than the data resolve')
    if ratio > config.worse_ratio:
        why = []
        if xu[3] < 0:
            why.append(f'F_v = {xu[3]:.4g} N m s/rad (torque falling with speed faster than '
                       'a Stribeck term inside the data\'s speeds allows)')
        if xu[1] < 0:
            why.append(f'F_c = {xu[1]:.4g} N m (a level that pushes along the motion)')
        if 2 in cols and xu[2] < 0:
            why.append(f'F_s - F_c = {xu[2]:.4g} N m (friction rising out of standstill)')
        problems.append(
            f'the bounded optimum fits {ratio:.2f} x worse than the unbounded one '
            f'({rms_c:.4g} against {rms_u:.4g} N m RMS), which has ' + '; '.join(why)
            + ': the extra freedom captures torque that is not friction (effort that holds '
            'more than friction: gravity, inertia or a drive torque not subtracted?)')
    elif ratio > 1.0 + 1e-9:
        notes.append(f'the bounds cost {100 * (ratio - 1):.2g} % RMS against the unbounded '
                     f'fit ({rms_c:.4g} against {rms_u:.4g} N m)')
    # residuals on every sample, cluster-robust intervals of the free parameters ----------
    r = y - _model_values(v, x, vs)
    rmse = float(np.sqrt(np.mean(r * r)))
    free = [c for c in cols if not (LOWER_ZERO[c] and x[c] == 0.0)]
    with_vs = strib and not active_vs(active)
    J_bins = _columns(vbar, vs, free) if free else np.zeros((0, len(vbar)))
    if with_vs:          # d tau_f / d v_s = (h sign(v) - a) e 2 v^2 / v_s^3
        eb = np.exp(-np.square(vbar / vs))
        J_bins = np.vstack([J_bins, (x[2] * np.sign(vbar) - x[4]) * eb * 2 * vbar**2
                            / vs**3])
    q = J_bins.shape[0]
    A = (J_bins * total.n) @ J_bins.T
    G = np.empty((n_blocks, q))
    wr = r if w_sample is None else w_sample * r
    sg = np.sign(v)
    e = np.exp(-np.square(v / vs)) if strib else None
    for i, c in enumerate(free):         # score columns, as in _columns
        col = {0: lambda: None, 1: lambda: sg, 2: lambda: sg * e, 3: lambda: v,
               4: lambda: 1.0 - e}[c]()
        G[:, i] = np.bincount(blocks, wr if col is None else col * wr, minlength=n_blocks)
    if with_vs:
        G[:, -1] = np.bincount(blocks, (x[2] * sg - x[4]) * e * 2 * v * v / vs**3 * wr,
                               minlength=n_blocks)
    B = G.T @ G * n_blocks / max(n_blocks - 1, 1)
    cov6 = np.zeros((6, 6))
    try:
        Ai = np.linalg.inv(A)
        idx = list(free) + ([5] if with_vs else [])
        cov6[np.ix_(idx, idx)] = Ai @ B @ Ai
        inv_ok = True
    except np.linalg.LinAlgError:
        inv_ok = False
    tq = stats.t.ppf(0.975, max(n_blocks - q, 1))
    e_top = np.exp(-(v_hi / vs) ** 2) if strib else 0.0
    if strib:   # tau_0, F_c, h, F_v, a, v_s -> report keys
        lin = {'offset': [1, 0, 0, 0, 0, 0], 'coulomb_positive': [0, 1, 0, 0, 1, 0],
               'coulomb_negative': [0, 1, 0, 0, -1, 0], 'coulomb': [0, 1, 0, 0, 0, 0],
               'static': [0, 1, 1, 0, 0, 0], 'viscous': [0, 0, 0, 1, 0, 0],
               'stribeck_velocity': [0, 0, 0, 0, 0, 1]}
        values = dict(offset=x[0], coulomb_positive=x[1] + x[4], coulomb_negative=x[1] - x[4],
                      static=x[1] + x[2], viscous=x[3], stribeck_velocity=vs, coulomb=x[1])
    else:       # no Stribeck term: the offset goes into the per-sign levels
        lin = {'coulomb_positive': [1, 1, 0, 0, 0, 0], 'coulomb_negative': [-1, 1, 0, 0, 0, 0],
               'coulomb': [0, 1, 0, 0, 0, 0], 'static': [0, 1, 0, 0, 0, 0],
               'viscous': [0, 0, 0, 1, 0, 0]}
        values = dict(offset=0.0, coulomb_positive=x[1] + x[0], coulomb_negative=x[1] - x[0],
                      static=x[1], viscous=x[3], stribeck_velocity=0.05, coulomb=x[1])
    lin['dissipative_top'] = [0, 1, e_top, v_hi, 0, 0]
    ci = {}
    if inv_ok:
        for key, L in lin.items():
            L = np.asarray(L, float)
            var = float(L @ cov6 @ L)
            if var > 0:
                ci[key] = float(tq * np.sqrt(var))
    d_top = x[1] + x[2] * e_top + x[3] * v_hi
    hw_top = ci.pop('dissipative_top', 0.0)
    if not d_top > hw_top:
        problems.append(f'no friction resolved: the dissipative torque at the top speed '
                        f'{v_hi:.4g} rad/s is {d_top:.4g} ± {hw_top:.2g} N m: interval wider '
                        'than the value (the torque does not oppose the motion)')
    for key in ('coulomb_positive', 'coulomb_negative'):
        if values[key] < 0:
            notes.append(f'{key} = {values[key]:.4g} N m < 0: with the offset '
                         f'{values["offset"]:.4g} N m this sign\'s level pushes along the '
                         'motion (the per-sign levels are free; check the offset)')
    for key in ('coulomb', 'static', 'viscous', 'stribeck_velocity'):
        if key in ci and values[key] != 0 and ci[key] > abs(values[key]):
            notes.append(f'{key} = {values[key]:.4g} ± {ci[key]:.3g}: interval wider than '
                         'the value (weakly identified)')
    # symmetric model without offset (what the thesis's odd model gives), from the bins
    xs, vss, _ = _fit_model(total, *SYMMETRIC, v_lo, v_hi, config.vs_grid)
    rmse_sym = float(np.sqrt(plain.model_cost(_model_values(vbar, xs, vss)) / N))
    poly_p = poly_n = None
    rmse_chosen = rmse
    if chosen == 'polynomials':
        poly_p = tuple(float(c) for c in polys['p'][0].convert().coef)
        poly_n = tuple(float(c) for c in polys['p'][1].convert().coef)
        rmse_chosen = cand['polynomials']['rms']
    return SampleFit(
        offset=float(values['offset']), coulomb_positive=float(values['coulomb_positive']),
        coulomb_negative=float(values['coulomb_negative']), static=float(values['static']),
        viscous=float(values['viscous']),
        stribeck_velocity=float(values['stribeck_velocity']), ci95=ci, rmse=float(rmse_chosen),
        rmse_symmetric=rmse_sym, samples=N, blocks=n_blocks, valid_range=(v_lo, v_hi),
        stribeck_identified=bool(strib), offset_identified=bool(strib and 0 in cols),
        notes=notes, problems=problems, model=chosen, parametric_model=pmodel,
        candidates=cand, v_min=float(v_min), v_min_rule=rule, rmse_parametric=rmse,
        rmse_unbounded=float(rms_u), bounds_active=active, poly_positive=poly_p,
        poly_negative=poly_n, folds=k)


def _select(names: list, fold_sse: dict, tol: float) -> str:
    """The simplest of ``names`` (in order) whose held-out squared error is not larger than
    the best one's by more than 2 standard errors of the paired per-fold differences, or by
    more than ``tol`` (relative)."""
    best = min(names, key=lambda m: fold_sse[m].sum())
    ref = fold_sse[best]
    for m in names:
        d = fold_sse[m] - ref
        se = np.sqrt(len(d)) * float(np.std(d, ddof=1)) if len(d) > 1 else 0.0
        if d.sum() <= max(2 * se, tol * ref.sum()):
            return m
    return best


def active_vs(active: list) -> bool:
    return any(a.startswith('stribeck_velocity') for a in active)


def binned_means(v: np.ndarray, tau_f: np.ndarray, v_min: float, bins: int = 40
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Mean speed and torque (m,) per (sign, log |v| bin) with at least 5 samples: the
    points the plots show."""
    v, y = np.asarray(v, float), np.asarray(tau_f, float)
    ok = np.isfinite(v) & np.isfinite(y) & (np.abs(v) >= v_min) & (v != 0)
    v, y = v[ok], y[ok]
    if not len(v):
        return np.zeros(0), np.zeros(0)
    lo = max(v_min, float(np.abs(v).min()))
    edges = np.geomspace(lo, np.abs(v).max() * 1.0001, bins + 1)
    k = np.clip(np.searchsorted(edges, np.abs(v), side='right') - 1, 0, bins - 1)
    k = k + bins * (v < 0)
    cnt = np.bincount(k, minlength=2 * bins)
    sv = np.bincount(k, v, minlength=2 * bins)
    sy = np.bincount(k, y, minlength=2 * bins)
    keep = cnt >= 5
    return sv[keep] / cnt[keep], sy[keep] / cnt[keep]
