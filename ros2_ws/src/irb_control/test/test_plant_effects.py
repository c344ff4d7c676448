"""Plant effects (irb_control.plant_effects): schema, and each effect against physics."""
import math

import numpy as np
import pinocchio as pin
import pytest
import yaml
from numpy.testing import assert_allclose

from irb_control.closed_loop import build_default, simulate_closed_loop
from irb_control.plant import Plant, PlantConfig, default_plant_yaml, load_plant_friction
from irb_control.plant_effects import (EFFECT_NAMES, EffectsError, PlantEffects,
                                       load_plant_effects, moderate_effect, save_effects)

QUIET = PlantConfig(delay_samples=1, position_noise_rad=0.0, velocity_noise_rad_s=0.0,
                    encoder_resolution_rad=0.0, camera_noise_m=0.0)


@pytest.fixture
def friction(model):
    return load_plant_friction(default_plant_yaml(), model.joint_names)[1]


def hold(plant, model, extra=np.zeros(3), steps=100):
    """Command g(q) + extra for ``steps`` periods; returns the encoder samples."""
    out = []
    for _ in range(steps):
        plant.command(model.gravity(plant.state.q) + extra)
        plant.step()
        out.append(plant.measure())
    return out


def test_names_and_moderate_sizes_cover_design():
    assert EFFECT_NAMES == ('stribeck', 'coulomb_asymmetry', 'torque_offset',
                            'viscous_nonlinear', 'payload_mass', 'rotor_inertia',
                            'time_delay', 'cogging', 'backlash', 'joint_elasticity',
                            'viscous_temperature_drift')
    for name in EFFECT_NAMES:
        assert moderate_effect(name).names() == [name]


def test_yaml_round_trip_and_errors(tmp_path):
    fx = PlantEffects.from_dict({'torque_offset': {'offset_nm': [1.0, 2.0, 3.0]},
                                 'joint_elasticity': {'stiffness_nm_rad': ['.inf', 2e5, 1e5]},
                                 'time_delay': {'extra_delay_s': 0.002}})
    path = tmp_path / 'plant.yaml'
    plant_yaml = yaml.safe_load(default_plant_yaml().read_text())
    save_effects(fx, path, {'friction_map': plant_yaml['friction_map']})
    back = load_plant_effects(path)
    assert back.to_dict() == fx.to_dict()
    assert math.isinf(back.get('joint_elasticity').stiffness_nm_rad[0])
    assert not load_plant_effects(default_plant_yaml())       # no section: no effects
    with pytest.raises(EffectsError, match='unknown effect'):
        PlantEffects.from_dict({'gremlins': {}})
    with pytest.raises(EffectsError, match='unknown parameter'):
        PlantEffects.from_dict({'torque_offset': {'offset': 1.0}})
    with pytest.raises(EffectsError, match='3 values'):
        PlantEffects.from_dict({'torque_offset': {'offset_nm': [1.0, 2.0]}})
    with pytest.raises(EffectsError, match='> 0'):
        PlantEffects.from_dict({'cogging': {'period_rad': [0.1, 0.0, 0.1]}})


def test_no_effects_is_the_unchanged_plant(model):
    a, ctrl_a = build_default(duration_s=2.0, model=model)
    b, ctrl_b = build_default(duration_s=2.0, model=model)
    b = Plant(model, b.friction, b.config, PlantEffects())
    ra = simulate_closed_loop(a, ctrl_a, 1.0)
    rb = simulate_closed_loop(b, ctrl_b, 1.0)
    assert np.array_equal(ra.q, rb.q) and np.array_equal(ra.cam_p, rb.cam_p)


def test_torque_offset_breaks_stiction(model, friction):
    """An offset larger than the static level moves a joint that g(q) alone holds."""
    offset = np.array([0.0, 0.0, friction.static[2] + 10.0])
    p0 = Plant(model, friction, QUIET)
    p1 = Plant(model, friction, QUIET,
               PlantEffects.from_dict({'torque_offset': {'offset_nm': offset.tolist()}}))
    hold(p0, model, steps=120)
    hold(p1, model, steps=120)
    assert_allclose(p0.state.qd, 0.0, atol=1e-12)
    assert p1.state.qd[2] < -1e-3 and abs(p1.state.qd[0]) < 1e-9   # pushed backwards


def test_stribeck_raises_breakaway(model, friction):
    extra = np.array([0.0, 0.0, friction.static[2] + 2.0])
    p0 = Plant(model, friction, QUIET)
    p1 = Plant(model, friction, QUIET, PlantEffects.from_dict(
        {'stribeck': {'static_increase_nm': [0.0, 0.0, 5.0], 'velocity_rad_s': 0.1}}))
    hold(p0, model, extra, 120)
    hold(p1, model, extra, 120)
    assert p0.state.qd[2] > 1e-3          # nominal: slides
    assert p1.state.qd[2] == 0.0          # stronger Stribeck hump: still sticks


@pytest.mark.parametrize('name, params, expected', [
    ('coulomb_asymmetry', {'delta_nm': [3.0, 0, 0]}, lambda v, q, t: 3.0 * (1 - math.exp(
        -(v / 0.03) ** 2))),
    ('viscous_nonlinear', {'coefficient': [5.0, 0, 0], 'exponent': 1.5},
     lambda v, q, t: 5.0 * math.copysign(abs(v) ** 1.5, v)),
    ('cogging', {'amplitude_nm': [2.0, 0, 0], 'period_rad': 0.2, 'phase_rad': 0.5},
     lambda v, q, t: 2.0 * math.sin(2 * math.pi * q / 0.2 + 0.5)),
    ('viscous_temperature_drift', {'cold_extra_viscous_nms_rad': [8.0, 0, 0],
                                   'time_constant_s': 20.0},
     lambda v, q, t: 8.0 * math.exp(-t / 20.0) * v),
])
def test_extra_torque_formulas_and_effect_on_motion(model, friction, name, params, expected):
    """tau_x as documented, and one substep of the plant sees exactly -h M^-1 tau_x more."""
    fx = PlantEffects.from_dict({name: params})
    p1 = Plant(model, friction, QUIET, fx)
    for v, q, t in ((0.4, 0.13, 0.0), (-0.7, -0.31, 25.0), (0.01, 0.02, 3.0)):
        x = p1._fx.extra_torque([q, 0.9, 0.2], [v, 0.0, 0.0], t)
        assert_allclose(x[0], expected(v, q, t), rtol=1e-12, atol=1e-12)
        assert x[1:] == [0.0, 0.0]
    # motion: both plants moving at the same state with the same torque, one substep
    p0 = Plant(model, friction, QUIET)
    q0, v0 = np.array([0.13, 0.9, 0.2]), np.array([0.4, 0.3, -0.3])   # all joints slide
    tau = model.gravity(q0) + model.coriolis(q0, v0) + friction.steady_torque(v0)
    for p in (p0, p1):
        p.reset(q0, v0, t=10.0)
        p.braked = False
        p._substep(tau.tolist())
    h = p0._h
    xt = np.array(p1._fx.extra_torque(q0.tolist(), v0.tolist(), 10.0))
    dv = -h * np.linalg.solve(model.mass_matrix(q0), xt)
    assert_allclose(p1.state.qd - p0.state.qd, dv, rtol=1e-6, atol=1e-12)
    assert np.abs(dv).max() > 1e-6


def test_payload_and_rotor_inertia_change_the_dynamics(model, friction):
    q = np.array([0.2, 0.8, 0.3])
    m, off = 4.0, np.array([0.0, 0.0, 0.07])
    p = Plant(model, friction, QUIET, PlantEffects.from_dict({
        'payload_mass': {'mass_kg': m, 'offset_m': off.tolist()},
        'rotor_inertia': {'armature_kgm2': [1.0, 2.0, 0.5]}}))
    # gravity of a point mass at the tool0 point + offset: J_c^T m g (finite differences)
    R = model.fk_full(np.r_[q, 0, 0, 0])[:3, :3]

    def point(qq):
        return model.fk(qq) + model.fk_full(np.r_[qq, 0, 0, 0])[:3, :3] @ off
    eps = 1e-6
    Jc = np.column_stack([(point(q + eps * e) - point(q - eps * e)) / (2 * eps)
                          for e in np.eye(3)])
    g_payload = Jc.T @ np.array([0.0, 0.0, m * 9.81])
    g_plant = pin.computeGeneralizedGravity(p._pm, p._pd, q)
    assert_allclose(g_plant - model.gravity(q), g_payload, rtol=1e-5, atol=1e-6)
    M_plant = pin.crba(p._pm, p._pd, q)
    M_plant = np.triu(M_plant) + np.triu(M_plant, 1).T
    Mp = m * Jc.T @ Jc
    assert_allclose(M_plant - model.mass_matrix(q), Mp + np.diag([1.0, 2.0, 0.5]),
                    rtol=1e-5, atol=1e-6)
    assert R.shape == (3, 3)
    assert_allclose(p.tcp(), model.fk(p.state.q))     # kinematics unchanged


@pytest.mark.parametrize('extra_s, first_k', [(0.0, 3), (0.004032, 4), (0.008064, 5)])
def test_time_delay_shifts_the_applied_torque(model, friction, extra_s, first_k):
    """A torque step commanded at sample 0 shows in the effort at sample 3 + extra samples."""
    fx = PlantEffects.from_dict({'time_delay': {'extra_delay_s': extra_s}})
    p = Plant(model, friction, PlantConfig(), fx)
    g = model.gravity(p.state.q)
    efforts = []
    for k in range(12):
        p.command(g + (np.array([5.0, 0, 0]) if k >= 6 else 0.0))
        p.step()
        efforts.append(p.measure().tau[0] - g[0])
    efforts = np.array(efforts)
    # the step is commanded at k = 6; measure() after step k reports the period [k, k+1)
    step_at = 6 + first_k
    assert_allclose(efforts[step_at:], 5.0, atol=1e-9)
    assert np.all(efforts[6:step_at] < 5.0 - 1e-9)


def test_half_sample_delay_reports_the_mean_torque(model, friction):
    fx = PlantEffects.from_dict({'time_delay': {'extra_delay_s': 0.004032 * 0.4}})
    p = Plant(model, friction, PlantConfig(), fx)
    assert p._fx.delay_substeps == 2
    g = model.gravity(p.state.q)
    eff = []
    for k in range(12):
        p.command(g + (np.array([5.0, 0, 0]) if k >= 6 else 0.0))
        p.step()
        eff.append(p.measure().tau[0] - g[0])
    assert_allclose(eff[9], 5.0 * 3 / 5, atol=1e-9)   # 3 of 5 substeps already stepped up
    assert_allclose(eff[10], 5.0, atol=1e-9)


@pytest.mark.parametrize('name, params', [
    ('joint_elasticity', {'stiffness_nm_rad': [2e5, 2e5, 1e5]}),
    ('backlash', {'half_width_rad': [3e-4, 3e-4, 3e-4], 'torque_smoothing_nm': 2.0}),
])
def test_link_side_effects_show_in_the_camera_only(model, friction, name, params):
    p0 = Plant(model, friction, QUIET)
    p1 = Plant(model, friction, QUIET, PlantEffects.from_dict({name: params}))
    m0 = hold(p0, model, steps=60)
    m1 = hold(p1, model, steps=60)
    assert_allclose(np.array([m.q for m in m1]), np.array([m.q for m in m0]), atol=0)
    cam0, cam1 = p0.take_camera(), p1.take_camera()
    q = p1.state.q
    g = model.gravity(q)           # at rest the gear carries gravity (friction ~0)
    if name == 'joint_elasticity':
        dq = -g / np.array(params['stiffness_nm_rad'])
    else:
        dq = -np.array(params['half_width_rad']) * np.tanh(g / 2.0)
    expected = model.jacobian(q) @ dq
    assert_allclose(cam1[-1][1] - cam0[-1][1], expected, rtol=2e-2, atol=2e-7)
    assert np.linalg.norm(expected) > 5e-5          # 50 um: far above the 37 um noise


def test_every_effect_runs_the_circle(model):
    """Each moderate effect in the closed loop: the circle still completes, finite output."""
    for name in EFFECT_NAMES:
        plant, ctrl = build_default(duration_s=2.5, model=model)
        plant = Plant(model, plant.friction, plant.config, moderate_effect(name))
        res = simulate_closed_loop(plant, ctrl, 3.5)
        assert res.finished(), name
        assert np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.cam_p)), name
