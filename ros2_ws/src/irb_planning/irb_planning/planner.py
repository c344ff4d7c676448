"""The planning core: request in, checked plan out (numpy/dataclasses, no ROS).

``Planner.plan(PlanRequest) -> PlanResult`` or raises ``PlanError`` with an ERROR_* code.
Problems are built once per (path, grid, boundary, friction map) and cached; every request
re-solves them with new bounds/parameters. Every returned plan has been resampled at
``evaluation_rate_hz`` by the independent evaluator; its energy is the one reported.
Thread safety: ``plan`` may be called from several threads; each cached problem serialises
its own solves, and the model's pinocchio workspace is guarded by a lock.
"""
from __future__ import annotations

import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from irb_description.friction import FrictionMap, FrictionMapError, load_friction_map
from irb_description.model import RobotModel, UnreachableError
from irb_description.path import CirclePath, joint_path

from .baselines import EnergyBound, trapezoid_profile
from .evaluator import Evaluation, LimitSet, evaluate
from .fourier import FourierProblem
from .problem import (casadi_friction, casadi_inverse_dynamics, effective_speed_limit,
                      path_dynamics)
from .profile import ThetaProfile
from .request import (ERROR_FRICTION_MAP, ERROR_INFEASIBLE_DURATION, ERROR_INVALID_REQUEST,
                      ERROR_SOLVER, ERROR_UNREACHABLE, OBJECTIVE_ENERGY, OBJECTIVE_TIME,
                      OBJECTIVE_TRAPEZOID, PlanError, PlanRequest, validate)
from .transcription import (BOUNDARY_PERIODIC, TIME_OBJECTIVE_ENERGY_WEIGHT, SolveRequest,
                            Transcription)


@dataclass(frozen=True)
class PlannerSettings:
    """Planner settings (the node's parameters; units in the names)."""

    grid_size: int = 200                 # theta nodes
    min_theta_dot_rad_s: float = 0.05    # delta: theta_dot >= delta inside the path
    friction_smoothing_rad_s: float = 1e-3   # tanh(v / eps) for sign(v) in the NLP
    abs_smoothing_j_rad: float = 0.0     # 0: exact |.| (split); > 0: sqrt(y^2 + eps^2)
    constraint_margin: float = 0.005     # fraction of every limit kept free in the NLP
    max_iterations: int = 1000
    tolerance: float = 1e-8
    warm_start: bool = True
    trapezoid_ramp_fraction: float = 0.1  # of the duration, each ramp
    evaluation_rate_hz: float = 1000.0
    cache_size: int = 8                  # built problems kept (LRU)


@dataclass
class PlanResult:
    """A checked plan. profile (theta grid); evaluation at evaluation_rate_hz (energy [J],
    duration [s], peak torques [N m], q/qd/qdd/tau); optimizer_energy [J] (the optimiser's
    own quadrature); min_duration [s] (time-optimal, same boundary); baseline = trapezoid at
    the same duration (evaluated; may violate limits: baseline.violations)."""

    objective: str
    profile: ThetaProfile
    evaluation: Evaluation
    optimizer_energy: float
    min_duration: float
    solve_time: float
    iterations: int
    status: str
    baseline: Evaluation | None
    joint_names: list[str]
    request: PlanRequest
    fourier_coeffs: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)


class _Entry:
    """Everything built for one (path, grid, boundary, friction map)."""

    def __init__(self, nodes, mids, transcription):
        self.nodes, self.mids, self.transcription = nodes, mids, transcription
        self.fourier: dict[int, FourierProblem] = {}
        self.fourier_nodes = None
        self.bound: EnergyBound | None = None
        self.min_duration: dict[tuple, tuple] = {}
        self.lock = threading.Lock()


class Planner:
    """Builds, caches and solves the planning problems for one robot model."""

    def __init__(self, model: RobotModel | None = None,
                 settings: PlannerSettings | None = None):
        self.model = model or RobotModel.load()
        self.settings = settings or PlannerSettings()
        self._model_lock = threading.Lock()
        self._cache: OrderedDict = OrderedDict()
        self._cache_lock = threading.Lock()
        self._inverse_dynamics = casadi_inverse_dynamics(self.model)

    # --- the pieces ---------------------------------------------------------------------
    def friction_map(self, path: str) -> FrictionMap:
        """The nominal map ('') or the file; PlanError(FRICTION_MAP) if it is unusable."""
        if not path:
            return self.model.friction
        try:
            return load_friction_map(Path(path), self.model.joint_names)
        except FrictionMapError as exc:
            raise PlanError(ERROR_FRICTION_MAP, str(exc)) from exc

    def sample_path(self, path: CirclePath):
        """theta (K,) -> JointPath of ``path`` (thread safe)."""
        def sample(theta):
            with self._model_lock:
                return joint_path(self.model, path, theta)
        return sample

    def torque(self, friction: FrictionMap):
        """(q, qd, qdd) -> tau (n,) [N m]: pinocchio RNEA + numpy friction (the evaluator's)."""
        def tau(q, qd, qdd):
            with self._model_lock:
                return self.model.inverse_dynamics_with_friction(q, qd, qdd, friction)
        return tau

    def _entry(self, req: PlanRequest, path: CirclePath, fm: FrictionMap) -> _Entry:
        fkey = (req.friction_map, Path(req.friction_map).stat().st_mtime
                if req.friction_map else 0.0)
        key = (req.path_key, req.grid_size, req.boundary, fkey)
        with self._cache_lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                return self._cache[key]
        s = self.settings
        theta = np.linspace(0.0, 2 * np.pi, req.grid_size)
        sample = self.sample_path(path)
        try:
            nodes = path_dynamics(theta, sample, self._inverse_dynamics)
            mids = path_dynamics(0.5 * (theta[1:] + theta[:-1]), sample,
                                 self._inverse_dynamics)
        except UnreachableError as exc:
            raise PlanError(ERROR_UNREACHABLE, f'path unreachable: {exc}') from exc
        friction = casadi_friction(fm, s.friction_smoothing_rad_s)
        tr = Transcription(nodes, mids, friction, req.boundary, s.abs_smoothing_j_rad,
                           s.max_iterations, s.tolerance, s.warm_start)
        entry = _Entry(nodes, mids, tr)
        entry.friction = friction
        entry.friction_map = fm
        with self._cache_lock:
            self._cache[key] = entry
            while len(self._cache) > s.cache_size:
                self._cache.popitem(last=False)
        return entry

    def _limits(self, req: PlanRequest, fm: FrictionMap) -> tuple[SolveRequest, LimitSet]:
        """(limits for the NLP with margin, limits the evaluator checks)."""
        lim = self.model.limits
        vel = effective_speed_limit(lim.velocity, fm) * req.limit_scaling
        tau = lim.torque * req.limit_scaling
        keep = 1.0 - self.settings.constraint_margin
        nlp = SolveRequest(0.0, 0.0, 1.0, self.settings.min_theta_dot_rad_s, vel * keep,
                           tau * keep)
        return nlp, LimitSet(vel, tau, lim.lower, lim.upper)

    def min_duration(self, entry: _Entry, base: SolveRequest) -> tuple[float, object]:
        """Time-optimal duration [s] and its result (cached per limits)."""
        key = (base.min_theta_dot, tuple(base.velocity_limit), tuple(base.torque_limit))
        with entry.lock:
            if key in entry.min_duration:
                return entry.min_duration[key]
        req = SolveRequest(0.0, 1.0, TIME_OBJECTIVE_ENERGY_WEIGHT, base.min_theta_dot,
                           base.velocity_limit, base.torque_limit)
        res = entry.transcription.solve(req, warm=False)
        if not res.stats.success:
            raise PlanError(ERROR_SOLVER, f'time-optimal problem failed: {res.stats.status}')
        with entry.lock:
            entry.min_duration[key] = (res.duration, res)
        return res.duration, res

    def fourier_problem(self, entry: _Entry, order: int, sample) -> FourierProblem:
        with entry.lock:
            if order not in entry.fourier:
                if entry.fourier_nodes is None:
                    theta = np.linspace(0.0, 2 * np.pi, entry.nodes.theta.size,
                                        endpoint=False)
                    entry.fourier_nodes = path_dynamics(theta, sample,
                                                        self._inverse_dynamics)
                entry.fourier[order] = FourierProblem(
                    entry.fourier_nodes, entry.friction, order, 2 * self.settings.max_iterations,
                    self.settings.tolerance)
            return entry.fourier[order]

    def bound(self, req: PlanRequest, duration: float) -> float:
        """Convex lower bound [J] at ``duration`` for the request's path/grid/limits."""
        req = validate(req, self.settings.grid_size)
        fm = self.friction_map(req.friction_map)
        path = request_path(req)
        entry = self._entry(req, path, fm)
        base, _ = self._limits(req, fm)
        with entry.lock:
            if entry.bound is None:
                entry.bound = EnergyBound(entry.nodes, entry.mids, fm, req.boundary,
                                          2 * self.settings.max_iterations)
        res = entry.bound.solve(SolveRequest(duration, 0.0, 1.0, base.min_theta_dot,
                                             base.velocity_limit, base.torque_limit))
        if not res.stats.success:
            raise PlanError(ERROR_SOLVER, f'bound problem failed: {res.stats.status}')
        return res.energy

    # --- the request --------------------------------------------------------------------
    def plan(self, request: PlanRequest) -> PlanResult:
        """Plan ``request`` (see module docstring); raises PlanError."""
        s = self.settings
        req = validate(request, s.grid_size)
        fm = self.friction_map(req.friction_map)
        path = request_path(req)
        entry = self._entry(req, path, fm)
        base, checked = self._limits(req, fm)
        sample = self.sample_path(path)
        t_min, t_res = self.min_duration(entry, base)
        if req.duration > 0 and req.duration < t_min * (1 - 1e-9):
            raise PlanError(ERROR_INFEASIBLE_DURATION,
                            f'duration {req.duration:.4f} s is shorter than the time-optimal '
                            f'{t_min:.4f} s for this path and limits')
        coeffs = None
        notes = []
        t0 = time.perf_counter()
        if req.objective == OBJECTIVE_TIME:
            profile, e_opt, stats = t_res.profile, t_res.energy, t_res.stats
        elif req.objective == OBJECTIVE_TRAPEZOID:
            profile = trapezoid_profile(req.duration, s.trapezoid_ramp_fraction)
            e_opt, stats = float('nan'), None
        else:
            sreq = SolveRequest(req.duration, req.time_weight, 1.0, base.min_theta_dot,
                                base.velocity_limit, base.torque_limit)
            if req.objective == OBJECTIVE_ENERGY:
                res = entry.transcription.solve(sreq)
            else:
                res = self.fourier_problem(entry, req.fourier_order, sample).solve(sreq)
                coeffs = res.coeffs
            if not res.stats.success or res.profile is None:
                raise PlanError(ERROR_SOLVER, f'{req.objective} problem failed: '
                                f'{res.stats.status} after {res.stats.iterations} iterations')
            profile, e_opt, stats = res.profile, res.energy, res.stats
        elapsed = time.perf_counter() - t0
        evaluation = evaluate(profile, sample, self.torque(fm), checked, s.evaluation_rate_hz)
        if evaluation.violations:
            code = (ERROR_INFEASIBLE_DURATION if req.objective == OBJECTIVE_TRAPEZOID
                    else ERROR_SOLVER)
            raise PlanError(code, f'{req.objective} plan violates limits at '
                            f'{s.evaluation_rate_hz:g} Hz: ' + '; '.join(evaluation.violations))
        baseline = evaluation if req.objective == OBJECTIVE_TRAPEZOID else evaluate(
            trapezoid_profile(evaluation.duration, s.trapezoid_ramp_fraction), sample,
            self.torque(fm), checked, s.evaluation_rate_hz)
        if baseline.violations:
            notes.append('trapezoid baseline violates limits: ' + baseline.violations[0])
        if req.boundary == BOUNDARY_PERIODIC and req.objective != OBJECTIVE_TRAPEZOID:
            notes.append('periodic profile: starts and ends at theta_dot = '
                         f'{profile.theta_dot[0]:.3f} rad/s')
        return PlanResult(
            objective=req.objective, profile=profile, evaluation=evaluation,
            optimizer_energy=e_opt, min_duration=t_min,
            solve_time=stats.solve_time if stats else elapsed,
            iterations=stats.iterations if stats else 0,
            status=stats.status if stats else 'closed form', baseline=baseline,
            joint_names=list(self.model.joint_names), request=req, fourier_coeffs=coeffs,
            notes=notes)

    def evaluate(self, result: PlanResult, rate_hz: float) -> Evaluation:
        """``result``'s profile resampled by the evaluator at ``rate_hz`` [Hz], with the
        dynamics and limits ``plan`` checked it with (e.g. its energy at a finer rate)."""
        req = result.request
        fm = self.friction_map(req.friction_map)
        return evaluate(result.profile, self.sample_path(request_path(req)), self.torque(fm),
                        self._limits(req, fm)[1], rate_hz)

    def node_samples(self, result: PlanResult) -> dict:
        """The plan at its theta nodes for the controller: t (N,) [s]; q, qd, qdd, tau (N, n)
        (tau by the evaluator's dynamics, theta_ddot at a node = mean of its intervals)."""
        req, pr = result.request, result.profile
        jp = self.sample_path(request_path(req))(pr.theta)
        td, tdd = pr.theta_dot[:, None], pr.theta_ddot_nodes[:, None]
        qd = jp.dq * td
        qdd = jp.ddq * td ** 2 + jp.dq * tdd
        torque = self.torque(self.friction_map(req.friction_map))
        tau = np.array([torque(jp.q[k], qd[k], qdd[k]) for k in range(pr.theta.size)])
        return {'t': pr.times, 'q': jp.q, 'qd': qd, 'qdd': qdd, 'tau': tau}


def request_path(req: PlanRequest) -> CirclePath:
    """The geometric path of a (validated) request: the one place a request becomes a path."""
    try:
        return CirclePath(req.center, req.radius, req.start_angle, req.direction)
    except ValueError as exc:
        raise PlanError(ERROR_INVALID_REQUEST, str(exc)) from exc


def request_error_code(exc: Exception) -> int:
    """Map an unexpected exception to an error code (for the node's last-resort handler)."""
    if isinstance(exc, PlanError):
        return exc.code
    if isinstance(exc, UnreachableError):
        return ERROR_UNREACHABLE
    if isinstance(exc, FrictionMapError):
        return ERROR_FRICTION_MAP
    if isinstance(exc, ValueError):
        return ERROR_INVALID_REQUEST
    return ERROR_SOLVER
