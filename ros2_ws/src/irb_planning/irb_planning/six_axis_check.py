"""The independent played check of a six-joint trajectory (numpy/scipy only, no ROS).

It receives what a controller receives, the trajectory's points (t, q, qd, qdd) of all six
joints, and what the task asked for: the path's definition p(theta), p'(theta), p''(theta), the
tool-orientation law R(theta), the TCP on tool0, the thesis's DH table as numbers and the
limits. It shares nothing with the planner's theta interpolation or the closed-form IK:

* **as played**: per joint the quintic Hermite polynomial through (q, qd, qdd) at both ends of
  every interval (scipy ``BPoly`` in the Bernstein basis, ``play``; what a joint-trajectory
  controller does with positions, velocities and accelerations), sampled on a global clock
  at ``rate_hz`` from the first stamp (and at every stamp);
* **kinematics**: the TCP pose of every played sample by its own vectorised DH product
  (thesis Table 3.2, eq. 3.2-3.4) times the TCP transform;
* **position error**: the TCP's distance from the path (its own projection: the nearest point
  of a dense table, then Newton steps, ``verify.PathCurve``, the three-axis check's
  projection);
* **orientation error**: the angle of R_law(theta*)^T R_played, theta* the TCP's projection
  onto the path (the law at the point of the path the tool is at; on a closed path unwrapped
  along the samples, so the lap's end is at 2 pi), 2 asin(|R_a - R_b|_F / sqrt(8)), exact for
  small angles;
* **limits** of the played samples: positions, speeds, torques = the given rigid-body
  function (pinocchio RNEA on six joints in the planner) + friction evaluated here from the
  map's numbers (``verify.MapFriction``); energy int sum |tau_i qd_i| dt (and, given an
  electrical model, its electrical energy of the played torques and speeds);
* **smoothness** (given ``verify.SmoothLimits``, as the three-axis check): joint jerk from the
  quintics' own third derivative, the rate of the rigid-body torque and the TCP jerk as
  differences between samples of the TCP acceleration (``verify.dh_point_rates`` at the TCP,
  analytic in q, qd, qdd); samples inside ``smooth_exempt`` windows (the twin points around a
  blend end, where the path's curvature jumps) are reported apart.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.interpolate import BPoly

from .verify import (LIMIT_RTOL, DHTable, MapFriction, PathCurve, SmoothLimits, TcpBand,
                     check_band, check_smooth, dh_point_rates)



def rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Angle [rad] (M,) of Ra^T Rb for rotations (M, 3, 3): |Ra - Rb|_F = 2 sqrt(2) sin(a/2)."""
    diff = np.linalg.norm((Ra - Rb).reshape(-1, 9), axis=1)
    return 2.0 * np.arcsin(np.clip(diff / np.sqrt(8.0), 0.0, 1.0))


def play(t, q, qd, qdd, rate_hz: float = 10_000.0, jerk: bool = False):
    """The points t (K,) [s], q, qd, qdd (K, n) played by quintic Hermite interpolation per
    joint at ``rate_hz`` from t[0] (and at every stamp): (ts, qs, qds, qdds).

    scipy's ``BPoly`` (Bernstein basis) with the quintic's Bernstein coefficients on an
    interval of length h: q0, q0 + h v0 / 5, q0 + 2 h v0 / 5 + h^2 a0 / 20, and mirrored from
    the end (q1 - 2 h v1 / 5 + h^2 a1 / 20, q1 - h v1 / 5, q1): the polynomial whose value,
    first and second derivative match (q, qd, qdd) at both ends (``BPoly.from_derivatives``
    gives the same, one interval at a time in Python). ``jerk``: the third derivative too
    (a fifth item)."""
    t = np.asarray(t, float)
    q, qd, qdd = (np.asarray(x, float) for x in (q, qd, qdd))
    clock = t[0] + np.arange(int(np.floor((t[-1] - t[0]) * rate_hz)) + 1) / rate_hz
    ts = np.unique(np.concatenate([clock[clock <= t[-1]], t]))
    h = np.diff(t)[:, None]
    c = np.stack([q[:-1], q[:-1] + h * qd[:-1] / 5,
                  q[:-1] + 2 * h * qd[:-1] / 5 + h ** 2 * qdd[:-1] / 20,
                  q[1:] - 2 * h * qd[1:] / 5 + h ** 2 * qdd[1:] / 20,
                  q[1:] - h * qd[1:] / 5, q[1:]])              # (6, K - 1, n)
    poly = BPoly(c, t)
    out = (ts, poly(ts), poly.derivative(1)(ts), poly.derivative(2)(ts))
    return out + (poly.derivative(3)(ts),) if jerk else out


@dataclass
class PlayedCheck:
    """Outcome of ``check_played``: the largest position error [m] and orientation error [rad]
    of the played TCP (and where: t [s]); at the points themselves; peak |speed| and |torque|
    (6,) of the played samples (and peak |acceleration|, reported, not checked); energy [J];
    problems (one line each, empty = within)."""

    position_error: float
    orientation_error: float
    t_position: float
    t_orientation: float
    point_position_error: float
    point_orientation_error: float
    peak_speed: np.ndarray
    peak_torque: np.ndarray
    energy: float
    duration: float
    samples: int
    problems: list = field(default_factory=list)
    ts: np.ndarray = field(default=None, repr=False)
    position_errors: np.ndarray = field(default=None, repr=False)
    orientation_errors: np.ndarray = field(default=None, repr=False)
    peak_accel: np.ndarray = field(default=None)     # (6,) [rad/s^2] of the played samples
    peak_jerk: np.ndarray | None = None              # (6,) [rad/s^3] as played (smooth)
    peak_torque_rate: np.ndarray | None = None       # (6,) [N m/s] rigid-body torque, played
    tcp_jerk_peak: float = float('nan')              # [m/s^3] as played
    blend: dict = field(default_factory=dict)        # the same peaks inside smooth_exempt
    electrical_energy: float = float('nan')          # [J] of the played torques and speeds
    # process constraints (``band``), as played: peak TCP speed [m/s], lowest TCP speed away
    # from the rest ends [m/s], peak |TCP acceleration| [m/s^2], lowest speed / floor
    tcp_speed_peak: float = float('nan')
    tcp_speed_low: float = float('nan')
    tcp_accel_peak: float = float('nan')
    tcp_floor_ratio: float = float('nan')

    @property
    def ok(self) -> bool:
        return not self.problems


def check_played(t, q, qd, qdd, path, rotation: Callable, tcp: np.ndarray, dh: DHTable,
                 lower, upper, velocity, torque, rigid_torque: Callable | None = None,
                 friction_joints: dict | None = None, joint_names=None,
                 rate_hz: float = 10_000.0, position_tol: float = 1e-4,
                 orientation_tol: float = np.radians(0.05),
                 smooth: SmoothLimits | None = None, smooth_exempt=None,
                 electrical=None, band: TcpBand | None = None,
                 rest: bool = True) -> PlayedCheck:
    """Play the points and measure (module docstring).

    path: anything with point, d_point, dd_point (theta -> (M, 3)) and closed;
    rotation(theta (M,)) -> (M, 3, 3): the law; tcp (4, 4) on tool0 (= the DH frame 6);
    lower, upper, velocity, torque (6,) the limits checked; rigid_torque(q, qd, qdd) (M, 6) ->
    (M, 6) [N m] and friction_joints (a friction map's ``joints`` mapping, names
    ``joint_names``): the torque as played (None: not checked); ``smooth``: the smoothness
    limits checked (None: measured only, with the torques), ``smooth_exempt`` (B, 2) [s] the
    windows reported apart; ``electrical``: an ``ElectricalModel`` of the six axes (the
    played electrical energy, with the torques); ``band``: process constraints (TCP speed
    band, |TCP acceleration|; ``verify.check_band``, the three-axis check's rule, on the TCP
    of the DH product), the floor away from the rest ends if ``rest``."""
    t, q, qd, qdd = (np.asarray(x, float) for x in (t, q, qd, qdd))
    problems = []
    if not all(np.all(np.isfinite(x)) for x in (t, q, qd, qdd)) or t.size < 2 \
            or np.any(np.diff(t) <= 0):
        inf, nan6 = float('inf'), np.full(6, np.nan)
        return PlayedCheck(inf, inf, 0.0, 0.0, inf, inf, nan6, nan6, np.nan, np.nan, 0,
                           ['non-finite values or stamps not strictly increasing'])
    curve = PathCurve(path.point, path.d_point, path.dd_point, bool(path.closed))
    tcp = np.asarray(tcp, float)

    def errors(qq):
        T = dh.forward(qq) @ tcp
        p = T[:, :3, 3]
        pos = curve.deviation(p)
        # theta* along the time-ordered samples: on a closed path unwrapped from about 0, so
        # the end of the lap is at 2 pi, not at the start's 0 (the same point, where a law
        # like slerp has another orientation)
        th = np.clip(curve.theta(p), 0.0, 2 * np.pi)
        ori = rotation_angle(np.asarray(rotation(th), float), T[:, :3, :3])
        return pos, ori
    pos_pts, ori_pts = errors(q)
    ts, qs, qds, qdds, jerk = play(t, q, qd, qdd, rate_hz, jerk=True)
    pos, ori = errors(qs)
    kp, ko = int(np.argmax(pos)), int(np.argmax(ori))
    if pos[kp] > position_tol:
        problems.append(f'played, the TCP leaves the path by {pos[kp] * 1e3:.4f} mm at '
                        f't = {ts[kp]:.4f} s (> {position_tol * 1e3:g} mm)')
    if ori[ko] > orientation_tol:
        problems.append(f'played, the tool is {np.degrees(ori[ko]):.4f} deg off its law at '
                        f't = {ts[ko]:.4f} s (> {np.degrees(orientation_tol):g} deg)')
    lower, upper, velocity, torque = (np.asarray(x, float) for x in
                                      (lower, upper, velocity, torque))
    peak_v = np.abs(qds).max(axis=0)
    for i in range(q.shape[1]):
        lo, hi = qs[:, i].min(), qs[:, i].max()
        if lo < lower[i] - 1e-9 or hi > upper[i] + 1e-9:
            problems.append(f'joint {i + 1} leaves its limits [{np.degrees(lower[i]):.0f}, '
                            f'{np.degrees(upper[i]):.0f}] deg (played {np.degrees(lo):.2f} .. '
                            f'{np.degrees(hi):.2f})')
        if peak_v[i] > velocity[i] * (1 + LIMIT_RTOL):
            problems.append(f'joint {i + 1} speed {peak_v[i]:.3f} rad/s > {velocity[i]:.3f}')
    peak_tau, energy = np.full(q.shape[1], np.nan), float('nan')
    elec, smooth_out = float('nan'), {}
    if rigid_torque is not None:
        tau_r = np.asarray(rigid_torque(qs, qds, qdds), float)
        tau = tau_r
        if friction_joints is not None:
            tau = tau + MapFriction(friction_joints, list(joint_names))(qds)
        peak_tau = np.abs(tau).max(axis=0)
        energy = float(np.trapezoid(np.abs(tau * qds).sum(axis=1), ts))
        if electrical is not None:
            elec = float(electrical.energy(ts, tau, qds))
        for i in np.flatnonzero(peak_tau > torque * (1 + LIMIT_RTOL)):
            problems.append(f'joint {i + 1} torque {peak_tau[i]:.2f} N m > {torque[i]:.2f}')
        smooth_out = _smoothness(ts, qs, qds, qdds, jerk, tau_r, tcp, dh, smooth,
                                 smooth_exempt, problems)
    band_out = {}
    if band is not None and band.active:
        rates = dh_point_rates(dh, qs, qds, qdds, origin=tcp[:, 3], positions=True)
        band_out = dict(zip(('tcp_speed_peak', 'tcp_speed_low', 'tcp_accel_peak',
                             'tcp_floor_ratio'),
                            check_band(band, ts, qs, qds, qdds, curve, None, rest, problems,
                                       rates)))
    return PlayedCheck(float(pos[kp]), float(ori[ko]), float(ts[kp]), float(ts[ko]),
                       float(pos_pts.max()), float(ori_pts.max()), peak_v, peak_tau, energy,
                       float(t[-1] - t[0]), int(ts.size), problems, ts, pos, ori,
                       np.abs(qdds).max(axis=0), electrical_energy=elec, **smooth_out,
                       **band_out)


def _smoothness(ts, qs, qds, qdds, jerk, tau_r, tcp, dh: DHTable, smooth, exempt,
                problems: list) -> dict:
    """Peaks of the joint jerk (at the samples), the rigid-body torque rate and the TCP jerk
    (between samples) outside the ``exempt`` windows, and inside them apart (``blend``);
    ``smooth``'s limits checked into ``problems`` (as the three-axis check does)."""
    dts = np.diff(ts)[:, None]
    rate = np.abs(np.diff(tau_r, axis=0)) / dts
    acc = dh_point_rates(dh, qs, qds, qdds, origin=np.asarray(tcp, float)[:, 3])[1]
    tj = np.linalg.norm(np.diff(acc, axis=0), axis=1) / dts[:, 0]
    out_j, out_r = np.ones(jerk.shape[0], bool), np.ones(rate.shape[0], bool)
    for lo, hi in (() if exempt is None else np.asarray(exempt, float)):
        out_j &= ~((ts >= lo) & (ts < hi))
        out_r &= ~((ts[1:] > lo) & (ts[:-1] < hi))
    n = jerk.shape[1]
    blend = {}
    if not out_j.all() or not out_r.all():
        blend = {'joint_jerk': np.abs(jerk[~out_j]).max(axis=0) if (~out_j).any()
                 else np.zeros(n),
                 'torque_rate': rate[~out_r].max(axis=0) if (~out_r).any() else np.zeros(n),
                 'tcp_jerk': float(tj[~out_r].max()) if (~out_r).any() else 0.0}
    if smooth is not None:
        check_smooth(smooth, ts, np.where(out_j[:, None], jerk, 0.0),
                     np.where(out_r[:, None], rate, 0.0), np.where(out_r, tj, 0.0), problems)
    return {'peak_jerk': np.abs(jerk[out_j]).max(axis=0) if out_j.any() else np.zeros(n),
            'peak_torque_rate': rate[out_r].max(axis=0) if out_r.any() else np.zeros(n),
            'tcp_jerk_peak': float(tj[out_r].max()) if out_r.any() else 0.0,
            'blend': blend}
