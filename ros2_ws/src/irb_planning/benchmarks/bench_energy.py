"""Electrical energy, placement and savings at the thesis circle (issue 17); JSON in results/.

    python benchmarks/bench_energy.py [--quick]

1. thesis placement (0.6, 0, 0.13) m, r 0.15 m: optimal timing per energy model against the
   trapezoid at 10 s, 5 s and 1.5 T_min (energies of the independently checked trajectory);
2. placement search in the 0.4 x 0.8 x 0.6 m box around the thesis centre (3 x 3 x 3 grid,
   both models), best placement + optimal timing against the trapezoid at the thesis placement;
3. the electrical breakdown of the 10 s plan (standby, copper, gearbox, drive shares).
"""
import argparse
import os
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import dump  # noqa: E402

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
    a = ap.parse_args()
    load0 = os.getloadavg()
    pl = Planner()
    out = {'load_average_start': load0, 'models': MODELS, 'thesis_center': THESIS.tolist()}
    # --- 1. timing at the thesis placement ---------------------------------------------
    t_min = pl.plan(PlanRequest(objective='time')).min_duration
    out['t_min_s'] = t_min
    rows = []
    for T in (10.0, 5.0, 1.5 * t_min):
        for model in MODELS:
            t0 = time.perf_counter()
            r = pl.plan(PlanRequest(duration=T, energy_model=model))
            wall = time.perf_counter() - t0
            e, b = measure(r.verification, model), measure(r.baseline, model)
            row = dict(duration_s=T, model=model, plan_j=e, trapezoid_j=b,
                       saving_pct=100 * (1 - e / b), wall_s=wall,
                       mechanical_j=float(r.verification.energy),
                       electrical=r.verification.electrical,
                       trapezoid_electrical=r.baseline.electrical)
            if model != 'mechanical':
                fixed = r.verification.electrical['standby'] + float(
                    np.sum(pl.electrical.drive_idle_power)) * T
                row['saving_of_motion_part_pct'] = 100 * (e - b) / (fixed - b)
            rows.append(row)
            print(f'T {T:.2f} s {model}: {e:.2f} J vs trapezoid {b:.2f} J '
                  f'({row["saving_pct"]:.2f} %), {wall:.0f} s', flush=True)
    out['thesis_placement'] = rows
    out['electrical_bound_gap'] = ('not computed: the convex lower bound exists for the '
                                   'mechanical model only (baselines.EnergyBound)')
    # --- 3. shares at 10 s ---------------------------------------------------------------
    r10 = [r for r in rows if r['duration_s'] == 10.0 and r['model'] == 'electrical_shared'][0]
    el = r10['electrical']
    tot = el['total_shared']
    out['shares_10s_electrical_optimum'] = {
        k: 100 * el[k] / tot for k in ('standby', 'copper', 'gear_loss', 'drive_loss',
                                       'mechanical')}
    out['published_shares'] = ('not compared: no published standby / copper-loss shares for '
                               'robots of this class were read in this session')
    # --- 2. placement ----------------------------------------------------------------------
    n = (2, 2, 2) if a.quick else (3, 3, 3)
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
    out['load_average_end'] = os.getloadavg()
    dump('energy', out)


if __name__ == '__main__':
    main()
