"""Six-axis planning along a path with a tool-orientation law (issue 30; numpy/CasADi, no ROS).

The three-axis planner's formulation, reused as it is: the path parameter theta drives all six
joints through the closed-form IK (``irb_description.orientation.joint_path6``, Phi, Phi',
Phi'' (N, 6)), the path-projected dynamics tau = m a + c b + g + tau_f(Phi' sqrt b) come from
the six-joint CasADi RNEA (``SixAxisDynamics.rnea_function``) through
``problem.path_dynamics``, and the NLP is ``transcription.Transcription`` (direct
transcription in b = theta_dot^2, a = theta_ddot; nothing in it is three-axis: its joint
count is the columns of Phi'). Time-optimal and energy-optimal at a given duration, on either
energy model: mechanical (sum |tau_i qd_i|) or the electrical model of the six axes
(irb_description config/electrical.yaml, its DC-bus mode or one asked for), with the speed,
torque and position limits of all six joints and, as the three-axis planner, the smoothness
limits (issue 28): joint jerk, rigid-body torque rate and TCP jerk as played, rest ends with a
constant path jerk (``jerk_limits``). Joints 1-3 keep the three-axis planner's limits
(``PlannerSettings``, its config/planner.yaml); the wrist's are this planner's settings
(config/six_axis_plan.yaml, stated assumptions).

What is not reused, and why: ``planner.Planner`` is bound to the three-axis ``RobotModel``
(its path check, IK, pinocchio workspace, friction-map files of three joints, electrical
model of three axes and the three-axis independent check with joints 4-6 at 0); a six-axis
mode inside it would touch most of its methods. Here the same pieces are wired for six joints
(``SixAxisPlanner``): the grid (``planner.theta_grid``), the message points
(``planner.message_points``), the consistency rule of ``trajectory_rules``, the exact time
law (``profile.ThetaProfile``), and a smaller limit adaptation.

Model constants come from irb_description: position and speed limits of the six joints
(config/kinematics.yaml), torque limits (config/dynamics.yaml ``torque_limit_nm``; joints 4-6
are its stated assumptions), friction of joints 1-3 (dynamics.yaml ``friction``). Friction of
joints 4-6 is published nowhere: irb_description's dynamics.yaml ``wrist_friction`` holds the
assumption and its reasoning (``six_axis_model.nominal_six_joint_friction``), used while
dynamics.yaml's ``friction`` has three joints.

A path mapping for six axes is ``path_from_spec``'s with an ``orientation`` block
(``orientation_from_spec``: law fixed / path_normal / slerp); the three-axis readers refuse that
block with a line naming the six-axis chain. Every plan's trajectory is checked as played by
``six_axis_check`` (quintic per joint at 10 kHz, own DH kinematics): the message gets points
between the theta nodes until the played TCP is within half the position and orientation
tolerances (0.1 mm, 0.05 deg); a plan outside them or a limit is refused.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml
from irb_description.friction import FrictionMap, JointFriction
from irb_description.orientation import (ORIENTATION_KEY, OrientationLaw, joint_path6,
                                         orientation_from_spec)
from irb_description.params import load_dynamics, load_kinematics
from irb_description.path import (PROCESS_KEY, JointPath, PathBase, path_from_spec,
                                   process_from_spec)
from irb_description.six_axis import SixAxisKinematics, UnreachablePoseError, pose, rpy_matrix
from irb_description.six_axis_model import nominal_six_joint_friction
from irb_description.trajectory_rules import (CONSISTENCY_ATOL, CONSISTENCY_RTOL,
                                              MIN_POINT_SPACING_S, worst_inconsistency)

from .planner import (PlannerSettings, band_text, blend_windows, jerk_path, message_points,
                      tcp_path, theta_grid, tighten_band, tighten_smooth)
from .problem import casadi_friction, path_dynamics
from .profile import ThetaProfile
from .request import PlanError
from .six_axis_check import DHTable, PlayedCheck, SmoothLimits, check_played
from .transcription import (BOUNDARY_REST, RAMP_SPEED_EXPONENT, TIME_OBJECTIVE_ENERGY_WEIGHT,
                            SolveRequest, Transcription)
from .verify import TcpBand

CONFIG_NAME = 'six_axis_plan.yaml'
OBJECTIVES6 = ('energy', 'time')
#: energy models: mechanical, or electrical with the DC-bus mode of electrical.yaml or a named one
ENERGY_MODELS6 = ('mechanical', 'electrical', 'electrical_none', 'electrical_shared',
                  'electrical_regenerative')
#: joint_path6's central-difference step [rad] (its default h)
CENTRAL_STEP = 1e-4


class SixAxisPlanError(ValueError):
    """A six-axis request that cannot be planned (one line saying why)."""


# --- configuration -------------------------------------------------------------------------
def config_path() -> Path:
    """config/six_axis_plan.yaml of irb_planning (source tree or installed share)."""
    source = Path(__file__).resolve().parent.parent / 'config' / CONFIG_NAME
    if source.is_file():
        return source
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('irb_planning')) / 'config' / CONFIG_NAME


def load_config(path: Path | None = None) -> dict:
    with open(path or config_path(), encoding='utf-8') as f:
        return yaml.safe_load(f)


@dataclass(frozen=True)
class SixAxisLimits:
    """Limits of the six joints (6,) each: lower, upper [rad], velocity [rad/s], torque [N m];
    the friction map of the six joints and where each part comes from."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    torque: np.ndarray
    friction: FrictionMap
    sources: dict


def load_limits(config: dict | None = None) -> SixAxisLimits:
    """The six joints' limits and friction (module docstring: sources); every value comes from
    irb_description (``config``, the planner's settings, holds none of them: kept for
    callers)."""
    k, d = load_kinematics(), load_dynamics()
    names = list(k.joint_names)
    block = d.friction

    def joint(i, src):
        return JointFriction(coulomb=float(src['coulomb_nm'][i]),
                             static=float(src['static_nm'][i]),
                             stribeck_velocity=float(src['stribeck_velocity_rad_s'][i]),
                             viscous=float(src['viscous_nms_rad'][i]),
                             valid_range=tuple(float(x) for x in src['valid_range_rad_s']))
    n_desc = len(block['coulomb_nm'])
    joints = [joint(i, block) for i in range(n_desc)]
    wrist_src = 'irb_description config/dynamics.yaml friction'
    if n_desc < 6:
        # joints 4-6: irb_description's wrist_friction block (its stated assumption), the one
        # source the simulator's and pdplus's six-joint mode read too
        joints += list(nominal_six_joint_friction().joints[n_desc:])
        wrist_src = 'assumption, irb_description config/dynamics.yaml wrist_friction'
    if len(joints) != 6:
        raise ValueError(f'friction for {len(joints)} joints, expected 6')
    fm = FrictionMap(tuple(names), tuple(joints), 'nominal six-axis')
    torque = np.asarray(d.torque_limit, float)
    if torque.size != 6:
        raise ValueError('dynamics.yaml torque_limit_nm needs 6 values for six axes')
    return SixAxisLimits(k.lower.copy(), k.upper.copy(), k.velocity.copy(), torque, fm, {
        'position, speed': 'irb_description config/kinematics.yaml (data sheet)',
        'torque 1-3': 'irb_description config/dynamics.yaml torque_limit_nm',
        'torque 4-6': 'irb_description config/dynamics.yaml torque_limit_nm (its assumption)',
        'friction 1-3': 'irb_description config/dynamics.yaml friction (nominal)',
        'friction 4-6': wrist_src})


def tcp_from_config(cfg: dict) -> np.ndarray:
    """The TCP (4, 4) on tool0 from ``tcp: {xyz: [m], rpy: [rad]}``."""
    t = cfg.get('tcp') or {}
    return pose(rpy_matrix(np.asarray(t.get('rpy', [0.0, 0.0, 0.0]), float)),
                np.asarray(t.get('xyz', [0.0, 0.0, 0.0]), float))


def process_band(process: dict | None, jerk_limits: bool = True) -> TcpBand | None:
    """A path file's process block (``irb_description.path.process_from_spec``'s mapping) as
    the check's TcpBand (None without one), its ramp floor rising as the three-axis planner's
    (exponent 2/3 with the jerk limits: a constant-jerk start; else 1/2)."""
    if not process:
        return None
    band = TcpBand(process.get('tcp_speed_max', 0.0), process.get('tcp_speed_min', 0.0),
                   process.get('tcp_accel_max', 0.0), process.get('tcp_ramp_length', 0.0),
                   RAMP_SPEED_EXPONENT if jerk_limits else 0.5)
    return band if band.active else None


def task_process(spec) -> dict:
    """The process block of a path mapping (``process_from_spec``; {} without one);
    SixAxisPlanError with one line for a bad one."""
    try:
        return process_from_spec(spec)
    except ValueError as exc:
        raise SixAxisPlanError(str(exc)) from None


# --- path files with an orientation block -------------------------------------------------
def task_from_spec(spec) -> tuple[PathBase, OrientationLaw]:
    """(path, law) from a path mapping with an ``orientation`` block; SixAxisPlanError with
    one line naming what is wrong."""
    if not isinstance(spec, dict):
        raise SixAxisPlanError('a path spec must be a mapping with a "type"')
    if ORIENTATION_KEY not in spec:
        raise SixAxisPlanError("a six-axis path needs an 'orientation' block (law: fixed, "
                               'path_normal or slerp; irb_description doc/six_axis.md)')
    task_process(spec)                   # a bad process block: one line, here
    geometry = {k: v for k, v in spec.items() if k not in (ORIENTATION_KEY, PROCESS_KEY)}
    try:
        path = path_from_spec(geometry)
        law = orientation_from_spec(spec[ORIENTATION_KEY], path)
    except (TypeError, ValueError) as exc:
        raise SixAxisPlanError(str(exc)) from None
    return path, law


def read_task_file(name) -> tuple[PathBase, OrientationLaw]:
    """(path, law) from a YAML path file with an ``orientation`` block."""
    from irb_description.path import read_path_spec
    try:
        return task_from_spec(read_path_spec(name))
    except (SixAxisPlanError, ValueError) as exc:
        raise SixAxisPlanError(f'path file {name}: {exc}') from None


# --- the planner ----------------------------------------------------------------------------
@dataclass(frozen=True)
class SixAxisSettings:
    """Settings (config/six_axis_plan.yaml ``planner``; units in the names)."""

    grid_size: int = 200
    min_theta_dot_rad_s: float = 0.05
    friction_smoothing_rad_s: float = 1e-3
    constraint_margin: float = 0.005
    max_iterations: int = 1000
    tolerance: float = 1e-8
    adapt_rounds: int = 3
    play_rate_hz: float = 10_000.0
    path_tolerance_m: float = 1e-4
    orientation_tolerance_deg: float = 0.05
    min_point_spacing_s: float = MIN_POINT_SPACING_S
    max_trajectory_points: int = 20000
    reference_samples: int = 721        # theta samples every IK call is continued along
    side_step_rad: float = 1e-3         # one-sided differences at a polyline's piece ends
    jerk_limits: bool = True            # joint jerk, torque rate, TCP jerk kept as played
    wrist_jerk_limit_rad_s3: tuple = (1000.0, 1000.0, 1000.0)        # joints 4-6
    wrist_torque_rate_limit_nm_s: tuple = (1200.0, 1200.0, 600.0)    # joints 4-6
    electrical_smoothing_w: float = 0.5  # eps [W] of |.| in the electrical NLP objective

    @classmethod
    def from_config(cls, cfg: dict) -> 'SixAxisSettings':
        block = dict(cfg.get('planner') or {})
        unknown = set(block) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f'{CONFIG_NAME} planner: unknown keys {sorted(unknown)}')
        for k in ('wrist_jerk_limit_rad_s3', 'wrist_torque_rate_limit_nm_s'):
            if k in block:
                v = tuple(float(x) for x in block[k])
                if len(v) != 3 or not all(np.isfinite(x) and x > 0 for x in v):
                    raise ValueError(f'{CONFIG_NAME} planner: {k} needs 3 values > 0')
                block[k] = v
        return cls(**block)


@dataclass
class SixAxisProblem:
    """Everything built for one (path, law, grid): the joint path sampler, the nodes', midpoints'
    and piece ends' dynamics and the NLP."""

    path: PathBase
    law: OrientationLaw
    configuration: tuple
    q_start: np.ndarray
    theta: np.ndarray
    nodes: object
    mids: object
    transcription: Transcription
    sample: object
    build_time: float
    min_duration: dict = field(default_factory=dict)
    energy_model: str = 'mechanical'
    band: TcpBand | None = None          # process constraints (TCP speed band, |TCP accel|)


@dataclass
class SixAxisPlan:
    """A checked six-axis plan: objective, profile, duration [s], time-optimal duration [s],
    optimiser's energy [J], played energy [J], solve time [s] (all solves), iterations, build
    time [s] of the problem, the message's points (t, theta, q, qd, qdd), the played check,
    notes."""

    objective: str
    profile: ThetaProfile
    duration: float
    min_duration: float
    optimizer_energy: float
    solve_time: float
    iterations: int
    build_time: float
    trajectory: dict
    check: PlayedCheck
    configuration: tuple
    notes: list = field(default_factory=list)
    energy_model: str = 'mechanical'

    @property
    def energy(self) -> float:
        """Mechanical energy of the trajectory as played [J]."""
        return self.check.energy

    @property
    def electrical_energy(self) -> float:
        """Electrical energy of the trajectory as played [J] (the six axes' electrical model,
        the plan's DC-bus mode; standby included)."""
        return self.check.electrical_energy


class SixAxisPlanner:
    """Plans along a path with an orientation law on six joints (module docstring)."""

    def __init__(self, settings: SixAxisSettings | None = None, tcp=None,
                 limits: SixAxisLimits | None = None, dynamics=None, config: dict | None = None):
        from irb_description.six_axis_dynamics import SixAxisDynamics
        cfg = config or load_config()
        self.settings = settings or SixAxisSettings.from_config(cfg)
        self.tcp = tcp_from_config(cfg) if tcp is None else np.asarray(tcp, float)
        self.kin = SixAxisKinematics(tcp=self.tcp)
        self.limits = limits or load_limits(cfg)
        self.dynamics = dynamics or SixAxisDynamics()
        f = self.dynamics.rnea_function()
        maps = {}

        def inverse_dynamics(q, qd, qdd):
            q = np.atleast_2d(q)
            F = maps.get(q.shape[0])
            if F is None:
                F = maps[q.shape[0]] = f.map(q.shape[0])
            return np.asarray(F(q.T, np.atleast_2d(qd).T, np.atleast_2d(qdd).T)).T
        self._inverse_dynamics = inverse_dynamics
        k = self.kin.kinematics
        self.dh = DHTable(k.dh_a, k.dh_alpha, k.dh_d, k.dh_offset)
        self._friction_joints = self.limits.friction.to_dict()['friction_map']['joints']
        from irb_description.electrical import load_electrical
        self.electrical = load_electrical().axes(6)

    @property
    def smooth_limits(self) -> SmoothLimits | None:
        """The smoothness limits every plan keeps as played (None: jerk_limits off): joints
        1-3 and the TCP jerk as the three-axis planner (``PlannerSettings``), the wrist's
        from this planner's settings."""
        s = self.settings
        if not s.jerk_limits:
            return None
        arm = PlannerSettings()
        return SmoothLimits(
            np.concatenate([np.broadcast_to(np.asarray(arm.joint_jerk_limit_rad_s3, float),
                                            (3,)), s.wrist_jerk_limit_rad_s3]),
            float(arm.tcp_jerk_limit_m_s3),
            np.concatenate([np.broadcast_to(np.asarray(arm.torque_rate_limit_nm_s, float),
                                            (3,)), s.wrist_torque_rate_limit_nm_s]))

    def electrical_model(self, energy_model: str):
        """The six axes' ElectricalModel of ``energy_model`` ('electrical': electrical.yaml's
        bus mode; 'electrical_<mode>': that mode)."""
        if energy_model not in ENERGY_MODELS6 or energy_model == 'mechanical':
            raise SixAxisPlanError(f'energy model must be one of {list(ENERGY_MODELS6[1:])} '
                                   f'for an electrical model, not {energy_model!r}')
        mode = energy_model.partition('_')[2]
        return self.electrical.with_mode(mode) if mode else self.electrical

    # --- the joint path -------------------------------------------------------------------
    def _sampler(self, path: PathBase, law: OrientationLaw, cfg, q0):
        """theta (M,) -> JointPath (q, dq, ddq (M, 6)): ``joint_path6`` on the union of theta
        and a reference grid (so that every call continues the joints along the same samples
        and takes the same 2 pi representatives), in configuration ``cfg`` from ``q0``."""
        s = self.settings
        ref = np.linspace(0.0, 2 * np.pi, s.reference_samples)

        def joints(theta, derivatives):
            grid, inv = np.unique(np.concatenate([theta, ref]), return_inverse=True)
            jp = joint_path6(self.kin, path, law, grid, configuration=cfg, seed=q0,
                             derivatives=derivatives)
            k = inv[:theta.size]
            return jp.q[k], (jp.dq[k] if derivatives else None), \
                (jp.ddq[k] if derivatives else None)

        def sample(theta, side=None):
            theta = np.atleast_1d(np.asarray(theta, float))
            q, dq, ddq = joints(theta, True)
            if not path.breaks.size:
                return JointPath(theta, q, dq, ddq)
            # within the central differences' reach of a piece end (where Phi'' jumps) the
            # derivatives are one-sided, from the sample's own side; at a piece end itself
            # from its more curved side ('curved', the default) or the other ('other')
            gap = theta[:, None] - path.breaks[None, :]
            j = np.argmin(np.abs(gap), axis=1)
            g = gap[np.arange(theta.size), j]
            near = np.abs(g) <= 2 * CENTRAL_STEP
            if np.any(near):
                dq, ddq = dq.copy(), ddq.copy()
                for k in np.flatnonzero(near):
                    if g[k] != 0:
                        sgn = float(np.sign(g[k]))
                    else:
                        sgn = self._curved_side(path, theta[k], side or 'curved')
                    dq[k], ddq[k] = self._one_sided(theta[k], sgn, joints)
            return JointPath(theta, q, dq, ddq)
        return sample

    @staticmethod
    def _curved_side(path, b, side) -> float:
        """-1 (before) or +1 (after the piece end ``b``): its more curved side ('curved') or
        the other ('other')."""
        eps = 1e-9
        lo_curved = (np.linalg.norm(path.dd_point(np.array([b - eps])))
                     > np.linalg.norm(path.dd_point(np.array([b + eps]))))
        go_lo = lo_curved if side == 'curved' else not lo_curved
        return -1.0 if go_lo else 1.0

    def _one_sided(self, th, sgn, joints):
        """dq, ddq (6,) at ``th`` by second-order one-sided differences of the IK towards
        ``sgn`` (+-1), step side_step_rad."""
        h = self.settings.side_step_rad
        st = th + sgn * h * np.arange(4)
        q = joints(np.sort(st), False)[0]
        if sgn < 0:
            q = q[::-1]
        dq = sgn * (-3 * q[0] + 4 * q[1] - q[2]) / (2 * h)
        ddq = (2 * q[0] - 5 * q[1] + 4 * q[2] - q[3]) / h ** 2
        return dq, ddq

    def problem(self, path: PathBase, law: OrientationLaw, grid_size: int | None = None,
                configuration=None, seed=None, boundary: str = BOUNDARY_REST,
                energy_model: str = 'mechanical', process: dict | None = None
                ) -> SixAxisProblem:
        """Build the NLP for ``path`` with ``law`` (configuration kept all along: given, or the
        one nearest ``seed`` at the start, or the first that solves the path), its energy
        objective on ``energy_model`` (ENERGY_MODELS6); ``process``: a path file's process
        block (``process_from_spec``: tcp_speed_max, tcp_speed_min, tcp_accel_max,
        tcp_ramp_length) as rows of the NLP and checked as played, as the three-axis
        planner does."""
        s = self.settings
        band = process_band(process, s.jerk_limits)
        if energy_model not in ENERGY_MODELS6:
            raise SixAxisPlanError(f'energy model must be one of {list(ENERGY_MODELS6)}, '
                                   f'not {energy_model!r}')
        electrical = None if energy_model == 'mechanical' else \
            self.electrical_model(energy_model)
        steps = getattr(law, 'inner_keyframes', np.zeros(0))
        if s.jerk_limits and getattr(law, 'easing', '') == 'linear' and steps.size:
            raise SixAxisPlanError(
                'slerp with easing linear: the tool\'s rotation rate steps at the keyframe(s) '
                'theta = ' + ', '.join(f'{x:.4f}' for x in steps) + ' rad, so the joint speeds '
                'would step there at any path speed > 0, which the jerk limits (jerk_limits) '
                'forbid: use easing smooth (the default) or turn jerk_limits off')
        t0 = time.perf_counter()
        ref = np.linspace(0.0, 2 * np.pi, s.reference_samples)
        try:
            jp = joint_path6(self.kin, path, law, ref, configuration=configuration, seed=seed)
        except UnreachablePoseError as exc:
            raise SixAxisPlanError(f'path unreachable: {exc}') from None
        cfg, q0 = jp.configuration, jp.q[0].copy()
        sample = self._sampler(path, law, cfg, q0)
        theta = theta_grid(int(grid_size or s.grid_size), path.breaks)
        mids_th = 0.5 * (theta[1:] + theta[:-1])
        try:
            nodes = path_dynamics(theta, lambda th: sample(th, 'curved'),
                                  self._inverse_dynamics)
            mids = path_dynamics(mids_th, sample, self._inverse_dynamics)
            sides = None
            if path.breaks.size:
                idx = np.flatnonzero(np.isin(theta, path.breaks))
                sides = (idx, path_dynamics(theta[idx], lambda th: sample(th, 'other'),
                                            self._inverse_dynamics))
            jerk = jerk_path(path, sample, theta, nodes, sides) if s.jerk_limits else None
        except UnreachablePoseError as exc:
            raise SixAxisPlanError(f'path unreachable: {exc}') from None
        friction = casadi_friction(self.limits.friction, s.friction_smoothing_rad_s)
        tr = Transcription(nodes, mids, friction, boundary=boundary, max_iter=s.max_iterations,
                           tol=s.tolerance, warm_start=True, sides=sides,
                           electrical=electrical,
                           bus_mode=electrical.bus_mode if electrical is not None else 'shared',
                           electrical_smoothing=s.electrical_smoothing_w, jerk=jerk,
                           **({} if band is None else dict(
                               tcp=tcp_path(path, theta), accel_rows=band.accel_max > 0,
                               band_rows=band.speed_max > 0 or band.speed_min > 0)))
        return SixAxisProblem(path, law, cfg, q0, theta, nodes, mids, tr, sample,
                              time.perf_counter() - t0, energy_model=energy_model, band=band)

    def _nlp_limits(self, band: TcpBand | None = None) -> SolveRequest:
        s, lim = self.settings, self.limits
        keep = 1.0 - s.constraint_margin
        vel = np.minimum(lim.velocity, lim.friction.valid_range()[:, 1])
        sm = self.smooth_limits
        b = band or TcpBand()
        # the process bounds with the same margin as the three-axis planner's
        return SolveRequest(0.0, 0.0, 1.0, s.min_theta_dot_rad_s, vel * keep,
                            lim.torque * keep, b.speed_max * keep,
                            b.speed_min * (2.0 - keep), b.accel_max * keep, b.ramp_length,
                            jerk_limit=None if sm is None else sm.jerk * keep,
                            tcp_jerk_max=0.0 if sm is None else sm.tcp_jerk * keep)

    # --- message points and the played check -------------------------------------------
    def trajectory(self, prob: SixAxisProblem, profile: ThetaProfile,
                   consistency: bool = True, smooth: bool = False
                   ) -> tuple[dict, PlayedCheck, list]:
        """The message's points: the profile's nodes, each interval split into m equal theta
        pieces (m = 1, 2, 4, ...) until the trajectory played by quintic interpolation stays
        within half the position and orientation tolerances and keeps the consistency rule
        of ``trajectory_rules`` with half its tolerances (``consistency``; or the point budget
        is used; the check then says whether it is within the tolerances). ``smooth``: the
        final check holds the plan to the smoothness limits too (a profile made without them,
        e.g. a trapezoid, is only measured)."""
        s = self.settings
        nodes = profile.theta
        problems = []
        m = 1
        while True:
            frac = np.arange(m) / m
            theta = np.append((nodes[:-1, None] + np.diff(nodes)[:, None] * frac).ravel(),
                              nodes[-1])
            theta = self._clear_twins(profile, theta, prob.path.breaks)
            t, theta, td, tdd, jp = message_points(profile, theta, prob.path.breaks,
                                                   s.min_point_spacing_s, prob.sample)
            qd = jp.dq * td[:, None]
            qdd = jp.ddq * td[:, None] ** 2 + jp.dq * tdd[:, None]
            chk = self.check(prob, t, jp.q, qd, qdd, torque=False)
            bad = worst_inconsistency(t, jp.q, qd, qdd, 0.5 * CONSISTENCY_RTOL,
                                      0.5 * CONSISTENCY_ATOL) if consistency else None
            within = (chk.position_error <= 0.5 * s.path_tolerance_m and
                      chk.orientation_error <= 0.5 * np.radians(s.orientation_tolerance_deg))
            if (within and bad is None) or 2 * m * (nodes.size - 1) + 1 > s.max_trajectory_points:
                break
            m *= 2
        # the torques, smoothness and energies too, on the final points
        chk = self.check(prob, t, jp.q, qd, qdd, smooth=smooth,
                         exempt=self.blend_windows(profile, prob.path))
        if bad is not None:
            problems.append(f'inconsistent {bad.what}: joint {bad.joint + 1} at point '
                            f'{bad.point} (t = {t[bad.point]:.4f} s): {bad.detail()}')
        return {'t': t, 'theta': theta, 'q': jp.q, 'qd': qd, 'qdd': qdd}, chk, problems

    def _clear_twins(self, profile: ThetaProfile, theta: np.ndarray, breaks: np.ndarray
                     ) -> np.ndarray:
        """``theta`` without the candidates (other than the piece ends themselves) less than
        1.5 min_point_spacing_s from a piece end in time: ``message_points`` puts two points
        half the spacing before and after each piece end, and its spacing rule may otherwise
        keep a nearby candidate instead of a twin, leaving an interval across the jump of
        Phi'' whose declared end accelerations do not bound it (seen on the rectangle's
        time-optimal plan: joint 5, -22.8 rad/s^2 inside, -19.1 declared at both ends)."""
        inner = breaks[(breaks > theta[0]) & (breaks < theta[-1])] if breaks.size else breaks
        if not inner.size:
            return theta
        t_b = profile.theta_at(inner)[0]
        t = profile.theta_at(theta)[0]
        near = np.min(np.abs(t[:, None] - t_b[None, :]), axis=1) < \
            1.5 * self.settings.min_point_spacing_s
        keep = ~near | np.isin(theta, inner)
        keep[[0, -1]] = True
        return theta[keep]

    def rigid_torque(self, q, qd, qdd) -> np.ndarray:
        """pinocchio RNEA on six joints (M, 6) -> (M, 6) [N m] (the check's dynamics)."""
        inv = self.dynamics.inverse_dynamics
        return np.array([inv(a, b, c) for a, b, c in zip(q, qd, qdd)])

    def blend_windows(self, profile: ThetaProfile, path: PathBase) -> np.ndarray | None:
        """(B, 2) [s]: the message intervals between the twin points around each interior
        piece end (``planner.blend_windows``), reported apart by the smoothness check."""
        return blend_windows(profile, path.breaks, self.settings.min_point_spacing_s)

    def check(self, prob: SixAxisProblem, t, q, qd, qdd, torque: bool = True,
              smooth: bool = False, exempt=None) -> PlayedCheck:
        """``six_axis_check.check_played`` of the points with this planner's limits (the
        played torques, mechanical and electrical energy and smoothness peaks only with
        ``torque``; the smoothness limits checked with ``smooth``, ``exempt`` windows
        apart)."""
        s, lim = self.settings, self.limits
        model = getattr(prob, 'energy_model', 'mechanical')
        electrical = (self.electrical if model == 'mechanical'
                      else self.electrical_model(model))
        return check_played(t, q, qd, qdd, prob.path, prob.law.rotation, self.tcp, self.dh,
                            lim.lower, lim.upper, np.minimum(
                                lim.velocity, lim.friction.valid_range()[:, 1]), lim.torque,
                            self.rigid_torque if torque else None, self._friction_joints,
                            self.kin.joint_names,
                            s.play_rate_hz, s.path_tolerance_m,
                            np.radians(s.orientation_tolerance_deg),
                            smooth=self.smooth_limits if smooth else None,
                            smooth_exempt=exempt, electrical=electrical if torque else None,
                            band=getattr(prob, 'band', None),
                            rest=getattr(getattr(prob, 'transcription', None), 'boundary',
                                         BOUNDARY_REST) == BOUNDARY_REST)

    # --- solves -----------------------------------------------------------------------------
    def _solve_checked(self, prob: SixAxisProblem, sreq: SolveRequest, duration: float,
                       consistency: bool = True):
        """Solve, rescale to the exact ``duration`` (0: keep), build the message and play it;
        where the played speed or torque exceeds a limit, tighten it by the excess and solve
        again (adapt_rounds). Returns (result, profile, trajectory, check, notes, time,
        iterations)."""
        s, lim = self.settings, self.limits
        vel_lim = np.minimum(lim.velocity, lim.friction.valid_range()[:, 1])
        notes, spent, iters = [], 0.0, 0
        for attempt in range(s.adapt_rounds + 1):
            res = prob.transcription.solve(sreq, warm=False)
            spent += res.stats.solve_time
            iters += res.stats.iterations
            if not res.stats.success or res.profile is None:
                with_band = (f' with the process constraints ({band_text(prob.band)})'
                             if prob.band is not None else '')
                raise SixAxisPlanError(f'the optimiser found no solution{with_band} '
                                       f'({res.stats.status}, {res.stats.iterations} '
                                       'iterations)')
            profile = res.profile
            for _ in range(2 if duration > 0 else 0):
                profile = profile.scaled_in_time(duration / profile.duration)
            traj, chk, problems = self.trajectory(prob, profile, consistency, smooth=True)
            over_tau = chk.peak_torque - lim.torque
            over_v = chk.peak_speed - vel_lim
            smooth_fix = tighten_smooth(self.smooth_limits, sreq, chk)
            try:
                smooth_fix.update(tighten_band(sreq, prob.band, chk))
            except PlanError as exc:
                raise SixAxisPlanError(exc.message) from None
            limit_hit = np.any(over_tau > 0) or np.any(over_v > 0) or bool(smooth_fix)
            if not limit_hit or attempt == s.adapt_rounds:
                return res, profile, traj, chk, notes + problems, spent, iters
            notes.append('limits tightened after the played check: ' + '; '.join(chk.problems))
            sreq = replace(sreq, **smooth_fix)
            sreq = replace(sreq, torque_limit=np.where(
                over_tau > 0, sreq.torque_limit - over_tau - 1e-3 * lim.torque,
                sreq.torque_limit), velocity_limit=np.where(
                over_v > 0, sreq.velocity_limit - over_v - 1e-3 * vel_lim, sreq.velocity_limit))
        raise AssertionError('unreachable')

    def min_duration(self, prob: SixAxisProblem) -> tuple:
        """The time-optimal plan's (duration [s], _solve_checked output); cached. Its
        message is dense enough for the played tolerances and limits, not for the consistency
        rule (only a time-optimal plan that is the answer needs that: ``plan``)."""
        if 'time' not in prob.min_duration:
            req = replace(self._nlp_limits(prob.band), duration=0.0, time_weight=1.0,
                          energy_weight=TIME_OBJECTIVE_ENERGY_WEIGHT)
            out = self._solve_checked(prob, req, 0.0, consistency=False)
            prob.min_duration['time'] = (out[1].duration, out)
        return prob.min_duration['time']

    def plan(self, prob: SixAxisProblem, objective: str = 'energy',
             duration: float = 0.0) -> SixAxisPlan:
        """Time-optimal (``objective`` 'time') or mechanical-energy-optimal at ``duration``
        [s] ('energy'); SixAxisPlanError when it cannot be planned or fails its check."""
        if objective not in OBJECTIVES6:
            raise SixAxisPlanError(f'objective must be one of {list(OBJECTIVES6)}, '
                                   f'not {objective!r}')
        if objective == 'energy' and not (np.isfinite(duration) and duration > 0):
            raise SixAxisPlanError('an energy plan needs a duration > 0 s')
        t_min, t_out = self.min_duration(prob)
        if objective == 'time':
            res, profile, traj, chk, notes, spent, iters = t_out
            traj, chk, problems = self.trajectory(prob, profile, smooth=True)
            notes = notes + problems
        else:
            if duration < t_min * (1 - 1e-9):
                raise SixAxisPlanError(f'duration {duration:.4f} s is shorter than the '
                                       f'time-optimal {t_min:.4f} s for this path, law and '
                                       'limits')
            sreq = replace(self._nlp_limits(prob.band), duration=float(duration),
                           time_weight=0.0,
                           energy_weight=1.0)
            res, profile, traj, chk, notes, spent, iters = self._solve_checked(
                prob, sreq, duration)
        problems = chk.problems + [n for n in notes if n.startswith('inconsistent')]
        if problems:
            raise SixAxisPlanError(f'the {objective} plan fails the played check: '
                                   + '; '.join(problems))
        opt = float(res.electrical_energy if prob.energy_model != 'mechanical' else res.energy)
        return SixAxisPlan(objective, profile, profile.duration, t_min, opt,
                           spent, iters, prob.build_time, traj, chk, prob.configuration, notes,
                           prob.energy_model)


# --- placement ------------------------------------------------------------------------------
#: the keys of a path mapping that hold positions [m] (moved by a placement); every other key
#: (normals, radii, the orientation block's directions and rotations) is unchanged by a shift
POSITION_KEYS = ('center', 'waypoints')


def translated_spec(spec: dict, offset) -> dict:
    """The path mapping ``spec`` (orientation block included) moved by ``offset`` (3,) [m]:
    its centre or waypoints shifted; the tool-orientation law is unchanged by a translation
    (fixed rotations, a plane's normal, slerp keyframes on theta)."""
    d = np.asarray(offset, float)
    if d.shape != (3,) or not np.all(np.isfinite(d)):
        raise SixAxisPlanError(f'a placement offset is 3 finite numbers [m], not {offset!r}')
    out = dict(spec)
    for key in POSITION_KEYS:
        if key in out and out[key] is not None:
            v = np.asarray(out[key], float)
            if v.shape[-1:] != (3,):
                raise SixAxisPlanError(f"path '{key}' must hold points of 3 coordinates")
            out[key] = (v + d).tolist()
    return out


@dataclass
class PlacementPoint:
    """One placement of the task: its offset (3,) [m] from the path file's, the played energy
    [J] of the energy model asked for (NaN where refused) and the refusal's reason."""

    offset: np.ndarray
    energy: float
    reason: str = ''
    plan: SixAxisPlan | None = field(default=None, repr=False)


@dataclass
class SixAxisPlacement:
    """A grid search over offsets of a six-axis task: every point, the best, on which grid."""

    points: list
    energy_model: str
    duration: float
    grid_size: int

    @property
    def planned(self) -> list:
        return [p for p in self.points if np.isfinite(p.energy)]

    @property
    def best(self) -> PlacementPoint | None:
        ok = self.planned
        return min(ok, key=lambda p: p.energy) if ok else None


def placement_offsets(lo, hi, n) -> np.ndarray:
    """(M, 3) [m]: the grid of offsets in the box [lo, hi] with n (3,) points per axis (1:
    the box's middle on that axis)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    n = [int(k) for k in n]
    if lo.shape != (3,) or hi.shape != (3,) or np.any(hi < lo) or min(n) < 1:
        raise SixAxisPlanError('placement box: lo <= hi (3 values each), n >= 1 per axis')
    axes = [np.linspace(a, b, k) if k > 1 else np.array([0.5 * (a + b)])
            for a, b, k in zip(lo, hi, n)]
    return np.array(np.meshgrid(*axes, indexing='ij')).reshape(3, -1).T


def place(planner: SixAxisPlanner, spec: dict, offsets, duration: float,
          energy_model: str = 'electrical', grid_size: int = 40, progress=None
          ) -> SixAxisPlacement:
    """Energy plan of ``spec`` (a path mapping with an orientation block) moved by every
    offset (M, 3) [m], each on the ``grid_size`` grid and checked as played; the energy of
    ``energy_model`` compared (mechanical: the played mechanical energy; electrical*: the
    played electrical energy). A placement that cannot be planned (unreachable, shorter than
    its time-optimal duration, fails its check) is kept with its reason. ``progress(k, M,
    point)`` after each."""
    offsets = np.atleast_2d(np.asarray(offsets, float))
    points = []
    for k, d in enumerate(offsets):
        try:
            moved = translated_spec(spec, d)
            path, law = task_from_spec(moved)
            prob = planner.problem(path, law, grid_size, energy_model=energy_model,
                                   process=task_process(moved))
            plan = planner.plan(prob, 'energy', duration)
            e = plan.energy if energy_model == 'mechanical' else plan.electrical_energy
            pt = PlacementPoint(d.copy(), float(e), plan=plan)
        except SixAxisPlanError as exc:
            pt = PlacementPoint(d.copy(), float('nan'), str(exc))
        points.append(pt)
        if progress is not None:
            progress(k + 1, len(offsets), pt)
    return SixAxisPlacement(points, energy_model, float(duration), int(grid_size))


def refine_placement(planner: SixAxisPlanner, spec: dict, result: SixAxisPlacement, lo, hi,
                     step, min_step: float, progress=None) -> SixAxisPlacement:
    """Compass search from ``result``'s best offset, inside the box [lo, hi] (3,) [m]: plan
    the 6 neighbours at +-``step`` (3,) [m] along each axis (on the result's grid, duration
    and energy model, as ``place``); move to the best that is lower, else halve the step,
    until every axis's step is below ``min_step`` [m]. Every point planned is kept (the
    grid's and the search's); the best of all is ``best``. A local search: it finds a lower
    energy near the grid's best, it proves nothing about the box (no bound)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    h = np.asarray(step, float).copy()
    best = result.best
    if best is None:
        return result
    seen = {tuple(np.round(p.offset, 9)): p for p in result.points}
    points = list(result.points)
    x, e = best.offset.copy(), best.energy
    while np.any(h >= min_step):
        trial = []
        for ax in range(3):
            if h[ax] < min_step:
                continue
            for sgn in (-1.0, 1.0):
                d = x.copy()
                d[ax] = np.clip(d[ax] + sgn * h[ax], lo[ax], hi[ax])
                key = tuple(np.round(d, 9))
                if key not in seen:
                    pt = place(planner, spec, d[None], result.duration, result.energy_model,
                               result.grid_size).points[0]
                    seen[key] = pt
                    points.append(pt)
                    if progress is not None:
                        progress(len(points), h.copy(), pt)
                trial.append(seen[key])
        better = [p for p in trial if np.isfinite(p.energy) and p.energy < e]
        if better:
            b = min(better, key=lambda p: p.energy)
            x, e = b.offset.copy(), b.energy
        else:
            h = h / 2.0
    return SixAxisPlacement(points, result.energy_model, result.duration, result.grid_size)


def on_box_edge(offset, lo, hi, tol: float = 1e-9) -> list:
    """The axes (0, 1, 2) on which ``offset`` lies on the box's face: there a lower energy may
    lie outside the box."""
    o, lo, hi = (np.asarray(v, float) for v in (offset, lo, hi))
    return [ax for ax in range(3) if hi[ax] > lo[ax] and (o[ax] <= lo[ax] + tol
                                                          or o[ax] >= hi[ax] - tol)]