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

Bounds (``search(bounds=True)``): the map's energies are local optima of a nonconvex NLP; the
planner's convex relaxation (``Planner.bound``, baselines.EnergyBound) gives at each planned
map point a lower bound on every timing of that placement (on the same theta grid), and one at
the best placement on the full grid. Their lowest value over the map is what no timing at any
planned point can beat: a sound statement at the points, up to the theta discretisation, and
none between them (the bounds are as steep as the energies, and the Lipschitz argument above
would need a spacing of millimetres).
"""
from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
from irb_description.path import plane_axes

from .request import PlanError, PlanRequest

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


def plan_energy(result, energy_model: str) -> float:
    """The energy a placement is judged by: of the independently checked trajectory."""
    ver = result.verification
    if energy_model in ('', 'mechanical'):
        return float(ver.energy)
    return float(ver.electrical['total_' + energy_model.split('_', 1)[1]])


def search(planner, task: PlanRequest, region: Region, n: tuple = (3, 3, 3),
           coarse_grid: int = 40, refine: int = 2, min_step: float = 0.01,
           progress: Callable[[str], None] = print,
           min_tilt_step: float = np.radians(2.0), bounds: bool = False) -> PlacementResult:
    """Grid over the region, refine the best points (module docstring). ``task`` holds the
    radius, direction, duration, energy_model (its centre and start angle are replaced).
    ``bounds``: also the planner's convex lower bound (``Planner.bound``) at every planned
    map point and at the best placement (module docstring, "Bounds")."""
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
        req = replace(placement_request(task, center, *o), grid_size=grid,
                      objective='energy')
        try:
            return float(planner.bound(req, task.duration))
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
    best = (np.inf, None, None, None)
    for flat in order:
        idx = np.unravel_index(flat, E.shape)
        c = np.array([axes[d][idx[d]] for d in range(3)])
        try:
            e, res = run(c, orient[idx[3]], task.grid_size)
        except PlanError:
            continue
        progress(f'refine {np.round(c, 3).tolist()} {describe(orient[idx[3]])}: {e:.2f} J '
                 'on the full grid')
        if e < best[0]:
            best = (e, c, orient[idx[3]], res)
    if best[1] is None:
        return PlacementResult(axes[0], axes[1], axes[2], rots, E, reasons,
                               wall_time=time.perf_counter() - t0, **empty)
    e_best, c_best, o_best, res_best = best
    # compass search over (x, y, z, tilt_x, tilt_y) within the box and the tilt ranges
    z_best = np.concatenate([c_best, o_best[1:]])
    t_axes = [np.unique(region.tilt_x), np.unique(region.tilt_y)]
    z_lo = np.concatenate([lo, [a.min() for a in t_axes]])
    z_hi = np.concatenate([hi, [a.max() for a in t_axes]])
    spacing = [(a[1] - a[0]) if a.size > 1 else 0.0 for a in axes]
    spacing += [float(np.min(np.diff(a))) if a.size > 1 else 0.0 for a in t_axes]
    step = 0.5 * np.array(spacing)
    floor = np.array([min_step] * 3 + [min_tilt_step] * 2)
    while np.any(step >= floor):
        improved = False
        for d in range(5):
            if step[d] < floor[d]:
                continue
            for sgn in (1, -1):
                z = z_best.copy()
                z[d] = np.clip(z[d] + sgn * step[d], z_lo[d], z_hi[d])
                if np.allclose(z, z_best):
                    continue
                o = np.array([o_best[0], z[3], z[4]])
                try:
                    e, res = run(z[:3], o, task.grid_size)
                except PlanError:
                    continue
                if e < e_best:
                    e_best, z_best, o_best, res_best, improved = e, z, o, res, True
                    progress(f'compass: {np.round(z[:3], 3).tolist()} {describe(o)} '
                             f'{e:.2f} J')
                    break
        if not improved:
            step = step / 2
    c_best = z_best[:3]
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
    progress(f'best {np.round(c_best, 3).tolist()} {describe(o_best)}: '
             f'{e_best:.2f} J; lower bound over {covered}/{cells} fully reachable cells '
             f'(grid + Lipschitz) {bound:.2f} J, possible improvement there <= {gap:.2f} %; '
             f'{evals} plans, {time.perf_counter() - t0:.0f} s')
    return PlacementResult(axes[0], axes[1], axes[2], rots, E, reasons, c_best,
                           float(o_best[0]), float(e_best), res_best, float(bound), float(gap),
                           lip, cells_covered=covered, cells_total=cells, evaluations=evals,
                           wall_time=time.perf_counter() - t0, measure=model, tilts=tilts,
                           best_tilt=np.array(o_best[1:], float), **extra)


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
