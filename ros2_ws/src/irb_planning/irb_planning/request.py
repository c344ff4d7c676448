"""Plan requests as plain data, their validation, and the error codes (no ROS imports).

The codes equal the ERROR_* constants of irb_interfaces/srv/PlanPath (a test checks that).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from irb_description.path import path_from_spec

from .fourier import ORDERS
from .transcription import BOUNDARIES, BOUNDARY_PERIODIC, BOUNDARY_REST

ERROR_NONE = 0
ERROR_INVALID_REQUEST = 1
ERROR_UNREACHABLE = 2
ERROR_INFEASIBLE_DURATION = 3
ERROR_FRICTION_MAP = 4
ERROR_SOLVER = 5

OBJECTIVE_ENERGY = 'energy'
OBJECTIVE_TIME = 'time'
OBJECTIVE_TRAPEZOID = 'trapezoid'
OBJECTIVE_FOURIER = 'fourier'
OBJECTIVES = (OBJECTIVE_ENERGY, OBJECTIVE_TIME, OBJECTIVE_TRAPEZOID, OBJECTIVE_FOURIER)

#: what the energy objective minimises: the thesis's mechanical int sum |tau qd| dt, or the
#: electrical energy from the grid (irb_description.electrical) with the given DC-bus mode
ENERGY_MECHANICAL = 'mechanical'
ENERGY_MODELS = {ENERGY_MECHANICAL: None, 'electrical_none': 'none',
                 'electrical_shared': 'shared', 'electrical_regenerative': 'regenerative'}

PATH_CIRCLE = 'circle'
PATH_ARC = 'arc'
PATH_LINE = 'line'
PATH_POLYLINE = 'polyline'
PATH_SPLINE = 'spline'
PATH_TYPES = (PATH_CIRCLE, PATH_ARC, PATH_LINE, PATH_POLYLINE, PATH_SPLINE)
#: most waypoints a request may carry
MAX_WAYPOINTS = 200
#: shortest path [m] (shorter: the TCP barely moves, theta is ill-defined for the controller)
MIN_PATH_LENGTH = 0.005
MIN_GRID = 20
#: smallest fraction of the speed/torque limits a request may ask for
MIN_LIMIT_SCALING = 0.01
#: radius range [m]: below, the circle is a point for the controller; above, no IRB 1600
RADIUS_RANGE = (1e-3, 2.0)
#: |center| coordinates beyond this are not a place the robot can reach [m]
MAX_COORDINATE = 10.0


class PlanError(Exception):
    """A request that cannot be planned: ``code`` (ERROR_*) and a message saying why."""

    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.code = code
        self.message = message


@dataclass(frozen=True)
class PlanRequest:
    """One planning request, SI units (mirrors PlanPath.Request).

    center (3,) [m], radius [m], start_angle [rad] (reduced to [0, 2 pi)), direction +1/-1;
    objective one of OBJECTIVES; duration [s] (0 = free); time_weight [J/s]; fourier_order 3/5/7;
    grid_size (0 = planner default); limit_scaling (0 = 1.0) in (0, 1]; friction_map path
    ('' = nominal); boundary 'rest' (default, '') or 'periodic'.

    path_type one of PATH_TYPES (irb_description.path): 'circle' uses center, radius,
    start_angle, direction; 'arc' center, normal (3,), radius, start_angle, sweep [rad]
    (0 = 2 pi, a full circle); 'line' waypoints (2, 3) [m]; 'polyline' waypoints (K, 3),
    blend_radii [m] (one, or one per corner), closed; 'spline' waypoints, closed.
    """

    center: np.ndarray = field(default_factory=lambda: np.array([0.6, 0.0, 0.13]))
    radius: float = 0.15
    start_angle: float = 0.0
    direction: int = 1
    objective: str = OBJECTIVE_ENERGY
    duration: float = 0.0
    time_weight: float = 0.0
    fourier_order: int = 0
    grid_size: int = 0
    limit_scaling: float = 0.0
    friction_map: str = ''
    boundary: str = ''
    path_type: str = PATH_CIRCLE
    normal: np.ndarray = field(default_factory=lambda: np.zeros(3))
    sweep: float = 0.0
    waypoints: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    blend_radii: np.ndarray = field(default_factory=lambda: np.zeros(0))
    closed: bool = False
    energy_model: str = ''               # one of ENERGY_MODELS; '' = mechanical
    # process constraints (0 = none): TCP speed band [m/s] (the floor away from the rest
    # ends, i.e. beyond tcp_ramp_length [m] of arc length from each; 0 = speed_min^2 /
    # accel_max), |TCP acceleration| [m/s^2]
    tcp_speed_max: float = 0.0
    tcp_speed_min: float = 0.0
    tcp_accel_max: float = 0.0
    tcp_ramp_length: float = 0.0

    @property
    def has_process(self) -> bool:
        """True if any process constraint is set."""
        return bool(self.tcp_speed_max or self.tcp_speed_min or self.tcp_accel_max)

    @property
    def path_key(self) -> tuple:
        """Hashable identity of the geometric path."""
        if self.path_type == PATH_CIRCLE:
            return (self.path_type, *np.round(np.asarray(self.center, float), 12).tolist(),
                    round(float(self.radius), 12), round(float(self.start_angle), 12),
                    int(self.direction))
        r = lambda x: tuple(np.round(np.asarray(x, float), 12).ravel().tolist())  # noqa: E731
        if self.path_type == PATH_ARC:
            return (self.path_type, r(self.center), r(self.normal), r(self.radius),
                    r(self.start_angle), r(self.sweep))
        return (self.path_type, r(self.waypoints), r(self.blend_radii), bool(self.closed))

    def path_spec(self) -> dict:
        """The path as the plain mapping of ``irb_description.path.path_from_spec``."""
        t = self.path_type
        if t == PATH_CIRCLE:
            return dict(type=t, center=np.asarray(self.center, float).tolist(),
                        radius=float(self.radius), start_angle=float(self.start_angle),
                        direction=int(self.direction))
        if t == PATH_ARC:
            return dict(type=t, center=np.asarray(self.center, float).tolist(),
                        normal=np.asarray(self.normal, float).tolist(),
                        radius=float(self.radius), start_angle=float(self.start_angle),
                        sweep=float(self.sweep) or 2 * math.pi)
        spec = dict(type=t, waypoints=np.asarray(self.waypoints, float).tolist())
        if t == PATH_POLYLINE:
            spec['blend_radii'] = np.atleast_1d(np.asarray(self.blend_radii, float)).tolist()
        if t in (PATH_POLYLINE, PATH_SPLINE):
            spec['closed'] = bool(self.closed)
        return spec


def validate(req: PlanRequest, default_grid: int, max_grid: int = 1000) -> PlanRequest:
    """Check ``req``; return it with defaults filled in and the start angle reduced to
    [0, 2 pi), or raise PlanError(INVALID) with the reason."""
    def bad(msg):
        raise PlanError(ERROR_INVALID_REQUEST, msg)

    if req.path_type not in PATH_TYPES:
        bad(f'path type {req.path_type!r} unknown; one of {list(PATH_TYPES)}')
    circle = req.path_type in (PATH_CIRCLE, PATH_ARC)
    numbers = {'duration': req.duration, 'time_weight': req.time_weight,
               'limit_scaling': req.limit_scaling, 'tcp_speed_max': req.tcp_speed_max,
               'tcp_speed_min': req.tcp_speed_min, 'tcp_accel_max': req.tcp_accel_max,
               'tcp_ramp_length': req.tcp_ramp_length}
    if circle:
        numbers.update(center=req.center, radius=req.radius, start_angle=req.start_angle)
    if req.path_type == PATH_ARC:
        numbers.update(normal=req.normal, sweep=req.sweep)
    if not circle:
        numbers.update(waypoints=req.waypoints, blend_radii=req.blend_radii)
    for name, value in numbers.items():
        try:
            arr = np.asarray(value, float)
        except (TypeError, ValueError):
            bad(f'{name} must be numbers')
        if not np.all(np.isfinite(arr)):
            bad(f'{name} is not finite: {arr.tolist()}')
    direction = req.direction
    if circle:
        if np.asarray(req.center).shape != (3,):
            bad('center must have 3 coordinates')
        if np.any(np.abs(np.asarray(req.center, float)) > MAX_COORDINATE):
            bad(f'center coordinates must be within +-{MAX_COORDINATE:g} m')
        if not RADIUS_RANGE[0] <= req.radius <= RADIUS_RANGE[1]:
            bad(f'radius must be in [{RADIUS_RANGE[0]:g}, {RADIUS_RANGE[1]:g}] m, '
                f'got {req.radius}')
    if req.path_type == PATH_CIRCLE and direction not in (1, -1):
        bad(f'direction must be +1 (counter-clockwise) or -1 (clockwise), got {req.direction}')
    if not circle:
        w = np.asarray(req.waypoints, float)
        if w.ndim != 2 or w.shape[1] != 3:
            bad('waypoints must be a list of [x, y, z] points')
        if w.shape[0] > MAX_WAYPOINTS:
            bad(f'at most {MAX_WAYPOINTS} waypoints, got {w.shape[0]}')
        if np.any(np.abs(w) > MAX_COORDINATE):
            bad(f'waypoint coordinates must be within +-{MAX_COORDINATE:g} m')
    try:
        path = path_from_spec(replace(req, direction=direction if direction in (1, -1)
                                      else 1).path_spec())
    except ValueError as exc:
        bad(f'path: {exc}')
    if path.length < MIN_PATH_LENGTH:
        bad(f'path length {path.length * 1e3:.2f} mm is below {MIN_PATH_LENGTH * 1e3:g} mm')
    if req.objective not in OBJECTIVES:
        bad(f'unknown objective {req.objective!r}; one of {list(OBJECTIVES)}')
    if req.duration < 0:
        bad(f'duration must be >= 0 s, got {req.duration}')
    if req.time_weight < 0:
        bad(f'time_weight must be >= 0 J/s, got {req.time_weight}')
    if (req.objective in (OBJECTIVE_ENERGY, OBJECTIVE_FOURIER) and req.duration == 0
            and req.time_weight == 0):
        bad('duration = 0 (free) needs time_weight > 0, else the slowest motion wins')
    if req.objective == OBJECTIVE_TRAPEZOID and req.duration == 0:
        bad('the trapezoid profile needs a duration > 0')
    if req.objective == OBJECTIVE_FOURIER and req.fourier_order not in ORDERS:
        bad(f'fourier_order must be one of {ORDERS}, got {req.fourier_order}')
    grid = req.grid_size or default_grid
    if not MIN_GRID <= grid <= max_grid:
        bad(f'grid_size must be in [{MIN_GRID}, {max_grid}] (planner parameter max_grid_size), '
            f'got {grid}')
    scaling = req.limit_scaling or 1.0
    if not MIN_LIMIT_SCALING <= scaling <= 1:
        bad(f'limit_scaling must be in [{MIN_LIMIT_SCALING:g}, 1], got {req.limit_scaling}')
    energy_model = req.energy_model or ENERGY_MECHANICAL
    if energy_model not in ENERGY_MODELS:
        bad(f'unknown energy_model {req.energy_model!r}; one of {list(ENERGY_MODELS)}')
    if energy_model != ENERGY_MECHANICAL and req.objective == OBJECTIVE_FOURIER:
        bad('the Fourier profile minimises mechanical energy only')
    boundary = req.boundary or BOUNDARY_REST
    if req.objective == OBJECTIVE_FOURIER:
        if req.boundary and req.boundary != BOUNDARY_PERIODIC:
            bad("the Fourier profile is periodic: boundary must be '' or 'periodic'")
        boundary = BOUNDARY_PERIODIC
    if boundary not in BOUNDARIES:
        bad(f'unknown boundary {req.boundary!r}; one of {list(BOUNDARIES)}')
    if boundary == BOUNDARY_PERIODIC and not path.closed:
        bad(f'a periodic profile (boundary periodic, or the Fourier profile) needs a closed '
            f'path; this {req.path_type} is open')
    if not math.isfinite(req.duration):
        bad('duration is not finite')
    ramp = _process_ramp(req, boundary, path.length, bad)
    # the angle of the start point, reduced exactly (fmod is exact in floating point): a huge
    # angle would otherwise leave no digits for theta in cos(s theta + phi0)
    start = math.fmod(float(req.start_angle), 2 * math.pi)
    start = start + 2 * math.pi if start < 0 else start
    return replace(req, center=np.asarray(req.center, float), direction=int(direction),
                   start_angle=start, grid_size=grid, limit_scaling=scaling,
                   boundary=boundary, normal=np.asarray(req.normal, float),
                   sweep=float(req.sweep), waypoints=np.asarray(req.waypoints, float),
                   blend_radii=np.atleast_1d(np.asarray(req.blend_radii, float)),
                   closed=bool(req.closed), energy_model=energy_model,
                   tcp_speed_max=float(req.tcp_speed_max),
                   tcp_speed_min=float(req.tcp_speed_min),
                   tcp_accel_max=float(req.tcp_accel_max), tcp_ramp_length=ramp)


def _process_ramp(req: PlanRequest, boundary: str, length: float, bad) -> float:
    """Check the process constraints on their own (against each other and the path length;
    whether the path and duration allow them is the planner's to find) and return the ramp
    length [m] at each rest end where the speed may stay below tcp_speed_min."""
    vmax, vmin, amax = req.tcp_speed_max, req.tcp_speed_min, req.tcp_accel_max
    ramp = float(req.tcp_ramp_length)
    for name in ('tcp_speed_max', 'tcp_speed_min', 'tcp_accel_max', 'tcp_ramp_length'):
        if getattr(req, name) < 0:
            bad(f'{name} must be >= 0 (0 = none), got {getattr(req, name)}')
    if not req.has_process:
        if ramp:
            bad('tcp_ramp_length without tcp_speed_min means nothing')
        return 0.0
    if req.objective == OBJECTIVE_FOURIER:
        bad('the Fourier profile takes no process constraints (tcp_*); use the energy, time '
            'or trapezoid objective')
    if vmax and vmin and not vmin < vmax:
        bad(f'tcp_speed_min {vmin:g} m/s must be below tcp_speed_max {vmax:g} m/s')
    if not vmin:
        if ramp:
            bad('tcp_ramp_length without tcp_speed_min means nothing')
        return 0.0
    if boundary != BOUNDARY_REST:
        return 0.0                        # periodic: the floor holds all along the path
    if not ramp:
        if not amax:
            bad('tcp_speed_min on a rest-to-rest plan needs tcp_ramp_length (the start and '
                'stop ramps) or tcp_accel_max (ramps of tcp_speed_min^2 / tcp_accel_max)')
        ramp = vmin ** 2 / amax
    if not 2 * ramp < length:
        bad(f'the start and stop ramps ({ramp * 1e3:.1f} mm each) leave no part of the '
            f'{length * 1e3:.1f} mm path for the speed floor')
    return ramp
