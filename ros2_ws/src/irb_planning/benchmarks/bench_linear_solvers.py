"""Where a warm polyline solve's time goes, and what the linear solvers here can do about it
(issue 18: <= 200 ms warm median at N = 400).

    python ros2_ws/src/irb_planning/benchmarks/bench_linear_solvers.py [--repeats 3]

On the 10-segment polyline of bench_paths.py at N = 400, after the planner's own energy plan,
the same NLP (its bounds, its cold initial guess) is solved again by IPOPT with each linear
solver and MUMPS ordering this CasADi build has, ``--repeats`` times each: median and spread
of the wall time per iteration, and IPOPT's own split (function evaluations vs the rest).
The KKT matrix of that NLP at its solution (exact Hessian of the Lagrangian + a positive
diagonal standing in for the barrier terms, the constraint Jacobian, -1e-8 I) is then
factored outside IPOPT by SciPy's SuperLU with a minimum-degree ordering: its fill and time
are what a fill-reducing sparse factorisation of this matrix costs, against which MUMPS's
per-iteration time is read. Writes results/linear_solvers.json.
"""
import argparse
import json
import os
import time

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from _common import RESULTS, dump
from bench_paths import meander, request

from irb_planning.planner import Planner, PlannerSettings
from irb_planning.problem import ipopt_options

VARIANTS = {
    'mumps (default ordering)': {},
    'mumps AMD': {'mumps_pivot_order': 0},
    'mumps AMF': {'mumps_pivot_order': 2},
    'mumps PORD': {'mumps_pivot_order': 4},
    'mumps METIS': {'mumps_pivot_order': 5},
    'mumps QAMD': {'mumps_pivot_order': 6},
    'spral': {'linear_solver': 'spral'},
}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--grid', type=int, default=400)
    ap.add_argument('--repeats', type=int, default=3)
    a = ap.parse_args()
    os.environ.setdefault('OMP_CANCELLATION', 'TRUE')    # SPRAL asks for both
    os.environ.setdefault('OMP_PROC_BIND', 'TRUE')
    out = {'grid': a.grid, 'load_average_before': os.getloadavg(), 'casadi': ca.__version__}
    spec = meander()
    planner = Planner(settings=PlannerSettings(grid_size=a.grid))
    first = planner.plan(request(spec, objective='time'))
    planner.plan(request(spec, duration=1.5 * first.min_duration))
    tr = next(e.transcription for e in planner._cache.values()
              if e.transcription._last is not None and e.transcription._last[3].duration > 0)
    x_opt, _, lam_g, req = tr._last
    lbx, ubx, lbg, ubg = tr._bounds(req)
    x0 = tr.initial_guess(req, lbx, ubx)
    par = [req.energy_weight, req.time_weight]
    nlp = tr._nlp
    out['variables'], out['rows'] = int(nlp['x'].numel()), int(nlp['g'].numel())
    rows = {}
    for name, extra in VARIANTS.items():
        per_it, its, evals, objective, status = [], [], [], [], []
        for _ in range(a.repeats):
            solver = ca.nlpsol('s', 'ipopt', nlp, ipopt_options(500, 1e-8, extra=extra))
            t0 = time.perf_counter()
            sol = solver(x0=x0, p=par, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
            wall = time.perf_counter() - t0
            st = solver.stats()
            n_it = max(1, int(st['iter_count']))
            per_it.append(1e3 * wall / n_it)
            its.append(n_it)
            evals.append(1e3 * sum(v for k, v in st.items() if k.startswith('t_wall_nlp_'))
                         / n_it)
            objective.append(float(sol['f']))
            status.append(str(st['return_status']))
        rows[name] = {'median_ms_per_iteration': float(np.median(per_it)),
                      'min_ms_per_iteration': float(min(per_it)),
                      'max_ms_per_iteration': float(max(per_it)),
                      'median_function_evaluations_ms_per_iteration': float(np.median(evals)),
                      'iterations': its, 'objective': objective, 'status': status}
        print(name, rows[name], flush=True)
    out['ipopt'] = rows
    x, lam = nlp['x'], ca.SX.sym('lam', nlp['g'].numel())
    jac = ca.Function('J', [x, nlp['p']], [ca.jacobian(nlp['g'], x)])(x_opt, par).sparse()
    hess = ca.Function('H', [x, nlp['p'], lam], [ca.hessian(nlp['f'] + ca.dot(lam, nlp['g']),
                                                            x)[0]])(x_opt, par, lam_g).sparse()
    rng = np.random.default_rng(0)
    n_x, n_g = jac.shape[1], jac.shape[0]
    kkt = sp.bmat([[hess + sp.diags(rng.uniform(1.0, 2.0, n_x)), jac.T],
                   [jac, -1e-8 * sp.eye(n_g)]]).tocsc()
    times, fill = [], 0
    for _ in range(max(3, a.repeats)):
        t0 = time.perf_counter()
        lu = sla.splu(kkt, permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                      options={'SymmetricMode': True})
        times.append(1e3 * (time.perf_counter() - t0))
        fill = int(lu.L.nnz + lu.U.nnz)
    out['kkt'] = {'dimension': int(kkt.shape[0]), 'nonzeros': int(kkt.nnz),
                  'superlu_mmd_factor_nonzeros': fill,
                  'superlu_mmd_ordering_and_factor_ms_median': float(np.median(times)),
                  'superlu_mmd_ordering_and_factor_ms_min': float(min(times))}
    best = min(r['median_ms_per_iteration'] for r in rows.values())
    warm = json.loads((RESULTS / 'paths_warm.json').read_text())['polyline10']['warm']
    its = warm['median_iterations']               # bench_paths.py --warm, its own run
    out['warm_median_iterations_from_paths_warm_json'] = its
    out['warm_solve_ms_with_fastest_solver_here'] = its * best
    out['ms_per_iteration_a_200ms_warm_solve_needs'] = 200 / its
    out['load_average_after'] = os.getloadavg()
    print('kkt', out['kkt'], flush=True)
    dump('linear_solvers', out)


if __name__ == '__main__':
    main()
