"""What a plan must satisfy before the controller may use it (numpy only, no ROS).

A plan is what pdplus will demand from the robot, so it is checked for that, not only for its
shape (issue 14, defect 9: accelerations of 1e5 rad/s^2, +-0.04 rad chatter declared with zero
velocity, a 1 rad step and 200 000 points were accepted):

* size: at most ``max_points`` points, at least 2, finite, time strictly increasing;
* consistency: positions, velocities and accelerations must agree with each other: between
  neighbours the mean rate lies between the declared rates (with tolerances); a step or
  chatter that the declared velocities do not explain is refused, accelerations that switch
  at or between points (trapezoid and sweep ramps) are not;
* limits: positions inside the limits, speeds below the speed limits, accelerations below
  ``max_acceleration``;
* torque: the feed-forward the controller will command, M(q) qdd + C(q, qd) qd + g(q) +
  tau_f(qd), below the torque limits (a feedback margin kept free, ``torque_fraction``).

``check_joint_plan`` raises ``PlanRejected`` naming the first problem (joint, point, time).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from irb_description.trajectory_rules import (CONSISTENCY_ATOL, CONSISTENCY_RTOL,
                                              worst_inconsistency)


class PlanRejected(ValueError):
    """A plan the controller must not use; the message says why (point, joint, numbers)."""


@dataclass(frozen=True)
class PlanLimits:
    """Per joint (3,): lower/upper [rad], velocity [rad/s], torque [N m]; scalars below."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    torque: np.ndarray
    max_acceleration: float = 50.0       # [rad/s^2], any joint
    torque_fraction: float = 0.9         # of the torque limit the feed-forward may use
    max_points: int = 20000
    consistency_rtol: float = CONSISTENCY_RTOL      # residual / what the rates allow
    consistency_atol_rad: float = CONSISTENCY_ATOL  # [rad] (and [rad/s] for velocities)


def check_size(n_points: int, limits: PlanLimits) -> None:
    if n_points < 2:
        raise PlanRejected('a plan needs at least 2 points')
    if n_points > limits.max_points:
        raise PlanRejected(f'{n_points} points, more than max_plan_points = '
                           f'{limits.max_points}')


def check_joint_plan(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                     limits: PlanLimits, feed_forward: Callable | None = None,
                     consistency: bool = True) -> dict:
    """Check a joint plan t (N,) [s], q, qd, qdd (N, 3); returns a summary dict (peaks).

    ``feed_forward(q, qd, qdd)`` -> (N, 3) [N m], the torque the controller would command;
    None skips the torque check. ``consistency`` False skips the rate consistency (for
    references on a theta grid, whose consistency is that of the theta law).
    """
    t, q, qd, qdd = (np.asarray(a, float) for a in (t, q, qd, qdd))
    check_size(t.size, limits)
    for name, a in (('time', t), ('positions', q), ('velocities', qd),
                    ('accelerations', qdd)):
        if not np.all(np.isfinite(a)):
            raise PlanRejected(f'non-finite {name}')
    dt = np.diff(t)
    if np.any(dt <= 0):
        k = int(np.argmax(dt <= 0))
        raise PlanRejected(f'time not strictly increasing at point {k + 1}')

    def fail(kind, k, i, text):
        raise PlanRejected(f'{kind}: joint {i + 1} at point {k} (t = {t[k]:.4f} s): {text}')
    # limits
    for i in range(q.shape[1]):
        bad = (q[:, i] < limits.lower[i]) | (q[:, i] > limits.upper[i])
        if np.any(bad):
            k = int(np.argmax(bad))
            fail('position limit', k, i, f'{q[k, i]:.4f} rad outside '
                 f'[{limits.lower[i]:.3f}, {limits.upper[i]:.3f}]')
        k = int(np.argmax(np.abs(qd[:, i])))
        if abs(qd[k, i]) > limits.velocity[i]:
            fail('speed limit', k, i, f'|qd| = {abs(qd[k, i]):.3f} > '
                 f'{limits.velocity[i]:.3f} rad/s')
        k = int(np.argmax(np.abs(qdd[:, i])))
        if abs(qdd[k, i]) > limits.max_acceleration:
            fail('acceleration limit', k, i, f'|qdd| = {abs(qdd[k, i]):.3g} > '
                 f'{limits.max_acceleration:g} rad/s^2')
    # consistency: one rule for the planner and this gate (irb_description.trajectory_rules:
    # between neighbours the mean rate must lie between the declared rates at the two
    # points, widened by the tolerances)
    bad = (worst_inconsistency(t, q, qd, qdd, limits.consistency_rtol,
                               limits.consistency_atol_rad) if consistency else None)
    if bad is not None:
        fail(f'inconsistent {bad.what}', bad.point, bad.joint, bad.detail())
    summary = {'points': int(t.size), 'duration_s': float(t[-1] - t[0]),
               'peak_speed': np.abs(qd).max(axis=0).tolist(),
               'peak_acceleration': np.abs(qdd).max(axis=0).tolist()}
    if feed_forward is not None:
        tau = np.asarray(feed_forward(q, qd, qdd), float)
        allowed = limits.torque_fraction * limits.torque
        over = np.abs(tau) - allowed
        if np.any(over > 0):
            k, i = np.unravel_index(int(np.argmax(over)), over.shape)
            fail('torque', k, i, f'feed-forward {tau[k, i]:.1f} N m beyond '
                 f'{limits.torque_fraction:.0%} of the limit {limits.torque[i]:.0f} N m')
        summary['peak_feed_forward'] = np.abs(tau).max(axis=0).tolist()
    return summary
