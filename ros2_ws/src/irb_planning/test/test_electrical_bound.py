"""The convex lower bound on the electrical energy (baselines.EnergyBound with an electrical
model) against energies it did not compute: the 1 kHz evaluator's electrical energy
(pinocchio RNEA + numpy friction + irb_description's numpy electrical model) of the
electrical optimum, of trapezoids and of random feasible profiles at the same duration."""
import numpy as np
import pytest
from irb_description.path import thesis_circle

from irb_planning.baselines import trapezoid_profile
from irb_planning.evaluator import LimitSet, evaluate
from irb_planning.problem import effective_speed_limit
from irb_planning.profile import ThetaProfile
from irb_planning.request import PlanRequest

MODES = ('none', 'shared', 'regenerative')


def full_limits(planner):
    """The limits a plan is checked with (nominal map, limit scaling 1)."""
    fm, lim = planner.model.friction, planner.model.limits
    return LimitSet(effective_speed_limit(lim.velocity, fm), lim.torque, lim.lower, lim.upper)


def random_profiles(rng, duration, count):
    """Rest-to-rest profiles of exact ``duration`` [s]: trapezoids with random ramps and
    theta_dot = c sqrt(sin(theta / 2)) (1 + random 3-harmonic ripple) (b linear in theta at
    the rest ends: finite acceleration), scaled in time to ``duration``."""
    out = [trapezoid_profile(duration, r) for r in rng.uniform(0.05, 0.5, count // 2)]
    theta = np.linspace(0.0, 2 * np.pi, 801)
    for _ in range(count - len(out)):
        a, ph = rng.uniform(-0.25, 0.25, 3), rng.uniform(0, 2 * np.pi, 3)
        ripple = 1 + sum(a[j] * np.sin((j + 1) * theta + ph[j]) for j in range(3))
        td = np.sqrt(np.abs(np.sin(theta / 2))) * ripple
        td[0] = td[-1] = 0.0
        prof = ThetaProfile(theta, td)
        out.append(prof.scaled_in_time(duration / prof.duration))
    return out


@pytest.fixture(scope='module')
def t_min(planner):
    return planner.plan(PlanRequest(objective='time')).min_duration


@pytest.mark.slow
@pytest.mark.parametrize('which', ['10 s', '5 s', '1.5 T_min'])
def test_electrical_bound_below_optimum_trapezoid_and_random_profiles(planner, t_min, rng,
                                                                      which):
    T = {'10 s': 10.0, '5 s': 5.0, '1.5 T_min': 1.5 * t_min}[which]
    req = PlanRequest(duration=T, energy_model='electrical_shared')
    res = planner.plan(req)
    bound = planner.bound(req, T)
    e_plan = res.verification.electrical['total_shared']
    # below the optimum as played (independent check) and as the optimiser integrates it
    assert bound <= e_plan
    assert bound <= res.optimizer_electrical_energy
    # below the trapezoid at the same duration (1 kHz evaluator)
    assert bound <= res.baseline.electrical['total_shared']
    # and below every feasible profile of that duration, by the evaluator
    sample = planner.sample_path(thesis_circle())
    fm, _ = planner.friction_map('')
    limits = full_limits(planner)
    feasible = 0
    # near T_min most random shapes break a speed or torque limit: draw more there
    for prof in random_profiles(rng, T, 6 if T >= 5 else 24):
        ev = evaluate(prof, sample, planner.torque(fm), limits, 1000.0, planner.electrical)
        assert ev.duration == pytest.approx(T, rel=1e-9)
        if not ev.ok:
            continue
        feasible += 1
        assert bound <= ev.electrical['total_shared'], (prof.theta_dot[:3], bound)
    assert feasible >= 3
    # the bound is not trivial: above the standby + drive idle energy (it sees the motion)
    # and within 5 % of the plan
    fixed = (planner.electrical.standby_power + planner.electrical.drive_idle_power.sum()) * T
    assert bound > fixed
    assert bound >= 0.95 * e_plan


@pytest.mark.slow
def test_every_bus_mode_bounds_the_evaluated_energies(planner, rng):
    T = 5.0
    sample = planner.sample_path(thesis_circle())
    fm, _ = planner.friction_map('')
    torque = planner.torque(fm)
    limits = full_limits(planner)
    evs = [evaluate(p, sample, torque, limits, 1000.0, planner.electrical)
           for p in random_profiles(rng, T, 4)]
    evs = [ev for ev in evs if ev.ok]
    assert len(evs) >= 3
    bounds = {}
    for mode in MODES:
        bounds[mode] = planner.bound(PlanRequest(duration=T,
                                                 energy_model=f'electrical_{mode}'), T)
        for ev in evs:
            assert bounds[mode] <= ev.electrical[f'total_{mode}']
    # the bus functions are ordered pointwise (none >= shared >= regenerative), the
    # relaxation is the same: so are the bounds
    assert bounds['none'] >= bounds['shared'] - 1e-6 >= bounds['regenerative'] - 2e-6
