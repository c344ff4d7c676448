"""Six-joint dynamics of the IRB 1600: the wrist links carved out of the thesis's lumped body.

The thesis (and ``model.RobotModel``) treats links 3-6 as one body on link_3 (Table 3.3). Here
the wrist links 4, 5, 6 (and an optional payload on tool0) get the masses and box inertias of
``wrist_links`` in config/dynamics.yaml (stated assumptions, doc/six_axis.md), and link_3
keeps the remainder: mass, first and second moments of the lumped body minus those of the
wrist links at q4 = q5 = q6 = 0 (parallel-axis theorem about link_3's origin); a ``payload``
on tool0 is added to link_6 (0 kg by default, as in the thesis). So

* with joints 4-6 at 0, the six bodies add up exactly to the lumped body, and locking joints
  4-6 there (``three_axis_model``) reproduces today's three-axis dynamics (tested to 1e-9);
* with the wrist moving, its mass moves with it: the six-joint model.

The remainder starts from the inertia pinocchio reads from the committed URDF (not from the
YAML), so the reduction is exact to rounding. ``rnea_function`` gives the same inverse
dynamics as a CasADi Function (the project's RNEA in ``casadi_dynamics``, over this model;
PyPI's pin has no ``pinocchio.casadi``). Robot equation without friction:
M(q) qdd + C(q, qd) qd + g(q) = tau, q (6,). No ROS imports.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import yaml

from .params import box_inertia, config_path, urdf_path

WRIST_LINKS = ('link_4', 'link_5', 'link_6')


@dataclass(frozen=True)
class Body:
    """Mass [kg], CoM (3,) [m] in its frame, inertia (3, 3) [kg m^2] about the CoM."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray

    def pin(self) -> pin.Inertia:
        return pin.Inertia(float(self.mass), np.asarray(self.com, float),
                           np.asarray(self.inertia, float))


def _body(entry: dict, what: str) -> Body:
    try:
        mass = float(entry['mass'])
        com = np.asarray(entry['com_m'], float)
        box = np.asarray(entry['inertia_box_m'], float)
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f'{what}: needs mass, com_m (3) and inertia_box_m (3): {exc}') from None
    if not (np.isfinite(mass) and mass >= 0 and com.shape == (3,) and box.shape == (3,)
            and np.all(np.isfinite(com)) and np.all(box >= 0)):
        raise ValueError(f'{what}: mass >= 0, com_m 3 finite numbers, inertia_box_m 3 '
                         'numbers >= 0')
    return Body(mass, com, box_inertia(mass, box))


def load_wrist(path: Path | None = None) -> tuple[dict[str, Body], Body]:
    """``wrist_links`` (link_4..link_6) and ``payload`` of config/dynamics.yaml."""
    with open(path or config_path('dynamics.yaml'), encoding='utf-8') as f:
        d = yaml.safe_load(f)
    if 'wrist_links' not in d:
        raise ValueError('dynamics.yaml has no wrist_links block (six-joint dynamics)')
    links = {n: _body(d['wrist_links'][n], f'wrist_links.{n}') for n in WRIST_LINKS}
    payload = _body(d.get('payload', {'mass': 0.0, 'com_m': [0, 0, 0],
                                      'inertia_box_m': [0, 0, 0]}), 'payload')
    return links, payload


def _second_moment(I: pin.Inertia) -> np.ndarray:
    """Inertia (3, 3) about the frame origin: I_c + m (|c|^2 1 - c c^T)."""
    c = np.asarray(I.lever, float)
    return np.asarray(I.inertia, float) + I.mass * (c @ c * np.eye(3) - np.outer(c, c))


def is_physical(I: pin.Inertia, tol: float = 1e-12) -> bool:
    """Mass > 0, inertia about the CoM positive definite and obeying the triangle
    inequalities (a rigid body can have it)."""
    J = np.asarray(I.inertia, float)
    ev = np.linalg.eigvalsh(0.5 * (J + J.T))
    return bool(I.mass > 0 and ev.min() > tol and 2 * ev.max() <= ev.sum() + tol)


class SixAxisDynamics:
    """Pinocchio model of the six-joint arm with the wrist's masses (module doc).

    One instance keeps its own ``Data``: do not share it between threads (``copy``).
    """

    def __init__(self, urdf: Path | None = None, wrist: dict[str, Body] | None = None,
                 payload: Body | None = None):
        self.urdf = Path(urdf or urdf_path())
        if wrist is None or payload is None:
            w, p = load_wrist()
            wrist = w if wrist is None else wrist
            payload = p if payload is None else payload
        self.wrist, self.payload = wrist, payload
        model = pin.buildModelFromUrdf(str(self.urdf))
        self.joint_names = [model.names[i] for i in range(1, model.njoints)]
        if self.joint_names != [f'joint_{i}' for i in range(1, 7)]:
            raise ValueError(f'{self.urdf}: expected joint_1..joint_6, got {self.joint_names}')
        j3 = model.getJointId('joint_3')
        lumped = model.inertias[j3]
        for n in ('joint_4', 'joint_5', 'joint_6'):
            if model.inertias[model.getJointId(n)].mass > 0:
                raise ValueError(f'{self.urdf}: {n} already carries mass; the split assumes '
                                 'the thesis URDF (links 3-6 lumped on link_3)')
        # the wrist bodies (and the payload on tool0) in their joint frames
        parts = {n: wrist[f'link_{n[-1]}'].pin() for n in ('joint_4', 'joint_5', 'joint_6')}
        # their placement in link_3 at q4 = q5 = q6 = 0 (frames parallel there)
        m_w, first, second = 0.0, np.zeros(3), np.zeros((3, 3))
        at = pin.SE3.Identity()
        for n in ('joint_4', 'joint_5', 'joint_6'):
            at = at * model.jointPlacements[model.getJointId(n)]
            I_in_3 = at.act(parts[n])
            m_w += I_in_3.mass
            first += I_in_3.mass * np.asarray(I_in_3.lever)
            second += _second_moment(I_in_3)
        m3 = lumped.mass - m_w
        if m3 <= 0:
            raise ValueError(f'the wrist links ({m_w:.3f} kg) outweigh the lumped links 3-6 '
                             f'body ({lumped.mass:.3f} kg)')
        c3 = (lumped.mass * np.asarray(lumped.lever) - first) / m3
        J3_origin = _second_moment(lumped) - second
        J3 = J3_origin - m3 * (c3 @ c3 * np.eye(3) - np.outer(c3, c3))
        J3 = 0.5 * (J3 + J3.T)
        ev = np.linalg.eigvalsh(J3)
        if ev.min() <= 1e-12 or 2 * ev.max() > ev.sum() + 1e-12:
            raise ValueError('the forearm left after removing the wrist links is not a rigid '
                             f'body (inertia eigenvalues {ev.round(5).tolist()} kg m^2)')
        forearm = pin.Inertia(m3, c3, J3)
        self.forearm = forearm
        # the payload is added to link_6 (the lumped body of the thesis carries none)
        tool0 = model.frames[model.getFrameId('tool0')].placement      # in link_6
        if payload.mass > 0:
            parts['joint_6'] = parts['joint_6'] + tool0.act(payload.pin())
        model.inertias[j3] = forearm
        for n, I in parts.items():
            model.inertias[model.getJointId(n)] = I
        self.model = model
        self.data = model.createData()
        self.lower = model.lowerPositionLimit.copy()
        self.upper = model.upperPositionLimit.copy()

    def copy(self) -> 'SixAxisDynamics':
        return SixAxisDynamics(self.urdf, self.wrist, self.payload)

    @property
    def nq(self) -> int:
        return self.model.nq

    def total_mass(self) -> float:
        """Mass of the moving links [kg] (payload included)."""
        return float(sum(self.model.inertias[i].mass for i in range(1, self.model.njoints)))

    # --- dynamics (no friction) ---------------------------------------------------------
    def inverse_dynamics(self, q, qd, qdd) -> np.ndarray:
        """M qdd + C qd + g (6,) [N m] by RNEA."""
        return pin.rnea(self.model, self.data, np.asarray(q, float), np.asarray(qd, float),
                        np.asarray(qdd, float)).copy()

    def mass_matrix(self, q) -> np.ndarray:
        """M(q) (6, 6) [kg m^2]."""
        M = pin.crba(self.model, self.data, np.asarray(q, float))
        return np.triu(M) + np.triu(M, 1).T

    def gravity(self, q) -> np.ndarray:
        """g(q) (6,) [N m]."""
        return pin.computeGeneralizedGravity(self.model, self.data,
                                             np.asarray(q, float)).copy()

    def forward_dynamics(self, q, qd, tau) -> np.ndarray:
        """qdd (6,) [rad/s^2] by ABA, tau without friction."""
        return pin.aba(self.model, self.data, np.asarray(q, float), np.asarray(qd, float),
                       np.asarray(tau, float)).copy()

    def three_axis_model(self, q_wrist=(0.0, 0.0, 0.0)) -> pin.Model:
        """The pinocchio model with joints 4-6 locked at ``q_wrist`` (3,) [rad]: at 0 the
        thesis's three-axis model (``model.RobotModel.model``) to rounding."""
        q0 = pin.neutral(self.model)
        q0[3:] = np.asarray(q_wrist, float)
        locked = [self.model.getJointId(n) for n in ('joint_4', 'joint_5', 'joint_6')]
        return pin.buildReducedModel(self.model, locked, q0)

    def rnea_function(self):
        """CasADi Function ``rnea(q, qd, qdd) -> tau`` (all (6,)) of this model, built by
        ``casadi_dynamics.rnea_expression`` (the planner's RNEA) over its pinocchio model."""
        import casadi as ca

        from .casadi_dynamics import rnea_expression
        q, qd, qdd = ca.SX.sym('q', 6), ca.SX.sym('qd', 6), ca.SX.sym('qdd', 6)
        tau = rnea_expression(SimpleNamespace(model=self.model, nq=6), q, qd, qdd)
        return ca.Function('rnea6', [q, qd, qdd], [tau], ['q', 'qd', 'qdd'], ['tau'])
