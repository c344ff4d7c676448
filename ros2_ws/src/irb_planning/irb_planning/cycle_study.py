"""The work-cycle study (issue 29) on a planned cycle: the saving against the baselines at
the takt and its ceilings, per year, energy per cycle against the takt, and the saving's
sensitivity to each power-mode parameter (tornado). Re-solves the DP on the plan's fronts;
no planner call. Used by the main job (irb_bringup thesis_run) and benchmarks/bench_cycle.py.
No rclpy."""
from __future__ import annotations

from dataclasses import replace

GOAL_SAVING = 20.0          # [%] issue 29: at least 20 % less than baseline A at the takt

#: plausible ranges of the mode parameters (low, high) for the tornado; base = the YAML.
#: standby: the range of doc/electrical_published.md (150 W to the 400 W vendor ceiling)
RANGES = {
    'standby_power_w': (150.0, 400.0),
    'brake_coils_w': (20.0, 80.0),
    'bus_on_w': (15.0, 70.0),
    'bus_capacitance_f': (0.3e-3, 2.0e-3),
    'hold__brakes': (0.1, 1.0),          # transition durations [s]
    'brakes__hold': (0.2, 1.5),
    'brakes__bus_off': (0.2, 1.5),
    'bus_off__brakes': (1.0, 4.0),
    'hibernate_fraction': (0.05, 0.30),
    'bus_off__hibernate': (5.0, 60.0),
    'hibernate__bus_off': (20.0, 120.0),
}


def per_year(energy_j: float, takt_s: float, duty: dict) -> dict:
    cycles = duty['hours_per_year'] * 3600.0 / takt_s
    kwh = energy_j * cycles / 3.6e6
    return {'cycles_per_year': cycles, 'kwh_per_year': kwh,
            'cost_per_year': kwh * duty['price_per_kwh'], 'currency': duty['currency']}


def with_standby(plan, modes, standby_w):
    """Fronts, stations and modes of ``plan`` with another controller standby power: every
    electrical energy carries P_sb x duration (the standby is additive in the model), so the
    fronts shift by dP x d, the hold powers by dP; nothing is re-planned."""
    from irb_planning.cycle import Front, StationItem
    dp = standby_w - modes.standby_power_w
    fronts = {}
    for n, f in plan.fronts.items():
        pts = {d: dict(r, energy_j=r['energy_j'] + dp * r['duration_s'])
               for d, r in f.points.items()}
        fast = dict(f.fastest, energy_j=f.fastest['energy_j'] + dp * f.fastest['duration_s'])
        fronts[n] = Front(n, fast, pts, f.refused)
    items = [replace(it, holding_power_w=it.holding_power_w + dp)
             if isinstance(it, StationItem) else it for it in plan.items]
    return replace(plan, fronts=fronts, items=items, modes=modes.with_params(
        standby_power_w=float(standby_w)))


def saving_at(plan, takt, modes=None):
    from irb_planning.cycle import resolve_at_takt
    opt, a, b = resolve_at_takt(plan, takt, modes)
    return 100 * (1 - opt.total_j / a['total_j']), opt, a, b


def variant(plan, name, value):
    """(plan, modes) with one mode parameter set to ``value``."""
    pm = plan.modes
    if name == 'standby_power_w':
        p = with_standby(plan, pm, value)
        return p, p.modes
    return plan, pm.with_params(**{name: value})


def needed_value(plan, takt, name, lo, hi, goal=GOAL_SAVING):
    """Value of one parameter within [lo, hi] at which the saving reaches ``goal`` (bisection
    on a monotone response), or None if it does not within the range."""
    def s(v):
        p, m = variant(plan, name, v)
        return saving_at(p, takt, m)[0]
    s_lo, s_hi = s(lo), s(hi)
    if (s_lo - goal) * (s_hi - goal) > 0:
        return None
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if (s(mid) - goal) * (s_lo - goal) > 0:
            lo, s_lo = mid, s(mid)
        else:
            hi = mid
    return 0.5 * (lo + hi)


def section_gluing(plan, duty) -> dict:
    sol, a, b = plan.solution, plan.baseline_a, plan.baseline_b
    takt = sol.takt_s
    saving = 100 * (1 - sol.total_j / a['total_j'])
    # ceiling: every station at its chosen mode's power for its whole duration (transitions
    # free), and every station at the deepest mode's power (no transition at all)
    pm = plan.modes
    free = sol.total_j - sum(c['energy_j'] - pm.power_w(c['mode'], c['holding_power_w'])
                             * c['duration_s'] for c in sol.choices if c['kind'] == 'station')
    rest = sum(c['duration_s'] for c in sol.choices if c['kind'] == 'station')
    motions = sum(c['energy_j'] for c in sol.choices if c['kind'] == 'motion')
    hold_rest = sum(c['holding_power_w'] * c['duration_s'] for c in sol.choices
                    if c['kind'] == 'station')
    cap_bus_off = 100 * (1 - (motions + pm.power_w('bus_off') * rest) / a['total_j'])
    # baseline B taken literally: every motion at its longest planned duration, hold
    longest = {n: max(f.points) for n, f in plan.fronts.items()}
    e_long = sum(plan.fronts[n].points[d]['energy_j'] for n, d in longest.items())
    t_long = sum(longest.values())
    st_items = [it for it in plan.items if hasattr(it, 'holding_power_w')]
    fixed = sum(it.fixed_s for it in st_items)
    rest_long = takt - t_long - fixed
    first_wait = next(i for i, it in enumerate(st_items) if it.wait)
    b_literal = e_long + sum(pm.power_w('hold', it.holding_power_w) * (
        it.fixed_s + (rest_long if i == first_wait else 0.0)) for i, it in enumerate(st_items))
    needs = {}
    for name in ('bus_on_w', 'brake_coils_w', 'standby_power_w', 'bus_off__brakes'):
        lo, hi = RANGES[name]
        v = needed_value(plan, takt, name, lo, hi)
        needs[name] = v
    return {
        'takt_s': takt, 'energy_j': sol.total_j, 'baseline_a_j': a['total_j'],
        'baseline_b_j': b.total_j if b else None, 'saving_vs_a_percent': saving,
        'saving_vs_b_percent': 100 * (1 - sol.total_j / b.total_j) if b else None,
        'saving_b_vs_a_percent': 100 * (1 - b.total_j / a['total_j']) if b else None,
        'baseline_b_longest_j': b_literal, 'baseline_b_longest_durations_s': longest,
        'saving_vs_b_longest_percent': 100 * (1 - sol.total_j / b_literal),
        'goal_percent': GOAL_SAVING, 'goal_met': bool(saving >= GOAL_SAVING),
        'lower_bound_j': sol.lower_bound_j, 'gap_j': sol.gap_j, 'gap_percent': 100 * sol.gap_rel,
        'dp_time_s': sol.solve_time_s,
        'operations': sol.choices, 'baseline_a': a['choices'],
        'baseline_b': b.choices if b else None,
        'rest_s': rest, 'rest_hold_energy_j': hold_rest,
        'ceiling_transitions_free_percent': 100 * (1 - free / a['total_j']),
        'ceiling_all_rest_in_bus_off_percent': cap_bus_off,
        'parameter_for_goal': needs,
        'per_year': {k: per_year(v, takt, duty) for k, v in
                     (('plan', sol.total_j), ('baseline_a', a['total_j']),
                      ('baseline_b', b.total_j if b else float('nan')))},
        'duty': duty, 'power_modes': pm.as_dict(),
        'fronts': {n: {'durations_s': sorted(f.points),
                       'energies_j': [f.points[d]['energy_j'] for d in sorted(f.points)],
                       'time_optimal_s': f.fastest['duration_s'],
                       'time_optimal_j': f.fastest['energy_j']}
                   for n, f in plan.fronts.items()},
        'front_time_s': plan.front_time_s, 'plan_time_s': plan.plan_time_s}


def section_sweep(plan, takts) -> dict:
    rows = []
    for t in takts:
        try:
            s, opt, a, b = saving_at(plan, t)
        except ValueError as exc:
            rows.append({'takt_s': t, 'error': str(exc)})
            continue
        rows.append({'takt_s': t, 'plan_j': opt.total_j, 'baseline_a_j': a['total_j'],
                     'baseline_b_j': b.total_j, 'saving_vs_a_percent': s,
                     'gap_percent': 100 * opt.gap_rel,
                     'modes': [c['mode'] for c in opt.choices if c['kind'] == 'station']})
    return {'rows': rows}


def section_tornado(plan, takt) -> dict:
    base = saving_at(plan, takt)[0]
    pm = plan.modes
    base_values = {'standby_power_w': pm.standby_power_w, 'brake_coils_w': pm.brake_coils_w,
                   'bus_on_w': pm.bus_on_w, 'bus_capacitance_f': pm.bus_capacitance_f,
                   'hibernate_fraction': pm.hibernate_fraction}
    for t in pm.transitions:
        base_values[f'{t.src}__{t.dst}'] = t.duration_s
    rows = []
    for name, (lo, hi) in RANGES.items():
        out = {}
        for tag, v in (('low', lo), ('high', hi)):
            p, m = variant(plan, name, v)
            out[tag] = saving_at(p, takt, m)[0]
        rows.append({'parameter': name, 'base': base_values.get(name), 'low': lo, 'high': hi,
                     'saving_low_percent': out['low'], 'saving_high_percent': out['high'],
                     'span_percent': abs(out['high'] - out['low'])})
    rows.sort(key=lambda r: -r['span_percent'])
    return {'takt_s': takt, 'base_saving_percent': base, 'rows': rows}


def plot_sweep(sweep, takt, path):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    rows = [r for r in sweep['rows'] if 'plan_j' in r]
    t = [r['takt_s'] for r in rows]
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(7.5, 6), sharex=True,
                                  gridspec_kw={'height_ratios': [2, 1]})
    ax.plot(t, [r['baseline_a_j'] for r in rows], 'C3-', label='A: fastest motions, hold')
    ax.plot(t, [r['baseline_b_j'] for r in rows], 'C1--', label='B: durations chosen, hold')
    ax.plot(t, [r['plan_j'] for r in rows], 'C0-', lw=2, label='plan: durations + modes')
    ax.axvline(takt, color='0.5', ls=':')
    ax.set_ylabel('electrical energy per cycle [J]')
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax2.plot(t, [r['saving_vs_a_percent'] for r in rows], 'C0-')
    ax2.axhline(GOAL_SAVING, color='C2', ls='--', label=f'goal {GOAL_SAVING:g} %')
    ax2.axvline(takt, color='0.5', ls=':', label=f'stated takt {takt:g} s')
    ax2.set_xlabel('takt [s]')
    ax2.set_ylabel('saving vs A [%]')
    ax2.legend(fontsize=8)
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_tornado(tornado, path):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    rows = tornado['rows'][::-1]
    base = tornado['base_saving_percent']
    fig, ax = plt.subplots(figsize=(8, 0.45 * len(rows) + 1.5))
    for k, r in enumerate(rows):
        lo, hi = r['saving_low_percent'], r['saving_high_percent']
        ax.barh(k, lo - base, left=base, color='C0', alpha=0.8)
        ax.barh(k, hi - base, left=base, color='C3', alpha=0.8)
        ax.text(min(lo, hi) - 0.2, k, f'{r["low"]:g}', ha='right', va='center', fontsize=7)
        ax.text(max(lo, hi) + 0.2, k, f'{r["high"]:g}', ha='left', va='center', fontsize=7)
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels([r['parameter'] for r in rows], fontsize=8)
    ax.axvline(base, color='k', lw=1)
    ax.axvline(GOAL_SAVING, color='C2', ls='--', label=f'goal {GOAL_SAVING:g} %')
    ax.set_xlabel(f'saving vs baseline A at takt {tornado["takt_s"]:g} s [%] '
                  '(blue: low end, red: high end of the range)')
    ax.legend(fontsize=8, loc='lower right')
    ax.grid(axis='x', alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
