"""The six-joint arm behind the interface the controller and the simulator use (issue 30).

``SixJointModel`` offers what ``model.RobotModel`` offers to irb_control's plant and PD+
(``model``/``data`` a pinocchio model and its workspace, ``fk``, ``limits``, ``friction``,
``joint_names``, ``nq``, ``copy``), for all six joints:

* dynamics: ``six_axis_dynamics.SixAxisDynamics`` (the wrist's masses carved out of the
  thesis's lumped body; with joints 4-6 at 0 the three-axis model to rounding);
* ``fk(q)``: the position of the TCP (a transform ``tcp`` in tool0, default tool0 itself,
  e.g. the 0.10 m gluing nozzle of doc/six_axis.md) -- the point a path is about;
* limits: positions and speeds of config/kinematics.yaml (data sheet), torques of
  config/dynamics.yaml ``torque_limit_nm`` (joints 4-6 its stated assumption);
* nominal friction: dynamics.yaml ``friction`` (joints 1-3) and ``wrist_friction`` (joints
  4-6, a stated assumption: ABB publishes none and the thesis identified joints 1-3 only);
* armature (``wrist_armature``, default on): the reflected rotor inertias gear_ratio^2 J_rotor
  of joints 4-6 (dynamics.yaml ``actuators``, stated assumptions) on the diagonal of M. The
  wrist links alone have 2e-4 to 1e-2 kg m^2 about their axes, against 0.025-0.128 kg m^2 of
  the motors behind the gears: without them joint 6 would be nearly massless against ~1 N m
  of friction (and the plant's explicit viscous term unstable: h F_v / M_66 ~ 2). Joints 1-3
  keep none, as the thesis's and the three-axis model (so the arm joints are today's).

No ROS imports. One instance keeps its own pinocchio ``Data``: ``copy()`` for another thread.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml

from .friction import FrictionMap, nominal_friction_map
from .model import TCP_FRAME, Limits
from .params import config_path, load_dynamics, load_kinematics
from .six_axis_dynamics import SixAxisDynamics


def nominal_six_joint_friction(path: Path | None = None) -> FrictionMap:
    """Nominal friction of joints 1-6: dynamics.yaml ``friction`` (1-3) + ``wrist_friction``
    (4-6) (a ``friction`` block with six joints is taken as it is)."""
    with open(path or config_path('dynamics.yaml'), encoding='utf-8') as f:
        d = yaml.safe_load(f)
    names = [f'joint_{i}' for i in range(1, 7)]
    block = d['friction']
    if len(block['coulomb_nm']) == 6:
        return nominal_friction_map(block, names)
    if 'wrist_friction' not in d:
        raise ValueError('dynamics.yaml has friction for joints 1-3 and no wrist_friction '
                         'block: no friction for joints 4-6')
    w = d['wrist_friction']
    keys = ('coulomb_nm', 'static_nm', 'stribeck_velocity_rad_s', 'viscous_nms_rad')
    arm = nominal_friction_map(block, names[:3])
    wrist = nominal_friction_map({**{k: w[k] for k in keys},
                                  'valid_range_rad_s': w['valid_range_rad_s']}, names[3:])
    return FrictionMap(tuple(names), arm.joints + wrist.joints,
                       'nominal (irb_description dynamics.yaml friction + wrist_friction)')


class SixJointModel:
    """Six actuated joints (module docstring). ``tcp`` (4, 4) in tool0, None = tool0."""

    def __init__(self, tcp=None, dynamics: SixAxisDynamics | None = None,
                 wrist_armature: bool = True):
        self.dynamics = dynamics or SixAxisDynamics()
        self.wrist_armature = bool(wrist_armature)
        self.tcp = np.eye(4) if tcp is None else np.asarray(tcp, float).copy()
        if self.tcp.shape != (4, 4) or not np.all(np.isfinite(self.tcp)):
            raise ValueError('tcp must be a finite (4, 4) homogeneous transform')
        k, d = load_kinematics(), load_dynamics()
        self.model = pin.Model(self.dynamics.model)        # own copy (armature below)
        if self.wrist_armature:
            arm = np.zeros(6)
            arm[3:] = d.armature[3:6]
            self.model.armature = np.asarray(self.model.armature, float) + arm
        self.data = self.model.createData()
        self.urdf = self.dynamics.urdf
        self.joint_names = list(self.dynamics.joint_names)
        if list(k.joint_names) != self.joint_names or d.torque_limit.size != 6:
            raise ValueError('kinematics.yaml / dynamics.yaml do not describe joints 1-6')
        self.limits = Limits(k.lower.copy(), k.upper.copy(), k.velocity.copy(),
                             d.torque_limit.copy())
        self.friction: FrictionMap = nominal_six_joint_friction()
        self._tool0 = self.model.getFrameId(TCP_FRAME)
        self._tcp_p = self.tcp[:3, 3].copy()
        self._tcp_R = self.tcp[:3, :3].copy()

    def copy(self) -> 'SixJointModel':
        """Independent instance (own workspace) for another thread."""
        return SixJointModel(self.tcp, self.dynamics.copy(), self.wrist_armature)

    @property
    def nq(self) -> int:
        return self.model.nq

    def fk_pose(self, q: np.ndarray) -> np.ndarray:
        """Pose (4, 4) of the TCP in base_link for q (6,) [rad]."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, float))
        return self.data.oMf[self._tool0].homogeneous @ self.tcp

    def fk(self, q: np.ndarray) -> np.ndarray:
        """TCP position (3,) [m] in base_link for q (6,) [rad]."""
        pin.forwardKinematics(self.model, self.data, np.asarray(q, float))
        return pin.updateFramePlacement(self.model, self.data, self._tool0).act(self._tcp_p)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Linear TCP Jacobian (3, 6) [m/rad], d p / d q, in base_link axes."""
        q = np.asarray(q, float)
        J = pin.computeFrameJacobian(self.model, self.data, q, self._tool0,
                                     pin.LOCAL_WORLD_ALIGNED)
        r = self.data.oMf[self._tool0].rotation @ self._tcp_p     # tool0 -> TCP, base axes
        skew = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
        return J[:3, :] - skew @ J[3:, :]          # v_tcp = v_tool0 + w x r

    def inverse_dynamics(self, q, qd, qdd) -> np.ndarray:
        """M qdd + C qd + g (6,) [N m] by RNEA (armature included), without friction."""
        return pin.rnea(self.model, self.data, np.asarray(q, float), np.asarray(qd, float),
                        np.asarray(qdd, float)).copy()
