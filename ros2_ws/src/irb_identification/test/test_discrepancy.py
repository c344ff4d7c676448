"""Discrepancy workflow: every plant effect hidden in the data is named and its held-out gap
shrinks; clean data gives 'none'. The workflow sees only the bags and the nominal model file
(irb_control's plant friction map, i.e. a correctly identified map, without effects)."""
import json
import math

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose

plant_mod = pytest.importorskip('irb_control.plant')
from irb_control.plant_effects import (EFFECT_NAMES, EffectsRuntime,  # noqa: E402
                                       load_plant_effects, moderate_effect)
from irb_description.friction import load_friction_map  # noqa: E402

from irb_identification import discrepancy, excite  # noqa: E402
from irb_identification.discrepancy_core.bagdata import (decode_points,  # noqa: E402
                                                         encode_points, read_run)
from irb_identification.discrepancy_core.excitation import (load_plan,  # noqa: E402
                                                            run_plan, write_runs)
from irb_identification.discrepancy_core.library import contribution, pool  # noqa: E402
from irb_identification.discrepancy_core.residuals import prepare_run  # noqa: E402
from irb_identification.discrepancy_core.selection import tau_int  # noqa: E402
from irb_identification.discrepancy_core.workflow import (WorkflowConfig,  # noqa: E402
                                                          run_workflow)

PLAN = load_plan(discrepancy.default_config_path().parent / 'excitation.yaml', 'short')
CONFIG = WorkflowConfig(n_boot=20)


@pytest.fixture(scope='module')
def plant_yaml():
    return plant_mod.default_plant_yaml()


@pytest.fixture(scope='module')
def plant_map(model, plant_yaml):
    return load_friction_map(plant_yaml, model.joint_names)


def make_bags(model, plant_map, tmp_path, effect=None, seed=1, scale=1.0):
    fx = moderate_effect(effect, scale) if effect else None
    runs = run_plan(model, PLAN, plant_map, plant_map, fx, seed=seed)
    return write_runs(runs, tmp_path / 'bags', model.joint_names)


def test_point_stamped_round_trip():
    t_ns = np.array([1_700_000_000_010_000_000, 1_700_000_000_020_000_000])
    p = np.array([[0.6, 0.1, 0.13], [0.61, -0.2, 0.5]])
    t, q = decode_points(encode_points(t_ns, p), t_ns)
    assert_allclose(t, t_ns * 1e-9)
    assert_allclose(q, p)


def test_tau_int_of_white_and_smoothed_noise(rng):
    x = rng.standard_normal(20000)
    assert tau_int(x) < 1.2
    smooth = np.convolve(x, np.ones(25) / 25, 'same')
    assert 15 < tau_int(smooth) < 35          # ~ window length for a boxcar


@pytest.mark.parametrize('name', ['torque_offset', 'cogging', 'viscous_temperature_drift',
                                  'stribeck', 'coulomb_asymmetry', 'viscous_nonlinear'])
def test_library_contribution_equals_the_plant_equation(model, plant_map, name, rng):
    """Oracle: the library's prediction of a torque effect is the plant's tau_x."""
    from irb_identification.discrepancy_core.library import Pooled
    fx = moderate_effect(name)
    block = fx.get(name)
    n = 200
    q = rng.uniform(-1, 1, (n, 3))
    qd = rng.uniform(-1.0, 1.0, (n, 3))
    t = rng.uniform(0, 60, n)
    z3, z0 = np.zeros((n, 3)), np.zeros(0)
    P = Pooled(t, q, qd, z3, z3, np.ones((n, 3), bool), np.zeros(n, int), np.empty((0, 3)),
               np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3, 3)), z0.astype(int),
               np.empty((0, 3)), np.empty((0, 3)), np.empty((1, 0, 3)), np.zeros(1),
               z0.astype(int), np.array([j.stribeck_velocity for j in plant_map.joints]), {})
    _, pred = contribution(name, block, P)
    rt = EffectsRuntime(fx, P.v_s, 0.004032, 5)
    if name == 'stribeck':     # a dry-level change: sign(v) times the added level
        want = np.sign(qd) * (np.array([rt.dry_level(v.tolist(), [0, 0, 0]) for v in qd]))
    else:
        want = np.array([rt.extra_torque(a.tolist(), b.tolist(), c)
                         for a, b, c in zip(q, qd, t)])
    assert_allclose(pred, want, rtol=1e-9, atol=1e-9)


def test_residuals_of_clean_data_are_small(model, plant_map, tmp_path):
    bags = make_bags(model, plant_map, tmp_path)
    ch = [prepare_run(read_run(b, model.joint_names), model, plant_map) for b in bags]
    P = pool(ch, model, plant_map)
    rms = np.sqrt(np.mean(P.r[P.mask.all(axis=1)] ** 2, axis=0))
    assert np.all(rms < 0.6), rms                             # N m, against 10-300 N m
    tcp = np.sqrt(np.mean(np.sum(P.r_tcp**2, axis=1)))
    assert tcp < 1e-4, tcp                                    # 37 um noise per axis
    assert np.abs(P.r_cmd).max() < 0.02           # effort = cmd 4 samples back (stamp rounding)


@pytest.mark.parametrize('effect', list(EFFECT_NAMES) + ['none'])
def test_hidden_effect_is_named_and_gap_shrinks(model, plant_map, plant_yaml, tmp_path, effect):
    bags = make_bags(model, plant_map, tmp_path, None if effect == 'none' else effect)
    res = run_workflow(bags, plant_yaml, CONFIG, model=model)
    r = res.report
    ranking = [(c['effect'], round(c['delta_bic'], 1)) for c in r['candidates'][:3]]
    assert r['effect'] == effect, ranking
    if effect == 'none':
        assert r['heldout_reduction'] is None and r['parameters'] == {}
        return
    assert r['confidence'] >= 0.6
    assert r['heldout_reduction'] >= 0.5, (r['rms_before'], r['rms_after'])
    assert r['candidates'][0]['effect'] == effect


def test_cli_end_to_end(model, plant_yaml, tmp_path):
    """excite -> bags -> discrepancy -> report.json, plots, an updated model the plant loads."""
    bags = tmp_path / 'bags'
    assert excite.main(['--out', str(bags), '--effect', 'torque_offset', '--seed', '3']) == 0
    out = tmp_path / 'out'
    args = sum((['--bag', str(b)] for b in sorted(bags.iterdir())), [])
    assert discrepancy.main(args + ['--model', str(plant_yaml), '--out', str(out)]) == 0
    rep = json.loads((out / 'report.json').read_text())
    for key in ('effect', 'joints', 'parameters', 'confidence', 'rms_before', 'rms_after',
                'candidates', 'updated_model'):
        assert key in rep
    assert rep['effect'] == 'torque_offset' and rep['joints'] == [1, 2, 3]
    offset = rep['parameters']['offset_nm']
    lo, hi = offset['ci95']
    for j, truth in enumerate([4.0, 4.0, 2.0]):
        assert lo[j] <= truth <= hi[j] or math.isclose(offset['value'][j], truth, rel_tol=0.05)
    for f in rep['plots']:
        assert (out / f).stat().st_size > 1000
    assert (out / 'report.md').read_text().startswith('# Model-discrepancy report')
    upd = rep['updated_model']
    fx = load_plant_effects(upd)
    assert fx.names() == ['torque_offset']
    fm, pf = plant_mod.load_plant_friction(upd, model.joint_names)
    plant = plant_mod.Plant(model, pf, plant_mod.PlantConfig(), fx)
    plant.command(model.gravity(plant.state.q))
    plant.step()
    # a second pass with the updated model finds nothing left
    out2 = tmp_path / 'out2'
    assert discrepancy.main(args + ['--model', upd, '--out', str(out2), '--no-plots']) == 0
    assert json.loads((out2 / 'report.json').read_text())['effect'] == 'none'
    assert yaml.safe_load(open(upd))['friction_map']['joints']


def test_cli_bad_input(tmp_path, plant_yaml):
    assert discrepancy.main(['--bag', str(tmp_path / 'missing'), '--model', str(plant_yaml),
                             '--out', str(tmp_path / 'o')]) == 1
    assert not (tmp_path / 'o').exists()        # a refusal leaves no empty report folder
    empty = tmp_path / 'empty_bag'
    empty.mkdir()
    assert discrepancy.main(['--bag', str(empty), '--model', str(plant_yaml),
                             '--out', str(tmp_path / 'o2' / 'deeper')]) == 1
    assert not (tmp_path / 'o2').exists()
    assert excite.main(['--out', str(tmp_path / 'x'), '--effect', 'gremlins']) == 1
