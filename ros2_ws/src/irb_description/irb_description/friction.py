"""Joint friction maps: parametric Coulomb + viscous + Stribeck, optional polynomials.

A friction map gives the arm-side friction torque tau_f(v) [N m] of each actuated joint as a
function of joint speed v [rad/s] (thesis ch. 4). File schema (YAML, version 1)::

    friction_map:
      version: 1
      source: nominal            # free text: 'nominal', bag names, date ...
      joints:
        joint_1:
          coulomb: 18.0          # F_c [N m], symmetric level ((F_c+ + F_c-) / 2 if both given)
          static: 24.0           # F_s [N m], breakaway level (>= F_c; = F_c: no Stribeck dip)
          stribeck_velocity: 0.05  # v_s [rad/s]
          viscous: 25.0          # F_v [N m s/rad]
          valid_range: [0.02, 2.0]  # |v| [rad/s] where the map was identified
          # optional (identified maps): asymmetric Coulomb levels (magnitudes, >= 0) and a
          # torque offset [N m] (signed, acts at every speed); absent = coulomb, coulomb, 0
          coulomb_positive: 18.5   # F_c+ [N m], level for v > 0
          coulomb_negative: 17.5   # F_c- [N m], level for v < 0
          static_positive: 24.0    # F_s+ [N m], breakaway for v > 0 (absent: F_s - F_c + F_c+)
          static_negative: 24.0    # F_s- [N m] (absent: F_s - F_c + F_c-)
          offset: 0.3              # tau_0 [N m]
          # optional: polynomials of order 5-7 fitted per sign (eq. 4.8 data), coefficients in
          # increasing powers of v, used inside valid_range; outside it the parametric model.
          polynomial_positive: [c0, c1, ...]
          polynomial_negative: [c0, c1, ...]
          # optional: 95 % confidence half-widths of the parametric parameters
          ci95: {coulomb: 0.4, viscous: 0.3, static: 0.5, stribeck_velocity: 0.01}
          # optional: the fit could not be trusted (written by identify, refused by the loader
          # unless allow_degenerate=True)
          degenerate: true
          degenerate_reason: 'stribeck_velocity 3.6 rad/s beyond the top speed 0.09 rad/s'
          # optional (identify, samples method): the model chosen by held-out error, every
          # candidate's score, v_min and its rule, bounded vs unbounded RMS; not used by loaders
          fit: {model: asymmetric_stribeck, candidates: {...}, v_min: 0.02, ...}

Parametric model, with e = exp(-(v / v_s)^2):

    tau_f(v) = tau_0 + F_v v + (F_c+ + (F_s+ - F_c+) e)    for v > 0
    tau_f(v) = tau_0 + F_v v - (F_c- + (F_s- - F_c-) e)    for v < 0,   tau_0 at v = 0.

Without ``static_positive``/``static_negative`` the hump F_s - F_c is shared by both signs.
Identified maps write F_s+ = F_s- = F_s (one breakaway level, Coulomb levels per sign: the
plant's ``coulomb_asymmetry``), which is what lets an offset be told from an asymmetry.

Maps without the optional fields (every map written before they existed) load unchanged:
F_c+ = F_c- = F_c, tau_0 = 0 gives sign(v) (F_c + (F_s - F_c) e) + F_v v.
No ROS imports; the CasADi form uses a smooth sign so the planner gets derivatives.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

from .params import yaml_problem

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
    coulomb_positive: float | None = None     # None = coulomb
    coulomb_negative: float | None = None     # None = coulomb
    static_positive: float | None = None      # None = static - coulomb + coulomb_positive
    static_negative: float | None = None      # None = static - coulomb + coulomb_negative
    offset: float = 0.0
    degenerate_reason: str = ''               # '' = a trusted fit (or not identified at all)
    fit_report: dict = field(default_factory=dict)   # how the fit chose its model (identify)

    def __post_init__(self):
        if self.coulomb_positive is None:
            object.__setattr__(self, 'coulomb_positive', float(self.coulomb))
        if self.coulomb_negative is None:
            object.__setattr__(self, 'coulomb_negative', float(self.coulomb))

    @property
    def degenerate(self) -> bool:
        return bool(self.degenerate_reason)

    @property
    def symmetric(self) -> bool:
        """No asymmetry and no offset: the thesis's odd model."""
        return (self.coulomb_positive == self.coulomb == self.coulomb_negative
                and self.offset == 0.0 and self.static_positive in (None, self.static)
                and self.static_negative in (None, self.static))

    def humps(self) -> tuple[float, float]:
        """Stribeck humps F_s+ - F_c+ and F_s- - F_c- [N m]."""
        hp = (self.static - self.coulomb if self.static_positive is None
              else self.static_positive - self.coulomb_positive)
        hn = (self.static - self.coulomb if self.static_negative is None
              else self.static_negative - self.coulomb_negative)
        return hp, hn

    def parametric(self, v: np.ndarray) -> np.ndarray:
        """Parametric tau_f(v) [N m] for speeds ``v`` [rad/s] (any shape)."""
        v = np.asarray(v, float)
        stribeck = (self.static - self.coulomb) * np.exp(-(v / self.stribeck_velocity) ** 2)
        if self.symmetric:
            return np.sign(v) * (self.coulomb + stribeck) + self.viscous * v
        e = np.exp(-(v / self.stribeck_velocity) ** 2)
        hp, hn = self.humps()
        level = np.where(v > 0, self.coulomb_positive + hp * e, self.coulomb_negative + hn * e)
        return np.sign(v) * level + self.viscous * v + self.offset

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

        sign(v) is replaced by s = tanh(v / smoothing) [smoothing in rad/s] so the planner's
        NLP has continuous derivatives; the error is below 1e-6 N m for |v| > 10 smoothing.
        Asymmetric levels L+-(v): s (L+ + L-)/2 + s^2 (L+ - L-)/2 (equal to the
        per-sign levels where |s| = 1, continuous through 0); the offset is added as it is.
        """
        import casadi as ca
        out = []
        for i, j in enumerate(self.joints):
            vi = v[i]
            sgn = ca.tanh(vi / smoothing)
            stribeck = (j.static - j.coulomb) * ca.exp(-(vi / j.stribeck_velocity) ** 2)
            if j.symmetric:
                out.append(sgn * (j.coulomb + stribeck) + j.viscous * vi)
                continue
            e = ca.exp(-(vi / j.stribeck_velocity) ** 2)
            hp, hn = j.humps()
            lp, ln = j.coulomb_positive + hp * e, j.coulomb_negative + hn * e
            out.append(sgn * 0.5 * (lp + ln) + sgn * sgn * 0.5 * (lp - ln) + j.viscous * vi
                       + j.offset)
        return ca.vertcat(*out)

    def scaled(self, factor: float) -> 'FrictionMap':
        """Every torque multiplied by ``factor`` (for 'wrong model' experiments)."""
        return FrictionMap(self.joint_names, tuple(
            replace(j, coulomb=j.coulomb * factor, static=j.static * factor,
                    viscous=j.viscous * factor, coulomb_positive=j.coulomb_positive * factor,
                    coulomb_negative=j.coulomb_negative * factor, offset=j.offset * factor,
                    static_positive=None if j.static_positive is None
                    else j.static_positive * factor,
                    static_negative=None if j.static_negative is None
                    else j.static_negative * factor,
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
            if not j.symmetric:
                d.update(coulomb_positive=float(j.coulomb_positive),
                         coulomb_negative=float(j.coulomb_negative), offset=float(j.offset))
                for key in ('static_positive', 'static_negative'):
                    if getattr(j, key) is not None:
                        d[key] = float(getattr(j, key))
            if j.polynomial_positive is not None:
                d['polynomial_positive'] = [float(c) for c in j.polynomial_positive]
            if j.polynomial_negative is not None:
                d['polynomial_negative'] = [float(c) for c in j.polynomial_negative]
            if j.ci95:
                d['ci95'] = {k: float(v) for k, v in j.ci95.items()}
            if j.degenerate:
                d.update(degenerate=True, degenerate_reason=j.degenerate_reason)
            if j.fit_report:
                d['fit'] = _plain(j.fit_report)
            joints[name] = d
        return {'friction_map': {'version': SCHEMA_VERSION, 'source': self.source,
                                 'joints': joints}}

    def save(self, path: str | Path) -> None:
        """Write the map as YAML (schema in the module docstring)."""
        Path(path).write_text(yaml.safe_dump(self.to_dict(), sort_keys=False))


def _plain(x):
    """numpy scalars and tuples inside a report -> YAML-safe Python types."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x)
    return x


class FrictionMapError(ValueError):
    """A friction-map file is missing, unreadable or inconsistent."""


def _joint_from_dict(name: str, d: dict, allow_degenerate: bool = False) -> JointFriction:
    if not isinstance(d, dict):
        raise FrictionMapError(f'joint {name}: not a mapping')
    if d.get('degenerate') and not allow_degenerate:
        raise FrictionMapError(f'joint {name}: marked degenerate by its fit '
                               f'({d.get("degenerate_reason", "no reason given")}); not used')
    try:
        if 'coulomb' in d:
            coulomb = float(d['coulomb'])
        else:      # only the per-sign levels: their mean is the symmetric level
            coulomb = 0.5 * (float(d['coulomb_positive']) + float(d['coulomb_negative']))
        jf = JointFriction(
            coulomb=coulomb, static=float(d.get('static', coulomb)),
            stribeck_velocity=float(d.get('stribeck_velocity', 0.05)),
            viscous=float(d['viscous']),
            valid_range=tuple(float(x) for x in d.get('valid_range', (0.0, float('inf')))),
            polynomial_positive=(tuple(float(c) for c in d['polynomial_positive'])
                                 if 'polynomial_positive' in d else None),
            polynomial_negative=(tuple(float(c) for c in d['polynomial_negative'])
                                 if 'polynomial_negative' in d else None),
            ci95=dict(d.get('ci95', {})),
            coulomb_positive=float(d.get('coulomb_positive', coulomb)),
            coulomb_negative=float(d.get('coulomb_negative', coulomb)),
            offset=float(d.get('offset', 0.0)),
            static_positive=(float(d['static_positive']) if 'static_positive' in d else None),
            static_negative=(float(d['static_negative']) if 'static_negative' in d else None),
            degenerate_reason=(str(d.get('degenerate_reason') or 'degenerate')
                               if d.get('degenerate') else ''),
            fit_report=dict(d.get('fit') or {}))
    except (KeyError, TypeError, ValueError) as exc:
        raise FrictionMapError(f'joint {name}: bad or missing field ({exc})') from exc
    values = [jf.coulomb, jf.static, jf.stribeck_velocity, jf.viscous, jf.coulomb_positive,
              jf.coulomb_negative, jf.offset, *jf.valid_range]
    if not np.all(np.isfinite(values[:-1])) or np.isnan(values[-1]):
        raise FrictionMapError(f'joint {name}: non-finite parameter')
    if jf.stribeck_velocity <= 0 or jf.valid_range[0] > jf.valid_range[1]:
        raise FrictionMapError(f'joint {name}: stribeck_velocity <= 0 or empty valid_range')
    return jf


def friction_map_from_dict(data: dict, joint_names: list[str] | None = None,
                           allow_degenerate: bool = False) -> FrictionMap:
    """Parse the ``friction_map`` mapping; ``joint_names`` fixes the order and checks presence.
    A joint marked ``degenerate`` is refused unless ``allow_degenerate`` (reports, plots)."""
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
    return FrictionMap(tuple(names), tuple(_joint_from_dict(n, joints[n], allow_degenerate)
                                           for n in names),
                       str(fm.get('source', '')))


def load_friction_map(path: str | Path, joint_names: list[str] | None = None,
                      allow_degenerate: bool = False) -> FrictionMap:
    """Read a friction-map YAML; raises FrictionMapError with the reason on any problem
    (also for a joint its fit marked ``degenerate``, unless ``allow_degenerate``)."""
    path = Path(path)
    if not path.is_file():
        raise FrictionMapError(f'friction map {path} does not exist')
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise FrictionMapError(f'friction map {path} unreadable: {exc.strerror}') from exc
    except yaml.YAMLError as exc:
        raise FrictionMapError(f'friction map {path} is not YAML: {yaml_problem(exc)}') \
            from exc
    if not isinstance(data, dict):
        raise FrictionMapError(f'friction map {path}: not a YAML mapping')
    return friction_map_from_dict(data, joint_names, allow_degenerate)


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
