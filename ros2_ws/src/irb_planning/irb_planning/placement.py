"""Task placement: where to put a circle task so that its optimal timing costs least (no ROS).

A task is the circle's radius, direction and duration plus where it may go: a box for its
centre, rotations about the vertical axis, and tilts of the circle's plane about the base x
and y axes. The task's orientation is R = Rz(rotation) Ry(tilt_y) Rx(tilt_x) applied to the
horizontal circle (start point at ``start_angle`` in its own plane): its plane normal is
R e_z and its start point c + r R (cos phi0, sin phi0, 0). Untilted placements are planned
as the horizontal ``circle`` (for it a rotation is a change of the start angle), tilted ones
as a full ``arc`` with that normal and start point (``placement_request``).

Search (``search``): every point of a regular grid over the box x rotations x tilts is
planned with the planner's public API (``Planner.plan(PlanRequest)``, energy objective, the
requested energy model) on a coarse theta grid; points the planner refuses (unreachable,
too short for the limits, solver failure) are kept in the map with their reason, never
dropped. The best ``refine`` grid points are then re-planned on the full theta grid, and
around the best one a compass search (steps halved down to ``min_step`` [m] for the centre
and ``min_tilt_step`` [rad] for the two tilts, inside the box and the tilt ranges) refines
the centre and tilt.

Evidence (``certificate``): on the coarse map, with L_d the largest finite difference
|dE/dx_d| between neighbouring reachable grid points along axis d, no point of a grid cell
whose corners are reachable can be below min(corners) - sum_d L_d h_d / 2; the certificate
reports the lowest such value over all such cells against the refined best, i.e. the largest
possible improvement the grid leaves, and how many cells it covers: a cell with a refused
corner is not covered (nothing is claimed there; with none covered the bound is NaN). L_d is
measured on the grid, not proven: a function that varies faster between grid points than
between them and their neighbours escapes it. The map is planned on the coarse theta grid,
the best on the full one; their discretisations differ (0.2 % at the thesis circle). The
certificate runs per orientation over the centre axes: it claims nothing about the
rotations and tilts between their grid values.

Multi-start (``search(starts=K)``, K > 1): the compass search runs from K starts, not only
from the best re-planned point: that point and the best other local minima of the coarse map
(a planned point no planned neighbour along x, y or z, and no other orientation at the same
centre, is below; refused neighbours do not count), then the best remaining points if there
are fewer minima. Each start is re-planned on the full grid and refined; the best end is the
answer. ``PlacementResult.starts`` lists each start, where its search ended and its energy;
``multistart_spread_pct`` = 100 (worst end - best end) / best end. Its honest meaning: K
local searches from distinct starts (the coarse map's basins first) ended within that much of
the best, and none below it: the best is the lowest of the basins the grid resolves (spread
~0: they all end in one). It is evidence, not a bound: a basin narrower than the grid
spacing is missed.

Coverage (``coverage``): the grid cells above need all 8 corners reachable. Instead, every
point of the box belongs to the box of its nearest grid point (half a spacing each way,
clipped to the region); under the same measured constants L_d no reachable point of the box
of a reachable grid point v is below E(v) - sum_d L_d h_d / 2. Those boxes are covered, the
boxes of refused grid points are not (nothing is claimed there: the planner could not plan
their centre, and the part of them that is reachable is unknown); the covered share of the
box's volume is reported with the bound. The same function applied to the convex bounds
(below) gives a lower bound of every timing over the covered boxes, with the bounds' own
measured constants. Both are as good as the measured L_d: with a spacing of decimetres and
L of hundreds of J/m the bound is far below the best (often below 0, i.e. vacuous);
``coverage`` also reports the spacing a 1 % argument would need.

Bounds (``search(bounds=True)``): the map's energies are local optima of a nonconvex NLP; the
planner's convex relaxation (``Planner.bound``, baselines.EnergyBound) gives at each planned
map point a lower bound on every timing of that placement (on the same theta grid), and one at
the best placement on the full grid. Their lowest value over the map is what no timing at any
planned point can beat: a sound statement at the points, up to the theta discretisation, and
none between them (the bounds are as steep as the energies, and the Lipschitz argument above
would need a spacing of millimetres).

Electrical cap (``fixed_electrical_energy``): with irb_description's electrical model every
plan of duration T draws at least (P_sb + sum_i P_idle_i) T, in every DC-bus mode, whatever
the placement and the timing, so no placement or timing saves more than
1 - (P_sb + sum P_idle) T / E_ref against a reference plan of energy E_ref and the same T.
Proof: per axis P_ax - P_idle = f(P_e) with f(x) = max(x, 0) / eta_d + min(x, 0) eta_d >= x,
P_e = P_g + P_cu >= P_g >= P_j = tau qd (P_cu >= 0; P_j / eta_m >= P_j when P_j >= 0,
eta_g P_j >= P_j when P_j < 0; all efficiencies in (0, 1]); the bus adds max(S, 0) >= S
('shared'), sum_i max(P_ax_i, 0) >= S ('none'), max(S, 0) + eta_r min(S, 0) >= S
('regenerative'), S = sum_i P_ax_i. So E >= (P_sb + sum P_idle) T + int sum_i tau_i qd_i dt,
and the last term, the net work on the arm, is Delta(kinetic + potential energy) + the
friction's dissipation >= 0 when (a) the motion starts and ends at rest (or, 'periodic',
with the same speed on the closed path: same q and qd at both ends), (b) it ends in the
configuration it started in (a closed path, joint 1 not wrapped: the planner refuses a
crossing of +-180 deg), (c) tau is the model's rigid-body torque plus a friction that
opposes the speed (tau_f qd >= 0: Coulomb, viscous, Stribeck), exactly integrated. The
played energies are trapezoidal sums at the check's rate: equal up to that quadrature. A
regenerative bus does not break it: what it returns is at most the net negative work, which
over such a cycle is paid for by the motoring work first.
"""
from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
from irb_description.path import plane_axes

from .request import ENERGY_MODELS, PlanError, PlanRequest

#: a search's planner skips playing and checking the time-optimal profile of a placement
#: whose duration is at least this many times its time-optimal one (PlannerSettings.
#: min_duration_check_factor): 6.4 of 7.0 s per 10 s plan at N = 40, deciding nothing there
PLACEMENT_MIN_DURATION_CHECK_FACTOR = 1.5

#: largest tilt of the circle's plane [rad] a region may ask for (beyond, "tilt" is a
#: vertical circle: ask for it as a rotation of a vertical task instead)
MAX_TILT = np.radians(90.0)


@dataclass(frozen=True)
class Region:
    """Box for the centre: lo, hi (3,) [m]; rotations about z [rad]; tilts of the plane
    about the base x and y axes [rad] (grid values; the compass search stays within
    [min, max] of each)."""

    lo: np.ndarray
    hi: np.ndarray
    rotations: tuple = (0.0,)
    tilt_x: tuple = (0.0,)
    tilt_y: tuple = (0.0,)

    def __post_init__(self):
        lo, hi = np.asarray(self.lo, float), np.asarray(self.hi, float)
        if (lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo))
                or not np.all(np.isfinite(hi)) or np.any(hi < lo)):
            raise ValueError(f'region: lo and hi must be 3 finite numbers with lo <= hi, got '
                             f'{lo.tolist()} {hi.tolist()}')
        for name in ('rotations', 'tilt_x', 'tilt_y'):
            v = np.asarray(getattr(self, name), float)
            if v.ndim != 1 or v.size == 0 or not np.all(np.isfinite(v)):
                raise ValueError(f'region: {name} must be one or more finite angles')
        if max(np.abs(self.tilt_x).max(), np.abs(self.tilt_y).max()) > MAX_TILT:
            raise ValueError('region: tilts must be within +-90 deg')

    def orientations(self) -> np.ndarray:
        """(M, 3) [rad]: every (rotation, tilt_x, tilt_y) of the grid."""
        return np.array(list(itertools.product(self.rotations, self.tilt_x, self.tilt_y)),
                        float)


def orientation_matrix(rotation: float, tilt_x: float, tilt_y: float) -> np.ndarray:
    """R = Rz(rotation) Ry(tilt_y) Rx(tilt_x) (3, 3)."""
    cz, sz = np.cos(rotation), np.sin(rotation)
    cy, sy = np.cos(tilt_y), np.sin(tilt_y)
    cx, sx = np.cos(tilt_x), np.sin(tilt_x)
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return Rz @ Ry @ Rx


def placement_request(task: PlanRequest, center, rotation: float = 0.0, tilt_x: float = 0.0,
                      tilt_y: float = 0.0) -> PlanRequest:
    """``task`` (a horizontal circle: radius, start_angle, direction, duration, ...) placed
    with its centre at ``center`` [m] and the orientation (module docstring). Untilted: the
    ``circle`` with the start angle turned by ``rotation``; tilted: the full ``arc`` with the
    plane normal R e_z, starting at c + r R (cos phi0, sin phi0, 0), running the task's
    direction about that normal."""
    center = np.asarray(center, float)
    if tilt_x == 0.0 and tilt_y == 0.0:
        return replace(task, path_type='circle', center=center,
                       start_angle=float(task.start_angle) + float(rotation))
    R = orientation_matrix(rotation, tilt_x, tilt_y)
    normal = R[:, 2]
    start = R @ np.array([np.cos(task.start_angle), np.sin(task.start_angle), 0.0])
    u, v, _ = plane_axes(normal)
    return replace(task, path_type='arc', center=center, normal=normal,
                   start_angle=float(np.arctan2(start @ v, start @ u)),
                   sweep=2 * np.pi * (1 if int(task.direction) >= 0 else -1))


@dataclass
class PlacementResult:
    """The map (axes xs, ys, zs [m], orientations: rotations [rad] and tilts (M, 2) [rad] of
    each; energy [J] NaN where refused and reasons there), the best placement (centre,
    rotation, tilt (2,) [rad] about x and y, energy [J], its PlanResult),
    the certificate (lower bound over the region [J], possible improvement [%]),
    evaluations and wall time [s]."""

    xs: np.ndarray
    ys: np.ndarray
    zs: np.ndarray
    rotations: np.ndarray
    energy: np.ndarray                    # (nx, ny, nz, orientations)
    reasons: dict = field(default_factory=dict)
    best_center: np.ndarray | None = None
    best_rotation: float = 0.0
    best_energy: float = float('nan')
    best_plan: object = None
    region_lower_bound: float = float('nan')
    possible_improvement_pct: float = float('nan')
    lipschitz: np.ndarray | None = None
    cells_covered: int = 0
    cells_total: int = 0
    evaluations: int = 0
    wall_time: float = 0.0
    measure: str = 'mechanical'
    tilts: np.ndarray | None = None       # (M, 2) [rad], tilt about x and y per orientation
    best_tilt: np.ndarray = field(default_factory=lambda: np.zeros(2))
    # with ``bounds``: the convex lower bound [J] of every timing at each planned map point
    # (same grid, NaN where refused or not computed), their lowest value, and the bound at
    # the best placement on the full grid
    lower_bounds: np.ndarray | None = None
    grid_bound_floor: float = float('nan')
    best_lower_bound: float = float('nan')
    # the compass searches (module docstring, "Multi-start"): per start a dict with
    # 'start_center', 'start_orientation' (rotation, tilt_x, tilt_y) [m, rad],
    # 'coarse_energy', 'start_energy' (full grid), 'end_center', 'end_orientation',
    # 'end_energy' [J], 'plans', 'wall_s' [s], 'local_minimum' (of the coarse map); the
    # spread [%]
    starts: list = field(default_factory=list)
    multistart_spread_pct: float = float('nan')
    # ``coverage`` of the map's energies and (with ``bounds``) of the convex bounds
    energy_coverage: dict = field(default_factory=dict)
    bound_coverage: dict = field(default_factory=dict)


def plan_energy(result, energy_model: str) -> float:
    """The energy a placement is judged by: of the independently checked trajectory."""
    ver = result.verification
    if energy_model in ('', 'mechanical'):
        return float(ver.energy)
    return float(ver.electrical['total_' + energy_model.split('_', 1)[1]])


def search(planner, task: PlanRequest, region: Region, n: tuple = (3, 3, 3),
           coarse_grid: int = 40, refine: int = 2, min_step: float = 0.01,
           progress: Callable[[str], None] = print,
           min_tilt_step: float = np.radians(2.0), bounds: bool = False,
           starts: int = 1) -> PlacementResult:
    """Grid over the region, refine the best points (module docstring). ``task`` holds the
    radius, direction, duration, energy_model (its centre and start angle are replaced).
    ``bounds``: also the planner's convex lower bound (``Planner.bound``) at every planned
    map point and at the best placement (module docstring, "Bounds"). ``starts``: compass
    searches from that many distinct starts (module docstring, "Multi-start"; 1: from the
    best re-planned point only, as before)."""
    t0 = time.perf_counter()
    lo, hi = np.asarray(region.lo, float), np.asarray(region.hi, float)
    axes = [np.linspace(lo[d], hi[d], n[d]) if hi[d] > lo[d] else np.array([lo[d]])
            for d in range(3)]
    orient = region.orientations()
    rots, tilts = orient[:, 0], orient[:, 1:]
    E = np.full((axes[0].size, axes[1].size, axes[2].size, orient.shape[0]), np.nan)
    reasons = {}
    LB = np.full(E.shape, np.nan) if bounds else None
    model = task.energy_model or 'mechanical'
    total = E.size
    evals = 0

    def run(center, o, grid):
        nonlocal evals
        evals += 1
        req = replace(placement_request(task, center, *o), grid_size=grid,
                      objective='energy')
        res = planner.plan(req)
        return plan_energy(res, model), res

    def lower_bound(center, o, grid) -> float:
        try:
            return placement_bound(planner, task, center, o, grid)
        except PlanError as exc:
            progress(f'bound at {np.round(center, 3).tolist()} failed: {exc.message[:80]}')
            return float('nan')

    def describe(o):
        text = f'rotation {np.degrees(o[0]):.0f} deg'
        if o[1] or o[2]:
            text += f' tilt ({np.degrees(o[1]):.1f}, {np.degrees(o[2]):.1f}) deg'
        return text

    for k, idx in enumerate(itertools.product(*[range(a.size) for a in axes],
                                              range(orient.shape[0]))):
        c = np.array([axes[d][idx[d]] for d in range(3)])
        try:
            E[idx], _ = run(c, orient[idx[3]], coarse_grid)
            msg = f'{E[idx]:.2f} J'
            if bounds:
                LB[idx] = lower_bound(c, orient[idx[3]], coarse_grid)
                msg += f', bound {LB[idx]:.2f} J'
        except PlanError as exc:
            reasons[idx] = f'error {exc.code}: {exc.message[:80]}'
            msg = 'refused: ' + reasons[idx]
        progress(f'[{k + 1}/{total}] centre {np.round(c, 3).tolist()} '
                 f'{describe(orient[idx[3]])}: {msg} ({time.perf_counter() - t0:.0f} s)')
    empty = dict(evaluations=evals, measure=model, tilts=tilts)
    if np.all(np.isnan(E)):
        return PlacementResult(axes[0], axes[1], axes[2], rots, E, reasons,
                               wall_time=time.perf_counter() - t0, **empty)
    # --- refine: the best coarse points on the planner's full grid, then a compass search --
    order = np.argsort(np.where(np.isnan(E), np.inf, E), axis=None)[:max(refine, 1)]
    best = (np.inf, None, None, None, None)
    full = {}                     # map index -> (energy, result) on the full grid
    for flat in order:
        idx = tuple(int(v) for v in np.unravel_index(flat, E.shape))
        c = np.array([axes[d][idx[d]] for d in range(3)])
        try:
            e, res = run(c, orient[idx[3]], task.grid_size)
        except PlanError:
            continue
        full[idx] = (e, res)
        progress(f'refine {np.round(c, 3).tolist()} {describe(orient[idx[3]])}: {e:.2f} J '
                 'on the full grid')
        if e < best[0]:
            best = (e, c, orient[idx[3]], res, idx)
    if best[1] is None:
        return PlacementResult(axes[0], axes[1], axes[2], rots, E, reasons,
                               wall_time=time.perf_counter() - t0, **empty)
    seed_idx = best[4]
    t_axes = [np.unique(region.tilt_x), np.unique(region.tilt_y)]
    z_lo = np.concatenate([lo, [a.min() for a in t_axes]])
    z_hi = np.concatenate([hi, [a.max() for a in t_axes]])
    spacing = [(a[1] - a[0]) if a.size > 1 else 0.0 for a in axes]
    spacing += [float(np.min(np.diff(a))) if a.size > 1 else 0.0 for a in t_axes]
    floor = np.array([min_step] * 3 + [min_tilt_step] * 2)

    def compass(e0, c0, o0, res0):
        """Compass search over (x, y, z, tilt_x, tilt_y) within the box and the tilt ranges
        from c0, o0 (energy e0 on the full grid): (energy, centre, orientation, result)."""
        e_b, z_b, o_b, res_b = e0, np.concatenate([c0, o0[1:]]), np.asarray(o0), res0
        step = 0.5 * np.array(spacing)
        while np.any(step >= floor):
            improved = False
            for d in range(5):
                if step[d] < floor[d]:
                    continue
                for sgn in (1, -1):
                    z = z_b.copy()
                    z[d] = np.clip(z[d] + sgn * step[d], z_lo[d], z_hi[d])
                    if np.allclose(z, z_b):
                        continue
                    o = np.array([o_b[0], z[3], z[4]])
                    try:
                        e, res = run(z[:3], o, task.grid_size)
                    except PlanError:
                        continue
                    if e < e_b:
                        e_b, z_b, o_b, res_b, improved = e, z, o, res, True
                        progress(f'compass: {np.round(z[:3], 3).tolist()} {describe(o)} '
                                 f'{e:.2f} J')
                        break
            if not improved:
                step = step / 2
        return e_b, z_b[:3], o_b, res_b

    minima = local_minima(E)
    start_idx = [seed_idx] + [i for i in _start_points(E, minima, max(starts, 1))
                              if i != seed_idx][:max(starts, 1) - 1]
    runs = []
    for k, idx in enumerate(start_idx):
        c0 = np.array([axes[d][idx[d]] for d in range(3)])
        o0 = orient[idx[3]]
        n0, t_start = evals, time.perf_counter()
        if idx in full:
            e0, res0 = full[idx]
        else:
            try:
                e0, res0 = run(c0, o0, task.grid_size)
            except PlanError as exc:
                progress(f'start {np.round(c0, 3).tolist()} {describe(o0)}: refused on the '
                         f'full grid ({exc.message[:60]})')
                runs.append(dict(start_center=c0.tolist(), start_orientation=o0.tolist(),
                                 coarse_energy=float(E[idx]), start_energy=float('nan'),
                                 end_center=None, end_orientation=None,
                                 end_energy=float('nan'), plans=evals - n0,
                                 local_minimum=idx in minima))
                continue
        e1, c1, o1, res1 = compass(e0, c0, o0, res0)
        runs.append(dict(start_center=c0.tolist(), start_orientation=o0.tolist(),
                         coarse_energy=float(E[idx]), start_energy=float(e0),
                         end_center=np.asarray(c1, float).tolist(),
                         end_orientation=np.asarray(o1, float).tolist(), end_energy=float(e1),
                         plans=evals - n0, wall_s=time.perf_counter() - t_start,
                         local_minimum=idx in minima, result=res1))
        if len(start_idx) > 1:
            progress(f'start {k + 1}/{len(start_idx)} {np.round(c0, 3).tolist()} '
                     f'{describe(o0)} (coarse {E[idx]:.2f} J) ended at '
                     f'{np.round(c1, 3).tolist()} {describe(o1)}: {e1:.2f} J')
    ended = [r for r in runs if np.isfinite(r['end_energy'])]
    won = min(ended, key=lambda r: r['end_energy'])
    e_best, res_best = won['end_energy'], won.pop('result')
    c_best, o_best = np.array(won['end_center']), np.array(won['end_orientation'])
    for r in runs:
        r.pop('result', None)
    spread = (100 * (max(r['end_energy'] for r in ended) - e_best) / e_best
              if len(ended) > 1 else float('nan'))
    if len(start_idx) > 1:
        progress(f'multi-start: {len(ended)} of {len(runs)} starts ended, all within '
                 f'{spread:.2f} % of the best {e_best:.2f} J')
    extra = {}
    if bounds:
        floor = float(np.nanmin(LB)) if np.any(np.isfinite(LB)) else float('nan')
        lb_best = lower_bound(c_best, o_best, task.grid_size)
        extra = dict(lower_bounds=LB, grid_bound_floor=floor, best_lower_bound=lb_best)
        progress(f'convex bounds: lowest {floor:.2f} J over {int(np.isfinite(LB).sum())} '
                 f'planned map points; {lb_best:.2f} J at the best placement (its plan '
                 f'{e_best:.2f} J)')
    bound, lip, covered, cells = certificate(axes, E)
    gap = 100 * (e_best - bound) / e_best
    extra['energy_coverage'] = coverage(axes, E, e_best)
    if bounds:
        extra['bound_coverage'] = coverage(axes, LB, e_best)
    cov = extra['energy_coverage']
    progress(f'coverage: {100 * cov["covered_fraction"]:.0f} % of the box is nearest to a '
             f'reachable map point ({100 * cov["uncovered_fraction"]:.0f} % to a refused one: '
             f'no claim); measured Lipschitz lower bound there {cov["lower_bound"]:.2f} J '
             f'(margin {cov["margin"]:.1f} J)')
    progress(f'best {np.round(c_best, 3).tolist()} {describe(o_best)}: '
             f'{e_best:.2f} J; lower bound over {covered}/{cells} fully reachable cells '
             f'(grid + Lipschitz) {bound:.2f} J, possible improvement there <= {gap:.2f} %; '
             f'{evals} plans, {time.perf_counter() - t0:.0f} s')
    return PlacementResult(axes[0], axes[1], axes[2], rots, E, reasons, c_best,
                           float(o_best[0]), float(e_best), res_best, float(bound), float(gap),
                           lip, cells_covered=covered, cells_total=cells, evaluations=evals,
                           wall_time=time.perf_counter() - t0, measure=model, tilts=tilts,
                           best_tilt=np.array(o_best[1:], float), starts=runs,
                           multistart_spread_pct=float(spread), **extra)


def certificate(axes, E: np.ndarray) -> tuple[float, np.ndarray, int, int]:
    """(lowest value any point of a fully reachable grid cell can take under the measured
    Lipschitz constants (NaN: no such cell), those constants (3,) [J/m], cells covered,
    cells in all); module docstring."""
    L = np.zeros(3)
    for d in range(3):
        if axes[d].size > 1:
            diff = np.abs(np.diff(E, axis=d)) / np.diff(axes[d])[0]
            L[d] = np.nanmax(diff) if np.any(np.isfinite(diff)) else 0.0
    h = np.array([(a[1] - a[0]) if a.size > 1 else 0.0 for a in axes])
    lowest = np.inf
    covered = total = 0
    shape = E.shape[:3]
    cells = [range(max(s - 1, 1)) for s in shape]
    for r in range(E.shape[3]):
        for i, j, k in itertools.product(*cells):
            corner = E[i:i + 2, j:j + 2, k:k + 2, r]
            total += 1
            if np.any(np.isnan(corner)):
                continue
            covered += 1
            lowest = min(lowest, float(np.min(corner)) - float(np.dot(L, h)) / 2)
    return (lowest if np.isfinite(lowest) else float('nan')), L, covered, total


def local_minima(E: np.ndarray) -> list[tuple]:
    """Map indices (i, j, k, orientation) of the planned points of E (nx, ny, nz, M) that no
    planned neighbour along x, y or z (same orientation) and no other orientation at the
    same centre is below (refused points, NaN, do not count), lowest first; of equal minima
    within one grid step of each other in x, y and z (a plateau of ties) only the first
    counts."""
    out = []
    for idx in zip(*np.nonzero(np.isfinite(E))):
        idx = tuple(int(v) for v in idx)
        e = E[idx]
        others = [E[idx[:3] + (m,)] for m in range(E.shape[3]) if m != idx[3]]
        for d in range(3):
            for sgn in (-1, 1):
                j = list(idx)
                j[d] += sgn
                if 0 <= j[d] < E.shape[d]:
                    others.append(E[tuple(j)])
        if not any(np.isfinite(o) and o < e for o in others):
            out.append(idx)
    kept = []
    for idx in sorted(out, key=lambda i: E[i]):
        if not any(np.all(np.abs(np.subtract(idx[:3], k[:3])) <= 1) and E[idx] == E[k]
                   for k in kept):
            kept.append(idx)
    return kept


def _start_points(E: np.ndarray, minima: list, k: int) -> list[tuple]:
    """``k`` starts: the local minima, lowest first, then the lowest other planned points
    that are no grid neighbour (in x, y, z) of a start already chosen, then any."""
    chosen = list(minima[:k])
    rest = [tuple(int(v) for v in np.unravel_index(f, E.shape))
            for f in np.argsort(np.where(np.isnan(E), np.inf, E), axis=None)
            if np.isfinite(E.flat[f])]
    rest = [i for i in rest if i not in chosen]
    far = [i for i in rest if all(np.abs(np.subtract(i[:3], c[:3])).sum() > 1
                                  for c in chosen)]
    for i in far + rest:
        if len(chosen) >= k:
            break
        if i not in chosen:
            chosen.append(i)
    return chosen


def coverage(axes, V: np.ndarray, reference: float = float('nan'),
             target_pct: float = 1.0) -> dict:
    """The nearest-grid-point boxes of V (nx, ny, nz, M) (module docstring, "Coverage"):
    'lipschitz' L_d (3,) [J/m] measured on V as in ``certificate``; 'margin' sum_d L_d h_d / 2
    [J]; 'lower_bound' [J] min over the reachable (finite) points of V - margin (NaN: none);
    'covered_fraction' of the box's volume (x orientations) whose grid point is reachable,
    'uncovered_fraction' the rest (the refused points' boxes: nothing claimed);
    'points_covered', 'points_total'; with ``reference`` (the best energy) 'possible_
    improvement_pct' 100 (reference - lower_bound) / reference and 'spacing_for_target_m'
    (3,): spacings with L_d h_d / 2 = target_pct % of the reference / (axes with L_d > 0) each,
    what a grid argument at that resolution would need."""
    V = np.asarray(V, float)
    L = np.zeros(3)
    h = np.array([(a[1] - a[0]) if a.size > 1 else 0.0 for a in axes])
    for d in range(3):
        if axes[d].size > 1:
            diff = np.abs(np.diff(V, axis=d)) / h[d]
            L[d] = np.nanmax(diff) if np.any(np.isfinite(diff)) else 0.0
    margin = float(np.dot(L, h)) / 2
    # volume of each point's box: half a spacing at the region's faces, a whole one inside
    w = []
    for d in range(3):
        wd = np.full(axes[d].size, h[d] if axes[d].size > 1 else 1.0)
        if axes[d].size > 1:
            wd[[0, -1]] = h[d] / 2
        w.append(wd)
    vol = np.einsum('i,j,k->ijk', *w)[..., None] * np.ones(V.shape[3])
    ok = np.isfinite(V)
    out = dict(lipschitz=L.tolist(), margin=margin, spacing_m=h.tolist(),
               lower_bound=float(np.min(V[ok]) - margin) if ok.any() else float('nan'),
               covered_fraction=float(vol[ok].sum() / vol.sum()),
               uncovered_fraction=float(vol[~ok].sum() / vol.sum()),
               points_covered=int(ok.sum()), points_total=int(V.size))
    if np.isfinite(reference):
        out['possible_improvement_pct'] = float(100 * (reference - out['lower_bound'])
                                                / reference)
        active = L > 0
        share = target_pct / 100 * reference / max(int(active.sum()), 1)
        out['spacing_for_target_m'] = [float(2 * share / L[d]) if active[d] else None
                                       for d in range(3)]
        out['target_pct'] = float(target_pct)
    return out


def bound_map(planner, task: PlanRequest, region: Region, n: tuple, coarse_grid: int = 20,
              progress: Callable[[str], None] = print) -> tuple[list, np.ndarray, dict]:
    """The planner's convex lower bound (``Planner.bound``) of every timing at each point of
    an n[0] x n[1] x n[2] grid over the region's box (its first orientation), without the
    plans: (axes, bounds (nx, ny, nz, 1) [J], NaN where refused, reasons by index). A
    denser picture of the bound surface than the search's map; a claim at its points only."""
    lo, hi = np.asarray(region.lo, float), np.asarray(region.hi, float)
    axes = [np.linspace(lo[d], hi[d], n[d]) if hi[d] > lo[d] else np.array([lo[d]])
            for d in range(3)]
    o = region.orientations()[0]
    LB = np.full([a.size for a in axes] + [1], np.nan)
    reasons = {}
    t0 = time.perf_counter()
    for k, idx in enumerate(itertools.product(*[range(a.size) for a in axes])):
        c = np.array([axes[d][idx[d]] for d in range(3)])
        try:
            LB[idx + (0,)] = placement_bound(planner, task, c, o, coarse_grid)
            msg = f'bound {LB[idx + (0,)]:.2f} J'
        except PlanError as exc:
            reasons[idx + (0,)] = f'error {exc.code}: {exc.message[:80]}'
            msg = 'refused: ' + reasons[idx + (0,)]
        progress(f'[{k + 1}/{LB.size}] centre {np.round(c, 3).tolist()}: {msg} '
                 f'({time.perf_counter() - t0:.0f} s)')
    return axes, LB, reasons


def plot_bound_map(path: str, axes, LB: np.ndarray, goal: float, title: str = '',
                   best=None) -> str:
    """PNG of ``bound_map``: one panel per z level, the bound over (x, y) as coloured squares
    with their values, points at or below ``goal`` [J] ringed red, refused points as red
    crosses, ``best`` (centre (3,)) a star on the panel nearest its height."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    xs, ys, zs = axes
    fig, axs = plt.subplots(1, zs.size, figsize=(3.4 * zs.size + 1.2, 5.0), squeeze=False,
                            sharey=True)
    vmin, vmax = np.nanmin(LB), np.nanmax(LB)
    k_best = int(np.argmin(np.abs(zs - best[2]))) if best is not None else -1
    X, Y = np.meshgrid(xs, ys, indexing='ij')
    for k in range(zs.size):
        ax = axs[0, k]
        b = LB[:, :, k, 0]
        sc = ax.scatter(X.ravel(), Y.ravel(), c=b.ravel(), s=150, marker='s', vmin=vmin,
                        vmax=vmax, cmap='viridis')
        bad = np.isnan(b)
        ax.scatter(X[bad], Y[bad], marker='x', color='red', s=50, label='refused')
        low = np.isfinite(b) & (b <= goal)
        if np.any(low):
            ax.scatter(X[low], Y[low], s=220, facecolors='none', edgecolors='red',
                       label=f'bound <= {goal:.2f} J')
        for x, y, v in zip(X.ravel(), Y.ravel(), b.ravel()):
            if np.isfinite(v):
                ax.annotate(f'{v:.0f}', (x, y), ha='center', va='center', fontsize=6,
                            color='white')
        if k == k_best:
            ax.plot(best[0], best[1], '*', color='orange', ms=14, label='best placement')
        ax.set_title(f'z = {zs[k]:.3f} m')
        ax.set_xlabel('centre x [m]')
        pad = [0.06 * max(a.max() - a.min(), 0.1) for a in (xs, ys)]
        ax.set_xlim(xs.min() - pad[0], xs.max() + pad[0])
        ax.set_ylim(ys.min() - pad[1], ys.max() + pad[1])
        if k == 0:
            ax.set_ylabel('centre y [m]')
    handles = {}
    for ax in axs[0]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    fig.legend(handles.values(), handles.keys(), loc='lower center', ncol=3, fontsize=8)
    fig.subplots_adjust(left=0.05, right=0.9, bottom=0.2, top=0.86, wspace=0.08)
    fig.colorbar(sc, cax=fig.add_axes([0.915, 0.2, 0.012, 0.66]),
                 label='convex lower bound of every timing [J]')
    fig.suptitle(title or f'convex lower bounds over the box; goal {goal:.2f} J', fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def bound_gap_pct(res: PlacementResult) -> float:
    """[%] 100 (best - lowest convex bound over the planned map points) / best: no timing
    at any planned map point is more than this below the best (NaN without bounds)."""
    best, floor = float(res.best_energy), float(res.grid_bound_floor)
    if not (np.isfinite(best) and np.isfinite(floor) and best > 0):
        return float('nan')
    return 100 * (best - floor) / best


def placement_bound(planner, task: PlanRequest, center, orientation, grid: int) -> float:
    """The planner's convex lower bound [J] of every timing of ``task`` placed at ``center``
    with ``orientation`` (rotation, tilt_x, tilt_y) on a theta grid of ``grid`` nodes;
    raises PlanError as ``Planner.bound`` does."""
    req = replace(placement_request(task, center, *orientation), grid_size=grid,
                  objective='energy')
    return float(planner.bound(req, task.duration))


def task_fixed_electrical_energy(planner, task: PlanRequest) -> float:
    """``fixed_electrical_energy`` of the planner's electrical model at the task's
    duration when the task is judged on an electrical model, NaN on the mechanical one."""
    if not ENERGY_MODELS.get(task.energy_model or 'mechanical'):
        return float('nan')
    return fixed_electrical_energy(planner.electrical, task.duration)


def fixed_electrical_energy(electrical, duration: float) -> float:
    """(P_sb + sum_i P_idle_i) T [J]: the standby and drive idle energy every plan of
    ``duration`` pays in every DC-bus mode, whatever its placement and timing (module
    docstring, "Electrical cap")."""
    return float((float(electrical.standby_power)
                  + float(np.sum(electrical.drive_idle_power))) * duration)


def plot_bounds(path: str, res: PlacementResult, reference: float, goal_pct: float = 20.0,
                title: str = '') -> str:
    """PNG of the evidence against a saving goal: one panel per z level, per (x, y) grid
    point (over the orientations, the lowest) the map's energy (circle) and the convex lower
    bound of every timing there (triangle, joined to it), refused points as red crosses on
    the axis, the ``reference`` energy (trapezoid at the reference placement) and the goal's
    line (1 - goal_pct / 100) x reference, the best placement (star, on the panel nearest
    its height, at its grid column)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    nz = res.zs.size
    E = res.energy
    LB = res.lower_bounds if res.lower_bounds is not None else np.full(E.shape, np.nan)
    fig, axs = plt.subplots(1, nz, figsize=(5.0 * nz, 4.4), squeeze=False, sharey=True)
    goal = (1 - goal_pct / 100) * reference
    finite = np.concatenate([E[np.isfinite(E)], LB[np.isfinite(LB)], [goal, reference]])
    lo, hi = 0.9 * finite.min(), 1.05 * finite.max()
    k_best = (int(np.argmin(np.abs(np.asarray(res.zs) - res.best_center[2])))
              if res.best_center is not None else -1)
    labels = [f'({x:.2f}, {y:.2f})' for x in res.xs for y in res.ys]
    pos = np.arange(len(labels))
    for k in range(nz):
        ax = axs[0, k]
        e = E[:, :, k, :].reshape(len(labels), -1)
        b = LB[:, :, k, :].reshape(len(labels), -1)
        planned = np.isfinite(e).any(axis=1)
        e_min = np.where(planned, np.nanmin(np.where(np.isfinite(e), e, np.inf), axis=1),
                         np.nan)
        b_min = np.where(np.isfinite(b).any(axis=1),
                         np.nanmin(np.where(np.isfinite(b), b, np.inf), axis=1), np.nan)
        ax.vlines(pos, b_min, e_min, color='grey', lw=1)
        ax.plot(pos, e_min, 'o', color='tab:blue', label='map: optimal timing (coarse grid)')
        ax.plot(pos, b_min, 'v', color='tab:green', label='convex bound: no timing below')
        ax.plot(pos[~planned], np.full((~planned).sum(), lo), 'x', color='red', ms=10,
                mew=2, label='refused (unreachable): no claim', clip_on=False)
        ax.axhline(reference, color='k', ls='--', lw=1,
                   label=f'trapezoid, reference placement {reference:.2f} J')
        ax.axhline(goal, color='tab:red', ls='-', lw=1.2,
                   label=f'{goal_pct:g} % saving: {goal:.2f} J')
        for p, v in zip(pos, b_min):
            if np.isfinite(v) and v < reference:
                ax.annotate(f'{v:.1f}', (p, v), xytext=(0, -11), textcoords='offset points',
                            ha='center', fontsize=6, color='tab:green')
        for s in res.starts:
            if s.get('end_center') is not None and (
                    int(np.argmin(np.abs(res.zs - s['end_center'][2]))) == k):
                ax.plot(_column(res, s['end_center']), s['end_energy'], 'D', ms=5, mfc='none',
                        color='tab:orange', label='multi-start ends (full grid)'
                        if s is res.starts[0] else None)
        if k == k_best:
            ax.plot(_column(res, res.best_center), res.best_energy, '*', color='orange', ms=16,
                    label=f'best {res.best_energy:.2f} J at '
                          f'{np.round(res.best_center, 3).tolist()} m'
                          + (f', bound {res.best_lower_bound:.2f} J'
                             if np.isfinite(res.best_lower_bound) else ''))
        ax.set_xticks(pos, labels, rotation=60, fontsize=7)
        ax.set_xlabel('centre (x, y) [m]')
        ax.set_title(f'z = {res.zs[k]:.2f} m')
        ax.set_ylim(lo, hi)
        ax.set_yscale('log')
        ax.grid(alpha=0.3)
        if k in (0, k_best):
            ax.legend(fontsize=6, loc='upper left')
    axs[0, 0].set_ylabel(f'{res.measure} energy [J]')
    fig.suptitle(title or f'{res.measure} energy and convex lower bounds over the region')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _column(res: PlacementResult, center) -> float:
    """Position of ``center`` on plot_bounds' axis of (x, y) grid columns: the nearest x
    column, the y between its columns (centres off the grid sit between them)."""
    ib = int(np.argmin(np.abs(res.xs - center[0])))
    jf = (float(np.interp(center[1], res.ys, np.arange(res.ys.size)))
          if res.ys.size > 1 else 0.0)
    return ib * res.ys.size + jf


def plot_map(path: str, res: PlacementResult, title: str = '') -> str:
    """PNG of the energy map: one panel per z level, x right, y up, the energy at each centre
    the lowest over the orientations (rotations x tilts); centres refused in every
    orientation drawn as red crosses, in some of them as small orange crosses, the best
    placement as a star."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    nz = res.zs.size
    fig, axs = plt.subplots(1, nz, figsize=(4.2 * nz, 3.8), squeeze=False)
    vmin, vmax = np.nanmin(res.energy), np.nanmax(res.energy)
    # the star on the one panel nearest the best centre's height (refinement moves it off
    # the grid's levels; 'within half a spacing' put it on two panels or on none)
    k_best = (int(np.argmin(np.abs(np.asarray(res.zs) - res.best_center[2])))
              if res.best_center is not None else -1)
    for k in range(nz):
        ax = axs[0, k]
        refused = np.isnan(res.energy[:, :, k, :])
        e = np.where(refused.all(axis=-1), np.nan, np.nanmin(
            np.where(refused, np.inf, res.energy[:, :, k, :]), axis=-1))
        X, Y = np.meshgrid(res.xs, res.ys, indexing='ij')
        sc = ax.scatter(X.ravel(), Y.ravel(), c=e.ravel(), s=260, marker='s', vmin=vmin,
                        vmax=vmax, cmap='viridis')
        bad = np.isnan(e)
        ax.scatter(X[bad], Y[bad], marker='x', color='red', s=80, label='refused')
        some = refused.any(axis=-1) & ~bad
        if np.any(some):
            ax.scatter(X[some], Y[some], marker='x', color='orange', s=30,
                       label='refused in some orientations')
        for (x, y, v) in zip(X.ravel(), Y.ravel(), e.ravel()):
            if np.isfinite(v):
                ax.annotate(f'{v:.0f}', (x, y), ha='center', va='center', fontsize=7,
                            color='white')
        if res.best_center is not None and k == k_best:
            ax.plot(res.best_center[0], res.best_center[1], '*', color='orange', ms=16,
                    label=f'best {res.best_energy:.1f} J at z = {res.best_center[2]:.3f} m')
        ax.set_title(f'z = {res.zs[k]:.2f} m')
        ax.set_xlabel('centre x [m]')
        ax.set_ylabel('centre y [m]')
        ax.legend(fontsize=7, loc='lower right')
    fig.colorbar(sc, ax=axs[0, :].tolist(), label=f'{res.measure} energy [J]')
    m = res.energy.shape[3]
    fig.suptitle(title or f'{res.measure} energy of the optimal timing over the region'
                 + (f' (lowest of {m} orientations)' if m > 1 else ''))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
