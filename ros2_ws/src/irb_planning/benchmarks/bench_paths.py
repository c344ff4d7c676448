"""Planning on paths beyond the circle (issue 18): a 10-segment polyline at N = 400 and
every path type, each success re-checked at 5 kHz.

    python ros2_ws/src/irb_planning/benchmarks/bench_paths.py [--grid 400] [--warm 30]

polyline10: a meander of 10 straight segments (a glue bead over a part) with 20-30 mm blends
in a plane tilted 15 deg. cold: a fresh Planner's first energy request (path check, sampling,
NLP construction, time-optimal and energy solves, checks). warm: ``--warm`` energy requests
on the built problem with durations drifting by up to 5 % per request (IPOPT time as
``solve_time``, and the whole plan() call) -- the circle's warm figure in bench_timing.py.
Every success is re-checked by the independent check at 5 kHz and 16 samples per segment on
a path re-built from the request (bench_random's standard: a success that fails it is an
"invalid success"). Per path type (line, arc, polyline, spline, rectangle): the energy plan at
1.5 x T_min + 1 s and the trapezoid at the same duration, saving and solve time.
``--profile``: one more warm polyline request under cProfile (cumulative time of the plan's
stages: solve, 1 kHz evaluation, message building, the independent check and its parts) and
IPOPT's own timers of that solve (function and derivative evaluations vs the rest of IPOPT,
i.e. its linear algebra), to say where a warm plan() call's time goes.
``--mumps-ordering``: IPOPT's mumps_pivot_order for the run (A/B against the planner's
problem.MUMPS_ORDERING, see bench_linear_solvers.py).
``--paired-band-rows K``: K warm polyline requests (durations drifting as above) planned by two
planners in turn, one whose problems carry the quarter-point rows of b that only a TCP speed
band needs (``Transcription(band_rows=True)``, as before 2026-11-26) and the planner as it is
(without them when no band is asked for): paired solve-time ratio, iterations, energies.
Writes results/paths.json (``--name`` to write another file).
"""
import argparse
import os
import time

import numpy as np
from _common import dump
from irb_description.path import path_from_spec, path_spec, rectangle_path

from irb_planning import problem
from irb_planning.planner import BOUNDARY_REST, Planner, PlannerSettings, request_path
from irb_planning.request import PlanError, PlanRequest
from irb_planning.verify import ArmKinematics, MapFriction, PathCurve, verify_plan


def meander(n_seg=10):
    """A meander of n_seg segments in a plane tilted 15 deg about x, about 0.7 m ahead."""
    tilt = np.radians(15)
    pts = []
    for k in range(n_seg + 1):      # x: 0.55 0.85 0.85 0.55 0.55 ...; y steps every 2 points
        pts.append([0.55 + 0.3 * ((k + 1) // 2 % 2), -0.2 + 0.4 * (k // 2) / (n_seg // 2),
                    0.0])
    pts = np.array(pts)
    z = 0.3 + np.tan(tilt) * pts[:, 1]
    pts[:, 2] = z
    return dict(type='polyline', waypoints=pts.tolist(),
                blend_radii=[0.02 + 0.01 * (k % 2) for k in range(n_seg - 1)])


WAY = [[0.55, -0.25, 0.25], [0.8, -0.2, 0.3], [0.85, 0.05, 0.4], [0.7, 0.2, 0.35],
       [0.55, 0.15, 0.3]]
TYPES = {
    'line': dict(type='line', waypoints=[[0.5, -0.2, 0.25], [0.8, 0.25, 0.45]]),
    'arc_tilted': dict(type='arc', center=[0.65, 0.0, 0.3], normal=[0.2, -0.4, 1.0],
                       radius=0.12, start_angle=0.4, sweep=-4.5),
    'polyline': dict(type='polyline', waypoints=WAY, blend_radii=[0.03, 0.05, 0.02]),
    'spline': dict(type='spline', waypoints=WAY),
    'spline_closed': dict(type='spline', waypoints=WAY, closed=True),
    'rectangle_tilted': path_spec(rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2,
                                                 0.025)),
}


def request(spec, **kw):
    f = dict(path_type=spec['type'])
    for k in ('center', 'normal', 'waypoints', 'blend_radii'):
        if k in spec:
            f[k] = np.asarray(spec[k], float)
    for k in ('radius', 'start_angle', 'sweep', 'closed'):
        if k in spec:
            f[k] = spec[k]
    return PlanRequest(**f, **kw)


def recheck(planner, res):
    """The success re-checked at 5 kHz, 16 samples per segment, on the request's path."""
    tr, req, pr = res.trajectory, res.request, res.profile
    lim = planner.model.limits
    kin = ArmKinematics(velocity=lim.velocity, torque=lim.torque, **planner._kin)
    fm = planner.model.friction.to_dict()['friction_map']['joints']
    path = request_path(req)
    return verify_plan(tr['t'], tr['q'], tr['qd'], tr['qdd'],
                       (pr.theta, pr.theta_dot, pr.theta_ddot_nodes, pr.quadratic),
                       PathCurve(path.point, path.d_point, path.dd_point, path.closed), kin,
                       planner.rigid_torque, MapFriction(fm, planner.model.joint_names),
                       req.boundary == BOUNDARY_REST, rate_hz=5000.0,
                       min_samples_per_segment=16)


#: (module file, function) of the plan's stages reported by --profile
STAGES = [('planner.py', '_plan'), ('planner.py', '_solve_checked'),
          ('transcription.py', 'solve'), ('planner.py', 'trajectory'),
          ('evaluator.py', 'evaluate'), ('verify.py', 'verify_plan'),
          ('verify.py', 'profile_segment_time'), ('verify.py', 'quintic'),
          ('verify.py', 'deviation'), ('planner.py', 'rigid_torque'),
          ('trajectory_rules.py', 'worst_inconsistency'), ('path.py', 'joint_path'),
          ('profile.py', 'theta_at'), ('planner.py', 'evaluate')]


def profile_one(planner, spec, T):
    """Where one warm plan() call's time goes: cProfile cumulative seconds per stage and
    IPOPT's timers (t_wall_*) of the transcription's solvers after it."""
    import cProfile
    import pstats
    prof = cProfile.Profile()
    s = time.perf_counter()
    prof.enable()
    r = planner.plan(request(spec, duration=T))
    prof.disable()
    out = {'plan_call_s': time.perf_counter() - s, 'solve_time_s': r.solve_time,
           'iterations': r.iterations, 'message_points': len(r.trajectory['t'])}
    stats = pstats.Stats(prof).stats
    cum = {}
    for (fname, _, func), (_, _, _, ct, _) in stats.items():
        for mod, name in STAGES:
            if fname.endswith(mod) and func == name:
                key = f'{mod[:-3]}.{name}'
                cum[key] = max(cum.get(key, 0.0), ct)
    out['cumulative_s'] = cum
    for entry in planner._cache.values():
        for label, solver in (('warm', entry.transcription._solver_warm),
                              ('cold', entry.transcription._solver_cold)):
            if solver is None:
                continue
            st = solver.stats()
            t = {k: float(v) for k, v in st.items() if k.startswith('t_wall_')}
            evals = sum(v for k, v in t.items() if k.startswith('t_wall_nlp_'))
            out[f'ipopt_{label}'] = {'iterations': int(st.get('iter_count', -1)),
                                     'status': str(st.get('return_status')), **t,
                                     'function_evaluations_s': evals,
                                     'rest_of_ipopt_s': t.get('t_wall_total', np.nan) - evals}
    return out


def paired_band_rows(spec, grid, k):
    """Warm solves with the quarter-point rows (forced) and without (the planner as it is),
    in turn, on the same requests: medians, the paired ratio and the energies' difference."""
    from irb_planning import planner as planner_module
    from irb_planning.transcription import Transcription

    class WithRows(Transcription):
        def __init__(self, *args, **kw):
            kw['band_rows'] = True
            super().__init__(*args, **kw)
    planners = {}
    try:
        for name, cls in (('with_rows', WithRows), ('without', Transcription)):
            planner_module.Transcription = cls
            pl = Planner(settings=PlannerSettings(grid_size=grid))
            tmin = pl.plan(request(spec, objective='time')).min_duration
            pl.plan(request(spec, duration=1.5 * tmin))
            planners[name] = pl
    finally:
        planner_module.Transcription = Transcription
    rng = np.random.default_rng(0)
    T = 1.5 * tmin
    rows = {name: [] for name in planners}
    for i in range(k):
        T = float(np.clip(T * rng.uniform(0.95, 1.05), 1.05 * tmin, 30.0))
        order = list(planners.items())
        for name, pl in (order if i % 2 == 0 else order[::-1]):
            r = pl.plan(request(spec, duration=T))
            rows[name].append((r.solve_time, r.iterations, r.verification.energy))
    w, wo = np.array(rows['with_rows']), np.array(rows['without'])
    return {'requests': k, 'median_solve_with_rows_s': float(np.median(w[:, 0])),
            'median_solve_without_s': float(np.median(wo[:, 0])),
            'paired_ratio_median': float(np.median(wo[:, 0] / w[:, 0])),
            'paired_ratio_min_max': [float(np.min(wo[:, 0] / w[:, 0])),
                                     float(np.max(wo[:, 0] / w[:, 0]))],
            'iterations_with_rows': w[:, 1].tolist(), 'iterations_without': wo[:, 1].tolist(),
            'energy_max_relative_difference': float(np.max(np.abs(wo[:, 2] / w[:, 2] - 1)))}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--grid', type=int, default=400)
    ap.add_argument('--warm', type=int, default=30)
    ap.add_argument('--no-types', action='store_true', help='only the 10-segment polyline')
    ap.add_argument('--profile', action='store_true',
                    help='profile one more warm polyline request (where the time goes)')
    ap.add_argument('--name', default='paths', help='results/<name>.json')
    ap.add_argument('--mumps-ordering', type=int, default=None,
                    help="IPOPT's mumps_pivot_order for this run (default: the planner's, "
                         'problem.MUMPS_ORDERING; 7 = IPOPT\'s automatic choice)')
    ap.add_argument('--paired-band-rows', type=int, default=0, metavar='K',
                    help='A/B: K warm requests with and without the quarter-point rows')
    ap.add_argument('--circle', action='store_true',
                    help='also the thesis circle warm at the same grid, same load (reference)')
    a = ap.parse_args()
    if a.mumps_ordering is not None:
        problem.MUMPS_ORDERING = a.mumps_ordering
    out = {'grid': a.grid, 'load_average_before': os.getloadavg(),
           'mumps_pivot_order': problem.MUMPS_ORDERING}
    spec = meander()
    path = path_from_spec(spec)
    invalid, successes = [], 0
    t0 = time.perf_counter()
    planner = Planner(settings=PlannerSettings(grid_size=a.grid))
    first = planner.plan(request(spec, objective='time'))
    T = 1.5 * first.min_duration
    t1 = time.perf_counter()
    r = planner.plan(request(spec, duration=T))
    t2 = time.perf_counter()
    out['polyline10'] = {'segments': len(spec['waypoints']) - 1, 'length_m': path.length,
                         'min_duration_s': first.min_duration,
                         'cold_first_request_s': t1 - t0,
                         'cold_time_optimal_solve_s': first.solve_time,
                         'first_energy_plan_call_s': t2 - t1, 'first_energy_solve_s':
                         r.solve_time}
    rng = np.random.default_rng(0)
    solve, total, iters = [], [], []
    for i in range(a.warm):
        T = float(np.clip(T * rng.uniform(0.95, 1.05), 1.05 * first.min_duration, 30.0))
        s = time.perf_counter()
        try:
            r = planner.plan(request(spec, duration=T))
        except PlanError as exc:
            out.setdefault('refused', []).append((T, exc.code, exc.message))
            continue
        total.append(time.perf_counter() - s)
        solve.append(r.solve_time)
        iters.append(r.iterations)
        successes += 1
        ver = recheck(planner, r)
        if not ver.ok:
            invalid.append(('polyline10', T, ver.problems))
        print(f'warm {i}: T = {T:.3f} s, solve {1e3 * r.solve_time:.0f} ms, '
              f'{r.iterations} it, call {total[-1]:.2f} s, 5 kHz recheck ok {ver.ok}',
              flush=True)
    out['polyline10']['warm'] = {
        'requests': len(solve), 'median_solve_s': float(np.median(solve)),
        'p90_solve_s': float(np.percentile(solve, 90)), 'max_solve_s': float(max(solve)),
        'median_plan_call_s': float(np.median(total)),
        'median_iterations': float(np.median(iters))}
    if a.profile:
        T = float(T * 1.01)
        out['polyline10']['profile'] = prof = profile_one(planner, spec, T)
        print('profile', prof, flush=True)
    if a.circle:
        cp = Planner(planner.model.copy(), PlannerSettings(grid_size=a.grid))
        Tc = 1.5 * cp.plan(PlanRequest(objective='time')).min_duration
        cp.plan(PlanRequest(duration=Tc))
        cs = []
        for i in range(a.warm):
            Tc = float(Tc * rng.uniform(0.95, 1.05))
            cs.append(cp.plan(PlanRequest(duration=Tc)).solve_time)
        out['thesis_circle_same_grid'] = {'median_solve_s': float(np.median(cs)),
                                          'max_solve_s': float(max(cs))}
        print('circle', out['thesis_circle_same_grid'], flush=True)
    if a.paired_band_rows:
        out['paired_band_rows'] = paired_band_rows(spec, a.grid, a.paired_band_rows)
        print('paired', out['paired_band_rows'], flush=True)
    per_type = {}
    for name, sp in ({} if a.no_types else TYPES).items():
        pl = Planner(planner.model.copy(), PlannerSettings(grid_size=a.grid))
        s = time.perf_counter()
        tmin = pl.plan(request(sp, objective='time')).min_duration
        Tn = 1.5 * tmin + 1.0
        row = {'length_m': path_from_spec(sp).length, 'min_duration_s': tmin,
               'duration_s': Tn}
        for obj in ('energy', 'trapezoid'):
            rr = pl.plan(request(sp, objective=obj, duration=Tn))
            ver = recheck(pl, rr)
            successes += 1
            if not ver.ok:
                invalid.append((name, obj, ver.problems))
            row[obj] = {'energy_J': rr.evaluation.energy, 'solve_s': rr.solve_time,
                        'max_path_deviation_um': 1e6 * rr.verification.max_path_deviation,
                        'points': len(rr.trajectory['t']), 'recheck_5khz_ok': ver.ok}
        row['saving_vs_trapezoid_pct'] = 100 * (1 - row['energy']['energy_J']
                                                / row['trapezoid']['energy_J'])
        row['wall_s'] = time.perf_counter() - s
        per_type[name] = row
        print(name, row, flush=True)
    out['types'] = per_type
    out['successes_rechecked'] = successes
    out['invalid_successes'] = len(invalid)
    out['invalid'] = invalid
    out['load_average_after'] = os.getloadavg()
    dump(a.name, out)


if __name__ == '__main__':
    main()
