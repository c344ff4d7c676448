"""Electrical energy, placement and savings at the thesis circle (issue 17); JSON in results/.

    python benchmarks/bench_energy.py [--quick] [--section timing placement pareto]

1. ``timing``: thesis placement (0.6, 0, 0.13) m, r 0.15 m: optimal timing per energy model
   against the trapezoid at 10 s, 5 s and 1.5 T_min (energies of the independently checked
   trajectory), the convex lower bound of each model and the gap (plan - bound) / plan, and
   the electrical breakdown of the 10 s plan (standby, copper, gearbox, drive shares);
2. ``placement``: placement search in the 0.4 x 0.8 x 0.6 m box around the thesis centre
   (3 x 3 x 3 grid, both models), best placement + optimal timing against the trapezoid at
   the thesis placement;
3. ``pareto``: energy vs duration for both models at the thesis placement and at each model's
   best placement (from the placement section, this run's or the stored energy.json), the
   Pareto front, its knee (the front point farthest below the chord between the front's
   ends, both axes scaled to [0, 1] over the front) and, for the electrical model, the
   minimum-energy duration (a free-duration plan with a negligible time weight);
   results/pareto_energy.png.
Default: timing and placement. The sections run are merged into results/energy.json (the
others keep their stored values).
"""
import argparse
import json
import os
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import RESULTS, dump  # noqa: E402

from irb_planning.placement import Region, search  # noqa: E402
from irb_planning.planner import Planner  # noqa: E402
from irb_planning.request import PlanRequest  # noqa: E402

THESIS = np.array([0.6, 0.0, 0.13])
MODELS = ('mechanical', 'electrical_shared')


def measure(ev, model):
    if model == 'mechanical':
        return float(ev.energy)
    return float(ev.electrical['total_' + model.split('_', 1)[1]])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--quick', action='store_true', help='2 x 2 x 2 placement grid')
    ap.add_argument('--section', nargs='+', default=['timing', 'placement'],
                    choices=['timing', 'placement', 'pareto', 'replot'],
                    help="'replot': the Pareto PNG and knees from the stored JSON only")
    ap.add_argument('--pareto-grid', type=int, default=100, help='theta nodes of the sweep')
    a = ap.parse_args()
    stored = RESULTS / 'energy.json'
    out = json.loads(stored.read_text()) if stored.exists() else {}
    pl = Planner()
    load0 = os.getloadavg()
    out.update({'models': MODELS, 'thesis_center': THESIS.tolist()})
    for section in a.section:
        t0 = time.perf_counter()
        if section == 'replot':
            plot_pareto(out)
            continue
        {'timing': timing, 'placement': placement, 'pareto': pareto}[section](pl, out, a)
        out[f'{section}_load_average'] = {'start': load0, 'end': os.getloadavg()}
        out[f'{section}_wall_s'] = time.perf_counter() - t0
        load0 = os.getloadavg()
    dump('energy', out)


def timing(pl, out, a):
    """Section 1: optimal timing vs trapezoid at the thesis placement, bounds and gaps."""
    t_min = pl.plan(PlanRequest(objective='time')).min_duration
    out['t_min_s'] = t_min
    rows = []
    for T in (10.0, 5.0, 1.5 * t_min):
        for model in MODELS:
            t0 = time.perf_counter()
            r = pl.plan(PlanRequest(duration=T, energy_model=model))
            wall = time.perf_counter() - t0
            e, b = measure(r.verification, model), measure(r.baseline, model)
            t0 = time.perf_counter()
            bound = pl.bound(PlanRequest(duration=T, energy_model=model), T)
            row = dict(duration_s=T, model=model, plan_j=e, trapezoid_j=b,
                       saving_pct=100 * (1 - e / b), wall_s=wall,
                       bound_j=bound, gap_to_bound_pct=100 * (e - bound) / e,
                       max_possible_saving_vs_trapezoid_pct=100 * (1 - bound / b),
                       bound_wall_s=time.perf_counter() - t0,
                       mechanical_j=float(r.verification.energy),
                       electrical=r.verification.electrical,
                       trapezoid_electrical=r.baseline.electrical)
            if model != 'mechanical':
                fixed = r.verification.electrical['standby'] + float(
                    np.sum(pl.electrical.drive_idle_power)) * T
                row['saving_of_motion_part_pct'] = 100 * (e - b) / (fixed - b)
                row['gap_of_motion_part_pct'] = 100 * (e - bound) / (e - fixed)
            rows.append(row)
            print(f'T {T:.2f} s {model}: {e:.2f} J vs trapezoid {b:.2f} J '
                  f'({row["saving_pct"]:.2f} %), bound {bound:.2f} J (gap '
                  f'{row["gap_to_bound_pct"]:.2f} %), {wall:.0f} s', flush=True)
    out['thesis_placement'] = rows
    out.pop('electrical_bound_gap', None)
    # --- shares at 10 s ------------------------------------------------------------------
    r10 = [r for r in rows if r['duration_s'] == 10.0 and r['model'] == 'electrical_shared'][0]
    el = r10['electrical']
    tot = el['total_shared']
    out['shares_10s_electrical_optimum'] = {
        k: 100 * el[k] / tot for k in ('standby', 'copper', 'gear_loss', 'drive_loss',
                                       'mechanical')}
    out['published_shares'] = ('not compared: no published standby / copper-loss shares for '
                               'robots of this class were read in this session')


def placement(pl, out, a):
    """Section 2: the placement search for both models."""
    n = (2, 2, 2) if a.quick else (3, 3, 3)
    rows = out['thesis_placement']
    region = Region(THESIS + [-0.2, -0.4, -0.3], THESIS + [0.2, 0.4, 0.3])
    out['region'] = {'lo': region.lo.tolist(), 'hi': region.hi.tolist(), 'n': n}
    place = []
    for model in MODELS:
        res = search(pl, PlanRequest(duration=10.0, energy_model=model), region, n,
                     coarse_grid=40, refine=2, min_step=0.05,
                     progress=lambda s: print(s, flush=True))
        base = [r for r in rows if r['duration_s'] == 10.0 and r['model'] == model][0]
        place.append(dict(
            model=model, best_center=res.best_center.tolist(), best_energy_j=res.best_energy,
            trapezoid_thesis_j=base['trapezoid_j'],
            saving_vs_trapezoid_thesis_pct=100 * (1 - res.best_energy / base['trapezoid_j']),
            region_lower_bound_j=res.region_lower_bound,
            possible_improvement_pct=res.possible_improvement_pct,
            cells_covered=res.cells_covered, cells_total=res.cells_total,
            certificate_cap_pct=100 * (1 - min(res.region_lower_bound, res.best_energy)
                                       / base['trapezoid_j']),
            refused=len(res.reasons), points=int(res.energy.size),
            evaluations=res.evaluations, search_wall_s=res.wall_time,
            map_j=np.where(np.isnan(res.energy), None, res.energy).tolist()))
        if model == 'electrical_shared' and res.best_plan is not None:
            place[-1]['best_plan_mechanical_j'] = float(res.best_plan.verification.energy)
    out['placement'] = place


def knee(T, E):
    """Index of the front point farthest below the chord between the front's first and last
    points, T and E scaled to [0, 1] over the front (None with fewer than 3 points)."""
    T, E = np.asarray(T, float), np.asarray(E, float)
    if T.size < 3:
        return None
    t = (T - T[0]) / (T[-1] - T[0])
    e = (E - E[-1]) / (E[0] - E[-1])
    # chord from (0, 1) to (1, 0): distance below it ~ 1 - t - e
    return int(np.argmax(1 - t - e))


def front(T, E):
    """Indices (increasing T) of the Pareto-optimal points: no other point is both shorter
    and uses less energy."""
    order = np.argsort(T)
    keep, best = [], np.inf
    for i in order:
        if E[i] < best:
            keep.append(int(i))
            best = E[i]
    return keep


def pareto(pl, out, a):
    """Section 3: energy vs duration for both models at the thesis and the best placements,
    the front and its knee; one PNG."""
    from irb_planning.costs import time_weight
    best = {p['model']: p['best_center'] for p in out.get('placement', [])}
    factors = (1.1, 1.3, 1.6, 2.0, 3.0, 5.0, 8.0)
    curves = []
    w_cost = time_weight(0.25, 40.0)
    for model in MODELS:
        places = [('thesis', THESIS.tolist())]
        if model in best:
            places.append(('best', best[model]))
        for name, centre in places:
            t0 = time.perf_counter()
            base = PlanRequest(center=np.asarray(centre, float), grid_size=a.pareto_grid,
                               energy_model=model)
            t_min = pl.plan(replace(base, objective='time')).min_duration
            Ts = sorted(set([float(f * t_min) for f in factors] + [10.0]))
            E, tz = [], []
            for T in Ts:
                r = pl.plan(replace(base, duration=T))
                E.append(measure(r.verification, model))
                tz.append(measure(r.baseline, model))
                print(f'pareto {model} {name} T {T:.3f} s: {E[-1]:.2f} J', flush=True)
            c = dict(model=model, placement=name, center=list(centre), t_min_s=t_min,
                     duration_s=Ts, energy_j=E, trapezoid_j=tz)   # trapezoid: same Ts
            if model != 'mechanical':
                # minimum-energy duration: free duration, negligible time weight
                r = pl.plan(replace(base, duration=0.0, time_weight=1e-9))
                c['min_energy_duration_s'] = float(r.verification.duration)
                c['min_energy_j'] = measure(r.verification, model)
                Ts.append(c['min_energy_duration_s'])
                E.append(c['min_energy_j'])
                print(f'pareto {model} {name} free: T {Ts[-1]:.3f} s {E[-1]:.2f} J',
                      flush=True)
            c['wall_s'] = time.perf_counter() - t0
            curves.append(c)
    out['pareto'] = dict(
        curves=curves, grid=a.pareto_grid, duration_factors_of_t_min=factors,
        knee_definition='the front point farthest below the chord between the front\'s '
        'ends, duration and energy each scaled to [0, 1] over the front; where the front '
        'has fewer than 3 points (electrical: it ends at the minimum-energy duration T*, '
        'just above T_min) the knee is T* itself (dE/dT = 0: the cost optimum at zero time '
        'value; any longer cycle costs more energy and more time)',
        cost_time_weight_j_per_s=w_cost,
        cost_time_weight_note='0.25 /kWh and 40 /h (costs.time_weight): far above every '
        '-dE/dT on the fronts, so the cost-optimal cycle is the shortest feasible one')
    plot_pareto(out)


def mark_knees(curves):
    """Front and knee of every curve (see pareto's knee_definition)."""
    for c in curves:
        Ta, Ea = np.array(c['duration_s']), np.array(c['energy_j'])
        f = front(Ta, Ea)
        c['front'] = f
        k = knee(Ta[f], Ea[f])
        if k is not None:
            kk = f[k]
            c['knee'] = dict(duration_s=float(Ta[kk]), energy_j=float(Ea[kk]))
            # the time value [J/s] at which the knee is the cost optimum: -dE/dT there
            # (central difference on the front)
            lo_, hi_ = f[max(k - 1, 0)], f[min(k + 1, len(f) - 1)]
            c['knee']['minus_dE_dT_j_per_s'] = float(-(Ea[hi_] - Ea[lo_])
                                                     / (Ta[hi_] - Ta[lo_]))
        elif 'min_energy_duration_s' in c:
            c['knee'] = dict(duration_s=c['min_energy_duration_s'],
                             energy_j=c['min_energy_j'], minus_dE_dT_j_per_s=0.0,
                             note='front shorter than 3 points: T* (minimum energy)')


def plot_pareto(out):
    """results/pareto_energy.png from out['pareto'] (fronts and knees recomputed)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    curves = out['pareto']['curves']
    mark_knees(curves)
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.6), constrained_layout=True)
    for ax, model in zip(axs, MODELS):
        for i, c in enumerate(x for x in curves if x['model'] == model):
            T, E = np.array(c['duration_s']), np.array(c['energy_j'])
            o = np.argsort(T)
            lab = f"{c['placement']} ({', '.join(f'{v:.2f}' for v in c['center'])}) m"
            ax.plot(T[o], E[o], 'o-', color=f'C{i}', alpha=0.5, label=lab)
            f = c['front']
            ax.plot(T[f], E[f], '-', color=f'C{i}', lw=2.5)
            if 'knee' in c:
                ax.plot(c['knee']['duration_s'], c['knee']['energy_j'], '*', ms=16,
                        color=f'C{i}', mec='k',
                        label=f"knee {c['knee']['duration_s']:.2f} s, "
                              f"{c['knee']['energy_j']:.1f} J")
            if 'min_energy_duration_s' in c:
                ax.axvline(c['min_energy_duration_s'], color=f'C{i}', ls=':', lw=1,
                           label=f"T* (minimum energy) {c['min_energy_duration_s']:.3f} s")
        ax.set(xscale='log', yscale='log', xlabel='duration T [s]',
               ylabel=f'{model} energy [J]', title=f'{model}: energy vs cycle duration '
               '(thick: Pareto front)')
        ax.grid(True, which='both', alpha=0.3)
        ax.legend(fontsize=8)
    fig.savefig(RESULTS / 'pareto_energy.png', dpi=110)
    plt.close(fig)


if __name__ == '__main__':
    main()
