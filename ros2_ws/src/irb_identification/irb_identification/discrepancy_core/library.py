"""Candidate effects as regressors on the residual channels. No rclpy.

``Pooled`` stacks the prepared runs (residuals.Channels); every candidate effect of
irb_control.plant_effects.EFFECT_NAMES maps to columns that are linear in its amplitude
parameters, with nonlinear scales on a grid (profiled):

=========================== ======= =============================================== ==========
effect                      channel regressor (per joint j unless stated)           grid
=========================== ======= =============================================== ==========
torque_offset               torque  1                                               -
coulomb_asymmetry           torque  1 - exp(-(v / v_s,j)^2), v_s from the map       -
stribeck                    torque  sign(v) exp(-(v / v_x)^2)                       v_x per j
viscous_nonlinear           torque  sign(v) |v|^n                                   n shared
viscous_temperature_drift   torque  v exp(-t / T_th), t from the first sample       T_th shared
cogging                     torque  sin(2 pi q / P), cos(2 pi q / P)                P per j
rotor_inertia               torque  qdd_j                                           -
payload_mass                torque  rnea(model + 1 kg at c) - rnea(model), all j    c shared
backlash                    tcp     J(q)[:, j] tanh(tau_j / tau_e)  (coef -b_j)       tau_e
joint_elasticity            tcp     J(q)[:, j] tau_j  (coef -1/K_j)                   -
time_delay                  command effort - cmd(t - L T - d)                       d
=========================== ======= =============================================== ==========

v, q, qdd, tau (rigid-body torque, the torque through the gear) come from the SG-smoothed
encoder data (residuals.py); J is the TCP Jacobian at the camera instants.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from irb_control.plant_effects import EFFECT_CLASSES, PlantEffects

from .residuals import Channels, ResidualConfig

TORQUE, TCP, COMMAND = 'torque', 'tcp', 'command'
CHANNEL = {'torque_offset': TORQUE, 'coulomb_asymmetry': TORQUE, 'stribeck': TORQUE,
           'viscous_nonlinear': TORQUE, 'viscous_temperature_drift': TORQUE,
           'cogging': TORQUE, 'rotor_inertia': TORQUE, 'payload_mass': TORQUE,
           'backlash': TCP, 'joint_elasticity': TCP, 'time_delay': COMMAND}


@dataclass(frozen=True)
class Grids:
    """Nonlinear scales tried (SI units)."""

    stribeck_velocity: tuple = (0.02, 0.035, 0.05, 0.07, 0.1, 0.15, 0.2, 0.3)
    viscous_exponent: tuple = (1.5, 2.0, 2.5, 3.0)
    drift_time_constant: tuple = (5.0, 10.0, 20.0, 30.0, 50.0, 80.0, 130.0, 200.0)
    cogging_period: tuple = tuple(np.round(np.geomspace(0.02, 0.6, 30), 5))
    payload_offset_z: tuple = (0.0, 0.05, 0.1, 0.2)
    backlash_smoothing: tuple = (0.5, 2.0, 8.0)
    delay_max_s: float = 0.0202
    delay_step_s: float = 0.0002


@dataclass
class Pooled:
    """All runs stacked. Torque channel: N samples (t_global (N,) [s], q, qd, qdd, r (N, 3),
    mask (N, 3) moving, block (N,)); TCP: M samples (cam_q, cam_tau, r_tcp (M, 3), J (M, 3, 3),
    cam_block (M,)); command: K samples (r_cmd (K, 3), cmd_pred (D, K, 3) predictions for the
    delay grid ``delays`` (D,) [s], cmd_block (K,)); v_s (3,) the map's Stribeck speeds."""

    t_global: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    r: np.ndarray
    mask: np.ndarray
    block: np.ndarray
    cam_q: np.ndarray
    cam_tau: np.ndarray
    r_tcp: np.ndarray
    J: np.ndarray
    cam_block: np.ndarray
    eff: np.ndarray
    r_cmd: np.ndarray
    cmd_pred: np.ndarray
    delays: np.ndarray
    cmd_block: np.ndarray
    v_s: np.ndarray
    payload_unit: dict
    effort: np.ndarray | None = None
    inertial: np.ndarray | None = None
    enc_tau: np.ndarray | None = None
    off_tau: np.ndarray | None = None
    noise: dict = field(default_factory=dict)

    def subset(self, blocks: np.ndarray) -> 'Pooled':
        """Samples whose block id is in ``blocks`` (all channels)."""
        a = np.isin(self.block, blocks)
        b = np.isin(self.cam_block, blocks)
        c = np.isin(self.cmd_block, blocks)
        return Pooled(self.t_global[a], self.q[a], self.qd[a], self.qdd[a], self.r[a],
                      self.mask[a], self.block[a], self.cam_q[b], self.cam_tau[b],
                      self.r_tcp[b], self.J[b], self.cam_block[b], self.eff[c],
                      self.r_cmd[c], self.cmd_pred[:, c], self.delays, self.cmd_block[c],
                      self.v_s, {k: v[a] for k, v in self.payload_unit.items()},
                      None if self.effort is None else self.effort[a],
                      None if self.inertial is None else self.inertial[a],
                      None if self.enc_tau is None else self.enc_tau[a],
                      None if self.off_tau is None else self.off_tau[a], dict(self.noise))


def pool(channels: list[Channels], model, friction, block_s: float = 1.0,
         grids: Grids = Grids(), config: ResidualConfig = ResidualConfig()) -> Pooled:
    """Stack runs; block ids = run * 10000 + floor((t - t_run0) / block_s)."""
    t0 = min(c.t[0] for c in channels)
    parts = {k: [] for k in ('tg', 'q', 'qd', 'qdd', 'r', 'mask', 'block', 'cq', 'ctau',
                             'rtcp', 'cblock', 'eff', 'rcmd', 'kblock')}
    delays = np.arange(0.0, grids.delay_max_s + 1e-12, grids.delay_step_s)
    preds = []
    for i, c in enumerate(channels):
        parts['tg'].append(c.t - t0)
        for k, v in (('q', c.q), ('qd', c.qd), ('qdd', c.qdd), ('r', c.r_tau),
                     ('mask', c.moving)):
            parts[k].append(v)
        parts['block'].append(i * 10000 + np.floor((c.t - c.t[0]) / block_s).astype(int))
        parts['cq'].append(c.cam_q)
        parts['ctau'].append(c.cam_tau)
        parts['rtcp'].append(c.r_tcp)
        parts['cblock'].append(i * 10000 + np.floor((c.cam_t - c.t[0]) / block_s).astype(int))
        parts['eff'].append(c.eff)
        parts['rcmd'].append(c.r_cmd)
        parts['kblock'].append(i * 10000 + np.floor((c.eff_t - c.t[0]) / block_s).astype(int))
        T = c.extra['period_s']
        lag = config.command_lag_samples * T
        if len(c.eff_t):
            preds.append(np.stack([np.stack([np.interp(c.eff_t - lag - d, c.cmd_t, c.cmd[:, j])
                                             for j in range(3)], axis=1) for d in delays]))
        else:
            preds.append(np.empty((len(delays), 0, 3)))
    cat = {k: (np.concatenate(v) if v else np.empty(0)) for k, v in parts.items()}
    cam_q = cat['cq'].reshape(-1, 3)
    J = np.array([model.jacobian(x) for x in cam_q]).reshape(-1, 3, 3)
    v_s = np.array([j.stribeck_velocity for j in friction.joints])
    P = Pooled(cat['tg'], cat['q'], cat['qd'], cat['qdd'], cat['r'], cat['mask'].astype(bool),
               cat['block'], cam_q, cat['ctau'].reshape(-1, 3), cat['rtcp'].reshape(-1, 3), J,
               cat['cblock'], cat['eff'].reshape(-1, 3), cat['rcmd'].reshape(-1, 3),
               np.concatenate(preds, axis=1), delays, cat['kblock'], v_s, {})
    P.payload_unit = {z: payload_unit_torque(model, P.q, P.qd, P.qdd, (0.0, 0.0, z))
                      for z in grids.payload_offset_z}
    P.effort = np.concatenate([c.effort for c in channels]).reshape(-1, 3)
    P.inertial = inertial_columns(model, P.q, P.qd, P.qdd)
    P.enc_tau = encoder_scale_torque(model, friction, P.q, P.qd, P.qdd)
    P.off_tau = encoder_offset_torque(model, P.q, P.qd, P.qdd)
    ss = np.sum([c.extra.get('smoothing_bias_ss', [0.0] * 3) for c in channels], axis=0)
    nm = np.sum([c.extra.get('moving_samples', [0] * 3) for c in channels], axis=0)
    P.noise = {'effort_nm': np.sqrt(np.mean([np.square(c.extra['effort_noise_nm'])
                                             for c in channels], axis=0)),
               # RMS over the moving samples of every run (residuals.prepare_run)
               'smoothing_bias_nm': np.sqrt(ss / np.maximum(nm, 1))}
    return P


#: links whose mass and first moments are candidates (pinocchio joint index of the body)
INERTIAL_LINKS = {'inertial_link2': 2, 'inertial_link3': 3}


def inertial_columns(model, q, qd, qdd) -> np.ndarray:
    """(N, 3, 8): the rigid-body model's torque regressor columns (pinocchio
    computeJointTorqueRegressor) of the mass m and first moments m c (body frame) of link 2
    (0-3) and link 3 with wrist, tool and payload (4-7; one rigid body in the 3-joint model)."""
    import pinocchio as pin
    pm = model.model
    pd = pm.createData()
    cols = [10 * (INERTIAL_LINKS[k] - 1) + i for k in sorted(INERTIAL_LINKS) for i in range(4)]
    out = np.empty((len(q), 3, 8))
    for i, (a, b, c) in enumerate(zip(q, qd, qdd)):
        out[i] = pin.computeJointTorqueRegressor(pm, pd, a, b, c)[:, cols]
    return out


def encoder_offset_torque(model, q, qd, qdd, h: float = 1e-6) -> np.ndarray:
    """(N, 3 rows, 3 k): d/dq_k of M qdd + C qd + g (central differences). A measured
    q_k = q_true,k + d_k leaves the torque residual -d_k times column k."""
    out = np.empty((len(q), 3, 3))
    for k in range(3):
        up, dn = np.array(q, float), np.array(q, float)
        up[:, k] += h
        dn[:, k] -= h
        tu = model.inverse_dynamics_batch(up, qd, qdd)
        td = model.inverse_dynamics_batch(dn, qd, qdd)
        out[:, :, k] = (tu - td) / (2 * h)
    return out


def encoder_scale_torque(model, friction, q, qd, qdd, h: float = 1e-5) -> np.ndarray:
    """(N, 3 rows, 3 k): d/ds_k of the model torque M qdd + C qd + g + tau_f(qd) when joint k's
    measured position (and its derivatives) is scaled by (1 + s_k), at s = 0 (central
    differences). A measured q_k = (1 + e_k) q_true,k leaves the torque residual -e_k times
    column k."""
    out = np.empty((len(q), 3, 3))
    for k in range(3):
        up, dn = [np.array(x, float) for x in (q, qd, qdd)], [np.array(x, float)
                                                            for x in (q, qd, qdd)]
        for arr_u, arr_d in zip(up, dn):
            arr_u[:, k] *= 1 + h
            arr_d[:, k] *= 1 - h
        tu = model.inverse_dynamics_batch(*up)
        td = model.inverse_dynamics_batch(*dn)
        tu += friction.torque(up[1])
        td += friction.torque(dn[1])
        out[:, :, k] = (tu - td) / (2 * h)
    return out


def payload_unit_torque(model, q, qd, qdd, offset) -> np.ndarray:
    """Torque (N, 3) [N m per kg] of a 1 kg point mass at ``offset`` (tool0 frame) [m]."""
    import pinocchio as pin
    from irb_control.plant_effects import EffectsRuntime
    pm = model.model.copy()
    EffectsRuntime(PlantEffects.from_dict({'payload_mass': {'mass_kg': 1.0,
                                                            'offset_m': list(offset)}}),
                   np.ones(3), 0.004032, 5).apply_to_model(pm)
    pd = pm.createData()
    pd0 = model.model.createData()
    return np.array([pin.rnea(pm, pd, a, b, c) - pin.rnea(model.model, pd0, a, b, c)
                     for a, b, c in zip(q, qd, qdd)])


# --- torque-channel columns ---------------------------------------------------------------
def torque_columns(name: str, P: Pooled, j: int, scale) -> np.ndarray:
    """Columns (N, p) of effect ``name`` for joint j at nonlinear ``scale``."""
    v = P.qd[:, j]
    if name == 'torque_offset':
        return np.ones((len(v), 1))
    if name == 'coulomb_asymmetry':
        return (1.0 - np.exp(-(v / P.v_s[j]) ** 2))[:, None]
    if name == 'stribeck':
        return (np.sign(v) * np.exp(-(v / scale) ** 2))[:, None]
    if name == 'viscous_nonlinear':
        return (np.sign(v) * np.abs(v) ** scale)[:, None]
    if name == 'viscous_temperature_drift':
        return (v * np.exp(-P.t_global / scale))[:, None]
    if name == 'cogging':
        ph = 2 * np.pi * P.q[:, j] / scale
        return np.column_stack([np.sin(ph), np.cos(ph)])
    if name == 'rotor_inertia':
        return P.qdd[:, j][:, None]
    raise KeyError(name)


PER_JOINT_SCALE = {'stribeck': 'stribeck_velocity', 'cogging': 'cogging_period'}
SHARED_SCALE = {'viscous_nonlinear': 'viscous_exponent',
                'viscous_temperature_drift': 'drift_time_constant',
                'payload_mass': 'payload_offset_z', 'backlash': 'backlash_smoothing',
                'time_delay': None}


def tcp_columns(name: str, P: Pooled, scale) -> np.ndarray:
    """Columns (3M, 3) of a link-side effect: J[:, :, j] times the joint's signal."""
    tau = P.cam_tau
    sig = np.tanh(tau / scale) if name == 'backlash' else tau
    cols = P.J * sig[:, None, :]                     # (M, 3 coords, 3 joints)
    return cols.reshape(-1, 3)


# --- coefficients <-> parameter blocks ------------------------------------------------------
def to_block(name: str, coef: dict, scales: dict):
    """irb_control parameter block from fitted coefficients.

    coef: joint -> coefficient array; scales: joint -> scale (per-joint) or 'shared' -> scale.
    Joints without a coefficient get a zero amplitude.
    """
    cls = EFFECT_CLASSES[name]

    def amp(k=0):
        return tuple(float(coef[j][k]) if j in coef else 0.0 for j in range(3))
    if name == 'torque_offset':
        return cls(offset_nm=amp())
    if name == 'coulomb_asymmetry':
        return cls(delta_nm=amp())
    if name == 'rotor_inertia':
        return cls(armature_kgm2=amp())
    if name == 'stribeck':
        return cls(static_increase_nm=amp(),
                   velocity_rad_s=tuple(float(scales.get(j, 0.1)) for j in range(3)))
    if name == 'viscous_nonlinear':
        return cls(coefficient=amp(), exponent=float(scales['shared']))
    if name == 'viscous_temperature_drift':
        return cls(cold_extra_viscous_nms_rad=amp(), time_constant_s=float(scales['shared']))
    if name == 'cogging':
        a = [float(np.hypot(*coef[j])) if j in coef else 0.0 for j in range(3)]
        ph = [float(np.arctan2(coef[j][1], coef[j][0])) if j in coef else 0.0
              for j in range(3)]
        return cls(amplitude_nm=tuple(a), phase_rad=tuple(ph),
                   period_rad=tuple(float(scales.get(j, 0.1)) for j in range(3)))
    if name == 'payload_mass':
        return cls(mass_kg=float(coef['all'][0]), offset_m=(0.0, 0.0, float(scales['shared'])))
    if name == 'backlash':
        return cls(half_width_rad=tuple(-x for x in amp()),
                   torque_smoothing_nm=float(scales['shared']))
    if name == 'joint_elasticity':
        return cls(stiffness_nm_rad=tuple(float(-1.0 / coef[j][0]) if j in coef
                                          and coef[j][0] < 0 else float('inf')
                                          for j in range(3)))
    if name == 'time_delay':
        return cls(extra_delay_s=float(scales['shared']))
    raise KeyError(name)


def contribution(name: str, block, P: Pooled) -> tuple[str, np.ndarray]:
    """(channel, predicted residual) of an effect block on P: torque (N, 3), tcp (M, 3),
    command (K, 3) (for time_delay: the change of the command residual)."""
    ch = CHANNEL[name]
    if ch == TORQUE:
        out = np.zeros_like(P.r)
        if name == 'payload_mass':
            unit = payload_unit_torque_cached(P, block.offset_m[2])
            return ch, block.mass_kg * unit
        for j in range(3):
            if name == 'stribeck':
                out[:, j] = torque_columns(name, P, j, block.velocity_rad_s[j])[:, 0] * \
                    block.static_increase_nm[j]
            elif name == 'cogging':
                cols = torque_columns(name, P, j, block.period_rad[j])
                a, ph = block.amplitude_nm[j], block.phase_rad[j]
                out[:, j] = cols @ np.array([a * np.cos(ph), a * np.sin(ph)])
            elif name == 'viscous_nonlinear':
                out[:, j] = torque_columns(name, P, j, block.exponent)[:, 0] * \
                    block.coefficient[j]
            elif name == 'viscous_temperature_drift':
                out[:, j] = torque_columns(name, P, j, block.time_constant_s)[:, 0] * \
                    block.cold_extra_viscous_nms_rad[j]
            else:
                a = {'torque_offset': block.offset_nm if name == 'torque_offset' else None,
                     'coulomb_asymmetry': getattr(block, 'delta_nm', None),
                     'rotor_inertia': getattr(block, 'armature_kgm2', None)}[name]
                out[:, j] = torque_columns(name, P, j, None)[:, 0] * a[j]
        return ch, out
    if ch == TCP:
        if name == 'backlash':
            coef = -np.asarray(block.half_width_rad)
            X = tcp_columns(name, P, block.torque_smoothing_nm)
        else:
            coef = -1.0 / np.asarray(block.stiffness_nm_rad)
            X = tcp_columns(name, P, None)
        return ch, (X @ coef).reshape(-1, 3)
    d = block.extra_delay_s
    k = int(np.argmin(np.abs(P.delays - d)))
    return ch, P.cmd_pred[k] - P.cmd_pred[0]


def payload_unit_torque_cached(P: Pooled, z: float) -> np.ndarray:
    for key, v in P.payload_unit.items():
        if abs(key - z) < 1e-9:
            return v
    raise KeyError(f'payload offset {z} not precomputed')
