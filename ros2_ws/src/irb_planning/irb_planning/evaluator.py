"""Independent check of any planned profile: resample at 1 kHz, torques, limits, energy.

Shares no code with the CasADi problems: joint motion from the path (closed-form IK and
Jacobians of irb_description), torques from pinocchio's RNEA plus the numpy friction map
(``RobotModel.inverse_dynamics_with_friction``), energy by the trapezoidal rule in time over
the 1 kHz samples, E = int sum_i |tau_i qd_i| dt (thesis eq. 6.8-6.9, no regeneration), and,
when an ``irb_description.electrical.ElectricalModel`` is given, the electrical energy of the
same samples for every DC-bus mode. numpy only, no ROS.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .profile import ThetaProfile

#: relative tolerance of the limit checks (round-off, not a margin)
CHECK_RTOL = 1e-6


@dataclass(frozen=True)
class LimitSet:
    """Limits the evaluator checks, each (n,): speed [rad/s], torque [N m], position [rad]."""

    velocity: np.ndarray
    torque: np.ndarray
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None


@dataclass(frozen=True)
class Evaluation:
    """A profile resampled at ``rate`` [Hz]: t (M,) [s]; q, qd, qdd, tau, power (M, n) SI.

    energy [J] = int sum_i |tau_i qd_i| dt; peak_* (n,); violations: one line per broken limit;
    electrical: {'total_none'|'total_shared'|'total_regenerative'|'copper'|'standby'|...: J}
    (ElectricalModel.breakdown; empty without an electrical model).
    """

    t: np.ndarray
    theta: np.ndarray
    theta_dot: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    power: np.ndarray
    energy: float
    duration: float
    peak_torque: np.ndarray
    peak_speed: np.ndarray
    violations: list[str] = field(default_factory=list)
    electrical: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.violations


def evaluate(profile: ThetaProfile, sample_path: Callable, torque: Callable,
             limits: LimitSet, rate: float = 1000.0, electrical=None) -> Evaluation:
    """Resample ``profile`` at ``rate`` [Hz] (plus the end point) and check it.

    sample_path(theta (M,)) -> object with q, dq, ddq (M, n) (irb_description JointPath);
    torque(q, qd, qdd) with (M, n) arrays -> tau (M, n) [N m] (rigid body + friction);
    electrical: an ElectricalModel of the n axes (or None).
    """
    T = profile.duration
    t = np.arange(0.0, T, 1.0 / rate)
    if t[-1] < T:
        t = np.append(t, T)
    theta, theta_dot, theta_ddot = profile.sample(t)
    jp = sample_path(theta)
    qd = jp.dq * theta_dot[:, None]
    qdd = jp.ddq * theta_dot[:, None] ** 2 + jp.dq * theta_ddot[:, None]
    tau = np.asarray(torque(jp.q, qd, qdd), float)
    power = np.abs(tau * qd)
    energy = float(np.trapezoid(power.sum(axis=1), t))
    peak_torque = np.abs(tau).max(axis=0)
    peak_speed = np.abs(qd).max(axis=0)
    violations = []
    for i in range(tau.shape[1]):
        if peak_torque[i] > limits.torque[i] * (1 + CHECK_RTOL):
            k = int(np.argmax(np.abs(tau[:, i])))
            violations.append(f'joint {i + 1} torque {peak_torque[i]:.2f} N m > '
                              f'{limits.torque[i]:.2f} at t = {t[k]:.3f} s')
        if peak_speed[i] > limits.velocity[i] * (1 + CHECK_RTOL):
            k = int(np.argmax(np.abs(qd[:, i])))
            violations.append(f'joint {i + 1} speed {peak_speed[i]:.3f} rad/s > '
                              f'{limits.velocity[i]:.3f} at t = {t[k]:.3f} s')
        if limits.lower is not None and (np.any(jp.q[:, i] < limits.lower[i] - 1e-9)
                                         or np.any(jp.q[:, i] > limits.upper[i] + 1e-9)):
            violations.append(f'joint {i + 1} leaves its position limits')
    if not np.all(np.isfinite(tau)):
        violations.append('non-finite torque')
    elec = electrical.breakdown(t, tau, qd) if electrical is not None else {}
    return Evaluation(t, theta, theta_dot, jp.q, qd, qdd, tau, power, energy, T,
                      peak_torque, peak_speed, violations, elec)
