"""URDF generation, model_check and the installed layout."""
import json

import numpy as np
import pinocchio as pin
import pytest

from irb_description import generate_urdf as gen
from irb_description import model_check
from irb_description.params import load_dynamics, load_kinematics, urdf_path
from irb_description.urdf_gen import generate_urdf


def test_committed_urdf_is_generated_from_the_yaml():
    assert urdf_path().read_text() == generate_urdf(load_kinematics(), load_dynamics())
    assert gen.main(['--check']) == 0


def test_generate_urdf_check_detects_stale_file(tmp_path, capsys):
    stale = tmp_path / 'robot.urdf'
    stale.write_text('<robot/>')
    assert gen.main(['--check', '--output', str(stale)]) == 1
    assert gen.main(['--output', str(stale)]) == 0
    assert gen.main(['--check', '--output', str(stale)]) == 0


def test_urdf_has_six_joints_with_limits():
    full = pin.buildModelFromUrdf(str(urdf_path()))
    kin, dyn = load_kinematics(), load_dynamics()
    assert list(full.names)[1:] == [f'joint_{i}' for i in range(1, 7)]
    np.testing.assert_allclose(full.lowerPositionLimit, kin.lower)
    np.testing.assert_allclose(full.upperPositionLimit, kin.upper)
    np.testing.assert_allclose(np.degrees(full.velocityLimit),
                               [150, 160, 170, 320, 400, 450])
    np.testing.assert_allclose(full.effortLimit, dyn.torque_limit)


def test_model_check_json_reports_the_thesis_circle(capsys):
    assert model_check.main(['--json', '--periods', '10']) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['checks_failed'] == []
    assert out['circle']['path_length_m'] == pytest.approx(2 * np.pi * 0.15)
    run = out['runs'][0]
    assert run['q_max_deg'][0] == pytest.approx(np.degrees(np.arcsin(0.25)), abs=0.01)
    assert run['q_min_deg'][0] == pytest.approx(-run['q_max_deg'][0], abs=1e-6)
    assert 0 < run['energy_j'] < 1000


def test_model_check_refuses_unreachable_circle(capsys):
    assert model_check.main(['--center', '2', '0', '0', '--periods', '10']) == 1
    assert 'not usable' in capsys.readouterr().err
