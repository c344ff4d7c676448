"""Issue 28's open points: every energy and time plan reports what the smoothness limits cost
it (PlanResult.limit_cost, the answer's message), and a TCP speed floor refused under the TCP
jerk limit carries a certificate (certificate.py) that is true."""
from dataclasses import replace

import numpy as np
import pytest

from irb_planning.certificate import curvature, jerk_certificate
from irb_planning.planner import (LIMIT_COST_NOTE, Planner, PlannerSettings,
                                  limit_cost_from_message, request_path)
from irb_planning.request import PlanRequest, validate


@pytest.fixture(scope='module')
def planner():
    return Planner(settings=PlannerSettings(grid_size=40, cache_size=2))


def test_energy_plan_reports_its_cost(planner):
    res = planner.plan(PlanRequest(duration=4.0))
    c = res.limit_cost
    assert c is not None and c.quantity == 'energy' and c.status == 'Solve_Succeeded'
    assert c.with_limits == pytest.approx(res.optimizer_energy, rel=1e-12)
    # the reference starts on the plan, which is feasible without the jerk rows
    assert c.without_limits <= c.with_limits * (1 + 1e-6)
    assert c.cost >= -1e-6
    note = next(n for n in res.notes if LIMIT_COST_NOTE in n)
    got = limit_cost_from_message('energy plan; ' + note + '; more')
    assert got['quantity'] == 'energy'
    assert got['cost'] == pytest.approx(c.cost, abs=5e-5)
    assert got['without'] == pytest.approx(c.without_limits, rel=1e-5)
    # oracle: the same problem without the jerk rows solved cold, from the planner's own
    # initial guess (not from the plan): the same optimum
    tr = planner._cache[next(reversed(planner._cache))].transcription
    cold = tr.solve(replace(tr.last_request, jerk_limit=None, tcp_jerk_max=0.0), warm=False)
    assert cold.stats.success
    assert c.without_limits == pytest.approx(cold.energy, rel=2e-3)


def test_time_plan_reports_its_duration_cost_and_off_means_none(planner):
    res = planner.plan(PlanRequest(objective='time'))
    c = res.limit_cost
    assert c.quantity == 'duration' and c.with_limits == pytest.approx(res.min_duration)
    # the thesis circle: |TCP jerk| v^3 / r^2 <= 100 m/s^3 slows it down (0.66 -> 1.19 s)
    assert 0.3 < c.cost < 1.5
    quiet = Planner(planner.model.copy(), replace(planner.settings, limit_cost=False))
    res = quiet.plan(PlanRequest(objective='time'))
    assert res.limit_cost is None and not any(LIMIT_COST_NOTE in n for n in res.notes)
    assert limit_cost_from_message('; '.join(res.notes)) is None


def test_normal_jerk_is_the_rate_of_kappa_v3():
    """The identity the certificate rests on, checked by finite differences on a motion
    along an ellipse with a varying speed: jerk . N = d(kappa v^3)/ds."""
    a, b = 0.2, 0.05
    t = np.linspace(0.0, 1.0, 200001)
    dt = t[1] - t[0]
    phi = 2 * np.pi * (t + 0.1 * np.sin(2 * np.pi * t))      # any smooth time law
    x = np.stack([a * np.cos(phi), b * np.sin(phi), 0.01 * phi], axis=1)
    v = np.gradient(x, dt, axis=0)
    acc = np.gradient(v, dt, axis=0)
    jerk = np.gradient(acc, dt, axis=0)
    speed = np.linalg.norm(v, axis=1)
    kappa = curvature(v, acc)
    T = v / speed[:, None]
    n = acc - (acc * T).sum(axis=1, keepdims=True) * T
    N = n / np.linalg.norm(n, axis=1, keepdims=True)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * dt)])
    rate = np.gradient(kappa * speed ** 3, s)
    inner = slice(1000, -1000)
    np.testing.assert_allclose((jerk * N).sum(axis=1)[inner], rate[inner],
                               atol=1e-3 * np.abs(rate).max())


def test_certificate_bound_and_a_motion_that_has_it(planner):
    """A closed spline with a tight bend at a 0.3 m/s floor: the certificate's bound exceeds
    the limit, and a motion in the band (constant speed v_min, its jerk from the path's
    derivatives in theta) has at least that jerk; a gentle floor gets none."""
    # bench_floor_certificate.py's case 0 (seed 1): refused with the limits, planned without
    way = np.array([[0.6741, 0.3195, 0.3341], [0.782, 0.2079, 0.1433], [0.7197, 0.2142, 0.0888],
                    [0.7374, 0.19, 0.0409], [0.6268, 0.243, 0.0624], [0.5412, 0.3306, 0.2111]])
    req = PlanRequest(path_type='spline', waypoints=way, closed=True, boundary='periodic',
                      objective='time', tcp_speed_min=0.3, tcp_speed_max=1.2,
                      tcp_accel_max=30.0)
    v = validate(req, 40)
    path = request_path(v)
    cert = planner.jerk_certificate(v, path, planner.model.limits.velocity)
    assert cert is not None and cert.need > 100.0 and 'tcp_jerk_limit_m_s3' in cert.text()
    # constant speed v_min along the path: theta_dot = g(theta) = v / |p'|, and the jerk
    # p''' g^3 + 3 p'' g^2 g' + p' g (g'^2 + g g'') from the path's own derivatives
    th = np.linspace(0.0, 2 * np.pi, 20001)
    d1, d2 = path.d_point(th), path.dd_point(th)
    d3 = np.gradient(d2, th, axis=0)
    g = 0.3 / np.linalg.norm(d1, axis=1)
    g1 = np.gradient(g, th)
    g2 = np.gradient(g1, th)
    jerk = (d3 * g[:, None] ** 3 + 3 * d2 * (g ** 2 * g1)[:, None]
            + d1 * (g * (g1 ** 2 + g * g2))[:, None])
    assert np.linalg.norm(jerk[2:-2], axis=1).max() >= cert.need
    assert planner.jerk_certificate(replace(v, tcp_speed_min=0.05), path,
                                    planner.model.limits.velocity) is None


def test_certificate_of_a_curvature_ramp():
    """kappa rising linearly from 0 to k over ell at v_min, capped at v_max before: the bound
    is k v_min^3 / ell exactly (the pair at both ends of the ramp)."""
    s = np.linspace(0.0, 1.0, 2001)
    k, ell = 200.0, 0.01
    kappa = np.clip((s - 0.5) / ell, 0.0, 1.0) * k
    cert = jerk_certificate(s, 1.0, kappa, np.full(s.size, 1.2), 0.3, 100.0, False)
    assert cert.need == pytest.approx(k * 0.3 ** 3 / ell, rel=1e-3)
    assert cert.from_m == pytest.approx(0.5, abs=1e-3)
    assert jerk_certificate(s, 1.0, kappa, np.full(s.size, 1.2), 0.3,
                            1.01 * k * 0.3 ** 3 / ell, False) is None
