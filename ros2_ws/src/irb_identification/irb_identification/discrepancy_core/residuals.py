"""The nominal model on the measured motion: three residual channels. No rclpy.

Per run (bag), with T the sample period:

* **torque** (N, 3) [N m]: r = L(effort) - [M(q) qdd + C(q, qd) qd + g(q)] - tau_f(qd)
  - tau_x(known effects), where L is a Savitzky-Golay smoother (order 3, ``window_s``),
  q = L(q_enc) and qd, qdd are its central first and second differences, and the effort
  (torque over [t - T, t)) is moved to t and smoothed with the same L, so both sides of the
  robot equation see the same linear filter (M varies slowly). ``moving`` (N, 3)
  marks samples whose joint slides (|qd| > ``v_min``, no zero crossing within half a window):
  at rest dry friction is indeterminate and carries no information.
* **tcp** (M, 3) [m]: r = camera - FK(q(t_cam)) with q interpolated to the camera instants
  (cubic); the camera sees the link side, the encoders the motor side.
* **command** (K, 3) [N m]: r = effort(t) - cmd(t - L T), L = ``command_lag_samples`` (the
  nominal pipeline: 3 samples + the effort's own period = 4); braked samples are excluded.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_filter

from .bagdata import RunData


@dataclass(frozen=True)
class ResidualConfig:
    """window_s [s] SG window (upper bound), sg_order, v_min [rad/s], command_lag_samples,
    period_s [s], edge_s [s], gap_factor [-] (a command step longer than this x period is a
    gap the command channel does not interpolate across); the window adapts to the
    excitation: at most ``window_per_reversal`` times the median time between velocity
    reversals of the run, at least ``min_window_s`` (see ``smoothing_window``)."""

    window_s: float = 0.1
    sg_order: int = 3
    min_window_s: float = 0.03
    window_per_reversal: float = 0.25
    v_min: float = 0.01
    command_lag_samples: int = 4
    period_s: float = 0.004032
    edge_s: float = 0.1
    gap_factor: float = 1.5


@dataclass
class Channels:
    """Prepared data of one run; arrays as in the module docstring plus what the library
    needs: t (N,), q, qd, qdd (N, 3), tau_rigid (N, 3) = M qdd + C qd + g, t_global (N,)
    [s since the first sample of all runs]; cam_*: camera channel; cmd_*: command channel."""

    name: str
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    effort: np.ndarray
    tau_rigid: np.ndarray
    tau_f: np.ndarray
    r_tau: np.ndarray
    moving: np.ndarray
    cam_t: np.ndarray
    cam_q: np.ndarray
    cam_tau: np.ndarray
    r_tcp: np.ndarray
    cmd_t: np.ndarray
    cmd: np.ndarray
    eff_t: np.ndarray
    eff: np.ndarray
    r_cmd: np.ndarray
    t0_global: float = 0.0
    extra: dict = field(default_factory=dict)


def _odd_window(window_s: float, period_s: float, n: int, order: int) -> int:
    w = int(round(window_s / period_s)) | 1
    return max(order + 2 | 1, min(w, (n - 1) | 1 if n % 2 == 0 else n))


def reversal_interval(t: np.ndarray, qd: np.ndarray, v_min: float) -> float | None:
    """Median time [s] between velocity reversals over the joints of a run (None: no joint
    reverses twice). A reversal: the sign of qd changes between two samples with |qd| > v_min
    (slow samples in between are skipped)."""
    gaps = []
    for j in range(qd.shape[1]):
        fast = np.abs(qd[:, j]) > v_min
        if fast.sum() < 2:
            continue
        s = np.sign(qd[fast, j])
        tr = t[fast][1:][s[1:] != s[:-1]]
        gaps.extend(np.diff(tr).tolist())
    return float(np.median(gaps)) if gaps else None


def smoothing_window(t: np.ndarray, qd_raw: np.ndarray, config: 'ResidualConfig'
                     ) -> tuple[float, float | None]:
    """(window [s], median reversal interval [s] or None): the configured window, shrunk to
    ``window_per_reversal`` x the reversal interval for fast-reversal excitation (an SG window
    across a reversal smears the friction jump into the residual), not below min_window_s."""
    rev = reversal_interval(t, qd_raw, config.v_min)
    w = config.window_s
    if rev is not None:
        w = min(w, max(config.min_window_s, config.window_per_reversal * rev))
    return w, rev


def across_gap(x: np.ndarray, t: np.ndarray, max_step_s: float, margin_s: float = 0.0
               ) -> np.ndarray:
    """(K,) True where interpolating the series at t (M,) anywhere in [x - margin_s, x]
    would bridge a step longer than ``max_step_s`` (a gap: missing commands)."""
    x = np.asarray(x, float)
    bad = np.zeros(len(x), bool)
    if len(t) < 2:
        return bad
    idx = np.flatnonzero(np.diff(t) > max_step_s)
    if not len(idx):
        return bad
    lo = np.searchsorted(x, t[idx], 'right')                 # x > gap start
    hi = np.searchsorted(x, t[idx + 1] + margin_s, 'left')   # x - margin < gap end
    mark = np.zeros(len(x) + 1, int)
    np.add.at(mark, lo, 1)
    np.add.at(mark, hi, -1)
    return np.cumsum(mark)[:-1] > 0


def prepare_run(run: RunData, model, friction, config: ResidualConfig = ResidualConfig(),
                t_origin: float = 0.0, cmd_margin_s: float = 0.0202) -> Channels:
    """Channels of one run for the nominal ``model`` (RobotModel) and ``friction`` map.

    The joint states must have no gap (bagdata.run_pieces cuts runs at gaps and fills the
    few missing samples of short ones); the command channel leaves out every sample whose
    lagged command (and the delay grid's ``cmd_margin_s`` before it) falls in a command gap
    (a step longer than ``gap_factor`` x period)."""
    c = config
    T = float(np.median(np.diff(run.t))) if len(run.t) > 1 else c.period_s
    n = len(run.t)
    if n < 2 * c.sg_order + 3:
        raise ValueError(f'bag {run.name}: only {n} joint states')
    window_s, rev = smoothing_window(run.t, run.qd, c)
    w = _odd_window(window_s, T, n, c.sg_order)
    # One linear filter L (SG smoothing) on both sides of M qdd + n = tau: the derivatives
    # are central differences of L(q) = L(differences of q); the second difference of the
    # samples matches the mean torque over [t_{k-1}, t_{k+1}) = (e_k + e_{k+1}) / 2.
    q = savgol_filter(run.q, w, c.sg_order, axis=0)
    qd = np.gradient(q, T, axis=0)
    qdd = np.zeros_like(q)
    qdd[1:-1] = (q[2:] - 2 * q[1:-1] + q[:-2]) / T**2
    qdd[0], qdd[-1] = qdd[1], qdd[-2]
    e_mid = run.effort.copy()
    e_mid[:-1] = 0.5 * (run.effort[:-1] + run.effort[1:])   # torque around t_k
    effort = savgol_filter(e_mid, w, c.sg_order, axis=0)
    tau_rigid = model.inverse_dynamics_batch(q, qd, qdd)
    tau_f = friction.torque(qd)
    r_tau = effort - tau_rigid - tau_f
    # what L itself does to this excitation's torque: L(tau_hat) - tau_hat of the model's own
    # torque (no effect in it). The robot equation is nonlinear (friction, Coriolis), so L on
    # the effort and L on the joints do not commute exactly; where the motion has content near
    # the smoother's cutoff (fast reversals, short window) this is what a clean plant leaves
    # in the torque residual (measured: clean 'short' plan 0.29 / 0.21 / 0.11 N m against a
    # residual of 0.23 / 0.22 / 0.13; clean 'fast' plan 0.50 / 0.48 / 0.25 against 0.80 /
    # 0.59 / 0.34). A floor per excitation (workflow._floors), not a correction.
    tau_hat = tau_rigid + tau_f
    bias = savgol_filter(tau_hat, w, c.sg_order, axis=0) - tau_hat
    # effort noise seen by the residual: high-pass part of the raw effort times the
    # smoother's white-noise gain (a floor for the torque channel)
    from scipy.signal import savgol_coeffs
    gain = float(np.linalg.norm(savgol_coeffs(w, c.sg_order)))
    hp = e_mid - effort
    mad = np.median(np.abs(hp - np.median(hp, axis=0)), axis=0) * 1.4826
    noise = mad / max(np.sqrt(max(1.0 - gain**2, 1e-6)), 1e-3) * gain
    # moving: sliding and no slow sample or sign change (smoothed or measured speed) within
    # half a window
    half = w // 2
    slide = np.abs(qd) > c.v_min
    flip = np.zeros_like(slide)
    for v in (qd, run.qd):
        flip[1:] |= np.sign(v[1:]) != np.sign(v[:-1])
    bad = ~slide | flip
    k = np.ones(2 * half + 1)
    near_stop = np.stack([np.convolve(bad[:, j].astype(float), k, 'same') > 0
                          for j in range(3)], axis=1)
    edge = (run.t - run.t[0] < c.edge_s) | (run.t[-1] - run.t < c.edge_s)
    filled = np.zeros(n, bool) if run.filled is None else np.asarray(run.filled, bool)
    moving = slide & ~near_stop & ~edge[:, None] & ~filled[:, None]
    bias_ss = np.array([float(np.sum(bias[moving[:, j], j] ** 2)) for j in range(3)])
    # camera channel
    inside = (run.cam_t >= run.t[0] + c.edge_s) & (run.cam_t <= run.t[-1] - c.edge_s)
    cam_t = run.cam_t[inside]
    if len(cam_t) and n > 3:
        cam_q = CubicSpline(run.t, q, axis=0)(cam_t)
        cam_tau = np.stack([np.interp(cam_t, run.t, tau_rigid[:, j]) for j in range(3)], 1)
        fk = np.array([model.fk(x) for x in cam_q])
        r_tcp = run.cam_p[inside] - fk
    else:
        cam_q = cam_tau = r_tcp = np.empty((0, 3))
    # command channel: effort(t) against cmd(t - L T)
    if len(run.cmd_t) > 1:
        lagged = run.t - c.command_lag_samples * T
        ok = ((lagged >= run.cmd_t[0]) & (lagged <= run.cmd_t[-1])
              & np.any(run.effort != 0.0, axis=1)
              & ~across_gap(lagged, run.cmd_t, c.gap_factor * T, cmd_margin_s)
              & ~filled)
        eff_t, eff = run.t[ok], run.effort[ok]
        pred = np.stack([np.interp(eff_t - c.command_lag_samples * T, run.cmd_t,
                                   run.cmd[:, j]) for j in range(3)], axis=1)
        r_cmd = eff - pred
        if len(r_cmd) > 4 * w:
            # the reported effort's own noise, free of the torque signal: high-pass part of
            # effort - cmd(t - L T) (the nominal pipeline takes the signal out)
            hpc = r_cmd - savgol_filter(r_cmd, w, c.sg_order, axis=0)
            madc = np.median(np.abs(hpc - np.median(hpc, axis=0)), axis=0) * 1.4826
            raw = madc / max(np.sqrt(max(1.0 - gain**2, 1e-6)), 1e-3)
            noise = np.minimum(noise, raw * gain)
    else:
        eff_t, eff, r_cmd = np.empty(0), np.empty((0, 3)), np.empty((0, 3))
    return Channels(run.name, run.t, q, qd, qdd, effort, tau_rigid, tau_f, r_tau, moving,
                    cam_t, cam_q, cam_tau, r_tcp, run.cmd_t, run.cmd, eff_t, eff, r_cmd,
                    t_origin, {'period_s': T, 'window': w, 'window_s': w * T,
                               'reversal_interval_s': rev,
                               'window_adapted': window_s < c.window_s,
                               'effort_noise_nm': noise.tolist(),
                               'effort_noise_raw_nm': (noise / gain).tolist(),
                               'smoothing_bias_ss': bias_ss.tolist(),
                               'moving_samples': moving.sum(axis=0).tolist()})
