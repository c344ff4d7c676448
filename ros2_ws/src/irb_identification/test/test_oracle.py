"""Oracle: simulated plant with known friction -> bags -> identify -> the friction it was given.

Plant: irb_description's model (pinocchio ABA) with the nominal friction map as truth, PD +
inverse-dynamics tracking of eq. 4.1, measurement noise. Every bag is read back by rosbags and
by mcap + mcap_ros2 with CRCs validated.
"""
import json

import numpy as np
import pytest
from irb_description.friction import load_friction_map

from irb_identification import identify
from irb_identification.offline_sim import SimConfig, run_experiments
from irb_identification.profiles import DEFAULT_SPEEDS

pytestmark = pytest.mark.slow


@pytest.fixture(scope='module')
def experiment_bags(model, tmp_path_factory):
    out = tmp_path_factory.mktemp('oracle')
    cfg = SimConfig(velocity_noise=0.002, effort_noise=0.5, seed=7)
    bags = run_experiments(model, model.friction, [0, 1, 2], list(DEFAULT_SPEEDS), out,
                           config=cfg, log=lambda s: None)
    return out, bags


def test_every_bag_reads_back(experiment_bags, bag_check):
    _, bags = experiment_bags
    assert len(bags) == 3 * len(DEFAULT_SPEEDS)
    for bag in bags:
        counts = bag_check(bag, decode_limit=50)
        assert counts['/joint_states'] > 300


def test_identified_map_matches_truth(experiment_bags, model, tmp_path):
    _, bags = experiment_bags
    out = tmp_path / 'friction_map.yaml'
    args = sum((['--bag', str(b)] for b in bags), []) + [
        '--out', str(out), '--json', str(tmp_path / 'report.json')]
    assert identify.main(args) == 0
    fmap = load_friction_map(out, model.joint_names)       # the controller's/planner's loader
    report = json.loads((tmp_path / 'report.json').read_text())
    for name, truth, ident in zip(model.joint_names, model.friction.joints, fmap.joints):
        # parametric Coulomb and viscous within 5 % of the truth
        assert ident.coulomb == pytest.approx(truth.coulomb, rel=0.05), name
        assert ident.viscous == pytest.approx(truth.viscous, rel=0.05), name
        assert ident.ci95['coulomb'] > 0 and ident.ci95['viscous'] > 0
        # the map (polynomials inside the valid range) within 5 % over the sampled range
        lo, hi = ident.valid_range
        assert lo == pytest.approx(min(DEFAULT_SPEEDS), rel=0.05)
        assert hi == pytest.approx(max(DEFAULT_SPEEDS), rel=0.05)
        v = np.linspace(lo, hi, 1000)
        v = np.r_[v, -v]
        rel = np.abs(ident.torque(v) - truth.torque(v)) / np.abs(truth.torque(v))
        assert rel.max() < 0.05, f'{name}: map off by {100 * rel.max():.1f} %'
        assert ident.polynomial_positive is not None and ident.polynomial_negative is not None
        assert (out.parent / f'friction_map_{name}.png').stat().st_size > 10_000
        assert report['joints'][name]['speeds'] == len(DEFAULT_SPEEDS)


def test_partial_identification_and_bad_bags(experiment_bags, model, tmp_path, capsys):
    """Joint 3 from too few speeds, plus a corrupt and a missing bag: joints 1-2 still come
    out, the problems are named, exit code 2."""
    _, bags = experiment_bags
    n = len(DEFAULT_SPEEDS)
    j12 = bags[:2 * n]
    j3 = bags[2 * n:2 * n + 2]
    corrupt = tmp_path / 'corrupt'
    import shutil
    shutil.copytree(j3[0], corrupt)
    for f in corrupt.glob('*.mcap'):
        f.write_bytes(f.read_bytes()[:100])
    out = tmp_path / 'partial.yaml'
    args = sum((['--bag', str(b)] for b in [*j12, *j3, corrupt, tmp_path / 'missing']),
               []) + ['--out', str(out), '--no-plots']
    assert identify.main(args) == 2
    err = capsys.readouterr()
    assert 'corrupt' in err.err and 'does not exist' in err.err
    # joint 3 swept at 0.02 and 0.035 rad/s only: below 2 % of the fastest joint's top speed
    # it is reported as not moved on its own (issue 27's relative v_min), not fitted
    assert 'joint_3: not moved on its own' in err.out, err.out
    fmap = load_friction_map(out)
    assert list(fmap.joint_names) == ['joint_1', 'joint_2']
    assert identify.main(args[:-1] + ['--fill-nominal']) == 2
    full = load_friction_map(out, model.joint_names)
    assert 'not identified' in full.source and full.joints[2] == model.friction.joints[2]


def test_nothing_identifiable(tmp_path, capsys):
    assert identify.main(['--bag', str(tmp_path / 'none'), '--out',
                          str(tmp_path / 'x.yaml')]) == 1
    assert 'no usable bag' in capsys.readouterr().err
