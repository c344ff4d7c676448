"""Plan requests as plain data, their validation, and the error codes (no ROS imports).

The codes equal the ERROR_* constants of irb_interfaces/srv/PlanPath (a test checks that).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

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
    energy_model: str = ''               # one of ENERGY_MODELS; '' = mechanical

    @property
    def path_key(self) -> tuple:
        """Hashable identity of the geometric path."""
        return (self.path_type, *np.round(np.asarray(self.center, float), 12).tolist(),
                round(float(self.radius), 12), round(float(self.start_angle), 12),
                int(self.direction))


def validate(req: PlanRequest, default_grid: int, max_grid: int = 1000) -> PlanRequest:
    """Check ``req``; return it with defaults filled in and the start angle reduced to
    [0, 2 pi), or raise PlanError(INVALID) with the reason."""
    def bad(msg):
        raise PlanError(ERROR_INVALID_REQUEST, msg)

    numbers = {'center': req.center, 'radius': req.radius, 'start_angle': req.start_angle,
               'duration': req.duration, 'time_weight': req.time_weight,
               'limit_scaling': req.limit_scaling}
    for name, value in numbers.items():
        arr = np.asarray(value, float)
        if not np.all(np.isfinite(arr)):
            bad(f'{name} is not finite: {arr.tolist()}')
    if np.asarray(req.center).shape != (3,):
        bad('center must have 3 coordinates')
    if req.path_type != PATH_CIRCLE:
        bad(f"path type {req.path_type!r} unknown (only 'circle')")
    if np.any(np.abs(np.asarray(req.center, float)) > MAX_COORDINATE):
        bad(f'center coordinates must be within +-{MAX_COORDINATE:g} m')
    if not RADIUS_RANGE[0] <= req.radius <= RADIUS_RANGE[1]:
        bad(f'radius must be in [{RADIUS_RANGE[0]:g}, {RADIUS_RANGE[1]:g}] m, got {req.radius}')
    direction = req.direction
    if direction not in (1, -1):
        bad(f'direction must be +1 (counter-clockwise) or -1 (clockwise), got {req.direction}')
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
    if not math.isfinite(req.duration):
        bad('duration is not finite')
    # the angle of the start point, reduced exactly (fmod is exact in floating point): a huge
    # angle would otherwise leave no digits for theta in cos(s theta + phi0)
    start = math.fmod(float(req.start_angle), 2 * math.pi)
    start = start + 2 * math.pi if start < 0 else start
    return replace(req, center=np.asarray(req.center, float), direction=int(direction),
                   start_angle=start, grid_size=grid, limit_scaling=scaling,
                   boundary=boundary, energy_model=energy_model)
