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

PATH_CIRCLE = 'circle'
GRID_RANGE = (20, 2000)


class PlanError(Exception):
    """A request that cannot be planned: ``code`` (ERROR_*) and a message saying why."""

    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.code = code
        self.message = message


@dataclass(frozen=True)
class PlanRequest:
    """One planning request, SI units (mirrors PlanPath.Request).

    center (3,) [m], radius [m], start_angle [rad], direction +1/-1 (0 = +1); objective one
    of OBJECTIVES; duration [s] (0 = free); time_weight [J/s]; fourier_order 3/5/7;
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

    @property
    def path_key(self) -> tuple:
        """Hashable identity of the geometric path."""
        return (self.path_type, *np.round(np.asarray(self.center, float), 12).tolist(),
                round(float(self.radius), 12), round(float(self.start_angle), 12),
                int(self.direction))


def validate(req: PlanRequest, default_grid: int) -> PlanRequest:
    """Check ``req``; return it with defaults filled in, or raise PlanError(INVALID)."""
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
    if req.radius <= 0:
        bad(f'radius must be > 0 m, got {req.radius}')
    direction = 1 if req.direction == 0 else req.direction
    if direction not in (1, -1):
        bad(f'direction must be +1 or -1, got {req.direction}')
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
    if not GRID_RANGE[0] <= grid <= GRID_RANGE[1]:
        bad(f'grid_size must be in {list(GRID_RANGE)}, got {grid}')
    scaling = req.limit_scaling or 1.0
    if not 0 < scaling <= 1:
        bad(f'limit_scaling must be in (0, 1], got {req.limit_scaling}')
    boundary = req.boundary or BOUNDARY_REST
    if req.objective == OBJECTIVE_FOURIER:
        if req.boundary and req.boundary != BOUNDARY_PERIODIC:
            bad("the Fourier profile is periodic: boundary must be '' or 'periodic'")
        boundary = BOUNDARY_PERIODIC
    if boundary not in BOUNDARIES:
        bad(f'unknown boundary {req.boundary!r}; one of {list(BOUNDARIES)}')
    if not math.isfinite(req.duration):
        bad('duration is not finite')
    return replace(req, center=np.asarray(req.center, float), direction=direction,
                   grid_size=grid, limit_scaling=scaling, boundary=boundary)
