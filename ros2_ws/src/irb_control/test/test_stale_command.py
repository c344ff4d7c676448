"""Issue 32: no stale command, ever. pdplus's command carries the stamp of the state it
answers; the receivers (simulator, axis bridge) act only on an answer to the newest state they
sent, and refuse, count and log any other: a pdplus frozen (SIGSTOP) between its age check and
its publish, and resumed a second later, puts an answer to an old state on the wire that
nobody acts on. Deterministic and in-process: pdplus answers a state, the simulator sends
newer ones meanwhile (the freeze), then receives that answer."""
import os
import socket
import uuid

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from irb_interfaces.msg import AxisStatus  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from irb_control.axis_bridge_node import AxisBridge  # noqa: E402
from irb_control.pdplus_node import PdPlusNode  # noqa: E402
from irb_control.simulator_node import SimulatorNode, _stamp  # noqa: E402

pytestmark = pytest.mark.ros
T = 0.004032


class _Capture:
    def __init__(self):
        self.sent = []

    def publish(self, msg):
        self.sent.append(msg)

    def get_subscription_count(self):
        return 1


class _Log:
    """Stands in for a node's logger: keeps the warnings."""

    def __init__(self, logger):
        self.logger, self.warnings = logger, []

    def warn(self, text, **kw):
        self.warnings.append(text)

    warning = error = warn

    def __getattr__(self, name):
        return getattr(self.logger, name)


@pytest.fixture
def ctx():
    c = rclpy.Context()
    rclpy.init(context=c, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    yield c
    rclpy.try_shutdown(context=c)


def test_an_answer_to_an_old_state_never_acts_on_the_simulated_robot(ctx):
    ns = f'/t{uuid.uuid4().hex[:8]}'
    sim = SimulatorNode(context=ctx, namespace=ns,
                        parameter_overrides=[Parameter('mode', value='lockstep')])
    ctrl = PdPlusNode(context=ctx, namespace=ns, parameter_overrides=[
        Parameter('executor', value='single'), Parameter('auto_enable', value=False)])
    try:
        sim.pub_state, ctrl.pub_cmd, ctrl.pub_state = _Capture(), _Capture(), _Capture()
        log = _Log(sim.get_logger())
        sim.get_logger = lambda: log
        applied = []
        sim.plant.command = lambda tau: applied.append(np.asarray(tau).tolist())
        t0 = ctrl.get_clock().now().nanoseconds * 1e-9
        ctrl.axis = AxisStatus(source='test')             # the drives report no error
        ctrl.watchdog.timeout_s = 5.0      # the test's own pace between samples
        sim.plant.reset(ctrl.ctrl.start_pose())
        assert ctrl._enable()[0]

        def state(k):                  # the simulator's k-th state, as pdplus receives it
            sim._publish_state(_stamp(t0 + k * T))
            return sim.pub_state.sent[-1]
        ctrl.on_state_raw(state(0))
        answer = ctrl.pub_cmd.sent[-1]
        # the command carries the stamp of the state it answers
        assert deserialize_message(answer, JointState).header.stamp == _stamp(t0)
        sim.on_command_raw(answer)
        assert len(applied) == 1 and sim.stale_commands == 0
        # pdplus took the next state, then froze for ~1 s before it published its answer;
        # the simulator sent 248 newer states meanwhile
        old = state(1)
        ctrl._clock_s = lambda: t0 + T                       # its age check passed then
        n = len(ctrl.pub_cmd.sent)
        ctrl.on_state_raw(old)
        assert len(ctrl.pub_cmd.sent) == n + 1
        late = ctrl.pub_cmd.sent[-1]
        assert deserialize_message(late, JointState).header.stamp == _stamp(t0 + T)
        for k in range(2, 250):
            state(k)
        sim.on_command_raw(late)                             # resumed: on the wire now
        sim.log.flush()
        assert len(applied) == 1, 'an answer to a state 1 s old acted on the robot'
        assert sim.stale_commands == 1
        assert log.warnings and '999.9 ms' in log.warnings[-1] and 'older than the newest' in \
            log.warnings[-1], log.warnings
        # the answer to the newest state still acts
        newest = JointState(name=['joint_1', 'joint_2', 'joint_3'], effort=[1.0, 2.0, 3.0])
        newest.header.stamp = _stamp(t0 + 249 * T)
        sim.on_command_raw(serialize_message(newest))
        assert applied[-1] == [1.0, 2.0, 3.0] and sim.stale_commands == 1
    finally:
        ctrl.destroy_node()
        sim.destroy_node()


def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def test_the_axis_bridge_refuses_an_answer_to_an_old_state(ctx):
    bridge = AxisBridge(context=ctx, namespace=f'/t{uuid.uuid4().hex[:8]}',
                        parameter_overrides=[Parameter('state_port', value=_free_port()),
                                             Parameter('command_port', value=_free_port())])
    try:
        log = _Log(bridge.get_logger())
        bridge.get_logger = lambda: log
        sent = []

        class Sock:                   # stands in for the socket: keeps what is sent
            def sendto(self, data, peer):
                sent.append(data)
        real_sock, bridge.sock = bridge.sock, Sock()
        newest = 1_000_000_000_000
        bridge.last_key = newest                    # the newest state it published
        cmd = JointState(name=['joint_1', 'joint_2', 'joint_3'], effort=[1.0, 2.0, 3.0])
        old = newest - 1_000_000_000                # a state 1 s older
        cmd.header.stamp.sec, cmd.header.stamp.nanosec = old // 10**9, old % 10**9
        late = bridge.core.stats.late_commands
        bridge.on_command(cmd)
        bridge.log.flush()
        assert not sent and bridge.core.stats.late_commands == late + 1
        assert log.warnings and '1000.0 ms older than the newest state' in log.warnings[-1]
    finally:
        bridge.sock = real_sock
        bridge.destroy_node()
