"""/joint_states names all six joints (4-6 locked): the loop's readers pick joints 1-3 by name
and refuse a state without them, with the reason."""
import pytest
from irb_description.robot_state import six_joint_names, six_joints

from irb_control.cdr import JointSelector, JointStateDecoder, JointStateEncoder

SIX = [f'joint_{i}' for i in range(1, 7)]
THREE = ('joint_1', 'joint_2', 'joint_3')


def test_six_joint_state_bytes_decode_to_joints_1_to_3_by_name():
    assert list(six_joint_names()) == SIX
    pos, vel, eff = six_joints([0.1, -0.2, 0.3], [1.0, 2.0, 3.0], [10.0, 20.0, 30.0])
    assert pos == [0.1, -0.2, 0.3, 0.0, 0.0, 0.0] and vel[3:] == [0.0] * 3 and eff[3:] == [0.0] * 3
    order = [5, 2, 0, 4, 1, 3]                      # any order: selection is by name
    names = [SIX[i] for i in order]
    data = JointStateEncoder(names, 6, 6, 6).encode(
        1, 2, [pos[i] for i in order], [vel[i] for i in order], [eff[i] for i in order])
    sec, nanosec, got_names, p, v, e = JointStateDecoder().decode(data)
    sel = JointSelector(THREE)
    assert sel.select(got_names, p) == (0.1, -0.2, 0.3)
    assert sel.select(got_names, v) == (1.0, 2.0, 3.0)
    assert sel.select(got_names, e) == (10.0, 20.0, 30.0)


def test_selector_refuses_a_state_without_joints_1_to_3_with_the_reason():
    sel = JointSelector(THREE)
    with pytest.raises(ValueError, match='without joint_2 .*joint_1, joint_3, joint_4'):
        sel.select(('joint_1', 'joint_3', 'joint_4'), (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match='2 values for 6 joints'):
        sel.select(tuple(SIX), (0.0, 0.0))
    assert sel.select((), (4.0, 5.0, 6.0, 7.0)) == (4.0, 5.0, 6.0)   # no names: by position


def test_six_joints_refuses_other_lengths():
    with pytest.raises(ValueError, match='3 or 6'):
        six_joints([0.0] * 4, [0.0] * 3, [0.0] * 3)
    assert six_joints(range(6), range(6), range(6))[0] == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]


def test_pdplus_picks_joints_1_to_3_of_a_six_joint_state():
    from irb_control.pdplus_node import _joint_indices
    names = tuple(SIX[::-1])
    assert _joint_indices(names, list(THREE)) == (5, 4, 3)
    assert _joint_indices(('joint_4', 'joint_5'), list(THREE)) is None
