"""Offline friction experiments: eq. 4.1 on a simulated plant, written as bags. No rclpy.

Plant: qdd = ABA(q, qd, tau - tau_f(qd)) (irb_description's model, pinocchio) with a known
friction map tau_f, integrated with semi-implicit Euler at ``substeps`` per control period.
Controller (248 Hz, zero-order hold): tau = ID(q_ref, qd_ref, qdd_ref) + Kp e + Kd de, no
friction feed-forward, as in the thesis's experiments; Kp = M_ii w^2, Kd = 2 zeta M_ii w from
M(q_start). Measurements: q, qd at the control instants, effort = applied tau, plus optional
Gaussian noise. This is the oracle behind identification tests: the friction is known.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .bagio import BagWriter, TopicInfo, qos_profile_dict
from .profiles import ConstantVelocityProfile, joint_reference
from .series import JOINT_STATE, encode_joint_states

PERIOD_S = 0.004032


@dataclass(frozen=True)
class SimConfig:
    """Simulation settings: control period [s], substeps, bandwidth [rad/s], damping,
    noise std of velocity [rad/s] and effort [N m], RNG seed."""

    period_s: float = PERIOD_S
    substeps: int = 4
    bandwidth_rad_s: float = 25.0
    damping: float = 1.0
    velocity_noise: float = 0.0
    effort_noise: float = 0.0
    seed: int = 0


@dataclass(frozen=True)
class SimRun:
    """One simulated run: t (N,) [s]; q, qd, tau, q_ref, qd_ref (N, n) [rad, rad/s, N m]."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    tau: np.ndarray
    q_ref: np.ndarray
    qd_ref: np.ndarray
    joint: int
    profile: ConstantVelocityProfile


def start_pose(model, joint: int, profile: ConstantVelocityProfile,
               center: np.ndarray | None = None) -> np.ndarray:
    """q0 (n,) [rad] so the motion of ``joint`` is centred on ``center`` (default zeros).

    Raises ValueError if the stroke leaves the joint's position limits.
    """
    q0 = np.zeros(len(model.joint_names)) if center is None else np.array(center, float)
    q0[joint] -= profile.amplitude / 2
    lo, hi = model.limits.lower[joint], model.limits.upper[joint]
    if q0[joint] < lo or q0[joint] + profile.amplitude > hi:
        raise ValueError(f'{model.joint_names[joint]}: stroke {profile.amplitude:.3f} rad '
                         f'around {q0[joint] + profile.amplitude / 2:.3f} leaves '
                         f'[{lo:.3f}, {hi:.3f}] rad')
    return q0


def _friction_fn(friction):
    """Fast tau_f(v) (n,) for a FrictionMap: vectorised parametric model if no polynomials."""
    if any(j.polynomial_positive is not None for j in friction.joints):
        return friction.torque
    fc = np.array([j.coulomb for j in friction.joints])
    fs = np.array([j.static for j in friction.joints])
    vs = np.array([j.stribeck_velocity for j in friction.joints])
    fv = np.array([j.viscous for j in friction.joints])

    def tau_f(v):
        return np.sign(v) * (fc + (fs - fc) * np.exp(-(v / vs) ** 2)) + fv * v
    return tau_f


def simulate(model, friction, profile: ConstantVelocityProfile, joint: int,
             q0: np.ndarray | None = None, config: SimConfig = SimConfig()) -> SimRun:
    """Run eq. 4.1 on ``joint`` (index) of the plant with ``friction`` (FrictionMap)."""
    if q0 is None:
        q0 = start_pose(model, joint, profile)
    q0 = np.asarray(q0, float)
    n_steps = int(np.ceil(profile.duration / config.period_s)) + 1
    t = np.arange(n_steps) * config.period_s
    q_ref, qd_ref, qdd_ref = joint_reference(profile, joint, q0, t)
    m_diag = np.diag(model.mass_matrix(q0))
    w = config.bandwidth_rad_s
    kp, kd = m_diag * w**2, 2.0 * config.damping * m_diag * w
    tau_f = _friction_fn(friction)
    rng = np.random.default_rng(config.seed)
    h = config.period_s / config.substeps
    n = len(q0)
    q_log, qd_log, tau_log = (np.empty((n_steps, n)) for _ in range(3))
    q, qd = q0.copy(), np.zeros(n)
    for k in range(n_steps):
        qd_meas = qd + config.velocity_noise * rng.standard_normal(n)
        tau = (model.inverse_dynamics(q_ref[k], qd_ref[k], qdd_ref[k])
               + kp * (q_ref[k] - q) + kd * (qd_ref[k] - qd_meas))
        q_log[k], qd_log[k] = q, qd_meas
        tau_log[k] = tau + config.effort_noise * rng.standard_normal(n)
        for _ in range(config.substeps):
            qdd = model.forward_dynamics(q, qd, tau - tau_f(qd))
            qd = qd + h * qdd
            q = q + h * qd
    return SimRun(t, q_log, qd_log, tau_log, q_ref, qd_ref, joint, profile)


def write_run_bag(run: SimRun, path: str | Path, joint_names: list[str],
                  start_ns: int = 1_700_000_000 * 10**9, topic: str = '/joint_states',
                  custom_data: dict[str, str] | None = None) -> Path:
    """Write ``run`` as a bag with JointState on ``topic`` (stamp = log time)."""
    t_ns = start_ns + np.round(run.t * 1e9).astype(np.int64)
    payloads = encode_joint_states(t_ns, joint_names, run.q, run.qd, run.tau)
    meta = {'experiment': 'eq4.1', 'joint': joint_names[run.joint],
            'speed_rad_s': repr(run.profile.speed), 'hold_s': repr(run.profile.hold_s),
            'source': 'irb_identification.offline_sim'}
    meta.update(custom_data or {})
    # split by simulated time, 2 s per file, like the live recorder
    clock_t = [0.0]
    with BagWriter(path, split_period_s=2.0, clock=lambda: clock_t[0],
                   custom_data=meta) as w:
        w.add_topic(TopicInfo.for_type(topic, JOINT_STATE,
                                       [qos_profile_dict('best_effort', depth=1)]))
        for tk, ns, data in zip(run.t, t_ns, payloads):
            clock_t[0] = float(tk)
            w.write(topic, int(ns), data)
    return Path(path)


def run_experiments(model, friction, joints: list[int], speeds: list[float], out_dir: Path,
                    prefix: str = 'friction', config: SimConfig = SimConfig(),
                    profile_kwargs: dict | None = None, log=print) -> list[Path]:
    """One bag per (joint, speed) under ``out_dir``; returns the bag paths."""
    bags = []
    for j in joints:
        for c in speeds:
            prof = ConstantVelocityProfile.for_speed(c, **(profile_kwargs or {}))
            run = simulate(model, friction, prof, j, config=config)
            name = f'{prefix}_{model.joint_names[j]}_{c:.4f}'.replace('.', 'p')
            bags.append(write_run_bag(run, Path(out_dir) / name, model.joint_names))
            log(f'{name}: {prof.duration:.1f} s simulated, {len(run.t)} samples')
    return bags
