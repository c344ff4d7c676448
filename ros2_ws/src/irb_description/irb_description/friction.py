"""Joint friction maps: parametric Coulomb + viscous + Stribeck, optional polynomials.

A friction map gives the arm-side friction torque tau_f(v) [N m] of each actuated joint as a
function of joint speed v [rad/s] (thesis ch. 4). File schema (YAML, version 1)::

    friction_map:
      version: 1
      source: nominal            # free text: 'nominal', bag names, date ...
      joints:
        joint_1:
          coulomb: 18.0          # F_c [N m]
          static: 24.0           # F_s [N m], breakaway level (>= F_c; = F_c: no Stribeck dip)
          stribeck_velocity: 0.05  # v_s [rad/s]
          viscous: 25.0          # F_v [N m s/rad]
          valid_range: [0.02, 2.0]  # |v| [rad/s] where the map was identified
          # optional: polynomials of order 5-7 fitted per sign (eq. 4.8 data), coefficients in
          # increasing powers of v, used inside valid_range; outside it the parametric model.
          polynomial_positive: [c0, c1, ...]
          polynomial_negative: [c0, c1, ...]
          # optional: 95 % confidence half-widths of the parametric parameters
          ci95: {coulomb: 0.4, viscous: 0.3, static: 0.5, stribeck_velocity: 0.01}

Parametric model: tau_f(v) = sign(v) (F_c + (F_s - F_c) exp(-(v / v_s)^2)) + F_v v.
No ROS imports; the CasADi form uses a smooth sign so the planner gets derivatives.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

SCHEMA_VERSION = 1


@dataclass(frozen=True)
class JointFriction:
    """Friction of one joint, SI units (see module docstring)."""

    coulomb: float
    static: float
    stribeck_velocity: float
    viscous: float
    valid_range: tuple[float, float] = (0.0, float('inf'))
    polynomial_positive: tuple[float, ...] | None = None
    polynomial_negative: tuple[float, ...] | None = None
    ci95: dict = field(default_factory=dict)

    def parametric(self, v: np.ndarray) -> np.ndarray:
        """Parametric tau_f(v) [N m] for speeds ``v`` [rad/s] (any shape)."""
        v = np.asarray(v, float)
        stribeck = (self.static - self.coulomb) * np.exp(-(v / self.stribeck_velocity) ** 2)
        return np.sign(v) * (self.coulomb + stribeck) + self.viscous * v

    def torque(self, v: np.ndarray) -> np.ndarray:
        """tau_f(v) [N m]: the polynomials inside ``valid_range`` if given, else parametric."""
        v = np.asarray(v, float)
        out = self.parametric(v)
        if self.polynomial_positive is None or self.polynomial_negative is None:
            return out
        lo, hi = self.valid_range
        speed = np.abs(v)
        inside = (speed >= lo) & (speed <= hi)
        pos = inside & (v > 0)
        neg = inside & (v < 0)
        out = np.where(pos, np.polynomial.polynomial.polyval(v, self.polynomial_positive), out)
        out = np.where(neg, np.polynomial.polynomial.polyval(v, self.polynomial_negative), out)
        return out


@dataclass(frozen=True)
class FrictionMap:
    """Friction of the actuated joints, in joint order."""

    joint_names: tuple[str, ...]
    joints: tuple[JointFriction, ...]
    source: str = 'nominal'

    def torque(self, v: np.ndarray) -> np.ndarray:
        """tau_f (n,) [N m] for joint speeds ``v`` (n,) [rad/s]; (..., n) also works."""
        v = np.asarray(v, float)
        return np.stack([j.torque(v[..., i]) for i, j in enumerate(self.joints)], axis=-1)

    def valid_range(self) -> np.ndarray:
        """(n, 2) |v| ranges [rad/s] where each joint's map is valid."""
        return np.array([j.valid_range for j in self.joints], float)

    def casadi_torque(self, v, smoothing: float = 1e-3):
        """tau_f as a CasADi expression of ``v`` (n,), parametric part only.

        sign(v) is replaced by tanh(v / smoothing) [smoothing in rad/s] so the planner's
        NLP has continuous derivatives; the error is below 1e-6 N m for |v| > 10 smoothing.
        """
        import casadi as ca
        out = []
        for i, j in enumerate(self.joints):
            vi = v[i]
            sgn = ca.tanh(vi / smoothing)
            stribeck = (j.static - j.coulomb) * ca.exp(-(vi / j.stribeck_velocity) ** 2)
            out.append(sgn * (j.coulomb + stribeck) + j.viscous * vi)
        return ca.vertcat(*out)

    def scaled(self, factor: float) -> 'FrictionMap':
        """Every torque multiplied by ``factor`` (for 'wrong model' experiments)."""
        return FrictionMap(self.joint_names, tuple(
            replace(j, coulomb=j.coulomb * factor, static=j.static * factor,
                    viscous=j.viscous * factor,
                    polynomial_positive=None if j.polynomial_positive is None else tuple(
                        c * factor for c in j.polynomial_positive),
                    polynomial_negative=None if j.polynomial_negative is None else tuple(
                        c * factor for c in j.polynomial_negative))
            for j in self.joints), f'{self.source} x{factor:g}')

    # --- files -------------------------------------------------------------------------
    def to_dict(self) -> dict:
        joints = {}
        for name, j in zip(self.joint_names, self.joints):
            d = {'coulomb': float(j.coulomb), 'static': float(j.static),
                 'stribeck_velocity': float(j.stribeck_velocity), 'viscous': float(j.viscous),
                 'valid_range': [float(x) for x in j.valid_range]}
            if j.polynomial_positive is not None:
                d['polynomial_positive'] = [float(c) for c in j.polynomial_positive]
            if j.polynomial_negative is not None:
                d['polynomial_negative'] = [float(c) for c in j.polynomial_negative]
            if j.ci95:
                d['ci95'] = {k: float(v) for k, v in j.ci95.items()}
            joints[name] = d
        return {'friction_map': {'version': SCHEMA_VERSION, 'source': self.source,
                                 'joints': joints}}

    def save(self, path: str | Path) -> None:
        """Write the map as YAML (schema in the module docstring)."""
        Path(path).write_text(yaml.safe_dump(self.to_dict(), sort_keys=False))


class FrictionMapError(ValueError):
    """A friction-map file is missing, unreadable or inconsistent."""


def _joint_from_dict(name: str, d: dict) -> JointFriction:
    try:
        jf = JointFriction(
            coulomb=float(d['coulomb']), static=float(d.get('static', d['coulomb'])),
            stribeck_velocity=float(d.get('stribeck_velocity', 0.05)),
            viscous=float(d['viscous']),
            valid_range=tuple(float(x) for x in d.get('valid_range', (0.0, float('inf')))),
            polynomial_positive=(tuple(float(c) for c in d['polynomial_positive'])
                                 if 'polynomial_positive' in d else None),
            polynomial_negative=(tuple(float(c) for c in d['polynomial_negative'])
                                 if 'polynomial_negative' in d else None),
            ci95=dict(d.get('ci95', {})))
    except (KeyError, TypeError, ValueError) as exc:
        raise FrictionMapError(f'joint {name}: bad or missing field ({exc})') from exc
    values = [jf.coulomb, jf.static, jf.stribeck_velocity, jf.viscous, *jf.valid_range]
    if not np.all(np.isfinite(values[:-1])) or np.isnan(values[-1]):
        raise FrictionMapError(f'joint {name}: non-finite parameter')
    if jf.stribeck_velocity <= 0 or jf.valid_range[0] > jf.valid_range[1]:
        raise FrictionMapError(f'joint {name}: stribeck_velocity <= 0 or empty valid_range')
    return jf


def friction_map_from_dict(data: dict, joint_names: list[str] | None = None) -> FrictionMap:
    """Parse the ``friction_map`` mapping; ``joint_names`` fixes the order and checks presence."""
    try:
        fm = data['friction_map']
        version = int(fm.get('version', SCHEMA_VERSION))
        joints = fm['joints']
    except (KeyError, TypeError, AttributeError) as exc:
        raise FrictionMapError(f'not a friction map: missing {exc}') from exc
    if version != SCHEMA_VERSION:
        raise FrictionMapError(f'friction map version {version}, expected {SCHEMA_VERSION}')
    names = list(joint_names) if joint_names is not None else list(joints)
    missing = [n for n in names if n not in joints]
    if missing:
        raise FrictionMapError(f'friction map has no entry for {missing}')
    return FrictionMap(tuple(names), tuple(_joint_from_dict(n, joints[n]) for n in names),
                       str(fm.get('source', '')))


def load_friction_map(path: str | Path, joint_names: list[str] | None = None) -> FrictionMap:
    """Read a friction-map YAML; raises FrictionMapError with the reason on any problem."""
    path = Path(path)
    if not path.is_file():
        raise FrictionMapError(f'friction map {path} does not exist')
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise FrictionMapError(f'friction map {path} unreadable: {exc}') from exc
    if not isinstance(data, dict):
        raise FrictionMapError(f'friction map {path}: not a YAML mapping')
    return friction_map_from_dict(data, joint_names)


def nominal_friction_map(block: dict, joint_names: list[str]) -> FrictionMap:
    """The nominal map from the ``friction`` block of config/dynamics.yaml."""
    lo, hi = block['valid_range_rad_s']
    joints = tuple(
        JointFriction(coulomb=float(c), static=float(s), stribeck_velocity=float(vs),
                      viscous=float(fv), valid_range=(float(lo), float(hi)))
        for c, s, vs, fv in zip(block['coulomb_nm'], block['static_nm'],
                                block['stribeck_velocity_rad_s'], block['viscous_nms_rad']))
    if len(joints) != len(joint_names):
        raise FrictionMapError(f'nominal friction has {len(joints)} joints, '
                               f'expected {len(joint_names)}')
    return FrictionMap(tuple(joint_names), joints, 'nominal (irb_description dynamics.yaml)')
