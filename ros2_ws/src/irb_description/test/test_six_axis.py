"""Six-joint kinematics (six_axis): FK against DH and pinocchio, closed-form IK round trips in
every configuration, the singularities, limits and the continuity helper."""
import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from irb_description.dh import dh_forward
from irb_description.six_axis import (CONFIGURATIONS, SixAxisKinematics, UnreachablePoseError,
                                      pose, rot_x, rot_y, rot_z, rotation_error)

# a nozzle 0.12 m out of the flange, tilted 20 deg about the flange's y and 5 mm sideways
TCP = pose(rot_y(np.radians(20.0)), [0.005, 0.0, 0.12])


@pytest.fixture(scope='module')
def kin(model):
    return SixAxisKinematics(model.kinematics)


@pytest.fixture(scope='module')
def kin_tcp(model):
    return SixAxisKinematics(model.kinematics, tcp=TCP)


def dh(model, q6):
    k = model.kinematics
    return dh_forward(q6, k.dh_a, k.dh_alpha, k.dh_d, k.dh_offset)


def test_zero_pose_is_the_datasheet_geometry(kin):
    T = kin.fk(np.zeros(6))
    assert_allclose(T[:3, 3], [0.15 + 0.6 + 0.065, 0.0, 0.4865 + 0.475], atol=1e-15)
    assert_allclose(T[:3, 2], [1.0, 0.0, 0.0], atol=1e-15)      # z out of the flange: +x
    assert_allclose(kin.wrist_centre(np.zeros(6)), [0.75, 0.0, 0.9615], atol=1e-15)


def test_fk_matches_dh_and_pinocchio_with_and_without_tcp(model, kin, kin_tcp, rng):
    full = model.full
    data = full.createData()
    fid = full.getFrameId('tool0')
    Q = rng.uniform(kin.lower, kin.upper, (200, 6))
    T, T_tcp = kin.fk(Q), kin_tcp.fk(Q)
    for i, q in enumerate(Q):
        T_dh = dh(model, q)
        pin.framesForwardKinematics(full, data, q)
        T_pin = data.oMf[fid].homogeneous
        assert np.abs(T[i] - T_dh).max() <= 1e-9
        assert np.abs(T[i] - T_pin).max() <= 1e-9
        assert np.abs(T_tcp[i] - T_dh @ TCP).max() <= 1e-9
        assert np.abs(T_tcp[i] - T_pin @ TCP).max() <= 1e-9


@pytest.mark.parametrize('tcp', [False, True], ids=['tool0', 'nozzle'])
def test_ik_round_trip_in_every_configuration(model, kin, kin_tcp, rng, tcp):
    """Random joint vectors inside the limits: every solution returned reproduces the pose to
    1e-9 (checked with the DH kinematics), carries the configuration its q has, and the
    original joint vector is among them (ik_nearest returns it)."""
    k = kin_tcp if tcp else kin
    seen = dict.fromkeys(CONFIGURATIONS, 0)
    Q = rng.uniform(k.lower, k.upper, (150, 6))
    for q in Q:
        T = k.fk(q)
        sols = k.ik(T)
        assert sols, f'no solution for the pose of {q}'
        for s in sols:
            assert not np.any(np.isnan(s.q)) and s.within_limits
            assert k.within_limits(s.q)
            T_dh = dh(model, s.q) @ k.tcp
            assert np.abs(T_dh - T).max() <= 1e-9
            assert k.configuration(s.q) == s.configuration
            seen[s.configuration] += 1
        assert k.configuration(q) in [s.configuration for s in sols]
        near = k.ik_nearest(T, q)
        assert np.abs(near.q - q).max() <= 1e-7
    assert min(seen.values()) >= 5, seen


def test_ik_front_elbow_up_with_locked_wrist_is_the_three_axis_ik(model, kin, rng):
    lim = model.limits
    n = 0
    for _ in range(100):
        q3 = rng.uniform(lim.lower, lim.upper)
        q3[2] = rng.uniform(-np.pi / 2 + 0.05, min(lim.upper[2], np.pi / 2) - 0.05)
        p = model.fk(q3)
        q6 = np.concatenate([q3, np.zeros(3)])
        if np.hypot(p[0], p[1]) < 0.05 or kin.configuration(q6)[0] != 'front':
            continue      # the three-axis IK has q1 = atan2(y, x): the front shoulder only
        n += 1
        s = kin.ik_nearest(kin.fk(q6), np.zeros(6), configuration=('front', 'up', 'noflip'))
        assert_allclose(s.q[:3], model.ik(p, check_limits=False), atol=1e-9)
        assert_allclose(s.q, q6, atol=1e-9)
    assert n >= 30


@pytest.mark.parametrize('q5', [0.0, 1e-12, -3e-10])
def test_wrist_singularity_keeps_q4_and_is_flagged(model, kin, q5):
    q = np.array([0.3, 0.2, -0.1, 0.7, q5, 0.4])
    T = kin.fk(q)
    ref = np.array([0.0, 0.0, 0.0, -0.5, 0.0, 0.0])
    for seed in (None, ref):
        sols = kin.ik(T, q_ref=seed)
        front_up = [s for s in sols if s.shoulder == 'front' and s.elbow == 'up']
        assert len(front_up) == 1           # flip and noflip coincide there
        s = front_up[0]
        assert s.wrist_singular and not np.any(np.isnan(s.q))
        assert s.q[3] == pytest.approx(0.0 if seed is None else -0.5, abs=1e-15)
        assert s.q[3] + s.q[5] == pytest.approx(q[3] + q[5], abs=1e-9)
        assert np.abs(dh(model, s.q) - T).max() <= 1e-9


def test_shoulder_singularity_wrist_centre_on_axis_1(model, kin):
    # joint 2 at 0, joint 3 such that the wrist centre is on axis 1: 0.15 + 0.6 cos q3 = 0
    q = np.array([0.4, 0.0, -np.arccos(-0.25), 0.3, 0.8, -0.2])
    assert np.hypot(*kin.wrist_centre(q)[:2]) < 1e-12
    T = kin.fk(q)
    sols = kin.ik(T, q_ref=np.array([1.1, 0, 0, 0, 0, 0]))
    assert sols
    for s in sols:
        assert s.shoulder_singular and not np.any(np.isnan(s.q))
        assert np.abs(dh(model, s.q) - T).max() <= 1e-9
        assert s.q[0] in (pytest.approx(1.1), pytest.approx(1.1 - np.pi))
    assert kin.ik_nearest(T, q).q == pytest.approx(q, abs=1e-9)


def test_limits_applied_and_unreachable_poses(kin):
    # q5 = 120 deg is outside +-115 deg: that pose's noflip branch needs it
    q = np.array([0.0, 0.3, -0.2, 0.0, np.radians(120.0), 0.0])
    T = kin.fk(q)
    inside = kin.ik(T)
    everything = kin.ik(T, check_limits=False)
    assert len(everything) > len(inside)
    assert all(kin.within_limits(s.q) for s in inside)
    assert any(not s.within_limits for s in everything)
    with pytest.raises(UnreachablePoseError, match='no solution inside the joint limits'):
        kin.ik_nearest(T, q, configuration=('front', 'up', 'noflip'))
    far = pose(np.eye(3), [2.0, 0.0, 0.5])
    assert kin.ik(far) == []
    with pytest.raises(UnreachablePoseError):
        kin.ik_nearest(far, np.zeros(6))
    with pytest.raises(UnreachablePoseError, match='not a rotation'):
        kin.ik(pose(2 * np.eye(3), [0.7, 0, 0.5]))
    with pytest.raises(ValueError, match='configuration'):
        kin.ik_config(far, ('front', 'sideways', 'noflip'))


def test_nearest_picks_the_turn_of_q6_nearest_the_seed(kin):
    q = np.array([0.1, 0.3, -0.2, 0.4, 0.6, 2 * np.pi - 0.3])   # q6 = 343 deg (limit 400)
    T = kin.fk(q)
    assert kin.ik_nearest(T, q).q == pytest.approx(q, abs=1e-9)
    assert kin.ik_nearest(T, np.zeros(6)).q[5] == pytest.approx(-0.3, abs=1e-9)


def test_rotation_error_is_the_angle(rng):
    for a in (1e-10, 1e-4, 0.5, 3.0):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        R0 = rot_z(0.3) @ rot_x(-0.7)
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        R = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
        assert rotation_error(R0, R0 @ R) == pytest.approx(a, rel=1e-6, abs=1e-15)


def test_ik_one_in_plain_floats_equals_ik_config(kin_tcp, rng):
    """The control-loop form: same branches, representatives and singular choice."""
    k = kin_tcp
    Q = rng.uniform(k.lower, k.upper, (50, 6))
    refs = rng.uniform(k.lower, k.upper, (50, 6))      # random: no ties between two turns
    Q[:5, 4] = 0.0                                       # and a few wrist-singular poses
    for q, ref in zip(Q, refs):
        T = k.fk(q)
        for cfg in CONFIGURATIONS:
            r = k.ik_config(T, cfg, ref)
            q1, inside, wsing = k.ik_one(T, cfg, ref)
            if not r.reachable[0]:
                assert q1 is None
                continue
            assert np.abs(np.asarray(q1) - r.q[0]).max() <= 1e-12
            assert inside == r.within_limits[0] and wsing == r.wrist_singular[0]
    assert k.ik_one(pose(np.eye(3), [2.0, 0.0, 0.5])) == (None, False, False)
