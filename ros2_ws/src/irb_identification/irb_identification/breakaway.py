"""Breakaway experiments: the static friction F_s and the Stribeck velocity v_s of one joint.

The sweeps of eq. 4.1 hold speeds of 0.1 rad/s and more; the wrist's Stribeck velocities are
0.03-0.07 rad/s, so the sweeps see no hump (F_s = F_c is all a fit of them can say), and the
sweep controller stick-slips at creep speeds. A breakaway run starts at rest with the other
joints held: the joint's torque rises slowly, ``rate`` [N m/s], from its holding torque (or
a preload below F_c), until the joint moves ``travel`` [rad]. While it sticks, friction
takes the whole ramp; the torque at which it starts is g + F_s (g the static load). Once it
slides, M q'' = tau - g - F(q'), and its first tenths of a second pass through the Stribeck
region.

``fit_breakaway`` (numpy/scipy, no ROS): per run the departure (the last sample within
``rest_band`` of the rest position) and the torque there from a straight line fitted to the
logged torque over the ramp (the effort's noise averages out); from a pair of runs, one per
direction, F_s = (tau_b+ - tau_b-) / 2 and g = (tau_b+ + tau_b-) / 2 to start from (no model
of g needed); then F_s, g, v_s and F_c by least squares of the joint's positions around the
departures against a 1-DOF integration of M q'' = tau(t) - g - F(q') (stuck while |tau - g|
<= F_s) with F_v from the sweeps and M = M_jj of the model (scipy ``solve_ivp``,
``least_squares``); the pairs averaged.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: [rad] a sample within this of the rest position is at rest (the encoder's 2e-6 rad
#: resolution and 1e-6 rad noise, with margin)
REST_BAND_RAD = 1e-5
#: [s] of the logged position after the departure that the v_s fit compares
FIT_WINDOW_S = 0.25
#: [s] into the ramp before its torque line is fitted (the drive's delay after a preload step)
RAMP_SKIP_S = 0.05
#: [s] of the logged position before the detected departure the fit compares as well
REST_LEAD_S = 0.1
#: model evaluations per start of a pair's least squares (a good pair converges in 10-30; a
#: run the model does not describe would otherwise spend minutes finding that out)
MAX_EVALUATIONS = 60
#: [rad] largest position RMS of a pair's fit that is accepted (200 x the encoder's noise;
#: the six-joint simulator's runs fit to 0.001-0.003 mrad, at a 0.806 ms step to 0.4)
MAX_POSITION_RMS_RAD = 2e-4


class BreakawayError(ValueError):
    """A breakaway run that cannot be read (no departure, too few samples)."""


@dataclass(frozen=True)
class Departure:
    """One run's departure: time [s], torque there [N m] (the ramp's fitted line), direction
    (+1 / -1), the ramp's fitted rate [N m/s] and its residual std [N m]."""

    t: float
    torque: float
    direction: int
    rate: float
    residual: float


@dataclass(frozen=True)
class BreakawayFit:
    """Means over the pairs of runs: F_s [N m], g [N m] (static load at the pose), v_s
    [rad/s]; the spreads (std between the pairs, 0 for one pair); the worst pair's position
    residual [rad] (RMS), the number of pairs and the fit's own F_c."""

    static: float
    static_spread: float
    load: float
    stribeck_velocity: float
    stribeck_velocity_spread: float
    position_rms: float
    pairs: int
    coulomb: float = float('nan')     # [N m] F_c of the fit (a nuisance: the sweeps' is kept)


def rest_position(t: np.ndarray, q: np.ndarray, ramp_start: float,
                  rest_band: float = REST_BAND_RAD) -> float:
    """The joint's position [rad] over the last REST_LEAD_S before the ramp (the median);
    BreakawayError if it was not at rest there (moved by more than 2 rest bands)."""
    t, q = np.asarray(t, float), np.asarray(q, float)
    last = (t < ramp_start) & (t >= ramp_start - REST_LEAD_S)
    if last.sum() < 3:
        raise BreakawayError('fewer than 3 samples just before the ramp: no rest position')
    if np.ptp(q[last]) > 2 * rest_band:
        raise BreakawayError(f'the joint was not at rest before the ramp: it moved by '
                             f'{np.ptp(q[last]) * 1e3:.3f} mrad in the last {REST_LEAD_S:g} s')
    return float(np.median(q[last]))


def departure(t: np.ndarray, q: np.ndarray, tau: np.ndarray, ramp_start: float,
              direction: int, rest_band: float = REST_BAND_RAD) -> tuple[Departure, int]:
    """The run's departure and the index of its last sample at rest. t (N,) [s], q (N,)
    [rad], tau (N,) [N m] logged torque of the joint; ``ramp_start`` [s]."""
    t, q, tau = (np.asarray(x, float) for x in (t, q, tau))
    q0 = rest_position(t, q, ramp_start, rest_band)
    moved = np.flatnonzero((np.abs(q - q0) > rest_band) & (t >= ramp_start))
    if moved.size == 0:
        raise BreakawayError('the joint never left its rest position: no breakaway within '
                             f'the ramp (largest torque {np.abs(tau).max():.3f} N m)')
    k = int(moved[0]) - 1
    # the line from RAMP_SKIP_S into the ramp: a preload steps the torque at its start,
    # and the logged (applied) torque follows the command samples later
    on = (t >= ramp_start + RAMP_SKIP_S) & (np.arange(t.size) <= k)
    if on.sum() < 10:
        raise BreakawayError(f'the joint left its rest {t[k] - ramp_start:.3f} s into the '
                             'ramp: start the ramp lower or slower')
    a, b = np.polyfit(t[on], tau[on], 1)
    res = float(np.std(tau[on] - (a * t[on] + b)))
    return Departure(float(t[k]), float(a * t[k] + b), int(direction), float(a), res), k


def _simulate(t: np.ndarray, q0: float, a: float, b: float, g: float, inertia: float,
              coulomb: float, static: float, vs: float, viscous: float,
              direction: int) -> np.ndarray:
    """q(t) at the times t of a joint at rest at q0 under the ramp tau(t) = a + b t: stuck
    while |tau - g| <= F_s, then M q'' = tau(t) - g - F(q') (Coulomb + viscous + Stribeck),
    sliding in ``direction`` (1-DOF, scipy LSODA)."""
    from scipy.integrate import solve_ivp

    t_go = (g + direction * static - a) / b
    q = np.full(t.size, q0, float)
    moving = t > t_go
    if not moving.any():
        return q

    def rhs(s, y):
        v = y[1]
        f = (coulomb + (static - coulomb) * np.exp(-(v / vs) ** 2)) * direction + viscous * v
        return [v, (a + b * s - g - f) / inertia]

    sol = solve_ivp(rhs, (t_go, t[-1]), [q0, 0.0], t_eval=t[moving], method='LSODA',
                    rtol=1e-8, atol=1e-12, max_step=1e-3)
    if not sol.success or sol.y.shape[1] != moving.sum():
        return np.full(t.size, np.nan)
    q[moving] = sol.y[0]
    return q


def _fit_pair(pair, inertia: float, coulomb: float, viscous: float, window_s: float,
              good_rms: float = 0.0):
    """(F_s, g, v_s, position RMS, F_c) of one pair of runs (one per direction), each entry
    (Departure, index of its last rest sample, run mapping); the starts of v_s end at the
    first whose fit is within ``good_rms``. F_c is fitted too, within
    10 % of the sweeps' ``coulomb``: the sliding after the departure depends on it, and the
    sweeps' 0.4 % (joint 6: 0.9416 for 0.9375 N m) took v_s to 0.035 for 0.040 rad/s."""
    from scipy.optimize import least_squares

    (up, _, _), (down, _, _) = pair
    static, load = 0.5 * (up.torque - down.torque), 0.5 * (up.torque + down.torque)
    if not static > coulomb:
        raise BreakawayError(f'breakaway torque {static:.3f} N m is not above the sweeps\' '
                             f'Coulomb level {coulomb:.3f} N m: no Stribeck hump to fit')
    segs = []
    for d, _, r in pair:
        t, q = np.asarray(r['t'], float), np.asarray(r['q'], float)
        end = min(d.t + window_s, float(r.get('release', np.inf)))
        sel = (t >= d.t - REST_LEAD_S) & (t <= end)
        if (t[sel] > d.t).sum() < 5:
            raise BreakawayError(f'fewer than 5 samples between the departure at {d.t:.3f} s '
                                 'and the release')
        q_rest = rest_position(t, q, r['ramp_start'])
        segs.append((t[sel], q[sel], q_rest, d.torque - d.rate * d.t, d.rate, d.direction))

    def residual(x):
        static_x, load_x, vs, fc = float(x[0]), float(x[1]), float(np.exp(x[2])), float(x[3])
        err = [_simulate(ts, q0, a, b, load_x, inertia, fc, static_x, vs, viscous, sgn)
               - qs for ts, qs, q0, a, b, sgn in segs]
        e = np.concatenate(err)
        return np.where(np.isfinite(e), e, 1.0)

    # the departure detected on the samples is late (the joint has moved less than the
    # rest band for a sample or two) and the ramp's line is noisy: F_s, g, v_s and F_c are
    # fitted together to the positions around the two departures, from the detected F_s
    # and g, the sweeps' F_c and several v_s (the cost has local minima in v_s)
    best = None
    for vs0 in (0.03, 0.01, 0.1):
        sol = least_squares(residual, [static, load, np.log(vs0), coulomb],
                            bounds=([coulomb, load - 0.5 * (static - coulomb), np.log(1e-3),
                                     0.9 * coulomb],
                                    [2.0 * static, load + 0.5 * (static - coulomb),
                                     np.log(0.5), min(1.1 * coulomb, static)]),
                            x_scale=[0.01, 0.01, 0.1, 0.01], xtol=1e-8, ftol=1e-10,
                            max_nfev=MAX_EVALUATIONS)
        if best is None or sol.cost < best.cost:
            best = sol
        if np.sqrt(2.0 * best.cost / best.fun.size) <= good_rms:
            break
    e = residual(best.x)
    return (float(best.x[0]), float(best.x[1]), float(np.exp(best.x[2])),
            float(np.sqrt(np.mean(e ** 2))), float(best.x[3]))


def fit_breakaway(runs, inertia: float, coulomb: float, viscous: float,
                  window_s: float = FIT_WINDOW_S, max_rms: float = MAX_POSITION_RMS_RAD
                  ) -> BreakawayFit:
    """F_s, g and v_s of one joint from breakaway runs, each a mapping with t, q, tau (the
    joint's columns), ramp_start [s], direction (+1 / -1) and release [s] (when the ramp was
    handed back to the holding controller; the fit stops there). Runs are paired in order,
    one per direction; each pair is fitted on its own (two departures fix F_s and g; the
    noise of each run's ramp line moves its departure by milliseconds, which one common F_s
    for all runs cannot follow) and the pairs' results are averaged, their standard
    deviation the spread. ``inertia`` M_jj [kg m^2]; ``coulomb`` [N m] and ``viscous`` [N m
    s/rad] from the sweeps. BreakawayError (one line) on runs that cannot be read or whose
    motion after the departure does not follow the model (position RMS above ``max_rms``)."""
    deps = []
    for r in runs:
        d, k = departure(r['t'], r['q'], r['tau'], r['ramp_start'], r['direction'])
        deps.append((d, k, r))
    ups = [x for x in deps if x[0].direction > 0]
    downs = [x for x in deps if x[0].direction < 0]
    if not ups or not downs:
        raise BreakawayError('breakaway needs a run in each direction (the static load '
                             'cancels between them)')
    fits = np.array([_fit_pair(p, inertia, coulomb, viscous, window_s, 0.1 * max_rms)
                     for p in zip(ups, downs)])
    worst = float(fits[:, 3].max())
    if worst > max_rms:
        raise BreakawayError(f'the motion after the departure does not follow the friction '
                             f'model: position RMS {worst * 1e3:.3f} mrad > '
                             f'{max_rms * 1e3:.3f} (a coarse simulator step, another '
                             'friction law, or a joint that was not at rest)')
    return BreakawayFit(float(fits[:, 0].mean()), float(fits[:, 0].std()),
                        float(fits[:, 1].mean()), float(fits[:, 2].mean()),
                        float(fits[:, 2].std()), worst, len(fits), float(fits[:, 4].mean()))
