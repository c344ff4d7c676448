"""cdr.py against rclpy's own serialization: the loop topics' bytes are the standard ones."""
import math
import struct

import numpy as np
import pytest

from irb_control.cdr import (CONTROLLER_STATE, JOINT_STATE, ControllerStateEncoder,
                             JointStateDecoder, JointStateEncoder, _layout)

serialization = pytest.importorskip('rclpy.serialization')
from irb_interfaces.msg import ControllerState  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

deserialize_message = serialization.deserialize_message
serialize_message = serialization.serialize_message

NAMES = ['joint_1', 'joint_2', 'joint_3']
CASES = [   # names, frame_id, lengths of position, velocity, effort
    (NAMES, '', 3, 3, 3),
    (NAMES, '', 0, 0, 3),
    (NAMES, 'base_link', 3, 0, 0),
    (['a', 'joint_22', 'xyz'], 'f', 1, 2, 3),
    ([], '', 3, 3, 0),
    (['gelenk_ä', 'j'], 'ab', 2, 2, 2),
    (['j'] * 6, 'odd', 6, 6, 6),
]


def _values(rng, n):
    return tuple(rng.normal(size=n).tolist())


@pytest.mark.parametrize('names,frame,npos,nvel,neff', CASES)
def test_joint_state_round_trip_with_rclpy(rng, names, frame, npos, nvel, neff):
    pos, vel, eff = _values(rng, npos), _values(rng, nvel), _values(rng, neff)
    data = JointStateEncoder(names, npos, nvel, neff, frame).encode(
        1_795_000_000, 123_456_789, pos, vel, eff)
    m = deserialize_message(data, JointState)
    assert (m.header.stamp.sec, m.header.stamp.nanosec) == (1_795_000_000, 123_456_789)
    assert m.header.frame_id == frame and list(m.name) == names
    assert tuple(m.position) == pos and tuple(m.velocity) == vel and tuple(m.effort) == eff
    # and the decoder reads rclpy's bytes (which end with a few bytes of slack)
    ref = serialize_message(m)
    got = JointStateDecoder().decode(ref)
    assert got == (1_795_000_000, 123_456_789, tuple(names), pos, vel, eff)
    assert JointStateDecoder().decode(data) == got


def test_decoder_special_values_and_names_cache():
    d = JointStateDecoder()
    m = JointState(name=NAMES, position=[math.nan, math.inf, -0.0], velocity=[1e-300, -1e300,
                                                                              5e-324])
    a = d.decode(serialize_message(m))
    assert math.isnan(a[3][0]) and a[3][1] == math.inf and math.copysign(1, a[3][2]) == -1
    assert a[4] == (1e-300, -1e300, 5e-324) and a[5] == ()
    m.position = [1.0, 2.0, 3.0]
    b = d.decode(serialize_message(m))
    assert b[2] is a[2]                 # same names: the same tuple (cheap identity check)
    m.name = ['joint_3', 'joint_1', 'joint_2']
    assert d.decode(serialize_message(m))[2] == ('joint_3', 'joint_1', 'joint_2')


def test_decoder_refuses_malformed_data_with_value_error():
    d = JointStateDecoder()
    data = JointStateEncoder(NAMES, 3, 3, 3).encode(1, 2, (1.0,) * 3, (2.0,) * 3, (3.0,) * 3)
    for n in range(len(data)):          # every truncation
        with pytest.raises(ValueError):
            d.decode(data[:n])
    with pytest.raises(ValueError):
        d.decode(b'\x00\x02\x00\x00' + data[4:])            # not plain CDR
    huge = bytearray(data)
    at = data.rfind(struct.pack('<I', 3))                    # the effort count
    huge[at:at + 4] = struct.pack('<I', 1 << 30)             # far too big
    with pytest.raises(ValueError):
        d.decode(bytes(huge))
    bad = bytearray(data)
    bad[data.find(b'joint_1') + 7] = 0x41                    # 'joint_1' loses its NUL
    with pytest.raises(ValueError):
        d.decode(bytes(bad))


def test_decoder_reads_big_endian():
    sizes = (0, 3, 7, 7, 7, 3, 3, 3)
    s = struct.Struct('>' + _layout(JOINT_STATE, sizes).format[1:])
    vals = [b'\x00\x00\x00\x00', 7, 8, 1, b'', 3]
    for n in NAMES:
        vals += [8, n.encode()]
    for k in range(3):
        vals += [3, 1.0 + k, 2.0 + k, 3.0 + k]
    got = JointStateDecoder().decode(s.pack(*vals))
    assert got == (7, 8, tuple(NAMES), (1.0, 2.0, 3.0), (2.0, 3.0, 4.0), (3.0, 4.0, 5.0))


@pytest.mark.parametrize('reason', ['', 'x', 'tracking error [0.1, 0.2, 0.0] rad > 0.05',
                                    'Überschreitung'])
def test_controller_state_matches_rclpy(rng, reason):
    arrays = [_values(rng, 3) for _ in range(8)] + [(math.nan,) * 3]
    data = ControllerStateEncoder().encode(12, 34, 4, reason, 1.5, math.nan, 0.25, arrays,
                                           2**40 + 3, 7, 1.25e-4)
    m = deserialize_message(data, ControllerState)
    assert (m.header.stamp.sec, m.header.stamp.nanosec, m.mode) == (12, 34, 4)
    assert m.stop_reason == reason and m.theta == 1.5 and math.isnan(m.theta_predicted)
    assert m.theta_dot_ref == 0.25
    fields = ('q_ref', 'qd_ref', 'qdd_ref', 'q_error', 'qd_error', 'tau_model',
              'tau_friction', 'tau_feedback')
    for f, a in zip(fields, arrays):
        assert tuple(getattr(m, f)) == a
    assert np.isnan(m.tau_command).all()
    assert (m.missed_deadlines, m.rejected_inputs, m.step_duration) == (2**40 + 3, 7, 1.25e-4)
    # the bytes rclpy itself writes carry the same values at the same places
    ref = serialize_message(m)
    assert len(ref) >= len(data)
    assert repr(deserialize_message(ref, ControllerState)) == repr(m)      # NaN-safe


def test_layout_rejects_unknown_types():
    with pytest.raises(ValueError):
        _layout(('f32',), ())
    assert _layout(CONTROLLER_STATE, (0, 0) + (3,) * 9).size > 0
