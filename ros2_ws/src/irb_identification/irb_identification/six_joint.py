"""Identification of the wrist, joints 4 to 6 (issue 30): the six-joint model and simulator.

The three-axis identification (the thesis's) reads joints 1-3 and drops the wrist, which the
model locks (``series.without_locked``). Asking for any of joint_4 .. joint_6 (the ``joints``
setting of ``experiments``, ``identify``, ``identifier``) switches to the six-joint arm:

* ``SixJointIdentificationModel``: irb_description's ``SixJointModel`` (wrist masses,
  reflected rotor inertias, nominal friction of joints 1-6: dynamics.yaml ``friction`` +
  ``wrist_friction``) with the batched inverse dynamics the total-torque fit subtracts;
* ``simulate_six``: eq. 4.1 on one joint of irb_control's six-joint simulator (``Plant`` with
  ``SixJointModel``: stick-slip friction of config/plant.yaml joint_1..6, 3-sample delay,
  5 substeps, encoder noise) tracked by the six-joint PD+ (``PdPlusController``, gains of
  irb_control config/pdplus_six_axis.yaml, time-driven, friction feed-forward off as in the
  thesis's experiments) -- the same loop as ``experiments mode:=ros`` against the simulator
  and pdplus ``joints:=6`` in lockstep, without ROS;
* the effort logged is what the simulator publishes: the torque applied over the period
  before the sample (``identify --effort-lag-s`` 0.6 T, as the main job passes), plus
  optional white noise.

No rclpy. irb_control is imported only when a simulation runs (design: identification ->
control only for the plant used in simulation).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
from irb_description.model import batched_rnea
from irb_description.robot_state import locked_joint_names
from irb_description.six_axis_model import SixJointModel

from .offline_sim import SimConfig, SimRun, start_pose, write_run_bag
from .profiles import ConstantVelocityProfile, joint_reference

#: joints the three-axis model locks and the six-joint identification adds
WRIST_JOINTS: tuple[str, ...] = tuple(locked_joint_names())

#: the pose [rad] a wrist joint's sweep is centred on: joints 1-3 at experiments' default
#: centre (0, 0.5, -0.8), the wrist at 0 except the moving joint's own stroke. Joint 5 at 0 is
#: the wrist singularity (axes 4 and 6 aligned): harmless for the dynamics of one joint moving
#: at a time, and it keeps joint 5's stroke (+-0.85 rad at 2 rad/s) inside +-115 deg.
WRIST_CENTER = (0.0, 0.0, 0.0)


def uses_wrist(joints) -> bool:
    """True when a joint selection names any of joint_4 .. joint_6 (the six-joint mode)."""
    return any(j in WRIST_JOINTS for j in (joints or ()))


def six_joint_center(center) -> np.ndarray:
    """A start pose (6,) [rad] from a centre of 3 (joints 1-3; the wrist at WRIST_CENTER) or
    6 values; ValueError otherwise."""
    c = np.asarray(center, float).ravel()
    if c.size == 3:
        return np.r_[c, WRIST_CENTER]
    if c.size == 6:
        return c
    raise ValueError(f'center: 3 values (joints 1-3) or 6, got {c.size}')


class SixJointIdentificationModel(SixJointModel):
    """``SixJointModel`` plus what the identification pipeline asks of a model:
    ``inverse_dynamics_batch`` (rows of (M, 6) q, qd, qdd -> (M, 6) [N m], pinocchio's batched
    RNEA with the wrist's armature, as ``RobotModel``'s) and ``mass_matrix``."""

    def copy(self) -> 'SixJointIdentificationModel':
        return SixJointIdentificationModel(self.tcp, self.dynamics.copy(), self.wrist_armature)

    def inverse_dynamics_batch(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
                               ) -> np.ndarray:
        return batched_rnea(self.model, q, qd, qdd)

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q) (6, 6) [kg m^2], armature included."""
        M = pin.crba(self.model, self.data, np.asarray(q, float))
        return np.triu(M) + np.triu(M, 1).T


def plant_friction_map(path: str | Path | None = None, joint_names=None):
    """The simulated plant's friction map of joints 1-6 (irb_control config/plant.yaml unless
    ``path``): the truth of the oracle tests."""
    from irb_control.plant import default_plant_yaml, load_plant_friction
    names = list(joint_names or [f'joint_{i}' for i in range(1, 7)])
    return load_plant_friction(path or default_plant_yaml(), names)[0]


def simulate_six(model: SixJointModel, friction, profile: ConstantVelocityProfile,
                 joint: int, q0: np.ndarray, config: SimConfig = SimConfig(),
                 settle_after_s: float = 0.2, feed_forward=None) -> SimRun:
    """Eq. 4.1 on ``joint`` (0..5) of the six-joint simulator with plant friction ``friction``
    (a FrictionMap of joints 1-6, parametric part), from rest at q0 (6,) [rad].

    The controller ramps (0.5 s, a standstill here: the plant starts at the trajectory's
    start), runs the time-driven reference and holds; the run ends ``settle_after_s`` after
    HOLD. Logged per control period: the encoder sample (q, qd with the plant's noise,
    ``config.velocity_noise``) and the applied torque (+ ``config.effort_noise`` white noise),
    stamped with the sample time. RuntimeError (one line) if the controller stops.
    ``feed_forward``: the controller's friction map (None: the nominal six-joint map, as
    pdplus joints:=6 by default); no stiction prediction.
    """
    from irb_control.closed_loop import six_axis_controller_config
    from irb_control.pd_plus import MODE_HOLD, PdPlusController
    from irb_control.plant import Plant, PlantConfig, PlantFriction
    from irb_control.profiles import TimeTrajectory
    from irb_description.path import thesis_circle

    q0 = np.asarray(q0, float)
    period = config.period_s
    n_steps = int(np.ceil(profile.duration / period)) + 1
    t_ref = np.arange(n_steps) * period
    q_ref, qd_ref, qdd_ref = joint_reference(profile, joint, q0, t_ref)
    plant = Plant(model, PlantFriction.from_map(friction),
                  PlantConfig(period_s=period, initial_q=tuple(q0.tolist()),
                              velocity_noise_rad_s=config.velocity_noise, seed=config.seed))
    if feed_forward is None:
        # pdplus joints:=6's default feed-forward (friction_mode nominal): without any, the
        # PD+ alone (no integral action in config/pdplus_six_axis.yaml) lags joint 6's 2 rad/s
        # sweep by (F_c + F_v v) / Kp = 2.1 / 40 rad, over its 0.05 rad tracking limit
        from irb_description.six_axis_model import nominal_six_joint_friction
        feed_forward = nominal_six_joint_friction()
    # the path is not used by a time-driven reference (the controller needs one to exist);
    # no stiction prediction: it needs the wrist's friction known to a few percent (irb_control
    # doc/six_joint.md), which is what these sweeps are run to find out
    ctrl = PdPlusController(model, thesis_circle(),
                            six_axis_controller_config(stiction_prediction=False),
                            feed_forward)
    ctrl.set_time_trajectory(TimeTrajectory(t_ref, q_ref, qd_ref, qdd_ref))
    ctrl.enable()
    rng = np.random.default_rng(config.seed + 1)
    ramp = ctrl.config.ramp_min_duration_s
    limit = int(np.ceil((profile.duration + ramp + 2.0) / period)) + 10
    t_log, q_log, qd_log, tau_log = [], [], [], []
    done_at = None
    for _ in range(limit):
        y = plant.measure()
        out = ctrl.step(y.t, y.q, y.qd)
        if out.publish:
            plant.command(out.tau)
        t_log.append(y.t)
        q_log.append(y.q)
        qd_log.append(y.qd)
        tau_log.append(y.tau)
        plant.step()
        if ctrl.stop_reason:
            raise RuntimeError(f'{model.joint_names[joint]} at {profile.speed:g} rad/s: the '
                               f'controller stopped at {y.t:.3f} s: {ctrl.stop_reason}')
        if out.mode == MODE_HOLD:
            done_at = y.t if done_at is None else done_at
            if y.t - done_at >= settle_after_s:
                break
    else:
        raise RuntimeError(f'{model.joint_names[joint]} at {profile.speed:g} rad/s: no HOLD '
                           f'within {limit * period:.1f} s')
    t = np.asarray(t_log)
    tau = np.asarray(tau_log)
    if config.effort_noise > 0:
        tau = tau + config.effort_noise * rng.standard_normal(tau.shape)
    # the reference on the log's clock (the profile starts after the ramp)
    tr = t - ramp
    q_r, qd_r, _ = joint_reference(profile, joint, q0, tr)
    return SimRun(t, np.asarray(q_log), np.asarray(qd_log), tau, q_r, qd_r, joint, profile)


def run_six_joint_experiments(joints: list[str], speeds: list[float], out_dir: Path,
                              prefix: str = 'friction', config: SimConfig = SimConfig(),
                              profile_kwargs: dict | None = None, center=(0.0, 0.5, -0.8),
                              friction=None, model: SixJointModel | None = None,
                              log=print) -> list[Path]:
    """One bag per (joint, speed) on the six-joint simulator (``simulate_six``), the six
    joints' names in /joint_states; ``friction``: the plant's map (default irb_control
    config/plant.yaml). Returns the bag paths."""
    model = model or SixJointIdentificationModel()
    friction = friction or plant_friction_map(joint_names=model.joint_names)
    c6 = six_joint_center(center)
    bags = []
    start_ns = 1_700_000_000 * 10**9        # the runs follow each other, 1 s apart
    for name in joints:
        if name not in model.joint_names:
            raise ValueError(f'unknown joint {name!r}, expected one of {model.joint_names}')
        j = model.joint_names.index(name)
        for c in speeds:
            prof = ConstantVelocityProfile.for_speed(float(c), **(profile_kwargs or {}))
            q0 = start_pose(model, j, prof, c6)
            run = simulate_six(model, friction, prof, j, q0, config)
            bag = f'{prefix}_{name}_{float(c):.4f}'.replace('.', 'p')
            bags.append(write_run_bag(run, Path(out_dir) / bag, model.joint_names,
                                      start_ns=start_ns,
                                      custom_data={'plant_friction': friction.source,
                                                   'simulator': 'irb_control Plant, 6 joints'}))
            start_ns += int(round((run.t[-1] + 1.0) * 1e9))
            log(f'{bag}: {prof.duration:.1f} s, {len(run.t)} samples (six-joint plant)')
    return bags


def simulate_breakaway(model: SixJointModel, friction, joint: int, q0: np.ndarray,
                       direction: int, rate_nm_s: float = 0.1, travel_rad: float = 0.02,
                       config: SimConfig = SimConfig(), settle_s: float = 0.5,
                       max_torque_nm: float | None = None, after_s: float = 0.5,
                       preload_nm: float = 0.0) -> dict:
    """A breakaway run (``breakaway.py``) on ``joint`` (0..5) of the six-joint simulator:
    the PD+ (config/pdplus_six_axis.yaml, time-driven, holding q0) holds every joint;
    after ``settle_s`` the joint's command is replaced by its model static load g_j(q0) +
    direction (``preload_nm`` + rate (t - t_start)) until it has moved ``travel_rad`` (then
    the PD+ takes it back and holds it for ``after_s``); a preload below F_c (e.g. 0.9 x the
    sweeps' Coulomb level) shortens the ramp. Logged per control period as ``simulate_six`` logs
    (encoder sample, applied torque + ``config.effort_noise``). Returns the mapping
    ``breakaway.fit_breakaway`` reads (t, q, tau of the joint, ramp_start, release,
    direction) plus q_all / tau_all (N, 6). RuntimeError (one line) if the joint has not
    moved at ``max_torque_nm`` beyond g_j (default: 4 x its nominal static friction)."""
    from irb_control.closed_loop import six_axis_controller_config
    from irb_control.pd_plus import PdPlusController
    from irb_control.plant import Plant, PlantConfig, PlantFriction
    from irb_control.profiles import TimeTrajectory
    from irb_description.path import thesis_circle
    from irb_description.six_axis_model import nominal_six_joint_friction

    q0 = np.asarray(q0, float)
    period = config.period_s
    nominal = nominal_six_joint_friction()
    cap = max_torque_nm or 4.0 * nominal.joints[joint].static
    longest = settle_s + max(cap - preload_nm, 0.0) / rate_nm_s + after_s + 1.0
    n_ref = int(np.ceil(longest / period)) + 10
    t_ref = np.arange(n_ref) * period
    hold = np.repeat(q0[None, :], n_ref, axis=0)
    plant = Plant(model, PlantFriction.from_map(friction),
                  PlantConfig(period_s=period, initial_q=tuple(q0.tolist()),
                              velocity_noise_rad_s=config.velocity_noise, seed=config.seed))
    # holding at rest: no friction feed-forward (config/pdplus_six_axis.yaml's wrist
    # Stribeck term on the measured speed kicks a held wrist joint by its hump at every
    # sign change of the encoder noise, and the arm then creeps under the experiment)
    ctrl = PdPlusController(model, thesis_circle(),
                            six_axis_controller_config(stiction_prediction=False,
                                                       stribeck_measured=None),
                            nominal.scaled(0.0))
    ctrl.set_time_trajectory(TimeTrajectory(t_ref, hold, np.zeros_like(hold),
                                            np.zeros_like(hold)))
    ctrl.enable()
    g = float(model.inverse_dynamics(q0, np.zeros(6), np.zeros(6))[joint])
    rng = np.random.default_rng(config.seed + 1)
    t0 = None
    ramp_start = release = None
    log_t, log_q, log_tau = [], [], []
    for _ in range(n_ref + int(2.0 / period)):
        y = plant.measure()
        if t0 is None:
            t0 = y.t
        s = y.t - t0
        out = ctrl.step(y.t, y.q, y.qd)
        tau = np.array(out.tau, float)
        if release is None and s >= settle_s:
            if ramp_start is None:
                ramp_start = y.t
            push = preload_nm + rate_nm_s * (y.t - ramp_start)
            if push > cap:
                raise RuntimeError(f'{model.joint_names[joint]}: no breakaway up to '
                                   f'{cap:.2f} N m beyond its static load (direction '
                                   f'{direction:+d})')
            if abs(y.q[joint] - q0[joint]) >= travel_rad:
                release = y.t
            else:
                tau[joint] = g + direction * push
        if out.publish:
            plant.command(tau)
        log_t.append(y.t)
        log_q.append(y.q)
        log_tau.append(y.tau)
        plant.step()
        if ctrl.stop_reason:
            raise RuntimeError(f'{model.joint_names[joint]}: the holding controller stopped '
                               f'at {s:.3f} s: {ctrl.stop_reason}')
        if release is not None and y.t - release >= after_s:
            break
    tau_all = np.asarray(log_tau)
    if config.effort_noise > 0:
        tau_all = tau_all + config.effort_noise * rng.standard_normal(tau_all.shape)
    q_all = np.asarray(log_q)
    return {'t': np.asarray(log_t), 'q': q_all[:, joint], 'tau': tau_all[:, joint],
            'ramp_start': float(ramp_start), 'release': float(release),
            'direction': int(direction), 'q_all': q_all, 'tau_all': tau_all, 'joint': joint}


def add_breakaway(map_path: str | Path, joints, config: SimConfig = SimConfig(),
                  rate_nm_s: float = 0.1, pairs: int = 3, center=(0.0, 0.5, -0.8),
                  friction=None, model: SixJointModel | None = None, log=print,
                  out_path: str | Path | None = None) -> dict:
    """Breakaway runs (``simulate_breakaway``: ``pairs`` runs per direction, each with its
    own noise seed, preloaded to 0.9 x the map's Coulomb level, then ``rate_nm_s``) of
    ``joints`` on the six-joint simulator and their fit (``breakaway.fit_breakaway`` with
    F_c, F_v of the map at ``map_path``, M_jj of the model at the pose): the map's ``static``
    and ``stribeck_velocity`` of those joints are replaced by the fitted F_s and v_s (a
    ``breakaway`` block per joint says so), written to ``out_path`` (default: ``map_path``)
    once every joint is fitted. Returns {joint: figures}. KeyError / ValueError (the map),
    BreakawayError (a fit), RuntimeError (a run) say why in one line."""
    import yaml

    from .breakaway import fit_breakaway
    model = model or SixJointIdentificationModel()
    friction = friction or plant_friction_map(joint_names=model.joint_names)
    q0 = six_joint_center(center)
    path = Path(map_path)
    data = yaml.safe_load(path.read_text())
    try:
        entries = data['friction_map']['joints']
    except (KeyError, TypeError):
        raise ValueError(f'{path}: not a friction map (no friction_map.joints)') from None
    out = {}
    for name in joints:
        if name not in model.joint_names:
            raise ValueError(f'unknown joint {name!r}, expected one of {model.joint_names}')
        if name not in entries or not all(k in entries[name] for k in ('coulomb', 'viscous')):
            raise ValueError(f'{path}: no coulomb and viscous of {name} (identify it first: '
                             'the breakaway fit takes F_c and F_v from the sweeps)')
        j = model.joint_names.index(name)
        e = entries[name]
        runs = []
        for i in range(pairs):
            for d in (1, -1):
                cfg = replace(config, seed=config.seed + 2 * i + (d < 0))
                runs.append(simulate_breakaway(model, friction, j, q0, d, rate_nm_s,
                                               config=cfg,
                                               preload_nm=0.9 * float(e['coulomb'])))
        inertia = float(model.mass_matrix(q0)[j, j]) if hasattr(model, 'mass_matrix') else \
            float(SixJointIdentificationModel().mass_matrix(q0)[j, j])
        fit = fit_breakaway(runs, inertia, float(e['coulomb']), float(e['viscous']))
        e['static'] = fit.static
        e['stribeck_velocity'] = fit.stribeck_velocity
        for k in ('static_positive', 'static_negative'):
            e.pop(k, None)
        figs = {'static': fit.static, 'static_spread': fit.static_spread,
                'stribeck_velocity': fit.stribeck_velocity,
                'stribeck_velocity_spread': fit.stribeck_velocity_spread,
                'static_load_nm': fit.load, 'coulomb_of_the_fit': fit.coulomb,
                'position_rms_rad': fit.position_rms,
                'pairs': fit.pairs, 'rate_nm_s': rate_nm_s, 'inertia_kg_m2': inertia,
                'pose_rad': [float(x) for x in q0]}
        e['breakaway'] = figs
        out[name] = figs
        log(f'   {name} breakaway ({fit.pairs} pairs): F_s {fit.static:.4f} '
            f'± {fit.static_spread:.4f} N m, v_s {fit.stribeck_velocity:.4f} ± '
            f'{fit.stribeck_velocity_spread:.4f} rad/s (worst position fit RMS '
            f'{fit.position_rms * 1e3:.3f} mrad)')
    Path(out_path or path).write_text(yaml.safe_dump(data, sort_keys=False))
    return out
