"""Issue 28: closed splines at a TCP speed floor that the planner refused without a
certificate (bench_floor_certificate.py, seed 1, cases 7 and 8) have motions within every
limit (benchmarks/floor_witness.py found them independently). The causes, each tested here:
the jerk rows' third derivatives (5-point stencils across spline knots), the TCP jerk rows
(each component within J / sqrt 3) and the grid (13.5 mm intervals against an 11 mm bend).
A refusal without a certificate says it is not proven and names a finer grid. Case 7 was
refused at every uniform grid tried (200, 216, 400): theta_ddot linear per interval cannot
follow kappa^2 v^3 through its 9 mm bend at the rows on the intervals' ends, and the spline's
arc length was off by 3e-7 m; with the grid spaced by curvature, a node at every knot
(planner.path_grid) and the arc length fixed it plans at grid 200."""
import importlib.util
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from irb_planning.planner import (Planner, PlannerSettings, jerk_path, path_grid, request_path,
                                  theta_grid)
from irb_planning.request import (ERROR_INFEASIBLE_DURATION, PlanError, PlanRequest,
                                  validate)
from irb_planning.transcription import BOUNDARY_PERIODIC, Transcription
from irb_planning.verify import LIMIT_RTOL

_spec = importlib.util.spec_from_file_location('played', Path(__file__).with_name('played.py'))
played = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(played)

#: bench_floor_certificate.py --seed 1, case 8 (its request exactly)
CASE8 = PlanRequest(path_type='spline', closed=True, boundary='periodic', objective='time',
                    waypoints=np.array([
                        [0.8059451642691711, 0.052813684539034705, 0.3442581396619382],
                        [0.7770327408241988, -0.031080343868107513, 0.4286843640906753],
                        [0.921588404281478, 0.0649037261056983, 0.6560200880097721],
                        [0.8915213906338776, 0.07397175651253617, 0.550444882019273]]),
                    tcp_speed_min=0.3, tcp_speed_max=1.2, tcp_accel_max=16.006857376297052,
                    tcp_ramp_length=0.0)
#: bench_floor_certificate.py --seed 1, case 7 (its request exactly)
CASE7 = PlanRequest(path_type='spline', closed=True, boundary='periodic', objective='time',
                    waypoints=np.array([
                        [0.6046785388756878, 0.011030439009903664, 0.13548200907504104],
                        [0.6681627903528091, 0.05364977364166311, 0.10342026685252996],
                        [0.7586099329342988, 0.15134589842965523, 0.05114702060529008],
                        [0.704715422114544, 0.24533764587370938, 0.05515024313789418]]),
                    tcp_speed_min=0.3, tcp_speed_max=1.2, tcp_accel_max=19.980755190023935,
                    tcp_ramp_length=0.0)


def test_jerk_rows_third_derivative_is_exact_next_to_spline_knots(planner):
    """p^(3) of the jerk rows against a central difference of p'' with a tiny step (each
    point away from the spline's knots by more than the step): within 1e-4 of max |p^(3)|
    at grid 60 (the 5-point stencils over the interval were off by 22 %)."""
    path = request_path(validate(CASE8, 60))
    theta = theta_grid(60, path.breaks)
    jp = jerk_path(path, planner.sample_path(path), theta, None, None)
    h = np.diff(theta)
    eps = 1e-6
    for m, off in enumerate((1e-7, 0.5, 1 - 1e-7)):
        th = theta[:-1] + off * h
        th = th[(th > 2 * eps) & (th < 2 * np.pi - 2 * eps)]
        ref = (path.dd_point(th + eps) - path.dd_point(th - eps)) / (2 * eps)
        got = jp.d3[m][(theta[:-1] + off * h > 2 * eps) & (theta[:-1] + off * h
                                                            < 2 * np.pi - 2 * eps)]
        # a knot within eps of a point: its two sides differ; none here
        assert np.abs(got - ref).max() <= 1e-4 * np.abs(ref).max()


@pytest.mark.parametrize('binormal', [0.0, 1.0, 1e3])
def test_tcp_jerk_rows_keep_the_norm_within_the_limit(binormal):
    """Every jerk vector that meets the rows (octagon T, N, (T +- N) / sqrt 2 and B) has
    |jerk| <= J: the octagon's corners lie at its apothem / cos(pi / 8); a planar path
    (B = 0) gets 0.924 J per direction, more than the J / sqrt 3 per component before."""
    K, J = 4, 100.0
    fake = SimpleNamespace(boundary=BOUNDARY_PERIODIC,
                           _binormal=[np.full(K, binormal)] * 3)
    req = SimpleNamespace(tcp_jerk_max=J)
    r = Transcription._tcp_jerk_bounds(fake, req, np.full(K, 0.5), np.full(K, 0.5))
    r_tn, r_b = r[0], r[4]
    assert np.all(r[:4] == r_tn)
    assert np.hypot(r_tn / np.cos(np.pi / 8), r_b) <= J * (1 + 1e-12)
    # the binormal bound covers the largest binormal component at the caps (or J / sqrt 3)
    assert r_b >= min(binormal * 0.5 ** 1.5, J / np.sqrt(3))
    if binormal == 0.0:
        assert r_tn == pytest.approx(np.cos(np.pi / 8) * J, rel=1e-6)
    # brute force: the largest norm over the octagon's corners and the binormal bound
    phi = np.pi / 8 + np.arange(8) * np.pi / 4
    corners = r_tn / np.cos(np.pi / 8) * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    t, n = corners.T
    assert np.all(np.abs(np.stack([t, n, (t + n) / np.sqrt(2), (t - n) / np.sqrt(2)]))
                  <= r_tn * (1 + 1e-12))
    assert np.sqrt((corners ** 2).sum(axis=1) + r_b ** 2).max() <= J * (1 + 1e-12)


def test_refusal_without_certificate_says_it_is_not_proven(model, map_dir):
    """Case 8 at the uniform grid 60 (curvature_grid_share 0; 13.5 mm intervals against an
    11.2 mm bend): the optimiser finds no motion, certificate.py's strongest bound (29.5
    m/s^3) is below the limit, so the refusal says it is not proven, with the bound, the
    limit and a finer grid."""
    uniform = Planner(model.copy(), PlannerSettings(
        grid_size=60, limit_cost=False, curvature_grid_share=0.0, cache_size=1,
        friction_map_dirs=(str(map_dir),)))
    with pytest.raises(PlanError) as err:
        uniform.plan(CASE8)
    msg = err.value.message
    assert err.value.code == ERROR_INFEASIBLE_DURATION
    assert 'not proven: no certificate: the strongest TCP jerk bound of certificate.py is '\
        '29.52 m/s^3 <= the limit 100 m/s^3' in msg
    assert 'intervals are 13.5 mm against a tightest bend of radius 11.2 mm' in msg
    assert 'a finer grid_size (e.g. 214) may plan it' in msg


def played_tcp(model, tr: dict, rate: float) -> np.ndarray:
    """The TCP (M, 3) of a plan's message played by quintic interpolation (test/played.py)
    on its clock's ticks at ``rate`` [Hz] (forward kinematics of the model)."""
    p = played.play(model, tr['t'], tr['q'], tr['qd'], tr['qdd'], rate=rate, stride=10 ** 9)
    ticks = (p.t - p.t[0]) * rate
    on = np.abs(ticks - np.round(ticks)) < 1e-6
    return np.array([model.fk(q) for q in p.q[on]])


@pytest.mark.parametrize('case', [CASE7, CASE8], ids=['case7', 'case8'])
def test_case_refused_before_plans_within_the_limits_as_played(model, case):
    """Cases 7 and 8 at grid 200 (refused before at every grid; 8: the stencils and the TCP
    jerk box; 7: the uniform grid and the spline's arc length): planned; the TCP jerk as
    played by quintic interpolation at 10 kHz (test/played.py, forward kinematics, third
    difference) within the limit, the speed within the band."""
    pl = Planner(model.copy(), PlannerSettings(grid_size=200, cache_size=1, limit_cost=False))
    res = pl.plan(case)
    rate = 10000.0
    x = played_tcp(model, res.trajectory, rate)
    jerk = np.linalg.norm(np.diff(x, n=3, axis=0), axis=1) * rate ** 3
    speed = np.linalg.norm(np.diff(x, axis=0), axis=1) * rate
    assert jerk.max() <= 100.0 * (1 + LIMIT_RTOL)
    assert speed.min() >= 0.3 * (1 - 1e-3) and speed.max() <= 1.2 * (1 + 1e-3)


def test_spline_points_agree_with_their_derivative():
    """SplinePath's arc length (Gauss-Legendre per table piece): p(theta) - p(theta') is the
    integral of p' (Simpson, 64 pieces) within 1e-12 m over every 0.32 mm step of case 7's
    spline (with one rule per knot interval: 1.7e-7 m next to its 9 mm bend, the points of
    a plan then disagreed with their velocities); and path_grid puts a node on every knot."""
    path = request_path(validate(CASE7, 200))
    theta = np.linspace(0.0, 2 * np.pi, 2001)
    x = np.linspace(0.0, 1.0, 65)
    w = np.ones(65)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    s = theta[:-1, None] + np.diff(theta)[:, None] * x[None, :]
    d = path.d_point(s.ravel()).reshape(s.shape + (3,))
    integral = np.diff(theta)[:, None] / 64 / 3 * np.einsum('j,kjx->kx', w, d)
    gap = np.linalg.norm(np.diff(path.point(theta), axis=0) - integral, axis=1)
    assert gap.max() <= 1e-12
    grid = path_grid(200, path, PlannerSettings().curvature_grid_share)
    assert grid.size == 200 and np.all(np.diff(grid) > 0)
    assert np.all(np.isin(path.knots, grid))


#: bench_smooth --seed 31's closed spline: its legs cross near 68 and 413 mm along it
CROSSING = np.array([[0.57738276, -0.26699967, 0.44288097],
                     [0.76253304, -0.23166506, 0.54776359],
                     [0.76408912, -0.22259135, 0.54289186],
                     [0.51455009, -0.32050884, 0.43450325]])


def test_a_closed_spline_that_crosses_itself_plans_within_the_limits_as_played(model):
    """bench_smooth --seed 31's periodic time-optimal plan of a closed spline whose legs
    cross was refused ("0.035 mm off the path", "points do not run once along the path",
    1e9 relative time error): the check projected points of one leg onto the other. It
    plans; played at 10 kHz (test/played.py) the TCP stays on the path by
    irb_description's own projection (not the check's) and within the TCP jerk limit."""
    from irb_description.path import SplinePath
    pl = Planner(model.copy(), PlannerSettings(grid_size=60, cache_size=1))
    res = pl.plan(PlanRequest(path_type='spline', waypoints=CROSSING, closed=True,
                              boundary='periodic', objective='time'))
    assert res.verification.ok, res.verification.problems
    rate = 10000.0
    x = played_tcp(model, res.trajectory, rate)
    path = SplinePath(CROSSING, closed=True)
    assert path.distance(x).max() <= 1e-4
    jerk = np.linalg.norm(np.diff(x, n=3, axis=0), axis=1) * rate ** 3
    assert jerk.max() <= 100.0 * (1 + LIMIT_RTOL)
