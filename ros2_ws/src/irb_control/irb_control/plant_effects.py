"""Extra physical effects of the simulated plant, switched on from the plant YAML (no ROS).

The nominal model (irb_description + a friction map) knows rigid-body dynamics and
Coulomb + viscous + Stribeck friction. The plant can add, one or several at a time, the
effects below (names exactly as in DESIGN.md §8). All quantities are arm side, SI units;
per-joint parameters are lists of 3 (joints 1-3). With the robot equation written as

    M(q) qdd + C(q, qd) qd + g(q) + tau_f(qd) + tau_x(q, qd, t) = tau        (tau = applied)

the effects are:

=========================== ==================================================================
name                        model (parameters)
=========================== ==================================================================
stribeck                    dry-friction level F(v) += dF_s exp(-(v / v_x)^2): a stronger
                            Stribeck hump (``static_increase_nm`` dF_s, ``velocity_rad_s``
                            v_x); solved inside the stick-slip model, so breakaway rises too
coulomb_asymmetry           Coulomb level F_c + delta for v > 0, F_c - delta for v < 0, the
                            static level symmetric: tau_x = delta (1 - exp(-(v / v_s)^2)),
                            v_s the plant friction's Stribeck speed (``delta_nm``)
torque_offset               tau_x = tau_0, constant, also at rest (``offset_nm``)
viscous_nonlinear           tau_x = c sign(v) |v|^n (``coefficient`` [N m (s/rad)^n],
                            ``exponent`` n, default 2)
payload_mass                point mass m at ``offset_m`` (tool0 frame) on the last link:
                            changes M, C and g (``mass_kg``, ``offset_m``)
rotor_inertia               extra armature J_a on the diagonal of M (= J_m N^2 of a rotor J_m
                            behind gear ratio N) (``armature_kgm2``)
time_delay                  the torque acts ``extra_delay_s`` later than the nominal
                            3-sample pipeline (substep resolution h = T / substeps); the
                            reported effort is the torque acting (mean over the period)
cogging                     tau_x = A sin(2 pi q / P + phi) (``amplitude_nm`` A,
                            ``period_rad`` P, ``phase_rad`` phi)
backlash                    link side q_L = q - b tanh(tau_t / tau_e): the gear rests on the
                            flank the transmitted torque tau_t pushes against
                            (``half_width_rad`` b, ``torque_smoothing_nm`` tau_e, default 2)
joint_elasticity            quasi-static gear compliance: q_L = q - tau_t / K
                            (``stiffness_nm_rad`` K; .inf = rigid)
viscous_temperature_drift   cold gearbox oil: tau_x = dF_v exp(-(t - t_0) / T_th) v
                            (``cold_extra_viscous_nms_rad`` dF_v, ``time_constant_s`` T_th,
                            ``t0_s`` t_0 = plant time of the cold start, default 0)
=========================== ==================================================================

Encoders sit on the motor side (the plant state q is what they measure); the camera sees the
link side. Backlash and elasticity therefore change only the camera channel (thesis §2.2):
tau_t, the torque through the gear, is tau - tau_f - tau_x of the last substep.

YAML (a section of the plant YAML next to ``friction_map:``, or a file of its own)::

    effects:
      torque_offset: {offset_nm: [0.0, 6.0, 0.0]}
      joint_elasticity: {stiffness_nm_rad: [.inf, 2.0e5, 1.0e5]}
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
import yaml

EFFECT_NAMES = ('stribeck', 'coulomb_asymmetry', 'torque_offset', 'viscous_nonlinear',
                'payload_mass', 'rotor_inertia', 'time_delay', 'cogging', 'backlash',
                'joint_elasticity', 'viscous_temperature_drift')
NONE = 'none'
#: effects seen by the camera only (link side)
LINK_SIDE_EFFECTS = ('backlash', 'joint_elasticity')


class EffectsError(ValueError):
    """An effects section is malformed (unknown name or parameter, wrong shape, bad value)."""


def _vec(name: str, value, n: int = 3, allow_inf: bool = False) -> tuple[float, ...]:
    def num(x):
        return float(x.strip().replace('.inf', 'inf')) if isinstance(x, str) else float(x)
    try:
        arr = np.array([num(x) for x in np.atleast_1d(np.asarray(value, object)).ravel()])
    except (TypeError, ValueError) as exc:
        raise EffectsError(f'{name}: not numbers: {value!r}') from exc
    if arr.size == 1:
        arr = np.repeat(arr, n)
    if arr.shape != (n,):
        raise EffectsError(f'{name}: expected {n} values, got {value!r}')
    if np.any(np.isnan(arr)) or (not allow_inf and not np.all(np.isfinite(arr))):
        raise EffectsError(f'{name}: non-finite value in {value!r}')
    return tuple(float(x) for x in arr)


# --- parameter blocks (one dataclass per effect, SI units) --------------------------------
@dataclass(frozen=True)
class Stribeck:
    static_increase_nm: tuple = (0.0, 0.0, 0.0)
    velocity_rad_s: tuple = (0.1, 0.1, 0.1)


@dataclass(frozen=True)
class CoulombAsymmetry:
    delta_nm: tuple = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class TorqueOffset:
    offset_nm: tuple = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class ViscousNonlinear:
    coefficient: tuple = (0.0, 0.0, 0.0)
    exponent: float = 2.0


@dataclass(frozen=True)
class PayloadMass:
    mass_kg: float = 0.0
    offset_m: tuple = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class RotorInertia:
    armature_kgm2: tuple = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class TimeDelay:
    extra_delay_s: float = 0.0


@dataclass(frozen=True)
class Cogging:
    amplitude_nm: tuple = (0.0, 0.0, 0.0)
    period_rad: tuple = (0.1, 0.1, 0.1)
    phase_rad: tuple = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Backlash:
    half_width_rad: tuple = (0.0, 0.0, 0.0)
    torque_smoothing_nm: float = 2.0


@dataclass(frozen=True)
class JointElasticity:
    stiffness_nm_rad: tuple = (math.inf, math.inf, math.inf)


@dataclass(frozen=True)
class ViscousTemperatureDrift:
    cold_extra_viscous_nms_rad: tuple = (0.0, 0.0, 0.0)
    time_constant_s: float = 300.0
    t0_s: float = 0.0


EFFECT_CLASSES = {
    'stribeck': Stribeck, 'coulomb_asymmetry': CoulombAsymmetry,
    'torque_offset': TorqueOffset, 'viscous_nonlinear': ViscousNonlinear,
    'payload_mass': PayloadMass, 'rotor_inertia': RotorInertia, 'time_delay': TimeDelay,
    'cogging': Cogging, 'backlash': Backlash, 'joint_elasticity': JointElasticity,
    'viscous_temperature_drift': ViscousTemperatureDrift,
}
_VECTOR_FIELDS = {'static_increase_nm', 'velocity_rad_s', 'delta_nm', 'offset_nm',
                  'coefficient', 'armature_kgm2', 'amplitude_nm', 'period_rad', 'phase_rad',
                  'half_width_rad', 'stiffness_nm_rad', 'cold_extra_viscous_nms_rad'}
_POSITIVE = {'velocity_rad_s', 'period_rad', 'torque_smoothing_nm', 'time_constant_s',
             'stiffness_nm_rad', 'exponent'}


def effect_from_dict(name: str, params: dict | None):
    """Parameter block of effect ``name`` from a mapping (missing fields: defaults)."""
    if name not in EFFECT_CLASSES:
        raise EffectsError(f'unknown effect {name!r}; known: {", ".join(EFFECT_NAMES)}')
    cls = EFFECT_CLASSES[name]
    params = dict(params or {})
    known = {f.name for f in fields(cls)}
    unknown = set(params) - known
    if unknown:
        raise EffectsError(f'{name}: unknown parameter(s) {sorted(unknown)}; '
                           f'known: {sorted(known)}')
    kw = {}
    for key, value in params.items():
        if key == 'offset_m':
            kw[key] = _vec(f'{name}.{key}', value)
        elif key in _VECTOR_FIELDS:
            kw[key] = _vec(f'{name}.{key}', value, allow_inf=key == 'stiffness_nm_rad')
        else:
            try:
                kw[key] = float(value)
            except (TypeError, ValueError) as exc:
                raise EffectsError(f'{name}.{key}: not a number: {value!r}') from exc
            if not math.isfinite(kw[key]):
                raise EffectsError(f'{name}.{key}: non-finite')
        vals = np.atleast_1d(kw[key])
        if key in _POSITIVE and np.any(vals <= 0):
            raise EffectsError(f'{name}.{key}: must be > 0, got {value!r}')
    if name == 'time_delay' and kw.get('extra_delay_s', 0.0) < 0:
        raise EffectsError('time_delay.extra_delay_s must be >= 0')
    if name == 'payload_mass' and kw.get('mass_kg', 0.0) < 0:
        raise EffectsError('payload_mass.mass_kg must be >= 0')
    return cls(**kw)


def effect_to_dict(block) -> dict:
    """Plain YAML-able mapping of one parameter block."""
    out = {}
    for f in fields(block):
        v = getattr(block, f.name)
        out[f.name] = [float(x) for x in v] if isinstance(v, tuple) else float(v)
    return out


@dataclass(frozen=True)
class PlantEffects:
    """The switched-on effects: ``blocks`` maps effect name -> parameter block."""

    blocks: dict = field(default_factory=dict)

    @classmethod
    def from_dict(cls, data: dict | None) -> 'PlantEffects':
        """From the ``effects`` mapping (name -> parameters); None/{} = no effects."""
        if data is None:
            return cls({})
        if not isinstance(data, dict):
            raise EffectsError(f'effects must be a mapping of name -> parameters, not {data!r}')
        return cls({name: effect_from_dict(name, p) for name, p in data.items()})

    def to_dict(self) -> dict:
        return {name: effect_to_dict(b) for name, b in self.blocks.items()}

    def __bool__(self) -> bool:
        return bool(self.blocks)

    def get(self, name: str):
        return self.blocks.get(name)

    def names(self) -> list[str]:
        return list(self.blocks)


def load_plant_effects(path: str | Path | None) -> PlantEffects:
    """The ``effects:`` section of a YAML file (a plant YAML or an effects file).

    A file without the section gives no effects; None or '' gives no effects.
    """
    if not path:
        return PlantEffects()
    data = yaml.safe_load(Path(path).read_text())
    if not isinstance(data, dict):
        raise EffectsError(f'{path}: not a YAML mapping')
    return PlantEffects.from_dict(data.get('effects'))


def save_effects(effects: PlantEffects, path: str | Path, extra: dict | None = None) -> None:
    """Write ``{**extra, 'effects': ...}`` as YAML (extra e.g. a friction_map section)."""
    data = dict(extra or {})
    data['effects'] = effects.to_dict()
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False))


# --- the plant's side: fast per-substep evaluation ------------------------------------------
class EffectsRuntime:
    """What Plant calls in its loop. Plain floats (3-lists) for speed; see module docstring.

    ``stribeck_velocity`` (3,) [rad/s] is the plant friction's v_s (coulomb_asymmetry).
    """

    def __init__(self, effects: PlantEffects, stribeck_velocity, period_s: float,
                 substeps: int):
        self.effects = effects
        e = effects.blocks
        self._vs = [float(x) for x in stribeck_velocity]
        self.has_torque = any(k in e for k in ('coulomb_asymmetry', 'torque_offset',
                                               'viscous_nonlinear', 'cogging',
                                               'viscous_temperature_drift'))
        self.stribeck = e.get('stribeck')
        self.link_side = any(k in e for k in LINK_SIDE_EFFECTS)
        h = period_s / substeps
        delay = e.get('time_delay')
        self.delay_substeps = int(round(delay.extra_delay_s / h)) if delay else 0
        self._substeps = substeps
        # history of the nominal applied torque per period (newest last)
        n_hist = self.delay_substeps // substeps + 2
        self._hist = [[0.0, 0.0, 0.0] for _ in range(n_hist)]

    # model changes (payload, armature) -----------------------------------------------------
    def apply_to_model(self, pm, tcp_frame: str = 'tool0') -> None:
        """Add payload mass and armature to the pinocchio model ``pm`` (in place)."""
        import pinocchio as pin
        e = self.effects.blocks
        ri = e.get('rotor_inertia')
        if ri is not None:
            pm.armature = np.asarray(pm.armature, float) + np.asarray(ri.armature_kgm2)
        pl = e.get('payload_mass')
        if pl is not None and pl.mass_kg > 0:
            frame = pm.frames[pm.getFrameId(tcp_frame)]
            c = frame.placement.act(np.asarray(pl.offset_m, float))
            jid = frame.parentJoint
            pm.inertias[jid] = pm.inertias[jid] + pin.Inertia(
                pl.mass_kg, c, np.zeros((3, 3)))

    # torques -------------------------------------------------------------------------------
    def extra_torque(self, q: list, v: list, t: float) -> list:
        """tau_x (3-list) [N m] at position q, speed v (3-lists), plant time t [s]."""
        e = self.effects.blocks
        x = [0.0, 0.0, 0.0]
        b = e.get('torque_offset')
        if b is not None:
            x = [x[i] + b.offset_nm[i] for i in range(3)]
        b = e.get('coulomb_asymmetry')
        if b is not None:
            x = [x[i] + (b.delta_nm[i] * (1.0 - math.exp(-(v[i] / self._vs[i]) ** 2))
                         if v[i] != 0.0 else 0.0) for i in range(3)]
        b = e.get('viscous_nonlinear')
        if b is not None:
            x = [x[i] + b.coefficient[i] * math.copysign(abs(v[i]) ** b.exponent, v[i])
                 for i in range(3)]
        b = e.get('cogging')
        if b is not None:
            x = [x[i] + b.amplitude_nm[i] * math.sin(2.0 * math.pi * q[i] / b.period_rad[i]
                                                     + b.phase_rad[i]) for i in range(3)]
        b = e.get('viscous_temperature_drift')
        if b is not None:
            f = math.exp(-max(t - b.t0_s, 0.0) / b.time_constant_s)
            x = [x[i] + b.cold_extra_viscous_nms_rad[i] * f * v[i] for i in range(3)]
        return x

    def dry_level(self, v: list, bound: list) -> list:
        """Dry-friction level with the extra Stribeck hump (3-list) [N m]."""
        b = self.stribeck
        return [bound[i] + b.static_increase_nm[i] * math.exp(-(v[i] / b.velocity_rad_s[i])
                                                              ** 2) for i in range(3)]

    # delay ----------------------------------------------------------------------------------
    def delayed_torques(self, applied: np.ndarray) -> tuple[list, np.ndarray]:
        """Per-substep torques (substeps x 3-list) for this period given the nominal pipeline
        output ``applied`` (3,), and their mean (what the drive reports as effort)."""
        S = self._substeps
        self._hist.pop(0)
        self._hist.append([float(x) for x in applied])
        n = len(self._hist)
        out = []
        for i in range(S):
            back = (self.delay_substeps - i + S - 1) // S     # periods back for substep i
            out.append(self._hist[n - 1 - back])
        return out, np.mean(np.array(out), axis=0)

    # link side --------------------------------------------------------------------------------
    def link_position(self, q: np.ndarray, tau_t: list) -> np.ndarray:
        """Link-side position (3,) [rad] from the motor-side q (3,) and gear torque tau_t."""
        e = self.effects.blocks
        out = np.array(q, float)
        b = e.get('backlash')
        if b is not None:
            out -= np.asarray(b.half_width_rad) * np.tanh(np.asarray(tau_t)
                                                          / b.torque_smoothing_nm)
        b = e.get('joint_elasticity')
        if b is not None:
            out -= np.asarray(tau_t) / np.asarray(b.stiffness_nm_rad)
        return out


#: moderate sizes used by tests and the benchmark (one entry per effect), SI units
MODERATE = {
    'stribeck': {'static_increase_nm': [8.0, 8.0, 4.0], 'velocity_rad_s': [0.15, 0.15, 0.15]},
    'coulomb_asymmetry': {'delta_nm': [4.0, 4.0, 2.0]},
    'torque_offset': {'offset_nm': [4.0, 4.0, 2.0]},
    'viscous_nonlinear': {'coefficient': [10.0, 10.0, 5.0], 'exponent': 2.0},
    'payload_mass': {'mass_kg': 3.0, 'offset_m': [0.0, 0.0, 0.05]},
    'rotor_inertia': {'armature_kgm2': [2.0, 2.0, 0.8]},
    'time_delay': {'extra_delay_s': 0.004032},
    'cogging': {'amplitude_nm': [4.0, 4.0, 2.0], 'period_rad': [0.12, 0.12, 0.12],
                'phase_rad': [0.0, 1.0, 2.0]},
    'backlash': {'half_width_rad': [2e-4, 2e-4, 2e-4], 'torque_smoothing_nm': 2.0},
    'joint_elasticity': {'stiffness_nm_rad': [4e5, 4e5, 2e5]},
    'viscous_temperature_drift': {'cold_extra_viscous_nms_rad': [12.0, 12.0, 6.0],
                                  'time_constant_s': 30.0},
}


def moderate_effect(name: str, scale: float = 1.0) -> PlantEffects:
    """One effect at its moderate size times ``scale`` (stiffness divided by it)."""
    p = {k: (list(v) if isinstance(v, list) else v) for k, v in MODERATE[name].items()}
    for key in ('static_increase_nm', 'delta_nm', 'offset_nm', 'coefficient', 'armature_kgm2',
                'amplitude_nm', 'half_width_rad', 'cold_extra_viscous_nms_rad'):
        if key in p:
            p[key] = [x * scale for x in p[key]]
    if name == 'payload_mass':
        p['mass_kg'] *= scale
    if name == 'time_delay':
        p['extra_delay_s'] *= scale
    if name == 'joint_elasticity':
        p['stiffness_nm_rad'] = [k / scale for k in p['stiffness_nm_rad']]
    return PlantEffects.from_dict({name: p})
