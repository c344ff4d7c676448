"""Energies on the thesis circle at 1.1x, 1.5x, 2x the time-optimal duration and at 10 s.

    python ros2_ws/src/irb_planning/benchmarks/bench_circle.py [--grid 200] [--no-pareto]

Every energy is the independent evaluator's (1 kHz). Rest-to-rest: transcription, trapezoid,
time-optimal stretched, bound. Periodic (theta_dot(0) = theta_dot(2 pi) > 0, as the thesis):
transcription and Fourier 3/5/7. Also writes results/pareto.png (energy vs duration).

Timing-independent energy (``timing_independent``): along the path, gravity work
W_g = int sum_i |g_i Phi'_i| dtheta and Coulomb work W_c = int sum_i F_c,i |Phi'_i| dtheta
do not depend on the timing; neither does the quasi-static energy
E_qs = int sum_i |g_i Phi'_i + F_c,i |Phi'_i|| dtheta (the T -> infinity limit of E with the
Stribeck bump ignored: Coulomb friction brakes a joint that gravity drives, so E_qs < W_g + W_c).
Each row reports the controllable part E - E_qs of the plan and of the trapezoid and the saving
as a fraction of it.
"""
import argparse
import time

import numpy as np
from _common import RESULTS, dump
from irb_description.path import thesis_circle

from irb_planning.evaluator import evaluate
from irb_planning.planner import Planner, PlannerSettings
from irb_planning.request import PlanError, PlanRequest


def timing_independent(planner, path, n=4001):
    """W_g, W_c, W_g + W_c and E_qs [J] of ``path`` on n uniform theta points."""
    theta = np.linspace(0.0, 2 * np.pi, n)
    jp = planner.sample_path(path)(theta)
    zero = np.zeros_like(jp.q)
    g = planner._inverse_dynamics(jp.q, zero, zero)
    fc = np.array([j.coulomb for j in planner.model.friction.joints])
    grav = g * jp.dq
    coul = fc * np.abs(jp.dq)
    w_g = float(np.trapezoid(np.abs(grav).sum(axis=1), theta))
    w_c = float(np.trapezoid(coul.sum(axis=1), theta))
    e_qs = float(np.trapezoid(np.abs(grav + coul).sum(axis=1), theta))
    return {'gravity_work_J': w_g, 'coulomb_work_J': w_c, 'gravity_plus_coulomb_J': w_g + w_c,
            'quasi_static_J': e_qs}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--grid', type=int, default=200)
    ap.add_argument('--no-pareto', action='store_true')
    a = ap.parse_args()
    planner = Planner(settings=PlannerSettings(grid_size=a.grid))
    path = thesis_circle()
    sample = planner.sample_path(path)
    torque = planner.torque(planner.model.friction)
    top = planner.plan(PlanRequest(objective='time'))
    top_p = planner.plan(PlanRequest(objective='time', boundary='periodic'))
    t_min = top.min_duration
    _, checked = planner._limits(planner.plan(PlanRequest(duration=3.0)).request,
                                 planner.model.friction)
    fixed = timing_independent(planner, path)
    e_qs = fixed['quasi_static_J']
    rows = []
    for label, T in [('1.1x', 1.1 * t_min), ('1.5x', 1.5 * t_min), ('2x', 2 * t_min),
                     ('10s', 10.0)]:
        row = {'label': label, 'duration_s': T}

        def run(key, **kw):
            try:
                r = planner.plan(PlanRequest(**kw))
                row[key] = r.evaluation.energy
                row[key + '_optimizer'] = r.optimizer_energy
                row[key + '_solve_s'] = r.solve_time
                return r
            except PlanError as exc:
                row[key] = None
                row[key + '_refused'] = f'code {exc.code}: {exc.message}'
        opt = run('transcription', duration=T)
        run('trapezoid', objective='trapezoid', duration=T)
        if opt is not None:
            row['trapezoid_feasible_note'] = opt.baseline.violations[:1]
            row['trapezoid_at_limits_ignored'] = opt.baseline.energy
        # time-optimal profile slowed uniformly to T (theta_dot scaled by t_min / T)
        pr = top.profile
        st = evaluate(pr.scaled_in_time(T / top.evaluation.duration), sample, torque, checked)
        row['time_optimal_stretched'] = st.energy
        row['time_optimal_stretched_ok'] = st.ok
        row['bound'] = planner.bound(PlanRequest(duration=T), T)
        if T >= top_p.min_duration:
            run('transcription_periodic', duration=T, boundary='periodic')
            for order in (3, 5, 7):
                run(f'fourier{order}', objective='fourier', fourier_order=order, duration=T)
        e, tz = row['transcription'], row.get('trapezoid_at_limits_ignored')
        if e and tz:
            row['saving_vs_trapezoid_pct'] = 100 * (1 - e / tz)
            # no rest-to-rest timing on this grid can use less than the convex bound
            row['max_possible_saving_vs_trapezoid_pct'] = 100 * (1 - row['bound'] / tz)
        if e:
            row['gap_to_bound_pct'] = 100 * (e / row['bound'] - 1)
            row['gap_to_bound_optimizer_pct'] = 100 * (
                row['transcription_optimizer'] / row['bound'] - 1)
        if e and tz:
            row['controllable_transcription_J'] = e - e_qs
            row['controllable_trapezoid_J'] = tz - e_qs
            row['saving_of_controllable_pct'] = 100 * (tz - e) / (tz - e_qs)
        if row.get('transcription_periodic') and row.get('fourier7'):
            row['periodic_saving_vs_fourier7_pct'] = 100 * (
                1 - row['transcription_periodic'] / row['fourier7'])
        rows.append(row)
    data = {'grid': a.grid, 'min_duration_rest_s': t_min,
            'min_duration_periodic_s': top_p.min_duration,
            'time_optimal_energy_J': top.evaluation.energy,
            'timing_independent': fixed, 'rows': rows}
    if not a.no_pareto:
        data['pareto'] = pareto(planner, t_min)
    dump('circle', data)


def pareto(planner, t_min):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    Ts = np.geomspace(1.02 * t_min, 12.0, 16)
    out = {'duration_s': [], 'transcription_J': [], 'trapezoid_J': [], 'bound_J': [],
           'trapezoid_feasible': []}
    for T in Ts:
        r = planner.plan(PlanRequest(duration=float(T)))
        out['duration_s'].append(float(T))
        out['transcription_J'].append(r.evaluation.energy)
        out['trapezoid_J'].append(r.baseline.energy)
        out['trapezoid_feasible'].append(r.baseline.ok)
        out['bound_J'].append(planner.bound(PlanRequest(duration=float(T)), float(T)))
    fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
    ax.plot(Ts, out['transcription_J'], 'o-', label='energy-optimal (transcription)')
    ax.plot(Ts, out['bound_J'], 'k:', label='convex lower bound')
    tz = np.array(out['trapezoid_J'])
    ok = np.array(out['trapezoid_feasible'])
    ax.plot(Ts[ok], tz[ok], 's--', label='trapezoid (feasible)')
    ax.plot(Ts[~ok], tz[~ok], 'x', color='C1', label='trapezoid (breaks a limit)')
    ax.axvline(t_min, color='grey', lw=0.8)
    ax.set(xscale='log', xlabel='duration T [s]', ylabel='energy E [J]',
           title='thesis circle: energy vs duration (rest to rest)')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend()
    fig.savefig(RESULTS / 'pareto.png', dpi=110)
    return out


if __name__ == '__main__':
    t0 = time.perf_counter()
    main()
    print(f'{time.perf_counter() - t0:.1f} s', flush=True)
