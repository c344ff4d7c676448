"""Planning on every path type (issue 18): line, arc in a tilted plane, blended polyline,
spline, closed rectangle; every objective where it makes sense; the same checks.

Oracles: the TCP of the returned joints by pinocchio's forward kinematics (not the DH of
verify.py, not the IK that made them) against the path; the TCP speed of the trapezoid from
the Jacobian; the thesis circle planned as an ``arc`` (other formulas, same geometry)."""
import numpy as np
import pytest
from irb_description.path import path_from_spec, path_spec, rectangle_path
from numpy.testing import assert_allclose

from irb_planning.request import (ERROR_INVALID_REQUEST, ERROR_UNREACHABLE, PlanError,
                                  PlanRequest)

WAY = [[0.55, -0.25, 0.25], [0.8, -0.2, 0.3], [0.85, 0.05, 0.4], [0.7, 0.2, 0.35],
       [0.55, 0.15, 0.3]]
RECT = path_spec(rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025))


def req(spec: dict, **kw) -> PlanRequest:
    """PlanRequest of a path mapping (what messages.request_from_msg makes of a PathSpec)."""
    f = dict(path_type=spec['type'])
    for k in ('center', 'normal', 'waypoints', 'blend_radii'):
        if k in spec:
            f[k] = np.asarray(spec[k], float)
    for k in ('radius', 'start_angle', 'sweep', 'closed', 'direction'):
        if k in spec:
            f[k] = spec[k]
    return PlanRequest(**f, **kw)


SPECS = {
    'line': dict(type='line', waypoints=[[0.5, -0.2, 0.25], [0.8, 0.25, 0.45]]),
    'arc': dict(type='arc', center=[0.65, 0.0, 0.3], normal=[0.2, -0.4, 1.0], radius=0.12,
                start_angle=0.4, sweep=-4.5),
    'polyline': dict(type='polyline', waypoints=WAY, blend_radii=[0.03, 0.05, 0.02]),
    'spline': dict(type='spline', waypoints=WAY),
    'rectangle': RECT,
}


def tcp(model, q):
    return np.array([model.fk(x) for x in q])


@pytest.mark.parametrize('name', sorted(SPECS))
def test_energy_plans_on_every_path_type_stay_on_the_path(planner, unlimited, model, name):
    spec = SPECS[name]
    path = path_from_spec(spec)
    T = 1.5 * planner.plan(req(spec, objective='time')).min_duration + 1.0
    r = planner.plan(req(spec, duration=T))
    assert r.verification.ok and r.evaluation.ok
    assert r.evaluation.duration == pytest.approx(T, rel=1e-9)
    p = tcp(model, r.trajectory['q'])
    assert path.distance(p).max() < 1e-9
    assert_allclose(p[[0, -1]], path.point(np.array([0.0, 2 * np.pi])), atol=1e-9)
    # as played, the TCP speed stays the path speed: |J qd| = |p'| theta_dot
    v = np.linalg.norm([model.jacobian(q) @ qd for q, qd in
                        zip(r.trajectory['q'], r.trajectory['qd'])], axis=1)
    thd = r.profile.theta_at(r.trajectory['theta'])[1]
    assert_allclose(v, path.length / (2 * np.pi) * thd, atol=1e-9)
    # the optimum uses no more energy than the trapezoid of the same duration: of the problem
    # the trapezoid is feasible for, the one without the smoothness limits (its theta_ddot
    # steps break them; with them the line's optimum was 0.24 % above it)
    free = unlimited.plan(req(spec, duration=T))
    assert free.verification.ok and free.evaluation.ok
    assert free.evaluation.energy <= free.baseline.energy * (1 + 1e-6)


def test_the_trapezoid_runs_at_constant_tcp_speed_along_arc_length(planner, model):
    spec = SPECS['polyline']
    path = path_from_spec(spec)
    r = planner.plan(req(spec, objective='trapezoid', duration=8.0))
    t = r.trajectory['t']
    v = np.linalg.norm([model.jacobian(q) @ qd for q, qd in
                        zip(r.trajectory['q'], r.trajectory['qd'])], axis=1)
    cruise = (t > 0.1 * 8.0 + 1e-6) & (t < 0.9 * 8.0 - 1e-6)
    # ramps of 10 % each: cruise speed L / (0.9 T) over corners and straights alike
    assert_allclose(v[cruise], path.length / (0.9 * 8.0), rtol=1e-9)


def test_closed_paths_plan_periodic_and_fourier_open_paths_refuse(planner):
    r = planner.plan(req(RECT, duration=6.0, boundary='periodic'))
    assert r.verification.ok and r.profile.theta_dot[0] > 0
    assert r.profile.theta_dot[0] == pytest.approx(r.profile.theta_dot[-1])
    f = planner.plan(req(RECT, objective='fourier', fourier_order=3, duration=6.0))
    assert f.verification.ok and f.evaluation.ok
    for kw in (dict(boundary='periodic', duration=6.0),
               dict(objective='fourier', fourier_order=3, duration=6.0)):
        with pytest.raises(PlanError) as e:
            planner.plan(req(SPECS['polyline'], **kw))
        assert e.value.code == ERROR_INVALID_REQUEST and 'closed path' in e.value.message


def test_the_thesis_circle_planned_as_an_arc_is_the_same_plan(planner):
    circle = planner.plan(PlanRequest(duration=8.0))
    arc = planner.plan(req(dict(type='arc', center=[0.6, 0.0, 0.13], normal=[0, 0, 1],
                                radius=0.15), duration=8.0))
    assert arc.evaluation.energy == pytest.approx(circle.evaluation.energy, rel=1e-7)
    assert_allclose(arc.profile.theta_dot, circle.profile.theta_dot, rtol=1e-6, atol=1e-8)
    # the arc's message may hold more points (the rate-consistency rule applies to every
    # path but the CirclePath): every m-th of them is the circle's point
    n_c, n_a = len(circle.trajectory['t']), len(arc.trajectory['t'])
    m = (n_a - 1) // (n_c - 1)
    assert (n_c - 1) * m == n_a - 1
    for k in ('t', 'q', 'qd', 'qdd'):
        assert_allclose(arc.trajectory[k][::m], circle.trajectory[k], rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize('spec, code, text', [
    (dict(type='polyline', waypoints=[[0.6, -0.5, 0.2], [1.6, 0.0, 0.2], [0.6, 0.5, 0.2]],
          blend_radii=[0.05]), ERROR_UNREACHABLE, 'workspace'),
    (dict(type='line', waypoints=[[0.42, -0.45, 0.65], [0.42, 0.45, 0.65]]),
     ERROR_UNREACHABLE, 'joint_3'),
    (dict(type='polyline', waypoints=[[0.5, 0, 0.3], [0.7, 0, 0.3], [0.7, 0.01, 0.3]],
          blend_radii=[0.05]), ERROR_INVALID_REQUEST, 'overlap'),
    (dict(type='spline', waypoints=[[0.5, 0, 0.3]] * 3), ERROR_INVALID_REQUEST, 'coincide'),
    (dict(type='line', waypoints=[[0.5, 0, 0.3], [0.5, 0, 0.3001]]), ERROR_INVALID_REQUEST,
     'length'),
    (dict(type='polyline', waypoints=[[0.5, 0, 0.3], [20.0, 0, 0.3]]), ERROR_INVALID_REQUEST,
     'within'),
    (dict(type='star'), ERROR_INVALID_REQUEST, 'unknown'),
])
def test_bad_paths_are_refused_with_a_code_and_a_reason(planner, spec, code, text):
    kw = {k: v for k, v in spec.items()}
    with pytest.raises(PlanError) as e:
        planner.plan(req(kw, duration=5.0) if kw['type'] != 'star'
                     else PlanRequest(path_type='star', duration=5.0))
    assert e.value.code == code and text in e.value.message
