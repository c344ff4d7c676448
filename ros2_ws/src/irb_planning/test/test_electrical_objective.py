"""energy_model: the electrical objective, and electrical energy reported by both checks."""
import numpy as np
import pytest

from irb_planning.planner import Planner, PlannerSettings
from irb_planning.request import PlanError, PlanRequest, validate


def test_energy_model_is_validated():
    with pytest.raises(PlanError, match='energy_model'):
        validate(PlanRequest(duration=5.0, energy_model='thermal'), 100)
    assert validate(PlanRequest(duration=5.0), 100).energy_model == 'mechanical'
    assert validate(PlanRequest(duration=5.0, energy_model='electrical_none'),
                    100).energy_model == 'electrical_none'


def test_energy_model_names_equal_the_service_constants():
    srv = pytest.importorskip('irb_interfaces.srv')
    R = srv.PlanPath.Request
    from irb_planning.request import ENERGY_MODELS
    assert sorted(ENERGY_MODELS) == sorted([
        R.ENERGY_MECHANICAL, R.ENERGY_ELECTRICAL_NONE, R.ENERGY_ELECTRICAL_SHARED,
        R.ENERGY_ELECTRICAL_REGENERATIVE])


@pytest.mark.slow
def test_electrical_objective_checked_by_both_evaluators():
    planner = Planner(settings=PlannerSettings(limit_cost=False))
    elec = planner.plan(PlanRequest(duration=6.0, grid_size=60,
                                    energy_model='electrical_none'))
    for res in (elec,):
        ev, ver = res.evaluation, res.verification
        # the 1 kHz evaluator and the independent check of the message (quintic playback,
        # own DH kinematics and friction reading) agree on the electrical energy
        for mode in ('none', 'shared', 'regenerative'):
            assert ver.electrical[f'total_{mode}'] == pytest.approx(
                ev.electrical[f'total_{mode}'], rel=2e-3)
        e = ver.electrical
        assert e['total_none'] >= e['total_shared'] - 1e-6 >= e['total_regenerative'] - 2e-6
        assert e['standby'] == pytest.approx(planner.electrical.standby_power * ver.duration)
        assert ver.energy == pytest.approx(e['mechanical'])
    # the electrical optimum beats the trapezoid at the same duration on electrical energy
    # (both as evaluated at 1 kHz from the same dynamics)
    assert elec.evaluation.electrical['total_none'] < elec.baseline.electrical['total_none']
    # the optimiser's own electrical quadrature is close to the played one
    assert np.isfinite(elec.optimizer_electrical_energy)
    assert elec.optimizer_electrical_energy == pytest.approx(
        elec.verification.electrical['total_none'], rel=0.01)
