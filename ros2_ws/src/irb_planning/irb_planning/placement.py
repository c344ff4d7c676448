"""Task placement: where to put a circle task so that its optimal timing costs least (no ROS).

A task is the circle's radius, direction and duration plus where it may go: a box for its
centre and a range of rotations about the vertical axis (for a horizontal circle a rotation
is a change of the start angle). Tilting the circle's plane is not offered: the planner's
path API (PlanRequest / CirclePath) has horizontal circles only.

Search (``search``): every point of a regular grid over the box x rotations is planned with
the planner's public API (``Planner.plan(PlanRequest)``, energy objective, the requested
energy model) on a coarse theta grid; points the planner refuses (unreachable, too short for
the limits, solver failure) are kept in the map with their reason, never dropped. The best
``refine`` grid points are then re-planned on the full theta grid, and around the best one a
compass search (steps halved down to ``min_step`` [m]) refines the centre.

Evidence (``certificate``): on the coarse map, with L_d the largest finite difference
|dE/dx_d| between neighbouring reachable grid points along axis d, no point of a grid cell
whose corners are reachable can be below min(corners) - sum_d L_d h_d / 2; the certificate
reports the lowest such value over all such cells against the refined best, i.e. the largest
possible improvement the grid leaves, and how many cells it covers: a cell with a refused
corner is not covered (nothing is claimed there; with none covered the bound is NaN). L_d is
measured on the grid, not proven: a function that varies faster between grid points than
between them and their neighbours escapes it. The map is planned on the coarse theta grid,
the best on the full one; their discretisations differ (0.2 % at the thesis circle).
"""
from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from .request import PlanError, PlanRequest


@dataclass(frozen=True)
class Region:
    """Box for the centre: lo, hi (3,) [m]; rotations about z [rad] (start-angle offsets)."""

    lo: np.ndarray
    hi: np.ndarray
    rotations: tuple = (0.0,)

    def __post_init__(self):
        lo, hi = np.asarray(self.lo, float), np.asarray(self.hi, float)
        if lo.shape != (3,) or hi.shape != (3,) or np.any(hi < lo):
            raise ValueError(f'region: lo and hi must be 3 numbers with lo <= hi, got '
                             f'{lo.tolist()} {hi.tolist()}')


@dataclass
class PlacementResult:
    """The map (axes xs, ys, zs [m], rotations [rad]; energy [J] NaN where refused and
    reasons there), the best placement (centre, rotation, energy [J], its PlanResult),
    the certificate (lower bound over the region [J], possible improvement [%]),
    evaluations and wall time [s]."""

    xs: np.ndarray
    ys: np.ndarray
    zs: np.ndarray
    rotations: np.ndarray
    energy: np.ndarray                    # (nx, ny, nz, nr)
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


def plan_energy(result, energy_model: str) -> float:
    """The energy a placement is judged by: of the independently checked trajectory."""
    ver = result.verification
    if energy_model in ('', 'mechanical'):
        return float(ver.energy)
    return float(ver.electrical['total_' + energy_model.split('_', 1)[1]])


def search(planner, task: PlanRequest, region: Region, n: tuple = (3, 3, 3),
           coarse_grid: int = 40, refine: int = 2, min_step: float = 0.01,
           progress: Callable[[str], None] = print) -> PlacementResult:
    """Grid over the region, refine the best points (module docstring). ``task`` holds the
    radius, direction, duration, energy_model (its centre and start angle are replaced)."""
    t0 = time.perf_counter()
    lo, hi = np.asarray(region.lo, float), np.asarray(region.hi, float)
    axes = [np.linspace(lo[d], hi[d], n[d]) if hi[d] > lo[d] else np.array([lo[d]])
            for d in range(3)]
    rots = np.asarray(region.rotations, float)
    E = np.full((axes[0].size, axes[1].size, axes[2].size, rots.size), np.nan)
    reasons = {}
    model = task.energy_model or 'mechanical'
    total = E.size
    evals = 0

    def run(center, rot, grid):
        nonlocal evals
        evals += 1
        req = replace(task, center=np.asarray(center, float),
                      start_angle=float(task.start_angle) + float(rot), grid_size=grid,
                      objective='energy')
        res = planner.plan(req)
        return plan_energy(res, model), res

    for k, idx in enumerate(itertools.product(*[range(a.size) for a in axes],
                                              range(rots.size))):
        c = np.array([axes[d][idx[d]] for d in range(3)])
        try:
            E[idx], _ = run(c, rots[idx[3]], coarse_grid)
            msg = f'{E[idx]:.2f} J'
        except PlanError as exc:
            reasons[idx] = f'error {exc.code}: {exc.message[:80]}'
            msg = 'refused: ' + reasons[idx]
        progress(f'[{k + 1}/{total}] centre {np.round(c, 3).tolist()} rotation '
                 f'{np.degrees(rots[idx[3]]):.0f} deg: {msg} ({time.perf_counter() - t0:.0f} s)')
    if np.all(np.isnan(E)):
        return PlacementResult(axes[0], axes[1], axes[2], rots, E, reasons, evaluations=evals,
                               wall_time=time.perf_counter() - t0, measure=model)
    # --- refine: the best coarse points on the planner's full grid, then a compass search --
    order = np.argsort(np.where(np.isnan(E), np.inf, E), axis=None)[:max(refine, 1)]
    best = (np.inf, None, None, None)
    for flat in order:
        idx = np.unravel_index(flat, E.shape)
        c = np.array([axes[d][idx[d]] for d in range(3)])
        try:
            e, res = run(c, rots[idx[3]], task.grid_size)
        except PlanError:
            continue
        progress(f'refine {np.round(c, 3).tolist()}: {e:.2f} J on the full grid')
        if e < best[0]:
            best = (e, c, rots[idx[3]], res)
    if best[1] is None:
        return PlacementResult(axes[0], axes[1], axes[2], rots, E, reasons, evaluations=evals,
                               wall_time=time.perf_counter() - t0, measure=model)
    e_best, c_best, r_best, res_best = best
    step = 0.5 * np.array([(a[1] - a[0]) if a.size > 1 else 0.0 for a in axes])
    while np.any(step >= min_step):
        improved = False
        for d in range(3):
            if step[d] < min_step:
                continue
            for sgn in (1, -1):
                c = c_best.copy()
                c[d] = np.clip(c[d] + sgn * step[d], lo[d], hi[d])
                if np.allclose(c, c_best):
                    continue
                try:
                    e, res = run(c, r_best, task.grid_size)
                except PlanError:
                    continue
                if e < e_best:
                    e_best, c_best, res_best, improved = e, c, res, True
                    progress(f'compass: {np.round(c, 3).tolist()} {e:.2f} J')
                    break
        if not improved:
            step = step / 2
    bound, lip, covered, cells = certificate(axes, E)
    gap = 100 * (e_best - bound) / e_best
    progress(f'best {np.round(c_best, 3).tolist()} rotation {np.degrees(r_best):.0f} deg: '
             f'{e_best:.2f} J; lower bound over {covered}/{cells} fully reachable cells '
             f'(grid + Lipschitz) {bound:.2f} J, possible improvement there <= {gap:.2f} %; '
             f'{evals} plans, {time.perf_counter() - t0:.0f} s')
    return PlacementResult(axes[0], axes[1], axes[2], rots, E, reasons, c_best, float(r_best),
                           float(e_best), res_best, float(bound), float(gap), lip,
                           cells_covered=covered, cells_total=cells, evaluations=evals,
                           wall_time=time.perf_counter() - t0, measure=model)


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
    """PNG of the energy map: one panel per z level (first rotation), x right, y up;
    refused points drawn as red crosses, the best placement as a star."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    nz = res.zs.size
    fig, axs = plt.subplots(1, nz, figsize=(4.2 * nz, 3.8), squeeze=False)
    vmin, vmax = np.nanmin(res.energy), np.nanmax(res.energy)
    for k in range(nz):
        ax = axs[0, k]
        e = res.energy[:, :, k, 0]
        X, Y = np.meshgrid(res.xs, res.ys, indexing='ij')
        sc = ax.scatter(X.ravel(), Y.ravel(), c=e.ravel(), s=260, marker='s', vmin=vmin,
                        vmax=vmax, cmap='viridis')
        bad = np.isnan(e)
        ax.scatter(X[bad], Y[bad], marker='x', color='red', s=80, label='refused')
        for (x, y, v) in zip(X.ravel(), Y.ravel(), e.ravel()):
            if np.isfinite(v):
                ax.annotate(f'{v:.0f}', (x, y), ha='center', va='center', fontsize=7,
                            color='white')
        if res.best_center is not None and abs(res.best_center[2] - res.zs[k]) <= (
                0.5 * (res.zs[1] - res.zs[0]) if nz > 1 else np.inf):
            ax.plot(res.best_center[0], res.best_center[1], '*', color='orange', ms=16,
                    label=f'best {res.best_energy:.1f} J')
        ax.set_title(f'z = {res.zs[k]:.2f} m')
        ax.set_xlabel('centre x [m]')
        ax.set_ylabel('centre y [m]')
        ax.legend(fontsize=7, loc='lower right')
    fig.colorbar(sc, ax=axs[0, :].tolist(), label=f'{res.measure} energy [J]')
    fig.suptitle(title or f'{res.measure} energy of the optimal timing over the region')
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
