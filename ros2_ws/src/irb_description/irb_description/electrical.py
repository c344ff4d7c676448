"""Electrical power drawn by the robot: motors, gearboxes, drives, DC bus, standby (no ROS).

Per axis i, from the arm-side torque tau [N m] and joint speed qd [rad/s] (README "Electrical
model"):

    P_j   = tau qd                                          joint (arm-side) power [W]
    s     = 1 if P_j >= 0 (motoring) else 0 (generating)
    P_g   = s P_j / eta_m + (1 - s) eta_g P_j               motor shaft power [W]
    tau_m = tau / N (s / eta_m + (1 - s) eta_g)              motor torque [N m]
    P_cu  = R (tau_m / k_t)^2                               copper losses [W]
    P_e   = P_g + P_cu                                      drive output power [W]
    P_ax  = max(P_e, 0) / eta_d + min(P_e, 0) eta_d + P_idle   power from the DC bus [W]

and for the robot, with P_sb the standby power and the DC-bus mode:

    none:          P = P_sb + sum_i max(P_ax_i, 0)          (negative power burned per axis)
    shared:        P = P_sb + max(sum_i P_ax_i, 0)          (axes feed each other)
    regenerative:  S = sum_i P_ax_i;  P = P_sb + max(S, 0) + eta_r min(S, 0)

The same formulas are written once over a small backend (numpy or CasADi), so the two forms
agree to round-off. ``smoothing`` eps > 0 (CasADi only, for gradient solvers) replaces
|x| by sqrt(x^2 + eps^2) and the step s by (1 + x / sqrt(x^2 + eps^2)) / 2.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .params import _load_yaml, config_path, load_dynamics

BUS_NONE = 'none'
BUS_SHARED = 'shared'
BUS_REGENERATIVE = 'regenerative'
BUS_MODES = (BUS_NONE, BUS_SHARED, BUS_REGENERATIVE)


@dataclass(frozen=True)
class ElectricalModel:
    """Per-axis arrays (n,): k_t [N m/A], R [ohm], gear ratio N [-], gearbox efficiencies
    eta_m (motoring), eta_g (generating) [-], drive idle power [W]; drive efficiency eta_d [-],
    standby power [W], bus mode (BUS_MODES), regenerative efficiency eta_r [-]."""

    torque_constant: np.ndarray
    resistance: np.ndarray
    gear_ratio: np.ndarray
    gear_efficiency_motoring: np.ndarray
    gear_efficiency_generating: np.ndarray
    drive_idle_power: np.ndarray
    drive_efficiency: float
    standby_power: float
    bus_mode: str = BUS_SHARED
    regenerative_efficiency: float = 0.9

    def __post_init__(self):
        if self.bus_mode not in BUS_MODES:
            raise ValueError(f'bus mode {self.bus_mode!r} unknown; one of {list(BUS_MODES)}')
        for name in ('gear_efficiency_motoring', 'gear_efficiency_generating'):
            v = np.asarray(getattr(self, name), float)
            if np.any(v <= 0) or np.any(v > 1):
                raise ValueError(f'{name} must be in (0, 1], got {v.tolist()}')
        for name in ('drive_efficiency', 'regenerative_efficiency'):
            v = getattr(self, name)
            if not 0 < v <= 1:
                raise ValueError(f'{name} must be in (0, 1], got {v}')
        if np.any(np.asarray(self.torque_constant) <= 0) or np.any(
                np.asarray(self.resistance) < 0) or np.any(np.asarray(self.gear_ratio) <= 0):
            raise ValueError('torque constants and gear ratios must be > 0, resistances >= 0')

    @property
    def n(self) -> int:
        return int(np.asarray(self.torque_constant).size)

    def axes(self, n: int) -> 'ElectricalModel':
        """The model of the first ``n`` axes (the planner's arm has 3)."""
        if not 1 <= n <= self.n:
            raise ValueError(f'the model has {self.n} axes, asked for {n}')
        cut = lambda v: np.asarray(v, float)[:n].copy()  # noqa: E731
        return replace(self, torque_constant=cut(self.torque_constant),
                       resistance=cut(self.resistance), gear_ratio=cut(self.gear_ratio),
                       gear_efficiency_motoring=cut(self.gear_efficiency_motoring),
                       gear_efficiency_generating=cut(self.gear_efficiency_generating),
                       drive_idle_power=cut(self.drive_idle_power))

    def with_mode(self, mode: str) -> 'ElectricalModel':
        return replace(self, bus_mode=mode)

    def scaled(self, **factors) -> 'ElectricalModel':
        """A copy with fields multiplied by factors (e.g. a plant that differs)."""
        return replace(self, **{k: np.asarray(getattr(self, k), float) * v
                                for k, v in factors.items()})

    # --- numpy form: tau, qd (M, n) or (n,) ------------------------------------------------
    def axis_power(self, tau, qd) -> np.ndarray:
        """Power of each axis from the DC bus [W], same shape as ``tau``."""
        tau = np.asarray(tau, float)
        qd = np.asarray(qd, float)
        cols = [_axis_power(_NUMPY, self, i, tau[..., i], qd[..., i], 0.0)
                for i in range(self.n)]
        return np.stack(cols, axis=-1)

    def power(self, tau, qd, mode: str | None = None) -> np.ndarray:
        """Total power drawn from the grid [W], shape tau.shape[:-1]."""
        pax = self.axis_power(tau, qd)
        return _bus_power(_NUMPY, self, [pax[..., i] for i in range(self.n)],
                          mode or self.bus_mode, 0.0)

    def energy(self, t, tau, qd, mode: str | None = None) -> float:
        """Electrical energy [J] over samples t (M,) (trapezoidal rule in time)."""
        return float(np.trapezoid(self.power(tau, qd, mode), np.asarray(t, float)))

    def _axis_flows(self, tau, qd):
        """Per axis and sample [W]: joint power P_j = tau qd, gearbox input P_g, copper loss
        P_cu, motor electrical power P_e = P_g + P_cu and the axis's bus power P_ax."""
        tau = np.asarray(tau, float)
        qd = np.asarray(qd, float)
        pj = tau * qd
        s = (pj >= 0).astype(float)
        em, eg = self._v('gear_efficiency_motoring'), self._v('gear_efficiency_generating')
        pg = s * pj / em + (1 - s) * eg * pj
        taum = tau / self._v('gear_ratio') * (s / em + (1 - s) * eg)
        pcu = self._v('resistance') * (taum / self._v('torque_constant')) ** 2
        return pj, pg, pcu, pg + pcu, self.axis_power(tau, qd)

    def breakdown(self, t, tau, qd) -> dict:
        """Energies [J] over t: 'mechanical' int sum |tau qd|, 'copper', 'gear_loss',
        'drive_loss' (incl. idle), 'standby', and 'total_<mode>' for every bus mode."""
        t = np.asarray(t, float)
        integ = lambda p: float(np.trapezoid(p, t))  # noqa: E731
        pj, pg, pcu, pe, pax = self._axis_flows(tau, qd)
        out = {'mechanical': integ(np.abs(pj).sum(axis=-1)),
               'copper': integ(pcu.sum(axis=-1)),
               'gear_loss': integ(np.abs(pg - pj).sum(axis=-1)),
               'drive_loss': integ(np.abs(pax - pe).sum(axis=-1)),
               'standby': integ(np.full(t.shape, self.standby_power))}
        for mode in BUS_MODES:
            out[f'total_{mode}'] = self.energy(t, tau, qd, mode)
        return out

    def flows(self, t, tau, qd, mode: str | None = None) -> dict:
        """Where the electrical energy of one bus mode goes, over samples t (M,) [J].

        Every part is the time integral (trapezoidal rule, like ``energy``) of a power that
        is >= 0 at each instant except 'work', and the parts add up to the total exactly:

            total = standby + work + gear_loss + copper + drive_conversion + drive_idle
                    + brake_resistor + regeneration_loss

        'work' = int sum_i tau_i qd_i (net joint work: motoring minus generated, 'work_motoring'
        and 'work_generated' >= 0 given apart); 'gear_loss' = P_g - P_j; 'copper' = P_cu;
        'drive_conversion' = P_ax - P_idle - P_e; 'drive_idle' = P_idle; 'brake_resistor' the
        surplus burned ('none': every axis's negative P_ax, 'shared': the negative net bus
        power, 'regenerative': 0); 'regeneration_loss' = (1 - eta_r) x the negative net bus
        power ('regenerative' only), whose other part, 'returned', went back to the grid (it is
        already netted inside 'work'). Also 'total' (= ``energy``), 'duration' [s], 'mode'.
        """
        mode = mode or self.bus_mode
        if mode not in BUS_MODES:
            raise ValueError(f'bus mode {mode!r} unknown; one of {list(BUS_MODES)}')
        t = np.asarray(t, float)
        integ = lambda p: float(np.trapezoid(p, t))  # noqa: E731
        pj, pg, pcu, pe, pax = self._axis_flows(tau, qd)
        idle = np.broadcast_to(self._v('drive_idle_power'), pax.shape)
        net = pax.sum(axis=-1)
        surplus = np.maximum(-net, 0.0)
        burned = {BUS_NONE: np.maximum(-pax, 0.0).sum(axis=-1), BUS_SHARED: surplus,
                  BUS_REGENERATIVE: np.zeros_like(net)}[mode]
        er = float(self.regenerative_efficiency) if mode == BUS_REGENERATIVE else 0.0
        regen = surplus if mode == BUS_REGENERATIVE else np.zeros_like(net)
        return {'mode': mode, 'duration': float(t[-1] - t[0]),
                'standby': integ(np.full(t.shape, float(self.standby_power))),
                'work': integ(pj.sum(axis=-1)),
                'work_motoring': integ(np.maximum(pj, 0.0).sum(axis=-1)),
                'work_generated': integ(np.maximum(-pj, 0.0).sum(axis=-1)),
                'gear_loss': integ((pg - pj).sum(axis=-1)),
                'copper': integ(pcu.sum(axis=-1)),
                'drive_conversion': integ((pax - idle - pe).sum(axis=-1)),
                'drive_idle': integ(idle.sum(axis=-1)),
                'brake_resistor': integ(burned),
                'regeneration_loss': integ((1 - er) * regen),
                'returned': integ(er * regen),
                'total': self.energy(t, tau, qd, mode)}

    def _v(self, name):
        return np.asarray(getattr(self, name), float)

    # --- CasADi form: tau, qd (n, M) casadi matrices (one row per axis) ----------------
    def casadi_axis_power(self, tau, qd, smoothing: float = 0.0):
        """(n, M) CasADi expression of the axis powers [W]."""
        import casadi as ca
        ops = _casadi_ops(smoothing)
        return ca.vertcat(*[_axis_power(ops, self, i, tau[i, :], qd[i, :], smoothing)
                            for i in range(self.n)])

    def casadi_power(self, tau, qd, mode: str | None = None, smoothing: float = 0.0):
        """(1, M) CasADi expression of the total power [W]."""
        pax = self.casadi_axis_power(tau, qd, smoothing)
        return _bus_power(_casadi_ops(smoothing), self, [pax[i, :] for i in range(self.n)],
                          mode or self.bus_mode, smoothing)


#: the parts of ``ElectricalModel.flows`` that add up to its total
FLOW_PARTS = ('standby', 'work', 'gear_loss', 'copper', 'drive_conversion', 'drive_idle',
              'brake_resistor', 'regeneration_loss')


def shares(flows: dict) -> dict:
    """Percentages of the total [%] of every part of ``flows`` (FLOW_PARTS, 'returned' and
    the work split), with 'parts_sum' (100 up to round-off) and 'motion' (100 - standby)."""
    total = float(flows['total'])
    if not total > 0:
        raise ValueError(f'total electrical energy {total} J is not positive')
    keys = FLOW_PARTS + ('returned', 'work_motoring', 'work_generated')
    out = {k: 100.0 * float(flows[k]) / total for k in keys}
    out['parts_sum'] = sum(out[k] for k in FLOW_PARTS)
    out['motion'] = 100.0 - out['standby']
    return out


class _Ops:
    def __init__(self, absf, step):
        self.abs, self.step = absf, step


_NUMPY = _Ops(np.abs, lambda x: (np.asarray(x) >= 0).astype(float))


def _casadi_ops(eps: float) -> _Ops:
    import casadi as ca
    if eps > 0:
        return _Ops(lambda x: ca.sqrt(x ** 2 + eps ** 2),
                    lambda x: 0.5 * (1 + x / ca.sqrt(x ** 2 + eps ** 2)))
    return _Ops(ca.fabs, lambda x: ca.if_else(x >= 0, 1, 0))


def _pos(ops, x):
    return 0.5 * (x + ops.abs(x))


def _neg(ops, x):
    return 0.5 * (x - ops.abs(x))


def _axis_power(ops, m: ElectricalModel, i: int, tau, qd, eps):
    em = float(m.gear_efficiency_motoring[i])
    eg = float(m.gear_efficiency_generating[i])
    pj = tau * qd
    s = ops.step(pj)
    pg = s * pj / em + (1 - s) * eg * pj
    taum = tau / float(m.gear_ratio[i]) * (s / em + (1 - s) * eg)
    pcu = float(m.resistance[i]) * (taum / float(m.torque_constant[i])) ** 2
    pe = pg + pcu
    ed = float(m.drive_efficiency)
    return _pos(ops, pe) / ed + _neg(ops, pe) * ed + float(m.drive_idle_power[i])


def _bus_power(ops, m: ElectricalModel, pax: list, mode: str, eps):
    if mode not in BUS_MODES:
        raise ValueError(f'bus mode {mode!r} unknown; one of {list(BUS_MODES)}')
    if mode == BUS_NONE:
        total = sum(_pos(ops, p) for p in pax)
    else:
        net = sum(pax)
        total = _pos(ops, net)
        if mode == BUS_REGENERATIVE:
            total = total + float(m.regenerative_efficiency) * _neg(ops, net)
    return total + float(m.standby_power)


def load_electrical(path: Path | None = None, dynamics_path: Path | None = None
                    ) -> ElectricalModel:
    """Load ``config/electrical.yaml`` (or ``path``); gear ratios from dynamics.yaml."""
    d = _load_yaml(path or config_path('electrical.yaml'))
    try:
        ax = d['axes']
        ratio = load_dynamics(dynamics_path).gear_ratio
        vec = lambda k: np.asarray(ax[k], float)  # noqa: E731
        model = ElectricalModel(
            torque_constant=vec('torque_constant_nm_a'), resistance=vec('resistance_ohm'),
            gear_ratio=ratio, gear_efficiency_motoring=vec('gear_efficiency_motoring'),
            gear_efficiency_generating=vec('gear_efficiency_generating'),
            drive_idle_power=vec('drive_idle_power_w'),
            drive_efficiency=float(d['drive']['efficiency']),
            standby_power=float(d['controller']['standby_power_w']),
            bus_mode=str(d['bus']['mode']),
            regenerative_efficiency=float(d['bus']['regenerative_efficiency']))
    except KeyError as exc:
        raise ValueError(f'electrical parameters: missing key {exc}') from exc
    sizes = {model.torque_constant.size, model.resistance.size, model.gear_ratio.size,
             model.gear_efficiency_motoring.size, model.gear_efficiency_generating.size,
             model.drive_idle_power.size}
    if len(sizes) != 1:
        raise ValueError(f'electrical parameters: per-axis lists differ in length {sizes}')
    return model
