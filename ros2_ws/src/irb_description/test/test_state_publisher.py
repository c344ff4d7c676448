"""state_publisher: /tf through the URDF, checked against a forward kinematics of its own.

The oracle is the thesis's DH table (Table 3.2, eq. 3.2-3.4) written out below in a few lines:
it shares nothing with the URDF, ``robot_state`` or pinocchio. The node's output is recorded
into an MCAP file and read back with the ``mcap`` reader and the ``mcap_ros2`` decoder (not the
project's bagio); the TF chain base_link -> tool0 is resolved at every joint-state stamp.
"""
import math
import os
import uuid

import numpy as np
import pytest

from irb_description.params import urdf_path
from irb_description.robot_state import TfTree, Trace, six_joints

# thesis Table 3.2: a [m], alpha [rad], d [m], theta offset [rad]
DH_A = (0.150, 0.475, 0.0, 0.0, 0.0, 0.0)
DH_ALPHA = tuple(math.radians(v) for v in (-90, 0, -90, 90, 90, 0))
DH_D = (0.4865, 0.0, 0.0, 0.600, 0.0, 0.065)
DH_OFFSET = tuple(math.radians(v) for v in (0, -90, 0, 0, 180, 0))
SIX = [f'joint_{i}' for i in range(1, 7)]
TOL = 1e-6


def dh_pose(q) -> np.ndarray:
    """base_link -> tool0 (4, 4): product of Rz(theta) Tz(d) Tx(a) Rx(alpha)."""
    T = np.eye(4)
    for qi, a, al, d, off in zip(q, DH_A, DH_ALPHA, DH_D, DH_OFFSET):
        ct, st = math.cos(qi + off), math.sin(qi + off)
        ca, sa = math.cos(al), math.sin(al)
        T = T @ np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                          [0, sa, ca, d], [0, 0, 0, 1]])
    return T


def random_q6(rng, n):
    lo = np.radians([-180, -63, -235, -200, -115, -400])
    hi = np.radians([180, 110, 55, 200, 115, 400])
    return rng.uniform(lo, hi, size=(n, 6))


def test_tree_matches_the_dh_table_and_fills_locked_joints(rng):
    tree = TfTree(urdf_path().read_text())
    assert tree.names == SIX and [j.child for j in tree.fixed] == ['tool0']
    for q in random_q6(rng, 200):
        np.testing.assert_allclose(tree.pose(q, 'base_link', 'tool0'), dh_pose(q), atol=1e-9)
    # a three-joint state: 4-6 at their locked position (0); a state without joint 2: refused
    q, missing = tree.positions(['joint_3', 'joint_1', 'joint_2'], [0.3, 0.1, 0.2])
    assert q == [0.1, 0.2, 0.3, 0.0, 0.0, 0.0] and missing == []
    q, missing = tree.positions(['joint_1', 'joint_3'], [0.1, 0.3])
    assert q is None and missing == ['joint_2']
    with pytest.raises(ValueError, match='no chain'):
        tree.pose(q or [0.0] * 6, 'tool0', 'base_link')


def test_trace_is_bounded_and_throttled():
    tr = Trace(duration_s=1.0, sample_period_s=0.1, rate_hz=2.0)
    published = 0
    for k in range(500):                   # 2 s of 4 ms states
        t = k * 0.004
        if tr.wants(t):
            tr.add(t, (t, 0.0, 0.0))
        published += tr.due(t)
    first, last = tr.points[0][0], tr.points[-1][0]
    assert len(tr.points) == 11                     # duration / sample period + 1
    assert 1.996 - last < 0.1 + 0.004 and last - first < 1.0 + 0.1 + 0.004
    assert published == 4
    assert tr.wants(0.0) and not tr.points          # time went back (a new replay): restart


rclpy = pytest.importorskip('rclpy')


@pytest.mark.ros
@pytest.mark.parametrize('names', [SIX, ['joint_1', 'j2', 'joint_3xx'], ['a'], []])
@pytest.mark.parametrize('frame_id', ['', 'abc', 'abcde'])
def test_serialized_joint_state_and_tf_agree_with_rclpy(names, frame_id):
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState
    from tf2_msgs.msg import TFMessage

    from irb_description.robot_state import JointStateReader, TfEncoder
    js = JointState(name=names, position=[0.1 * k - 0.2 for k in range(len(names))],
                    velocity=[1.0] * len(names))
    js.header.stamp.sec, js.header.stamp.nanosec, js.header.frame_id = 5, 7, frame_id
    data = serialize_message(js)
    reader = JointStateReader()
    assert reader.read(data) == (5, 7, tuple(names), tuple(js.position))
    assert reader.read(data)[2] is reader.read(data)[2]       # names kept while unchanged
    for bad in (data[:len(data) // 2], b'\x00\x02\x00\x00' + data[4:]):
        with pytest.raises(ValueError):
            reader.read(bad)
    tree = TfTree(urdf_path().read_text())
    tr = tree.transforms([0.1, -0.2, 0.3, 0.4, -0.5, 0.6])
    msg = deserialize_message(TfEncoder([(p, c) for p, c, _, _ in tr]).encode(9, 11, tr),
                              TFMessage)
    assert [(m.header.frame_id, m.child_frame_id) for m in msg.transforms] == [
        (p, c) for p, c, _, _ in tr]
    for m, (_, _, t, q) in zip(msg.transforms, tr):
        assert (m.header.stamp.sec, m.header.stamp.nanosec) == (9, 11)
        v, r = m.transform.translation, m.transform.rotation
        assert (v.x, v.y, v.z) == t and (r.x, r.y, r.z, r.w) == q


@pytest.mark.ros
def test_recorded_tf_resolves_base_to_tool0_at_every_joint_state(tmp_path, rng):
    from mcap.reader import make_reader
    from mcap.writer import Writer
    from mcap_ros2.decoder import DecoderFactory
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rosbags.typesys import Stores, get_typestore
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from tf2_msgs.msg import TFMessage
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    from visualization_msgs.msg import MarkerArray

    from irb_description.state_publisher import make_node

    ns = f'/sp_{uuid.uuid4().hex[:8]}'
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '0')))
    node = make_node(context=ctx, namespace=ns, cli_args=[
        '--ros-args', '-r', f'/tf:={ns}/tf', '-r', f'/tf_static:={ns}/tf_static',
        '-p', 'trace_rate_hz:=50.0', '-p', 'trace_sample_period_s:=0.004'])
    peer = rclpy.create_node('sp_peer', namespace=ns, context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    executor.add_node(peer)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    reliable = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE)
    types = {'tf': TFMessage, 'tf_static': TFMessage, 'joint_states': JointState,
             'robot_description': String, 'visualization/planned_path': MarkerArray,
             'visualization/tcp_trace': MarkerArray}
    got = {t: [] for t in types}
    for topic, ty in types.items():
        qos = latched if topic in ('tf_static', 'robot_description',
                                   'visualization/planned_path') else reliable
        peer.create_subscription(ty, f'{ns}/{topic}', lambda d, t=topic: got[t].append(d), qos,
                                 raw=True)
    pub = peer.create_publisher(JointState, f'{ns}/joint_states', reliable)
    plan_pub = peer.create_publisher(JointTrajectory, f'{ns}/planned_trajectory', latched)

    def spin_until(cond, bound_s=60.0):
        deadline = peer.get_clock().now().nanoseconds + bound_s * 1e9
        while not cond() and peer.get_clock().now().nanoseconds < deadline:
            executor.spin_once(timeout_sec=0.05)
        return cond()

    n = 60
    q6 = random_q6(rng, n)
    q6[: n // 2, 3:] = 0.0            # first half as the simulator sends them (4-6 locked)
    plan_q = random_q6(rng, 7)[:, :3]
    try:
        assert spin_until(lambda: pub.get_subscription_count() >= 1
                          and node.pub_tf.get_subscription_count() >= 1
                          and got['tf_static'] and got['robot_description'])
        for k in range(n):
            pos, vel, eff = six_joints(q6[k], [0.0] * 6, [0.0] * 6)
            m = JointState(name=SIX, position=pos, velocity=vel, effort=eff)
            m.header.stamp.sec, m.header.stamp.nanosec = 100, k * 4_032_000
            pub.publish(m)
        plan_pub.publish(JointTrajectory(joint_names=SIX[:3], points=[
            JointTrajectoryPoint(positions=list(q)) for q in plan_q]))
        assert spin_until(lambda: len(got['tf']) >= n and len(got['joint_states']) >= n
                          and got['visualization/planned_path']), \
            f'{len(got["tf"])} /tf of {n} joint states'
    finally:
        executor.shutdown()
        node.destroy_node()
        peer.destroy_node()
        rclpy.try_shutdown(context=ctx)

    # record what arrived into an MCAP file (ros2 profile, the way rosbag2 writes it)
    store = get_typestore(Stores.ROS2_JAZZY)
    bag = tmp_path / 'tf.mcap'
    with open(bag, 'wb') as f:
        w = Writer(f)
        w.start(profile='ros2', library='test_state_publisher')
        for topic, ty in types.items():
            name = f'{ty.__module__.split(".")[0]}/msg/{ty.__name__}'
            schema = w.register_schema(name, 'ros2msg',
                                       store.generate_msgdef(name, ros_version=2)[0].encode())
            channel = w.register_channel(f'/{topic}', 'cdr', schema)
            for i, data in enumerate(got[topic]):
                w.add_message(channel, log_time=i, data=data, publish_time=i)
        w.finish()

    # read it back with the mcap reader and resolve base_link -> tool0 per joint-state stamp
    tf_at, static, states = {}, {}, []
    with open(bag, 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages():
            if channel.topic in ('/tf', '/tf_static'):
                for tr in msg.transforms:
                    key = (tr.header.stamp.sec, tr.header.stamp.nanosec)
                    target = static if channel.topic == '/tf_static' else tf_at.setdefault(
                        key, {})
                    target[tr.child_frame_id] = tr
            elif channel.topic == '/joint_states':
                states.append(msg)
            elif channel.topic == '/robot_description':
                assert msg.data == urdf_path().read_text()
            elif channel.topic == '/visualization/planned_path':
                path = [(p.x, p.y, p.z) for p in msg.markers[0].points]
                assert msg.markers[0].header.frame_id == 'base_link'
            elif channel.topic == '/visualization/tcp_trace':
                trace = [(p.x, p.y, p.z) for p in msg.markers[0].points]

    def matrix(tr):
        x, y, z, w = (tr.transform.rotation.x, tr.transform.rotation.y,
                      tr.transform.rotation.z, tr.transform.rotation.w)
        T = np.eye(4)
        T[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
        T[:3, 3] = (tr.transform.translation.x, tr.transform.translation.y,
                    tr.transform.translation.z)
        return T

    assert len(states) == n and len(tf_at) == n
    tcp = []
    for js in states:
        frames = dict(static)
        frames.update(tf_at[(js.header.stamp.sec, js.header.stamp.nanosec)])
        T, link = np.eye(4), 'tool0'
        while link != 'base_link':
            tr = frames[link]
            T = matrix(tr) @ T
            link = tr.header.frame_id
        q = [js.position[list(js.name).index(j)] for j in SIX]
        ref = dh_pose(q)
        assert np.abs(T[:3, 3] - ref[:3, 3]).max() < TOL
        assert np.abs(T[:3, :3] - ref[:3, :3]).max() < TOL
        tcp.append(ref[:3, 3])
    # markers: the planned path is the TCP of each planned point (4-6 locked), the trace a
    # run of the latest TCP positions
    assert len(path) == len(plan_q)
    for p, q in zip(path, plan_q):
        assert np.abs(np.array(p) - dh_pose(list(q) + [0.0] * 3)[:3, 3]).max() < TOL
    assert len(trace) >= 2
    for p in trace:
        assert np.min(np.abs(np.array(tcp) - p).max(axis=1)) < TOL
