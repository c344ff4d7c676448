"""JointState vectorised codec and the eq. 4.1 profile."""
import numpy as np
import pytest
from numpy.testing import assert_allclose

from irb_identification import bagio
from irb_identification.profiles import ConstantVelocityProfile, joint_reference
from irb_identification.series import (JOINT_STATE, JointStateError, decode_joint_states,
                                       encode_joint_states)


def test_codec_matches_rosbags(rng):
    n = 50
    t = 1_700_000_000 * 10**9 + np.arange(n) * 4_032_000
    q, qd, tau = rng.normal(size=(3, n, 3))
    data = encode_joint_states(t, ['a', 'bb', 'ccc'], q, qd, tau, frame_id='base')
    for k in (0, 17, n - 1):
        m = bagio.deserialize(JOINT_STATE, data[k])
        assert list(m.name) == ['a', 'bb', 'ccc'] and m.header.frame_id == 'base'
        assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == t[k]
        assert_allclose(m.position, q[k], rtol=0, atol=0)
        assert_allclose(m.effort, tau[k], rtol=0, atol=0)
    js = decode_joint_states(data, t)
    assert js.names == ('a', 'bb', 'ccc')
    assert_allclose(js.t, t * 1e-9)
    assert_allclose(js.velocity, qd, rtol=0, atol=0)


def test_codec_mixed_layouts_and_errors():
    ts = bagio.typestore()
    JS, H, T = (ts.types[k]
                for k in (JOINT_STATE, 'std_msgs/msg/Header', 'builtin_interfaces/msg/Time'))

    def msg(k, pos, vel, eff, names=('j1', 'j2')):
        return bagio.serialize(JOINT_STATE, JS(
            header=H(stamp=T(sec=k, nanosec=0), frame_id=''), name=list(names),
            position=np.array(pos, float), velocity=np.array(vel, float),
            effort=np.array(eff, float)))

    # same length, different layout (velocity empty, effort longer): per-message fallback
    data = [msg(1, [1, 2], [3, 4], [5, 6]), msg(2, [1, 2], [], [5, 6, 7, 8]),
            msg(3, [9, 9], [9, 9], [9, 9])]
    js = decode_joint_states(data, [0, 0, 0])
    assert np.isnan(js.velocity[1]).all() and np.isnan(js.effort[1]).all()
    assert_allclose(js.position[1], [1, 2])
    assert_allclose(js.t, [1, 2, 3])
    with pytest.raises(JointStateError, match='no effort'):
        decode_joint_states([msg(1, [1, 2], [3, 4], [])], [0])
    with pytest.raises(JointStateError, match='names change'):
        decode_joint_states([msg(1, [1, 2], [3, 4], [5, 6]),
                             msg(2, [1, 2], [3, 4], [5, 6], names=('x', 'y'))], [0, 0])
    with pytest.raises(JointStateError):
        decode_joint_states([data[0][:20]], [0])


@pytest.mark.parametrize('speed', [0.02, 0.5, 2.0])
def test_profile_eq_4_1(speed):
    p = ConstantVelocityProfile.for_speed(speed, accel=8.0, periods=2)
    t = np.linspace(0, p.duration, 200001)
    v, a, x = p.velocity(t), p.acceleration(t), p.position(t)
    dt = t[1] - t[0]
    assert np.max(np.abs(np.diff(v))) < 8.0 * dt * 1.01          # continuous, |qdd| <= a1
    assert_allclose(np.diff(v) / dt, 0.5 * (a[1:] + a[:-1]), atol=8.0 * 1.01)
    integral = np.concatenate([[0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    assert_allclose(x, integral, atol=1e-6)
    assert abs(x[-1]) < 1e-9 and np.max(x) == pytest.approx(p.amplitude, rel=1e-6)
    assert np.max(np.abs(v)) == pytest.approx(speed)
    for t0, t1, c in p.hold_windows():
        sel = (t > t0) & (t < t1)
        assert_allclose(v[sel], c)
    # +c and -c holds cover the same positions (gravity cancels in eq. 4.8)
    (a0, a1, _), (b0, b1, _) = p.hold_windows()[:2]
    assert p.position(a0) == pytest.approx(p.position(b1), abs=1e-9)
    assert p.position(a1) == pytest.approx(p.position(b0), abs=1e-9)


def test_joint_reference_moves_one_joint():
    p = ConstantVelocityProfile.for_speed(0.3)
    t = np.arange(0, p.duration, 0.004032)
    q, qd, qdd = joint_reference(p, 1, np.array([0.1, -0.2, 0.3]), t)
    assert_allclose(q[:, [0, 2]], np.tile([0.1, 0.3], (len(t), 1)))
    assert_allclose(qd[:, 1], p.velocity(t))
    with pytest.raises(ValueError):
        ConstantVelocityProfile(0.0, 1.0, 1.0)

