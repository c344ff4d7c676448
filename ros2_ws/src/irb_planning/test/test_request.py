"""Validation of plan requests (pure, no solver)."""
import numpy as np
import pytest

from irb_planning import request as rq
from irb_planning.request import PlanError, PlanRequest, validate


@pytest.mark.parametrize('kwargs, text', [
    (dict(radius=0.0, duration=2.0), 'radius'),
    (dict(radius=-0.1, duration=2.0), 'radius'),
    (dict(radius=float('nan'), duration=2.0), 'radius'),
    (dict(center=np.array([0.6, np.nan, 0.13]), duration=2.0), 'center'),
    (dict(duration=float('inf')), 'duration'),
    (dict(duration=-1.0), 'duration'),
    (dict(objective='fastest', duration=2.0), 'objective'),
    (dict(objective='fourier', fourier_order=4, duration=2.0), 'fourier_order'),
    (dict(objective='trapezoid'), 'duration'),
    (dict(duration=0.0, time_weight=0.0), 'time_weight'),
    (dict(duration=2.0, grid_size=5), 'grid_size'),
    (dict(duration=2.0, limit_scaling=1.5), 'limit_scaling'),
    (dict(duration=2.0, direction=3), 'direction'),
    (dict(duration=2.0, direction=0), 'direction'),
    (dict(duration=2.0, boundary='loop'), 'boundary'),
    (dict(duration=2.0, time_weight=float('nan')), 'time_weight'),
])
def test_invalid_requests_are_refused_with_a_reason(kwargs, text):
    with pytest.raises(PlanError) as info:
        validate(PlanRequest(**kwargs), 200)
    assert info.value.code == rq.ERROR_INVALID_REQUEST
    assert text in info.value.message


def test_defaults_are_filled_in():
    req = validate(PlanRequest(duration=2.0, direction=-1), 150)
    assert (req.grid_size, req.limit_scaling, req.boundary, req.direction) == (
        150, 1.0, 'rest', -1)
    four = validate(PlanRequest(objective='fourier', fourier_order=5, duration=2.0), 150)
    assert four.boundary == 'periodic'


def test_error_codes_match_the_service_definition():
    srv = pytest.importorskip('irb_interfaces.srv')
    R = srv.PlanPath.Response
    assert (R.ERROR_NONE, R.ERROR_INVALID_REQUEST, R.ERROR_UNREACHABLE,
            R.ERROR_INFEASIBLE_DURATION, R.ERROR_FRICTION_MAP, R.ERROR_SOLVER) == (
        rq.ERROR_NONE, rq.ERROR_INVALID_REQUEST, rq.ERROR_UNREACHABLE,
        rq.ERROR_INFEASIBLE_DURATION, rq.ERROR_FRICTION_MAP, rq.ERROR_SOLVER)
    Q = srv.PlanPath.Request
    assert {Q.OBJECTIVE_ENERGY, Q.OBJECTIVE_TIME, Q.OBJECTIVE_TRAPEZOID,
            Q.OBJECTIVE_FOURIER} == set(rq.OBJECTIVES)
