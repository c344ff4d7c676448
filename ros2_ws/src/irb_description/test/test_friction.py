"""Friction maps: model, file schema, errors."""
import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from irb_description.friction import (FrictionMap, FrictionMapError, JointFriction,
                                      load_friction_map)


def test_nominal_map_follows_the_thesis_shape(model):
    fm = model.friction
    assert fm.joint_names == tuple(model.joint_names)
    v = np.linspace(0.05, 2.0, 20)
    tau = np.array([fm.torque(np.full(3, s)) for s in v])
    assert np.all(np.diff(tau[5:], axis=0) > 0)          # viscous growth at higher speed
    assert_allclose(fm.torque(-np.full(3, 0.7)), -fm.torque(np.full(3, 0.7)))
    # joint 3 about half of joints 1-2 (thesis §4.4)
    ratio = tau[:, 2] / tau[:, :2].mean(axis=1)
    assert np.all((ratio > 0.35) & (ratio < 0.65))


def test_parametric_formula():
    j = JointFriction(coulomb=10.0, static=15.0, stribeck_velocity=0.1, viscous=2.0)
    assert j.torque(0.0) == 0.0
    assert j.torque(1e-9) == pytest.approx(15.0, rel=1e-6)
    assert j.torque(0.1) == pytest.approx(10 + 5 * np.exp(-1) + 0.2)
    assert j.torque(-3.0) == pytest.approx(-(10 + 6.0), rel=1e-9)


def test_polynomials_used_inside_valid_range_only():
    j = JointFriction(1.0, 1.0, 0.1, 1.0, valid_range=(0.1, 1.0),
                      polynomial_positive=(5.0, 0.0), polynomial_negative=(-7.0,))
    assert j.torque(0.5) == 5.0
    assert j.torque(-0.5) == -7.0
    assert j.torque(2.0) == pytest.approx(3.0)          # parametric outside the range


def test_save_load_round_trip(tmp_path, model):
    fm = FrictionMap(('joint_1', 'joint_2', 'joint_3'), tuple(
        JointFriction(1.0 + i, 2.0 + i, 0.05, 3.0, (0.02, 2.0), (0.1, 0.2), (-0.1, 0.2),
                      {'coulomb': 0.1}) for i in range(3)), 'test')
    path = tmp_path / 'map.yaml'
    fm.save(path)
    back = load_friction_map(path, model.joint_names)
    assert back == fm
    v = np.array([0.3, -0.4, 1.5])
    assert_allclose(back.torque(v), fm.torque(v))


def test_casadi_torque_matches_numpy_away_from_zero(model):
    v = ca.SX.sym('v', 3)
    f = ca.Function('f', [v], [model.friction.casadi_torque(v, smoothing=1e-3)])
    for s in (-1.3, -0.2, 0.05, 0.8):
        x = np.array([s, -s, 0.5 * s])
        assert_allclose(np.asarray(f(x)).ravel(), model.friction.torque(x), atol=1e-6)


@pytest.mark.parametrize('text, reason', [
    ('not: a map', 'not a friction map'),
    ('friction_map: {version: 2, joints: {}}', 'version'),
    ('friction_map: {joints: {joint_1: {coulomb: 1, viscous: 1}}}', 'no entry'),
    ('friction_map: {joints: {joint_1: {coulomb: x, viscous: 1}, joint_2: {}, joint_3: {}}}',
     'joint_1'),
    ('[1, 2', r'not YAML: .* at line 1, column 6'),
    ('- 1\n- 2\n', 'mapping'),
])
def test_bad_files_give_clear_errors(tmp_path, model, text, reason):
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    with pytest.raises(FrictionMapError, match=reason):
        load_friction_map(path, model.joint_names)


def test_missing_file(tmp_path):
    with pytest.raises(FrictionMapError, match='does not exist'):
        load_friction_map(tmp_path / 'nope.yaml')


def _asym():
    return JointFriction(coulomb=10.0, static=14.0, stribeck_velocity=0.1, viscous=2.0,
                         valid_range=(0.02, 2.0), coulomb_positive=11.0, coulomb_negative=9.0,
                         offset=-0.5)


def test_asymmetric_coulomb_and_offset_formula():
    j = _asym()
    hump = 4.0 * np.exp(-1.0)
    # written out per sign, independently of the implementation's where/sign form
    assert j.torque(0.1) == pytest.approx(-0.5 + 11.0 + hump + 0.2)
    assert j.torque(-0.1) == pytest.approx(-0.5 - 9.0 - hump - 0.2)
    assert j.torque(0.0) == pytest.approx(-0.5)
    assert j.torque(5.0) == pytest.approx(-0.5 + 11.0 + 10.0)


def test_asymmetric_map_round_trip_and_casadi(tmp_path):
    names = ('a', 'b')
    fm = FrictionMap(names, (_asym(), JointFriction(3.0, 3.0, 0.05, 1.0)), 'test')
    path = tmp_path / 'map.yaml'
    fm.save(path)
    text = path.read_text()
    assert 'coulomb_positive' in text and 'offset' in text
    back = load_friction_map(path)
    assert back == fm
    assert 'coulomb_positive' not in str(back.to_dict()['friction_map']['joints']['b'])
    v = ca.SX.sym('v', 2)
    f = ca.Function('f', [v], [fm.casadi_torque(v, smoothing=1e-3)])
    for s in (-1.3, -0.2, 0.05, 0.8):
        x = np.array([s, -0.5 * s])
        assert_allclose(np.asarray(f(x)).ravel(), fm.torque(x), atol=1e-6)
    scaled = fm.scaled(2.0)
    assert_allclose(scaled.torque(np.array([0.3, -0.3])), 2 * fm.torque(np.array([0.3, -0.3])))


def test_old_map_without_new_fields_loads_as_symmetric(tmp_path):
    path = tmp_path / 'old.yaml'
    path.write_text('friction_map:\n  version: 1\n  joints:\n    j:\n      coulomb: 5.0\n'
                    '      static: 6.0\n      stribeck_velocity: 0.05\n      viscous: 1.0\n')
    j = load_friction_map(path).joints[0]
    assert j.coulomb_positive == j.coulomb_negative == 5.0 and j.offset == 0.0
    assert j.symmetric
    assert j.torque(-0.7) == -j.torque(0.7)


def test_per_sign_levels_only_give_their_mean(tmp_path):
    path = tmp_path / 'sign.yaml'
    path.write_text('friction_map:\n  joints:\n    j: {coulomb_positive: 4.0, '
                    'coulomb_negative: 2.0, viscous: 1.0, offset: 0.25}\n')
    j = load_friction_map(path).joints[0]
    assert j.coulomb == 3.0 and j.static == 3.0
    assert j.torque(1.0) == pytest.approx(4.0 + 1.0 + 0.25)
    assert j.torque(-1.0) == pytest.approx(-2.0 - 1.0 + 0.25)


def test_degenerate_joint_is_refused_unless_asked(tmp_path):
    bad = JointFriction(1.0, 1.0, 0.05, 1.0, degenerate_reason='v_s beyond the data')
    fm = FrictionMap(('j',), (bad,), 'test')
    path = tmp_path / 'deg.yaml'
    fm.save(path)
    assert 'degenerate: true' in path.read_text()
    with pytest.raises(FrictionMapError, match='degenerate.*v_s beyond the data'):
        load_friction_map(path)
    assert load_friction_map(path, allow_degenerate=True).joints[0].degenerate


def test_per_sign_static_levels():
    """Identified maps: one breakaway level F_s for both signs, Coulomb per sign."""
    j = JointFriction(coulomb=10.0, static=14.0, stribeck_velocity=0.1, viscous=0.0,
                      coulomb_positive=11.0, coulomb_negative=9.0, static_positive=14.0,
                      static_negative=14.0, offset=0.0)
    assert j.torque(1e-6) == pytest.approx(14.0)
    assert j.torque(-1e-6) == pytest.approx(-14.0)
    assert j.torque(0.1) == pytest.approx(11.0 + 3.0 * np.exp(-1))
    assert j.torque(-0.1) == pytest.approx(-(9.0 + 5.0 * np.exp(-1)))
    v = ca.SX.sym('v', 1)
    f = ca.Function('f', [v], [FrictionMap(('j',), (j,)).casadi_torque(v)])
    for s in (-0.3, -0.05, 0.05, 0.3):
        assert float(f(s)) == pytest.approx(float(j.torque(s)), abs=1e-6)
