"""Issue 32: starting a run never stalls the loop. Enable and the first ramp step do only the
step on the control thread: the log lines they cause ("enable: ...", "mode idle -> ramp") are
written by the log thread (rclpy's logger stats the caller's source file on every call: 1-2 ms
here, tens of ms on a loaded machine; the 23 and 87 ms first ramp steps that latched "stall"),
so a logger that takes 200 ms per line costs the loop nothing. In-process, private Context."""
import os
import threading
import time
import uuid

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from irb_interfaces.msg import AxisStatus  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from irb_control.pdplus_node import PdPlusNode  # noqa: E402

pytestmark = pytest.mark.ros


class _Capture:
    def __init__(self):
        self.sent = []

    def publish(self, msg):
        self.sent.append(msg)

    def get_subscription_count(self):
        return 1


class _SlowLog:
    """A logger that takes 200 ms per line (and remembers on which thread it ran)."""

    def __init__(self):
        self.lines, self.threads = [], set()

    def _write(self, text, **kw):
        self.threads.add(threading.get_ident())
        time.sleep(0.2)
        self.lines.append(text)
    info = warn = warning = error = _write


def test_enable_and_first_ramp_step_do_not_wait_for_log_lines():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    node = PdPlusNode(context=ctx, namespace=f'/t{uuid.uuid4().hex[:8]}', parameter_overrides=[
        Parameter('executor', value='single'), Parameter('auto_enable', value=False)])
    try:
        slow = _SlowLog()
        node.get_logger = lambda: slow
        node.pub_cmd, node.pub_state = _Capture(), _Capture()
        node.axis = AxisStatus(source='test')
        node.watchdog.timeout_s = 5.0      # the machine's own stalls are not this test's
        q = (node.ctrl.start_pose() + np.array([0.05, 0.0, 0.0])).tolist()

        def state():
            m = JointState(name=['joint_1', 'joint_2', 'joint_3'], position=q,
                           velocity=[0.0] * 3, effort=[0.0] * 3)
            ns = node.get_clock().now().nanoseconds
            m.header.stamp.sec, m.header.stamp.nanosec = ns // 10**9, ns % 10**9
            return serialize_message(m)
        node.on_state_raw(state())
        t = time.perf_counter()
        assert node.on_enable(Trigger.Request(), Trigger.Response()).success
        t_enable = time.perf_counter() - t
        steps = []
        for _ in range(5):
            t = time.perf_counter()
            node.on_state_raw(state())
            steps.append(time.perf_counter() - t)
        assert len(node.pub_cmd.sent) == 5, node.ctrl.stop_reason       # all answered
        assert node.ctrl.mode == 1                                       # ramping
        # no log line was written on this thread, and none was waited for (each takes 200 ms)
        assert threading.get_ident() not in slow.threads
        assert t_enable < 0.1 and max(steps) < 0.1, (t_enable, steps)
        assert node.log.flush(10.0)
        assert any('enable: enabled' in x for x in slow.lines)
        assert any('mode idle -> ramp' in x for x in slow.lines)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
