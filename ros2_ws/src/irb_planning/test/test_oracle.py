"""The optimiser against the independent evaluator (pinocchio + numpy friction at 1 kHz)."""
import numpy as np
import pytest
from irb_description.path import thesis_circle

from irb_planning import request as rq
from irb_planning.baselines import trapezoid_profile
from irb_planning.evaluator import LimitSet, evaluate
from irb_planning.planner import Planner, PlannerSettings
from irb_planning.request import PlanError, PlanRequest

#: the optimiser's energy must agree with the evaluator's within this fraction
AGREEMENT = 0.01


def _check(result):
    ev = result.evaluation
    assert ev.ok, ev.violations
    assert abs(result.optimizer_energy - ev.energy) <= AGREEMENT * ev.energy
    assert abs(ev.duration - result.profile.duration) < 1e-9
    return ev


@pytest.fixture(scope='module')
def t_min(planner):
    return planner.plan(PlanRequest(objective='time')).min_duration


def test_time_optimal_profile_is_feasible_and_shortest(planner, unlimited, t_min):
    res = planner.plan(PlanRequest(objective='time'))
    ev = _check(res)
    assert 0.3 < ev.duration < 2.0
    # a trapezoid at the minimum duration breaks a limit: nothing is faster. The trapezoid
    # (theta_ddot steps) is a witness of the problem without the smoothness limits only, so
    # it is checked against that problem's minimum; the limits can only lengthen it
    free = unlimited.plan(PlanRequest(objective='time'))
    _check(free)
    with pytest.raises(PlanError) as info:
        unlimited.plan(PlanRequest(objective='trapezoid', duration=free.min_duration))
    assert info.value.code == rq.ERROR_INFEASIBLE_DURATION
    assert t_min >= free.min_duration * (1 - 1e-6)


@pytest.mark.parametrize('factor', [1.5, 5.0])
def test_energy_optimum_agrees_with_evaluator_and_beats_trapezoid(planner, unlimited, t_min,
                                                                  factor):
    T = factor * t_min
    res = planner.plan(PlanRequest(duration=T))
    ev = _check(res)
    assert abs(ev.duration - T) < 1e-6 * T
    assert res.baseline is not None and abs(res.baseline.duration - T) < 1e-9
    assert ev.energy <= res.baseline.energy
    # the bound lies below the optimum (up to the optimiser's quadrature error)
    bound = planner.bound(PlanRequest(duration=T), T)
    assert bound <= res.optimizer_energy * (1 + 1e-6)
    assert bound <= ev.energy * (1 + AGREEMENT)
    assert bound >= 0.9 * ev.energy
    if factor < 2:     # where time is scarce the relaxation is tight (README: within 1 %)
        # of the optimum of its own problem: the relaxation has no jerk or torque-rate rows
        # (with them the optimum at 1.5 x their T_min is 10.7 % above it, issue 28), so the
        # claim is checked on the problem without them, at factor x that problem's T_min
        T_free = factor * unlimited.plan(PlanRequest(objective='time')).min_duration
        free = unlimited.plan(PlanRequest(duration=T_free))
        _check(free)
        b_free = unlimited.bound(PlanRequest(duration=T_free), T_free)
        assert 0.99 * free.optimizer_energy <= b_free <= free.optimizer_energy * (1 + 1e-6)


def test_grid_convergence_near_the_time_optimum(planner, t_min):
    # second-order collocation: the energy on 200 nodes is within 0.5 % of that on 600 nodes
    # at 1.6 T_min (the first-order scheme moved it by ~1 % from 200 to 1000 nodes)
    T = 1.6 * t_min
    coarse = _check(planner.plan(PlanRequest(duration=T, grid_size=200)))
    fine = _check(planner.plan(PlanRequest(duration=T, grid_size=600)))
    assert abs(coarse.energy / fine.energy - 1) < 0.005


def test_re_evaluation_at_another_rate(planner, t_min):
    res = planner.plan(PlanRequest(duration=1.5 * t_min))
    same = planner.evaluate(res, planner.settings.evaluation_rate_hz)
    assert same.energy == res.evaluation.energy and same.violations == []
    fine = planner.evaluate(res, 10_000.0)
    assert fine.t.size > 9 * res.evaluation.t.size
    assert fine.energy == pytest.approx(res.evaluation.energy, rel=2e-3)


def test_trapezoid_result_is_the_evaluator_energy(planner, model):
    res = planner.plan(PlanRequest(objective='trapezoid', duration=4.0))
    def torque(q, qd, qdd):
        return np.array([model.inverse_dynamics_with_friction(*x) for x in zip(q, qd, qdd)])
    ev = evaluate(trapezoid_profile(4.0), lambda th: planner.sample_path(thesis_circle())(th),
                  torque, LimitSet(model.limits.velocity, model.limits.torque))
    assert res.evaluation.energy == pytest.approx(ev.energy, rel=1e-12)


def test_fourier_profile_agrees_and_is_no_better_than_periodic_transcription(planner):
    four = planner.plan(PlanRequest(objective='fourier', fourier_order=3, duration=4.0))
    _check(four)
    assert four.fourier_coeffs.shape == (7,)
    trans = planner.plan(PlanRequest(duration=4.0, boundary='periodic'))
    _check(trans)
    assert trans.evaluation.energy <= four.evaluation.energy * (1 + AGREEMENT)


def test_time_energy_trade_off(planner):
    slow = planner.plan(PlanRequest(duration=0.0, time_weight=1.0))
    fast = planner.plan(PlanRequest(duration=0.0, time_weight=50.0))
    _check(slow), _check(fast)
    assert fast.evaluation.duration < slow.evaluation.duration
    assert fast.evaluation.energy > slow.evaluation.energy


def test_random_circles_are_solved_or_refused(planner, rng):
    for _ in range(3):
        req = PlanRequest(center=np.array([rng.uniform(0.45, 0.8), rng.uniform(-0.3, 0.3),
                                           rng.uniform(0.0, 0.6)]),
                          radius=rng.uniform(0.05, 0.25), duration=rng.uniform(1.0, 8.0))
        try:
            _check(planner.plan(req))
        except PlanError as exc:
            assert exc.code in (rq.ERROR_UNREACHABLE, rq.ERROR_INFEASIBLE_DURATION)
            assert exc.message


@pytest.mark.parametrize('kwargs, code', [
    (dict(center=np.array([1.5, 0.0, 0.13]), duration=3.0), rq.ERROR_UNREACHABLE),
    (dict(radius=0.0, duration=3.0), rq.ERROR_INVALID_REQUEST),
    (dict(radius=float('nan'), duration=3.0), rq.ERROR_INVALID_REQUEST),
    (dict(duration=0.05), rq.ERROR_INFEASIBLE_DURATION),
    (dict(objective='greenest', duration=3.0), rq.ERROR_INVALID_REQUEST),
    (dict(friction_map='/nonexistent/friction.yaml', duration=3.0), rq.ERROR_FRICTION_MAP),
])
def test_bad_requests_get_a_specific_code(planner, kwargs, code):
    with pytest.raises(PlanError) as info:
        planner.plan(PlanRequest(**kwargs))
    assert info.value.code == code and info.value.message


def test_unreadable_friction_map(planner, map_dir):
    bad = map_dir / 'friction.yaml'
    bad.write_text('friction_map: {version: 1, joints: {joint_1: {coulomb: 1}}}\n')
    with pytest.raises(PlanError) as info:
        planner.plan(PlanRequest(friction_map=str(bad), duration=3.0))
    assert info.value.code == rq.ERROR_FRICTION_MAP


def test_friction_map_file_is_used(planner, model, map_dir):
    path = map_dir / 'scaled.yaml'
    model.friction.scaled(1.5).save(path)
    nominal = planner.plan(PlanRequest(duration=4.0))
    scaled = planner.plan(PlanRequest(duration=4.0, friction_map=str(path)))
    _check(scaled)
    assert scaled.evaluation.energy > nominal.evaluation.energy


def test_solver_failure_is_reported(model):
    starved = Planner(model.copy(), PlannerSettings(grid_size=40, max_iterations=2))
    with pytest.raises(PlanError) as info:
        starved.plan(PlanRequest(duration=3.0))
    assert info.value.code == rq.ERROR_SOLVER
    assert 'iteration limit reached' in info.value.message
