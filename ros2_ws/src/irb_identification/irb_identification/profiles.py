"""Constant-velocity back-and-forth motion for friction experiments (thesis eq. 4.1). No rclpy.

One period T of eq. 4.1 (speed c = a2 [rad/s], acceleration a1 [rad/s^2], t1 = c / a1)::

    qd(t) =  a1 t                      0 <= t <= t1            ramp up
             c                         t1 < t <= T/2 - t1      constant +c   (hold)
             c - a1 (t - (T/2 - t1))   ... <= T/2 + t1         reversal
            -c                         ... <= T - t1           constant -c   (hold)
            -c + a1 (t - (T - t1))     ... <= T                ramp down to 0

(The thesis prints the ramps as +-a1 t; they are written here continuous, which is what its
fig. 4.1 shows.) T = 4 t1 + 2 t_hold. The joint moves from q0 to q0 + c (t1 + t_hold) and back,
so the +c and -c holds cover the same positions and gravity cancels in eq. 4.8. A still
``settle_s`` precedes the periods.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


#: shortest ramp of a sweep [s]: three control periods of 4.032 ms, so that every ramp spans
#: samples of the trajectory message (at 8 rad/s^2 this matters below 0.097 rad/s)
MIN_RAMP_S = 3 * 0.004032


@dataclass(frozen=True)
class ConstantVelocityProfile:
    """Eq. 4.1 on one joint: speed [rad/s], acceleration [rad/s^2], hold [s], periods."""

    speed: float
    accel: float
    hold_s: float
    periods: int = 1
    settle_s: float = 0.5

    def __post_init__(self):
        if not (self.speed > 0 and self.accel > 0 and self.hold_s > 0 and self.periods >= 1):
            raise ValueError(f'bad profile {self}')

    @classmethod
    def for_speed(cls, speed: float, accel: float = 8.0, stroke_rad: float = 0.8,
                  hold_min_s: float = 0.6, hold_max_s: float = 4.0, periods: int = 1,
                  settle_s: float = 0.5, min_ramp_s: float = MIN_RAMP_S
                  ) -> 'ConstantVelocityProfile':
        """Hold time stroke/speed clipped to [hold_min_s, hold_max_s] [s]; the acceleration is
        lowered where the ramp c / a1 would be shorter than ``min_ramp_s`` [s]: a ramp shorter
        than a control period is a velocity step between two samples of the trajectory, which
        the declared accelerations do not explain (the controller's plan gate refuses it)."""
        hold = float(np.clip(stroke_rad / speed, hold_min_s, hold_max_s))
        accel = min(float(accel), float(speed) / min_ramp_s) if min_ramp_s > 0 else accel
        return cls(float(speed), float(accel), hold, int(periods), float(settle_s))

    @property
    def t1(self) -> float:
        """Ramp duration [s]."""
        return self.speed / self.accel

    @property
    def period(self) -> float:
        """T [s] of one back-and-forth."""
        return 4.0 * self.t1 + 2.0 * self.hold_s

    @property
    def duration(self) -> float:
        """Total duration [s] including the settle time."""
        return self.settle_s + self.periods * self.period

    @property
    def amplitude(self) -> float:
        """Largest displacement from q0 [rad]."""
        return self.speed * (self.t1 + self.hold_s)

    def _phase(self, t: np.ndarray) -> np.ndarray:
        tau = np.asarray(t, float) - self.settle_s
        inside = (tau >= 0) & (tau < self.periods * self.period)
        return np.where(inside, np.mod(tau, self.period), -1.0)

    def velocity(self, t: np.ndarray) -> np.ndarray:
        """qd(t) [rad/s] for times t [s] (any shape)."""
        s = self._phase(t)
        c, a, t1, T = self.speed, self.accel, self.t1, self.period
        return np.select(
            [s < 0, s <= t1, s <= T / 2 - t1, s <= T / 2 + t1, s <= T - t1],
            [0.0, a * s, c, c - a * (s - (T / 2 - t1)), -c],
            -c + a * (s - (T - t1)))

    def acceleration(self, t: np.ndarray) -> np.ndarray:
        """qdd(t) [rad/s^2]."""
        s = self._phase(t)
        a, t1, T = self.accel, self.t1, self.period
        return np.select(
            [s < 0, s <= t1, s <= T / 2 - t1, s <= T / 2 + t1, s <= T - t1],
            [0.0, a, 0.0, -a, 0.0], a)

    def position(self, t: np.ndarray) -> np.ndarray:
        """q(t) - q0 [rad], closed-form integral of ``velocity``."""
        s = self._phase(t)
        c, a, t1, T, h = self.speed, self.accel, self.t1, self.period, self.hold_s
        p1 = 0.5 * c * t1                       # end of ramp up
        p2 = p1 + c * h                          # end of +c hold
        u3 = s - (T / 2 - t1)
        u4 = s - (T / 2 + t1)
        u5 = s - (T - t1)
        return np.select(
            [s < 0, s <= t1, s <= T / 2 - t1, s <= T / 2 + t1, s <= T - t1],
            [0.0, 0.5 * a * s**2, p1 + c * (s - t1), p2 + c * u3 - 0.5 * a * u3**2,
             p2 - c * u4],
            p1 - c * u5 + 0.5 * a * u5**2)

    def hold_windows(self) -> list[tuple[float, float, float]]:
        """(start [s], end [s], signed speed [rad/s]) of every constant-speed hold."""
        out = []
        for k in range(self.periods):
            t0 = self.settle_s + k * self.period
            out.append((t0 + self.t1, t0 + self.period / 2 - self.t1, self.speed))
            out.append((t0 + self.period / 2 + self.t1, t0 + self.period - self.t1,
                        -self.speed))
        return out


def joint_reference(profile: ConstantVelocityProfile, joint: int, q0: np.ndarray,
                    t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """References (N, n) q [rad], qd [rad/s], qdd [rad/s^2] moving only ``joint`` from q0 (n,)."""
    t = np.asarray(t, float)
    q0 = np.asarray(q0, float)
    q = np.tile(q0, (len(t), 1))
    qd = np.zeros_like(q)
    qdd = np.zeros_like(q)
    q[:, joint] += profile.position(t)
    qd[:, joint] = profile.velocity(t)
    qdd[:, joint] = profile.acceleration(t)
    return q, qd, qdd


DEFAULT_SPEEDS = (0.02, 0.035, 0.06, 0.1, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0)
"""Experiment speeds [rad/s]: dense below 0.1 rad/s where the Stribeck dip is, then every
0.2 rad/s, so that order-7 polynomials stay within a few % between the points."""


def speed_list(lo: float = 0.02, hi: float = 2.0, count: int = 12) -> np.ndarray:
    """``count`` speeds [rad/s] spaced logarithmically from lo to hi."""
    return np.geomspace(lo, hi, count)
