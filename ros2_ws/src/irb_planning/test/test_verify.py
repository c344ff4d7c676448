"""The independent check catches the class of error the outside tester found: wrong stamps, a
joint that wraps, points off the path, limits between points (verify.py, no optimiser)."""
import numpy as np
import pytest

from irb_planning.planner import BOUNDARY_REST
from irb_planning.request import PlanRequest
from irb_planning.verify import ArmKinematics, Circle, MapFriction, verify_plan


@pytest.fixture(scope='module')
def plan(planner):
    return planner.plan(PlanRequest(duration=4.0))


def _check(planner, res, t=None, q=None, qd=None, qdd=None, **kw):
    tr = res.trajectory
    req = res.request
    lim = planner.model.limits
    kin = ArmKinematics(velocity=lim.velocity, torque=lim.torque, **planner._kin)
    circle = Circle(req.center, req.radius, req.start_angle, req.direction)
    pr = res.profile
    fm = planner.model.friction.to_dict()['friction_map']['joints']
    return verify_plan(tr['t'] if t is None else t, tr['q'] if q is None else q,
                       tr['qd'] if qd is None else qd, tr['qdd'] if qdd is None else qdd,
                       (pr.theta, pr.theta_dot, pr.theta_ddot_nodes, pr.quadratic), circle, kin,
                       planner.rigid_torque, MapFriction(fm, planner.model.joint_names),
                       req.boundary == BOUNDARY_REST, **kw)


def test_a_planned_message_passes(planner, plan):
    ver = _check(planner, plan)
    assert ver.ok, ver.problems
    assert ver.energy == pytest.approx(plan.evaluation.energy, rel=1e-3)


def test_stamps_off_the_time_law_are_caught(planner, plan):
    t = plan.trajectory['t'].copy()
    t[5:] += 1e-4                     # one segment 0.1 ms longer
    ver = _check(planner, plan, t=t)
    assert any('time stamps disagree' in p for p in ver.problems)


def test_a_joint_1_wrap_is_caught(planner, plan):
    q = plan.trajectory['q'].copy()
    q[20:, 0] -= 2 * np.pi            # the same TCP, joint 1 one turn lower from point 20
    ver = _check(planner, plan, q=q)
    assert any('joint 1 jumps' in p for p in ver.problems)
    assert any('leaves its limits' in p for p in ver.problems)


def test_points_off_the_path_and_a_long_pause_are_caught(planner, plan):
    q = plan.trajectory['q'].copy()
    q[30, 1] += 0.01
    assert any('off the path' in p for p in _check(planner, plan, q=q).problems)
    t = plan.trajectory['t'].copy()
    t[1:] += 5.0                      # the first segment takes 5 s: a hidden pause
    ver = _check(planner, plan, t=t)
    assert any('time stamps disagree' in p for p in ver.problems)
    # and played quintically a long segment leaves the path
    assert ver.max_path_deviation > 1e-4


def test_torque_between_points_is_checked(planner, plan):
    lim = planner.model.limits
    res = _check(planner, plan)
    tight = ArmKinematics(velocity=lim.velocity, torque=0.99 * res.peak_torque,
                          **planner._kin)
    req = plan.request
    pr = plan.profile
    fm = planner.model.friction.to_dict()['friction_map']['joints']
    tr = plan.trajectory
    ver = verify_plan(tr['t'], tr['q'], tr['qd'], tr['qdd'],
                      (pr.theta, pr.theta_dot, pr.theta_ddot_nodes, True),
                      Circle(req.center, req.radius, req.start_angle, req.direction), tight,
                      planner.rigid_torque, MapFriction(fm, planner.model.joint_names), True)
    assert sum('torque' in p for p in ver.problems) == 3


def test_map_friction_is_read_from_the_numbers():
    joints = {'j': {'coulomb': 10.0, 'static': 14.0, 'stribeck_velocity': 0.1, 'viscous': 2.0,
                    'coulomb_positive': 11.0, 'coulomb_negative': 9.0, 'offset': 0.5}}
    f = MapFriction(joints, ['j'])
    v = np.array([[0.5], [-0.5], [1e-9]])
    e = np.exp(-25.0)
    expected = [11 + 4 * e + 1.0 + 0.5, -(9 + 4 * e) - 1.0 + 0.5, 11 + 4 + 0.5]
    np.testing.assert_allclose(f(v)[:, 0], expected, rtol=1e-9, atol=1e-8)
