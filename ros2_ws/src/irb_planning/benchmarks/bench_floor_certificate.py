"""Periodic closed splines with a 0.3 m/s TCP speed floor under the smoothness limits (issue
28): which plan, which are refused, and whether each refusal's certificate is true.

    python ros2_ws/src/irb_planning/benchmarks/bench_floor_certificate.py [--count 10]

Requests: closed splines drawn as in bench_smooth.py (``draw('periodic')``, seed --seed,
code-2 draws skipped), planned periodic and time-optimal with tcp_speed_min 0.3 m/s,
tcp_speed_max 1.2 m/s and |a| <= max(uniform [1, 4], 2 v_min^2 kappa_max) m/s^2 (as
bench_smooth's band). Each by the default planner (limits on) and by one with
``jerk_limits=False``. Per request the TCP jerk lower bound of certificate.py with no limit
(the largest (kappa(s2) v_min^3 - kappa(s1) v_max(s1)^3) / ell over sample pairs) and, for
every plan, its TCP jerk as played, found independently: the message's points played by
quintic interpolation at 10 kHz (test/played.py), the TCP by forward kinematics at every
clock sample, the jerk as the third difference. A true certificate: every plan, with the
limits or without, has a played TCP jerk >= the bound; a refusal with a certificate has a
bound > the limit.

Witness (floor_witness.py, shares nothing with the planner's transcription): per request the
speed profile of least peak |TCP jerk| found by a 1-D NLP in arc length on the spline
rebuilt from the waypoints (exact Frenet jerk, joint jerk and speed limits, |a| bound, the
band), then played in time by its own integrator. A witness within every limit proves the
request feasible: a refusal of it is false. A witness above the limit proves nothing (a
local optimum), but one within the limit where a certificate holds would refute the
certificate.
"""
import argparse
import importlib.util
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from _common import dump

from irb_planning.planner import Planner, PlannerSettings, request_path
from irb_planning.request import PlanError, validate

_here = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location('played', _here.parent / 'test' / 'played.py')
played = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(played)
sys.path.insert(0, str(_here))
import bench_smooth  # noqa: E402
import floor_witness  # noqa: E402

V_MIN = 0.3


def requests(seed: int, count: int, planner: Planner) -> list:
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        req = bench_smooth.draw('periodic', rng)
        try:
            v = validate(replace(req, objective='time'), 60)
            planner.check_path(v, request_path(v))
        except PlanError:
            continue
        path = request_path(v)
        th = np.linspace(0.0, 2 * np.pi, 2001)
        kappa = float(np.max(np.linalg.norm(path.dd_point(th), axis=1)
                             / np.sum(path.d_point(th) ** 2, axis=1)))
        amax = max(float(rng.uniform(1.0, 4.0)), 2.0 * V_MIN ** 2 * kappa)
        out.append(replace(req, objective='time', tcp_speed_min=V_MIN,
                           tcp_speed_max=4 * V_MIN, tcp_accel_max=amax, tcp_ramp_length=0.0))
    return out


def played_tcp_jerk(model, tr, rate: float = 10000.0) -> float:
    """Peak |TCP jerk| [m/s^3] of the message played at ``rate``: FK at the clock samples,
    third difference (the periodic message's wrap-around is not played)."""
    p = played.play(model, tr['t'], tr['q'], tr['qd'], tr['qdd'], rate=rate, stride=10 ** 9)
    ticks = (p.t - p.t[0]) * rate
    on = np.abs(ticks - np.round(ticks)) < 1e-6
    x = np.array([model.fk(q) for q in p.q[on]])
    return float(np.linalg.norm(np.diff(x, n=3, axis=0), axis=1).max() * rate ** 3)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--count', type=int, default=10)
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--grid', type=int, default=60)
    ap.add_argument('--witness-samples', type=int, default=1500)
    ap.add_argument('--cases', type=int, nargs='*', default=None, help='only these cases')
    ap.add_argument('--name', default='floor_certificate', help='results/<name>.json')
    a = ap.parse_args()
    on = Planner(settings=PlannerSettings(grid_size=a.grid, cache_size=2, limit_cost=False))
    off = Planner(settings=PlannerSettings(grid_size=a.grid, cache_size=2, jerk_limits=False))
    loose = Planner(settings=PlannerSettings(grid_size=a.grid, tcp_jerk_limit_m_s3=1e-9))
    load0, t0 = os.getloadavg(), time.perf_counter()
    rows = []
    model, sm = on.model, on.smooth_limits
    for i, req in enumerate(requests(a.seed, a.count, on)):
        if a.cases and i not in a.cases:
            continue
        v = validate(req, a.grid)
        cert = loose.jerk_certificate(v, request_path(v), on.model.limits.velocity)
        row = {'case': i, 'tcp_accel_max': req.tcp_accel_max,
               'tcp_jerk_lower_bound': None if cert is None else cert.need}
        w = time.perf_counter()
        geo = floor_witness.geometry(model, req.waypoints, a.witness_samples)
        wit = floor_witness.witness(model, geo, V_MIN, req.tcp_speed_max, req.tcp_accel_max,
                                    sm.jerk)
        td = floor_witness.time_domain_check(model, geo, wit)
        ok = bool(wit['solved'] and td['tcp_jerk_peak'] <= sm.tcp_jerk
                  and td['speed_range'][0] >= V_MIN * (1 - 1e-3)
                  and td['speed_range'][1] <= req.tcp_speed_max
                  and td['tcp_accel_peak'] <= req.tcp_accel_max
                  and np.all(np.asarray(td['joint_jerk_peak']) <= sm.jerk)
                  and wit['joint_speed_ratio'] <= 1 and wit['torque_ratio'] <= 1
                  and np.all(wit['torque_rate_peak'] <= sm.torque_rate))
        row['witness'] = {
            'within_all_limits': ok, 'solved': wit['solved'],
            'tcp_jerk_peak': wit['tcp_jerk_peak'], 'speed_range': wit['speed_range'],
            'tcp_accel_peak': wit['tcp_accel_peak'],
            'joint_jerk_peak': wit['joint_jerk_peak'].tolist(),
            'joint_speed_ratio': wit['joint_speed_ratio'],
            'torque_ratio': wit['torque_ratio'],
            'torque_rate_peak': wit['torque_rate_peak'].tolist(), 'period_s': wit['period_s'],
            'played': td, 'wall_s': time.perf_counter() - w}
        for name, pl in (('on', on), ('off', off)):
            w = time.perf_counter()
            try:
                res = pl.plan(req)
                row[name] = {'planned': True, 't_min_s': res.min_duration,
                             'grid': res.request.grid_size,
                             'played_tcp_jerk': played_tcp_jerk(on.model, res.trajectory),
                             'reported_tcp_jerk': float(res.verification.tcp_jerk_peak)}
            except PlanError as exc:
                row[name] = {'planned': False, 'code': exc.code, 'message': exc.message,
                             'certificate': 'tcp_jerk_limit_m_s3' in exc.message,
                             'not_proven': 'not proven' in exc.message}
            row[name]['wall_s'] = time.perf_counter() - w
        bound = row['tcp_jerk_lower_bound'] or 0.0
        row['bound_holds'] = all(row[k]['played_tcp_jerk'] >= bound * (1 - 1e-3)
                                 for k in ('on', 'off') if row[k]['planned'])
        rows.append(row)
        # a certificate and a witness within the limits cannot both hold
        row['witness_agrees'] = not (row['witness']['within_all_limits']
                                     and bound > sm.tcp_jerk)
        print(json.dumps({k: row[k] for k in ('case', 'tcp_jerk_lower_bound', 'bound_holds')}
                         | {'witness_jerk': row['witness']['tcp_jerk_peak'],
                            'witness_ok': row['witness']['within_all_limits']}
                         | {k: {f: row[k].get(f) for f in ('planned', 'played_tcp_jerk',
                                                           'certificate')}
                            for k in ('on', 'off')}), file=sys.stderr, flush=True)
    limit = on.smooth_limits.tcp_jerk
    dump(a.name, {
        'command': ' '.join(['bench_floor_certificate.py'] + sys.argv[1:]),
        'v_min_m_s': V_MIN, 'tcp_jerk_limit_m_s3': limit,
        'planned_with_limits': sum(r['on']['planned'] for r in rows),
        'refused_with_certificate': sum((not r['on']['planned']) and r['on']['certificate']
                                        for r in rows),
        'refused_without_certificate': sum((not r['on']['planned'])
                                           and not r['on']['certificate'] for r in rows),
        'refused_although_a_witness_exists': sum(
            (not r['on']['planned']) and r['witness']['within_all_limits'] for r in rows),
        'planned_on_a_finer_grid': sum(r['on']['planned'] and r['on']['grid'] != a.grid
                                       for r in rows),
        'certificates_true': all(r['bound_holds'] for r in rows),
        'witnesses_agree_with_certificates': all(r['witness_agrees'] for r in rows),
        'wall_s': time.perf_counter() - t0, 'load_start': load0, 'load_end': os.getloadavg(),
        'rows': rows})


if __name__ == '__main__':
    main()
