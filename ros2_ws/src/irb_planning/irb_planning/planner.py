"""The planning core: request in, checked plan out (numpy/dataclasses, no ROS).

``Planner.plan(PlanRequest) -> PlanResult`` or raises ``PlanError`` with an ERROR_* code.
Problems are built once per (path, grid, boundary, friction map) and cached; every request
re-solves them with new bounds/parameters. What a request gets back has passed, in order:

1. the path check along the whole path (``irb_description.path.check_joint_path``: reachable,
   continuous, inside the position limits between samples too; else ERROR_UNREACHABLE);
2. the solve, the profile rescaled so that its exact time law gives the requested duration,
   and the 1 kHz evaluator (``evaluator.evaluate``); where the exact friction map or the
   torque between grid points breaks a limit the NLP kept with its margin, that limit is
   tightened by the measured excess and the problem re-solved (``adapt_rounds`` times);
3. the trajectory message, dense enough that its quintic interpolation stays on the path,
   and the independent check of that message as a controller plays it (``verify.py``: own
   time integration, own DH kinematics, own reading of the friction map). A plan that fails
   it is refused, never returned.
Thread safety: ``plan`` may be called from several threads; each cached problem serialises
its own solves, and the model's pinocchio workspace is guarded by a lock.
"""
from __future__ import annotations

import ctypes
import re
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np
from irb_description.electrical import load_electrical
from irb_description.friction import FrictionMap, FrictionMapError
from irb_description.model import RobotModel, UnreachableError
from irb_description.path import (CirclePath, JointPath, PathBase, check_joint_path,
                                  joint_path, path_from_spec)

from .baselines import EnergyBound, trapezoid_profile
from .certificate import JerkCertificate, curvature, jerk_certificate
from .evaluator import Evaluation, LimitSet, evaluate
from .fourier import FourierProblem
from .map_files import default_map_dirs, read_map, resolve_map_path
from .problem import (casadi_friction, casadi_inverse_dynamics, effective_speed_limit,
                      path_dynamics)
from .profile import ThetaProfile
from .request import (ERROR_FRICTION_MAP, ERROR_INFEASIBLE_DURATION, ERROR_INVALID_REQUEST,
                      ERROR_SOLVER, ERROR_UNREACHABLE, ENERGY_MECHANICAL, ENERGY_MODELS,
                      OBJECTIVE_ENERGY, OBJECTIVE_TIME,
                      OBJECTIVE_TRAPEZOID, PlanError, PlanRequest, validate)
from .transcription import (BOUNDARY_PERIODIC, BOUNDARY_REST,
                            RAMP_SPEED_EXPONENT, TIME_OBJECTIVE_ENERGY_WEIGHT, JerkPath,
                            SolveRequest, TcpPath, Transcription)
from irb_description.trajectory_rules import (CONSISTENCY_ATOL, CONSISTENCY_RTOL,
                                              MIN_POINT_SPACING_S, STAMP_RESOLUTION_S,
                                              gate_limit_notes, spaced, stamps_ns,
                                              worst_inconsistency)
from .verify import (LIMIT_RTOL, ArmKinematics, Circle, MapFriction, PathCurve,
                     SmoothLimits, TcpBand, Verification, verify_plan)


#: the check plays every message interval shorter than SHORT_INTERVAL_S [s] (the 1 ms
#: twins, not every interval of a dense grid) at >= this many
#: instants (others at >= 8 and play_rate_hz): the 1 ms twins around a blend end carry a
#: spike of torque and TCP acceleration whose sampled peak moved by 0.2-2 % with the
#: sampling phase at 10 samples (issue 28)
PEAK_SAMPLES_PER_INTERVAL = 64
SHORT_INTERVAL_S = 1.5e-3

#: step of jerk_path's difference formulas for third derivatives, as a share of the grid
#: interval (second-order differences: a relative error ~1e-6 on the splines of
#: bench_floor_certificate.py; small, so that a spline knot rarely lies within it)
THIRD_STEP = 1e-3


@dataclass(frozen=True)
class PlannerSettings:
    """Planner settings (the node's parameters; units in the names)."""

    grid_size: int = 200                 # theta nodes
    max_grid_size: int = 1000            # largest grid a request may ask for
    min_theta_dot_rad_s: float = 0.05    # delta: theta_dot >= delta inside the path
    friction_smoothing_rad_s: float = 1e-3   # tanh(v / eps) for sign(v) in the NLP
    abs_smoothing_j_rad: float = 0.0     # 0: exact |.| (split); > 0: sqrt(y^2 + eps^2)
    constraint_margin: float = 0.005     # fraction of every limit kept free in the NLP
    max_iterations: int = 1000
    tolerance: float = 1e-8
    warm_start: bool = True
    # the warm solver's iteration cap; a warm solve that reaches it is repeated cold. 40
    # suits a request near the last one; the cycle planner's fronts (durations 10-25 % apart)
    # take 20-100 warm iterations, fewer than cold, and set more (cycle.FRONT_WARM_ITERATIONS)
    warm_max_iterations: int = 40
    # a warm start when the duration and limits are within this fraction of the last solve's
    warm_window: float = 0.2
    # the first fixed-duration solve after the time-optimal one starts from its solution
    warm_from_time_optimal: bool = False
    # > 0: IPOPT's initial barrier for a warm re-solve at the same duration (0: 1e-4)
    resolve_mu_init: float = 0.0
    # >= 0: IPOPT's mumps_permuting_scaling for every solver (MUMPS ICNTL(6)); -1: IPOPT's
    # default (7, automatic). The cycle's fronts set 0 (cycle.FRONT_MUMPS_PERMUTING_SCALING)
    mumps_permuting_scaling: int = -1
    trapezoid_ramp_fraction: float = 0.1  # of the duration, each ramp
    evaluation_rate_hz: float = 1000.0
    # the independent check plays the message by quintic interpolation at this rate (and at
    # least 8 samples per interval): the reported peaks are the played ones
    play_rate_hz: float = 10000.0
    min_point_spacing_s: float = MIN_POINT_SPACING_S   # between message points
    cache_size: int = 8                  # built problems kept (LRU)
    memory_limit_mib: float = 400.0      # drop least recently used problems above this RSS
    friction_map_dirs: tuple = ()        # where maps may be read from; () = default_map_dirs()
    path_tolerance_m: float = 1e-4       # TCP deviation of the message played quintically
    max_trajectory_points: int = 20000   # message points at most
    adapt_rounds: int = 3                # re-solves with limits tightened by measured excess
    # share of a spline path's grid nodes placed by its curvature, and a node at every knot
    # (path_grid); 0 = the uniform grid
    curvature_grid_share: float = 0.3
    path_check_samples: int = 4096       # theta samples of the along-path check
    electrical_smoothing_w: float = 0.5  # eps [W] of |.| in the electrical NLP objective
    electrical_config: str = ''          # electrical-model YAML; '' = irb_description's
    # > 0: a fixed-duration request at least this many times the optimiser's time-optimal
    # duration does not play and check the time-optimal profile (see Planner.min_duration)
    min_duration_check_factor: float = 0.0
    # smoothness limits (issue 28), on by default: every plan keeps them as played, and a
    # rest-to-rest plan starts and ends with theta_ddot = 0 (the static torque, no step)
    jerk_limits: bool = True
    joint_jerk_limit_rad_s3: tuple = (500.0, 500.0, 500.0)
    tcp_jerk_limit_m_s3: float = 100.0
    # rigid-body torque rate; default: each joint's torque limit in 50 ms
    torque_rate_limit_nm_s: tuple = (14000.0, 18000.0, 9000.0)
    # report what the smoothness limits cost each energy and time plan (PlanResult.limit_cost):
    # one more solve of the same problem without the jerk rows, warm-started from the plan;
    # off for the placement search (its many plans need no such figure)
    limit_cost: bool = True


#: the note that carries a plan's LimitCost (the service answer's message, plan's summary)
LIMIT_COST_NOTE = 'cost of the smoothness limits'


@dataclass(frozen=True)
class LimitCost:
    """What the smoothness limits (jerk_limits) cost one plan, issue 28: the optimiser's
    objective figure of the plan (``with_limits``) against the same problem, request and grid
    solved without the joint-jerk, torque-rate and TCP-jerk rows (``without_limits``; warm-
    started from the plan, so at most the plan's figure up to the solver's tolerance; the rest
    ends keep theta_ddot = 0 and their constant-jerk intervals, which are part of the limits
    too: the figure leaves their share out). ``quantity``: 'energy' [J] for an energy plan
    (the objective's energy model), 'duration' [s] for a time-optimal one. Both figures are the
    optimiser's own quadrature (the plan's played energy is the evaluation's). ``solve_time``
    [s] and ``iterations`` of the extra solve; ``status``: IPOPT's, without_limits NaN if it
    failed (the plan stands)."""

    quantity: str
    with_limits: float
    without_limits: float
    solve_time: float
    iterations: int
    status: str
    rest: bool = False      # rest-to-rest: the reference keeps the constant-jerk rest ends

    @property
    def cost(self) -> float:
        """with / without - 1 (NaN if the reference solve failed)."""
        return self.with_limits / self.without_limits - 1.0

    def text(self) -> str:
        unit = 'J' if self.quantity == 'energy' else 's'
        head = f'{self.quantity} {LIMIT_COST_NOTE}: '
        if not np.isfinite(self.without_limits):
            return head + (f'not known (the solve without the jerk rows failed: {self.status}, '
                           f'{self.solve_time:.2f} s)')
        return head + (f'{100 * self.cost:+.2f} % ({self.with_limits:.6g} {unit} with them, '
                       f'{self.without_limits:.6g} {unit} without the jerk and torque-rate '
                       'rows' + (' (rest ends still at theta_ddot = 0)' if self.rest else '')
                       + f', optimiser figures, extra solve {self.solve_time:.2f} s, '
                       f'{self.iterations} iterations)')


def limit_cost_from_message(message: str) -> dict | None:
    """The LimitCost note of a plan's one-line message (the service answer's): {'note',
    'quantity', 'cost' (fraction), 'with', 'without'} ('cost' etc. NaN if not known), None
    without one (jerk_limits or limit_cost off, a baseline objective)."""
    note = next((n for n in message.split('; ') if f' {LIMIT_COST_NOTE}: ' in n), None)
    if note is None:
        return None
    m = re.match(r'(\w+) [^:]*: ([+-][0-9.]+) % \(([0-9.e+-]+) \w+ with them, '
                 r'([0-9.e+-]+) \w+ without', note)
    nan = float('nan')
    return {'note': note, 'quantity': note.split(' ', 1)[0],
            'cost': float(m.group(2)) / 100 if m else nan,
            'with': float(m.group(3)) if m else nan, 'without': float(m.group(4)) if m else nan}


@dataclass
class PlanResult:
    """A checked plan. profile (theta grid); evaluation at evaluation_rate_hz (energy [J],
    duration [s], peak torques [N m], q/qd/qdd/tau); optimizer_energy [J] (the optimiser's
    own quadrature); min_duration [s] (time-optimal, same boundary); baseline = trapezoid at
    the same duration (evaluated; may violate limits: baseline.violations)."""

    objective: str
    profile: ThetaProfile
    evaluation: Evaluation
    optimizer_energy: float              # mechanical [J], the optimiser's own quadrature
    min_duration: float
    solve_time: float
    iterations: int
    status: str
    baseline: Evaluation | None
    joint_names: list[str]
    request: PlanRequest
    fourier_coeffs: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    trajectory: dict | None = None       # the message's points: t, theta, q, qd, qdd, tau
    verification: Verification | None = None   # the independent check of that message
    optimizer_electrical_energy: float = float('nan')  # [J], own quadrature, electrical
    # what the smoothness limits cost this plan (settings.limit_cost; None: not measured, for
    # a trapezoid, a Fourier plan or with jerk_limits off)
    limit_cost: LimitCost | None = None


class _Entry:
    """Everything built for one (path, grid, boundary, friction map)."""

    def __init__(self, nodes, mids, transcription):
        self.nodes, self.mids, self.transcription = nodes, mids, transcription
        self.fourier: dict[int, FourierProblem] = {}
        self.fourier_nodes = None
        self.bound: EnergyBound | None = None
        self.min_duration: dict[tuple, tuple] = {}
        self.min_duration_unchecked: dict[tuple, float] = {}   # [s], see min_duration
        self.tightened: dict[tuple, dict] = {}   # per objective kind, see _solve_checked
        self.free_duration: dict[tuple, tuple] = {}   # time-optimal without jerk rows
        self.lock = threading.Lock()


class Planner:
    """Builds, caches and solves the planning problems for one robot model."""

    def __init__(self, model: RobotModel | None = None,
                 settings: PlannerSettings | None = None):
        self.model = model or RobotModel.load()
        self.settings = settings or PlannerSettings()
        if not self.settings.min_theta_dot_rad_s > 0:
            raise ValueError('min_theta_dot_rad_s must be > 0 (the controller must not stall)')
        if not self.settings.min_point_spacing_s > 0:
            raise ValueError('min_point_spacing_s must be > 0 (message points microseconds '
                             'apart are played with accelerations the plan does not have)')
        self._model_lock = threading.Lock()
        self._cache: OrderedDict = OrderedDict()
        self._cache_lock = threading.Lock()
        self._checked_paths: OrderedDict = OrderedDict()
        self._inverse_dynamics = casadi_inverse_dynamics(self.model)
        self.map_dirs = [Path(d) for d in self.settings.friction_map_dirs] or default_map_dirs()
        k = self.model.kinematics
        lim = self.model.limits
        self.electrical = load_electrical(
            Path(self.settings.electrical_config) if self.settings.electrical_config
            else None).axes(len(self.model.joint_names))
        self._kin = dict(a=k.dh_a, alpha=k.dh_alpha, d=k.dh_d, offset=k.dh_offset,
                         lower=lim.lower, upper=lim.upper)

    # --- the pieces ---------------------------------------------------------------------
    def friction_map(self, name: str) -> tuple[FrictionMap, dict]:
        """(map, its joints mapping) of the nominal map ('') or of a file in the allowed
        directories; PlanError(FRICTION_MAP) if it is not allowed or not usable."""
        if not name:
            fm = self.model.friction
            return fm, fm.to_dict()['friction_map']['joints']
        path = resolve_map_path(name, self.map_dirs)
        fm, block = read_map(path, self.model.joint_names)
        return fm, block['joints']

    def sample_path(self, path: PathBase):
        """theta (K,) -> JointPath of ``path`` (thread safe)."""
        def sample(theta):
            with self._model_lock:
                return joint_path(self.model, path, theta)
        return sample

    def torque(self, friction: FrictionMap):
        """(q, qd, qdd) (M, n) -> tau (M, n) [N m]: pinocchio RNEA + numpy friction map (the
        evaluator's dynamics)."""
        def tau(q, qd, qdd):
            q, qd, qdd = (np.atleast_2d(np.asarray(x, float)) for x in (q, qd, qdd))
            return self.rigid_torque(q, qd, qdd) + friction.torque(qd)
        return tau

    def rigid_torque(self, q, qd, qdd):
        """pinocchio RNEA on the URDF, no friction, for (M, n) arrays -> (M, n) [N m]."""
        with self._model_lock:
            return self.model.inverse_dynamics_batch(q, qd, qdd)

    def check_path(self, req: PlanRequest, path: PathBase) -> None:
        """The whole joint motion along the path (cached per path); PlanError(UNREACHABLE)."""
        key = req.path_key
        with self._cache_lock:
            if key in self._checked_paths:
                self._checked_paths.move_to_end(key)
                return
        try:
            with self._model_lock:
                check_joint_path(self.model, path, self.settings.path_check_samples)
        except UnreachableError as exc:
            raise PlanError(ERROR_UNREACHABLE, f'path unreachable: {exc}') from None
        with self._cache_lock:
            self._checked_paths[key] = True
            while len(self._checked_paths) > 256:
                self._checked_paths.popitem(last=False)

    def _entry(self, req: PlanRequest, path: PathBase, fm: FrictionMap) -> _Entry:
        accel_rows = req.tcp_accel_max > 0      # the |TCP acceleration| rows: own problem
        band_rows = req.tcp_speed_max > 0 or req.tcp_speed_min > 0   # quarter-point rows
        key = (req.path_key, req.grid_size, req.boundary, fm.to_dict().__repr__(),
               req.energy_model) + (('tcp_accel',) if accel_rows else ()) \
            + (('tcp_band',) if band_rows else ()) \
            + (('jerk',) if self.settings.jerk_limits else ())
        with self._cache_lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                return self._cache[key]
        s = self.settings
        theta = path_grid(req.grid_size, path, s.curvature_grid_share)
        sample = self.sample_path(path)
        sides = None
        try:
            if path.breaks.size:
                plain = sample
                sample = self._sample_side(path, plain, curved=True)
                idx = np.flatnonzero(np.isin(theta, path.breaks))
                sides = (idx, path_dynamics(theta[idx],
                                            self._sample_side(path, plain, curved=False),
                                            self._inverse_dynamics))
            nodes = path_dynamics(theta, sample, self._inverse_dynamics)
            mids = path_dynamics(0.5 * (theta[1:] + theta[:-1]), sample,
                                 self._inverse_dynamics)
        except UnreachableError as exc:
            raise PlanError(ERROR_UNREACHABLE, f'path unreachable: {exc}') from None
        friction = casadi_friction(fm, s.friction_smoothing_rad_s)
        mode = ENERGY_MODELS[req.energy_model or ENERGY_MECHANICAL]
        jerk = None
        if s.jerk_limits:
            try:
                jerk = jerk_path(path, self.sample_path(path), theta, nodes, sides)
            except UnreachableError as exc:
                raise PlanError(ERROR_UNREACHABLE, f'path unreachable: {exc}') from None
        tr = Transcription(nodes, mids, friction, req.boundary, s.abs_smoothing_j_rad,
                           s.max_iterations, s.tolerance, s.warm_start, sides,
                           electrical=self.electrical if mode else None,
                           bus_mode=mode or 'shared',
                           electrical_smoothing=s.electrical_smoothing_w,
                           tcp=tcp_path(path, theta), accel_rows=accel_rows,
                           band_rows=band_rows, jerk=jerk,
                           warm_max_iter=s.warm_max_iterations, warm_window=s.warm_window,
                           warm_from_time_optimal=s.warm_from_time_optimal,
                           resolve_mu_init=s.resolve_mu_init,
                           mumps_permuting_scaling=s.mumps_permuting_scaling)
        entry = _Entry(nodes, mids, tr)
        entry.friction = friction
        entry.friction_map = fm
        with self._cache_lock:
            self._cache[key] = entry
            while len(self._cache) > s.cache_size:
                self._cache.popitem(last=False)
        self._trim_cache()
        return entry

    @staticmethod
    def _sample_side(path: PathBase, sample, curved: bool):
        """``sample`` that takes Phi, Phi', Phi'' at a piece end (where a polyline's
        curvature jumps between a straight and a blend) from its more curved side
        (``curved``) or from the other one. The nodes use the curved side (the energy rows
        and the blend's torque up to its end); the transcription adds torque rows for the
        other side, so the limits hold on both."""
        eps = 1e-9

        def at(theta):
            theta = np.asarray(theta, float)
            near = np.isin(theta, path.breaks)
            if not np.any(near):
                return sample(theta)
            b = theta[near]
            k_lo = np.linalg.norm(path.dd_point(b - eps), axis=-1)
            k_hi = np.linalg.norm(path.dd_point(b + eps), axis=-1)
            lo_side = (k_lo > k_hi) if curved else ~(k_lo > k_hi)
            shifted = theta.copy()
            shifted[near] = np.where(lo_side, b - eps, b + eps)
            jp = sample(shifted)
            return JointPath(theta, jp.q, jp.dq, jp.ddq)
        return at

    def _trim_cache(self) -> None:
        """Drop least recently used problems (never the newest) while the process's resident
        memory is above memory_limit_mib, giving the freed heap back to the OS."""
        release_memory()
        while resident_mib() > self.settings.memory_limit_mib:
            with self._cache_lock:
                if len(self._cache) <= 1:
                    return
                self._cache.popitem(last=False)
            release_memory()

    def _limits(self, req: PlanRequest, fm: FrictionMap) -> tuple[SolveRequest, LimitSet]:
        """(limits for the NLP with margin, limits the evaluator checks)."""
        lim = self.model.limits
        vel = effective_speed_limit(lim.velocity, fm) * req.limit_scaling
        tau = lim.torque * req.limit_scaling
        keep = 1.0 - self.settings.constraint_margin
        sm = self.smooth_limits
        nlp = SolveRequest(0.0, 0.0, 1.0, self.settings.min_theta_dot_rad_s, vel * keep,
                           tau * keep, req.tcp_speed_max * keep,
                           req.tcp_speed_min * (2.0 - keep), req.tcp_accel_max * keep,
                           req.tcp_ramp_length,
                           jerk_limit=None if sm is None else sm.jerk * keep,
                           tcp_jerk_max=0.0 if sm is None else sm.tcp_jerk * keep)
        return nlp, LimitSet(vel, tau, lim.lower, lim.upper)

    @property
    def ramp_exponent(self) -> float:
        """The tcp_speed_min floor over a rest ramp rises as (d / ramp)^this: 2/3 (a
        constant-jerk start) with the jerk limits on, else 1/2 (constant acceleration)."""
        return RAMP_SPEED_EXPONENT if self.settings.jerk_limits else 0.5

    @property
    def smooth_limits(self) -> SmoothLimits | None:
        """The smoothness limits every plan keeps as played (None: jerk_limits off)."""
        s = self.settings
        if not s.jerk_limits:
            return None
        n = len(self.model.joint_names)
        return SmoothLimits(np.broadcast_to(np.asarray(s.joint_jerk_limit_rad_s3, float),
                                            (n,)).copy(), float(s.tcp_jerk_limit_m_s3),
                            np.broadcast_to(np.asarray(s.torque_rate_limit_nm_s, float),
                                            (n,)).copy())

    def _solve_checked(self, sreq: SolveRequest, checked: LimitSet, check, solve,
                       fixed_duration: float, band: TcpBand | None = None,
                       memory: dict | None = None):
        """Solve, rescale the profile to the exact ``fixed_duration`` (0 = keep its own) and
        ``check`` it (1 kHz evaluation and the independent check of its message); where a
        speed or torque limit is broken (the exact map against the NLP's smooth one, torque
        between grid points), tighten that limit by the measured excess and solve again, at
        most adapt_rounds times; likewise a process constraint of ``band`` (TCP speed band,
        acceleration) the played trajectory breaks. ``memory`` (a dict of the path's problem
        entry): the joint limits a re-solve had to tighten are remembered as ratios to the
        limits asked for, and the next request on the same problem starts from them (the
        excess between grid nodes is a property of the path and grid, nearly the same at a
        nearby duration: on the 10-segment polyline every energy plan was a solve, a failed
        check and a second solve). The check still decides; a plan that breaks a limit is
        tightened further. Returns (result, profile, (evaluation, trajectory, verification),
        notes); the result's stats sum the solve time and iterations of every solve; raises
        PlanError if the solver fails."""
        notes = []
        asked = sreq
        if memory and 'limits' in memory:
            tau_r, vel_r = memory['limits']
            sreq = replace(sreq, torque_limit=sreq.torque_limit * tau_r,
                           velocity_limit=sreq.velocity_limit * vel_r)
            notes.append('limits tightened as the last plan on this path needed: torque x '
                         + ' '.join(f'{v:.3f}' for v in tau_r) + ', speed x '
                         + ' '.join(f'{v:.3f}' for v in vel_r))
        spent, iters = 0.0, 0
        for attempt in range(self.settings.adapt_rounds + 1):
            res = solve(sreq)
            spent += res.stats.solve_time
            iters += res.stats.iterations
            res = replace(res, stats=replace(res.stats, solve_time=spent, iterations=iters))
            if not res.stats.success or res.profile is None:
                raise PlanError(ERROR_SOLVER, 'the optimiser found no solution '
                                f'({_status_text(res.stats.status)}, '
                                f'{res.stats.iterations} iterations)')
            profile = res.profile
            for _ in range(2 if fixed_duration > 0 else 0):     # 2nd pass: round-off
                profile = profile.scaled_in_time(fixed_duration / profile.duration)
            checks = check(profile)
            ev, _, ver = checks
            if (ev.ok and ver.ok) or attempt == self.settings.adapt_rounds:
                ratios = (sreq.torque_limit / asked.torque_limit,
                          sreq.velocity_limit / asked.velocity_limit)
                if memory is not None and ev.ok and ver.ok and min(map(np.min, ratios)) < 1:
                    memory['limits'] = ratios
                return res, profile, checks, notes
            over_tau = np.maximum(ev.peak_torque, ver.peak_torque) - checked.torque
            over_v = np.maximum(ev.peak_speed, ver.peak_speed) - checked.velocity
            tcp_fix = tighten_band(sreq, band, ver)
            tcp_fix.update(self._tighten_smooth(sreq, ver))
            if not (np.any(over_tau > 0) or np.any(over_v > 0) or tcp_fix):
                return res, profile, checks, notes          # not a limit: nothing to tighten
            tau = np.where(over_tau > 0, sreq.torque_limit - over_tau - 1e-3 * checked.torque,
                           sreq.torque_limit)
            vel = np.where(over_v > 0, sreq.velocity_limit - over_v - 1e-3 * checked.velocity,
                           sreq.velocity_limit)
            if np.any(tau < 0.25 * checked.torque) or np.any(vel < 0.25 * checked.velocity):
                raise PlanError(ERROR_SOLVER, 'between the grid nodes the motion exceeds a '
                                'limit by far more than at them (' + '; '.join(
                                    ev.violations + ver.problems)[:300] + '): the grid is too '
                                'coarse for this path, ask for a larger grid_size')
            notes.append('limits tightened after the exact check: '
                         + '; '.join(ev.violations + ver.problems))
            sreq = replace(sreq, torque_limit=tau, velocity_limit=vel, **tcp_fix)
        raise AssertionError('unreachable')

    def _tighten_smooth(self, sreq: SolveRequest, ver: Verification) -> dict:
        """``tighten_smooth`` with this planner's smoothness limits."""
        return tighten_smooth(self.smooth_limits, sreq, ver)

    def min_duration(self, entry: _Entry, base: SolveRequest, checked: LimitSet, check,
                     band: TcpBand | None = None, far: float = 0.0) -> tuple[float, tuple]:
        """Time-optimal duration [s] (exact time law of a profile that passes the checks)
        and ``_solve_checked``'s output for it; cached per limits and process constraints.

        ``far`` [s]: the fixed duration of a request that does not need the time-optimal
        plan itself. With settings.min_duration_check_factor f > 0 and far >= f x the
        optimiser's own time-optimal duration, that duration is returned unchecked, with
        None for the output: playing and checking the bang-bang profile (message
        subdivision, re-solves with tightened limits) cost 6.4 of 7.0 s per 10 s placement
        plan at N = 40, and it decides nothing there: the time-optimal duration only refuses
        requests shorter than it, and the plan returned is checked in full anyway. The
        checked value may be larger (a tightened limit slows the profile down); f leaves
        room for that."""
        key = (base.min_theta_dot, tuple(base.velocity_limit), tuple(base.torque_limit),
               None if base.jerk_limit is None else tuple(base.jerk_limit), base.tcp_jerk_max)
        if band is not None:
            key += base.process_key
        with entry.lock:
            if key in entry.min_duration:
                return entry.min_duration[key]
        req = replace(base, duration=0.0, time_weight=1.0,
                      energy_weight=TIME_OBJECTIVE_ENERGY_WEIGHT)
        factor = self.settings.min_duration_check_factor
        first = []              # a solve made for the unchecked answer, used once below
        if factor > 0 and far > 0:
            with entry.lock:
                t_opt = entry.min_duration_unchecked.get(key)
            if t_opt is None:
                res = entry.transcription.solve(req, warm=False)
                first.append(res)
                if res.stats.success and res.profile is not None:
                    t_opt = res.profile.duration
                    with entry.lock:
                        entry.min_duration_unchecked[key] = t_opt
            if t_opt is not None and far >= factor * t_opt:
                return t_opt, None

        def solve(r):
            return first.pop() if first else entry.transcription.solve(r, warm=False)
        try:
            out = self._solve_checked(req, checked, check, solve, 0.0, band)
        except PlanError as exc:
            infeasible = 'cannot all be met' in exc.message
            raise PlanError(ERROR_INFEASIBLE_DURATION if infeasible else ERROR_SOLVER,
                            f'time-optimal problem: {exc.message}') from None
        ev, _, ver = out[2]
        # the message's consistency matters where the time-optimal plan is the answer; for
        # another objective only its duration is used (a time-optimal profile on a fine grid
        # may switch its acceleration faster than 1 ms points can declare)
        problems = [p for p in ver.problems if far <= 0 or not p.startswith('inconsistent')]
        if ev.violations or problems:
            raise PlanError(ERROR_SOLVER, 'the time-optimal profile fails the checks after '
                            f'{self.settings.adapt_rounds} tightened re-solves: '
                            + '; '.join(ev.violations + problems))
        value = (out[1].duration, out)
        with entry.lock:
            entry.min_duration[key] = value
        return value

    def max_duration(self, entry: _Entry, delta: float) -> float:
        """The longest duration [s] the planner accepts: theta_dot = delta along the path,
        leaving and reaching rest as fast as the transcription's rest rows allow (a valid
        profile of the transcription; slower would mean standing still on the path)."""
        theta = entry.nodes.theta
        if entry.transcription.boundary == BOUNDARY_PERIODIC:
            return 2 * np.pi / delta
        h = np.diff(theta)
        if entry.transcription.cubic_rest:      # rest intervals 3 h / delta (profile.py)
            return float((theta[-2] - theta[1] + 3 * (h[0] + h[-1])) / delta)
        td = np.full(theta.size, delta)
        td[0] = td[-1] = 0.0
        a = np.zeros(theta.size)
        a[0], a[-1] = delta ** 2 / h[0], -delta ** 2 / h[-1]
        return ThetaProfile(theta, td, a).duration

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
        """Convex lower bound [J] at ``duration`` for the request's path/grid/limits, on the
        request's energy model (mechanical, or electrical with its DC-bus mode)."""
        req = validate(req, self.settings.grid_size, self.settings.max_grid_size)
        fm, _ = self.friction_map(req.friction_map)
        path = request_path(req)
        entry = self._entry(req, path, fm)
        base, _ = self._limits(req, fm)
        with entry.lock:
            if entry.bound is None:
                mode = ENERGY_MODELS[req.energy_model]
                try:
                    entry.bound = EnergyBound(entry.nodes, entry.mids, fm, req.boundary,
                                              2 * self.settings.max_iterations,
                                              electrical=self.electrical if mode else None,
                                              bus_mode=mode or 'shared')
                except ValueError as exc:       # a map with polynomial branches: no bound
                    raise PlanError(ERROR_FRICTION_MAP, 'no convex bound for a friction '
                                    f'map with polynomial branches ({exc})') from None
        res = entry.bound.solve(SolveRequest(duration, 0.0, 1.0, base.min_theta_dot,
                                             base.velocity_limit, base.torque_limit))
        if not res.stats.success:
            raise PlanError(ERROR_SOLVER, 'bound problem failed: '
                            f'{_status_text(res.stats.status)}')
        return res.energy

    # --- the request --------------------------------------------------------------------
    def plan(self, request: PlanRequest) -> PlanResult:
        """Plan ``request`` (see module docstring); raises PlanError."""
        try:
            return self._plan(request)
        finally:
            release_memory()       # the request's 1 kHz arrays: back to the OS, not the arena

    @staticmethod
    def refined_grid(req: PlanRequest, path: PathBase, max_grid: int) -> tuple[int, float]:
        """(a grid for a refusal that is not proven, the path's tightest bend radius [m],
        inf without a bend): intervals of at most a third of that radius, at least twice and
        at most four times the nodes, at most ``max_grid``."""
        theta = np.linspace(0.0, 2 * np.pi, 4001)
        kmax = float(np.max(curvature(path.d_point(theta), path.dd_point(theta))))
        need = int(np.ceil(3 * path.length * kmax)) + 1 if kmax > 0 else 0
        grid = min(max_grid, 4 * req.grid_size, max(2 * req.grid_size, need))
        return grid, (1.0 / kmax if kmax > 0 else float('inf'))

    def _plan(self, request: PlanRequest) -> PlanResult:
        s = self.settings
        req = validate(request, s.grid_size, s.max_grid_size)
        fm, raw_map = self.friction_map(req.friction_map)
        path = request_path(req)
        self.check_path(req, path)
        entry = self._entry(req, path, fm)
        base, checked = self._limits(req, fm)
        sample = self.sample_path(path)
        torque = self.torque(fm)

        def check(profile):
            ev = evaluate(profile, sample, torque, checked, s.evaluation_rate_hz,
                          self.electrical)
            return (ev, *self.trajectory(profile, req, path, fm, raw_map, checked))
        band = request_band(req, self.ramp_exponent)
        t_max = self.max_duration(entry, base.min_theta_dot)
        if band is not None:
            check_band_fits(req, path, entry, t_max, checked.velocity)
        try:
            t_min, t_out = self.min_duration(
                entry, base, checked, check, band,
                far=req.duration if req.objective != OBJECTIVE_TIME else 0.0)
        except PlanError as exc:
            raise self._certified(_band_error(exc, band, 'at all'),
                                  req, path, band, checked, 'at all') from None
        if req.duration > 0 and req.duration < t_min * (1 - 1e-9):
            raise PlanError(ERROR_INFEASIBLE_DURATION,
                            f'duration {req.duration:.4f} s is shorter than the time-optimal '
                            f'{t_min:.4f} s for this path and limits'
                            + (f' ({band_text(band)})' if band is not None else ''))
        if req.duration > t_max:
            raise PlanError(ERROR_INFEASIBLE_DURATION,
                            f'duration {req.duration:.6g} s is longer than the slowest motion '
                            f'along the path, {t_max:.2f} s: the path speed stays >= '
                            f'min_theta_dot = {base.min_theta_dot:g} rad/s inside the path '
                            '(a controller must not creep or stall on the path); plan a '
                            'shorter motion and wait at rest before or after it')
        coeffs = None
        t0 = time.perf_counter()
        if req.objective == OBJECTIVE_TIME:
            res, profile, checks, notes = t_out
            notes = list(notes)
            e_opt, stats = res.energy, res.stats
        elif req.objective == OBJECTIVE_TRAPEZOID:
            profile = trapezoid_profile(req.duration, s.trapezoid_ramp_fraction)
            e_opt, stats, notes = float('nan'), None, []
            checks = check(profile)
            if checks[0].violations:
                raise PlanError(ERROR_INFEASIBLE_DURATION, 'the trapezoid at this duration '
                                'breaks a limit: ' + '; '.join(checks[0].violations))
            broken = [p for p in checks[2].problems if p.startswith('tcp_')]
            if broken:
                raise PlanError(ERROR_INFEASIBLE_DURATION, 'the trapezoid at this duration '
                                'breaks the process constraints: ' + '; '.join(broken))
        else:
            sreq = replace(base, duration=req.duration, time_weight=req.time_weight,
                           energy_weight=1.0)
            solve = entry.transcription.solve
            memory = None
            if req.objective != OBJECTIVE_ENERGY:
                solve = self.fourier_problem(entry, req.fourier_order, sample).solve
            else:       # energy plans of one kind on this problem share their tightening
                with entry.lock:
                    memory = entry.tightened.setdefault(
                        (req.duration > 0, req.time_weight, sreq.process_key), {})
            try:
                res, profile, checks, notes = self._solve_checked(sreq, checked, check, solve,
                                                                  req.duration, band, memory)
            except PlanError as exc:
                raise self._certified(_band_error(exc, band), req, path, band,
                                      checked) from None
            coeffs = getattr(res, 'coeffs', None)
            e_opt, stats = res.energy, res.stats
        evaluation, trajectory, verification = checks
        elapsed = time.perf_counter() - t0
        if evaluation.violations or not verification.ok:
            raise PlanError(ERROR_SOLVER, f'the {req.objective} plan fails the independent '
                            f'check and is not returned (after {s.adapt_rounds} re-solves '
                            'with tightened limits): '
                            + '; '.join(evaluation.violations + verification.problems))
        baseline = evaluation if req.objective == OBJECTIVE_TRAPEZOID else evaluate(
            trapezoid_profile(evaluation.duration, s.trapezoid_ramp_fraction), sample,
            torque, checked, s.evaluation_rate_hz, self.electrical)
        if baseline.violations:
            notes.append('trapezoid baseline violates limits: ' + baseline.violations[0])
        if t_out is None:
            notes.append('min_duration is the optimiser\'s time-optimal duration, its profile '
                         'not played and checked (the request is >= '
                         f'{s.min_duration_check_factor:g} x longer)')
        # against the model's full torque limits, as the gate judges (``checked`` carries
        # the request's limit_scaling)
        notes += ['pdplus gate: ' + n for n in gate_limit_notes(
            trajectory['qdd'], trajectory['tau'], self.model.limits.torque)]
        if req.boundary == BOUNDARY_PERIODIC and req.objective != OBJECTIVE_TRAPEZOID:
            notes.append('periodic profile: starts and ends at theta_dot = '
                         f'{profile.theta_dot[0]:.3f} rad/s')
        cost = None
        if (s.limit_cost and self.smooth_limits is not None
                and req.objective in (OBJECTIVE_ENERGY, OBJECTIVE_TIME)):
            cost = self._limit_cost(entry, req, base, res, profile)
            notes.insert(0, cost.text())
        return PlanResult(
            objective=req.objective, profile=profile, evaluation=evaluation,
            optimizer_energy=e_opt, min_duration=t_min,
            solve_time=stats.solve_time if stats else elapsed,
            iterations=stats.iterations if stats else 0,
            status=stats.status if stats else 'closed form', baseline=baseline,
            joint_names=list(self.model.joint_names), request=req, fourier_coeffs=coeffs,
            notes=notes, trajectory=trajectory, verification=verification,
            optimizer_electrical_energy=float(getattr(res, 'electrical_energy', float('nan'))
                                              if req.objective != OBJECTIVE_TRAPEZOID
                                              else float('nan')),
            limit_cost=cost)

    def _limit_cost(self, entry: _Entry, req: PlanRequest, base: SolveRequest, res,
                    profile: ThetaProfile) -> LimitCost:
        """The plan's LimitCost: its last solve (the accepted one, with the limits it was
        tightened to) once more without the jerk rows, warm-started from it."""
        tr = entry.transcription
        last = tr.last_request
        electrical = bool(ENERGY_MODELS[req.energy_model or ENERGY_MECHANICAL])
        if req.objective == OBJECTIVE_TIME:
            sreq = last if (last is not None and last.duration == 0.0
                            and last.energy_weight == TIME_OBJECTIVE_ENERGY_WEIGHT
                            and last.process_key == base.process_key) else replace(
                base, duration=0.0, time_weight=1.0,
                energy_weight=TIME_OBJECTIVE_ENERGY_WEIGHT)
            quantity, have = 'duration', float(profile.duration)
        else:
            sreq = last if (last is not None and last.duration == req.duration
                            and last.time_weight == req.time_weight) else replace(
                base, duration=req.duration, time_weight=req.time_weight, energy_weight=1.0)
            quantity = 'energy'
            have = float(res.electrical_energy if electrical else res.energy)
        key = (sreq.min_theta_dot, tuple(sreq.velocity_limit), tuple(sreq.torque_limit),
               sreq.process_key)
        with entry.lock:        # a time-optimal one: once per problem and limits
            known = entry.free_duration.get(key) if quantity == 'duration' else None
        rest = req.boundary == BOUNDARY_REST
        if known is not None:
            return LimitCost(quantity, have, *known, rest=rest)
        free = tr.solve_without_jerk(sreq)
        st = free.stats
        if not st.success or free.profile is None:
            value = float('nan')
        elif quantity == 'duration':
            value = float(free.profile.duration)
        else:
            value = float(free.electrical_energy if electrical else free.energy)
        out = (value, st.solve_time, st.iterations, st.status)
        if quantity == 'duration' and np.isfinite(value):
            with entry.lock:
                entry.free_duration[key] = out
        return LimitCost(quantity, have, *out, rest=rest)

    def trajectory(self, profile: ThetaProfile, req: PlanRequest, path: PathBase,
                   fm: FrictionMap, raw_map: dict, checked: LimitSet
                   ) -> tuple[dict, Verification]:
        """The message's points and their independent check: the profile's nodes, each
        interval split into m equal theta pieces (m = 1, 2, 4, ...) until the trajectory
        played by quintic interpolation stays within path_tolerance_m / 2 of the path and
        inside the torque and speed limits, or the point budget is used (the check then says
        whether it is within path_tolerance_m).
        Limits the check finds broken are for ``_solve_checked`` to fix."""
        s = self.settings
        sample, torque = self.sample_path(path), self.torque(fm)
        kin = ArmKinematics(velocity=checked.velocity, torque=checked.torque, **self._kin)
        if type(path) is CirclePath:
            circle = Circle(np.asarray(req.center, float), float(req.radius),
                            float(req.start_angle), int(req.direction))
        else:
            circle = PathCurve(path.point, path.d_point, path.dd_point, path.closed)
        friction = MapFriction(raw_map, self.model.joint_names)
        nodes = profile.theta
        prof = (nodes, profile.theta_dot, profile.theta_ddot_nodes, profile.quadratic)
        m = 1
        while True:
            frac = np.arange(m) / m
            theta = np.append((nodes[:-1, None] + np.diff(nodes)[:, None] * frac).ravel(),
                              nodes[-1])
            t, theta, td, tdd, jp = message_points(profile, theta, path.breaks,
                                                   s.min_point_spacing_s, sample)
            qd = jp.dq * td[:, None]
            qdd = jp.ddq * td[:, None] ** 2 + jp.dq * tdd[:, None]
            ver = verify_plan(t, jp.q, qd, qdd, prof, circle, kin, self.rigid_torque, friction,
                              req.boundary == BOUNDARY_REST, s.play_rate_hz,
                              path_tolerance_m=s.path_tolerance_m,
                              electrical=self.electrical,
                              band=request_band(req, self.ramp_exponent),
                              stamp_resolution_s=STAMP_RESOLUTION_S,
                              min_samples_per_segment=np.where(
                                  np.diff(t) < SHORT_INTERVAL_S, PEAK_SAMPLES_PER_INTERVAL,
                                  8),
                              # the trapezoid and Fourier baselines (b linear between nodes:
                              # theta_ddot steps at every node) are played unlimited
                              smooth=self.smooth_limits if profile.quadratic else None,
                              smooth_exempt=self._blend_windows(profile, path))
            # also denser while the played (quintic) trajectory breaks a torque or speed
            # limit: between sparse points at speed through a tight blend its acceleration,
            # hence torque, leaves the profile's (the NLP cannot fix that by tightening)
            played_limit = any(' torque ' in p or ' speed ' in p for p in ver.problems)
            bad = worst_inconsistency(t, jp.q, qd, qdd, 0.5 * CONSISTENCY_RTOL,
                                      0.5 * CONSISTENCY_ATOL)
            if ((ver.max_path_deviation <= 0.5 * s.path_tolerance_m and not played_limit
                 and bad is None)
                    or 2 * m * (nodes.size - 1) + 1 > s.max_trajectory_points):
                break
            m *= 2
        if bad is not None:         # what a consumer's plan gate would refuse: not a success
            ver.problems.append(f'inconsistent {bad.what}: joint {bad.joint + 1} at point '
                                f'{bad.point} (t = {t[bad.point]:.4f} s): {bad.detail()} '
                                '(half the tolerances of irb_description.trajectory_rules)')
        tau = torque(jp.q, qd, qdd)
        return {'t': t, 'theta': theta, 'q': jp.q, 'qd': qd, 'qdd': qdd, 'tau': tau}, ver

    def _blend_windows(self, profile: ThetaProfile, path: PathBase) -> np.ndarray | None:
        """(B, 2) [s]: the message intervals between the twin points around each interior
        piece end (where a circular blend's curvature jumps), which the smoothness check
        reports apart (None: no piece ends)."""
        return blend_windows(profile, path.breaks, self.settings.min_point_spacing_s)

    def _certified(self, exc: PlanError, req: PlanRequest, path: PathBase,
                   band: TcpBand | None, checked: LimitSet, what: str = 'of this duration'
                   ) -> PlanError:
        """A refusal for process constraints the solver found infeasible, with the TCP jerk
        certificate when there is one (certificate.py). Without one the refusal says that it
        is not proven (the strongest bound and the limit, the grid against the tightest
        bend), so that a false refusal shows itself (issue 28); ``exc`` unchanged for other
        refusals."""
        if (band is None or exc.code != ERROR_INFEASIBLE_DURATION
                or not exc.message.startswith('no motion')):
            return exc
        cert = self.jerk_certificate(req, path, checked.velocity, strict=False)
        if cert is not None and cert.proves:
            return PlanError(ERROR_INFEASIBLE_DURATION, f'no motion {what} keeps the '
                             f'{band_text(band)} together with the TCP jerk limit: '
                             f'{cert.text()}')
        if self.smooth_limits is None or not req.tcp_speed_min > 0:
            return exc
        why = (cert.shortfall() if cert is not None else 'no certificate: the path has '
               'curvature jumps or no bend, certificate.py has no bound for it')
        grid, radius = self.refined_grid(req, path, self.settings.max_grid_size)
        bend = (f'a tightest bend of radius {radius * 1e3:.1f} mm' if radius < np.inf
                else 'no bend')
        more = (f': a finer grid_size (e.g. {grid}) may plan it' if grid > req.grid_size
                else '')
        return PlanError(ERROR_INFEASIBLE_DURATION, f'{exc.message}; not proven: {why}; the '
                         f'grid\'s intervals are {path.length / (req.grid_size - 1) * 1e3:.1f} '
                         f'mm against {bend}{more}')

    def jerk_certificate(self, req: PlanRequest, path: PathBase, velocity_limit: np.ndarray,
                         samples: int = 4000, strict: bool = True) -> JerkCertificate | None:
        """A lower bound above the TCP jerk limit on the TCP jerk of every motion along
        ``path`` that keeps ``req``'s TCP speed floor (its ceiling and the joint speed limits
        ``velocity_limit`` bound the speed from above): certificate.py. None if none is
        found, the limits are off, or the path has interior piece ends (curvature jumps);
        ``strict`` False: the strongest bound whatever its value."""
        sm = self.smooth_limits
        inner = np.asarray(path.breaks, float)
        if (sm is None or not req.tcp_speed_min > 0 or not sm.tcp_jerk > 0
                or np.any((inner > 0) & (inner < 2 * np.pi))):
            return None
        periodic = req.boundary == BOUNDARY_PERIODIC
        theta = np.linspace(0.0, 2 * np.pi, samples + 1)
        theta = theta[:-1] if periodic else theta
        jp = self.sample_path(path)(theta)
        d1v, d2v = path.d_point(theta), path.dd_point(theta)
        d1 = np.linalg.norm(d1v, axis=1)
        sigma = np.concatenate([[0.0], np.cumsum(0.5 * (d1[1:] + d1[:-1]) * np.diff(theta))])
        L = float(sigma[-1])
        if periodic:        # the closing piece
            L += 0.5 * (d1[-1] + d1[0]) * (2 * np.pi - theta[-1])
        with np.errstate(divide='ignore'):
            v_cap = d1 * np.min(np.asarray(velocity_limit, float)[None, :]
                                / np.abs(jp.dq), axis=1)
        if req.tcp_speed_max > 0:
            v_cap = np.minimum(v_cap, req.tcp_speed_max)
        zone = None if periodic else (req.tcp_ramp_length, L - req.tcp_ramp_length)
        return jerk_certificate(sigma, L, curvature(d1v, d2v), v_cap, req.tcp_speed_min,
                                sm.tcp_jerk, periodic, zone, strict)

    def evaluate(self, result: PlanResult, rate_hz: float) -> Evaluation:
        """``result``'s profile resampled by the evaluator at ``rate_hz`` [Hz], with the
        dynamics and limits ``plan`` checked it with (e.g. its energy at a finer rate)."""
        req = result.request
        fm, _ = self.friction_map(req.friction_map)
        return evaluate(result.profile, self.sample_path(request_path(req)), self.torque(fm),
                        self._limits(req, fm)[1], rate_hz, self.electrical)

    def node_samples(self, result: PlanResult) -> dict:
        """The plan's trajectory message points (checked): t (K,) [s]; q, qd, qdd, tau (K, n)."""
        return result.trajectory


def tcp_path(path: PathBase, theta: np.ndarray) -> TcpPath:
    """p' and p'' of ``path`` at the grid ``theta`` and its midpoints; at piece ends (where
    p'' jumps) the nodes take the more curved side (as the nodes' dynamics do) and the
    sides the other one."""
    d1n, d2n = path.d_point(theta), path.dd_point(theta).copy()
    mids = 0.5 * (theta[1:] + theta[:-1])
    d1s, d2s = np.zeros((0, 3)), np.zeros((0, 3))
    near = np.isin(theta, path.breaks) if path.breaks.size else np.zeros(theta.size, bool)
    if np.any(near):
        b = theta[near]
        lo, hi = path.dd_point(b - 1e-9), path.dd_point(b + 1e-9)
        lo_curved = (np.linalg.norm(lo, axis=1) > np.linalg.norm(hi, axis=1))[:, None]
        d2n[near] = np.where(lo_curved, lo, hi)
        d1s, d2s = d1n[near], np.where(lo_curved, hi, lo)
    return TcpPath(d1n, d2n, path.d_point(mids), path.dd_point(mids), d1s, d2s,
                   theta * path.length / (2 * np.pi))


def request_band(req: PlanRequest, ramp_exponent: float = 0.5) -> TcpBand | None:
    """The request's process constraints as the independent check takes them (None: none)."""
    if not req.has_process:
        return None
    return TcpBand(req.tcp_speed_max, req.tcp_speed_min, req.tcp_accel_max,
                   req.tcp_ramp_length, ramp_exponent)


def band_text(band: TcpBand) -> str:
    """The process constraints in words."""
    parts = []
    if band.speed_min > 0 or band.speed_max > 0:
        parts.append('TCP speed ' + (f'>= {band.speed_min:g} m/s beyond '
                                     f'{band.ramp_length * 1e3:.0f} mm from the rest ends'
                                     if band.speed_min > 0 else '')
                     + (' and ' if band.speed_min > 0 and band.speed_max > 0 else '')
                     + (f'<= {band.speed_max:g} m/s' if band.speed_max > 0 else ''))
    if band.accel_max > 0:
        parts.append(f'|TCP acceleration| <= {band.accel_max:g} m/s^2')
    return 'process constraints: ' + ', '.join(parts)


def _band_error(exc: PlanError, band: TcpBand | None, what: str = 'of this duration'
                ) -> PlanError:
    """A solver failure under process constraints: infeasible (code 3) when IPOPT found the
    rows cannot all be met, with the constraints named; otherwise ``exc`` unchanged."""
    if band is None or 'cannot all be met' not in exc.message:
        return exc
    # the smoothness limits are on iff the ramp floor is the constant-jerk one (2/3)
    smooth = band.ramp_exponent != 0.5
    ramp = ('v_min^2 / (2 r)' if not smooth else f'{band.ramp_exponent:.3g} v_min^2 / r')
    return PlanError(ERROR_INFEASIBLE_DURATION, f'no motion {what} keeps the '
                     f'{band_text(band)} together with the robot limits ({exc.message}; no '
                     f'single bound is broken on its own: the ramp acceleration {ramp}, '
                     'the bends\' centripetal acceleration and the joint speeds at '
                     'the floor all fit, so it is their combination with the torque limits'
                     + (', the jerk and torque-rate limits (jerk_limits)' if smooth else '')
                     + ' and the duration)')


def check_band_fits(req: PlanRequest, path: PathBase, entry: _Entry, t_max: float,
                    velocity_limit: np.ndarray | None = None) -> None:
    """Refuse (code 3, one line) process constraints this path and duration cannot meet
    before any solve, each with its certificate (the bound that is broken and by how much):
    a duration below length / tcp_speed_max, or above what the speed floor allows; rest
    ramps too short to reach tcp_speed_min at tcp_accel_max (v_min^2 / (2 r) > a_max); a
    floor at which the centripetal acceleration in a bend away from the rest ends exceeds
    tcp_accel_max; a floor that needs a joint faster than its speed limit
    (``velocity_limit`` (n,) [rad/s], the limits checked); rest ramps shorter than the grid's
    first interval."""
    L = path.length
    T = req.duration
    rest = req.boundary == BOUNDARY_REST
    r = req.tcp_ramp_length if rest else 0.0
    vmax, vmin, amax = req.tcp_speed_max, req.tcp_speed_min, req.tcp_accel_max

    def no(msg):
        raise PlanError(ERROR_INFEASIBLE_DURATION, msg)
    if vmax > 0 and T > 0 and T < L / vmax:
        no(f'duration {T:.4g} s is too short for tcp_speed_max {vmax:g} m/s: the '
           f'{L * 1e3:.0f} mm path takes at least {L / vmax:.3f} s at that speed')
    if vmin > 0 and T > 0:         # the ramps' floor rises as a constant acceleration's
        longest = (L + 2 * r) / vmin       # speed: each takes at most 2 r / v_min
        if T > longest:
            no(f'duration {T:.4g} s is too long for tcp_speed_min {vmin:g} m/s: the path '
               f'({L * 1e3:.0f} mm, {r * 1e3:.0f} mm rest ramps) takes at most '
               f'{longest:.2f} s at that speed; plan a shorter motion and wait at rest')
    if vmin <= 0:
        return
    tcp = entry.transcription.tcp
    sig = tcp.sigma
    if rest and r <= sig[1] * (1 + 1e-12):
        no(f'tcp_ramp_length {r * 1e3:.2f} mm is within the first grid interval '
           f'({sig[1] * 1e3:.2f} mm at {sig.size} nodes): no room to reach tcp_speed_min')
    zone = (sig >= r) & (sig <= L - r) if rest else np.ones(sig.size, bool)
    s1 = np.sum(tcp.d1_nodes ** 2, axis=1)
    if amax > 0:
        kappa = np.linalg.norm(tcp.d2_nodes, axis=1) / s1          # curvature [1/m]
        k = int(np.argmax(np.where(zone, kappa, 0.0)))
        if zone[k] and vmin ** 2 * kappa[k] > amax:
            no(f'at tcp_speed_min {vmin:g} m/s the centripetal acceleration in the bend of '
               f'radius {1e3 / kappa[k]:.1f} mm ({sig[k] * 1e3:.0f} mm along the path) is '
               f'{vmin ** 2 * kappa[k]:.3g} m/s^2 > tcp_accel_max {amax:g} m/s^2 (by '
               f'{100 * (vmin ** 2 * kappa[k] / amax - 1):.1f} %)')
    e = entry.transcription._ramp_power / 2       # the ramp floor v_min (d / r)^e
    if rest and amax > 0 and e * vmin ** 2 / r > amax:
        need = e * vmin ** 2 / r       # a = d(v^2 / 2)/d sigma of the floor, at its top
        no(f'reaching tcp_speed_min {vmin:g} m/s within the {r * 1e3:.1f} mm rest ramps '
           f'needs a TCP acceleration of at least {e:.3g} v^2 / r = {need:.4g} m/s^2 > '
           f'tcp_accel_max {amax:g} m/s^2 (by {100 * (need / amax - 1):.1f} %); ramps of '
           f'at least {e * vmin ** 2 / amax * 1e3:.1f} mm fit')
    if velocity_limit is not None:        # joint speeds the floor needs: v |dq/dsigma|
        frac = (np.clip(np.minimum(sig, L - sig) / r, 0.0, 1.0) if rest
                else np.ones(sig.size))
        need = (vmin * frac ** e / np.sqrt(s1))[:, None] * np.abs(entry.nodes.dq)
        ratio = need / np.asarray(velocity_limit, float)[None, :]
        k, i = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
        if ratio[k, i] > 1.0:
            no(f'at tcp_speed_min {vmin:g} m/s joint {i + 1} must turn at '
               f'{need[k, i]:.3f} rad/s {sig[k] * 1e3:.0f} mm along the path, above its '
               f'speed limit {velocity_limit[i]:.3f} rad/s (by '
               f'{100 * (ratio[k, i] - 1):.1f} %)')


def tighten_band(sreq: SolveRequest, band: TcpBand | None, ver: Verification) -> dict:
    """SolveRequest fields of the process constraints the played trajectory broke, tightened
    by the measured excess + 0.1 % (as the joint limits in ``_solve_checked``); {} if none."""
    if band is None:
        return {}
    fix = {}
    if band.speed_max > 0 and ver.tcp_speed_peak > band.speed_max * (1 + LIMIT_RTOL):
        fix['tcp_speed_max'] = (sreq.tcp_speed_max - (ver.tcp_speed_peak - band.speed_max)
                                - 1e-3 * band.speed_max)
    if band.speed_min > 0 and ver.tcp_floor_ratio < 1 - LIMIT_RTOL:
        if not ver.tcp_floor_ratio > 0.25:       # 0 (a stop in the band) or far below
            raise PlanError(ERROR_SOLVER, 'the played motion falls far below the speed floor '
                            f'(lowest speed / floor {ver.tcp_floor_ratio:.3g}: ' + '; '.join(
                                p for p in ver.problems if p.startswith('tcp_'))[:300]
                            + '): ask for a larger grid_size or a lower tcp_speed_min')
        fix['tcp_speed_min'] = (sreq.tcp_speed_min / ver.tcp_floor_ratio
                                + 1e-3 * band.speed_min)
    if band.accel_max > 0 and ver.tcp_accel_peak > band.accel_max * (1 + LIMIT_RTOL):
        fix['tcp_accel_max'] = (sreq.tcp_accel_max - (ver.tcp_accel_peak - band.accel_max)
                                - 1e-3 * band.accel_max)
    vmax = fix.get('tcp_speed_max', sreq.tcp_speed_max)
    vmin = fix.get('tcp_speed_min', sreq.tcp_speed_min)
    if (fix.get('tcp_accel_max', 1.0) <= 0 or fix.get('tcp_speed_max', 1.0) <= 0
            or (vmax > 0 and vmin >= vmax)):
        raise PlanError(ERROR_SOLVER, 'between the grid nodes the motion breaks the process '
                        'constraints by more than their band (' + '; '.join(
                            p for p in ver.problems if p.startswith('tcp_'))[:300]
                        + '): ask for a larger grid_size')
    return fix


def tighten_smooth(sm: SmoothLimits | None, sreq: SolveRequest, ver) -> dict:
    """SolveRequest fields of the smoothness limits ``sm`` the played trajectory broke (``ver``
    has peak_jerk, peak_torque_rate (n,) and tcp_jerk_peak: the three- and the six-axis
    checks): a joint's jerk limit scaled by limit / played peak of its jerk or torque rate
    (- 0.1 %), the TCP jerk likewise; {} if none."""
    if sm is None or ver.peak_jerk is None or sreq.jerk_limit is None:
        return {}
    fix = {}
    ratio = np.maximum(ver.peak_jerk / sm.jerk, ver.peak_torque_rate / sm.torque_rate)
    if np.any(ratio > 1 + LIMIT_RTOL):
        fix['jerk_limit'] = np.where(ratio > 1 + LIMIT_RTOL,
                                     sreq.jerk_limit / ratio * 0.999, sreq.jerk_limit)
    if sm.tcp_jerk > 0 and ver.tcp_jerk_peak > sm.tcp_jerk * (1 + LIMIT_RTOL):
        fix['tcp_jerk_max'] = sreq.tcp_jerk_max * sm.tcp_jerk / ver.tcp_jerk_peak * 0.999
    return fix


def blend_windows(profile: ThetaProfile, breaks, min_spacing: float) -> np.ndarray | None:
    """(B, 2) [s]: the message intervals between the twin points ``message_points`` puts
    around each interior piece end (where a blend's curvature jumps), which the smoothness
    checks report apart (None: no interior piece ends)."""
    inner = np.asarray(breaks, float)
    inner = inner[(inner > 0) & (inner < 2 * np.pi)]
    if inner.size == 0:
        return None
    t_b = profile.theta_at(inner)[0]
    half = 0.5 * min_spacing * (1 + 1e-3) + 2e-9
    return np.column_stack([t_b - half, t_b + half])


def message_points(profile: ThetaProfile, theta: np.ndarray, breaks: np.ndarray,
                   min_spacing: float, sample) -> tuple:
    """The trajectory message's points from candidate path parameters ``theta`` (increasing,
    0 .. 2 pi): (t [s] as the message stamps them, theta, theta_dot, theta_ddot, the
    JointPath ``sample(theta)`` at them).

    * every interior candidate on a piece end (where Phi'' jumps: a blend's end) is replaced
      by two points half ``min_spacing`` (+0.1 %) of time before and after it: each interval
      but the one between them lies in one piece, so the accelerations declared at its ends
      are its own, and the jump is played as the quintic between the twins spreads it;
    * no two points closer than ``min_spacing`` [s] (``trajectory_rules.spaced``, points
      where a joint acceleration peaks or dips kept first, then nodes): a controller's
      quintic between points microseconds apart turns the stamps' nanosecond resolution
      into acceleration (issue 28);
    * times rounded to 1 ns, as ``time_from_start`` carries them: the independent check
      plays exactly what a controller receives (the points keep their exact theta; the
      <= 0.5 ns this moves a stamp is in the check)."""
    breaks = np.asarray(breaks, float)
    on = np.isin(theta, breaks)
    on[[0, -1]] = False
    if np.any(on):
        t_b = profile.theta_at(theta[on])[0]
        half = 0.5 * min_spacing * (1 + 1e-3)
        twins = np.concatenate([profile.sample(t_b - half)[0], profile.sample(t_b + half)[0]])
        theta = np.unique(np.concatenate([theta[~on], twins]))
    t, td, tdd = profile.theta_at(theta)
    jp = sample(theta)
    qdd = jp.ddq * td[:, None] ** 2 + jp.dq * tdd[:, None]
    # keep first where a joint's acceleration peaks or dips (an interval across such a point
    # breaks the mean-value rule of the consistency check: a time-optimal profile's switches,
    # nodes closer than min_spacing on a fine grid), then the profile's nodes, then the rest
    ext = np.zeros(theta.size, bool)
    d = np.diff(qdd, axis=0)
    ext[1:-1] = np.any(d[:-1] * d[1:] <= 0, axis=1)
    node = np.isin(theta, profile.theta)
    keep = spaced(t, min_spacing, node.astype(float) + 2.0 * ext)
    theta = theta[keep]
    jp = JointPath(theta, jp.q[keep], jp.dq[keep], jp.ddq[keep])
    return stamps_ns(t[keep]), theta, td[keep], tdd[keep], jp


def jerk_path(path: PathBase, sample, theta: np.ndarray, nodes, sides) -> JerkPath:
    """The path's derivatives for the transcription's jerk rows at 3 points of every interval
    (just after its start, its midpoint, just before its end: on its own side of a piece
    end): Phi, Phi', Phi'' from ``sample`` and p', p'' from the path; the third derivatives
    by second-order differences of the second with a step of THIRD_STEP x the interval,
    one-sided into the interval at its ends, central at the midpoint. (Issue 28: 5-point
    stencils over the whole interval differentiated across a spline's knots, where p^(3)
    and Phi^(3) jump: on a closed spline of bench_floor_certificate.py the normal TCP jerk
    component of a row was 2.9 x the true one next to a knot, and the planner refused
    motions that exist.) ``nodes``, ``sides``: the transcription's dynamics (unused)."""
    h = np.diff(theta)
    K = h.size
    eps = THIRD_STEP * h
    start, mid, end = theta[:-1] + 1e-7 * h, theta[:-1] + 0.5 * h, theta[1:] - 1e-7 * h
    # per point: the point and its two neighbours of the difference formula
    th = np.concatenate([start, start + eps, start + 2 * eps, mid - eps, mid, mid + eps,
                         end - 2 * eps, end - eps, end])
    jp = sample(th)
    n = jp.q.shape[1]
    dq, ddq = jp.dq.reshape(9, K, n), jp.ddq.reshape(9, K, n)
    d1, d2 = path.d_point(th).reshape(9, K, 3), path.dd_point(th).reshape(9, K, 3)

    def third(f):
        e = (2 * eps)[:, None]
        return np.stack([(-3 * f[0] + 4 * f[1] - f[2]) / e, (f[5] - f[3]) / e,
                         (f[6] - 4 * f[7] + 3 * f[8]) / e])

    pick = lambda f: np.stack([f[0], f[4], f[8]])  # noqa: E731
    return JerkPath(pick(dq), pick(ddq), third(ddq), pick(d1), pick(d2), third(d2))


def theta_grid(n: int, breaks: np.ndarray, min_intervals: int = 8,
               density: Callable | None = None) -> np.ndarray:
    """n nodes over [0, 2 pi]: uniform (np.linspace, the thesis circle's grid) for a path
    without pieces; with pieces (``breaks``, where the curvature jumps: a polyline's blends)
    a node at every piece end and at least ``min_intervals`` uniform intervals per piece
    (fewer if n is too small for that), the rest shared in proportion to length, so that
    the NLP sees every blend and never averages a corner's torque over a straight.
    ``density`` rho(theta) >= 1 (vectorised): the nodes equidistribute its integral instead
    of theta (pieces get nodes in proportion to it, and inside a piece equal parts of it)."""
    breaks = np.asarray(breaks, float)
    if breaks.size == 0 and density is None:
        return np.linspace(0.0, 2 * np.pi, n)
    edges = np.concatenate([[0.0], breaks, [2 * np.pi]])
    if density is not None:
        fine = np.linspace(0.0, 2 * np.pi, GRID_DENSITY_SAMPLES)
        rho = np.asarray(density(fine), float)
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (rho[1:] + rho[:-1]))])
        cum *= 2 * np.pi / cum[-1]
        edges_w = np.interp(edges, fine, cum)
        span = np.diff(edges_w)

        def piece(i, c):
            g = np.interp(np.linspace(edges_w[i], edges_w[i + 1], c + 1), cum, fine)
            g[0], g[-1] = edges[i], edges[i + 1]
            return g
    else:
        span = np.diff(edges)

        def piece(i, c):
            return np.linspace(edges[i], edges[i + 1], c + 1)
    if breaks.size == 0:
        return piece(0, n - 1)
    m = n - 1
    floor = min(min_intervals, max(m // span.size, 1))
    if floor * span.size > m:
        return np.linspace(0.0, 2 * np.pi, n)     # more pieces than nodes: uniform
    k = np.maximum(np.floor(m * span / (2 * np.pi)).astype(int), floor)
    while k.sum() > m:                            # give back from the coarsest pieces
        i = int(np.argmax(np.where(k > floor, span / k, -1.0)))
        k[i] -= 1
    while k.sum() < m:                            # add to the coarsest piece
        k[int(np.argmax(span / k))] += 1
    theta = np.concatenate([piece(i, c)[:-1] for i, c in enumerate(k)] + [[2 * np.pi]])
    return theta


#: samples of the grid density over [0, 2 pi] (theta_grid)
GRID_DENSITY_SAMPLES = 20001


def path_grid(n: int, path: PathBase, curvature_share: float) -> np.ndarray:
    """The planner's theta grid on ``path``: theta_grid(n, path.breaks), except on a spline
    (a path with ``knots``, no pieces) with ``curvature_share`` > 0: a node at every knot
    (p''' jumps there: the jerk rows then hold on each side) and the nodes spaced by the
    density 1 + c kappa / mean kappa, c = share / (1 - share), which puts about
    ``curvature_share`` of them where the curvature is. Issue 28: a closed spline with a
    bend of 9 mm radius on 646 mm (case 7 of bench_floor_certificate.py --seed 1) was
    refused at uniform grids 200, 216 and 400 while a motion within every limit exists;
    with theta_ddot linear per interval the rows at an interval's ends cannot follow
    kappa^2 v^3 through the bend: the witness's profile put on the grid broke the TCP jerk
    rows (91.9 m/s^3) with 154, 127, 107 and 89 at uniform grids 200, 400, 800 and 1600,
    <= 90 at 400 nodes spaced by this density (share 0.3), and the planner plans it at
    200 (benchmarks/RESULTS.md)."""
    if path.breaks.size or not hasattr(path, 'knots') or not curvature_share > 0:
        return theta_grid(n, path.breaks)
    share = min(float(curvature_share), 0.9)

    def density(theta):
        k = curvature(path.d_point(theta), path.dd_point(theta))
        mean = float(np.mean(k))
        return 1.0 + (share / (1.0 - share) * k / mean if mean > 0 else 0.0 * k)
    return theta_grid(n, np.asarray(path.knots, float), density=density)


def resident_mib() -> float:
    """Resident memory of this process [MiB] (Linux /proc; 0 where unknown)."""
    try:
        with open('/proc/self/status') as f:
            for line in f:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def release_memory() -> None:
    """Give freed heap back to the OS after dropping built problems (glibc keeps CasADi's
    freed blocks in its arenas otherwise; measured in benchmarks/bench_memory.py)."""
    try:
        ctypes.CDLL('libc.so.6').malloc_trim(0)
    except (OSError, AttributeError):
        pass


def _status_text(status: str) -> str:
    """IPOPT's return status in words."""
    return {
        'Maximum_Iterations_Exceeded': 'iteration limit reached',
        'Infeasible_Problem_Detected': 'the limits cannot all be met',
        'Restoration_Failed': 'no feasible point found',
        'Solved_To_Acceptable_Level': 'solved to the acceptable level only',
        'Error_In_Step_Computation': 'numerical trouble',
        'Invalid_Number_Detected': 'a non-finite number in the problem',
        'Maximum_CpuTime_Exceeded': 'time limit reached',
    }.get(status, status.replace('_', ' ').lower())


def request_path(req: PlanRequest) -> PathBase:
    """The geometric path of a (validated) request: the one place a request becomes a path."""
    try:
        if req.path_type == 'circle':
            return CirclePath(req.center, req.radius, req.start_angle, req.direction)
        return path_from_spec(req.path_spec())
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
