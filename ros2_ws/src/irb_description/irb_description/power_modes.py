"""Power modes of the robot system at rest and their transitions (no ROS; issue 29).

Modes, from the shallowest to the deepest (``MODES``):

    hold       motors on, brakes released, the servo loop holds the pose: the electrical model
               at rest, P = P_sb + sum_i P_idle_i + holding copper/conversion losses at the pose
               (``holding_power_w(electrical, tau_gravity)``; without a pose, zero torque)
    brakes     brakes engaged, power stages off:          P = P_sb - P_brake_coils
    bus_off    brakes engaged, DC bus off:                 P = P_sb - P_brake_coils - P_bus_on
    hibernate  controller suspended, bus off, brakes on:   P = f_hib (P_sb + sum_i P_idle_i)

P_sb and P_idle come from the electrical model (config/electrical.yaml), the rest from
config/power_modes.yaml, where every value names its source. A transition a -> b between
neighbours takes ``duration_s`` at the power of its origin or target mode (YAML ``power``)
plus a one-off ``extra_j`` (``bus_charge`` = C V^2: precharge resistor and bleeder together);
any other pair is the cheapest-in-time chain of neighbour transitions.

A wait of length d at a pose in mode m goes hold -> m, stays, m -> hold: it is feasible only
if both transitions fit in d (``wait_energy_j`` raises, ``feasible`` says False otherwise).

    >>> pm = load_power_modes()                       # reads electrical.yaml too
    >>> pm.power_w('brakes'), pm.transition('hold', 'bus_off').duration_s
    >>> pm.wait_energy_j('bus_off', 12.0, holding_power_w=285.0)
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .params import _load_yaml, config_path

HOLD, BRAKES, BUS_OFF, HIBERNATE = 'hold', 'brakes', 'bus_off', 'hibernate'
MODES = (HOLD, BRAKES, BUS_OFF, HIBERNATE)
BUS_CHARGE = 'bus_charge'


@dataclass(frozen=True)
class Transition:
    """A change of mode: duration [s], energy drawn from the grid [J], modes visited."""

    duration_s: float
    energy_j: float
    path: tuple = ()


@dataclass(frozen=True)
class TransitionSpec:
    """One neighbour transition as given in the YAML: origin, target, duration [s], the mode
    whose power is drawn meanwhile ('from' or 'to'), one-off extra energy [J] or
    ``BUS_CHARGE``, source text."""

    src: str
    dst: str
    duration_s: float
    power: str = 'from'
    extra_j: float | str = 0.0
    source: str = ''


@dataclass(frozen=True)
class PowerModes:
    """Mode powers and transitions. ``standby_power_w`` and ``drive_idle_power_w`` (sum over
    the axes) come from the electrical model; the rest from power_modes.yaml [W, F, V]."""

    standby_power_w: float
    drive_idle_power_w: float
    brake_coils_w: float
    bus_on_w: float
    hibernate_fraction: float
    bus_capacitance_f: float
    bus_voltage_v: float
    transitions: tuple = ()
    sources: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        for name in ('standby_power_w', 'drive_idle_power_w', 'brake_coils_w', 'bus_on_w',
                     'bus_capacitance_f', 'bus_voltage_v'):
            v = float(getattr(self, name))
            if not np.isfinite(v) or v < 0:
                raise ValueError(f'power modes: {name} must be a finite number >= 0, got {v}')
        if not 0 < self.hibernate_fraction <= 1:
            raise ValueError('power modes: hibernate fraction_of_idle must be in (0, 1], got '
                             f'{self.hibernate_fraction}')
        if self.brake_coils_w + self.bus_on_w >= self.standby_power_w:
            raise ValueError(f'power modes: brake_coils_w + bus_on_w ({self.brake_coils_w} + '
                             f'{self.bus_on_w} W) must stay below the standby '
                             f'{self.standby_power_w} W')
        if self.power_w(HIBERNATE) > self.power_w(BUS_OFF):
            raise ValueError(f'power modes: hibernate ({self.power_w(HIBERNATE):.1f} W) draws '
                             f'more than bus_off ({self.power_w(BUS_OFF):.1f} W)')
        for t in self.transitions:
            if t.src not in MODES or t.dst not in MODES or t.src == t.dst:
                raise ValueError(f'power modes: transition {t.src} -> {t.dst}: modes must be '
                                 f'two different ones of {list(MODES)}')
            if not (np.isfinite(t.duration_s) and t.duration_s >= 0):
                raise ValueError(f'power modes: transition {t.src} -> {t.dst}: duration_s '
                                 f'must be >= 0, got {t.duration_s}')
            if t.power not in ('from', 'to'):
                raise ValueError(f"power modes: transition {t.src} -> {t.dst}: power must be "
                                 f"'from' or 'to', got {t.power!r}")
            if not (t.extra_j == BUS_CHARGE or (isinstance(t.extra_j, (int, float))
                                                 and t.extra_j >= 0)):
                raise ValueError(f'power modes: transition {t.src} -> {t.dst}: extra_j must '
                                 f'be >= 0 or {BUS_CHARGE!r}, got {t.extra_j!r}')
        for m in MODES[1:]:
            for a, b in ((HOLD, m), (m, HOLD)):
                if self._path(a, b) is None:
                    raise ValueError(f'power modes: no chain of transitions from {a} to {b}')

    # --- powers -----------------------------------------------------------------------
    @property
    def idle_hold_power_w(self) -> float:
        """Hold power without gravity load: standby + every drive's idle [W]."""
        return float(self.standby_power_w + self.drive_idle_power_w)

    @property
    def bus_charge_j(self) -> float:
        """Energy of one bus off-on cycle, C V^2 [J] (half stored, half in the precharge)."""
        return float(self.bus_capacitance_f * self.bus_voltage_v ** 2)

    def power_w(self, mode: str, holding_power_w: float | None = None) -> float:
        """Input power of ``mode`` [W]. ``holding_power_w``: the hold power at the pose (the
        electrical model at rest with the gravity torque, ``holding_power_w()``); without it,
        hold is the gravity-free ``idle_hold_power_w``. Ignored for the other modes."""
        if mode == HOLD:
            return float(self.idle_hold_power_w if holding_power_w is None
                         else holding_power_w)
        if mode == BRAKES:
            return float(self.standby_power_w - self.brake_coils_w)
        if mode == BUS_OFF:
            return float(self.standby_power_w - self.brake_coils_w - self.bus_on_w)
        if mode == HIBERNATE:
            return float(self.hibernate_fraction * self.idle_hold_power_w)
        raise ValueError(f'power mode {mode!r} unknown; one of {list(MODES)}')

    # --- transitions --------------------------------------------------------------------
    def _spec_energy(self, t: TransitionSpec, holding_power_w) -> float:
        p = self.power_w(t.src if t.power == 'from' else t.dst, holding_power_w)
        extra = self.bus_charge_j if t.extra_j == BUS_CHARGE else float(t.extra_j)
        return p * float(t.duration_s) + extra

    def _path(self, a: str, b: str):
        """Neighbour transitions from a to b, shortest in time (Dijkstra), or None."""
        best = {a: 0.0}
        heap = [(0.0, a, ())]
        while heap:
            d, m, path = heapq.heappop(heap)
            if m == b:
                return path
            if d > best.get(m, np.inf):
                continue
            for t in self.transitions:
                if t.src == m and d + t.duration_s < best.get(t.dst, np.inf):
                    best[t.dst] = d + t.duration_s
                    heapq.heappush(heap, (d + t.duration_s, t.dst, path + (t,)))
        return None

    def transition(self, a: str, b: str, holding_power_w: float | None = None) -> Transition:
        """Duration [s] and energy [J] of going from mode ``a`` to mode ``b`` (through the
        neighbour transitions, fastest chain); zero if a == b."""
        for m in (a, b):
            if m not in MODES:
                raise ValueError(f'power mode {m!r} unknown; one of {list(MODES)}')
        if a == b:
            return Transition(0.0, 0.0, (a,))
        path = self._path(a, b)
        if path is None:
            raise ValueError(f'power modes: no chain of transitions from {a} to {b}')
        return Transition(float(sum(t.duration_s for t in path)),
                          float(sum(self._spec_energy(t, holding_power_w) for t in path)),
                          (a,) + tuple(t.dst for t in path))

    # --- waits --------------------------------------------------------------------------
    def min_wait_s(self, mode: str) -> float:
        """Shortest wait that can use ``mode``: hold -> mode -> hold [s]."""
        return self.transition(HOLD, mode).duration_s + self.transition(mode, HOLD).duration_s

    def feasible(self, mode: str, duration_s: float) -> bool:
        """Whether a wait of ``duration_s`` can use ``mode`` (both transitions fit)."""
        return bool(duration_s >= self.min_wait_s(mode) - 1e-12)

    def wait_energy_j(self, mode: str, duration_s: float,
                      holding_power_w: float | None = None) -> float:
        """Energy [J] of a wait of ``duration_s`` at a pose, starting and ending in hold and
        spending the time between the transitions in ``mode``. Raises ValueError if the
        transitions do not fit in the wait."""
        if not duration_s >= 0:
            raise ValueError(f'wait duration must be >= 0 s, got {duration_s}')
        if mode == HOLD:
            return self.power_w(HOLD, holding_power_w) * float(duration_s)
        t_in = self.transition(HOLD, mode, holding_power_w)
        t_out = self.transition(mode, HOLD, holding_power_w)
        rest = float(duration_s) - t_in.duration_s - t_out.duration_s
        if rest < -1e-12:
            raise ValueError(f'a wait of {duration_s:g} s cannot use {mode}: its transitions '
                             f'take {t_in.duration_s + t_out.duration_s:g} s')
        return t_in.energy_j + t_out.energy_j + self.power_w(mode) * max(rest, 0.0)

    def best_wait(self, duration_s: float, holding_power_w: float | None = None,
                  allowed=MODES) -> tuple[str, float]:
        """(mode, energy [J]) of the cheapest feasible mode among ``allowed`` for one wait."""
        options = [(self.wait_energy_j(m, duration_s, holding_power_w), i, m)
                   for i, m in enumerate(MODES) if m in allowed and self.feasible(m, duration_s)]
        if not options:
            raise ValueError(f'no mode of {list(allowed)} fits a wait of {duration_s:g} s')
        e, _, m = min(options)
        return m, float(e)

    def break_even_s(self, mode: str, holding_power_w: float | None = None) -> float:
        """Wait length [s] from which ``mode`` costs no more than hold (>= min_wait_s)."""
        if mode == HOLD:
            return 0.0
        p_h = self.power_w(HOLD, holding_power_w)
        p_m = self.power_w(mode)
        t_in = self.transition(HOLD, mode, holding_power_w)
        t_out = self.transition(mode, HOLD, holding_power_w)
        dt = t_in.duration_s + t_out.duration_s
        # E_mode(d) = E_in + E_out + p_m (d - dt) <= p_h d
        if p_h <= p_m:
            return float('inf')
        d = (t_in.energy_j + t_out.energy_j - p_m * dt) / (p_h - p_m)
        return float(max(d, dt))

    # --- variants (sensitivity studies, plants) -----------------------------------------
    def with_params(self, **kw) -> 'PowerModes':
        """A copy with fields replaced; ``duration_factor=<f>`` scales every transition's
        duration, ``<src>__<dst>=<s>`` sets one transition's duration."""
        factor = kw.pop('duration_factor', None)
        moves = {k: kw.pop(k) for k in list(kw) if '__' in k}
        trans = list(self.transitions)
        if factor is not None:
            trans = [replace(t, duration_s=t.duration_s * float(factor)) for t in trans]
        for k, v in moves.items():
            a, b = k.split('__', 1)
            hit = [i for i, t in enumerate(trans) if (t.src, t.dst) == (a, b)]
            if not hit:
                raise ValueError(f'power modes: no transition {a} -> {b} to change')
            trans[hit[0]] = replace(trans[hit[0]], duration_s=float(v))
        return replace(self, transitions=tuple(trans), **kw)

    def as_dict(self, holding_power_w: float | None = None) -> dict:
        """Powers, transitions (every ordered pair) and sources, for reports (JSON-ready)."""
        return {'power_w': {m: self.power_w(m, holding_power_w) for m in MODES},
                'min_wait_s': {m: self.min_wait_s(m) for m in MODES},
                'transitions': [{'from': a, 'to': b,
                                 'duration_s': self.transition(a, b).duration_s,
                                 'energy_j': self.transition(a, b, holding_power_w).energy_j,
                                 'path': list(self.transition(a, b).path)}
                                for a in MODES for b in MODES if a != b],
                'bus_charge_j': self.bus_charge_j, 'sources': dict(self.sources)}


def holding_power_w(electrical, tau_hold) -> float:
    """Hold power [W] at a pose: the electrical model at rest (q̇ = 0) with the arm-side
    holding torques ``tau_hold`` (n,) of its axes (the gravity torque g(q) of the pose)."""
    tau = np.asarray(tau_hold, float).reshape(-1)
    if tau.size != electrical.n:
        raise ValueError(f'holding torques have {tau.size} values, the electrical model has '
                         f'{electrical.n} axes')
    return float(electrical.power(tau, np.zeros_like(tau)))


def _num(d: dict, key: str, where: str) -> float:
    try:
        v = d[key]
    except (KeyError, TypeError):
        raise ValueError(f'power modes: missing key {where}.{key}') from None
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f'power modes: {where}.{key} must be a number, got {v!r}')
    return float(v)


def load_power_modes(path: Path | str | None = None, electrical=None) -> PowerModes:
    """Load ``config/power_modes.yaml`` (or ``path``). ``electrical``: the ElectricalModel
    whose standby and drive idle make the hold power (default: ``load_electrical()``; pass
    the planner's 3-axis model or a plant's model to stay consistent with it)."""
    if electrical is None:
        from .electrical import load_electrical
        electrical = load_electrical()
    try:
        d = _load_yaml(Path(path) if path else config_path('power_modes.yaml'))
    except (OSError, ValueError) as exc:
        raise ValueError(f'power modes: cannot read {path or "power_modes.yaml"}: {exc}'
                         ) from None
    except Exception as exc:  # noqa: BLE001 - YAML syntax errors: one line
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f'power modes: {path or "power_modes.yaml"} is not valid YAML: '
                         f'{first}') from None
    modes, bus = d.get('modes'), d.get('bus')
    if not isinstance(modes, dict) or not isinstance(bus, dict):
        raise ValueError('power modes: the file needs the mappings `modes` and `bus`')
    for m in MODES[1:]:
        if not isinstance(modes.get(m), dict):
            raise ValueError(f'power modes: missing mode modes.{m}')
    trans = []
    raw = d.get('transitions')
    if not isinstance(raw, list) or not raw:
        raise ValueError('power modes: `transitions` must be a non-empty list')
    for i, t in enumerate(raw):
        if not isinstance(t, dict) or 'from' not in t or 'to' not in t:
            raise ValueError(f'power modes: transitions[{i}] needs `from`, `to`, `duration_s`')
        extra = t.get('extra_j', 0.0)
        trans.append(TransitionSpec(
            src=str(t['from']), dst=str(t['to']),
            duration_s=_num(t, 'duration_s', f'transitions[{i}]'),
            power=str(t.get('power', 'from')),
            extra_j=extra if extra == BUS_CHARGE else (
                _num(t, 'extra_j', f'transitions[{i}]') if 'extra_j' in t else 0.0),
            source=str(t.get('source', ''))))
    sources = {m: str(modes.get(m, {}).get('source', '')) for m in MODES}
    sources['bus'] = str(bus.get('source', ''))
    for t in trans:
        sources[f'{t.src}->{t.dst}'] = t.source
    return PowerModes(
        standby_power_w=float(electrical.standby_power),
        drive_idle_power_w=float(np.sum(electrical.drive_idle_power)),
        brake_coils_w=_num(modes[BRAKES], 'brake_coils_w', 'modes.brakes'),
        bus_on_w=_num(modes[BUS_OFF], 'bus_on_w', 'modes.bus_off'),
        hibernate_fraction=_num(modes[HIBERNATE], 'fraction_of_idle', 'modes.hibernate'),
        bus_capacitance_f=_num(bus, 'capacitance_f', 'bus'),
        bus_voltage_v=_num(bus, 'voltage_v', 'bus'),
        transitions=tuple(trans), sources=sources)
