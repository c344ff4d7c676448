"""The bounded friction fit against an independent bounded fit (issue 27).

Generated logs with the properties real ones have (top speeds of 0.005 rad/s, friction that
decreases over the whole speed range, offsets, asymmetric levels, coloured noise, irregular
stamps, effort with an inertia residue). Oracle: scipy.optimize.least_squares on the samples
with the bounds written here (F_c, F_s - F_c, F_v >= 0, v_s inside the data's speed support,
offset and asymmetry free), multi-start over v_s; it shares no code with sample_fit. The
problem's definition (which samples: |v| >= the reported v_min; the speed support: the
reported valid range) is taken from the fit, the optimum is not.
"""
import numpy as np
import pytest
from scipy.optimize import least_squares, lsq_linear

from irb_identification.pipeline import PipelineConfig, identify_joints, report_entry
from irb_identification.sample_fit import MODELS, bounded_lsq, fit_samples
from irb_identification.series import JointSeries


def friction(v, off, fcp, fcn, fs, vs, fv):
    e = np.exp(-(v / vs) ** 2)
    return off + fv * v + np.where(v > 0, fcp * (1 - e) + fs * e, -(fcn * (1 - e) + fs * e))


def make_log(seed, top=0.5, duration=25.0, p=(0.1, 2.0, 1.6, 2.8, None, 1.0), ar=0.99,
             noise=0.05, inertia=0.0, jitter=(0.4e-3, 1.6e-3), gaps=True):
    """t, v, tau of continuous motion (sums of sines scaled to ``top``), friction with
    parameters p = (offset, F_c+, F_c-, F_s, v_s (None: top / 8), F_v (per top speed)),
    AR(1) noise of std ``noise`` and coefficient ``ar`` per sample, ``inertia`` x q_dd in the
    effort, irregular stamps (uniform in ``jitter``) with a few dropped stretches."""
    rng = np.random.default_rng(seed)
    n = int(duration / np.mean(jitter))
    t = np.cumsum(rng.uniform(*jitter, n))
    if gaps:
        for _ in range(5):                         # dropped stretches of 50-300 ms
            i = rng.integers(0, n - 1)
            t[i:] += rng.uniform(0.05, 0.3)
    w = 2 * np.pi * np.array([0.07, 0.23, 0.61])
    amp = np.array([0.6, 0.3, 0.1])
    ph = rng.uniform(0, 6, 3)
    v = (amp[:, None] * np.sin(w[:, None] * t + ph[:, None])).sum(axis=0)
    a = (amp[:, None] * w[:, None] * np.cos(w[:, None] * t + ph[:, None])).sum(axis=0)
    scale = top / np.max(np.abs(v))
    v, a = v * scale, a * scale
    off, fcp, fcn, fs, vs, fv = p
    vs = top / 8 if vs is None else vs
    tau = friction(v, off, fcp, fcn, fs, vs, fv / top)
    e = rng.standard_normal(n) * noise * np.sqrt(1 - ar**2)
    col = np.empty(n)
    acc = 0.0
    for i in range(n):                           # AR(1): coloured noise
        acc = ar * acc + e[i]
        col[i] = acc
    return t, v + 0.01 * top * rng.standard_normal(n), tau + col + inertia * a


CASES = {
    'top_0.005_rad_s': dict(seed=1, top=0.005),
    'decreasing_over_the_whole_range': dict(seed=2, p=(0.0, 0.5, 0.5, 4.0, 1.0, 0.0)),
    'offset_and_asymmetry': dict(seed=3, p=(0.6, 2.4, 1.2, 3.0, None, 0.8)),
    'coloured_noise': dict(seed=4, ar=0.999, noise=0.3),
    'irregular_stamps': dict(seed=5, jitter=(0.2e-3, 14e-3), duration=150.0),
    'inertia_residue': dict(seed=6, inertia=0.8),
}


def independent_fit(v, tau, form, v_lo, v_hi):
    """Plain bounded least squares of ``form`` on the samples: RMS [N m] and parameters
    (tau_0, F_c, h, F_v, a, v_s)."""
    s = np.sign(v)
    strib = form in ('stribeck', 'asymmetric_stribeck')
    free = {'coulomb_viscous': [1, 3], 'offset': [0, 1, 3], 'stribeck': [0, 1, 2, 3, 5],
            'asymmetric_stribeck': [0, 1, 2, 3, 4, 5]}[form]
    lower = np.array([-np.inf, 0.0, 0.0, 0.0, -np.inf, v_lo])[free]
    upper = np.array([np.inf, np.inf, np.inf, np.inf, np.inf, v_hi])[free]

    def full(z):
        p = np.zeros(6)
        p[free] = z
        return p, (np.exp(-(v / p[5]) ** 2) if strib else np.zeros_like(v))

    def model(z):
        p, e = full(z)
        return p[0] + s * (p[1] + p[2] * e) + p[3] * v + p[4] * (1 - e)

    def jac(z):
        p, e = full(z)
        d_vs = (s * p[2] - p[4]) * e * 2 * v * v / p[5] ** 3 if strib else 0 * v
        return np.column_stack([np.ones_like(v), s, s * e, v, 1 - e, d_vs])[:, free]

    best = None
    starts = np.geomspace(v_lo, v_hi, 5) if strib else [None]
    for vs0 in starts:
        z0 = np.array([0.0, np.mean(np.abs(tau)), 0.1, 0.1, 0.0, vs0 or 1.0])[free]
        z0 = np.minimum(np.maximum(z0, lower), upper)
        r = least_squares(lambda z: model(z) - tau, z0, jac=jac, bounds=(lower, upper),
                          x_scale='jac', method='trf')
        if best is None or r.cost < best.cost:
            best = r
    return float(np.sqrt(2 * best.cost / len(v))), best.x


def _identify(t, v, tau):
    s = JointSeries(t, ('axis',), np.cumsum(v)[:, None] * 1e-3, v[:, None], tau[:, None])
    res = identify_joints([s], ['log'], ['friction'], config=PipelineConfig(method='samples'))
    return res[0]


@pytest.mark.parametrize('case', list(CASES))
def test_map_rms_within_2_percent_of_an_independent_bounded_fit(case):
    t, v, tau = make_log(**CASES[case])
    r = _identify(t, v, tau)
    assert r.error is None, r.error
    fit = r.sample
    assert not r.degenerate, r.degenerate
    use = np.abs(v) >= fit.v_min
    vv, yy = v[use], tau[use]
    lo, hi = fit.valid_range
    j = r.friction
    rms_map = float(np.sqrt(np.mean((yy - j.torque(vv)) ** 2)))
    # the chosen parametric form, and the richest one, each against scipy's fit of it
    for form in {fit.parametric_model, 'asymmetric_stribeck'}:
        rms_ind, _ = independent_fit(vv, yy, form, lo, hi)
        ours = fit.candidates[form]['rms']
        assert ours <= 1.02 * rms_ind, (case, form, ours, rms_ind)
        assert rms_map <= 1.02 * rms_ind if form == fit.parametric_model else True, (
            case, rms_map, rms_ind)
    # physically valid: levels and slope never below their bounds
    assert j.coulomb >= 0 and j.viscous >= 0 and j.static >= j.coulomb
    assert lo <= j.stribeck_velocity <= hi or not fit.stribeck_identified
    entry = report_entry(r)
    assert set(entry['fit']['candidates']) >= set(MODELS)
    assert entry['fit']['v_min'] == fit.v_min and 'top speed' in entry['fit']['v_min_rule']


def test_slow_log_uses_a_relative_v_min():
    t, v, tau = make_log(**CASES['top_0.005_rad_s'])
    fit = fit_samples(t, v, tau, 'slow')
    top = np.quantile(np.abs(v), 0.999)
    assert fit.v_min == pytest.approx(0.02 * top, rel=1e-9)
    assert fit.valid_range[1] <= 0.0051


def test_decreasing_friction_is_a_valid_map_with_its_bound_named():
    """Friction falling over the whole range: the free fit's slope is negative; the bounded
    one reaches the same RMS with v_s at the top of the data and is not refused."""
    t, v, tau = make_log(**CASES['decreasing_over_the_whole_range'])
    fit = fit_samples(t, v, tau, 'dec')
    assert not fit.problems, fit.problems
    assert fit.viscous >= 0
    assert fit.rmse_parametric <= 1.02 * fit.rmse_unbounded
    assert any('Stribeck region wider than the data' in n or 'F_v = 0 on its bound' in n
               for n in fit.notes), fit.notes


def test_effort_that_holds_more_than_friction_is_refused_with_the_ratio():
    """A torque that falls steeply with speed (a drive torque not subtracted): the bounded
    optimum is clearly worse than the unbounded one; the report says by how much and why."""
    t, v, tau = make_log(seed=7)
    tau = tau - 12.0 * v                       # -12 N m s/rad on top of F_v = 2 N m s/rad
    fit = fit_samples(t, v, tau, 'x')
    assert fit.problems
    p = fit.problems[0]
    assert 'x worse than the unbounded one' in p and 'F_v = -' in p
    assert 'holds more than friction' in p


def test_model_choice_follows_the_data():
    """Coulomb + viscous data: the simplest candidate is chosen; asymmetric Stribeck data
    with an offset: the full parametric model."""
    t, v, tau = make_log(seed=8, p=(0.0, 2.0, 2.0, 2.0, None, 1.0), ar=0.0)
    assert fit_samples(t, v, tau, 'cv').parametric_model == 'coulomb_viscous'
    t, v, tau = make_log(**CASES['offset_and_asymmetry'])
    fit = fit_samples(t, v, tau, 'full')
    assert fit.parametric_model == 'asymmetric_stribeck'
    assert fit.offset == pytest.approx(0.6, abs=0.05)
    assert fit.coulomb_positive - fit.coulomb_negative == pytest.approx(1.2, abs=0.1)


def test_bounded_lsq_is_exact_against_lsq_linear():
    """The active-set solver at a fixed v_s against scipy's lsq_linear on random problems
    with some bounds active."""
    rng = np.random.default_rng(0)
    for _ in range(30):
        X = rng.standard_normal((200, 5))
        y = X @ rng.normal(0, 1, 5) + 0.1 * rng.standard_normal(200)
        lz = np.array([False, True, True, True, False])
        x, cost = bounded_lsq(X.T @ X, X.T @ y, float(y @ y), lz)
        ref = lsq_linear(X, y, bounds=(np.where(lz, 0.0, -np.inf), np.inf), tol=1e-12)
        np.testing.assert_allclose(x, ref.x, atol=1e-7)
        assert cost == pytest.approx(float(np.sum((X @ ref.x - y) ** 2)), rel=1e-9)
