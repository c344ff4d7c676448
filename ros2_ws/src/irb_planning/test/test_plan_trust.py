"""Issue 13: every plan that says success is one a controller can execute.

One regression test per defect the outside tester found (their requests and numbers), each
judged by the independent check (verify.py: own time integration, own DH kinematics, quintic
playback) and, where it matters, by a check written here.
"""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from irb_description.friction import FrictionMap

from irb_planning import request as rq
from irb_planning.planner import Planner, PlannerSettings
from irb_planning.request import PlanError, PlanRequest

DELTA = PlannerSettings().min_theta_dot_rad_s
CONTROL_DIR = Path(__file__).resolve().parents[2] / 'irb_control' / 'config'


def assert_executable(res, delta=DELTA):
    """What a controller needs: the check passed, stamps = exact time law, theta_dot > 0
    strictly inside, no interval hiding a pause, played within 0.1 mm."""
    ver = res.verification
    assert ver.ok, ver.problems
    assert ver.max_time_error <= 1e-6
    assert ver.max_path_deviation <= 1e-4
    pr = res.profile
    # theta_dot between the nodes, densely, from the profile's own interpolation
    th = np.linspace(0, 2 * np.pi, 20001)[1:-1]
    _, thd, _ = pr.theta_at(th)
    h = np.diff(pr.theta)
    inside = (th > pr.theta[1]) & (th < pr.theta[-2])
    assert thd[inside].min() >= delta * (1 - 1e-6)
    assert thd.min() > 0
    # no interval takes longer than at the slowest admissible speed: h / delta inside, at a
    # rest end 3 h / delta (constant-jerk start, issue 28) or 2 h / delta (constant theta_ddot)
    limit = h / delta * (1 + 1e-5)
    cubic = pr.cubic_ends
    limit[[0, -1]] = [(3.0 if c else 2.0) * h[k] / delta * (1 + 1e-9)
                      for c, k in zip(cubic, (0, -1))]
    assert np.all(np.diff(pr.times) <= limit)
    assert abs(ver.duration - pr.duration) <= 1e-9 * pr.duration


@pytest.mark.parametrize('duration', [15.0, 20.0, 30.0])
def test_long_durations_are_spread_over_the_path(planner, duration):
    # defect 1: at 30 s theta_ddot(0) = -0.55 from rest, b < 0 inside the first interval and a
    # 14.3 s first interval; played quintically 995 mm off the circle
    res = planner.plan(PlanRequest(duration=duration))
    assert_executable(res)
    assert res.verification.duration == pytest.approx(duration, rel=1e-9)
    assert res.verification.energy == pytest.approx(res.evaluation.energy, rel=1e-3)


def test_long_duration_energies_differ(planner):
    # defect 1: E(30 s) = E(60 s) because the plan waited; now the motion itself is slower
    e30 = planner.plan(PlanRequest(duration=30.0)).verification.energy
    e60 = planner.plan(PlanRequest(duration=60.0)).verification.energy
    assert abs(e60 - e30) > 1e-3 * e30


def test_random_circle_near_10_s(planner):
    # defect 1: 10.212 s -> a 4.05 s first interval, 155 mm off, 145 J against 81.16 J reported
    res = planner.plan(PlanRequest(center=np.array([0.6688, 0.2383, 0.4654]), radius=0.08378,
                                   start_angle=-1.2556, direction=-1, duration=10.212))
    assert_executable(res)


def test_free_duration_with_tiny_time_weight(planner):
    # defect 1: time weight 1e-9 (15.79 s) gave stamps 0.98 s off
    res = planner.plan(PlanRequest(duration=0.0, time_weight=1e-9))
    assert_executable(res)


def test_durations_beyond_the_slowest_motion_are_refused(planner):
    # defect 3: duration 1e6 ended in code 5
    with pytest.raises(PlanError) as info:
        planner.plan(PlanRequest(duration=1e6))
    assert info.value.code == rq.ERROR_INFEASIBLE_DURATION
    assert 'slowest motion' in info.value.message


@pytest.mark.parametrize('center, radius', [((-0.6, 0.0, 0.13), 0.15), ((0.0, 0.0, 0.0), 0.05),
                                            ((0.0, 0.0, 0.0), 0.1)])
def test_joint_1_crossing_180_deg_is_refused_naming_the_joint(planner, center, radius):
    # defect 2: q1 jumped from +179.8 to -179.8 deg between nodes 50 ms apart
    with pytest.raises(PlanError) as info:
        planner.plan(PlanRequest(center=np.array(center), radius=radius, duration=10.0))
    assert info.value.code == rq.ERROR_UNREACHABLE
    assert 'joint_1' in info.value.message and 'theta' in info.value.message


@pytest.mark.slow
def test_the_valid_request_that_failed_is_planned(model):
    # defect 3: code 5 after 1000 iterations on the default grid (11 s and 12 s succeeded)
    planner = Planner(model.copy(), PlannerSettings(limit_cost=False))
    res = planner.plan(PlanRequest(center=np.array([0.74406, -0.23256, 0.36227]),
                                   radius=0.12188, start_angle=0.59492, direction=-1,
                                   duration=11.6135))
    assert_executable(res)


@pytest.mark.parametrize('start', [1e16, 1e300, -7.5])
def test_start_angle_is_reduced_modulo_2_pi(planner, model, start):
    # defect 4: 1e16 succeeded with 4 distinct positions, 1e300 covered 0 turns
    res = planner.plan(PlanRequest(start_angle=start, duration=5.0))
    assert_executable(res)
    phi0 = res.request.start_angle
    assert 0 <= phi0 < 2 * np.pi and phi0 == pytest.approx(np.mod(start, 2 * np.pi), abs=1e-9)
    p0 = model.fk(res.trajectory['q'][0])
    assert np.arctan2(p0[1], p0[0] - 0.6) % (2 * np.pi) == pytest.approx(phi0, abs=1e-6)
    assert len(np.unique(np.round(res.trajectory['q'], 6), axis=0)) > 0.9 * len(
        res.trajectory['t'])


@pytest.mark.parametrize('kwargs, code, text', [
    (dict(direction=0), rq.ERROR_INVALID_REQUEST, 'direction'),
    (dict(limit_scaling=1e-9), rq.ERROR_INVALID_REQUEST, 'limit_scaling'),
    (dict(friction_map='x' * 5000), rq.ERROR_FRICTION_MAP, 'longer than'),
    (dict(friction_map='/proc/self/status'), rq.ERROR_FRICTION_MAP, 'outside the allowed'),
    (dict(friction_map='../../etc/passwd'), rq.ERROR_FRICTION_MAP, 'outside the allowed'),
])
def test_refusals_have_a_code_and_our_message(planner, kwargs, code, text):
    # defects 5 and 6
    with pytest.raises(PlanError) as info:
        planner.plan(PlanRequest(duration=5.0, **kwargs))
    assert info.value.code == code and text in info.value.message
    for leak in ('Errno', 'Name:', 'Traceback', 'Ill-posed'):
        assert leak not in info.value.message


def _write_map(path: Path, model, **fields):
    data = model.friction.to_dict()
    data['friction_map']['joints']['joint_2'].update(fields)
    import yaml
    path.write_text(yaml.safe_dump(data))
    return path.name


@pytest.mark.parametrize('fields, text', [
    (dict(coulomb=1e300), 'exceeds'),
    (dict(viscous=-3.0), 'negative'),
    (dict(static=float('nan')), 'not finite'),
    (dict(coulomb='Name: planner'), 'not a number'),
])
def test_unusable_map_numbers_are_refused_without_echo(planner, model, map_dir, fields, text):
    # defect 5: coefficients of 1e300 -> raw CasADi "Ill-posed problem"; negative friction
    # accepted; defect 6: errors echoed the file's lines
    name = _write_map(map_dir / f'bad_{text.replace(" ", "_")}.yaml', model, **fields)
    with pytest.raises(PlanError) as info:
        planner.plan(PlanRequest(duration=5.0, friction_map=name))
    assert info.value.code == rq.ERROR_FRICTION_MAP and text in info.value.message
    assert 'joint_2' in info.value.message and 'Name:' not in info.value.message


def test_binary_and_broken_files_are_refused_without_echo(planner, map_dir):
    # defect 5: a binary map gave code 1 with a raw UnicodeDecodeError; defect 6
    (map_dir / 'binary.yaml').write_bytes(bytes(range(256)) * 4)
    (map_dir / 'broken.yaml').write_text('secret: [1, 2\nName: planner\n')
    for name, text in (('binary.yaml', 'not a text file'), ('broken.yaml', 'not valid YAML')):
        with pytest.raises(PlanError) as info:
            planner.plan(PlanRequest(duration=5.0, friction_map=name))
        assert info.value.code == rq.ERROR_FRICTION_MAP and text in info.value.message
        assert 'secret' not in info.value.message and 'codec' not in info.value.message


def test_relative_map_names_are_looked_up_in_the_allowed_directories(planner, model, map_dir):
    # defect 5: relative names were resolved against the server's working directory
    model.friction.save(map_dir / 'nominal_copy.yaml')
    res = planner.plan(PlanRequest(duration=5.0, friction_map='nominal_copy.yaml'))
    assert res.verification.ok


def test_cache_memory_is_bounded(model):
    # defect 7: +60-70 MiB per cached problem, never returned; with a ceiling below the
    # process's size only the newest problem is kept
    planner = Planner(model.copy(), PlannerSettings(grid_size=40, memory_limit_mib=1.0,
                                                    limit_cost=False))
    for x in (0.55, 0.6, 0.65):
        planner.plan(PlanRequest(center=np.array([x, 0.0, 0.13]), duration=5.0))
    assert len(planner._cache) == 1
    # the count bound alone (a ceiling far above this process's size)
    many = Planner(model.copy(), PlannerSettings(grid_size=40, cache_size=2,
                                                 memory_limit_mib=1e6, limit_cost=False))
    for x in (0.55, 0.6, 0.65):
        many.plan(PlanRequest(center=np.array([x, 0.0, 0.13]), duration=5.0))
    assert len(many._cache) == 2
    with pytest.raises(PlanError) as info:
        many.plan(PlanRequest(duration=5.0, grid_size=2000))
    assert info.value.code == rq.ERROR_INVALID_REQUEST and 'max_grid_size' in info.value.message


def _polynomial_map(model) -> FrictionMap:
    """A map whose per-sign polynomials differ from its parametric part (as identified maps
    do): the NLP sees the parametric part, the check the polynomials."""
    joints = []
    for j in model.friction.joints:
        v = np.linspace(0.02, 2.0, 200)
        cp = np.polynomial.polynomial.polyfit(v, j.parametric(v) * (1 + 0.08 * v)
                                              + 1.5 * np.sin(3 * v), 7)
        cn = np.polynomial.polynomial.polyfit(-v, -j.parametric(v) * (1 + 0.05 * v), 7)
        joints.append(replace(j, valid_range=(0.02, 2.0), polynomial_positive=tuple(cp),
                              polynomial_negative=tuple(cn)))
    return FrictionMap(model.friction.joint_names, tuple(joints), 'polynomial test map')


@pytest.mark.parametrize('kwargs', [dict(objective='time'), dict(factor=1.05)])
def test_polynomial_map_time_optimal_and_fast_plans(planner, model, map_dir, kwargs):
    # defect 8: refused at 711.6 and 700.4 N m against 700 (smooth NLP friction vs the map);
    # the fast plan was at 1.0 s, which the jerk limits (issue 28) make shorter than the
    # time-optimal 1.24 s: now at 1.05 x that map's time-optimal duration
    _polynomial_map(model).save(map_dir / 'poly.yaml')
    if 'factor' in kwargs:
        t_min = planner.plan(PlanRequest(friction_map='poly.yaml',
                                         objective='time')).min_duration
        kwargs = dict(duration=kwargs['factor'] * t_min)
    res = planner.plan(PlanRequest(friction_map='poly.yaml', **kwargs))
    assert_executable(res)
    assert np.all(res.verification.peak_torque <= model.limits.torque * (1 + 1e-6))


def test_plant_map_time_optimal_at_grid_60(model):
    # defect 8: with the plant's map at grid 60 the time-optimal plan was refused
    planner = Planner(model.copy(), PlannerSettings(grid_size=60, limit_cost=False,
                                                    friction_map_dirs=(str(CONTROL_DIR),)))
    res = planner.plan(PlanRequest(objective='time', friction_map='plant.yaml'))
    assert_executable(res)


def test_no_convex_bound_for_a_polynomial_map_is_a_refusal_not_a_crash(planner, model,
                                                                      map_dir):
    """The convex relaxation knows only the parametric friction; a map with polynomial
    branches (every identified map of the main job) gets a PlanError with code 4 naming why,
    and a placement search asked for bounds keeps going without them (the main job's phase 6
    crashed on the ValueError before)."""
    from irb_planning.placement import Region, search
    _polynomial_map(model).save(map_dir / 'poly.yaml')
    req = PlanRequest(friction_map='poly.yaml', duration=6.0)
    with pytest.raises(PlanError) as info:
        planner.bound(req, 6.0)
    assert info.value.code == rq.ERROR_FRICTION_MAP and 'polynomial' in info.value.message
    lines = []
    res = search(planner, req, Region(np.array([0.6, 0.0, 0.13]), np.array([0.6, 0.0, 0.13])),
                 (1, 1, 1), coarse_grid=20, refine=1, min_step=0.1, progress=lines.append,
                 bounds=True)
    assert res.best_center is not None and np.isfinite(res.best_energy)
    assert np.all(np.isnan(res.lower_bounds)) and np.isnan(res.best_lower_bound)
    assert any('failed' in line and 'polynomial' in line for line in lines), lines
