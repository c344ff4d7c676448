"""pdplus node in-process: private Context, explicit executor, futures set in callbacks."""
import os
import uuid

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from irb_interfaces.msg import ControllerState  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.task import Future  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from irb_control import pd_plus  # noqa: E402
from irb_description.node_main import latched_qos, state_qos  # noqa: E402
from irb_control.pdplus_node import PdPlusNode  # noqa: E402
from irb_control.trajectory_io import theta_profile_msg  # noqa: E402
from irb_control.profiles import polynomial_theta_of_time  # noqa: E402

pytestmark = pytest.mark.ros
T = 0.004032
TIMEOUT = 30.0


@pytest.fixture
def graph():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    ns = f'/t{uuid.uuid4().hex[:8]}'
    ctrl = PdPlusNode(context=ctx, namespace=ns, parameter_overrides=[
        Parameter('executor', value='single')])
    peer = rclpy.create_node('peer', namespace=ns, context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(ctrl)
    ex.add_node(peer)
    yield ctrl, peer, ex, ns
    ex.shutdown()
    ctrl.destroy_node()
    peer.destroy_node()
    rclpy.try_shutdown(context=ctx)


class Collector:
    """Collects messages; ``wait(pred)`` completes a future when pred(msg) is true."""

    def __init__(self, node, typ, topic, qos):
        self.msgs = []
        self.pred = None
        self.future = None
        node.create_subscription(typ, topic, self.cb, qos)

    def cb(self, msg):
        self.msgs.append(msg)
        if self.future is not None and not self.future.done() and self.pred(msg):
            self.future.set_result(msg)

    def expect(self, pred):
        """Future of the first message from now on with pred(msg)."""
        self.pred = pred
        self.future = Future()
        return self.future


def joint_state(stamp_s, q, qd=(0.0, 0.0, 0.0)):
    m = JointState(name=['joint_1', 'joint_2', 'joint_3'], position=list(q), velocity=list(qd),
                   effort=[0.0] * 3)
    m.header.stamp.sec = int(stamp_s)
    m.header.stamp.nanosec = int(round((stamp_s - int(stamp_s)) * 1e9))
    return m


def feed_joint_states(peer, ns, t0, q):
    """A timer on ``peer`` publishing joint states at pose q every period, stamped t0 + k T."""
    pub = peer.create_publisher(JointState, f'{ns}/joint_states', state_qos())
    k = [0]

    def feed():
        k[0] += 1
        pub.publish(joint_state(t0 + k[0] * T, q))
    return peer.create_timer(T, feed)


def spin_for(ex, fut):
    ex.spin_until_future_complete(fut, timeout_sec=TIMEOUT)
    assert fut.done(), 'event did not happen within the timeout'
    return fut.result()


def test_command_answers_state_and_nan_is_rejected(graph):
    ctrl, peer, ex, ns = graph
    q0 = ctrl.ctrl.start_pose()
    cmds = Collector(peer, JointState, f'{ns}/torque_command', state_qos())
    states = Collector(peer, ControllerState, f'{ns}/controller_state', state_qos())
    pub = peer.create_publisher(JointState, f'{ns}/joint_states', state_qos())
    fut = cmds.expect(lambda m: m.header.stamp.sec == 100)
    # publish until the (best-effort) subscription is matched and answered
    timer = peer.create_timer(T, lambda: pub.publish(joint_state(100.0, q0)))
    cmd = spin_for(ex, fut)
    assert list(cmd.name) == ['joint_1', 'joint_2', 'joint_3']
    g = ctrl.model.gravity(q0)
    assert np.allclose(cmd.effort, g, atol=60.0)     # about gravity + friction FF at rest
    peer.destroy_timer(timer)
    n_cmds = len(cmds.msgs)
    fut = states.expect(lambda m: m.rejected_inputs >= 1)
    timer = peer.create_timer(T, lambda: pub.publish(joint_state(100.1, [np.nan, 0.0, 0.0])))
    st = spin_for(ex, fut)
    peer.destroy_timer(timer)
    assert all(np.isfinite(c.effort).all() for c in cmds.msgs)
    assert len(cmds.msgs) == n_cmds                   # no command for the NaN samples
    assert st.mode != ControllerState.MODE_STOPPED or 'watchdog' in st.stop_reason


def test_stop_enable_services_and_watchdog(graph):
    ctrl, peer, ex, ns = graph
    q0 = ctrl.ctrl.start_pose()
    states = Collector(peer, ControllerState, f'{ns}/controller_state', state_qos())
    Collector(peer, JointState, f'{ns}/torque_command', state_qos())    # auto_enable needs it
    timer = feed_joint_states(peer, ns, 10.0, q0)
    spin_for(ex, states.expect(lambda m: m.mode == ControllerState.MODE_RAMP))

    stop = peer.create_client(Trigger, f'{ns}/pdplus/stop')
    assert stop.wait_for_service(timeout_sec=TIMEOUT)
    assert spin_for(ex, stop.call_async(Trigger.Request())).success
    st = spin_for(ex, states.expect(lambda m: m.mode == ControllerState.MODE_STOPPED))
    assert st.stop_reason == 'stop service'
    n = len(states.msgs)
    spin_for(ex, states.expect(lambda m: len(states.msgs) > n + 20))
    assert states.msgs[-1].mode == ControllerState.MODE_STOPPED      # latched

    enable = peer.create_client(Trigger, f'{ns}/pdplus/enable')
    assert enable.wait_for_service(timeout_sec=TIMEOUT)
    assert spin_for(ex, enable.call_async(Trigger.Request())).success
    spin_for(ex, states.expect(lambda m: m.mode == ControllerState.MODE_RAMP))

    # the joint states stop: the steady-clock watchdog latches a safe stop
    peer.destroy_timer(timer)
    st = spin_for(ex, states.expect(lambda m: m.mode == ControllerState.MODE_STOPPED
                                    and 'watchdog' in m.stop_reason))
    assert 'no valid joint_states' in st.stop_reason


def test_theta_profile_from_planned_trajectory(graph):
    ctrl, peer, ex, ns = graph
    from trajectory_msgs.msg import JointTrajectory
    pub = peer.create_publisher(JointTrajectory, f'{ns}/planned_trajectory', latched_qos())
    t, th, thd, thdd = polynomial_theta_of_time(15.0, n=301)
    pub.publish(theta_profile_msg(t, th, thd, thdd))
    fut = Future()
    old = ctrl.ctrl.profile
    timer = peer.create_timer(0.01, lambda: fut.set_result(True)
                              if ctrl.ctrl.profile is not old and not fut.done() else None)
    spin_for(ex, fut)
    peer.destroy_timer(timer)
    prof = ctrl.ctrl.profile
    assert prof.t[-1] == pytest.approx(15.0, abs=0.1)
    assert np.max(prof.theta_dot) == pytest.approx(np.max(thd), rel=1e-3)


class _Capture:
    """Stands in for a publisher: keeps what is published."""

    def __init__(self):
        self.sent = []

    def publish(self, msg):
        self.sent.append(msg)

    def get_subscription_count(self):
        return 1


def test_hot_path_commands_identical_to_the_controller(graph):
    """The serialized path (raw subscription, bytes out) sends exactly the torques of
    PdPlusController.step for the same measurements, through ramp and path, and the
    message-object path the same bytes; other joint orders give the same command."""
    from rclpy.serialization import deserialize_message, serialize_message

    from irb_control.closed_loop import build_default
    from irb_control.pd_plus import PdPlusController
    ctrl, _, _, _ = graph
    ref = PdPlusController(ctrl.model, ctrl.path, ctrl.ctrl.config, ctrl.ctrl.friction)
    ref.set_path_profile(ctrl.ctrl.profile)
    ref.enable()
    plant, _ = build_default(friction_mode='nominal', duration_s=10.0)
    ctrl.pub_cmd, ctrl.pub_state = _Capture(), _Capture()
    assert ctrl.on_enable(Trigger.Request(), Trigger.Response()).success   # as ref: at once
    modes = set()
    order = [2, 0, 1]
    for k in range(400):
        y = plant.measure()
        t = 50.0 + k * T
        msg = joint_state(t, y.q.tolist(), y.qd.tolist())
        out = ref.step(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9, y.q, y.qd)
        modes.add(out.mode)
        n = len(ctrl.pub_cmd.sent)
        if k % 3 == 0:
            ctrl.on_state_raw(serialize_message(msg))
        elif k % 3 == 1:
            ctrl.on_state(msg)
        else:       # same joints, other order in the message
            perm = joint_state(t, y.q[order].tolist(), y.qd[order].tolist())
            perm.name = [msg.name[i] for i in order]
            ctrl.on_state_raw(serialize_message(perm))
        assert out.publish and len(ctrl.pub_cmd.sent) == n + 1
        cmd = deserialize_message(ctrl.pub_cmd.sent[-1], JointState)
        assert cmd.effort.tolist() == out.tau.tolist()                  # to the bit
        assert list(cmd.name) == ['joint_1', 'joint_2', 'joint_3']
        assert cmd.header.stamp == msg.header.stamp
        st = deserialize_message(ctrl.pub_state.sent[-1], ControllerState)
        assert st.mode == out.mode and st.tau_command.tolist() == out.tau.tolist()
        np.testing.assert_array_equal(st.q_ref, out.q_ref)             # NaN == NaN here
        np.testing.assert_array_equal([st.theta, st.theta_predicted, st.step_duration > 0],
                                      [out.theta, out.theta_predicted, True])
        plant.command(out.tau)
        plant.step()
    assert {ControllerState.MODE_RAMP, ControllerState.MODE_PATH} <= modes
    # malformed bytes and a missing joint: refused, counted, no command
    n, r = len(ctrl.pub_cmd.sent), ctrl.ctrl.rejected_inputs
    ctrl.on_state_raw(b'\x00\x01\x00\x00\x01')
    bad = joint_state(60.0, [0.1, 0.2])
    bad.name = ['joint_1', 'joint_2']
    ctrl.on_state_raw(serialize_message(bad))
    assert len(ctrl.pub_cmd.sent) == n and ctrl.ctrl.rejected_inputs == r + 2


def test_realtime_parameters_validated():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    try:
        node = PdPlusNode(context=ctx, parameter_overrides=[
            Parameter('realtime_priority', value=30), Parameter('cpu_affinity', value=[0])])
        assert node.realtime == (30, [0])      # applied by main() to the process, not here
        node.destroy_node()
        node = PdPlusNode(context=ctx)
        assert node.realtime == (0, [])
        node.destroy_node()
        for bad in (Parameter('realtime_priority', value=100),
                    Parameter('realtime_priority', value=-1),
                    Parameter('cpu_affinity', value=[-1])):
            with pytest.raises(ValueError):
                PdPlusNode(context=ctx, parameter_overrides=[bad])
    finally:
        rclpy.try_shutdown(context=ctx)


def test_controller_modes_equal_the_message_constants():
    cs = ControllerState
    assert (pd_plus.MODE_IDLE, pd_plus.MODE_RAMP, pd_plus.MODE_PATH, pd_plus.MODE_TIME,
            pd_plus.MODE_STOPPED, pd_plus.MODE_HOLD) == (
        cs.MODE_IDLE, cs.MODE_RAMP, cs.MODE_PATH, cs.MODE_TIME, cs.MODE_STOPPED, cs.MODE_HOLD)


def test_builtin_profile_none_waits_for_a_plan():
    """builtin_profile 'none': no profile, no command for joint states, enable refused until a
    plan arrives."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    try:
        node = PdPlusNode(context=ctx, namespace=f'/t{uuid.uuid4().hex[:8]}',
                          parameter_overrides=[Parameter('builtin_profile', value='none')])
        node.pub_cmd, node.pub_state = _Capture(), _Capture()
        assert node.ctrl.profile is None
        node.on_state(joint_state(1.0, node.model.ik(np.array([0.75, 0.0, 0.13]))))
        assert node.pub_cmd.sent == [] and len(node.pub_state.sent) == 1
        assert node.ctrl.enable() == (False, 'no profile')
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_auto_enable_waits_for_a_steady_stream_and_a_command_subscriber(graph):
    """No ramp while torque_command has no subscriber (0.6 s of joint states); once one is
    matched, the ramp starts (the settle time, SettleGate, is tested in test_pd_plus)."""
    ctrl, peer, ex, ns = graph
    q0 = ctrl.ctrl.start_pose()
    states = Collector(peer, ControllerState, f'{ns}/controller_state', state_qos())
    timer = feed_joint_states(peer, ns, 20.0, q0)
    spin_for(ex, states.expect(lambda m: len(states.msgs) >= 150))     # 0.6 s of samples
    assert {m.mode for m in states.msgs} == {ControllerState.MODE_IDLE}
    Collector(peer, JointState, f'{ns}/torque_command', state_qos())
    n_idle = len(states.msgs)
    first = spin_for(ex, states.expect(lambda m: m.mode == ControllerState.MODE_RAMP))
    peer.destroy_timer(timer)
    # the stream was steady long before: the ramp starts as soon as the subscriber is matched
    assert first.mode == ControllerState.MODE_RAMP and len(states.msgs) - n_idle < 124
