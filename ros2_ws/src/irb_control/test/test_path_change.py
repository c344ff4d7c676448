"""Issue 32: paths change at run time. A plan carries the path it was planned on
(irb_description.plan_path, header.frame_id); pdplus takes it on that path while idle or
holding, ramps to its start on enable and follows it, with no restart and no latched stop.
In-process: private Context, the node's hot path fed from a plant stepped in the test."""
import os
import uuid

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from irb_interfaces.msg import ControllerState, PlanStatus  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint  # noqa: E402

from irb_control.closed_loop import build_default, path_distance  # noqa: E402
from irb_control.pd_plus import PdPlusController  # noqa: E402
from irb_control.pdplus_node import PdPlusNode  # noqa: E402
from irb_control.profiles import (PathProfile, build_sliced,  # noqa: E402
                                  polynomial_theta_of_time, profile_from_theta_samples)
from irb_description.node_main import latched_qos  # noqa: E402
from irb_description.path import LinePath, path_from_spec, path_spec  # noqa: E402
from irb_description.plan_path import path_frame_id, path_spec_from_frame_id  # noqa: E402

from irb_interfaces.msg import AxisStatus  # noqa: E402
from rclpy.task import Future  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

pytestmark = pytest.mark.ros

LINE_A = {'type': 'line', 'waypoints': [[0.55, -0.10, 0.30], [0.75, 0.10, 0.30]]}
ARC_B = {'type': 'arc', 'center': [0.65, 0.0, 0.25], 'normal': [0.0, 0.0, 1.0],
         'radius': 0.08, 'start_angle': 0.0, 'sweep': 3.0}


class _Capture:
    """Stands in for a publisher: keeps what is published."""

    def __init__(self):
        self.sent = []

    def publish(self, msg):
        self.sent.append(msg)

    def get_subscription_count(self):
        return 1


def axis_ok(peer, ns):
    pub = peer.create_publisher(AxisStatus, f'{ns}/axis_status', latched_qos())
    pub.publish(AxisStatus(motors_on=False, brakes_engaged=True, source='test'))
    return pub


def _until(ex, cond, timeout=30.0):
    fut = Future()
    node = ex.get_nodes()[0]
    timer = node.create_timer(0.005, lambda: fut.done() or (cond() and fut.set_result(True)))
    ex.spin_until_future_complete(fut, timeout_sec=timeout)
    node.destroy_timer(timer)
    assert fut.done(), 'condition not met in time'


def _drive(ctrl, q, n, plant):
    """Feed n fresh states of ``plant`` through the node's hot path, apply the commands;
    returns the controller states sent."""
    from rclpy.serialization import deserialize_message, serialize_message
    ctrl.pub_cmd, ctrl.pub_state = _Capture(), _Capture()
    out = []
    for _ in range(n):
        y = plant.measure()
        m = JointState(name=['joint_1', 'joint_2', 'joint_3'], position=y.q.tolist(),
                       velocity=y.qd.tolist(), effort=[0.0] * 3)
        # stamped in the plant's time, and pdplus's clock reads that time (the test's pace
        # on the wall clock is not the robot's)
        ns = int(round((1000.0 + plant.state.t) * 1e9))
        m.header.stamp.sec, m.header.stamp.nanosec = ns // 10**9, ns % 10**9
        ctrl._clock_s = lambda: ns * 1e-9
        ctrl.on_state_raw(serialize_message(m))
        out.append(deserialize_message(ctrl.pub_state.sent[-1], ControllerState))
        if ctrl.pub_cmd.sent:
            cmd = deserialize_message(ctrl.pub_cmd.sent[-1], JointState)
            plant.command(np.array(cmd.effort))
            ctrl.pub_cmd.sent.clear()
        plant.step()
    return out


def plan_msg(model, spec, duration=2.0, carry=True, stamp=1):
    """A joint trajectory along ``spec`` (the polynomial speed law of §4.5), with the path in
    header.frame_id as the planner sends it (carry=False: an older plan without it)."""
    path = path_from_spec(spec)
    t, th, thd, thdd = polynomial_theta_of_time(duration, n=301)
    prof = profile_from_theta_samples(model, path, th, thd, thdd, t, grid=301)
    msg = JointTrajectory(joint_names=['joint_1', 'joint_2', 'joint_3'])
    msg.header.stamp.sec = stamp
    if carry:
        msg.header.frame_id = path_frame_id(spec)
    for k in range(len(prof.t)):
        p = JointTrajectoryPoint(positions=prof.q[k].tolist(), velocities=prof.qd[k].tolist(),
                                 accelerations=prof.qdd[k].tolist())
        p.time_from_start.sec = int(prof.t[k])
        p.time_from_start.nanosec = int(round((prof.t[k] % 1) * 1e9))
        msg.points.append(p)
    return msg, path


@pytest.fixture
def node():
    """pdplus on the thesis circle (its configured path), no built-in profile, no auto
    enable; a peer that publishes plans and the drives' status."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    ns = f'/t{uuid.uuid4().hex[:8]}'
    ctrl = PdPlusNode(context=ctx, namespace=ns, parameter_overrides=[
        Parameter('executor', value='single'), Parameter('builtin_profile', value='none'),
        Parameter('auto_enable', value=False)])
    ctrl.watchdog.timeout_s = 2.0      # the test steps a plant in Python between samples
    peer = rclpy.create_node('peer', namespace=ns, context=ctx)
    axis_ok(peer, ns)
    statuses = []
    peer.create_subscription(PlanStatus, f'{ns}/pdplus/plan_status', statuses.append,
                             latched_qos())
    pub = peer.create_publisher(JointTrajectory, f'{ns}/planned_trajectory', latched_qos())
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(peer)
    ex.add_node(ctrl)
    yield ctrl, pub, statuses, ex
    ex.shutdown()
    ctrl.destroy_node()
    peer.destroy_node()
    rclpy.try_shutdown(context=ctx)


def offer(ex, ctrl, pub, statuses, msg, plant):
    """Publish a plan and keep the robot fed until pdplus's verdict on it arrives."""
    n = len(statuses)
    pub.publish(msg)
    states = []
    while len(statuses) <= n or statuses[-1].plan_stamp.sec != msg.header.stamp.sec:
        states += _drive(ctrl, None, 2, plant)
        ex.spin_once(timeout_sec=0.01)
    return statuses[-1], states


def run_to_hold(ctrl, plant, limit=3000):
    states = []
    while not states or states[-1].mode not in (ControllerState.MODE_HOLD,
                                                ControllerState.MODE_STOPPED):
        states += _drive(ctrl, None, 50, plant)
        assert len(states) < limit, 'no hold reached'
    return states + _drive(ctrl, None, 25, plant)


def tcp_error_on(model, states, path):
    """Largest distance [m] of the measured TCP from ``path`` while in PATH mode."""
    q = np.array([np.array(s.q_ref) - np.array(s.q_error) for s in states
                  if s.mode == ControllerState.MODE_PATH])
    return float(np.max(path_distance(path, np.array([model.fk(x) for x in q]))))


def test_path_tag_round_trip_and_backwards_compatible():
    assert path_spec_from_frame_id('') is None and path_spec_from_frame_id('base_link') is None
    spec = path_spec(path_from_spec(LINE_A))
    assert path_spec_from_frame_id(path_frame_id(spec)) == spec
    with pytest.raises(ValueError, match='frame'):
        path_spec_from_frame_id('tool0#path={"type": "line"}')
    with pytest.raises(ValueError, match='JSON'):
        path_spec_from_frame_id('base_link#path={type')


def test_sliced_profile_is_the_same_object():
    rng = np.random.default_rng(3)
    n = 5000
    th = np.linspace(0.0, 6.0, n)
    arrays = dict(theta=th, theta_dot=1 + rng.random(n), theta_ddot=rng.random(n),
                  q=rng.random((n, 3)), qd=rng.random((n, 3)), qdd=rng.random((n, 3)), t=th)
    a = PathProfile(**arrays)
    pieces = []
    b = build_sliced(PathProfile, arrays, 256, lambda: pieces.append(1))
    assert len(pieces) > 20            # it was built in pieces
    assert a._xl == b._xl and a._rows_l == b._rows_l and a._h_slope == b._h_slope
    assert np.array_equal(a._table, b._table)
    for x in (0.0, 1.234, 5.9999, 7.0):
        assert a.sample_list(x) == b.sample_list(x) and a.h(x) == b.h(x)


def test_controller_switches_path_only_on_enable():
    plant, ctrl = build_default(duration_s=10.0)
    circle = ctrl.path
    line = LinePath(np.array([0.55, -0.1, 0.3]), np.array([0.75, 0.1, 0.3]))
    t, th, thd, thdd = polynomial_theta_of_time(2.0, n=101)
    prof = profile_from_theta_samples(ctrl.model, line, th, thd, thdd, t, grid=101)
    ctrl.set_path_profile(prof, line)
    assert ctrl.path is circle and ctrl.pending_path is line     # pending: nothing changes
    assert ctrl.enable()[0]
    assert ctrl.path is line and ctrl._tracker is not None and ctrl._circle is None
    assert ctrl.profile is prof
    # a plan without a path of its own is on the configured path again
    back = PdPlusController(ctrl.model, circle, ctrl.config, None)
    back.set_path_profile(prof, line)
    back.enable()
    back.stop('test')
    back.set_path_profile(ctrl.profile)       # (any profile: the path is what is checked)
    back.enable()
    assert back.path is circle and back._circle is not None


def test_plans_on_new_paths_run_without_restart(node):
    ctrl, pub, statuses, ex = node
    model = ctrl.model
    _until(ex, lambda: ctrl.axis is not None)
    plant, _ = build_default(duration_s=10.0)
    plant.reset(np.array([0.0, 0.5, 0.3]))
    # 1. a plan on a line (not the configured circle), carrying its path: accepted
    msg, line = plan_msg(model, LINE_A, stamp=1)
    status, _ = offer(ex, ctrl, pub, statuses, msg, plant)
    assert status.accepted, status.reason
    assert ctrl.on_enable(Trigger.Request(), Trigger.Response()).success
    states = run_to_hold(ctrl, plant)
    modes = [s.mode for s in states]
    assert ControllerState.MODE_STOPPED not in modes, states[-1].stop_reason
    assert ControllerState.MODE_PATH in modes and modes[-1] == ControllerState.MODE_HOLD
    assert tcp_error_on(model, states, line) < 2e-3
    assert np.linalg.norm(model.fk(plant.state.q) - line.point(2 * np.pi)) < 2e-3
    # 2. while holding, a plan on an arc elsewhere: stored, the hold is not changed
    msg, arc = plan_msg(model, ARC_B, stamp=2)
    hold_ref = np.array(states[-1].q_ref)
    status, held = offer(ex, ctrl, pub, statuses, msg, plant)
    assert status.accepted, status.reason
    assert {s.mode for s in held} == {ControllerState.MODE_HOLD}
    assert all(np.array_equal(s.q_ref, hold_ref) for s in held)
    # ... and enable ramps from the held pose to the arc's start and follows it
    assert ctrl.on_enable(Trigger.Request(), Trigger.Response()).success
    states = run_to_hold(ctrl, plant)
    modes = [s.mode for s in states]
    assert ControllerState.MODE_STOPPED not in modes, states[-1].stop_reason
    assert modes[0] == ControllerState.MODE_RAMP and ControllerState.MODE_PATH in modes
    assert tcp_error_on(model, states, arc) < 2e-3
    # 3. an older plan that carries no path and is not on the configured circle: refused,
    # with the reason on ~/plan_status; the pending arc run is untouched
    msg, _ = plan_msg(model, LINE_A, carry=False, stamp=3)
    status, _ = offer(ex, ctrl, pub, statuses, msg, plant)
    assert not status.accepted
    assert 'carries no path' in status.reason and 'mm' in status.reason, status.reason
    # 4. a plan whose carried path is not a path: refused with the reason
    msg, _ = plan_msg(model, LINE_A, stamp=4)
    msg.header.frame_id = path_frame_id({'type': 'line', 'waypoints': [[0, 0, 0]]})
    status, _ = offer(ex, ctrl, pub, statuses, msg, plant)
    assert not status.accepted and "plan's path is not valid" in status.reason
