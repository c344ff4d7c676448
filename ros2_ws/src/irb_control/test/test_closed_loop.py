"""Offline closed loop (no ROS): tracking on the thesis circle, friction feed-forward oracle."""
import numpy as np
import pytest
from numpy.testing import assert_allclose

from irb_control.closed_loop import (build_default, circle_distance, energy, polyline_distance,
                                     simulate_closed_loop)
from irb_control.pd_plus import MODE_HOLD, ControllerConfig, PdPlusController
from irb_control.plant import Plant
from irb_control.profiles import sine_trajectory


@pytest.fixture(scope='module')
def runs(model):
    """One 10 s circle per friction mode (each ~0.4 s of CPU)."""
    out = {}
    for mode in ('none', 'nominal', 'file'):
        plant, ctrl = build_default(mode, duration_s=10.0, model=model)
        out[mode] = simulate_closed_loop(plant, ctrl, 12.0)
    return out


def test_circle_is_tracked(runs, circle):
    r = runs['nominal']
    assert r.stop_reason == ''
    assert r.finished(), 'the controller must reach the end of the circle'
    assert 9.5 < r.t[-1] < 11.5                       # 0.5 s ramp + ~10 s circle
    th = r.theta[r.motion_mask()]
    assert th[-1] == pytest.approx(2 * np.pi, abs=0.03)
    err = r.path_error_camera()
    assert err.size > 900
    assert np.mean(err) < 1.5e-3 and np.max(err) < 3e-3   # [m]
    je = r.joint_error()[r.motion_mask()]
    assert np.nanmax(np.abs(je)) < 5e-3                # [rad]
    assert all(np.isfinite(r.tau_cmd).ravel())
    assert 50.0 < r.energy < 200.0                       # [J], about the planner's magnitude


def test_true_plant_feedforward_beats_no_feedforward(runs):
    """Oracle: with the plant's own friction as feed-forward the path error is much smaller
    than without feed-forward, and the nominal (wrong) map lies in between."""
    e = {k: np.mean(r.path_error_camera()) for k, r in runs.items()}
    assert e['file'] < 0.2 * e['none']
    assert e['nominal'] < 0.5 * e['none']
    assert e['file'] < e['nominal']


def test_energy_integral_matches_samples(runs):
    r = runs['file']
    e_samples = energy(r.t, r.tau_applied, r.qd)
    assert e_samples == pytest.approx(r.energy, rel=0.05)


def test_distance_helpers(circle):
    p = circle.point(np.array([0.0, 1.0, 2.0])) + np.array([0.0, 0.0, 0.003])
    assert_allclose(circle_distance(circle, p), 0.003, atol=1e-12)
    curve = circle.point(np.linspace(0, 2 * np.pi, 2000))
    assert_allclose(polyline_distance(curve, p), 0.003, atol=1e-6)


def test_time_driven_sine_tracks(model, circle):
    plant, _ = build_default('file', duration_s=10.0, model=model)
    q0 = np.array(plant.config.initial_q)
    traj = sine_trajectory(q0, 0, 0.5, amplitude=0.2)
    ctrl = PdPlusController(model, circle, ControllerConfig(),
                            _plant_map(plant, model))
    ctrl.set_time_trajectory(traj)
    r = simulate_closed_loop(plant, ctrl, traj.duration + 1.0)
    assert r.stop_reason == '' and r.finished()
    je = r.joint_error()[r.motion_mask()]
    assert np.nanmax(np.abs(je[:, 0])) < 3e-3
    assert np.nanmax(np.abs(r.qd[:, 0])) == pytest.approx(0.5, rel=0.05)


def _plant_map(plant: Plant, model):
    from irb_control.plant import default_plant_yaml
    from irb_description.friction import load_friction_map
    return load_friction_map(default_plant_yaml(), model.joint_names)


def test_stop_mid_path_brakes_the_plant(model):
    plant, ctrl = build_default('nominal', duration_s=10.0, model=model)
    r1 = simulate_closed_loop(plant, ctrl, 2.0)
    ctrl.stop('test')
    r2 = simulate_closed_loop(plant, ctrl, 0.5, enable=False)
    assert not r2.published.any()
    assert plant.braked
    assert_allclose(r2.qd[-10:], 0.0)
    assert any('brakes engaged' in m for _, m in r2.events)
    assert r1.mode[-1] != MODE_HOLD
