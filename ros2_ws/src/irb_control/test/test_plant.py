"""Plant core: dynamics against the model, stick-slip friction, delay, brakes, sensors."""
import numpy as np
import pytest
from numpy.testing import assert_allclose

from irb_control.plant import (Plant, PlantConfig, PlantFriction, default_plant_yaml,
                               load_plant_friction)


@pytest.fixture
def friction(model):
    return load_plant_friction(default_plant_yaml(), model.joint_names)[1]


def no_friction():
    z = np.zeros(3)
    return PlantFriction(z, z, np.ones(3), z)


def test_plant_yaml_differs_from_nominal(model, friction):
    nominal = PlantFriction.from_map(model.friction)
    assert not np.allclose(friction.coulomb, nominal.coulomb)
    assert not np.allclose(friction.viscous, nominal.viscous)


def test_free_motion_matches_model_forward_dynamics(model):
    """Without friction and without delay effects, one step equals integrating ABA."""
    cfg = PlantConfig(delay_samples=1, position_noise_rad=0, velocity_noise_rad_s=0,
                      encoder_resolution_rad=0, substeps=50)
    p = Plant(model, no_friction(), cfg)
    q0 = np.array([0.2, 0.7, 0.1])
    p.reset(q0)
    tau = model.gravity(q0) + np.array([5.0, -3.0, 2.0])
    p.command(tau)
    p.step()          # delay 1: this period still braked
    assert p.braked
    p.step()          # now the command acts for one period
    qdd = model.forward_dynamics(q0, np.zeros(3), tau)
    T = cfg.period_s
    assert_allclose(p.state.qd, qdd * T, rtol=2e-2, atol=1e-6)
    assert_allclose(p.state.q, q0 + 0.5 * qdd * T**2, rtol=5e-2, atol=1e-8)


def test_stiction_holds_below_static_and_slides_above(model, friction):
    p = Plant(model, friction, PlantConfig(delay_samples=1))
    q0 = np.array(p.config.initial_q)
    g = model.gravity(q0)
    for _ in range(250):   # 1 s, net torque 80 % of the static level on every joint
        p.command(g + 0.8 * friction.static)
        p.step()
    assert not p.braked
    assert_allclose(p.state.qd, 0.0, atol=1e-9)     # exactly at rest, no chattering
    assert_allclose(p.state.q, q0, atol=1e-8)
    p.reset(q0)
    extra = np.array([friction.static[0] + 10.0, 0.0, 0.0])
    for _ in range(1500):    # 6 s, about 8 time constants M11 / F_v
        p.command(model.gravity(p.state.q) + extra)
        p.step()
    # joint 1 reaches the steady speed where viscous + Coulomb balance the excess torque
    v_ss = (extra[0] - friction.coulomb[0]) / friction.viscous[0]
    assert p.state.qd[0] == pytest.approx(v_ss, rel=0.05)
    assert_allclose(p.friction_torque[0], friction.steady_torque(p.state.qd)[0], rtol=0.02)


def test_delay_is_three_samples(model):
    cfg = PlantConfig(delay_samples=3)
    p = Plant(model, no_friction(), cfg)
    q0 = np.array(cfg.initial_q)
    g = model.gravity(q0)
    applied = []
    for k in range(6):
        p.command(g + k)    # command k answers measurement k
        p.step()
        applied.append(p.applied.copy())
    # the command answering measurement k acts over [t_{k+3}, t_{k+4})
    assert p.braked is False
    assert_allclose(applied[3], g + 0.0)
    assert_allclose(applied[5], g + 2.0)
    assert np.all(applied[2] == 0.0)


def test_command_timeout_engages_brakes(model, friction):
    cfg = PlantConfig(command_timeout_s=0.02)
    p = Plant(model, friction, cfg)
    q0 = np.array(cfg.initial_q)
    for _ in range(10):
        p.command(model.gravity(p.state.q) + np.array([60.0, 0.0, 0.0]))
        p.step()
    assert not p.braked and abs(p.state.qd[0]) > 0
    for _ in range(10):
        p.step()    # no more commands
    assert p.braked
    assert_allclose(p.state.qd, 0.0)
    assert_allclose(p.applied, 0.0)
    q_held = p.state.q.copy()
    for _ in range(20):
        p.step()
    assert_allclose(p.state.q, q_held)
    assert any('brakes engaged' in msg for _, msg in p.events)
    assert not np.allclose(q_held, q0)


def test_brakes_latch_until_the_error_is_cleared(model, friction):
    # issue 14, defect 8: the simulator applied the last command for 50 ms and released its
    # brakes on the next command, unlike the latching axis computer
    cfg = PlantConfig(command_timeout_s=0.02)
    p = Plant(model, friction, cfg)
    hold = model.gravity(p.state.q)
    for _ in range(5):
        p.command(hold)
        p.step()
    assert not p.braked and not p.error
    for _ in range(8):
        p.step()                                   # the controller went silent
    assert p.braked and 'no command' in p.error
    q_held = p.state.q.copy()
    for _ in range(10):                            # commands again: ignored, still braked
        p.command(hold + 50.0)
        p.step()
    assert p.braked and p.rejected_latched == 10
    assert_allclose(p.state.q, q_held)
    assert_allclose(p.applied, 0.0)
    assert 'no command' in p.clear_error() and not p.error
    assert p.braked                                # the reset alone does not release
    for _ in range(cfg.delay_samples + 1):         # a command releases them (after the delay)
        p.command(hold)
        p.step()
    assert not p.braked


def test_invalid_command_is_ignored(model, friction):
    p = Plant(model, friction)
    p.command(np.array([np.nan, 0.0, 0.0]))
    p.command(np.array([1.0, 2.0]))
    for _ in range(5):
        p.step()
    assert p.braked and np.all(np.isfinite(p.state.q))
    assert sum('rejected' in m for _, m in p.events) == 2


def test_encoder_and_camera(model, friction):
    cfg = PlantConfig(encoder_resolution_rad=1e-5, position_noise_rad=0.0)
    p = Plant(model, friction, cfg)
    y = p.measure()
    assert_allclose(y.q / 1e-5, np.round(y.q / 1e-5), atol=1e-6)
    assert np.max(np.abs(y.q - p.state.q)) <= 0.5e-5 + 1e-12
    for _ in range(250):     # ~1 s, braked
        p.step()
    cam = p.take_camera()
    t = np.array([c[0] for c in cam])
    pts = np.array([c[1] for c in cam])
    assert len(cam) == pytest.approx(1.008 / 0.01, abs=1.5)
    assert_allclose(np.diff(t), 0.01, atol=1e-9)
    err = pts - model.fk(p.state.q)
    assert np.std(err) == pytest.approx(37e-6, rel=0.25)
    assert p.take_camera() == []
