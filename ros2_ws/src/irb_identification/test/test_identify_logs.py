"""Identification from logs of any motion (issue 15): known friction -> samples -> identify.

Oracles: the friction parameters the data were generated with (several effects at once:
asymmetric Coulomb, offset, Stribeck, viscous; noise, outlier spikes, irregular stamps,
foreign joint names); for total torque the irb_control plant (its own friction and dynamics
integration) or irb_description's inverse dynamics; for sweeps the eq. 4.8 method.
"""
import json

import numpy as np
import pytest
import yaml
from irb_description.friction import FrictionMapError, load_friction_map

from irb_identification import identify, import_log
from irb_identification.sample_fit import SampleFitConfig, SampleFitError, fit_samples

TRUTH = dict(offset=0.15, coulomb_positive=2.2, coulomb_negative=1.7, static=3.0,
             stribeck_velocity=0.06, viscous=1.4)


def truth_torque(v, p=TRUTH):
    e = np.exp(-(v / p['stribeck_velocity']) ** 2)
    return p['offset'] + p['viscous'] * v + np.where(
        v > 0, p['coulomb_positive'] * (1 - e) + p['static'] * e,
        -(p['coulomb_negative'] * (1 - e) + p['static'] * e))


def motion(rng, duration=300.0, slow=False):
    """Continuous motion, no constant-speed holds: sums of sines (slow, middle, fast
    components), stamps irregular by 1-13 ms."""
    n = int(duration / 7e-3)
    t = 3.0 + np.cumsum(rng.uniform(1e-3, 13e-3, n))
    amps = (0.05, 0.03, 0.02) if slow else (0.6, 0.3, 0.12)
    v = sum(a * np.sin(2 * np.pi * f * t + rng.uniform(0, 6))
            for a, f in zip(amps, (0.031, 0.11, 0.43)))
    return t, v


def noisy_friction(rng, v, noise=0.05, spikes=0.002):
    tau = truth_torque(v) + noise * rng.standard_normal(len(v))
    hit = rng.random(len(v)) < spikes
    tau[hit] += 8 * rng.standard_normal(hit.sum())        # outliers
    return tau


def test_samples_fit_recovers_all_parameters(rng):
    t, v = motion(rng)
    fit = fit_samples(t, v + 0.002 * rng.standard_normal(len(v)), noisy_friction(rng, v))
    assert not fit.problems, fit.problems
    assert fit.stribeck_identified and fit.offset_identified
    for key in ('coulomb_positive', 'coulomb_negative', 'static', 'stribeck_velocity',
                'viscous'):
        assert getattr(fit, key) == pytest.approx(TRUTH[key], rel=0.05), key
        # the interval is honest: it covers the truth, and is narrower than the value
        assert abs(getattr(fit, key) - TRUTH[key]) < 3 * fit.ci95[key], key
    assert fit.offset == pytest.approx(TRUTH['offset'], abs=0.05)
    # asymmetry and offset matter: the symmetric model without offset fits clearly worse
    # (the RMS includes the spikes; their share is common to both models)
    assert fit.rmse_symmetric**2 - fit.rmse**2 > 0.05


def test_too_few_samples_above_v_min_names_joint_range_and_threshold(rng):
    t, v = motion(rng, 20.0, slow=True)
    with pytest.raises(SampleFitError, match=r'axis 3: \d+ samples above v_min = 0.2 rad/s.*'
                       r'\|v\| seen: [0-9.e-]+\.\.[0-9.e-]+ rad/s'):
        fit_samples(t, v, truth_torque(v), 'axis 3', SampleFitConfig(v_min=0.2))


def test_stribeck_outside_the_data_is_dropped_not_reported(rng):
    """Only fast motion (|v| > 0.3 rad/s, v_s = 0.06): the hump is invisible; the fit must
    not invent a Stribeck velocity (the old fit gave 3.62 rad/s +- 1.5e6)."""
    t = np.cumsum(rng.uniform(1e-3, 13e-3, 20000))
    v = np.sign(np.sin(0.5 * t)) * (0.6 + 0.25 * np.sin(0.37 * t))
    fit = fit_samples(t, v, noisy_friction(rng, v, spikes=0), 'j')
    assert not fit.stribeck_identified
    assert any('Stribeck' in n for n in fit.notes)
    assert any('cannot be told apart' in n for n in fit.notes)
    # the levels per sign carry offset + Coulomb (+ the hump's tail, ~0 here)
    assert fit.coulomb_positive == pytest.approx(TRUTH['offset'] + TRUTH['coulomb_positive'],
                                                 abs=0.05)
    assert fit.coulomb_negative == pytest.approx(TRUTH['coulomb_negative'] - TRUTH['offset'],
                                                 abs=0.05)


def test_garbage_is_marked_degenerate(rng):
    """Torque unrelated to speed: negative or meaningless levels are problems."""
    t = np.cumsum(rng.uniform(1e-3, 13e-3, 5000))
    v = 0.5 * np.sin(0.8 * t)
    tau = -0.3 * v + 0.5 * rng.standard_normal(len(v))
    fit = fit_samples(t, v, tau, 'j')
    assert fit.problems
    assert any('< 0' in p or 'wider than the value' in p for p in fit.problems)


def _csv(path, t, cols):
    names = list(cols)
    rows = ['time,' + ','.join(names)] + [
        ','.join(repr(float(x)) for x in (t[i], *(cols[n][i] for n in names)))
        for i in range(len(t))]
    path.write_text('\n'.join(rows) + '\n')
    return path


def test_cli_real_log_path_foreign_names(tmp_path, rng, capsys):
    """import_log -> identify on a non-sweep friction log of a robot we did not build."""
    t, v = motion(rng, 200.0)
    src = _csv(tmp_path / 'log.csv', t, {'q': np.cumsum(v) * 7e-3, 'qd': v,
                                         'tf': noisy_friction(rng, v)})
    bag = tmp_path / 'bag'
    assert import_log.main([str(src), '--out', str(bag), '--time-column', 'time',
                            '--joint', 'Achse 2:q:qd:tf']) == 0
    out, rep = tmp_path / 'map.yaml', tmp_path / 'r.json'
    assert identify.main(['--bag', str(bag), '--out', str(out), '--json', str(rep),
                          '--no-plots']) == 0
    report = json.loads(rep.read_text())
    entry = report['joints']['Achse 2']
    assert entry['method'] == 'samples' and not entry['degenerate']
    assert report['torque_kinds'] == {'bag': 'friction'}
    j = load_friction_map(out).joints[0]          # keyed by the bag's name
    assert j.coulomb_positive == pytest.approx(TRUTH['coulomb_positive'], rel=0.05)
    assert j.offset == pytest.approx(TRUTH['offset'], abs=0.05)
    vv = np.linspace(0.05, 0.8, 50)
    np.testing.assert_allclose(j.parametric(np.r_[vv, -vv]), truth_torque(np.r_[vv, -vv]),
                               atol=0.1)
    # the map as the controller evaluates it (polynomials inside valid_range, if kept) stays
    # within 5 % + 0.05 N m of the truth over the whole valid range
    lo, hi = j.valid_range
    vv = np.geomspace(lo, hi, 500)
    vv = np.r_[vv, -vv]
    assert np.all(np.abs(j.torque(vv) - truth_torque(vv))
                  <= 0.05 * np.abs(truth_torque(vv)) + 0.05)
    # a name mapping onto the model's joint, and a selection
    out2 = tmp_path / 'map2.yaml'
    assert identify.main(['--bag', str(bag), '--out', str(out2), '--no-plots',
                          '--map-joint', 'Achse 2:joint_2', '--joints', 'joint_2']) == 0
    assert list(load_friction_map(out2).joint_names) == ['joint_2']
    # unknown names never crash: one line naming the bag and the names found
    capsys.readouterr()
    assert identify.main(['--bag', str(bag), '--out', str(tmp_path / 'x.yaml'), '--json',
                          str(rep), '--joints', 'joint_1']) == 1
    err = capsys.readouterr().err
    assert 'bag: no joint joint_1; joints found: Achse 2' in err
    assert json.loads(rep.read_text())['exit_code'] == 1
    # total torque of a foreign robot: refused with the reason and the way out
    assert identify.main(['--bag', str(bag), '--out', str(tmp_path / 'x.yaml'),
                          '--torque-kind', 'total']) == 1
    assert '--torque-kind friction' in capsys.readouterr().err


def test_cli_degenerate_fit_never_exits_0(tmp_path, rng, capsys):
    t = np.cumsum(rng.uniform(1e-3, 13e-3, 4000))
    v = 0.5 * np.sin(0.8 * t)
    src = _csv(tmp_path / 'l.csv', t, {'q': v, 'qd': v,
                                       'tf': -0.3 * v + 0.5 * rng.standard_normal(len(v))})
    bag = tmp_path / 'bag'
    assert import_log.main([str(src), '--out', str(bag), '--time-column', 'time',
                            '--joint', 'j:q:qd:tf']) == 0
    out, rep = tmp_path / 'map.yaml', tmp_path / 'r.json'
    assert identify.main(['--bag', str(bag), '--out', str(out), '--json', str(rep),
                          '--no-plots']) == 1
    data = yaml.safe_load(out.read_text())['friction_map']['joints']['j']
    assert data['degenerate'] is True and data['degenerate_reason']
    with pytest.raises(FrictionMapError, match='degenerate'):
        load_friction_map(out)
    report = json.loads(rep.read_text())
    assert report['joints']['j']['degenerate'] and report['exit_code'] == 1
    assert 'DEGENERATE' in capsys.readouterr().out


def test_cli_slow_log_gets_a_map_and_an_absolute_floor_refuses(tmp_path, rng, capsys):
    """Top speed 0.003 rad/s (issue 27: with the old absolute v_min = 0.01 rad/s no map):
    v_min is relative to the top speed by default and the report says which was used; an
    absolute floor above the data refuses with the joint, the threshold and the speeds."""
    t = np.cumsum(rng.uniform(1e-3, 13e-3, 2000))
    v = 0.003 * np.sin(t)
    src = _csv(tmp_path / 'l.csv', t, {'q': v, 'qd': v, 'tf': truth_torque(v)})
    bag = tmp_path / 'bag'
    assert import_log.main([str(src), '--out', str(bag), '--time-column', 'time',
                            '--joint', 'slow:q:qd:tf']) == 0
    rep = tmp_path / 'r.json'
    assert identify.main(['--bag', str(bag), '--out', str(tmp_path / 'm.yaml'), '--json',
                          str(rep), '--no-plots']) == 0
    entry = json.loads(rep.read_text())['joints']['slow']
    assert entry['fit']['v_min'] == pytest.approx(0.02 * 0.003, rel=0.01)
    assert 'top speed' in entry['fit']['v_min_rule']
    j = load_friction_map(tmp_path / 'm.yaml').joints[0]
    lo, hi = j.valid_range
    vv = np.geomspace(lo, hi, 50)
    vv = np.r_[vv, -vv]
    np.testing.assert_allclose(j.torque(vv), truth_torque(vv), atol=0.01)
    capsys.readouterr()
    assert identify.main(['--bag', str(bag), '--out', str(tmp_path / 'm2.yaml'), '--json',
                          str(rep), '--no-plots', '--v-min', '0.01']) == 1
    err = capsys.readouterr()
    assert 'slow: 0 samples above v_min = 0.01 rad/s' in err.out + err.err
    report = json.loads(rep.read_text())
    assert report['exit_code'] == 1 and 'v_min' in report['joints']['slow']['error']
    assert not (tmp_path / 'm2.yaml').exists()


def test_total_torque_through_the_model_with_mapped_names(tmp_path, rng, model):
    """Total torque of our robot under other names: the rigid-body part (irb_description's
    inverse dynamics on the logged motion) is subtracted, q_dd estimated from the speeds."""
    n = 30000
    t = np.cumsum(rng.uniform(1e-3, 13e-3, n))
    w = np.array([1.1, 0.9, 1.3])
    amp = np.array([0.5, 0.4, 0.45])
    q = np.array([0.0, 0.4, -0.6]) + amp * np.sin(np.outer(t, w))
    qd = amp * w * np.cos(np.outer(t, w))
    qdd = -amp * w * w * np.sin(np.outer(t, w))
    tau = np.array([model.inverse_dynamics(a, b, c) for a, b, c in zip(q, qd, qdd)])
    tau[:, 1] += truth_torque(qd[:, 1])
    tau[:, 0] += truth_torque(qd[:, 0])
    tau[:, 2] += truth_torque(qd[:, 2])
    tau += 0.05 * rng.standard_normal(tau.shape)
    cols = {}
    for k in range(3):
        cols.update({f'q{k}': q[:, k], f'v{k}': qd[:, k], f't{k}': tau[:, k]})
    src = _csv(tmp_path / 'l.csv', t, cols)
    bag = tmp_path / 'bag'
    assert import_log.main([str(src), '--out', str(bag), '--time-column', 'time',
                            '--torque-kind', 'total']
                           + sum((['--joint', f'A{k + 1}:q{k}:v{k}:t{k}'] for k in range(3)),
                                 [])) == 0
    out, rep = tmp_path / 'map.yaml', tmp_path / 'r.json'
    args = ['--bag', str(bag), '--out', str(out), '--json', str(rep), '--no-plots',
            '--joints', 'joint_2']
    assert identify.main(args) == 1                       # total torque, unknown names
    args += sum((['--map-joint', f'A{k + 1}:joint_{k + 1}'] for k in range(3)), [])
    assert identify.main(args) == 0
    j = load_friction_map(out).joints[0]
    assert json.loads(rep.read_text())['joints']['joint_2']['method'] == 'samples'
    assert j.coulomb_positive == pytest.approx(TRUTH['coulomb_positive'], rel=0.05)
    assert j.coulomb_negative == pytest.approx(TRUTH['coulomb_negative'], rel=0.05)
    assert j.viscous == pytest.approx(TRUTH['viscous'], rel=0.05)
    assert j.offset == pytest.approx(TRUTH['offset'], abs=0.05)


@pytest.fixture(scope='module')
def sweep_bags(model, tmp_path_factory):
    from irb_identification.offline_sim import SimConfig, run_experiments
    out = tmp_path_factory.mktemp('sweeps')
    speeds = [0.03, 0.06, 0.1, 0.2, 0.4, 0.7, 1.0, 1.5]
    return run_experiments(model, model.friction, [2], speeds, out,
                           config=SimConfig(velocity_noise=0.002, effort_noise=0.5, seed=3),
                           log=lambda s: None)


@pytest.mark.slow
def test_sweeps_choose_eq48_and_the_samples_fit_agrees(sweep_bags, model, tmp_path):
    """Sweep bags: auto picks eq. 4.8; the samples method (forced) on the same bags gives
    the same Coulomb and viscous within the two fits' intervals."""
    bags = sum((['--bag', str(b)] for b in sweep_bags), [])
    a, b = tmp_path / 'a.json', tmp_path / 'b.json'
    assert identify.main(bags + ['--out', str(tmp_path / 'a.yaml'), '--json', str(a),
                                 '--no-plots', '--joints', 'joint_3']) == 0
    assert identify.main(bags + ['--out', str(tmp_path / 'b.yaml'), '--json', str(b),
                                 '--no-plots', '--joints', 'joint_3', '--method',
                                 'samples']) == 0
    sw = json.loads(a.read_text())['joints']['joint_3']
    sa = json.loads(b.read_text())['joints']['joint_3']
    assert sw['method'] == 'sweep' and sa['method'] == 'samples'
    truth = model.friction.joints[2]
    for key in ('coulomb', 'viscous'):
        diff = abs(sw[key] - sa[key])
        assert diff <= sw['ci95'][key] + sa['ci95'][key], (key, sw[key], sa[key])
        assert sa[key] == pytest.approx(getattr(truth, key), rel=0.05), key
    # the plant has no asymmetry and no offset: the samples fit must not invent them
    assert abs(sa['coulomb_positive'] - sa['coulomb_negative']) < 0.05 * sa['coulomb'] + (
        sa['ci95']['coulomb_positive'] + sa['ci95']['coulomb_negative'])
