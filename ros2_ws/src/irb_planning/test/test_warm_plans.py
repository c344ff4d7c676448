"""Consecutive plans on one path reuse what the last one learned (issue 18, solve time).

- the warm start is the last solution played at the new duration (``_time_scaled``): checked
  against the exact time law of profile.py (closed form, not the NLP's quadrature rows);
- on a polyline whose first plan needs a tightened torque limit (the exact check between the
  grid nodes), the next plan starts from that limit: one warm solve instead of two cold ones,
  and its plan passes the independent check; the oracle for its energy is a fresh planner
  (cold solves, its own tightening) at the same duration.
"""
from dataclasses import replace

import numpy as np
import pytest

from irb_planning.planner import Planner, PlannerSettings
from irb_planning.profile import ThetaProfile
from irb_planning.request import PlanRequest

#: a glue bead: 4 segments in a plane tilted about x, 20-30 mm blends
WAY = [[0.55, -0.2, 0.25], [0.85, -0.2, 0.25], [0.85, 0.0, 0.30], [0.55, 0.0, 0.30],
       [0.55, 0.2, 0.36]]
GRID = 150


def polyline(**kw) -> PlanRequest:
    return PlanRequest(path_type='polyline', waypoints=np.asarray(WAY, float),
                       blend_radii=np.array([0.02, 0.03, 0.02]), grid_size=GRID, **kw)


def test_time_scaled_warm_start_meets_the_new_duration():
    planner = Planner(settings=PlannerSettings(grid_size=GRID, limit_cost=False))
    T_min = planner.plan(polyline(objective='time')).min_duration
    T0 = 1.6 * T_min
    planner.plan(polyline(duration=T0))
    tr = next(e for e in planner._cache.values()).transcription
    x, _, _, last = tr._last
    for T1 in (0.9 * T0, 1.13 * T0):
        y = tr._time_scaled(x, last, replace(last, duration=T1))
        b, a = (np.asarray(v).ravel() for v in tr._ba(y))
        # the exact time law (closed form in profile.py) of the scaled point
        prof = ThetaProfile(tr.nodes.theta, np.sqrt(np.maximum(b, 0.0)), a)
        assert prof.duration == pytest.approx(T1, rel=2e-3)
        # and the NLP's own rows: duration exact, collocation b' = 2a exact, epigraph = |y|
        energy, duration, _, _, yy, _ = (np.asarray(v).ravel() for v in tr._aux(y))
        # exactly the last duration row's value scaled (IPOPT met that row at the last
        # solution to its tolerance only: 4e-11 relative with the jerk rows, issue 28)
        last_duration = float(np.asarray(tr._aux(x)[1]).ravel()[0])
        assert duration[0] == pytest.approx(last_duration * T1 / last.duration, rel=1e-12)
        assert duration[0] == pytest.approx(T1, rel=1e-9)
        h = np.diff(tr.nodes.theta)
        if tr.cubic_rest:      # constant-jerk rest intervals: b_1 - b_0 = 1.5 (a_0 + a_1) h
            h[[0, -1]] *= 1.5
        assert np.max(np.abs(np.diff(b) - (a[:-1] + a[1:]) * h)) < 1e-9 * max(1.0, b.max())
        e = y[tr._nb + tr._na:]
        assert np.allclose(e[:yy.size] - e[yy.size:], yy, atol=1e-12)
    # the same duration: the last solution unchanged
    assert np.array_equal(tr._time_scaled(x, last, last), x)


@pytest.mark.slow
def test_next_plan_starts_from_the_learned_tightening_and_stays_valid():
    planner = Planner(settings=PlannerSettings(grid_size=GRID, limit_cost=False))
    T_min = planner.plan(polyline(objective='time')).min_duration
    T = 1.3 * T_min
    first = planner.plan(polyline(duration=T))
    assert first.verification.ok and not first.evaluation.violations
    if not any(n.startswith('limits tightened after the exact check') for n in first.notes):
        pytest.skip('this grid needed no tightening: nothing to learn')
    second = planner.plan(polyline(duration=1.04 * T))
    assert any(n.startswith('limits tightened as the last plan') for n in second.notes)
    # one solve was enough (no re-solve after the check) and the plan passes both checks
    assert not any(n.startswith('limits tightened after') for n in second.notes)
    assert second.verification.ok and not second.evaluation.violations
    # oracle: a fresh planner (cold solves, its own tightening) at the same duration
    fresh = Planner(settings=PlannerSettings(grid_size=GRID, limit_cost=False))
    fresh.plan(polyline(objective='time'))
    ref = fresh.plan(polyline(duration=1.04 * T))
    assert ref.verification.ok
    # the learned limit is the one the first plan needed, the fresh plan's own is measured at
    # this duration: the energies differ by the limit's effect only
    assert second.evaluation.energy == pytest.approx(ref.evaluation.energy, rel=5e-3)
    assert second.iterations < ref.iterations


@pytest.mark.slow
def test_far_requests_skip_only_the_time_optimal_check():
    """min_duration_check_factor: a 10 s circle plan at N = 40 does not play the bang-bang
    profile; the plan returned is the same and checked in full. Oracle: the default planner
    (checks the time-optimal profile) on the same request."""
    req = PlanRequest(duration=10.0, grid_size=40)
    ref = Planner(settings=PlannerSettings(limit_cost=False)).plan(req)
    quick = Planner(settings=PlannerSettings(min_duration_check_factor=1.5,
                                             limit_cost=False))
    got = quick.plan(req)
    assert any(n.startswith('min_duration is the optimiser') for n in got.notes)
    assert not any(n.startswith('min_duration is the optimiser') for n in ref.notes)
    assert got.verification.ok and not got.evaluation.violations
    assert got.evaluation.energy == pytest.approx(ref.evaluation.energy, rel=1e-6)
    # unchecked, it can only be shorter than the checked one (tightening slows it down)
    assert got.min_duration <= ref.min_duration * (1 + 1e-9)
    assert got.min_duration >= 0.9 * ref.min_duration
    # near the time optimum the full check runs (and a too-short request is refused by it)
    near = quick.plan(PlanRequest(duration=1.2 * ref.min_duration, grid_size=40))
    assert not any(n.startswith('min_duration is the optimiser') for n in near.notes)
    assert near.min_duration == pytest.approx(ref.min_duration, rel=1e-9)
