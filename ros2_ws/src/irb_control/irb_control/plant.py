"""Simulated IRB 1600 plant: forward dynamics, stick-slip friction, delay, sensors, brakes.

Plain class, no ROS imports. The joint count n is the model's: 3 with ``RobotModel`` (joints
1-3 actuated, 4-6 locked: the thesis's model, today's simulator, hand-unrolled below) or 6 with
``irb_description.six_axis_model.SixJointModel`` (the whole arm, issue 30: the same equations
on n-vectors in ``_substep_n``). One call of ``Plant.step`` advances one controller period
``period_s`` (0.004032 s) in ``substeps`` equal substeps of semi-implicit Euler (default
``DEFAULT_SUBSTEPS``: 5 for three joints, h = 0.806 ms; 10 for six, h = 0.403 ms)::

    v+ = v + h M(q)^-1 (tau - C(q, v) v - g(q) - F_v v - lambda)
    q+ = q + h v+

The dry-friction torque ``lambda`` (Coulomb + Stribeck) is solved *at the new velocity* in
every substep (time-stepping stick-slip model, projected Gauss-Seidel on the 3x3 Delassus
matrix h M^-1; n x n): each joint either sticks (v+_i = 0, |lambda_i| <= F(v_i)) or slides with
lambda_i = sign(v+_i) F(v_i), where F(v) = F_c + (F_s - F_c) exp(-(v / v_s)^2). A joint at rest
stays at rest until the net torque exceeds the static level F_s, and the model is stable at
zero speed with no chattering (there is no sign(v) of the old velocity). Viscous friction
F_v v is explicit (h F_v / M_ii < 0.01 here).

Command path: ``command(tau)`` hands the plant the answer to the latest measurement; a command
answering the measurement at t_k acts on the plant from t_{k + delay_samples} (default 3),
held constant over the period. Brakes: the robot starts on its brakes and the first command
releases them. Once commanded, no command for longer than ``command_timeout_s`` engages the
brakes (applied torque 0, velocity 0, position held) and *latches* the error, like the axis
computer: every command is ignored until ``clear_error()`` (the simulator's ~/reset).
Brakes as a mode (issue 29): with ``brake_torque_nm`` set, an engaged brake is one more dry
friction element of the joint: the joint stays put while the torque needed to hold it is within
the brake torque (plus its static friction), no motor torque needed; beyond, it slips against
it. A command whose torque acts releases the brakes only after ``brake_release_s`` of torque
against the closed brake (the brake's opening time): whatever the controller commands then
(the gravity torque) already acts when the joint comes free. This applies to brakes engaged
on purpose (at start, by a power mode, by a fault); after a single period without a command in
a motion the brakes open again at once, as before. ``request_power_mode`` changes the
drives' power mode (``POWER_MODES``: hold = motors on; brakes, bus_off, hibernate = brakes
engaged, torque off, commands ignored until hold is requested); a change takes its transition
time. Without ``brake_torque_nm`` (None) the brakes hold any torque exactly (the former model).
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
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml
from irb_description.friction import FrictionMap, friction_map_from_dict
from irb_description.model import RobotModel

from .plant_effects import EffectsRuntime, PlantEffects

PERIOD_S = 0.004032
#: the drives' power modes, shallowest first (irb_description.power_modes.MODES)
POWER_MODES = ('hold', 'brakes', 'bus_off', 'hibernate')


@dataclass(frozen=True)
class PlantFriction:
    """Parametric plant friction per joint, each (n,): F_c, F_s [N m], v_s [rad/s], F_v."""

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
        """Dry-friction magnitude F(v) = F_c + (F_s - F_c) exp(-(v/v_s)^2) [N m], v (n,)."""
        return self.coulomb + (self.static - self.coulomb) * np.exp(
            -(np.asarray(v) / self.stribeck_velocity) ** 2)

    def steady_torque(self, v: np.ndarray) -> np.ndarray:
        """Friction torque at constant nonzero speed v (n,) [rad/s]: sign(v) F(v) + F_v v."""
        v = np.asarray(v, float)
        return np.sign(v) * self.slip_level(v) + self.viscous * v


def load_plant_friction(path: str | Path, joint_names: list[str]) -> tuple[FrictionMap,
                                                                           PlantFriction]:
    """Read a plant YAML (friction-map schema of irb_description.friction) -> map, plant model."""
    data = yaml.safe_load(Path(path).read_text())
    fm = friction_map_from_dict(data, joint_names)
    return fm, PlantFriction.from_map(fm)


def load_plant_brakes(path: str | Path | None, joints: int = 3) -> dict:
    """The ``brakes:`` section of a plant YAML as PlantConfig fields
    (``brake_torque_nm``, ``brake_release_s``); {} when the file has none (ideal brakes).
    ``joints`` 6: ``torque_nm`` (joints 1-3) followed by ``wrist_torque_nm`` (joints 4-6)."""
    if not path:
        return {}
    data = yaml.safe_load(Path(path).read_text())
    b = data.get('brakes') if isinstance(data, dict) else None
    if b is None:
        return {}
    try:
        torque = tuple(float(x) for x in b['torque_nm'])
        if joints == 6:
            torque += tuple(float(x) for x in b['wrist_torque_nm'])
        release = float(b.get('release_s', 0.0))
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f'{path}: brakes needs torque_nm (3 numbers), release_s'
                         f'{" and wrist_torque_nm (3 numbers)" if joints == 6 else ""}: '
                         f'{exc}') from None
    return {'brake_torque_nm': torque, 'brake_release_s': release}


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


#: substeps per period by joint count when PlantConfig.substeps is 0. Three joints: 5, the
#: thesis plant (its runs reproduce bit for bit). Six: 10, because the Stribeck level is
#: taken at the substep's old speed: joint 6 (M_66 = 0.025 kg m^2, its dip's slope up to 6.7
#: N m s/rad) breaking away at h = 0.806 ms left the continuous model by 0.4 mrad within 60
#: ms (h |dF/dv| / M = 0.21), and a v_s fitted to that motion came out 0.050 for 0.040 rad/s;
#: at h = 0.403 ms 0.03 mrad (irb_identification breakaway.py, doc/simulator.md).
DEFAULT_SUBSTEPS = {3: 5, 6: 10}


@dataclass(frozen=True)
class PlantConfig:
    """Plant settings (SI units). Arrays are (n,) over the model's joints (initial_q's
    default is the thesis's three-axis pose: six joints need their own)."""

    period_s: float = PERIOD_S
    substeps: int = 0                    # 0: DEFAULT_SUBSTEPS of the model's joint count
    delay_samples: int = 3
    initial_q: tuple = (0.0, 0.90, 0.25)
    command_timeout_s: float = 0.0121    # 3 periods, as the axis computer's miss limit
    encoder_resolution_rad: float = 2.0e-6
    position_noise_rad: float = 1.0e-6
    velocity_noise_rad_s: float = 1.0e-3
    camera_period_s: float = 0.01
    camera_noise_m: float = 37e-6
    seed: int = 1
    gs_iterations: int = 30
    brake_torque_nm: tuple | None = None  # holding torque per joint; None = holds any torque
    brake_release_s: float = 0.0          # torque acts this long on the closed brake first

    def __post_init__(self):
        if not (self.period_s > 0 and self.substeps >= 0 and self.delay_samples >= 1):
            raise ValueError('period_s > 0, substeps >= 0 (0: the default of the joint '
                             'count) and delay_samples >= 1 required')
        vals = [self.command_timeout_s, self.encoder_resolution_rad, self.position_noise_rad,
                self.velocity_noise_rad_s, self.camera_period_s, self.camera_noise_m,
                *self.initial_q]
        if not np.all(np.isfinite(vals)) or min(vals[:6]) < 0 or self.camera_period_s <= 0:
            raise ValueError(f'plant settings must be finite and >= 0: {self}')
        if self.brake_torque_nm is not None:
            b = np.asarray(self.brake_torque_nm, float)
            if b.ndim != 1 or not np.all(np.isfinite(b)) or np.any(b <= 0):
                raise ValueError(f'brake_torque_nm must be finite numbers > 0, got {b}')
        if not (math.isfinite(self.brake_release_s) and self.brake_release_s >= 0):
            raise ValueError(f'brake_release_s must be >= 0, got {self.brake_release_s}')


@dataclass
class Measurement:
    """One encoder sample: time t [s], q (n,) [rad], qd (n,) [rad/s], applied torque (n,)."""

    t: float
    q: np.ndarray
    qd: np.ndarray
    tau: np.ndarray


@dataclass
class PlantState:
    """True state: t [s], q (n,) [rad], qd (n,) [rad/s], energy [J] = int sum |tau qd| dt."""

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
        self.n = n = int(self._pm.nq)          # joints: 3 (thesis) or 6 (the whole arm)
        self.effects = effects or PlantEffects()
        if config.substeps == 0:
            config = replace(config, substeps=DEFAULT_SUBSTEPS.get(n, max(
                DEFAULT_SUBSTEPS.values())))
        if n != 3 and self.effects:
            raise ValueError(f'plant effects are modelled for the three-axis plant only, not '
                             f'{n} joints')
        for name, v in (('friction', friction.coulomb), ('initial_q', config.initial_q),
                        ('brake_torque_nm', config.brake_torque_nm)):
            if v is not None and len(v) != n:
                raise ValueError(f'{name} has {len(v)} joints, the model {n}')
        if n != 3:      # the n-joint substep (the three-joint one is unrolled for speed)
            self._substep = self._substep_n
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
        self._dfs = [self._fs[i] - self._fc[i] for i in range(n)]     # F_s - F_c
        # the same as arrays, for the n-joint substep
        self._fc_a, self._vs_a, self._fv_a = (np.asarray(x, float) for x in (
            self._fc, self._vs, self._fv))
        self._dfs_a = np.asarray(self._dfs, float)
        self.events: list[tuple[float, str]] = []
        self.camera: list[tuple[float, np.ndarray]] = []
        self.reset(np.asarray(config.initial_q, float))

    # --- state ---------------------------------------------------------------------------
    def reset(self, q: np.ndarray, qd: np.ndarray | None = None, t: float = 0.0) -> None:
        """Put the robot at q (n,) [rad] with speed qd (default 0), brakes on, no commands."""
        n = self.n
        self.state = PlantState(float(t), np.array(q, float),
                                np.zeros(n) if qd is None else np.array(qd, float), 0.0)
        self.rng = np.random.default_rng(self.config.seed)
        self._noise = np.empty((0, n))
        self._noise_i = 0
        self._pipeline: deque = deque([None] * self.config.delay_samples)
        self._latest: np.ndarray | None = None
        self._last_command_t = -math.inf
        self.applied = np.zeros(n)
        self.braked = True
        self.power_mode = 'brakes'   # settled power mode of the drives (POWER_MODES)
        self.mode_target: str | None = None     # a change under way: target ...
        self._mode_done_t = 0.0                 # ... reached at this time [s]
        self._auto_hold = True       # a command switches brakes -> hold (no explicit request)
        self._release_t: float | None = None    # the brakes open at this time [s]
        # the opening time applies to brakes engaged on purpose (start, power mode, fault),
        # not to a period without a command in the middle of a motion (released at once, as
        # before: the drive holds on; its timeout is what engages the brakes for good)
        self._slow_release = True
        self.rejected_mode = 0       # commands ignored because the motors were off
        self.error = ''              # latched fault ('' = none): commands ignored until cleared
        self.friction_torque = np.zeros(n)
        self._tau_t = [0.0] * n
        if self.effects:
            self._fx = EffectsRuntime(self.effects, self.friction.stribeck_velocity,
                                      self.config.period_s, self.config.substeps)
        self._next_camera_t = self.state.t
        self.camera.clear()
        self.steps = 0
        self.rejected_latched = 0

    def clear_error(self) -> str:
        """Clear a latched error (the brakes stay on until the next command); its text."""
        was, self.error = self.error, ''
        if was:
            self.events.append((self.state.t, f'error reset: {was}'))
        return was

    def request_power_mode(self, mode: str, duration_s: float = 0.0) -> tuple[bool, str]:
        """Change the drives' power mode (the axis computer's mode interface); the change
        takes ``duration_s`` [s] of plant time (the transition). Deeper modes engage the
        brakes at once and switch the torque off; commands are ignored until hold is
        requested again. Refused while a change is under way, and hold while an error is
        latched. (ok, text)"""
        if mode not in POWER_MODES:
            return False, f'unknown power mode {mode!r} (one of {list(POWER_MODES)})'
        t = self.state.t
        if self.mode_target is not None:
            return False, (f'a change to {self.mode_target} is under way (done at t = '
                           f'{self._mode_done_t:.3f} s)')
        if mode == self.power_mode:
            self._auto_hold = mode == 'hold'       # asked for: no command powers them on
            return True, f'already in {mode}'
        if mode == 'hold' and self.error:
            return False, f'error latched ({self.error}): reset first'
        if mode != 'hold':
            self.braked = True
            self._slow_release = True
            self._release_t = None
            self._latest = None
            self._pipeline = deque([None] * self.config.delay_samples)
            self.applied = np.zeros(self.n)
            self._auto_hold = False
        self.mode_target = mode
        self._mode_done_t = t + max(float(duration_s), 0.0)
        self.events.append((t, f'power mode {self.power_mode} -> {mode} requested '
                               f'({duration_s:.3f} s)'))
        self._settle_mode()
        return True, f'{self.power_mode} -> {mode}' + (
            f' in {duration_s:.3f} s' if self.mode_target is not None else '')

    @property
    def motors_off_requested(self) -> bool:
        """The motors are off on request (a deeper mode, or a change under way): no
        command is expected."""
        return (self.mode_target is not None) or (self.power_mode != 'hold'
                                                  and not self._auto_hold)

    def _settle_mode(self) -> None:
        if self.mode_target is not None and self.state.t >= self._mode_done_t - 1e-12:
            self.events.append((self.state.t, f'power mode {self.mode_target} reached'))
            self.power_mode, self.mode_target = self.mode_target, None
            if self.power_mode == 'hold':
                self._auto_hold = True

    def command(self, tau: np.ndarray) -> None:
        """Hand over the torque command (n,) [N m] answering the latest measurement.

        Non-finite or wrongly shaped commands are ignored (as a drive would reject them).
        """
        tau = np.asarray(tau, float)
        if tau.shape != (self.n,) or not all(map(math.isfinite, tau.tolist())):
            self.events.append((self.state.t, f'rejected invalid command {tau!r}'))
            return
        if self.error:
            self.rejected_latched += 1
            return
        if self.power_mode != 'hold' or self.mode_target is not None:
            if self._auto_hold and self.power_mode == 'brakes' and self.mode_target is None:
                # the first torque command powers the drives (as before power modes existed)
                self.events.append((self.state.t, 'power mode brakes -> hold (a command)'))
                self.power_mode = 'hold'
            else:
                self.rejected_mode += 1
                return
        self._latest = tau.copy()
        self._last_command_t = self.state.t

    # --- sensors -------------------------------------------------------------------------
    def _gauss(self) -> np.ndarray:
        if self._noise_i >= len(self._noise):
            self._noise = self.rng.standard_normal((4096, self.n))
            self._noise_i = 0
        self._noise_i += 1
        return self._noise[self._noise_i - 1]

    def measure(self) -> Measurement:
        """Encoder sample of the current state (quantised, noisy) and the applied torque."""
        c = self.config
        s = self.state
        # element-wise in floats (the same IEEE operations as on the arrays; round() is
        # round-half-even like np.round)
        pn, res, vn = c.position_noise_rad, c.encoder_resolution_rad, c.velocity_noise_rad_s
        if self.n != 3:
            return self._measure_n(pn, res, vn)
        n0, n1, n2 = self._gauss().tolist()
        q0, q1, q2 = s.q.tolist()
        q = [q0 + pn * n0, q1 + pn * n1, q2 + pn * n2]
        if res > 0:
            q = [round(x / res) * res if math.isfinite(x) else x / res * res for x in q]
        n0, n1, n2 = self._gauss().tolist()
        v0, v1, v2 = s.qd.tolist()
        return Measurement(s.t, np.array(q), np.array((v0 + vn * n0, v1 + vn * n1,
                                                       v2 + vn * n2)), self.applied.copy())

    def _measure_n(self, pn: float, res: float, vn: float) -> Measurement:
        """``measure`` on n joints (the same operations per joint)."""
        s = self.state
        nz = self._gauss().tolist()
        q = [x + pn * e for x, e in zip(s.q.tolist(), nz)]
        if res > 0:
            q = [round(x / res) * res if math.isfinite(x) else x / res * res for x in q]
        nz = self._gauss().tolist()
        return Measurement(s.t, np.array(q), np.array([x + vn * e for x, e in
                                                       zip(s.qd.tolist(), nz)]),
                           self.applied.copy())

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
        self._settle_mode()
        stale = s.t - self._last_command_t > c.command_timeout_s + 1e-9
        if stale and self._latest is not None:
            self.error = (f'no command for {s.t - self._last_command_t:.4f} s '
                          f'(> {c.command_timeout_s} s)')
            self.events.append((s.t, f'{self.error}: brakes engaged, torque 0, error latched '
                                     'until reset'))
            self._latest = None
            self._pipeline = deque([None] * c.delay_samples)
            self.power_mode = 'brakes'           # power stages off on a fault
            self._slow_release = True
        self._pipeline.append(self._latest)
        applied = self._pipeline.popleft()
        if applied is None:
            if not self.braked:
                self.braked = True
            self._release_t = None
            self.applied = np.zeros(self.n)
        else:
            if self.braked:
                if self._release_t is None:      # torque on the closed brake from now on
                    self._release_t = s.t + (c.brake_release_s if self._slow_release
                                             else 0.0)
                if s.t >= self._release_t - 1e-12:
                    self.events.append((s.t, 'command received: brakes released'
                                        + (f' after {c.brake_release_s:.3f} s of torque'
                                           if c.brake_release_s and self._slow_release
                                           else '')))
                    self.braked = False
                    self._release_t = None
                    self._slow_release = False
            self.applied = applied
        t0 = s.t
        tau = self.applied.tolist()
        taus = [tau] * c.substeps
        if self._fx is not None and self._fx.delay_substeps:
            taus, self.applied = self._fx.delayed_torques(self.applied)
        for j in range(c.substeps):
            q_prev = s.q
            self._substep(taus[j])
            if self._next_camera_t <= s.t + 1e-12:      # a camera instant in this substep
                self._camera(q_prev)
        s.t = t0 + c.period_s
        self.steps += 1
        self._settle_mode()

    def _substep(self, tau: list) -> None:
        """One semi-implicit Euler substep of h [s]; tau (3,) list [N m].

        Plain Python floats inside, unrolled over the 3 joints: the 3-vectors are far cheaper
        as floats than as numpy arrays (this is the simulator's hot loop). The arithmetic is
        the same, in the same order, as the documented equations (bit-for-bit: tested against
        the generic active-set solver ``_solve_dry_friction``)."""
        s = self.state
        h = self._h
        brake = self.config.brake_torque_nm if self.braked else None
        if self.braked and brake is None:       # an ideal brake: holds any torque
            s.qd = np.zeros(3)
            self.friction_torque = np.zeros(3)
            s.t += h
            return
        q, v = s.q, s.qd
        (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = pin.computeMinverse(
            self._pm, self._pd, q).tolist()
        # W = h M^-1 (Delassus matrix of the dry friction)
        w00, w01, w02 = h * m00, h * m01, h * m02
        w10, w11, w12 = h * m10, h * m11, h * m12
        w20, w21, w22 = h * m20, h * m21, h * m22
        b0, b1, b2 = pin.nonLinearEffects(self._pm, self._pd, q, v).tolist()   # C v + g
        vl = v.tolist()
        v0, v1, v2 = vl
        t0, t1, t2 = tau
        fv0, fv1, fv2 = self._fv
        r0 = t0 - b0 - fv0 * v0
        r1 = t1 - b1 - fv1 * v1
        r2 = t2 - b2 - fv2 * v2
        fx = self._fx
        if fx is not None and fx.has_torque:
            x = fx.extra_torque(q.tolist(), vl, s.t)
            r0, r1, r2 = r0 - x[0], r1 - x[1], r2 - x[2]
        # free velocity (no dry friction)
        vf0 = v0 + w00 * r0 + w01 * r1 + w02 * r2
        vf1 = v1 + w10 * r0 + w11 * r1 + w12 * r2
        vf2 = v2 + w20 * r0 + w21 * r1 + w22 * r2
        fc0, fc1, fc2 = self._fc
        dfs0, dfs1, dfs2 = self._dfs
        vs0, vs1, vs2 = self._vs
        exp = math.exp
        bd0 = fc0 + dfs0 * exp(-(v0 / vs0) ** 2)
        bd1 = fc1 + dfs1 * exp(-(v1 / vs1) ** 2)
        bd2 = fc2 + dfs2 * exp(-(v2 / vs2) ** 2)
        if fx is not None and fx.stribeck is not None:
            bd0, bd1, bd2 = fx.dry_level(vl, [bd0, bd1, bd2])
        if brake is not None:      # an engaged brake: one more dry-friction element
            bd0, bd1, bd2 = bd0 + brake[0], bd1 + brake[1], bd2 + brake[2]
        # fast path of the active-set solver: every joint slides on its own and keeps the
        # direction of its free velocity with lambda_i = sign(vf_i) F_i (the first pattern
        # ``_solve_dry_friction`` tries, accepted there under exactly the same test)
        vn = None
        if (abs(vf0) > w00 * bd0 and abs(vf1) > w11 * bd1 and abs(vf2) > w22 * bd2):
            sgn = math.copysign
            s0, s1, s2 = sgn(1.0, vf0), sgn(1.0, vf1), sgn(1.0, vf2)
            l0, l1, l2 = s0 * bd0, s1 * bd1, s2 * bd2
            n0 = vf0 - w00 * l0 - w01 * l1 - w02 * l2
            n1 = vf1 - w10 * l0 - w11 * l1 - w12 * l2
            n2 = vf2 - w20 * l0 - w21 * l1 - w22 * l2
            if n0 * s0 >= 0.0 and n1 * s1 >= 0.0 and n2 * s2 >= 0.0:
                lam = [l0, l1, l2]
                vn = [n0, n1, n2]
        elif (abs(vf0) <= w00 * bd0 and abs(vf1) <= w11 * bd1 and abs(vf2) <= w22 * bd2):
            # ... and when every joint sticks on its own: lambda = W^-1 vf, accepted if it
            # stays inside every friction bound (again the solver's first pattern and test)
            W = [[w00, w01, w02], [w10, w11, w12], [w20, w21, w22]]
            lam = _solve_small(W, [vf0, vf1, vf2])
            l0, l1, l2 = lam
            if (abs(l0) <= bd0 * (1.0 + 1e-12) and abs(l1) <= bd1 * (1.0 + 1e-12)
                    and abs(l2) <= bd2 * (1.0 + 1e-12)):
                vn = [vf0 - w00 * l0 - w01 * l1 - w02 * l2,
                      vf1 - w10 * l0 - w11 * l1 - w12 * l2,
                      vf2 - w20 * l0 - w21 * l1 - w22 * l2]
        if vn is None:
            W = [[w00, w01, w02], [w10, w11, w12], [w20, w21, w22]]
            lam = self._solve_dry_friction(W, [vf0, vf1, vf2], [bd0, bd1, bd2])
            l0, l1, l2 = lam
            vn = [vf0 - w00 * l0 - w01 * l1 - w02 * l2,
                  vf1 - w10 * l0 - w11 * l1 - w12 * l2,
                  vf2 - w20 * l0 - w21 * l1 - w22 * l2]
        # sticking joints come out at ~1e-17 rad/s; make them exactly zero
        n0, n1, n2 = vn
        if abs(n0) < 1e-12:
            n0 = 0.0
        if abs(n1) < 1e-12:
            n1 = 0.0
        if abs(n2) < 1e-12:
            n2 = 0.0
        q0, q1, q2 = q.tolist()
        s.q = np.array((q0 + h * n0, q1 + h * n1, q2 + h * n2))
        s.qd = np.array((n0, n1, n2))
        self._lam = lam
        self._vprev = vl
        if fx is not None and fx.link_side:
            # torque through the gear: applied minus everything on the motor side
            xt = x if fx.has_torque else [0.0, 0.0, 0.0]
            self._tau_t = [t0 - lam[0] - fv0 * v0 - xt[0], t1 - lam[1] - fv1 * v1 - xt[1],
                           t2 - lam[2] - fv2 * v2 - xt[2]]
        s.energy += h * (abs(t0 * n0) + abs(t1 * n1) + abs(t2 * n2))
        s.t += h

    def _substep_n(self, tau: list) -> None:
        """``_substep`` on n joints (the six-joint arm): the same equations on n-vectors,
        numpy's products for W r and W lambda (so not the same bits as the unrolled
        three-joint substep; equal to ~1e-12, tested), the dry friction by
        ``_solve_dry_friction_n``."""
        s = self.state
        h = self._h
        n = self.n
        brake = self.config.brake_torque_nm if self.braked else None
        if self.braked and brake is None:       # an ideal brake: holds any torque
            s.qd = np.zeros(n)
            self.friction_torque = np.zeros(n)
            s.t += h
            return
        q, v = s.q, s.qd
        W = h * pin.computeMinverse(self._pm, self._pd, q)   # h M^-1 (Delassus matrix)
        tau_a = np.asarray(tau, float)
        r = tau_a - pin.nonLinearEffects(self._pm, self._pd, q, v) - self._fv_a * v
        vf = v + W @ r
        bd = self._fc_a + self._dfs_a * np.exp(-(v / self._vs_a) ** 2)
        if brake is not None:      # an engaged brake: one more dry-friction element
            bd = bd + np.asarray(brake, float)
        lam = self._solve_dry_friction_n(W, vf, bd)
        vn = vf - W @ lam
        vn[np.abs(vn) < 1e-12] = 0.0      # sticking joints: exactly zero
        s.q = q + h * vn
        s.qd = vn
        self._lam = lam.tolist()
        self._vprev = v.tolist()
        s.energy += h * float(np.sum(np.abs(tau_a * vn)))
        s.t += h

    def _solve_dry_friction_n(self, W: np.ndarray, vf: np.ndarray, bound: np.ndarray
                              ) -> np.ndarray:
        """``_solve_dry_friction`` on n joints with numpy: lambda (n,) [N m] with
        v+ = vf - W lambda, per joint stick (v+_i = 0, |lambda_i| <= bound_i) or slide
        (lambda_i = sign(v+_i) bound_i); the same active-set iteration, then projected
        Gauss-Seidel as the fallback."""
        n = self.n
        diag = W.diagonal()
        sign = np.where(np.abs(vf) <= diag * bound, 0.0, np.sign(vf))
        # (array methods and boolean rows/columns instead of np.any / np.ix_, and one
        # sticking joint by a division: the same values, a third of the time on 6 joints)
        for _ in range(2 * n):
            lam = sign * bound
            stick = sign == 0.0
            if stick.any():
                slide = ~stick
                rows = W[stick]
                rhs = vf[stick] - rows[:, slide] @ lam[slide]
                if rhs.size == 1:
                    lam[stick] = rhs / rows[:, stick][0]
                else:
                    lam[stick] = np.linalg.solve(rows[:, stick], rhs)
            v = vf - W @ lam
            flip_out = stick & (np.abs(lam) > bound * (1.0 + 1e-12))
            flip_in = ~stick & (v * sign < 0.0)
            if not (flip_out.any() or flip_in.any()):
                return lam
            sign = np.where(flip_out, np.sign(lam), np.where(flip_in, 0.0, sign))
        lam = np.zeros(n)
        for _ in range(self.config.gs_iterations):
            for i in range(n):
                vi0 = vf[i] - W[i] @ lam + W[i, i] * lam[i]
                lam[i] = (vi0 / W[i, i] if abs(vi0) <= W[i, i] * bound[i]
                          else math.copysign(bound[i], vi0))
        return lam

    @property
    def friction_torque(self) -> np.ndarray:
        """Friction torque (n,) [N m] of the last substep (dry + viscous)."""
        return np.array([self._lam[i] + self._fv[i] * self._vprev[i]
                         for i in range(len(self._lam))])

    @friction_torque.setter
    def friction_torque(self, value) -> None:
        self._lam = list(np.asarray(value, float))
        self._vprev = [0.0] * len(self._lam)

    def _solve_dry_friction(self, W: list, vf: list, bound: list) -> list:
        """Dry-friction torques lambda (3,) [N m] with v+ = vf - W lambda (W = h M^-1).

        Complementarity per joint: v+_i = 0 and |lambda_i| <= bound_i (stick), or
        lambda_i = sign(v+_i) bound_i with sign(v+_i) = sign(lambda_i) (slide). Active-set
        iteration over the stick/slide pattern (3 joints: converges in a few passes; a
        projected Gauss-Seidel sweep is the fallback).
        """
        # initial pattern: a joint slides if it would slide on its own
        # (explicit loops instead of comprehensions: this runs in the plant's hot loop)
        copysign = math.copysign
        sign = [0.0, 0.0, 0.0]
        for i in (0, 1, 2):
            if not abs(vf[i]) <= W[i][i] * bound[i]:
                sign[i] = copysign(1.0, vf[i])
        for _ in range(6):
            lam = [sign[0] * bound[0], sign[1] * bound[1], sign[2] * bound[2]]
            stick = []
            slide = []
            for i in (0, 1, 2):
                (stick if sign[i] == 0.0 else slide).append(i)
            if stick:
                rhs = []
                for i in stick:
                    Wi = W[i]
                    acc = 0.0               # sum of W_ij lambda_j over the sliding joints
                    for j in slide:
                        acc += Wi[j] * lam[j]
                    rhs.append(vf[i] - acc)
                sol = _solve_small([[W[i][j] for j in stick] for i in stick], rhs)
                for k, i in enumerate(stick):
                    lam[i] = sol[k]
            changed = False
            for i in (0, 1, 2):
                if sign[i] == 0.0:
                    if abs(lam[i]) > bound[i] * (1.0 + 1e-12):
                        sign[i] = copysign(1.0, lam[i])
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
