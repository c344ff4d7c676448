"""Discrepancy workflow, issue 16: several effects at once, model errors, unexplained residuals,
repeated passes, comparable scores, fast reversals, bad input. Regression tests of the cases
the issue lists. The oracle is the simulated truth (what the plant was given), never the
workflow's own intermediate values."""
import dataclasses
import json
import warnings

import numpy as np
import pytest
import yaml

plant_mod = pytest.importorskip('irb_control.plant')
from irb_control.plant_effects import PlantEffects, moderate_effect  # noqa: E402
from irb_description.friction import load_friction_map  # noqa: E402

from irb_identification import discrepancy, excite  # noqa: E402
from irb_identification.discrepancy_core.excitation import (EffortNoise,  # noqa: E402
                                                            RunSpec, SensorErrors,
                                                            load_plan, perturbed_model,
                                                            run_plan, write_runs)
from irb_identification.discrepancy_core.forward import Decision, forward_select  # noqa: E402
from irb_identification.discrepancy_core.selection import tau_int  # noqa: E402
from irb_identification.discrepancy_core.terms import (Blocks, Term,  # noqa: E402
                                                       white_noise_rms)
from irb_identification.discrepancy_core.workflow import (WorkflowConfig,  # noqa: E402
                                                          run_workflow)

PLANS = discrepancy.default_config_path().parent / 'excitation.yaml'
SHORT = load_plan(PLANS, 'short')
CONFIG = WorkflowConfig(n_boot=20)


@pytest.fixture(scope='module')
def plant_yaml():
    return plant_mod.default_plant_yaml()


@pytest.fixture(scope='module')
def plant_map(model, plant_yaml):
    return load_friction_map(plant_yaml, model.joint_names)


def simulate(model, plant_map, tmp_path, names=(), plan=SHORT, seed=2, **kw):
    fx = {}
    for n in names:
        fx.update(moderate_effect(n).blocks)
    runs = run_plan(model, plan, plant_map, plant_map, PlantEffects(fx) if fx else None,
                    seed=seed, **kw)
    return runs, write_runs(runs, tmp_path, model.joint_names)


def named(report):
    return [e['effect'] for e in report['effects']]


# --- several effects at once ------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize('pair', [('stribeck', 'torque_offset'),
                                  ('joint_elasticity', 'viscous_temperature_drift'),
                                  ('backlash', 'stribeck'),
                                  ('torque_offset', 'time_delay'),
                                  # was named as one asymmetry of the summed size
                                  ('torque_offset', 'coulomb_asymmetry')])
def test_pairs_are_both_named_with_shares(model, plant_map, plant_yaml, tmp_path, pair):
    _, bags = simulate(model, plant_map, tmp_path / 'bags', pair)
    r = run_workflow(bags, plant_yaml, CONFIG, model=model).report
    assert sorted(named(r)) == sorted(pair), (r['effect'], r['steps'][-1]['stop_reason'])
    assert r['confidence'] >= 0.6
    assert sum(e['share_of_explained'] for e in r['effects']) == pytest.approx(1.0)
    assert all(e['share_of_explained'] > 0 for e in r['effects'])
    assert r['heldout_reduction'] >= 0.5
    assert r['unexplained'] is None
    if pair == ('torque_offset', 'time_delay'):
        # a second pass on the updated model: the known delay is subtracted, nothing left
        out = tmp_path / 'o1'
        res = run_workflow(bags, plant_yaml, CONFIG, model=model)
        from irb_identification.discrepancy_core.workflow import write_updated_model
        upd = write_updated_model(res, out.with_suffix('.yaml'))
        r2 = run_workflow(bags, upd, CONFIG, model=model).report
        assert r2['effect'] == 'none' and r2['heldout_reduction'] is None, r2['effect']
        assert sorted(r2['known_effects']) == ['time_delay', 'torque_offset']
        for j in (1, 2, 3):           # the known delay is subtracted (to the grid step)
            k = f'command_joint_{j}'
            assert r2['rms_before'][k] < 0.1 * res.report['rms_before'][k]


# --- model errors outside the effect library --------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize('case', ['viscous_high', 'link2_heavier', 'torque_gain',
                                  'encoder_scale', 'encoder_offset'])
def test_model_errors_are_named_as_model_errors(model, plant_map, plant_yaml, tmp_path, case):
    model_file = plant_yaml
    kw = {}
    if case == 'viscous_high':         # the model's viscous friction 8 % too high
        data = yaml.safe_load(open(plant_yaml))
        for j in data['friction_map']['joints'].values():
            j['viscous'] *= 1.08
        data.pop('effects', None)
        model_file = tmp_path / 'model.yaml'
        model_file.write_text(yaml.safe_dump(data))
    elif case == 'link2_heavier':
        kw['plant_model'] = perturbed_model(model, 2, 3.0)
    elif case == 'torque_gain':
        kw['sensor'] = SensorErrors(torque_gain=(1.05, 1.05, 1.05))
    elif case == 'encoder_scale':
        kw['sensor'] = SensorErrors(encoder_scale=(1.0, 1.02, 1.0))
    runs, bags = simulate(model, plant_map, tmp_path / 'bags', **kw)
    if case == 'encoder_offset':           # joint 2 encoder zero 5 mrad off
        for r in runs:
            r.data.q = r.data.q + np.array([0.0, 0.005, 0.0])
        bags = write_runs(runs, tmp_path / 'bags_offset', model.joint_names)
    r = run_workflow(bags, model_file, CONFIG, model=model).report
    want = {'viscous_high': 'viscous_level', 'link2_heavier': 'inertial_link2',
            'torque_gain': 'torque_gain', 'encoder_scale': 'encoder_scale',
            'encoder_offset': 'encoder_offset'}[case]
    assert named(r)[0] == want, (r['effect'], [(c['effect'], round(c['delta_bic']))
                                               for c in r['candidates'][:4]])
    assert r['effects'][0]['kind'] == 'model_error'
    p = {k: v['value'] for k, v in r['effects'][0]['parameters'].items()}
    assert all(v['ci95'] is None or v['ci95'][0] <= v['value'] <= v['ci95'][1]
               for v in r['effects'][0]['parameters'].values())
    fm = load_friction_map(plant_yaml, model.joint_names)
    if case == 'viscous_high':
        for j in range(3):
            truth = -0.08 * fm.joints[j].viscous
            assert p[f'viscous_level[{j + 1}]'] == pytest.approx(truth, rel=0.25)
    elif case == 'link2_heavier':
        # 3 kg at link 2's centre of mass: first moment z changes by 3 kg x c_z
        cz = model.model.inertias[2].lever[2]
        assert p['inertial_link2.first_moment_z_kgm'] == pytest.approx(3.0 * cz, rel=0.2)
        assert p['inertial_link2.mass_kg'] > 0
    elif case == 'torque_gain':
        for j in range(3):
            assert 1 + p[f'torque_gain[{j + 1}]'] == pytest.approx(1.05, abs=0.01)
    elif case == 'encoder_scale':
        assert p['encoder_scale[2]'] == pytest.approx(0.02, abs=0.003)
        assert r['rms_after']['tcp'] < 2 * r['noise_floor']['tcp'] < r['rms_before']['tcp']
    else:
        assert p['encoder_offset[2]'] == pytest.approx(0.005, abs=0.0005)
        assert r['rms_after']['tcp'] < 2 * r['noise_floor']['tcp'] < r['rms_before']['tcp']
    assert r['heldout_reduction'] >= 0.5


@pytest.mark.slow
def test_known_effect_is_refit_not_renamed(model, plant_map, tmp_path, plant_yaml):
    """A model that already has viscous_nonlinear: at the true value nothing is named; at
    half the value the pass reports a joint refit of the known effect (not a new name) and
    the updated model holds the refitted value."""
    _, bags = simulate(model, plant_map, tmp_path / 'bags', ['viscous_nonlinear'])
    data = yaml.safe_load(open(plant_yaml))
    data['effects'] = moderate_effect('viscous_nonlinear').to_dict()
    right = tmp_path / 'right.yaml'
    right.write_text(yaml.safe_dump(data))
    r = run_workflow(bags, right, CONFIG, model=model).report
    assert r['effect'] == 'none', r['effect']
    data['effects']['viscous_nonlinear']['coefficient'] = [5.0, 5.0, 2.5]
    half = tmp_path / 'half.yaml'
    half.write_text(yaml.safe_dump(data))
    res = run_workflow(bags, half, CONFIG, model=model)
    r = res.report
    assert r['effect'] == 'refit:viscous_nonlinear', r['effect']
    assert r['effects'][0]['refit_of_known']
    block = res.extra['effects'].get('viscous_nonlinear')
    np.testing.assert_allclose(block.coefficient, [10.0, 10.0, 5.0], rtol=0.1)


@pytest.mark.slow
def test_unexplained_residual_is_reported_where_it_is(model, plant_map, plant_yaml, tmp_path):
    """A 'tight spot' (joint 2 friction +3 N m on the upper third of its travel) is in no
    candidate: the answer is 'unexplained' or names nothing with confidence, and says joint 2
    and the position range."""
    runs, _ = simulate(model, plant_map, tmp_path / 'clean')
    q_all = np.concatenate([r.data.q[:, 1] for r in runs])
    q_hi = np.quantile(q_all, 2 / 3)
    for r in runs:
        d = r.data
        spot = (d.q[:, 1] > q_hi) * np.sign(d.qd[:, 1]) * 3.0
        d.effort = d.effort.copy()
        d.effort[:, 1] += spot
    bags = write_runs(runs, tmp_path / 'bags', model.joint_names)
    r = run_workflow(bags, plant_yaml, CONFIG, model=model).report
    assert r['unexplained'] is not None
    blocks = r['unexplained']['blocks']
    assert 'torque_joint_2' in blocks
    lo, hi = blocks['torque_joint_2']['largest_position_bin_rad']
    assert hi > q_hi - 0.05
    assert r['effect'] == 'unexplained' and r['effects'] == [], \
        (r['effect'], r['partial_fits'])
    text = discrepancy_answer(r)
    assert 'UNEXPLAINED' in text and 'torque_joint_2' in text


@pytest.mark.slow
def test_fast_plan_uses_its_own_floor_for_none_not_for_names(model, plant_map, plant_yaml,
                                                             tmp_path):
    """The benchmark's fast-plan cases (its effort noise and seeds): clean data is `none`
    (it was `unexplained`: joint 1's clean residual 0.79 N m, 3.1 x the configured floor,
    1.6 x the excitation's own smoothing bias); the joint-2 tight spot on the same plan is
    still `unexplained`, not a Stribeck hump that explains a quarter of it (what a floor
    raised for everything gave)."""
    plan = load_plan(PLANS, 'fast')
    noise = EffortNoise((0.2, 0.2, 0.2), (0.1, 0.1, 0.1), 0.05, 0.005)
    _, bags = simulate(model, plant_map, tmp_path / 'clean', plan=plan, seed=100,
                       effort_noise=noise)
    r = run_workflow(bags, plant_yaml, CONFIG, model=model).report
    assert r['effect'] == 'none', (r['effect'], r['unexplained'])
    ef, nf = r['excitation_floor'], r['noise_floor']
    assert ef['torque_joint_1'] > 1.5 * nf['torque_joint_1']
    assert r['rms_after']['torque_joint_1'] > 3 * nf['torque_joint_1']
    runs, _ = simulate(model, plant_map, tmp_path / 'spot', plan=plan, seed=4,
                       effort_noise=noise)
    q_hi = np.quantile(np.concatenate([x.data.q[:, 1] for x in runs]), 2 / 3)
    for x in runs:
        d = x.data
        d.effort = d.effort + np.column_stack(
            [0 * d.t, (d.q[:, 1] > q_hi) * np.sign(d.qd[:, 1]) * 3.0, 0 * d.t])
    bags = write_runs(runs, tmp_path / 'spot_bags', model.joint_names)
    r = run_workflow(bags, plant_yaml, CONFIG, model=model).report
    assert r['effect'] == 'unexplained' and r['effects'] == [], (r['effect'],
                                                                 r['partial_fits'])
    assert 'torque_joint_2' in r['unexplained']['blocks']


@pytest.mark.slow
def test_marginal_backlash_near_the_camera_noise_is_named(model, plant_map, plant_yaml,
                                                          tmp_path):
    """The benchmark's marginal backlash on joint 3 (0.4 x moderate: 80 urad, ~60 um at the
    TCP against 37 um camera noise, with the bench's effort noise): it was `none` (fit RMS
    reduction 21 % < 25 %); the excess test over the measured camera noise names it, and
    the half-width on joint 3 comes back within 10 % of what the plant was given (measured:
    80.2 against 80 urad)."""
    fx = moderate_effect('backlash', 0.4).to_dict()
    fx['backlash']['half_width_rad'] = [0.0, 0.0, fx['backlash']['half_width_rad'][2]]
    noise = EffortNoise((0.2, 0.2, 0.2), (0.1, 0.1, 0.1), 0.05, 0.005)
    runs = run_plan(model, SHORT, plant_map, plant_map, PlantEffects.from_dict(fx), seed=1,
                    effort_noise=noise)
    bags = write_runs(runs, tmp_path, model.joint_names)
    res = run_workflow(bags, plant_yaml, CONFIG, model=model)
    r = res.report
    assert named(r) == ['backlash'], (r['effect'], r['candidates'][:3])
    row = [c for c in r['candidates'] if c['effect'] == 'backlash'][0]
    assert row['fit_rms_reduction'] < 0.25 < 0.5 < row['excess_rms_reduction'], row
    white = r['decision']['measured_white_noise']['tcp']
    assert 33e-6 < white < 41e-6, white            # 37 um simulated camera noise
    hw = r['effects'][0]['parameters']['half_width_rad']['value']
    assert hw[2] == pytest.approx(fx['backlash']['half_width_rad'][2], rel=0.1), hw
    assert abs(hw[1]) < 0.1 * hw[2], hw


def discrepancy_answer(r):
    from irb_identification.discrepancy_core.report import answer_line
    return answer_line(r)


@pytest.mark.slow
def test_fast_reversals_and_effort_noise_give_no_false_name(model, plant_map, plant_yaml,
                                                            tmp_path):
    plan = load_plan(PLANS, 'fast')
    noise = EffortNoise((0.3, 0.3, 0.3), (0.2, 0.2, 0.2), 0.05, 0.01)
    _, bags = simulate(model, plant_map, tmp_path / 'bags', plan=plan, effort_noise=noise)
    r = run_workflow(bags, plant_yaml, CONFIG, model=model).report
    assert r['effect'] == 'none', (r['effect'], r['candidates'][:3])
    assert any(s['adapted'] for s in r['smoothing'])
    assert all(s['window_s'] <= 0.25 * s['reversal_interval_s'] + 0.01
               for s in r['smoothing'] if s['adapted'])


@pytest.mark.slow
def test_joint_that_never_moves_gives_no_numpy_warning(model, plant_map, plant_yaml,
                                                       tmp_path):
    plan = [RunSpec('sweep', 4.0, (1, 1, 2), (0.0, 0.5, 0.8), (0.0, 0.6, -0.2)),
            RunSpec('sweep', 3.0, (1, 2, 1), (0.0, 0.3, 0.4), (0.0, 0.9, 0.2))]
    _, bags = simulate(model, plant_map, tmp_path / 'bags', ['torque_offset'], plan=plan)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        r = run_workflow(bags, plant_yaml, CONFIG, model=model).report
    assert 'torque_joint_1' not in r['rms_before']
    assert named(r) == ['torque_offset'] and r['effects'][0]['joints'] == [2, 3]


# --- selection logic on synthetic blocks (cheap) -----------------------------------------
def _synthetic(rng, n0=40000, n1=600):
    """Two torque blocks: block 0 (long, white noise) has a tiny but very significant effect
    a (1 % of its RMS), block 1 (short, smoothed noise, tau_int ~ 10) a large effect b."""
    t0, t1 = np.arange(n0), np.arange(n1)
    xa = np.sin(t0 / 50.0)
    xb = np.sign(np.sin(t1 / 130.0))
    y0 = 0.6 * xa + 3.0 * rng.standard_normal(n0)
    y1 = 2.0 * xb + np.convolve(rng.standard_normal(n1), np.ones(10) / 10, 'same') * 0.3
    B = Blocks({('torque', 0): t0, ('torque', 1): t1}, {('torque', 0): y0, ('torque', 1): y1},
               {('torque', 0): t0 // 200, ('torque', 1): t1 // 200},
               {('torque', 0): 1.0, ('torque', 1): 1.0})
    return B, xa, xb


def _term(name, cb, x):
    t = Term(name, 'effect', [cb[1]], {cb: x[:, None]}, [f'{name}[{cb[1] + 1}]'])
    t.groups = {cb[1]: [0]}
    return t


def test_floor_applies_to_every_candidate_and_scores_share_n_eff(rng):
    B, xa, xb = _synthetic(rng)
    tbs = np.unique(B.tb[('torque', 0)])
    fit, hold = tbs[tbs % 2 == 0], tbs[tbs % 2 == 1]

    def cands(e, fitrow, selected):
        out = [_term('a', ('torque', 0), xa), _term('b', ('torque', 1), xb)]
        return [t for t in out if t.key() not in selected]
    fr = forward_select(B, B.y, fit, hold, cands, lambda t, v: ({}, []),
                        Decision(n_boot=20, min_fit_reduction=0.25))
    assert [t.name for t in fr.selected] == ['b']
    first = {c['effect']: c for c in fr.steps[0].candidates}
    assert first['a']['delta_bic'] < first['b']['delta_bic'] < -30     # a: more "evidence"
    assert 'fit RMS reduction' in first['a']['reason']
    # one effective sample size per block: tau_int of what all candidates together leave
    # (recomputed by hand with numpy on the fit rows), the same for a and b
    f0 = np.isin(B.tb[('torque', 0)], fit)
    y = B.y[('torque', 0)][f0]
    X = xa[f0][:, None]
    beta = np.linalg.lstsq(X, y, rcond=None)[0]
    res = y - X @ beta
    want = f0.sum() / tau_int(res)
    rss1, rss0 = float(res @ res), float(y @ y)
    d_hand = want * np.log(rss1 / rss0) + np.log(want)
    assert first['a']['delta_bic'] == pytest.approx(d_hand, rel=1e-6)
    np.testing.assert_allclose(fr.beta['b'], [2.0], rtol=0.02)


def _camera_block(rng, signal, sigma=37e-6, floor=40e-6):
    """A TCP block (M samples x 3 axes, flattened as the workflow does): signal + white
    camera noise; time blocks of 250 samples (1 s at 250 Hz)."""
    m = len(signal)
    y = (signal + sigma * rng.standard_normal((m, 3))).reshape(-1)
    cb = ('tcp', None)
    tb = np.repeat(np.arange(m) // 250, 3)
    return cb, Blocks({cb: np.arange(3 * m)}, {cb: y}, {cb: tb}, {cb: floor},
                      {cb: white_noise_rms(y.reshape(-1, 3))})


def _tcp_term(name, cb, x):
    t = Term(name, 'effect', [2], {cb: x.reshape(-1)[:, None]}, [f'{name}[3]'])
    t.groups = {2: [0]}
    return t


def test_white_noise_of_a_smooth_error_is_measured(rng):
    """The camera's white noise under a smooth error 3 x as large (the estimator the
    excess test relies on), against the noise the data was made with."""
    t = np.arange(20000) / 250.0
    smooth = 110e-6 * np.stack([np.sin(2 * np.pi * 0.3 * t), np.cos(2 * np.pi * 0.7 * t),
                                np.sign(np.sin(2 * np.pi * 0.2 * t))], axis=1)
    got = white_noise_rms(smooth + 37e-6 * rng.standard_normal(smooth.shape))
    assert got == pytest.approx(37e-6, rel=0.05)
    # a filtered camera (AR(1) noise, rho 0.5): not white, so not measured (the excess test
    # is then off) rather than read 29 % low
    w = 37e-6 * rng.standard_normal(smooth.shape)
    ar = np.zeros_like(w)
    for k in range(1, len(w)):
        ar[k] = 0.5 * ar[k - 1] + w[k]
    assert np.isnan(white_noise_rms(smooth + ar))


def test_an_effect_near_the_camera_noise_is_named_by_what_stands_above_it(rng):
    """A camera-channel effect of 0.8 x the noise RMS: it explains all of what stands above
    the measured noise but cuts the RMS with the noise in it by ~20 % (< 25 %): named only
    through the excess test. An error of another shape that a candidate explains only in
    part (30 % of its variance) is not named, however significant."""
    m = 12000
    t = np.arange(m) / 250.0
    shape = np.stack([np.sin(2 * np.pi * 0.4 * t + k) for k in range(3)], axis=1)
    shape /= np.sqrt(np.mean(shape ** 2))
    cb, B = _camera_block(rng, 0.8 * 37e-6 * shape)
    tbs = np.unique(B.tb[cb])
    fit, hold = tbs[tbs % 2 == 0], tbs[tbs % 2 == 1]
    cands = lambda e, fitrow, sel: [t_ for t_ in [_tcp_term('backlash', cb, shape)]  # noqa
                                    if t_.key() not in sel]
    fr = forward_select(B, B.y, fit, hold, cands, lambda t_, v: ({}, []), Decision(n_boot=20))
    row = fr.steps[0].candidates[0]
    assert row['fit_rms_reduction'] < 0.25 < 0.5 < row['excess_rms_reduction']
    assert [t_.name for t_ in fr.selected] == ['backlash']
    np.testing.assert_allclose(fr.beta['backlash'], [0.8 * 37e-6], rtol=0.1)
    # the same data without a measured noise: the plain 25 % floor alone, not named
    B_plain = Blocks(B.rows, B.y, B.tb, B.floor)
    fr = forward_select(B_plain, B_plain.y, fit, hold, cands, lambda t_, v: ({}, []),
                        Decision(n_boot=20))
    assert fr.selected == [] and 'fit RMS reduction' in fr.steps[0].candidates[0]['reason']
    # outside the library: an error of 2 x the noise of which the candidate's shape carries
    # 30 % of the variance (the rest a 7 Hz ripple) -- significant, but a partial fit
    other = np.stack([np.sin(2 * np.pi * 7.0 * t + 2 * k) for k in range(3)], axis=1)
    other /= np.sqrt(np.mean(other ** 2))
    err = 2.0 * 37e-6 * (np.sqrt(0.3) * shape + np.sqrt(0.7) * other)
    cb, B = _camera_block(rng, err)
    fr = forward_select(B, B.y, fit, hold, cands, lambda t_, v: ({}, []), Decision(n_boot=20))
    row = fr.steps[0].candidates[0]
    assert row['delta_bic'] < -30 and row['excess_rms_reduction'] < 0.5
    assert fr.selected == [], row


def test_implausible_parameters_reject_the_joint(rng):
    B, xa, xb = _synthetic(rng)
    tbs = np.unique(B.tb[('torque', 0)])

    def cands(e, fitrow, selected):
        return [] if selected else [_term('b', ('torque', 1), xb)]

    def no_positive(t, v):
        return ({g: 'positive, unphysical' for g in t.groups if v[0] > 0}, [])
    fr = forward_select(B, B.y, tbs[tbs % 2 == 0], tbs[tbs % 2 == 1], cands, no_positive,
                        Decision(n_boot=10))
    assert fr.selected == []
    assert 'unphysical' in fr.steps[0].candidates[0]['reason']


# --- excitation and CLI input ------------------------------------------------------------
def test_effort_noise_knobs_have_the_asked_statistics(rng):
    t = np.arange(200000) * 0.004
    z = np.zeros((len(t), 3))
    w = EffortNoise((0.5, 0.5, 0.5)).apply(t, z, rng)
    np.testing.assert_allclose(w.std(axis=0), 0.5, rtol=0.02)
    c = EffortNoise(coloured=(0.3, 0.3, 0.3), coloured_tau_s=0.04).apply(t, z, rng)
    np.testing.assert_allclose(c.std(axis=0), 0.3, rtol=0.1)
    # AR(1) with a = exp(-T / tau): tau_int = (1 + a) / (1 - a)
    a = np.exp(-0.004 / 0.04)
    assert tau_int(c[:, 0], max_lag=2000) == pytest.approx((1 + a) / (1 - a), rel=0.2)
    q = EffortNoise((0.5, 0.5, 0.5), quantum=0.1).apply(t, z + 1.234, rng)
    np.testing.assert_allclose(np.round(q / 0.1) * 0.1, q, atol=1e-12)
    with pytest.raises(ValueError, match='>= 0'):
        EffortNoise((-1.0, 0, 0))
    with pytest.raises(ValueError, match='> 0'):
        SensorErrors(torque_gain=(0.0, 1, 1))


@pytest.mark.parametrize('args,msg', [
    (['--effect', 'bogus'], "unknown effect 'bogus'; known: stribeck"),
    (['--effect', 'stribeck:x'], "scale 'x' is not a number"),
    (['--effect', 'stribeck:-1'], 'scale must be > 0'),
    (['--effort-noise-white', '-0.1'], 'must be finite and >= 0'),
    (['--effort-noise-coloured', '0.1,0.2'], 'expected 1 or 3'),
    (['--torque-gain', 'abc'], 'not a number'),
    (['--link-mass-error', '5:3'], 'LINK 2 or 3'),
    (['--plan', 'nope'], "plan 'nope' not in"),
])
def test_excite_bad_arguments_one_clear_line(tmp_path, capsys, args, msg):
    assert excite.main(['--out', str(tmp_path / 'x')] + args) == 1
    err = capsys.readouterr().err
    assert msg in err and 'Traceback' not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / 'x').exists()


def test_excite_too_large_delay_is_a_clear_error(tmp_path, capsys):
    assert excite.main(['--out', str(tmp_path / 'x'), '--effect', 'time_delay:2']) == 1
    err = capsys.readouterr().err
    assert 'controller stopped' in err and 'Traceback' not in err


def test_discrepancy_bad_input(tmp_path, plant_yaml, capsys, model):
    # the same bag as --bag and --holdout-bag
    t = np.arange(0, 2.0, 0.004032)
    q = np.tile([0.0, 0.9, 0.25], (len(t), 1))
    eff = np.tile(model.gravity(q[0]), (len(t), 1))
    from irb_identification.discrepancy_core.bagdata import write_run
    bag = write_run(tmp_path / 'still', model.joint_names, t, q, 0 * q, eff, t, eff,
                    np.empty(0), np.empty((0, 3)))
    out = str(tmp_path / 'o')
    assert discrepancy.main(['--bag', str(bag), '--holdout-bag', str(bag), '--model',
                             str(plant_yaml), '--out', out]) == 1
    assert 'both as --bag and --holdout-bag' in capsys.readouterr().err
    # nothing moves faster than v_min: one clear line, no numpy warning
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        assert discrepancy.main(['--bag', str(bag), '--model', str(plant_yaml), '--out',
                                 out, '--no-plots']) == 1
    err = capsys.readouterr().err
    assert 'no joint moves' in err or 'no usable samples' in err
    assert 'All-NaN' not in err and 'Traceback' not in err


def test_config_file_round_trip(tmp_path):
    cfg = WorkflowConfig.from_yaml(discrepancy.default_config_path())
    assert cfg.heldout_threshold > 0 and cfg.unexplained_ratio > 1
    assert dataclasses.asdict(cfg)['noise_floor']['tcp_m'] > 0
    assert json.dumps(dataclasses.asdict(cfg), default=str)


def test_indistinguishable_candidates_are_aliases_not_a_split(rng):
    """Two candidates with the same signature on this data (as joint-1 armature and link 2's
    mass on its axis): the bootstrap splits between them, yet the explanation is certain; the
    named one lists the other as indistinguishable and the confidence counts both."""
    B, xa, xb = _synthetic(rng)
    tbs = np.unique(np.concatenate([B.tb[k] for k in B.keys]))

    def cands(e, fitrow, selected):
        out = [_term('b', ('torque', 1), xb), _term('b_alias', ('torque', 1), 2.0 * xb)]
        return [t for t in out if t.key() not in selected]
    fr = forward_select(B, B.y, tbs[tbs % 2 == 0], tbs[tbs % 2 == 1], cands,
                        lambda t, v: ({}, []), Decision(n_boot=20))
    assert len(fr.selected) == 1
    step = fr.steps[0]
    other = {'b': 'b_alias', 'b_alias': 'b'}[step.added]
    assert step.aliases == [other]
    n = sum(step.wins.values())
    assert step.support == (step.wins.get('b', 0) + step.wins.get('b_alias', 0)) / n >= 0.6


def test_split_bootstrap_names_a_needed_pair_jointly_else_ambiguous(rng):
    """Truth half of one candidate and half of another that explain the data equally well
    alone by construction (data, noise and fit/hold-out blocks are symmetric under time
    reversal, which swaps them; correlation 0.34, not aliases): the bootstrap of the first
    step splits between them. Each is significant once the other is in, so both are named
    in one joint step with the support of the two-step decision; where the pair cannot be
    added (max_terms = 1) nothing is named and the answer is `ambiguous`, with the split."""
    from irb_identification.discrepancy_core.report import answer_line
    from irb_identification.discrepancy_core.workflow import verdict
    n = 3100                                    # 31 blocks: reversal keeps their parity
    t = np.arange(n)
    xb = np.sin(t / 40.0) * (0.2 + t / n)
    xc = xb[::-1].copy()
    e = 0.3 * rng.standard_normal(n)
    y = 0.5 * (xb + xc) + (e + e[::-1]) / np.sqrt(2)
    cb = ('torque', 1)
    B = Blocks({cb: t}, {cb: y}, {cb: t // 100}, {cb: 0.3})
    tbs = np.unique(B.tb[cb])

    def cands(e, fitrow, selected):
        out = [_term('b', cb, xb), _term('c', cb, xc)]
        return [t_ for t_ in out if t_.key() not in selected]

    def select(**kw):
        return forward_select(B, B.y, tbs[tbs % 2 == 0], tbs[tbs % 2 == 1], cands,
                              lambda t_, v: ({}, []), Decision(n_boot=200, **kw))
    fr = select()
    assert sorted(t_.name for t_ in fr.selected) == ['b', 'c']
    first = fr.steps[0]
    assert max(first.wins.values()) / 200 < 0.6          # the first step alone: a split
    assert first.stop_reason.startswith('joint step') and first.support >= 0.6
    assert fr.steps[1].support == first.support
    np.testing.assert_allclose([fr.beta['b'][0], fr.beta['c'][0]], 0.5, atol=0.03)
    # no room for two: ambiguous, nothing named
    fr = select(max_terms=1)
    last = fr.steps[-1]
    assert fr.selected == [] and last.aliases == [], last.stop_reason
    assert 'bootstrap support' in last.stop_reason
    effect, confidence, amb = verdict([], last, True, 200)
    assert effect == 'ambiguous' and confidence == amb['support'] < 0.6
    assert amb['best'] in ('b', 'c') and set(amb['wins']) <= {'b', 'c', 'none'}
    assert amb['wins'].get('b', 0) >= 0.2 and amb['wins'].get('c', 0) >= 0.2, amb
    line = answer_line({'effects': [], 'effect': effect, 'confidence': confidence,
                        'ambiguous': amb, 'unexplained': None,
                        'decision': {'min_confidence': 0.6}})
    assert line.startswith('AMBIGUOUS: the bootstrap splits') and 'nothing named' in line
    # the same step with a name: that name wins over the split
    named = [{'effect': 'b', 'kind': 'effect', 'confidence': 0.9}]
    assert verdict(named, last, True, 200)[:2] == ('b', 0.9)


def test_cogging_period_is_kept_below_half_the_stroke(model, plant_map, rng):
    """A long-wave trend over a 0.3 rad stroke is no cogging: the profiled period stays
    <= half the stroke (the old fit ran to the grid maximum, 0.6 rad), and a period longer
    than that is rejected by the plausibility check."""
    from irb_identification.discrepancy_core.library import Grids, Pooled
    from irb_identification.discrepancy_core.terms import build_term, make_blocks
    from irb_identification.discrepancy_core.workflow import plausibility_check
    n = 3000
    q = np.zeros((n, 3))
    q[:, 0] = 0.15 * np.sin(np.linspace(0, 6 * np.pi, n))          # stroke 0.3 rad
    qd = np.gradient(q, 0.004, axis=0)
    r = np.zeros((n, 3))
    r[:, 0] = 2.0 * q[:, 0] / 0.15 + 0.1 * rng.standard_normal(n)   # slow trend in q
    z3, z0 = np.zeros((n, 3)), np.zeros(0)
    mask = np.zeros((n, 3), bool)
    mask[:, 0] = True
    P = Pooled(np.arange(n) * 0.004, q, qd, z3, r, mask, np.arange(n) // 250,
               np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3, 3)),
               z0.astype(int), np.empty((0, 3)), np.empty((0, 3)), np.empty((1, 0, 3)),
               np.zeros(1), z0.astype(int), np.ones(3) * 0.05, {})
    B = make_blocks(P, {'torque': [0.25] * 3, 'tcp': 4e-5, 'command': [1e-3] * 3})
    fitrow = {cb: np.ones(len(B.rows[cb]), bool) for cb in B.keys}
    stroke = np.array([np.ptp(q[:, 0]), 0.0, 0.0])
    t = build_term('cogging', P, B, B.y, fitrow, Grids(), stroke=stroke)
    assert t.scales[0] <= stroke[0] / 2 + 1e-9
    check = plausibility_check(model, plant_map, 12.0, stroke, {})
    long = build_term('cogging', P, B, B.y, fitrow, Grids(), fixed_scales={0: 0.6})
    bad, _ = check(long, np.array([1.0, 0.5]))
    assert 0 in bad and 'stroke' in bad[0]
