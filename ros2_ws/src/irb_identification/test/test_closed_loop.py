"""Closed-loop check: identified map as the controller's friction feed-forward on the thesis
circle improves the path error within 10 % of what the true plant's map achieves.

Uses irb_control's offline closed loop (Plant + PdPlusController); skipped where irb_control
is not installed. Experiments run on irb_control's plant friction (config/plant.yaml), which
differs from the nominal map on purpose.
"""
import numpy as np
import pytest
from irb_description.friction import load_friction_map

from irb_identification import identify
from irb_identification.offline_sim import SimConfig, run_experiments
from irb_identification.profiles import DEFAULT_SPEEDS

closed_loop = pytest.importorskip('irb_control.closed_loop')
plant_mod = pytest.importorskip('irb_control.plant')
pytestmark = pytest.mark.slow


def rms_path_error(model, friction_mode, friction_file=None) -> float:
    plant, ctrl = closed_loop.build_default(friction_mode, friction_file, duration_s=10.0,
                                            model=model)
    res = closed_loop.simulate_closed_loop(plant, ctrl, 11.0)
    e = res.path_error_camera()
    return float(np.sqrt(np.mean(e**2)))


def test_identified_feed_forward_matches_true_plant(model, tmp_path):
    plant_yaml = plant_mod.default_plant_yaml()
    truth = load_friction_map(plant_yaml, model.joint_names)
    bags = run_experiments(model, truth, [0, 1, 2], list(DEFAULT_SPEEDS), tmp_path,
                           config=SimConfig(velocity_noise=0.002, effort_noise=0.5, seed=5),
                           log=lambda s: None)
    out = tmp_path / 'identified.yaml'
    assert identify.main(sum((['--bag', str(b)] for b in bags), [])
                         + ['--out', str(out), '--no-plots']) == 0
    e_none = rms_path_error(model, 'none')
    e_true = rms_path_error(model, 'file', plant_yaml)
    e_ident = rms_path_error(model, 'file', out)
    gain_true, gain_ident = e_none - e_true, e_none - e_ident
    assert gain_true > 0
    assert abs(gain_ident - gain_true) <= 0.1 * gain_true, (e_none, e_true, e_ident)
