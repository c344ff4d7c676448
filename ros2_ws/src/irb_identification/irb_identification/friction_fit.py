"""Friction maps from constant-speed experiments (thesis §4.2, eq. 4.8). No rclpy.

Per joint: eq. 4.8 points (segments.py) -> a parametric Coulomb + viscous + Stribeck fit
tau_f(v) = sign(v) (F_c + (F_s - F_c) exp(-(v/v_s)^2)) + F_v v (scipy least_squares, 95 %
confidence half-widths from the Jacobian and the t distribution) and polynomials of order 5-7
in v for each sign (weighted by 1/|tau_f|, i.e. relative error), valid over the sampled speed
range. The result is an irb_description ``JointFriction``/``FrictionMap`` (schema in
irb_description/friction.py).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from irb_description.friction import FrictionMap, JointFriction, load_friction_map
from numpy.polynomial import Polynomial
from scipy import stats
from scipy.optimize import least_squares, lsq_linear

from .segments import (Rejection, SegmentConfig, SpeedPoint, find_segments, rolling_mean_std,
                       speed_points)
from .series import JointSeries

PARAMS = ('coulomb', 'static', 'stribeck_velocity', 'viscous')


class IdentificationError(ValueError):
    """A joint cannot be identified; the message names the reason."""


@dataclass(frozen=True)
class FitConfig:
    """poly_order: 5-7, or 0 to pick the order in 5-7 with the smallest leave-one-out
    relative error; min_speeds: fewest distinct speeds to identify a joint (parametric
    fit has 4 parameters); pair_rel_tol: |speed| agreement for pairing +c/-c segments."""

    poly_order: int = 7
    min_speeds: int = 4
    pair_rel_tol: float = 0.1
    segments: SegmentConfig = field(default_factory=SegmentConfig)


@dataclass(frozen=True)
class ParametricFit:
    """Fitted parameters (F_c, F_s [N m], v_s [rad/s], F_v [N m s/rad]), their 95 %
    half-widths (nan where not identifiable), RMS residual [N m], degrees of freedom."""

    coulomb: float
    static: float
    stribeck_velocity: float
    viscous: float
    ci95: dict
    rmse: float
    dof: int
    cov: np.ndarray | None = None     # (4, 4) of (F_c, F_s - F_c, v_s, F_v), nan if fixed

    def band95(self, v: np.ndarray) -> np.ndarray:
        """95 % half-width [N m] of the fitted curve at speeds v (delta method)."""
        v = np.asarray(v, float)
        if self.cov is None or self.dof <= 0:
            return np.full(v.shape, np.nan)
        x = np.array([self.coulomb, self.static - self.coulomb, self.stribeck_velocity,
                      self.viscous])
        J = np.empty(v.shape + (4,))
        for k in range(4):
            dx = np.zeros(4)
            dx[k] = 1e-6 * max(abs(x[k]), 1e-3)
            J[..., k] = (_parametric(v, *(x + dx)) - _parametric(v, *(x - dx))) / (2 * dx[k])
        cov = np.nan_to_num(self.cov)
        var = np.einsum('...i,ij,...j->...', J, cov, J)
        return stats.t.ppf(0.975, self.dof) * np.sqrt(np.abs(var))

    def torque(self, v: np.ndarray) -> np.ndarray:
        return _parametric(np.asarray(v, float), self.coulomb, self.static - self.coulomb,
                           self.stribeck_velocity, self.viscous)


@dataclass(frozen=True)
class JointResult:
    """Identification of one joint: points, fits, the map entry, warnings; or ``error``.
    ``rejected``: (label of the series, Rejection) of every hold dropped for stick-slip."""

    name: str
    points: list[SpeedPoint]
    parametric: ParametricFit | None = None
    poly_pos: np.ndarray | None = None       # increasing powers of v
    poly_neg: np.ndarray | None = None
    friction: JointFriction | None = None
    warnings: list[str] = field(default_factory=list)
    error: str | None = None
    rejected: list[tuple[str, Rejection]] = field(default_factory=list)
    method: str = 'sweep'                    # 'sweep' (eq. 4.8) or 'samples' (sample_fit)
    sample: object = None                    # sample_fit.SampleFit of the samples method
    hold_time_s: float = 0.0                 # time in accepted constant-speed holds [s]
    degenerate: list[str] = field(default_factory=list)   # honesty-check failures
    binned: tuple = ()                       # samples method: (speeds, mean torques) per bin


def _parametric(v, fc, ds, vs, fv):
    return np.sign(v) * (fc + ds * np.exp(-(v / vs) ** 2)) + fv * v


def independent_points(v: np.ndarray, tau: np.ndarray) -> int:
    """How many of the points (v, tau) carry information of their own for the odd model
    tau(v) = -tau(-v): a point whose mirror (-v, -tau) is also there is the same measurement
    twice (eq. 4.8 gives f_neg = -f_pos when it averages the two directions), so the pair
    counts once. The degrees of freedom and the covariance use this count: with 8 points of
    4 mirrored speeds a 4-parameter fit has no residual left, and its interval is unknown,
    not zero."""
    key = np.round(np.column_stack([np.abs(v), np.sign(v) * tau]), 12)
    return int(len(np.unique(key, axis=0)))


def fit_parametric(v: np.ndarray, tau: np.ndarray, stribeck: bool = True) -> ParametricFit:
    """Coulomb + viscous + Stribeck fit to signed speeds v (m,) [rad/s], tau_f (m,) [N m].

    Least squares in x = (F_c, F_s - F_c, v_s, F_v) with F_c, F_s - F_c, F_v >= 0 and
    v_s in [1e-3, 10] rad/s (the physically valid optimum, never a negative coefficient);
    multi-start over v_s. Covariance s^2 (J^T J)^-1 of the parameters off their bounds.
    ``stribeck`` False: Coulomb + viscous only (bounded linear least squares, F_s = F_c).
    """
    v, tau = np.asarray(v, float), np.asarray(tau, float)
    if not stribeck:
        if len(v) < 3:
            raise IdentificationError(f'{len(v)} points are too few for a 2-parameter fit')
        X = np.column_stack([np.sign(v), v])
        sol = lsq_linear(X, tau, bounds=(0.0, np.inf)).x          # F_c, F_v >= 0
        n_ind = independent_points(v, tau)
        rep = len(v) / n_ind                # each independent point counted rep times
        dof = n_ind - 2
        rmse = float(np.sqrt(np.sum((tau - X @ sol) ** 2) / rep / max(dof, 1)))
        cov = np.full((4, 4), np.nan)
        ci = {}
        free = sol > 0                     # a coefficient on its bound has no interval
        if dof > 0 and free.any():
            Xf = X[:, free]
            c2 = np.linalg.inv(Xf.T @ Xf) * rmse**2 * rep
            idx = np.array([0, 3])[free]
            cov[np.ix_(idx, idx)] = c2
            q = stats.t.ppf(0.975, dof)
            keys = [k for k, f in zip(('coulomb', 'viscous'), free) if f]
            ci = {k: float(q * np.sqrt(c2[i, i])) for i, k in enumerate(keys)}
        return ParametricFit(float(sol[0]), float(sol[0]), 0.05, float(sol[1]), ci, rmse, dof,
                             None)
    if len(v) < 5:
        raise IdentificationError(f'{len(v)} points are too few for a 4-parameter fit')
    speed, mag = np.abs(v), np.abs(tau)
    upper = speed >= np.median(speed)
    fv0, fc0 = np.polyfit(speed[upper], mag[upper], 1) if upper.sum() >= 2 else (0.0, mag.mean())
    fc0, fv0 = max(fc0, 0.0), max(fv0, 0.0)
    ds0 = max(0.0, float(np.max(mag[speed <= np.min(speed) * 1.01] - fc0)))

    def resid(x):
        return _parametric(v, *x) - tau

    best = None
    for vs0 in (0.01, 0.05, 0.2, 0.5):
        x0 = [fc0, ds0, vs0, fv0]
        r = least_squares(resid, x0, bounds=([0, 0, 1e-3, 0], [np.inf, np.inf, 10, np.inf]),
                          x_scale=[max(fc0, 1.0), max(ds0, 1.0), vs0, max(fv0, 1.0)])
        if best is None or r.cost < best.cost:
            best = r
    x, J = best.x, best.jac
    n_ind = independent_points(v, tau)
    rep = len(v) / n_ind                    # each independent point counted rep times
    dof = n_ind - 4
    rmse = float(np.sqrt(2 * best.cost / rep / max(dof, 1)))
    ci = {}
    cov = None
    # parameters at a bound (e.g. no Stribeck dip) are not identifiable: no half-width
    active = best.active_mask != 0
    if dof > 0:
        free = ~active
        cov = np.full((4, 4), np.nan)
        Jf = J[:, free]
        try:
            cov_f = np.linalg.inv(Jf.T @ Jf) * rmse**2 * rep
            cov[np.ix_(free, free)] = cov_f
        except np.linalg.LinAlgError:
            pass
        half = stats.t.ppf(0.975, dof) * np.sqrt(np.abs(np.diag(cov)))
        # F_s = F_c + ds: var(F_s) = var(F_c) + var(ds) + 2 cov
        var_fs = cov[0, 0] + cov[1, 1] + 2 * cov[0, 1]
        hw = {'coulomb': half[0], 'static': stats.t.ppf(0.975, dof) * np.sqrt(abs(var_fs)),
              'stribeck_velocity': half[2], 'viscous': half[3]}
        ci = {k: float(val) for k, val in hw.items() if np.isfinite(val)}
    return ParametricFit(float(x[0]), float(x[0] + x[1]), float(x[2]), float(x[3]), ci,
                         rmse, dof, cov)


def fit_polynomial(v: np.ndarray, tau: np.ndarray, order: int) -> np.ndarray:
    """Polynomial coefficients (order + 1,) in increasing powers of v [rad/s] -> tau_f [N m],
    least squares weighted by 1/|tau_f| (relative error)."""
    v, tau = np.asarray(v, float), np.asarray(tau, float)
    w = 1.0 / np.maximum(np.abs(tau), 1e-3 * np.max(np.abs(tau)) + 1e-9)
    p = Polynomial.fit(v, tau, order, w=w)
    return p.convert().coef


def _loo_error(v: np.ndarray, tau: np.ndarray, order: int) -> float:
    """Largest leave-one-out relative error of a polynomial fit (interior points only)."""
    errs = []
    for i in range(1, len(v) - 1):
        keep = np.arange(len(v)) != i
        p = fit_polynomial(v[keep], tau[keep], order)
        errs.append(abs(np.polynomial.polynomial.polyval(v[i], p) - tau[i]) / abs(tau[i]))
    return float(max(errs)) if errs else np.inf


def choose_order(v: np.ndarray, tau: np.ndarray, requested: int = 0) -> int | None:
    """Polynomial order: ``requested`` (5-7) or the best of 5-7 by leave-one-out; None if
    fewer than order + 2 points."""
    orders = [requested] if requested else [5, 6, 7]
    orders = [o for o in orders if len(v) >= o + 2]
    if not orders:
        return None
    if len(orders) == 1:
        return orders[0]
    return min(orders, key=lambda o: _loo_error(v, tau, o))


def identify_points(name: str, points: list[SpeedPoint], config: FitConfig = FitConfig(),
                    warnings: list[str] | None = None) -> JointResult:
    """Fits and the JointFriction of one joint from its eq. 4.8 points."""
    warnings = list(warnings or [])
    if len(points) < config.min_speeds:
        return JointResult(name, points, warnings=warnings, error=(
            f'{name}: {len(points)} usable speed(s), need at least {config.min_speeds} '
            f'(each needs a +c and a -c constant-speed segment)'))
    c = np.array([p.speed for p in points])
    f_pos = np.array([p.f_pos for p in points])
    f_neg = np.array([p.f_neg for p in points])
    try:
        par = fit_parametric(np.concatenate([c, -c]), np.concatenate([f_pos, f_neg]))
        why = stribeck_unsupported(par, float(c.min()), float(c.max()))
        if why:
            warnings.append(f'{name}: {why}: Stribeck term dropped (F_s = F_c)')
            par = fit_parametric(np.concatenate([c, -c]), np.concatenate([f_pos, f_neg]),
                                 stribeck=False)
    except IdentificationError as exc:      # a joint that cannot be fitted is reported, not fatal
        return JointResult(name, points, warnings=warnings, error=f'{name}: {exc}')
    degenerate = parametric_problems(par)
    poly_pos = poly_neg = None
    order_pos = choose_order(c, f_pos, config.poly_order)
    order_neg = choose_order(-c, f_neg, config.poly_order)
    if order_pos and order_neg:
        poly_pos = fit_polynomial(c, f_pos, order_pos)
        poly_neg = fit_polynomial(-c, f_neg, order_neg)
        worst = max(np.max(np.abs(np.polynomial.polynomial.polyval(c, poly_pos) - f_pos)
                           / np.abs(f_pos)),
                    np.max(np.abs(np.polynomial.polynomial.polyval(-c, poly_neg) - f_neg)
                           / np.abs(f_neg)))
        if worst > 0.05:
            warnings.append(f'{name}: polynomials miss a point by {100 * worst:.1f} % '
                            f'(the parametric fit by {100 * par.rmse / np.mean(np.abs(f_pos)):.1f}'
                            f' % RMS)')
    else:
        warnings.append(f'{name}: {len(points)} speeds are too few for a polynomial of order '
                        f'{config.poly_order or 5}: parametric model only')
    jf = JointFriction(
        coulomb=par.coulomb, static=par.static, stribeck_velocity=par.stribeck_velocity,
        viscous=par.viscous, valid_range=(float(c.min()), float(c.max())),
        polynomial_positive=None if poly_pos is None else tuple(float(x) for x in poly_pos),
        polynomial_negative=None if poly_neg is None else tuple(float(x) for x in poly_neg),
        ci95=par.ci95, degenerate_reason='; '.join(degenerate))
    return JointResult(name, points, par, poly_pos, poly_neg, jf, warnings,
                       degenerate=degenerate)


def stribeck_unsupported(par: ParametricFit, v_lo: float, v_hi: float) -> str | None:
    """Why the fitted Stribeck term is not supported by data at speeds v_lo..v_hi [rad/s]
    (None if it is, or if there is no hump at all)."""
    hump = par.static - par.coulomb
    if hump <= 0:
        return None
    vs = par.stribeck_velocity
    if not v_lo <= vs <= v_hi:
        return (f'Stribeck velocity {vs:.4g} rad/s outside the measured speeds '
                f'{v_lo:.4g}..{v_hi:.4g} rad/s')
    hw = par.ci95.get('stribeck_velocity', np.inf)
    if not hw < vs:
        return f'Stribeck velocity {vs:.4g} ± {hw:.3g} rad/s: interval wider than the value'
    return None


def parametric_problems(par: ParametricFit) -> list[str]:
    """Honesty checks of a sweep fit: negative levels, intervals wider than the value."""
    out = []
    for key in ('coulomb', 'viscous', 'static'):
        val = getattr(par, key)
        if val < 0:
            out.append(f'{key} = {val:.4g} < 0 (friction only dissipates)')
        elif key in par.ci95 and par.ci95[key] > abs(val):
            out.append(f'{key} = {val:.4g} ± {par.ci95[key]:.3g}: interval wider than the '
                       'value')
    return out


def identify_series(series_list: list[JointSeries], joint_names: list[str],
                    config: FitConfig = FitConfig(), model=None,
                    labels: list[str] | None = None) -> list[JointResult]:
    """Identify every joint of ``joint_names`` from one or more JointSeries (one per bag).

    ``model`` (irb_description RobotModel), optional: per-sign friction compensated by the
    model's M qdd + C qd + g on each segment (keeps an asymmetry eq. 4.8 averages away);
    eq. 4.8's tau_f is computed either way. ``labels`` (one per series, e.g. the bag names)
    name the series in warnings and rejections. Holds with a stick-slip signature are left
    out and listed in ``JointResult.rejected`` (and summarised in its warnings); a series in
    which a joint moved back and forth on its own but never held a steady speed gives a
    warning (a sweep lost entirely, e.g. to stick-slip).
    """
    labels = list(labels) if labels is not None else [f'series {k}'
                                                      for k in range(len(series_list))]
    segs = {j: [] for j in range(len(joint_names))}
    rejected = {j: [] for j in segs}
    unsteady = {j: [] for j in segs}

    def model_torque(q, qd):
        return model.inverse_dynamics_batch(q, qd, np.zeros_like(q))
    mt = model_torque if model is not None else None
    for s, label in zip(series_list, labels):
        s = s.select(joint_names)
        for j in segs:
            rej = []
            found = find_segments(s, j, config.segments, mt, rej)
            segs[j].extend(found)
            rejected[j].extend((label, r) for r in rej)
            if not found and not rej:
                fwd, bwd = _time_moving_alone(s, j, config.segments)
                if min(fwd, bwd) >= 2 * config.segments.min_duration_s:
                    unsteady[j].append(f'{label}: {joint_names[j]} moved back and forth on '
                                       f'its own ({fwd:.2f} s / {bwd:.2f} s) but never at a '
                                       'steady speed: no hold (stick-slip, chatter or '
                                       'dropped messages?)')
    results = []
    for j, name in enumerate(joint_names):
        notes = list(unsteady[j])
        if rejected[j]:
            notes.append(f'{name}: {len(rejected[j])} hold(s) rejected (stick-slip '
                         'signature): '
                         + '; '.join(f'{lab} {r.speed:+.4g} rad/s '
                                     f'{r.t_start:.2f}-{r.t_end:.2f} s ({r.reason})'
                                     for lab, r in rejected[j]))
        if not segs[j]:
            results.append(JointResult(name, [], warnings=notes, rejected=rejected[j],
                                       error=(f'{name}: no constant-speed segments (joint '
                                              f'never held a constant speed with the other '
                                              f'joints still)')))
            continue
        points, warnings = speed_points(segs[j], config.pair_rel_tol)
        res = identify_points(name, points, config, notes + warnings)
        results.append(replace(res, rejected=rejected[j], hold_time_s=float(sum(
            s.t_end - s.t_start for s in segs[j]))))
    return results


def _time_moving_alone(series: JointSeries, joint: int, config: SegmentConfig
                       ) -> tuple[float, float]:
    """Times [s] in which ``joint`` moves forward and backward (rolling mean speed over
    window_s above min_speed) while the others stay below still_tol: a back-and-forth of that
    joint alone, as an eq. 4.1 sweep (a move between two poses goes one way only)."""
    t = series.t
    if len(t) < 3:
        return 0.0, 0.0
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        return 0.0, 0.0
    w = max(3, int(round(config.window_s / dt)))
    means = [rolling_mean_std(series.velocity[:, k], w)[0]
             for k in range(series.velocity.shape[1])]
    alone = np.ones(len(t), bool)
    for k, m in enumerate(means):
        if k != joint:
            alone &= np.abs(m) < config.still_tol
    step = np.minimum(np.diff(t, append=t[-1]), 2 * dt)      # a recording gap counts 2 dt
    fwd = alone & (means[joint] > config.min_speed)
    bwd = alone & (means[joint] < -config.min_speed)
    return float(np.sum(step[fwd])), float(np.sum(step[bwd]))


def friction_map(results: list[JointResult], source: str,
                 fill: FrictionMap | None = None) -> FrictionMap:
    """FrictionMap of the identified joints; failed joints from ``fill`` if given, else left
    out. Raises IdentificationError if nothing is left."""
    names, joints = [], []
    for r in results:
        if r.friction is not None:
            names.append(r.name)
            joints.append(r.friction)
        elif fill is not None:
            names.append(r.name)
            joints.append(fill.joints[fill.joint_names.index(r.name)])
    if not joints:
        raise IdentificationError('no joint could be identified: ' + '; '.join(
            r.error or '' for r in results))
    missing = [r.name for r in results if r.friction is None]
    if missing and fill is not None:
        source += f' (not identified, from {fill.source}: {", ".join(missing)})'
    return FrictionMap(tuple(names), tuple(joints), source)


def complete_source(spec: str, model):
    """The map ``--complete-from`` names (None for ''), for the model's joints; 'nominal' =
    the model's nominal map. FrictionMapError (one line) when it lacks a joint or is bad."""
    if not spec:
        return None
    if spec == 'nominal':
        return model.friction
    return load_friction_map(spec, model.joint_names)


def complete_map(fmap: FrictionMap, base: FrictionMap, order) -> FrictionMap:
    """``fmap`` plus the joints of ``order`` it lacks, taken from ``base``, in ``order``
    (joints of ``fmap`` outside ``order`` follow); the source says which were copied."""
    names = [n for n in order if n in fmap.joint_names or n in base.joint_names]
    names += [n for n in fmap.joint_names if n not in names]
    copied = [n for n in names if n not in fmap.joint_names]
    joints = tuple(fmap.joints[fmap.joint_names.index(n)] if n in fmap.joint_names
                   else base.joints[base.joint_names.index(n)] for n in names)
    source = fmap.source + (f' (not identified here, from {base.source}: '
                            f'{", ".join(copied)})' if copied else '')
    return FrictionMap(tuple(names), joints, source)
