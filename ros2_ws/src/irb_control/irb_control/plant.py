"""Simulated IRB 1600 plant: forward dynamics, stick-slip friction, delay, sensors, brakes.

Plain class, no ROS imports. Joints 1-3 are actuated, 4-6 locked (the model of
irb_description). One call of ``Plant.step`` advances one controller period ``period_s``
(0.004032 s) in ``substeps`` equal substeps (default 5, h = 0.806 ms) of semi-implicit Euler::

    v+ = v + h M(q)^-1 (tau - C(q, v) v - g(q) - F_v v - lambda)
    q+ = q + h v+

The dry-friction torque ``lambda`` (Coulomb + Stribeck) is solved *at the new velocity* in
every substep (time-stepping stick-slip model, projected Gauss-Seidel on the 3x3 Delassus
matrix h M^-1): each joint either sticks (v+_i = 0, |lambda_i| <= F(v_i)) or slides with
lambda_i = sign(v+_i) F(v_i), where F(v) = F_c + (F_s - F_c) exp(-(v / v_s)^2). A joint at rest
stays at rest until the net torque exceeds the static level F_s, and the model is stable at
zero speed with no chattering (there is no sign(v) of the old velocity). Viscous friction
F_v v is explicit (h F_v / M_ii < 0.01 here).

Command path: ``command(tau)`` hands the plant the answer to the latest measurement; a command
answering the measurement at t_k acts on the plant from t_{k + delay_samples} (default 3),
held constant over the period. No command for longer than ``command_timeout_s`` engages the
brakes: applied torque 0, velocity 0, position held; the next command releases them.
Sensors: encoder-like joint measurement (quantisation + Gaussian noise) each period, and a
camera that samples the TCP position every ``camera_period_s`` with ``camera_noise_m`` noise
(per axis).

Extra physical effects (``effects``, irb_control.plant_effects: Stribeck hump, Coulomb
asymmetry, torque offset, nonlinear viscous, payload, rotor inertia, extra delay, cogging,
backlash, elasticity, viscous drift) hook in at four places: the pinocchio model (payload,
armature), the dry-friction level and an extra torque in each substep, the torque delay line,
and the camera's link-side position. Without effects the plant is unchanged.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml
from irb_description.friction import FrictionMap, friction_map_from_dict
from irb_description.model import RobotModel

from .plant_effects import EffectsRuntime, PlantEffects

PERIOD_S = 0.004032


@dataclass(frozen=True)
class PlantFriction:
    """Parametric plant friction per joint, each (3,): F_c, F_s [N m], v_s [rad/s], F_v."""

    coulomb: np.ndarray
    static: np.ndarray
    stribeck_velocity: np.ndarray
    viscous: np.ndarray

    @classmethod
    def from_map(cls, fm: FrictionMap) -> 'PlantFriction':
        """Parametric part of a friction map (polynomials, if any, are not used)."""
        return cls(np.array([j.coulomb for j in fm.joints]),
                   np.array([j.static for j in fm.joints]),
                   np.array([j.stribeck_velocity for j in fm.joints]),
                   np.array([j.viscous for j in fm.joints]))

    def slip_level(self, v: np.ndarray) -> np.ndarray:
        """Dry-friction magnitude F(v) = F_c + (F_s - F_c) exp(-(v/v_s)^2) [N m], v (3,)."""
        return self.coulomb + (self.static - self.coulomb) * np.exp(
            -(np.asarray(v) / self.stribeck_velocity) ** 2)

    def steady_torque(self, v: np.ndarray) -> np.ndarray:
        """Friction torque at constant nonzero speed v (3,) [rad/s]: sign(v) F(v) + F_v v."""
        v = np.asarray(v, float)
        return np.sign(v) * self.slip_level(v) + self.viscous * v


def load_plant_friction(path: str | Path, joint_names: list[str]) -> tuple[FrictionMap,
                                                                           PlantFriction]:
    """Read a plant YAML (friction-map schema of irb_description.friction) -> map, plant model."""
    data = yaml.safe_load(Path(path).read_text())
    fm = friction_map_from_dict(data, joint_names)
    return fm, PlantFriction.from_map(fm)


def default_plant_yaml() -> Path:
    """config/plant.yaml of this package (source tree or installed share directory)."""
    return config_path('plant.yaml')


def config_path(name: str) -> Path:
    """Path of ``config/<name>`` of irb_control (source tree first, then the ament index)."""
    source = Path(__file__).resolve().parent.parent / 'config' / name
    if source.is_file():
        return source
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('irb_control')) / 'config' / name


@dataclass(frozen=True)
class PlantConfig:
    """Plant settings (SI units). Arrays are (3,) over joints 1-3."""

    period_s: float = PERIOD_S
    substeps: int = 5
    delay_samples: int = 3
    initial_q: tuple = (0.0, 0.90, 0.25)
    command_timeout_s: float = 0.05
    encoder_resolution_rad: float = 2.0e-6
    position_noise_rad: float = 1.0e-6
    velocity_noise_rad_s: float = 1.0e-3
    camera_period_s: float = 0.01
    camera_noise_m: float = 37e-6
    seed: int = 1
    gs_iterations: int = 30

    def __post_init__(self):
        if not (self.period_s > 0 and self.substeps >= 1 and self.delay_samples >= 1):
            raise ValueError('period_s > 0, substeps >= 1 and delay_samples >= 1 required')
        vals = [self.command_timeout_s, self.encoder_resolution_rad, self.position_noise_rad,
                self.velocity_noise_rad_s, self.camera_period_s, self.camera_noise_m,
                *self.initial_q]
        if not np.all(np.isfinite(vals)) or min(vals[:6]) < 0 or self.camera_period_s <= 0:
            raise ValueError(f'plant settings must be finite and >= 0: {self}')


@dataclass
class Measurement:
    """One encoder sample: time t [s], q (3,) [rad], qd (3,) [rad/s], applied torque (3,)."""

    t: float
    q: np.ndarray
    qd: np.ndarray
    tau: np.ndarray


@dataclass
class PlantState:
    """True state: t [s], q (3,) [rad], qd (3,) [rad/s], energy [J] = int sum |tau qd| dt."""

    t: float = 0.0
    q: np.ndarray = field(default_factory=lambda: np.zeros(3))
    qd: np.ndarray = field(default_factory=lambda: np.zeros(3))
    energy: float = 0.0


class Plant:
    """The simulated robot. ``model`` is used for dynamics and FK only (its own workspace)."""

    def __init__(self, model: RobotModel, friction: PlantFriction, config: PlantConfig
                 = PlantConfig(), effects: PlantEffects | None = None):
        self.model = model.copy()
        self._pm = self.model.model
        self.effects = effects or PlantEffects()
        self._fx = (EffectsRuntime(self.effects, friction.stribeck_velocity, config.period_s,
                                   config.substeps) if self.effects else None)
        if self._fx is not None:
            self._fx.apply_to_model(self._pm)
            self.model.data = self._pm.createData()
        self._pd = self.model.data
        self.friction = friction
        self.config = config
        self._h = config.period_s / config.substeps
        self._fc = [float(x) for x in friction.coulomb]
        self._fs = [float(x) for x in friction.static]
        self._vs = [float(x) for x in friction.stribeck_velocity]
        self._fv = [float(x) for x in friction.viscous]
        self.events: list[tuple[float, str]] = []
        self.camera: list[tuple[float, np.ndarray]] = []
        self.reset(np.asarray(config.initial_q, float))

    # --- state ---------------------------------------------------------------------------
    def reset(self, q: np.ndarray, qd: np.ndarray | None = None, t: float = 0.0) -> None:
        """Put the robot at q (3,) [rad] with speed qd (default 0), brakes on, no commands."""
        self.state = PlantState(float(t), np.array(q, float),
                                np.zeros(3) if qd is None else np.array(qd, float), 0.0)
        self.rng = np.random.default_rng(self.config.seed)
        self._noise = np.empty((0, 3))
        self._noise_i = 0
        self._pipeline: deque = deque([None] * self.config.delay_samples)
        self._latest: np.ndarray | None = None
        self._last_command_t = -math.inf
        self.applied = np.zeros(3)
        self.braked = True
        self.friction_torque = np.zeros(3)
        self._tau_t = [0.0, 0.0, 0.0]
        if self.effects:
            self._fx = EffectsRuntime(self.effects, self.friction.stribeck_velocity,
                                      self.config.period_s, self.config.substeps)
        self._next_camera_t = self.state.t
        self.camera.clear()
        self.steps = 0

    def command(self, tau: np.ndarray) -> None:
        """Hand over the torque command (3,) [N m] answering the latest measurement.

        Non-finite or wrongly shaped commands are ignored (as a drive would reject them).
        """
        tau = np.asarray(tau, float)
        if tau.shape != (3,) or not np.all(np.isfinite(tau)):
            self.events.append((self.state.t, f'rejected invalid command {tau!r}'))
            return
        self._latest = tau.copy()
        self._last_command_t = self.state.t

    # --- sensors -------------------------------------------------------------------------
    def _gauss(self) -> np.ndarray:
        if self._noise_i >= len(self._noise):
            self._noise = self.rng.standard_normal((4096, 3))
            self._noise_i = 0
        self._noise_i += 1
        return self._noise[self._noise_i - 1]

    def measure(self) -> Measurement:
        """Encoder sample of the current state (quantised, noisy) and the applied torque."""
        c = self.config
        s = self.state
        q = s.q + c.position_noise_rad * self._gauss()
        if c.encoder_resolution_rad > 0:
            q = np.round(q / c.encoder_resolution_rad) * c.encoder_resolution_rad
        qd = s.qd + c.velocity_noise_rad_s * self._gauss()
        return Measurement(s.t, q, qd, self.applied.copy())

    def take_camera(self) -> list[tuple[float, np.ndarray]]:
        """Camera samples (t [s], TCP (3,) [m]) taken since the last call."""
        out = self.camera[:]
        self.camera.clear()
        return out

    # --- dynamics ------------------------------------------------------------------------
    def step(self) -> None:
        """Advance one period: update the command pipeline and brakes, integrate substeps."""
        c = self.config
        s = self.state
        stale = s.t - self._last_command_t > c.command_timeout_s + 1e-9
        if stale and self._latest is not None:
            self.events.append((s.t, f'no command for {s.t - self._last_command_t:.4f} s '
                                     f'(> {c.command_timeout_s} s): brakes engaged, '
                                     'torque 0'))
            self._latest = None
            self._pipeline = deque([None] * c.delay_samples)
        self._pipeline.append(self._latest)
        applied = self._pipeline.popleft()
        if applied is None:
            if not self.braked:
                self.braked = True
            self.applied = np.zeros(3)
        else:
            if self.braked:
                self.events.append((s.t, 'command received: brakes released'))
                self.braked = False
            self.applied = applied
        t0 = s.t
        tau = self.applied.tolist()
        taus = [tau] * c.substeps
        if self._fx is not None and self._fx.delay_substeps:
            taus, self.applied = self._fx.delayed_torques(self.applied)
        for j in range(c.substeps):
            q_prev = s.q
            self._substep(taus[j])
            self._camera(q_prev)
        s.t = t0 + c.period_s
        self.steps += 1

    def _substep(self, tau: list) -> None:
        """One semi-implicit Euler substep of h [s]; tau (3,) list [N m]. Plain floats inside:
        the 3-vectors are cheaper as Python lists than as numpy arrays."""
        s = self.state
        h = self._h
        if self.braked:
            s.qd = np.zeros(3)
            self.friction_torque = np.zeros(3)
            s.t += h
            return
        q, v = s.q, s.qd
        W = (h * pin.computeMinverse(self._pm, self._pd, q)).tolist()   # h M^-1
        b = pin.nonLinearEffects(self._pm, self._pd, q, v).tolist()      # C v + g
        vl = v.tolist()
        fv = self._fv
        r = [tau[i] - b[i] - fv[i] * vl[i] for i in range(3)]
        fx = self._fx
        if fx is not None and fx.has_torque:
            x = fx.extra_torque(q.tolist(), vl, s.t)
            r = [r[i] - x[i] for i in range(3)]
        vf = [vl[i] + W[i][0] * r[0] + W[i][1] * r[1] + W[i][2] * r[2] for i in range(3)]
        bound = [self._fc[i] + (self._fs[i] - self._fc[i])
                 * math.exp(-(vl[i] / self._vs[i]) ** 2) for i in range(3)]
        if fx is not None and fx.stribeck is not None:
            bound = fx.dry_level(vl, bound)
        lam = self._solve_dry_friction(W, vf, bound)
        vn = [vf[i] - W[i][0] * lam[0] - W[i][1] * lam[1] - W[i][2] * lam[2]
              for i in range(3)]
        # sticking joints come out at ~1e-17 rad/s; make them exactly zero
        vn = [0.0 if abs(x) < 1e-12 else x for x in vn]
        ql = q.tolist()
        s.q = np.array([ql[i] + h * vn[i] for i in range(3)])
        s.qd = np.array(vn)
        self._lam = lam
        self._vprev = vl
        if fx is not None and fx.link_side:
            # torque through the gear: applied minus everything on the motor side
            xt = x if fx.has_torque else [0.0, 0.0, 0.0]
            self._tau_t = [tau[i] - lam[i] - fv[i] * vl[i] - xt[i] for i in range(3)]
        s.energy += h * (abs(tau[0] * vn[0]) + abs(tau[1] * vn[1]) + abs(tau[2] * vn[2]))
        s.t += h

    @property
    def friction_torque(self) -> np.ndarray:
        """Friction torque (3,) [N m] of the last substep (dry + viscous)."""
        return np.array([self._lam[i] + self._fv[i] * self._vprev[i] for i in range(3)])

    @friction_torque.setter
    def friction_torque(self, value) -> None:
        self._lam = list(np.asarray(value, float))
        self._vprev = [0.0, 0.0, 0.0]

    def _solve_dry_friction(self, W: list, vf: list, bound: list) -> list:
        """Dry-friction torques lambda (3,) [N m] with v+ = vf - W lambda (W = h M^-1).

        Complementarity per joint: v+_i = 0 and |lambda_i| <= bound_i (stick), or
        lambda_i = sign(v+_i) bound_i with sign(v+_i) = sign(lambda_i) (slide). Active-set
        iteration over the stick/slide pattern (3 joints: converges in a few passes; a
        projected Gauss-Seidel sweep is the fallback).
        """
        # initial pattern: a joint slides if it would slide on its own
        sign = [0.0 if abs(vf[i]) <= W[i][i] * bound[i] else math.copysign(1.0, vf[i])
                for i in range(3)]
        for _ in range(6):
            stick = [i for i in range(3) if sign[i] == 0.0]
            lam = [sign[i] * bound[i] for i in range(3)]
            if stick:
                rhs = [vf[i] - sum(W[i][j] * lam[j] for j in range(3) if sign[j] != 0.0)
                       for i in stick]
                sol = _solve_small([[W[i][j] for j in stick] for i in stick], rhs)
                for k, i in enumerate(stick):
                    lam[i] = sol[k]
            changed = False
            for i in range(3):
                if sign[i] == 0.0:
                    if abs(lam[i]) > bound[i] * (1.0 + 1e-12):
                        sign[i] = math.copysign(1.0, lam[i])
                        changed = True
                else:
                    Wi = W[i]
                    vi = vf[i] - Wi[0] * lam[0] - Wi[1] * lam[1] - Wi[2] * lam[2]
                    if vi * sign[i] < 0.0:
                        sign[i] = 0.0
                        changed = True
            if not changed:
                return lam
        lam = [0.0, 0.0, 0.0]
        for _ in range(self.config.gs_iterations):
            for i in range(3):
                Wi = W[i]
                vi0 = vf[i] - Wi[0] * lam[0] - Wi[1] * lam[1] - Wi[2] * lam[2] + Wi[i] * lam[i]
                lam[i] = (vi0 / Wi[i] if abs(vi0) <= Wi[i] * bound[i]
                          else math.copysign(bound[i], vi0))
        return lam

    def _camera(self, q_prev: np.ndarray) -> None:
        c = self.config
        s = self.state
        t1 = s.t
        t0 = t1 - self._h
        while self._next_camera_t <= t1 + 1e-12:
            w = (self._next_camera_t - t0) / self._h
            q = q_prev + min(max(w, 0.0), 1.0) * (s.q - q_prev)
            if self._fx is not None and self._fx.link_side:
                q = self._fx.link_position(q, self._tau_t)
            p = self.model.fk(q) + c.camera_noise_m * self.rng.standard_normal(3)
            self.camera.append((self._next_camera_t, p))
            self._next_camera_t += c.camera_period_s

    def tcp(self) -> np.ndarray:
        """True TCP position (3,) [m] (motor-side joints; the camera sees the link side)."""
        return self.model.fk(self.state.q)


def _solve_small(A: list, b: list) -> list:
    """Solve A x = b for n <= 3 (A symmetric positive definite) by Gaussian elimination."""
    n = len(b)
    if n == 1:
        return [b[0] / A[0][0]]
    if n == 2:
        det = A[0][0] * A[1][1] - A[0][1] * A[1][0]
        return [(b[0] * A[1][1] - A[0][1] * b[1]) / det,
                (A[0][0] * b[1] - A[1][0] * b[0]) / det]
    (a, b_, c), (d, e, f), (g, h, i) = A
    ei_fh, fg_di, dh_eg = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * ei_fh + b_ * fg_di + c * dh_eg
    x0, x1, x2 = b
    return [(x0 * ei_fh + x1 * (c * h - b_ * i) + x2 * (b_ * f - c * e)) / det,
            (x0 * fg_di + x1 * (a * i - c * g) + x2 * (c * d - a * f)) / det,
            (x0 * dh_eg + x1 * (b_ * g - a * h) + x2 * (a * e - b_ * d)) / det]
