"""/joint_states names all six joints (irb_description locks 4-6): the bag readers keep reading
joints 1-3 by name, and keep a locked joint that moved."""
import numpy as np

from irb_identification.series import decode_joint_states, encode_joint_states

SIX = [f'joint_{i}' for i in range(1, 7)]


def _series(wrist_moves: bool):
    n = 50
    t_ns = 1_000_000_000 + np.arange(n, dtype=np.int64) * 4_032_000
    rng = np.random.default_rng(3)
    q, qd, tau = (rng.normal(size=(n, 6)) for _ in range(3))
    for a in (q, qd, tau):
        a[:, 3:] = 0.0
    if wrist_moves:
        q[:, 3] = np.linspace(0.0, 0.1, n)
    order = [3, 0, 5, 1, 4, 2]                       # the readers go by name, not by place
    data = encode_joint_states(t_ns, [SIX[i] for i in order], q[:, order], qd[:, order],
                               tau[:, order])
    return decode_joint_states(data, t_ns), q, tau


def test_still_locked_joints_are_left_out_and_1_to_3_read_by_name():
    s, q, tau = _series(wrist_moves=False)
    assert set(s.names) == {'joint_1', 'joint_2', 'joint_3'}
    sel = s.select(['joint_1', 'joint_2', 'joint_3'])
    np.testing.assert_array_equal(sel.position, q[:, :3])
    np.testing.assert_array_equal(sel.effort, tau[:, :3])


def test_a_locked_joint_that_moved_stays():
    s, q, _ = _series(wrist_moves=True)
    assert 'joint_4' in s.names and 'joint_5' not in s.names and len(s.names) == 4
    np.testing.assert_array_equal(s.select(['joint_4']).position[:, 0], q[:, 3])
