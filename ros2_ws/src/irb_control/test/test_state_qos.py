"""QoS of the 248 Hz topics: what the simulator and pdplus publish reaches a subscriber with the
ROS default QoS (reliable, as `ros2 topic echo`, rqt and most user nodes use) and the loop's
best-effort subscriber alike; a best-effort writer (the old setting) does not reach the first.

Publishers and subscribers live in separate Contexts (separate DDS participants), so matching
and delivery go through DDS discovery as between processes."""
import os
import uuid

import pytest

rclpy = pytest.importorskip('rclpy')
from rclpy.event_handler import SubscriptionEventCallbacks  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.task import Future  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from irb_control.pdplus_node import PdPlusNode  # noqa: E402
from irb_control.simulator_node import SimulatorNode, _stamp  # noqa: E402
from irb_description.node_main import state_pub_qos, state_qos  # noqa: E402

pytestmark = pytest.mark.ros
TIMEOUT = 30.0
DEFAULT_QOS = QoSProfile(depth=10)           # what rclpy gives `create_subscription(.., 10)`


def _context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    return ctx


class _Received:
    """Future done when the first message arrives; incompatible-QoS events counted."""

    def __init__(self, node, typ, topic, qos):
        self.first = Future()
        self.incompatible = Future()
        self.count = 0
        cbs = SubscriptionEventCallbacks(incompatible_qos=self._incompatible)
        node.create_subscription(typ, topic, self._cb, qos, event_callbacks=cbs)

    def _cb(self, msg):
        self.count += 1
        if not self.first.done():
            self.first.set_result(msg)

    def _incompatible(self, event):
        if not self.incompatible.done():
            self.incompatible.set_result(event)


@pytest.fixture
def graph():
    """(publisher side context, listener node, executor spinning both, namespace)."""
    pub_ctx, sub_ctx = _context(), _context()
    ns = f'/q{uuid.uuid4().hex[:8]}'
    listener = rclpy.create_node('listener', namespace=ns, context=sub_ctx)
    ex_pub = SingleThreadedExecutor(context=pub_ctx)
    ex_sub = SingleThreadedExecutor(context=sub_ctx)
    nodes = []
    yield pub_ctx, listener, (ex_pub, ex_sub), ns, nodes
    for ex in (ex_pub, ex_sub):
        ex.shutdown()
    for n in nodes:
        n.destroy_node()
    listener.destroy_node()
    rclpy.try_shutdown(context=pub_ctx)
    rclpy.try_shutdown(context=sub_ctx)


def _spin_until(executors, done, publish, timeout=TIMEOUT):
    """Publish and spin both sides until ``done()``; bounded, no sleeps."""
    import time
    end = time.monotonic() + timeout
    while not done() and time.monotonic() < end:
        publish()
        for ex in executors:
            ex.spin_once(timeout_sec=0.01)
    return done()


def test_state_publisher_qos_is_reliable_keep_last_1():
    q = state_pub_qos()
    assert q.reliability == ReliabilityPolicy.RELIABLE and q.depth >= 1
    assert state_qos().reliability == ReliabilityPolicy.BEST_EFFORT and state_qos().depth == 1


def test_simulator_joint_states_reach_default_and_best_effort_subscribers(graph):
    pub_ctx, listener, executors, ns, nodes = graph
    sim = SimulatorNode(context=pub_ctx, namespace=ns)
    nodes.append(sim)
    executors[0].add_node(sim)
    executors[1].add_node(listener)
    default = _Received(listener, JointState, f'{ns}/joint_states', DEFAULT_QOS)
    loop = _Received(listener, JointState, f'{ns}/joint_states', state_qos())
    t = [100.0]

    def publish():
        t[0] += 0.004032
        sim._publish_state(_stamp(t[0]))
    assert _spin_until(executors, lambda: default.first.done() and loop.first.done(), publish)
    assert not default.incompatible.done() and not loop.incompatible.done()
    for r in (default, loop):        # the simulator's own message, decoded by rclpy
        m = r.first.result()
        assert list(m.name) == [f'joint_{i}' for i in range(1, 7)] and len(m.position) == 6
        assert m.header.stamp.sec >= 100


def test_pdplus_command_and_state_reach_default_subscribers(graph):
    pub_ctx, listener, executors, ns, nodes = graph
    ctrl = PdPlusNode(context=pub_ctx, namespace=ns, parameter_overrides=[
        Parameter('executor', value='single')])
    nodes.append(ctrl)
    executors[0].add_node(ctrl)
    executors[1].add_node(listener)
    cmd_default = _Received(listener, JointState, f'{ns}/torque_command', DEFAULT_QOS)
    cmd_loop = _Received(listener, JointState, f'{ns}/torque_command', state_qos())
    sent = JointState(name=['joint_1', 'joint_2', 'joint_3'], effort=[1.0, -2.0, 3.5])

    # pdplus's own publisher object (its QoS as created by the node)
    assert _spin_until(executors, lambda: cmd_default.first.done() and cmd_loop.first.done(),
                       lambda: ctrl.pub_cmd.publish(sent))
    assert list(cmd_default.first.result().effort) == [1.0, -2.0, 3.5]
    assert list(cmd_loop.first.result().effort) == [1.0, -2.0, 3.5]
    infos = listener.get_publishers_info_by_topic(f'{ns}/controller_state')
    assert infos and all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)


def test_best_effort_writer_does_not_reach_default_subscriber(graph):
    """The negative control: the old setting gives a default subscriber nothing but an
    incompatible-QoS event (so the test above can tell the settings apart)."""
    pub_ctx, listener, executors, ns, nodes = graph
    node = rclpy.create_node('old_writer', namespace=ns, context=pub_ctx)
    nodes.append(node)
    executors[0].add_node(node)
    executors[1].add_node(listener)
    old = node.create_publisher(JointState, 'joint_states', state_qos())
    default = _Received(listener, JointState, f'{ns}/joint_states', DEFAULT_QOS)
    loop = _Received(listener, JointState, f'{ns}/joint_states', state_qos())
    msg = JointState(name=['joint_1'], position=[0.5])
    assert _spin_until(executors, lambda: default.incompatible.done() and loop.first.done(),
                       lambda: old.publish(msg))
    assert default.count == 0
