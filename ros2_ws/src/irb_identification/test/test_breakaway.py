"""Breakaway experiments (issue 30): F_s and v_s of a joint from a slow torque ramp at rest.

Oracles: a 1-DOF joint integrated here (explicit Euler at 20 us with its own stick rule, not
the fit's LSODA), and the six-joint simulator (irb_control Plant, config/plant.yaml's wrist
friction) through ``simulate_breakaway``."""
import numpy as np
import pytest

from irb_identification.breakaway import BreakawayError, fit_breakaway

PERIOD = 0.004032


def one_joint_run(direction, static=1.25, coulomb=0.9375, vs=0.04, viscous=0.6, inertia=0.025,
                  load=0.3, rate=0.1, travel=0.02, seed=0, preload=0.85):
    """A ramp on a 1-DOF joint (joint 6's friction of config/plant.yaml): stuck while
    |tau - g| <= F_s, else M a = tau - g - F(v); the torque held over each period (encoder
    quantum 2 urad, noise 1 urad; effort noise 0.05 N m)."""
    rng = np.random.default_rng(seed)
    h = 2e-5
    sub = int(round(PERIOD / h))
    t_start = 0.5
    q, v, t = 0.1, 0.0, 0.0
    log_t, log_q, log_tau = [], [], []
    release = None
    while True:
        tau = load + direction * (preload + rate * (t - t_start) if t >= t_start else 0.0)
        log_t.append(t)
        log_q.append(round((q + 1e-6 * rng.standard_normal()) / 2e-6) * 2e-6)
        log_tau.append(tau + 0.05 * rng.standard_normal())
        if release is not None and t - release > 0.3:
            break
        net = tau - load
        if v == 0.0 and abs(net) <= static:     # stuck for the whole period
            sub_left = 0
        else:
            sub_left = sub
        for _ in range(sub_left):
            if v == 0.0 and abs(net) <= static:
                continue
            s = np.sign(v) if v != 0.0 else np.sign(net)
            f = s * (coulomb + (static - coulomb) * np.exp(-(v / vs) ** 2)) + viscous * v
            v_new = v + h * (net - f) / inertia
            v = 0.0 if v != 0.0 and np.sign(v_new) != np.sign(v) else v_new
            q += h * v
        t += PERIOD
        if release is None and abs(q - 0.1) >= travel:
            release = t
    return {'t': np.array(log_t), 'q': np.array(log_q), 'tau': np.array(log_tau),
            'ramp_start': t_start, 'release': release, 'direction': direction}


def test_the_fit_recovers_static_friction_and_stribeck_velocity_of_a_one_joint_model():
    """Two pairs of runs, each pair fitted on its own and averaged: F_s within 0.5 %, v_s
    within 5 %, the static load within 2 mN m."""
    runs = [one_joint_run(d, seed=s) for s, d in ((1, 1), (2, -1), (3, 1), (4, -1))]
    fit = fit_breakaway(runs, inertia=0.025, coulomb=0.9375, viscous=0.6)
    assert fit.pairs == 2
    assert fit.static == pytest.approx(1.25, rel=0.005)
    assert fit.stribeck_velocity == pytest.approx(0.04, rel=0.05)
    assert fit.load == pytest.approx(0.3, abs=0.002)
    assert fit.position_rms < 5e-5 and fit.stribeck_velocity_spread < 0.004


def test_runs_that_cannot_be_read_are_refused_in_one_line():
    up, down = one_joint_run(1), one_joint_run(-1)
    with pytest.raises(BreakawayError, match='a run in each direction'):
        fit_breakaway([up], inertia=0.025, coulomb=0.9375, viscous=0.6)
    still = dict(up, q=np.full_like(up['q'], 0.1))
    # another friction law (twice the viscous term): the motion does not follow the model
    with pytest.raises(BreakawayError, match='does not follow the friction model'):
        fit_breakaway([up, down], 0.025, 0.9375, viscous=1.2)
    with pytest.raises(BreakawayError, match='never left its rest position'):
        fit_breakaway([still, down], 0.025, 0.9375, 0.6)
    with pytest.raises(BreakawayError, match='not above the sweeps'):
        fit_breakaway([up, down], 0.025, coulomb=1.4, viscous=0.6)


def test_breakaway_on_the_six_joint_simulator_finds_the_plants_wrist_friction():
    """One run per direction of joint 5 (a static load of -0.17 N m at the pose) on the
    six-joint plant (10 substeps: at 5, joint 6's sliding left the continuous model by 0.4
    mrad, and v_s came out 0.050 for 0.040), preloaded to 0.9 F_c: F_s within 1 %, v_s
    within 5 % of config/plant.yaml, given its F_c and F_v, and the static load that of the
    model within 0.01 N m."""
    from irb_identification.offline_sim import SimConfig
    from irb_identification.six_joint import (SixJointIdentificationModel,
                                              plant_friction_map, simulate_breakaway,
                                              six_joint_center)
    joint = 4
    model = SixJointIdentificationModel()
    friction = plant_friction_map(joint_names=model.joint_names)
    q0 = six_joint_center((0.0, 0.5, -0.8))
    cfg = SimConfig(velocity_noise=0.002, effort_noise=0.05, seed=3)
    truth = friction.joints[joint]
    runs = [simulate_breakaway(model, friction, joint, q0, d, 0.2, config=cfg,
                               preload_nm=0.9 * truth.coulomb) for d in (1, -1)]
    fit = fit_breakaway(runs, float(model.mass_matrix(q0)[joint, joint]), truth.coulomb,
                        truth.viscous)
    assert fit.static == pytest.approx(truth.static, rel=0.01)
    assert fit.stribeck_velocity == pytest.approx(truth.stribeck_velocity, rel=0.05)
    g = model.inverse_dynamics(q0, np.zeros(6), np.zeros(6))[joint]
    assert abs(g) > 0.1 and fit.load == pytest.approx(g, abs=0.01)


def test_the_cli_writes_the_map_with_the_breakaway_and_refuses_bad_input(tmp_path, capsys):
    """``breakaway`` as a user runs it: a map with F_s = F_c (what the sweeps' sample fit
    writes) gets joint 6's F_s and v_s; an existing --out, a missing map, a map without the
    joint: one line, exit 2, nothing written."""
    import yaml

    from irb_identification.breakaway_cli import main
    from irb_identification.six_joint import plant_friction_map
    truth = plant_friction_map().joints[5]
    src = tmp_path / 'wrist.yaml'
    src.write_text(yaml.safe_dump({'friction_map': {'version': 1, 'joints': {'joint_6': {
        'coulomb': truth.coulomb, 'static': truth.coulomb, 'stribeck_velocity': 0.05,
        'viscous': truth.viscous, 'valid_range': [0.1, 2.0]}}}}))
    out = tmp_path / 'wrist_breakaway.yaml'
    assert main(['--map', str(src), '--out', str(out), '--joints', 'joint_6', '--pairs', '1',
                 '--rate', '0.5', '--json', str(tmp_path / 'r.json')]) == 0
    j6 = yaml.safe_load(out.read_text())['friction_map']['joints']['joint_6']
    assert j6['static'] == pytest.approx(truth.static, rel=0.01)
    assert j6['stribeck_velocity'] == pytest.approx(truth.stribeck_velocity, rel=0.1)
    assert j6['coulomb'] == truth.coulomb and j6['breakaway']['pairs'] == 1
    before = out.read_text()
    capsys.readouterr()
    assert main(['--map', str(src), '--out', str(out)]) == 2
    assert out.read_text() == before
    assert main(['--map', str(tmp_path / 'none.yaml'), '--out', str(tmp_path / 'n.yaml')]) == 2
    assert main(['--map', str(src), '--out', str(tmp_path / 'n.yaml'), '--joints',
                 'joint_5']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith('breakaway: ') for line in err)
    assert 'exists' in err[0] and 'no such file' in err[1] and 'joint_5' in err[2]
    assert not (tmp_path / 'n.yaml').exists()
