"""Tool-orientation laws and the six joints along every path type (orientation.py)."""
import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from irb_description.orientation import (FixedOrientation, KeyframeSlerp, OrientationLaw,
                                         PathFrame, joint_path6, orientation_from_spec,
                                         path_normal, pose_errors, tool_poses)
from irb_description.path import (ArcPath, LinePath, SplinePath, rectangle_path,
                                  thesis_circle)
from irb_description.six_axis import (SixAxisKinematics, UnreachablePoseError, pose, rot_x,
                                      rot_y, rot_z, rotation_error)

DOWN = rot_x(np.pi)                               # tool z = -base z, tool x = base x
NOZZLE = pose(np.eye(3), [0.0, 0.0, 0.10])        # a straight 0.1 m nozzle on the flange
RECT_NORMAL = np.array([0.3, 0.1, 1.0])           # the main job's tilted rectangle


def rectangle():
    return rectangle_path([0.7, 0.0, 0.3], RECT_NORMAL, 0.3, 0.2, 0.025)


def tilted_spline():
    u = np.array([1.0, 0.0, -0.3]) / np.hypot(1.0, 0.3)
    v = np.array([0.0, 1.0, 0.0])
    c = np.array([0.65, 0.0, 0.35])
    w = [c + a * u + b * v for a, b in [(-0.1, -0.15), (0.0, -0.05), (0.08, 0.05),
                                        (0.0, 0.12), (-0.1, 0.15)]]
    return SplinePath(np.array(w))


@pytest.fixture(scope='module')
def kin(model):
    return SixAxisKinematics(model.kinematics, tcp=NOZZLE)


def test_path_frame_points_the_tool_against_the_normal_with_x_along_the_tangent():
    rect = rectangle()
    n = RECT_NORMAL / np.linalg.norm(RECT_NORMAL)
    assert_allclose(path_normal(rect), n, atol=1e-12)
    theta = np.linspace(0.0, 2 * np.pi, 101)
    R = PathFrame(rect).rotation(theta)
    t = rect.d_point(theta)
    assert_allclose(R[:, :, 2], np.broadcast_to(-n, (101, 3)), atol=1e-12)
    assert_allclose(np.einsum('nij,nik->njk', R, R), np.broadcast_to(np.eye(3), (101, 3, 3)),
                    atol=1e-12)
    # the path lies in the plane, so its tangent is the tool's x axis itself
    assert_allclose(R[:, :, 0], t / np.linalg.norm(t, axis=1)[:, None], atol=1e-12)
    Rf = PathFrame(rect, x_mode='fixed', approach='along').rotation(theta)
    assert_allclose(Rf[:, :, 2], np.broadcast_to(n, (101, 3)), atol=1e-12)
    assert np.ptp(Rf, axis=0).max() == 0.0
    with pytest.raises(ValueError, match='line has no plane'):
        PathFrame(LinePath(np.array([0.6, 0, 0.3]), np.array([0.7, 0, 0.3])))


def test_slerp_hits_the_keyframes_and_halves_the_angle_between():
    Ra, Rb = DOWN, rot_z(0.8) @ rot_y(0.3) @ DOWN
    law = KeyframeSlerp([0.0, 2.0], [Ra, Rb])
    R = law.rotation(np.array([-1.0, 0.0, 1.0, 2.0, 3.0]))
    assert_allclose(R[0], Ra, atol=1e-12)
    assert_allclose(R[1], Ra, atol=1e-12)
    assert_allclose(R[3], Rb, atol=1e-12)
    assert_allclose(R[4], Rb, atol=1e-12)
    total = rotation_error(Ra, Rb)
    assert rotation_error(Ra, R[2]) == pytest.approx(total / 2, abs=1e-12)
    assert rotation_error(R[2], Rb) == pytest.approx(total / 2, abs=1e-12)
    with pytest.raises(ValueError, match='increasing'):
        KeyframeSlerp([1.0, 0.0], [Ra, Rb])


CASES = {
    'rectangle path-normal tangent-x': lambda: (rectangle(), PathFrame(rectangle())),
    'rectangle path-normal fixed-x': lambda: (rectangle(),
                                              PathFrame(rectangle(), x_mode='fixed')),
    'circle path-normal fixed-x': lambda: (thesis_circle(),
                                           PathFrame(thesis_circle(), x_mode='fixed')),
    'arc path-normal tangent-x': lambda: (
        ArcPath(np.array([0.65, 0.1, 0.35]), np.array([0.0, -0.3, 1.0]), 0.1, 0.5, 4.0),
        None),
    'line slerp': lambda: (
        LinePath(np.array([0.55, -0.25, 0.25]), np.array([0.75, 0.2, 0.45])),
        KeyframeSlerp([0.0, np.pi, 2 * np.pi],
                      [DOWN, rot_y(0.4) @ DOWN, rot_z(0.6) @ rot_x(-0.3) @ DOWN])),
    'spline path-normal tangent-x': lambda: (tilted_spline(), PathFrame(tilted_spline())),
    'spline fixed': lambda: (tilted_spline(), FixedOrientation(rot_y(0.2) @ DOWN)),
}


@pytest.mark.parametrize('case', list(CASES))
def test_joint_path_reproduces_every_pose_with_one_configuration_and_no_jump(model, kin, case):
    path, law = CASES[case]()
    law = law or PathFrame(path)
    theta = np.linspace(0.0, 2 * np.pi, 721)
    jp = joint_path6(kin, path, law, theta, derivatives=True)
    assert jp.q.shape == (721, 6) and np.all(np.isfinite(jp.q))
    assert all(kin.configuration(q) == jp.configuration for q in jp.q[::20])
    assert np.all(kin.within_limits(jp.q))
    assert np.abs(np.diff(jp.q, axis=0)).max() < 0.1          # 0.5 deg of theta per step
    pos, ori = pose_errors(kin, jp.q, tool_poses(path, law, theta))
    assert pos.max() <= 1e-9 and ori.max() <= 1e-9
    # dq/dtheta: pinocchio's Jacobian maps it to the TCP's rate [p'; omega] of path and law
    data = model.full.createData()
    fid = model.full.getFrameId('tool0')
    d = 1e-6
    Rm, Rp = law.rotation(theta - d), law.rotation(theta + d)
    W = np.einsum('nij,nkj->nik', Rp - Rm, law.rotation(theta)) / (2 * d)   # R' R^T
    omega = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
    p1 = path.d_point(theta)
    # where path and law are smooth: away from the ends, the pieces' ends and the keyframes
    kinks = np.concatenate([[0.0, 2 * np.pi], np.asarray(getattr(path, 'breaks', [])),
                            getattr(law, 'thetas', [])])
    smooth = np.flatnonzero(np.abs(theta[:, None] - kinks[None, :]).min(axis=1) > 0.02)
    worst = 0.0
    for k in smooth[::6]:
        J = pin.computeFrameJacobian(model.full, data, jp.q[k], fid, pin.LOCAL_WORLD_ALIGNED)
        tw = J @ jp.dq[k]
        r = data.oMf[fid].rotation @ NOZZLE[:3, 3]
        v_tcp = tw[:3] + np.cross(tw[3:], r)
        worst = max(worst, np.abs(v_tcp - p1[k]).max(), np.abs(tw[3:] - omega[k]).max())
    assert worst <= 1e-6 * (1.0 + np.abs(jp.ddq).max())


def test_seed_and_configuration_are_kept(kin):
    path, law = rectangle(), PathFrame(rectangle(), x_mode='fixed')
    theta = np.linspace(0.0, 2 * np.pi, 200)
    first = joint_path6(kin, path, law, theta)
    cfg = ('front', 'up', 'flip')        # only the elbow-up configurations reach it
    other = joint_path6(kin, path, law, theta, configuration=cfg)
    assert other.configuration == cfg != first.configuration
    assert pose_errors(kin, other.q, other.T)[1].max() <= 1e-9
    # a seed one turn of joint 6 away: the path follows that turn (q6 range +-400 deg)
    seed = first.q[0] + np.array([0, 0, 0, 0, 0, 2 * np.pi])
    if seed[5] > kin.upper[5]:
        seed[5] -= 4 * np.pi
    turned = joint_path6(kin, path, law, theta, seed=seed)
    assert_allclose(turned.q[:, 5], first.q[:, 5] + (seed[5] - first.q[0, 5]), atol=1e-9)


class _Follow(OrientationLaw):
    """The tool orientation of the joint vector q0 carried round axis 1: q5 = 0 all along."""

    def __init__(self, kin, q0, sweep):
        self.R0, self.q0, self.sweep = kin.fk(q0)[:3, :3], q0, sweep

    def rotation(self, theta):
        return rot_z(self.sweep * np.asarray(theta) / (2 * np.pi)) @ self.R0


def test_a_path_along_the_wrist_singularity_keeps_q4_and_stays_exact(kin):
    q0 = np.array([0.0, 0.3, -0.4, 0.0, 0.0, 0.2])
    p0 = kin.fk(q0)[:3, 3]
    sweep = 1.2
    arc = ArcPath(np.array([0.0, 0.0, p0[2]]), np.array([0.0, 0.0, 1.0]), float(p0[0]),
                  0.0, sweep)
    law = _Follow(kin, q0, sweep)
    theta = np.linspace(0.0, 2 * np.pi, 50)
    seed = q0 + np.array([0, 0, 0, 0.7, 0, -0.7])     # same pose, other split of q4 + q6
    jp = joint_path6(kin, arc, law, theta, seed=seed)
    assert np.all(jp.wrist_singular)
    assert_allclose(jp.q[:, 3], 0.7, atol=1e-12)
    assert_allclose(jp.q[:, 0], sweep * theta / (2 * np.pi), atol=1e-9)
    pos, ori = pose_errors(kin, jp.q, jp.T)
    assert pos.max() <= 1e-9 and ori.max() <= 1e-9


def test_unreachable_paths_are_refused_with_the_place(kin):
    far = LinePath(np.array([0.6, 0.0, 0.3]), np.array([1.8, 0.0, 0.3]))
    with pytest.raises(UnreachablePoseError, match='outside the workspace'):
        joint_path6(kin, far, FixedOrientation(DOWN), np.linspace(0, 2 * np.pi, 50),
                    configuration=('front', 'up', 'noflip'))
    # pointing the tool up under the flange needs q5 beyond 115 deg
    up = FixedOrientation(np.eye(3))
    with pytest.raises(UnreachablePoseError, match='limits|jumps|workspace'):
        joint_path6(kin, thesis_circle(), up, np.linspace(0, 2 * np.pi, 50),
                    configuration=('front', 'up', 'noflip'))


def test_fixed_orientation_checks_its_matrix():
    with pytest.raises(ValueError, match='rotation'):
        FixedOrientation(2 * np.eye(3))
    R = FixedOrientation.from_axes([0, 0, -1], [1, 1, 0]).R
    assert_allclose(R, Rotation.from_euler('xz', [np.pi, np.pi / 4]).as_matrix(), atol=1e-12)


def test_orientation_from_spec_builds_each_law_and_refuses_bad_blocks():
    from irb_description.orientation import orientation_from_spec
    rect = rectangle()
    theta = np.linspace(0.0, 2 * np.pi, 9)
    law = orientation_from_spec({'law': 'path_normal', 'x_mode': 'fixed'}, rect)
    assert_allclose(law.rotation(theta), PathFrame(rect, x_mode='fixed').rotation(theta),
                    atol=0)
    fixed = orientation_from_spec({'law': 'fixed', 'rpy': [np.pi, 0.0, 0.0]}, rect)
    assert_allclose(fixed.rotation(theta)[3], DOWN, atol=1e-15)
    axes = orientation_from_spec({'law': 'fixed', 'z': [0, 0, -1], 'x': [1, 0, 0]}, rect)
    assert_allclose(axes.R, DOWN, atol=1e-15)
    sl = orientation_from_spec({'law': 'slerp', 'keyframes': [
        {'theta': 0.0, 'rpy': [np.pi, 0, 0]}, {'theta': 6.0, 'z': [0, 0, -1], 'x': [0, 1, 0]}]},
        rect)
    assert_allclose(sl.rotation(np.array([6.0]))[0], rot_z(np.pi / 2) @ DOWN, atol=1e-12)
    for bad, msg in [({'law': 'wobble'}, 'one of'),
                     ({'law': 'fixed', 'rpy': [0, 0]}, 'rpy must be 3'),
                     ({'law': 'fixed', 'rpy': [0, 0, 0], 'normal': [0, 0, 1]}, 'takes'),
                     ({'law': 'path_normal', 'x_mode': 'spin'}, 'x_mode'),
                     ({'law': 'slerp', 'keyframes': [{'theta': 0.0, 'rpy': [0, 0, 0]}]},
                      '>= 2'),
                     ({'law': 'slerp', 'keyframes': [{'rpy': [0, 0, 0]}, {'theta': 1}]},
                      'needs theta')]:
        with pytest.raises(ValueError, match=msg):
            orientation_from_spec(bad, rect)


class _JointLine:
    """A 'path' whose TCP poses are FK of a straight line in joint space (point, d_point)."""

    def __init__(self, kin, qa, qb):
        self.kin, self.qa, self.qb = kin, np.asarray(qa, float), np.asarray(qb, float)
        self.breaks = np.zeros(0)

    def q(self, theta):
        s = np.asarray(theta, float)[..., None] / (2 * np.pi)
        return self.qa + s * (self.qb - self.qa)

    def point(self, theta):
        return self.kin.fk(np.atleast_2d(self.q(theta)))[:, :3, 3]

    def d_point(self, theta):
        d = 1e-7
        return (self.point(np.asarray(theta) + d) - self.point(np.asarray(theta) - d)) / (2 * d)


class _JointLineLaw(OrientationLaw):
    def __init__(self, line):
        self.line = line

    def rotation(self, theta):
        return self.line.kin.fk(np.atleast_2d(self.line.q(theta)))[:, :3, :3]


def test_wrist_switch_follows_a_path_through_q5_zero(kin):
    """q5 from +0.3 to -0.3 rad (through 0 at a sample): with the wrist flag kept the path is
    refused (q4, q6 would jump by pi); with wrist_switch it is followed, exactly."""
    line = _JointLine(kin, [-0.3, 0.3, -0.2, 0.2, 0.3, 0.1], [0.3, 0.4, -0.1, 0.5, -0.3, -0.4])
    law = _JointLineLaw(line)
    theta = np.linspace(0.0, 2 * np.pi, 201)
    with pytest.raises(UnreachablePoseError, match='jumps'):
        joint_path6(kin, line, law, theta, configuration=('front', 'up', 'noflip'))
    jp = joint_path6(kin, line, law, theta, configuration=('front', 'up', 'noflip'),
                     wrist_switch=True, derivatives=True)
    assert jp.configuration == ('front', 'up', 'switch')
    pos, ori = pose_errors(kin, jp.q, jp.T)
    assert pos.max() <= 1e-9 and ori.max() <= 1e-9
    exact = line.q(theta)
    singular = np.flatnonzero(jp.wrist_singular)
    regular = np.setdiff1d(np.arange(201), singular)
    assert_allclose(jp.q[regular], exact[regular], atol=1e-9)
    assert np.abs(np.diff(jp.q, axis=0)).max() < 0.02
    assert singular.size <= 1             # q5 = 0 at theta = pi (to rounding)
    # dq/dtheta is the line's slope, but where q4 is kept at the singular sample
    far = np.all(np.abs(np.arange(201)[:, None] - singular[None, :]) > 1, axis=1)
    assert_allclose(jp.dq[far], np.broadcast_to((line.qb - line.qa) / (2 * np.pi),
                                                (int(far.sum()), 6)), atol=1e-6)


class _JointCurve(_JointLine):
    """Joint 5 bulging towards its +115 deg limit between samples: 1.92 + 0.089 sin(theta/2)
    rad peaks at 2.009 rad (limit 2.0071) while the samples every 72 deg stay below."""

    def q(self, theta):
        th = np.asarray(theta, float)
        q = np.broadcast_to(self.qa, th.shape + (6,)).copy()
        q[..., 4] = 1.92 + 0.089 * np.sin(th / 2)
        return q


def test_a_limit_crossed_between_samples_is_refused(kin):
    curve = _JointCurve(kin, [0.1, 0.3, -0.2, 0.4, 1.92, 0.1], np.zeros(6))
    law = _JointLineLaw(curve)
    coarse = np.linspace(0.0, 2 * np.pi, 6)
    assert np.all(curve.q(coarse)[:, 4] < kin.upper[4]) and kin.upper[4] < 1.92 + 0.089
    with pytest.raises(UnreachablePoseError, match=r"\['joint_5'\] outside their limits"):
        joint_path6(kin, curve, law, coarse, configuration=('front', 'up', 'noflip'))


def test_smooth_slerp_rests_its_rate_at_keyframes():
    """easing 'smooth' (the default): keyframes hit, the middle of a segment halfway (the
    smootherstep's 1/2), and the rotation rate zero at an inner keyframe (one-sided
    differences), where plain slerp ('linear') has a rate step."""
    Ra, Rb, Rc = DOWN, rot_z(0.8) @ rot_y(0.3) @ DOWN, rot_x(0.5) @ DOWN
    th = [0.0, 2.0, 3.0]
    smooth = KeyframeSlerp(th, [Ra, Rb, Rc])
    linear = KeyframeSlerp(th, [Ra, Rb, Rc], easing='linear')
    assert smooth.easing == 'smooth'
    for law in (smooth, linear):
        R = law.rotation(np.array(th))
        for k, Rk in enumerate((Ra, Rb, Rc)):
            assert_allclose(R[k], Rk, atol=1e-12)
    mid = smooth.rotation(np.array([1.0]))[0]
    assert rotation_error(Ra, mid) == pytest.approx(rotation_error(Ra, Rb) / 2, abs=1e-12)
    h = 1e-4

    def rate(law, a, b):
        Ra_, Rb_ = law.rotation(np.array([a, b]))
        return rotation_error(Ra_, Rb_) / h
    for side in ((2.0 - h, 2.0), (2.0, 2.0 + h)):
        assert rate(smooth, *side) < 1e-6                # ~ h^2: zero rate at the keyframe
        assert rate(linear, *side) > 0.1                 # the plain slerp's constant rate
    with pytest.raises(ValueError, match='easing'):
        KeyframeSlerp(th, [Ra, Rb, Rc], easing='cubic')
    assert orientation_from_spec({'law': 'slerp', 'easing': 'linear', 'keyframes': [
        {'theta': 0.0, 'rpy': [np.pi, 0, 0]}, {'theta': 1.0, 'rpy': [np.pi, 0.2, 0]}]},
        LinePath(np.array([0.6, 0, 0.3]), np.array([0.7, 0, 0.3]))).easing == 'linear'
