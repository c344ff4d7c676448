"""Work-cycle planner: motion durations and power modes of the waits within a takt (issue 29).

A cycle is an ordered list of operations, repeated every ``takt_s``:

    motion   a path of any type (irb_description.path spec, optional ``process`` block), planned
             by ``Planner`` at several durations: its energy-duration front on the electrical
             model (energy of the trajectory as played, standby and drive idle included);
    fixed    a step of fixed duration with the robot at rest (e.g. a 6 s part exchange);
    wait     a step of free duration >= 0 with the robot at rest: it takes the takt's slack.

Consecutive rest steps (cyclically: the last and the first too) form one *station*, spent in
one power mode (``irb_description.power_modes``) entered from and left to ``hold`` inside the
station, at the hold power of its pose (electrical model at rest with the gravity torque of
the preceding motion's end). A station may use a mode only if the mode is allowed by all its
steps and its transitions fit in the station's duration.

The choice (one front point per motion, the slack of each station, each station's mode) that
minimises the electrical energy per cycle with the cycle lasting exactly the takt is solved
exactly on a time grid of ``time_step_s`` by dynamic programming (a resource-constrained
shortest path: items in sequence, state = grid steps used; ``solve``). The certificate is its
gap to a continuous lower bound (``lower_bound``): each motion's energy replaced by the lower
convex hull of its front points, each station's by the lower convex hull of its energy over
all durations (min over modes, transitions included), time continuous; a separable convex
resource allocation solved exactly by taking the hull segments in order of slope. Every
discrete solution is feasible there with an energy no lower, so gap >= 0 (tested, and against
brute force on small instances). What the bound does not cover: the energy of a motion between
its planned durations (the planner's own optimum is not a convex function of the duration
in general); the front points are the planner's checked plans.

No ROS here: ``Planner`` in, dataclasses and dicts out; ``cycle_cli.py`` is the command line.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from irb_description.params import yaml_problem
from irb_description.power_modes import HOLD, MODES, PowerModes
from irb_description.trajectory_rules import (GATE_MAX_ACCELERATION_RAD_S2, GATE_TORQUE_FRACTION,
                                              gate_limit_notes)

OP_MOTION, OP_FIXED, OP_WAIT = 'motion', 'fixed', 'wait'
OP_KINDS = (OP_MOTION, OP_FIXED, OP_WAIT)
CACHE_VERSION = 1
#: re-plans of a front point at tighter limits when pdplus's plan gate would refuse it
GATE_RETRIES = 3
#: the warm solver's iteration cap for the fronts (PlannerSettings.warm_max_iterations): a
#: front point warm-started from its neighbour 10-25 % shorter took 20-100 iterations where a
#: cold solve took 40-110; at the planner's default cap of 40 most such warm solves stopped
#: unfinished and were repeated cold (both paid)
FRONT_WARM_ITERATIONS = 150
#: how far apart (relative) front points may be for a warm start (PlannerSettings.warm_window;
#: the planner's default 0.2): cycle_ten's neighbours on the 0.05 s grid are 10-25 % apart,
#: and a warm start 21-25 % away took 34-59 iterations where the cold solve took 47-99
FRONT_WARM_WINDOW = 0.3
#: IPOPT's initial barrier for a re-solve after the check tightened a bound (the gluing
#: rectangle's band by <= 0.3 %; PlannerSettings.resolve_mu_init): 15-18 iterations instead
#: of 28-45 at the warm solver's 1e-4, the same energies
FRONT_RESOLVE_MU_INIT = 1e-6
#: MUMPS's permuting scaling (IPOPT's mumps_permuting_scaling, ICNTL(6); PlannerSettings.
#: mumps_permuting_scaling) for the fronts: 0 = none. IPOPT's default 7 (automatic) spent
#: about half of every iteration on it for these KKT systems (N = 100, ~1400 variables,
#: ~4300 rows): cycle_ten's 41 solves took 2266 iterations at 31 ms, 0 made them 1807
#: iterations at 15 ms (one process under load; benchmarks/RESULTS.md, cyc30) with the same
#: front energies (test_cycle_fronts.py compares them with IPOPT's default)
FRONT_MUMPS_PERMUTING_SCALING = 0


class CycleError(ValueError):
    """A cycle that cannot be read or planned; the message is one line."""


# --- the cycle as read ----------------------------------------------------------------------
@dataclass(frozen=True)
class Operation:
    """One operation: kind (OP_KINDS), name; motion: path spec (without ``process``),
    process constraints {field: value}, explicit front durations [s] or (), longest front
    duration [s] (0 = front_span x the shortest); fixed: duration [s]; fixed/wait: modes."""

    kind: str
    name: str
    path: dict = field(default_factory=dict)
    process: dict = field(default_factory=dict)
    durations_s: tuple = ()
    max_duration_s: float = 0.0
    duration_s: float = 0.0
    modes: tuple = MODES


@dataclass(frozen=True)
class CycleSpec:
    """A cycle file: takt [s], operations, DP time step [s], front points per motion, longest
    / shortest front duration, planner grid (0 = default), energy model ('' = electrical on
    the planner's bus mode), friction map, power-modes YAML ('' = irb_description's)."""

    takt_s: float
    operations: tuple
    time_step_s: float = 0.05
    front_points: int = 6
    front_span: float = 2.5
    grid_size: int = 0
    energy_model: str = ''
    friction_map: str = ''
    power_modes: str = ''
    source: str = ''
    limit_scaling: float = 0.0     # fraction of the torque/speed limits the plans use (0 = 1)

    @property
    def motions(self) -> list:
        return [op for op in self.operations if op.kind == OP_MOTION]


def _err(where: str, msg: str) -> CycleError:
    return CycleError(f'{where}: {msg}')


def _number(d: dict, key: str, where: str, default=None, positive=False, minimum=None):
    if key not in d or d[key] is None:
        if default is None:
            raise _err(where, f'missing `{key}`')
        return default
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise _err(where, f'`{key}` must be a finite number, got {v!r}')
    if positive and not v > 0:
        raise _err(where, f'`{key}` must be > 0, got {v!r}')
    if minimum is not None and v < minimum:
        raise _err(where, f'`{key}` must be >= {minimum}, got {v!r}')
    return float(v)


def _modes(d: dict, where: str) -> tuple:
    m = d.get('modes', list(MODES))
    if isinstance(m, str):
        m = [m]
    if not isinstance(m, list) or not m or any(x not in MODES for x in m):
        raise _err(where, f'`modes` must be a non-empty list of {list(MODES)}, got {m!r}')
    return tuple(x for x in MODES if x in m)


def parse_cycle(data, source: str = 'cycle', base_dir: Path | None = None) -> CycleSpec:
    """A ``CycleSpec`` from the mapping of a cycle YAML; CycleError (one line) otherwise."""
    from irb_description.path import PROCESS_KEY, path_from_spec, process_from_spec
    if not isinstance(data, dict):
        raise _err(source, 'the file must hold a mapping with `takt_s` and `operations`')
    known = {'takt_s', 'operations', 'time_step_s', 'front_points', 'front_span', 'grid_size',
             'energy_model', 'friction_map', 'power_modes', 'description', 'duty',
             'limit_scaling'}
    extra = set(data) - known
    if extra:
        raise _err(source, f'unknown keys {sorted(extra)}; known: {sorted(known)}')
    takt = _number(data, 'takt_s', source, positive=True)
    step = _number(data, 'time_step_s', source, 0.05, positive=True)
    if takt / step > 200000:
        raise _err(source, f'takt_s / time_step_s = {takt / step:.0f} grid steps (at most '
                   '200000): take a coarser time_step_s')
    points = _number(data, 'front_points', source, 6.0, minimum=1)
    span = _number(data, 'front_span', source, 2.5, minimum=1.0)
    grid = _number(data, 'grid_size', source, 0.0, minimum=0)
    ops_raw = data.get('operations')
    if not isinstance(ops_raw, list) or not ops_raw:
        raise _err(source, '`operations` must be a non-empty list')
    ops, names = [], set()
    for i, raw in enumerate(ops_raw):
        where = f'{source}: operations[{i}]'
        if not isinstance(raw, dict):
            raise _err(where, 'must be a mapping with one of `motion`, `fixed`, `wait`')
        kinds = [k for k in OP_KINDS if k in raw]
        if len(kinds) != 1:
            raise _err(where, f'needs exactly one of {list(OP_KINDS)} (its name), got '
                       f'{sorted(raw)}')
        kind = kinds[0]
        name = str(raw[kind])
        where = f'{source}: operations[{i}] ({name})'
        if name in names:
            raise _err(where, 'operation names must be unique')
        names.add(name)
        allowed = {OP_MOTION: {'path', 'path_file', 'durations_s', 'max_duration_s'},
                   OP_FIXED: {'duration_s', 'modes'}, OP_WAIT: {'modes'}}[kind] | {kind}
        extra = set(raw) - allowed
        if extra:
            raise _err(where, f'a {kind} takes {sorted(allowed - {kind})}, not {sorted(extra)}')
        if kind == OP_MOTION:
            if ('path' in raw) == ('path_file' in raw):
                raise _err(where, 'a motion needs one of `path` (a path mapping) or '
                           '`path_file`')
            spec = raw.get('path')
            if 'path_file' in raw:
                f = Path(str(raw['path_file']))
                if not f.is_absolute() and base_dir is not None:
                    f = base_dir / f
                try:
                    spec = yaml.safe_load(f.read_text())
                except OSError as exc:
                    raise _err(where, f'cannot read path_file {f}: {exc.strerror}') from None
                except yaml.YAMLError as exc:
                    raise _err(where, f'path_file {f} is not YAML: '
                               f'{yaml_problem(exc)}') from None
            try:
                path_from_spec(spec)
                process = process_from_spec(spec)
            except ValueError as exc:
                raise _err(where, str(exc)) from None
            geometry = {k: v for k, v in spec.items() if k != PROCESS_KEY}
            durs = raw.get('durations_s', [])
            if not isinstance(durs, list) or any(
                    isinstance(x, bool) or not isinstance(x, (int, float)) or not x > 0
                    for x in durs):
                raise _err(where, '`durations_s` must be a list of durations > 0 [s]')
            ops.append(Operation(OP_MOTION, name, geometry, process,
                                 tuple(float(x) for x in durs),
                                 _number(raw, 'max_duration_s', where, 0.0, minimum=0)))
        elif kind == OP_FIXED:
            ops.append(Operation(OP_FIXED, name,
                                 duration_s=_number(raw, 'duration_s', where, minimum=0),
                                 modes=_modes(raw, where)))
        else:
            ops.append(Operation(OP_WAIT, name, modes=_modes(raw, where)))
    model = str(data.get('energy_model', '') or '')
    if model and not model.startswith('electrical_'):
        raise _err(source, f'energy_model must be electrical_<bus> (none, shared, '
                   f'regenerative) or empty, got {model!r}')
    scaling = _number(data, 'limit_scaling', source, 0.0, minimum=0)
    if scaling > 1:
        raise _err(source, f'`limit_scaling` must be in (0, 1] (0 = 1), got {scaling}')
    return CycleSpec(takt_s=takt, operations=tuple(ops), time_step_s=step,
                     limit_scaling=scaling,
                     front_points=int(points), front_span=span, grid_size=int(grid),
                     energy_model=model, friction_map=str(data.get('friction_map', '') or ''),
                     power_modes=str(data.get('power_modes', '') or ''), source=source)


def load_cycle(path) -> CycleSpec:
    """Read a cycle YAML file; CycleError with one line if it cannot be used."""
    p = Path(path)
    try:
        text = p.read_text(encoding='utf-8')
    except OSError as exc:
        raise CycleError(f'cannot read cycle file {p}: {exc.strerror}') from None
    except UnicodeDecodeError:
        raise CycleError(f'cycle file {p} is not UTF-8 text') from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise CycleError(f'cycle file {p} is not YAML: {yaml_problem(exc)}') from None
    return parse_cycle(data, str(p), p.parent)


# --- the DP problem ---------------------------------------------------------------------
@dataclass(frozen=True)
class MotionItem:
    """A motion's front: durations [s] (multiples of the time step), energies [J]."""

    name: str
    durations: tuple
    energies: tuple


@dataclass(frozen=True)
class StationItem:
    """A station (rest steps merged): fixed part [s], whether it takes slack (a wait step in
    it), allowed modes, hold power at its pose [W], member step names."""

    name: str
    fixed_s: float
    wait: bool
    modes: tuple
    holding_power_w: float
    members: tuple = ()


def station_energy(st: StationItem, duration_s: float, pm: PowerModes) -> tuple[str, float]:
    """(mode, energy [J]) of the cheapest allowed, feasible mode for a station lasting
    ``duration_s``; (None, inf) if none fits."""
    best = (None, math.inf)
    for m in st.modes:
        if pm.feasible(m, duration_s):
            e = pm.wait_energy_j(m, duration_s, st.holding_power_w)
            if e < best[1]:
                best = (m, e)
    return best


@dataclass
class Solution:
    """The optimum of the discretised problem and its certificate. ``choices``: one dict per
    item (motion: duration_s, energy_j, index; station: duration_s, mode, energy_j);
    total_j; lower_bound_j (continuous relaxation) and gap_j = total_j - lower_bound_j >= 0;
    the relaxation's own durations per item."""

    total_j: float
    choices: list
    lower_bound_j: float
    relaxed_durations: list
    takt_s: float
    step_s: float
    solve_time_s: float = 0.0

    @property
    def gap_j(self) -> float:
        return float(self.total_j - self.lower_bound_j)

    @property
    def gap_rel(self) -> float:
        return float(self.gap_j / self.total_j) if self.total_j else 0.0


def _grid_steps(d: float, step: float, what: str) -> int:
    n = int(round(d / step))
    if abs(n * step - d) > 1e-9 * max(1.0, d):
        raise CycleError(f'{what}: duration {d:g} s is not a multiple of the time step '
                         f'{step:g} s')
    return n


def solve(items: list, takt_s: float, step_s: float, pm: PowerModes) -> Solution:
    """Exact DP over (front points x station slack on the time grid x modes); raises
    CycleError if no choice fits the takt."""
    t0 = time.perf_counter()
    fixed = sum(it.fixed_s for it in items if isinstance(it, StationItem))
    budget = takt_s - fixed
    n_tot = int(math.floor(budget / step_s + 1e-9))
    fastest = sum(min(it.durations) for it in items if isinstance(it, MotionItem))
    if n_tot < 0 or fastest > budget + 1e-9:
        raise CycleError(f'the motions at their fastest ({fastest:.3f} s) and the fixed steps '
                         f'({fixed:.3f} s) take longer than the takt {takt_s:g} s')
    resid = budget - n_tot * step_s
    waits = [i for i, it in enumerate(items) if isinstance(it, StationItem) and it.wait]
    if not waits:
        raise CycleError('the cycle has no wait station to take the slack')
    first_wait = waits[0]
    cost = np.full(n_tot + 1, np.inf)
    cost[0] = 0.0
    back = []
    tables = []
    for i, it in enumerate(items):
        new = np.full(n_tot + 1, np.inf)
        arg = np.full(n_tot + 1, -1, dtype=int)
        if isinstance(it, MotionItem):
            for j, (d, e) in enumerate(zip(it.durations, it.energies)):
                n = _grid_steps(d, step_s, it.name)
                if n > n_tot:
                    continue
                cand = np.full(n_tot + 1, np.inf)
                cand[n:] = cost[:n_tot + 1 - n] + e
                better = cand < new
                new[better], arg[better] = cand[better], j
            tables.append(None)
        else:
            extra = resid if i == first_wait else 0.0
            ns = range(n_tot + 1) if it.wait else range(1)
            table = [station_energy(it, it.fixed_s + n * step_s + extra, pm) for n in ns]
            tables.append(table)
            for n, (_, e) in zip(ns, table):
                if not math.isfinite(e):
                    continue
                cand = np.full(n_tot + 1, np.inf)
                cand[n:] = cost[:n_tot + 1 - n] + e
                better = cand < new
                new[better], arg[better] = cand[better], n
        cost = new
        back.append(arg)
    if not math.isfinite(cost[n_tot]):
        raise CycleError(f'no choice of durations and modes fills the takt {takt_s:g} s '
                         '(a station allows no mode that fits its duration)')
    choices = [None] * len(items)
    t = n_tot
    for i in range(len(items) - 1, -1, -1):
        it, a = items[i], int(back[i][t])
        if isinstance(it, MotionItem):
            n = _grid_steps(it.durations[a], step_s, it.name)
            choices[i] = {'kind': 'motion', 'name': it.name, 'index': a,
                          'duration_s': float(it.durations[a]),
                          'energy_j': float(it.energies[a])}
        else:
            n = a
            extra = resid if i == first_wait else 0.0
            mode, e = tables[i][n]
            choices[i] = {'kind': 'station', 'name': it.name, 'mode': mode,
                          'duration_s': float(it.fixed_s + n * step_s + extra),
                          'slack_s': float(n * step_s + extra), 'energy_j': float(e),
                          'holding_power_w': float(it.holding_power_w),
                          'members': list(it.members)}
        t -= n
    lb, relaxed = lower_bound(items, takt_s, pm)
    return Solution(float(cost[n_tot]), choices, lb, relaxed, float(takt_s), float(step_s),
                    time.perf_counter() - t0)


# --- the continuous lower bound -----------------------------------------------------------
def lower_hull(x, y) -> tuple[np.ndarray, np.ndarray]:
    """Lower convex hull (monotone chain) of points (x, y); x sorted, duplicates: lowest y."""
    order = np.lexsort((np.asarray(y, float), np.asarray(x, float)))
    pts = []
    for k in order:
        p = (float(x[k]), float(y[k]))
        if pts and abs(pts[-1][0] - p[0]) <= 1e-12:
            continue                       # same x: the first (lowest y) stays
        while len(pts) >= 2:
            (x1, y1), (x2, y2) = pts[-2], pts[-1]
            if (x2 - x1) * (p[1] - y1) - (y2 - y1) * (p[0] - x1) <= 0:
                pts.pop()                  # the middle point is on or above the chord
            else:
                break
        pts.append(p)
    a = np.array(pts)
    return a[:, 0], a[:, 1]


def station_hull(st: StationItem, lo: float, hi: float, pm: PowerModes):
    """Points of the lower convex hull of the station energy over durations [lo, hi]: the
    energy is the min of affine functions (one per mode, each from its shortest wait on),
    concave between the modes' shortest waits, so the hull of its values there and at the
    ends lies below it."""
    xs = [lo, hi] + [pm.min_wait_s(m) for m in st.modes if lo < pm.min_wait_s(m) < hi]
    xs = sorted(set(xs))
    ys = [station_energy(st, x, pm)[1] for x in xs]
    ok = [k for k, y in enumerate(ys) if math.isfinite(y)]
    if not ok:
        return None
    return lower_hull(np.array(xs)[ok], np.array(ys)[ok])


def lower_bound(items: list, takt_s: float, pm: PowerModes) -> tuple[float, list]:
    """Continuous relaxation: min sum of hulls s.t. the durations add up to the takt
    (exact for separable convex piecewise-linear functions: start every item at its shortest
    duration and hand out the remaining time to the hull segments by increasing slope).
    Returns (bound [J], durations per item); (inf, []) if nothing fits."""
    fixed = sum(it.fixed_s for it in items if isinstance(it, StationItem))
    budget = takt_s - fixed
    hulls = []
    for it in items:
        if isinstance(it, MotionItem):
            hulls.append(lower_hull(np.array(it.durations), np.array(it.energies)))
        elif it.wait:
            h = station_hull(it, it.fixed_s, it.fixed_s + max(budget, 0.0), pm)
            if h is None:
                return math.inf, []
            hulls.append(h)
        else:
            _, e = station_energy(it, it.fixed_s, pm)
            if not math.isfinite(e):
                return math.inf, []
            hulls.append((np.array([it.fixed_s]), np.array([e])))
    x = [float(h[0][0]) for h in hulls]
    total = sum(float(h[1][0]) for h in hulls)
    remaining = takt_s - sum(x)
    if remaining < -1e-9:
        return math.inf, []
    segs = []
    for k, (hx, hy) in enumerate(hulls):
        for a in range(len(hx) - 1):
            dx = hx[a + 1] - hx[a]
            segs.append(((hy[a + 1] - hy[a]) / dx, k, dx))
    segs.sort()
    for slope, k, dx in segs:
        if remaining <= 1e-12:
            break
        take = min(dx, remaining)
        x[k] += take
        total += slope * take
        remaining -= take
    if remaining > 1e-6:
        return math.inf, []
    return float(total), x


def brute_force(items: list, takt_s: float, step_s: float, pm: PowerModes) -> float:
    """The discrete optimum by enumeration (tests only: exponential)."""
    import itertools
    fixed = sum(it.fixed_s for it in items if isinstance(it, StationItem))
    n_tot = int(math.floor((takt_s - fixed) / step_s + 1e-9))
    resid = takt_s - fixed - n_tot * step_s
    waits = [i for i, it in enumerate(items) if isinstance(it, StationItem) and it.wait]
    ranges = []
    for i, it in enumerate(items):
        if isinstance(it, MotionItem):
            ranges.append(range(len(it.durations)))
        else:
            ranges.append(range(n_tot + 1) if it.wait else range(1))
    memo = {}

    def st_energy(i, it, c):
        if (i, c) not in memo:
            extra = resid if waits and i == waits[0] else 0.0
            memo[(i, c)] = station_energy(it, it.fixed_s + c * step_s + extra, pm)[1]
        return memo[(i, c)]
    best = math.inf
    for combo in itertools.product(*ranges):
        used, e = 0, 0.0
        for i, (it, c) in enumerate(zip(items, combo)):
            if isinstance(it, MotionItem):
                used += _grid_steps(it.durations[c], step_s, it.name)
                e += it.energies[c]
            else:
                used += c
                e += st_energy(i, it, c)
        if used == n_tot and e < best:
            best = e
    return best


# --- stations from operations ------------------------------------------------------------
def stations_and_motions(spec: CycleSpec, holding: dict) -> list:
    """The DP items of a cycle, in order: motions (placeholders, the fronts come later) and
    stations (rest steps merged, cyclically). ``holding``: {motion name: hold power [W] at
    its end}; a station's pose is that of the motion before it (cyclically). A cycle without
    a wait step gets one at its end (name 'idle'). Returns a list of Operation (motions) and
    StationItem."""
    ops = list(spec.operations)
    if not any(op.kind == OP_WAIT for op in ops):
        ops.append(Operation(OP_WAIT, 'idle'))
    # rotate so that the list starts with a motion (stations then never wrap around)
    k0 = next((k for k, op in enumerate(ops) if op.kind == OP_MOTION), None)
    if k0 is None:
        raise CycleError(f'{spec.source}: the cycle has no motion')
    ops = ops[k0:] + ops[:k0]
    items, group, last_motion = [], [], None

    def close():
        if not group:
            return
        modes = tuple(m for m in MODES if all(m in op.modes for op in group))
        if not modes:
            raise CycleError(f'{spec.source}: the rest steps {[op.name for op in group]} '
                             'allow no common power mode')
        items.append(StationItem('+'.join(op.name for op in group),
                                 sum(op.duration_s for op in group if op.kind == OP_FIXED),
                                 any(op.kind == OP_WAIT for op in group), modes,
                                 float(holding[last_motion]), tuple(op.name for op in group)))
        group.clear()
    for op in ops:
        if op.kind == OP_MOTION:
            close()
            items.append(op)
            last_motion = op.name
        else:
            group.append(op)
    close()
    return items


# --- fronts from the planner ---------------------------------------------------------------
def plan_request(op: Operation, duration: float, objective: str, energy_model: str,
                 grid: int, friction_map: str, limit_scaling: float = 0.0):
    """The PlanRequest of a motion (any path type, its process constraints)."""
    from .request import PlanRequest
    s = op.path
    t = s.get('type', 'circle') or 'circle'
    kw = dict(objective=objective, duration=float(duration), energy_model=energy_model,
              grid_size=int(grid), friction_map=friction_map, path_type=t,
              limit_scaling=float(limit_scaling),
              **{k: float(v) for k, v in op.process.items()})
    if t == 'circle':
        kw.update(center=np.asarray(s['center'], float), radius=float(s['radius']),
                  start_angle=float(s.get('start_angle', 0.0)),
                  direction=int(s.get('direction', 1)))
    elif t == 'arc':
        kw.update(center=np.asarray(s['center'], float), normal=np.asarray(s['normal'], float),
                  radius=float(s['radius']), start_angle=float(s.get('start_angle', 0.0)),
                  sweep=float(s.get('sweep', 0.0)))
    else:
        kw.update(waypoints=np.asarray(s['waypoints'], float),
                  blend_radii=np.atleast_1d(np.asarray(s.get('blend_radii', [0.0]), float)),
                  closed=bool(s.get('closed', False)))
    return PlanRequest(**kw)


def gate_check(model, traj: dict) -> tuple[list, float]:
    """pdplus's plan-gate rules on a plan's message points (irb_description.trajectory_rules:
    |qdd| <= GATE_MAX_ACCELERATION_RAD_S2, feed-forward torque <= GATE_TORQUE_FRACTION of
    the model's torque limits), the feed-forward computed as the gate does: the model's
    inverse dynamics plus its nominal friction (pdplus's default compensation) at q, qd,
    qdd. (one line per broken rule, factor < 1 on the limit scaling that should clear them;
    1.0 when none is broken)."""
    q, qd, qdd = (np.asarray(traj[k], float) for k in ('q', 'qd', 'qdd'))
    tau = model.inverse_dynamics_batch(q, qd, qdd) + model.friction.torque(qd)
    lim = np.asarray(model.limits.torque, float)
    notes = gate_limit_notes(qdd, tau, lim, GATE_MAX_ACCELERATION_RAD_S2, GATE_TORQUE_FRACTION)
    if not notes:
        return [], 1.0
    share = float(np.max(np.abs(tau) / lim[None, :]))
    acc = float(np.max(np.abs(qdd)))
    factor = min(1.0, GATE_TORQUE_FRACTION / share, GATE_MAX_ACCELERATION_RAD_S2 / acc)
    return notes, 0.98 * factor


def _point_record(result, bus: str, electrical) -> dict:
    ver = result.verification
    tr = result.trajectory
    t = np.asarray(ver.t)
    p = np.asarray(electrical.power(ver.tau, ver.qd))
    idx = np.unique(np.linspace(0, t.size - 1, min(t.size, 400)).round().astype(int))
    return {'duration_s': float(ver.duration), 'energy_j': float(ver.electrical[f'total_{bus}']),
            'mechanical_j': float(ver.energy), 'min_duration_s': float(result.min_duration),
            'q_start': np.asarray(tr['q'][0], float).tolist(),
            'q_end': np.asarray(tr['q'][-1], float).tolist(),
            'limit_scaling': float(result.request.limit_scaling or 1.0),
            'power_t': t[idx].tolist(), 'power_w': p[idx].tolist(),
            'trajectory': {k: np.asarray(tr[k], float).tolist()
                           for k in ('t', 'theta', 'q', 'qd', 'qdd', 'tau') if k in tr}}


@dataclass
class Front:
    """A motion's energy-duration front: points {duration: record}, the time-optimal plan
    ('fastest', baseline A), durations refused (with the reason), CPU time [s] its process
    spent on it in this call (planning; ~0 from the cache), the id of that process and its
    CPU time [s] since it started, at the front's end (imports and planner included: the
    largest per process is what that process cost)."""

    name: str
    fastest: dict
    points: dict
    refused: dict = field(default_factory=dict)
    cpu_s: float = 0.0
    pid: int = 0
    process_cpu_s: float = 0.0

    def item(self) -> MotionItem:
        d = sorted(self.points)
        return MotionItem(self.name, tuple(d), tuple(self.points[x]['energy_j'] for x in d))


def front_durations(t_min: float, op: Operation, spec: CycleSpec) -> list:
    """Durations [s] to plan: the given ones (rounded up to the grid) or front_points of them
    from the shortest grid duration >= t_min up to max_duration_s (or front_span x it),
    geometrically spaced, on the time grid."""
    step = spec.time_step_s
    up = lambda d: round(math.ceil(d / step - 1e-9) * step, 9)  # noqa: E731
    if op.durations_s:
        return sorted({up(max(d, t_min)) for d in op.durations_s})
    lo = up(t_min * (1 + 1e-9))
    hi = max(lo, op.max_duration_s or spec.front_span * lo)
    n = max(spec.front_points, 1)
    ds = np.geomspace(lo, hi, n) if n > 1 else np.array([lo])
    return sorted({up(d) for d in ds})


def _cache_key(planner, op: Operation, spec: CycleSpec, energy_model: str) -> str:
    s = planner.settings
    blob = json.dumps({'v': CACHE_VERSION, 'path': op.path, 'process': op.process,
                       'grid': spec.grid_size or s.grid_size, 'map': spec.friction_map,
                       'model': energy_model, 'electrical': repr(planner.electrical),
                       'delta': s.min_theta_dot_rad_s, 'margin': s.constraint_margin,
                       'rate': [s.play_rate_hz, s.evaluation_rate_hz],
                       # the smoothness limits (issue 28) change every front
                       'smooth': [s.jerk_limits, list(s.joint_jerk_limit_rad_s3),
                                  s.tcp_jerk_limit_m_s3, list(s.torque_rate_limit_nm_s)],
                       # pdplus's plan gate: its points are re-planned until it accepts them
                       'gate': [GATE_MAX_ACCELERATION_RAD_S2, GATE_TORQUE_FRACTION],
                       # the linear solver's scaling: another stopping point, possibly
                       # another local optimum (cycle_ten: the same energies to 3.1e-7)
                       'mumps_ps': s.mumps_permuting_scaling,
                       # only when set: the caches of plans at the full limits stay valid
                       **({'limits': spec.limit_scaling} if spec.limit_scaling else {})},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def compute_front(planner, op: Operation, spec: CycleSpec, energy_model: str,
                  cache_dir: Path | None = None, progress=print, cached_only: bool = False
                  ) -> Front | None:
    """Plan ``op`` time-optimally and energy-optimally at its front durations (cached on disk
    per request in ``cache_dir``). A front duration the planner refuses as infeasible (code
    3) or fails to solve (code 5) is left out and recorded with its reason; any other
    refusal, or of the time-optimal plan, is a CycleError. ``cached_only``: None instead of
    planning when the cache lacks a plan."""
    from .request import ERROR_INFEASIBLE_DURATION, ERROR_SOLVER, PlanError
    cpu0 = time.process_time()
    bus = energy_model.split('_', 1)[1]
    grid = spec.grid_size
    key = _cache_key(planner, op, spec, energy_model)
    cfile = Path(cache_dir) / f'{op.name}-{key}.json' if cache_dir else None
    cache = {}
    if cfile is not None and cfile.is_file():
        try:
            cache = json.loads(cfile.read_text())
        except (OSError, ValueError):
            cache = {}
    cache.setdefault('points', {})
    cache.setdefault('refused', {})

    def save():
        if cfile is not None:
            cfile.parent.mkdir(parents=True, exist_ok=True)
            tmp = cfile.with_suffix('.tmp')
            tmp.write_text(json.dumps(cache))
            tmp.replace(cfile)

    def run(duration, objective):
        # a plan pdplus's gate would refuse is planned again at tighter limits (the same
        # duration; the time-optimal one at the limits the gate accepts: baseline A is as
        # fast as the controller allows), up to GATE_RETRIES times
        t0 = time.perf_counter()
        scaling = spec.limit_scaling or 1.0
        for _ in range(GATE_RETRIES + 1):
            try:
                r = planner.plan(plan_request(op, duration, objective, energy_model, grid,
                                              spec.friction_map, scaling))
            except PlanError as exc:
                if exc.code in (ERROR_INFEASIBLE_DURATION, ERROR_SOLVER) and \
                        objective != 'time':
                    return None, f'code {exc.code}: {exc.message}', time.perf_counter() - t0
                raise CycleError(f'motion {op.name}: the planner refused the {objective} '
                                 f'plan{f" at {duration:g} s" if duration else ""} at limit '
                                 f'scaling {scaling:.3g} (code {exc.code}): '
                                 f'{exc.message}') from None
            rec = _point_record(r, bus, planner.electrical)
            notes, factor = gate_check(planner.model, rec['trajectory'])
            if not notes:
                return rec, '', time.perf_counter() - t0
            scaling *= factor
        why = f"pdplus's plan gate refuses it at limit scaling {scaling / factor:.3g}: {notes[0]}"
        if objective == 'time':
            raise CycleError(f'motion {op.name}: the time-optimal plan: {why}')
        return None, why, time.perf_counter() - t0
    if cached_only:
        if 'fastest' not in cache:
            return None
        todo = [d for d in front_durations(cache['fastest']['min_duration_s'], op, spec)
                if f'{d:.9g}' not in cache['points'] and f'{d:.9g}' not in cache['refused']]
        if todo:
            return None
    if 'fastest' not in cache:
        rec, _, dt = run(0.0, 'time')
        cache['fastest'] = rec
        save()
        progress(f'  {op.name}: time-optimal {rec["duration_s"]:.3f} s, '
                 f'{rec["energy_j"]:.1f} J ({dt:.1f} s)')
    fastest = cache['fastest']
    for d in front_durations(fastest['min_duration_s'], op, spec):
        k = f'{d:.9g}'
        if k in cache['points'] or k in cache['refused']:
            continue
        rec, why, dt = run(d, 'energy')
        if rec is None:
            cache['refused'][k] = why
            progress(f'  {op.name}: {d:g} s refused ({why[:90]}) ({dt:.1f} s)')
        else:
            cache['points'][k] = rec
            progress(f'  {op.name}: {d:g} s -> {rec["energy_j"]:.1f} J ({dt:.1f} s)')
        save()
    wanted = {f'{d:.9g}' for d in front_durations(fastest['min_duration_s'], op, spec)}
    pts = {float(k): v for k, v in cache['points'].items() if k in wanted}
    if not pts:
        raise CycleError(f'motion {op.name}: every front duration was refused '
                         f'({"; ".join(sorted(set(cache["refused"].values())))[:200]})')
    return Front(op.name, fastest, pts, {float(k): v for k, v in cache['refused'].items()
                                         if k in wanted}, time.process_time() - cpu0,
                 os.getpid(), time.process_time())


# --- the whole cycle ----------------------------------------------------------------------
_WORKER = {}


def _front_worker(settings, op, spec, energy_model, cache_dir):
    """One motion's front in a worker process (its Planner built once per process)."""
    from .planner import Planner
    if _WORKER.get('settings') != settings:
        _WORKER.update(settings=settings, planner=Planner(settings=settings))
    def say(line):
        print(line, flush=True)         # the worker shares the caller's stdout
    return compute_front(_WORKER['planner'], op, spec, energy_model, cache_dir, say)


def front_cost(op: Operation) -> tuple:
    """A sort key for the planning cost of a motion's front, larger for costlier: process
    constraints first (every point a solve with the band rows and, in cycle_ten, a second
    one after the check tightened the band: the gluing rectangle was a third of the ten
    operations' planning), then path pieces, then path length."""
    from irb_description.path import path_from_spec
    path = path_from_spec(op.path)
    return (bool(op.process), int(np.asarray(path.breaks).size), float(path.length))


def _fronts_parallel(settings, ms, spec, energy_model, cache_dir, progress, jobs) -> dict:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed
    fronts = {}
    ctx = mp.get_context('forkserver')
    with ProcessPoolExecutor(max_workers=min(jobs, len(ms)), mp_context=ctx) as pool:
        # the costliest first (the pool hands out in submission order): a long front
        # started last would run alone while the other processes idle
        futs = {pool.submit(_front_worker, settings, op, spec, energy_model, cache_dir): op
                for op in sorted(ms, key=front_cost, reverse=True)}
        try:
            for k, fut in enumerate(as_completed(futs)):
                op = futs[fut]
                fronts[op.name] = fut.result()
                progress(f'front {k + 1}/{len(ms)} done: {op.name}')
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)
            raise
    return {op.name: fronts[op.name] for op in ms}


def hold_power_at(planner, q) -> float:
    """Hold power [W] at joint position q (the planner's arm) on the planner's electrical
    model: standby + drive idle + copper of the gravity torque."""
    from irb_description.power_modes import holding_power_w
    with planner._model_lock:
        g = np.asarray(planner.model.gravity(np.asarray(q, float)), float)
    return holding_power_w(planner.electrical, g)


def check_continuity(spec: CycleSpec, tol_m: float = 1e-3) -> None:
    """Each motion starts where the robot is: at the end of the motion before it
    (cyclically); CycleError naming both otherwise."""
    from irb_description.path import TWO_PI, path_from_spec
    ms = spec.motions
    for k, op in enumerate(ms):
        prev = ms[k - 1]
        a = np.asarray(path_from_spec(prev.path).point(TWO_PI), float)
        b = np.asarray(path_from_spec(op.path).point(0.0), float)
        if np.linalg.norm(a - b) > tol_m:
            raise CycleError(f'{spec.source}: motion {op.name} starts at '
                             f'{np.round(b, 4).tolist()} m but the robot is at '
                             f'{np.round(a, 4).tolist()} m after {prev.name} (more than '
                             f'{tol_m * 1e3:g} mm apart)')


def check_reachable(spec: CycleSpec, model) -> None:
    """Every motion's path inside the workspace and the joint limits (the planner's own
    along-path check, before any plan); CycleError naming the motion otherwise."""
    from irb_description.path import check_joint_path, path_from_spec
    for op in spec.motions:
        try:
            check_joint_path(model, path_from_spec(op.path))
        except ValueError as exc:
            raise CycleError(f'{spec.source}: motion {op.name}: path unreachable: '
                             f'{str(exc).splitlines()[0]}') from None


@dataclass
class CyclePlan:
    """The planned cycle: the optimum, the two baselines, fronts, items, power modes."""

    spec: CycleSpec
    solution: Solution
    baseline_a: dict
    baseline_b: Solution | None
    fronts: dict
    items: list
    modes: PowerModes
    plan_time_s: float
    front_time_s: float
    energy_model: str = ''

    def summary(self) -> dict:
        s = self.solution
        a = self.baseline_a['total_j']
        b = self.baseline_b.total_j if self.baseline_b else float('nan')
        return {'takt_s': s.takt_s, 'time_step_s': s.step_s, 'energy_j': s.total_j,
                'lower_bound_j': s.lower_bound_j, 'gap_j': s.gap_j,
                'gap_percent': 100 * s.gap_rel, 'baseline_a_j': a, 'baseline_b_j': b,
                'saving_vs_a_percent': 100 * (1 - s.total_j / a),
                'saving_vs_b_percent': 100 * (1 - s.total_j / b),
                'dp_time_s': s.solve_time_s, 'front_time_s': self.front_time_s,
                'plan_time_s': self.plan_time_s, 'operations': s.choices,
                'baseline_a': self.baseline_a,
                'baseline_b': self.baseline_b.choices if self.baseline_b else None,
                'power_modes': self.modes.as_dict()}


def baseline_a(fronts: dict, items: list, spec: CycleSpec, pm: PowerModes) -> dict:
    """Baseline A: every motion time-optimal, the robot holds (motors on) in every station,
    the slack in the first wait station."""
    t_motion = sum(fronts[it.name].fastest['duration_s'] for it in items
                   if isinstance(it, Operation))
    fixed = sum(it.fixed_s for it in items if isinstance(it, StationItem))
    slack = spec.takt_s - t_motion - fixed
    if slack < -1e-9:
        raise CycleError(f'baseline A: the time-optimal motions ({t_motion:.3f} s) and the '
                         f'fixed steps ({fixed:.3f} s) exceed the takt {spec.takt_s:g} s')
    out, total, given = [], 0.0, False
    for it in items:
        if isinstance(it, Operation):
            f = fronts[it.name].fastest
            out.append({'kind': 'motion', 'name': it.name, 'duration_s': f['duration_s'],
                        'energy_j': f['energy_j']})
            total += f['energy_j']
        else:
            d = it.fixed_s + (slack if it.wait and not given else 0.0)
            given = given or it.wait
            e = pm.wait_energy_j(HOLD, d, it.holding_power_w)
            out.append({'kind': 'station', 'name': it.name, 'mode': HOLD, 'duration_s': d,
                        'energy_j': e, 'holding_power_w': it.holding_power_w})
            total += e
    return {'total_j': float(total), 'choices': out}


def dp_items(items: list, fronts: dict) -> list:
    return [fronts[it.name].item() if isinstance(it, Operation) else it for it in items]


def restrict_modes(items: list, modes: tuple) -> list:
    """Items with every station limited to ``modes``."""
    from dataclasses import replace
    return [replace(it, modes=tuple(m for m in it.modes if m in modes))
            if isinstance(it, StationItem) else it for it in items]


def front_settings(spec: CycleSpec, **overrides):
    """PlannerSettings for a cycle's fronts: the spec's grid (200 if unset), no
    cost-of-the-limits solve (the fronts' many plans need no such figure), warm starts along
    the front (each point from its neighbour, FRONT_WARM_ITERATIONS, FRONT_WARM_WINDOW; the
    first from the time-optimal plan), MUMPS without permuting scaling
    (FRONT_MUMPS_PERMUTING_SCALING); ``overrides``: other PlannerSettings fields. The warm
    starts and the scaling change where and how IPOPT walks, not the problem:
    test_cycle_fronts.py compares such a front with cold solves at IPOPT's defaults."""
    from .planner import PlannerSettings
    kw = dict(grid_size=spec.grid_size or 200, limit_cost=False,
              warm_max_iterations=FRONT_WARM_ITERATIONS, warm_window=FRONT_WARM_WINDOW,
              warm_from_time_optimal=True, resolve_mu_init=FRONT_RESOLVE_MU_INIT,
              mumps_permuting_scaling=FRONT_MUMPS_PERMUTING_SCALING)
    kw.update(overrides)
    return PlannerSettings(**kw)


def plan_cycle(spec: CycleSpec, planner=None, modes: PowerModes | None = None,
               cache_dir=None, progress=print, takt_s: float | None = None,
               jobs: int = 1) -> CyclePlan:
    """Fronts (planner, cached), stations, the DP optimum with its certificate, baselines
    A (time-optimal motions, hold) and B (durations by the same DP, hold only). ``jobs`` > 1:
    the motions' fronts in that many processes (each with its own Planner of the same
    settings; their progress lines go to stdout as they come)."""
    from irb_description.power_modes import load_power_modes
    from .planner import Planner
    t0 = time.perf_counter()
    if takt_s is not None:
        from dataclasses import replace
        spec = replace(spec, takt_s=float(takt_s))
    check_continuity(spec)
    if planner is None:
        planner = Planner(settings=front_settings(spec))
    check_reachable(spec, planner.model)
    if modes is None:
        modes = load_power_modes(spec.power_modes or None, electrical=planner.electrical)
    energy_model = spec.energy_model or f'electrical_{planner.electrical.bus_mode}'
    fronts = {}
    ms = spec.motions
    if jobs > 1 and len(ms) > 1:
        cached = {op.name: compute_front(planner, op, spec, energy_model, cache_dir,
                                         progress, cached_only=True) for op in ms}
        todo = [op for op in ms if cached[op.name] is None]
        if todo:
            cached.update(_fronts_parallel(planner.settings, todo, spec, energy_model,
                                           cache_dir, progress, jobs))
        fronts = {op.name: cached[op.name] for op in ms}
    else:
        for k, op in enumerate(ms):
            progress(f'front {k + 1}/{len(ms)}: {op.name}')
            fronts[op.name] = compute_front(planner, op, spec, energy_model, cache_dir,
                                            progress)
    t_front = time.perf_counter() - t0
    holding = {name: hold_power_at(planner, f.fastest['q_end']) for name, f in fronts.items()}
    items = stations_and_motions(spec, holding)
    dp = dp_items(items, fronts)
    sol = solve(dp, spec.takt_s, spec.time_step_s, modes)
    base_a = baseline_a(fronts, items, spec, modes)
    try:
        base_b = solve(restrict_modes(dp, (HOLD,)), spec.takt_s, spec.time_step_s, modes)
    except CycleError:
        base_b = None
    return CyclePlan(spec, sol, base_a, base_b, fronts, items, modes,
                     time.perf_counter() - t0, t_front, energy_model)


def resolve_at_takt(plan: CyclePlan, takt_s: float, modes: PowerModes | None = None
                    ) -> tuple[Solution, dict, Solution]:
    """(optimum, baseline A, baseline B) of the same cycle and fronts at another takt or with
    other mode parameters (no planner call)."""
    from dataclasses import replace
    pm = modes or plan.modes
    spec = replace(plan.spec, takt_s=float(takt_s))
    dp = dp_items(plan.items, plan.fronts)
    return (solve(dp, takt_s, spec.time_step_s, pm), baseline_a(plan.fronts, plan.items, spec, pm),
            solve(restrict_modes(dp, (HOLD,)), takt_s, spec.time_step_s, pm))


def timeline(choices: list, fronts: dict, pm: PowerModes) -> tuple[np.ndarray, np.ndarray]:
    """Power [W] over one cycle of ``choices`` (a Solution's or baseline A's): motions as
    planned (the front point's played power, or the time-optimal plan's), stations as their
    transitions (mean power of each neighbour step) and mode."""
    ts, ps, t0 = [], [], 0.0
    for c in choices:
        if c['kind'] == 'motion':
            f = fronts[c['name']]
            rec = f.points.get(c['duration_s']) or f.fastest
            t = np.asarray(rec['power_t'], float)
            ts.append(t0 + t - t[0])
            ps.append(np.asarray(rec['power_w'], float))
            t0 += c['duration_s']
            continue
        hp, mode, d = c['holding_power_w'], c['mode'], c['duration_s']
        segs = []
        if mode != HOLD:
            t_in = pm.transition(HOLD, mode, hp)
            t_out = pm.transition(mode, HOLD, hp)
            steps_in = [pm.transition(x, y, hp) for x, y in zip(t_in.path, t_in.path[1:])]
            steps_out = [pm.transition(x, y, hp) for x, y in zip(t_out.path, t_out.path[1:])]
            rest = d - t_in.duration_s - t_out.duration_s
            segs = ([(s.duration_s, s.energy_j / s.duration_s if s.duration_s else 0.0)
                     for s in steps_in] + [(rest, pm.power_w(mode))]
                    + [(s.duration_s, s.energy_j / s.duration_s if s.duration_s else 0.0)
                       for s in steps_out])
        else:
            segs = [(d, pm.power_w(HOLD, hp))]
        for dur, p in segs:
            ts.append(np.array([t0, t0 + dur]))
            ps.append(np.array([p, p]))
            t0 += dur
    return np.concatenate(ts), np.concatenate(ps)
