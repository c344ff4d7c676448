"""Issue 32: a stamp refused across clocks says which clock each side uses, and pdplus follows
a lockstep simulator's /clock by itself while nothing moves (in-process, private Context)."""
import os
import uuid

import pytest

rclpy = pytest.importorskip('rclpy')
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from irb_control.pdplus_node import PdPlusNode  # noqa: E402

pytestmark = pytest.mark.ros


class _Log:
    def __init__(self, logger):
        self.logger, self.lines = logger, []

    def warn(self, text, **kw):
        self.lines.append(text)

    def info(self, text, **kw):
        self.lines.append(text)

    warning = error = warn

    def __getattr__(self, name):
        return getattr(self.logger, name)


def state(stamp_s):
    m = JointState(name=['joint_1', 'joint_2', 'joint_3'], position=[0.0, 0.9, 0.25],
                   velocity=[0.0] * 3, effort=[0.0] * 3)
    m.header.stamp.sec = int(stamp_s)
    m.header.stamp.nanosec = int(round((stamp_s % 1) * 1e9))
    return serialize_message(m)


@pytest.fixture
def pdplus(request):
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    node = PdPlusNode(context=ctx, namespace=f'/t{uuid.uuid4().hex[:8]}',
                      parameter_overrides=[Parameter('executor', value='single'),
                                           Parameter('auto_enable', value=False),
                                           *request.param])
    log = _Log(node.get_logger())
    node.get_logger = lambda: log
    yield node, log, ctx
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)


@pytest.mark.parametrize('pdplus', [[]], indirect=True)
def test_simulated_stamp_on_the_system_clock_says_so_and_follows_clock(pdplus):
    node, log, ctx = pdplus
    node.on_state_raw(state(12.0))              # a lockstep simulator's 12th second
    node.log.flush()
    assert node.rejected_stale == 1
    assert ('state stamped in simulated time (/clock) but pdplus uses the system clock: set '
            'use_sim_time:=true' in log.lines[-1]), log.lines
    assert 'clocks of the hosts' not in log.lines[-1]
    # once /clock is published, pdplus switches to it by itself (nothing moves)
    peer = rclpy.create_node('clock_peer', context=ctx)
    peer.create_publisher(Clock, '/clock', 10)
    node._clock_probe_due = 0.0
    node.on_state_raw(state(12.004))
    node.log.flush()
    assert node.get_parameter('use_sim_time').value is True
    assert node.watchdog.timeout_s >= 1.0 and 'pdplus now uses /clock' in log.lines[-1]
    peer.destroy_node()


@pytest.mark.parametrize('pdplus', [[Parameter('use_sim_time', value=True)]], indirect=True)
def test_system_stamp_on_simulated_time_says_so(pdplus):
    node, log, _ = pdplus
    node.on_state_raw(state(1795747175.667))
    node.log.flush()
    assert node.rejected_stale == 1
    assert 'state stamped in system time but pdplus uses simulated time (/clock' in \
        log.lines[-1], log.lines


@pytest.mark.parametrize('pdplus', [[Parameter('follow_sim_time', value=False)]],
                         indirect=True)
def test_both_on_system_time_names_a_stall_or_the_hosts_clocks(pdplus):
    node, log, _ = pdplus
    now = node.get_clock().now().nanoseconds * 1e-9
    node.on_state_raw(state(now - 0.5))
    node.log.flush()
    assert 'both in system time' in log.lines[-1] and 'clocks of the hosts' in log.lines[-1]
