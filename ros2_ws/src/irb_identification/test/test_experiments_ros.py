"""experiments, ROS mode, against a fake pdplus that runs on simulated time ~20x faster than
real time (as the lockstep simulator): runs are timed on the controller's modes and stamps,
never on the wall clock. In-process (private Context), conditions polled, no sleeps."""
import uuid

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('irb_interfaces.msg')
from irb_interfaces.msg import ControllerState, PlanStatus  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import (DurabilityPolicy, QoSProfile, ReliabilityPolicy)  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from trajectory_msgs.msg import JointTrajectory  # noqa: E402

from irb_identification import bagio  # noqa: E402
from irb_identification.run_timing import (MODE_HOLD, MODE_RAMP,  # noqa: E402
                                           MODE_STOPPED, MODE_TIME,
                                           controller_state_head, header_stamp)

pytestmark = pytest.mark.ros
T = 0.004032


class FakePdPlus(Node):
    """pdplus's state machine in the time-driven mode, stepped ``per_tick`` periods per 2 ms
    wall-clock tick: a built-in motion first (``busy_s`` of TIME), HOLD, and per trajectory
    RAMP (``ramp_s``) -> TIME (its duration) -> HOLD; a trajectory that arrives while moving
    is refused, like pdplus. ``stop_in_run`` (1-based): latch STOPPED half-way that run."""

    def __init__(self, tag, context, busy_s=1.0, ramp_s=0.5, per_tick=10, stop_in_run=0):
        super().__init__(f'fake_pdplus_{tag}', context=context)
        be = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.pub_js = self.create_publisher(JointState, f'/js_{tag}', be)
        self.pub_cs = self.create_publisher(ControllerState, f'/cs_{tag}', be)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(JointTrajectory, f'/traj_{tag}', self.on_plan, latched)
        # like pdplus: a plan is checked and kept pending until ~/enable
        self.pub_status = self.create_publisher(PlanStatus, f'/ps_{tag}', latched)
        self.create_service(Trigger, f'/en_{tag}', self.on_enable)
        self.offered = None
        self.t = 100.0
        self.mode, self.t_mode = MODE_TIME, self.t       # the built-in motion
        self.busy_s, self.ramp_s, self.per_tick = busy_s, ramp_s, per_tick
        self.duration = busy_s
        self.pending = None
        self.runs, self.refused, self.stop_in_run = 0, 0, stop_in_run
        self.reason = ''
        self.create_timer(0.002, self.tick)

    def on_plan(self, msg):
        last = msg.points[-1].time_from_start
        self.offered = last.sec + 1e-9 * last.nanosec
        self.pub_status.publish(PlanStatus(plan_stamp=msg.header.stamp, accepted=True,
                                           points=len(msg.points), duration=self.offered))

    def on_enable(self, request, response):
        if self.mode in (MODE_RAMP, MODE_TIME) or self.offered is None:
            self.refused += 1
            response.success, response.message = False, 'already running or no plan'
            return response
        self.pending, self.offered = self.offered, None
        response.success, response.message = True, 'enabled'
        return response

    def tick(self):
        for _ in range(self.per_tick):
            self.step()

    def step(self):
        self.t += T
        dt = self.t - self.t_mode
        if self.pending is not None and self.mode not in (MODE_RAMP, MODE_TIME):
            self.duration, self.pending = self.pending, None
            self.mode, self.t_mode, self.reason = MODE_RAMP, self.t, ''
            self.runs += 1
        elif self.mode == MODE_RAMP and dt >= self.ramp_s:
            self.mode, self.t_mode = MODE_TIME, self.t
        elif self.mode == MODE_TIME and dt >= self.duration:
            self.mode, self.t_mode = MODE_HOLD, self.t
        elif (self.mode == MODE_TIME and 0 < self.stop_in_run == self.runs
              and dt >= self.duration / 2):
            self.mode, self.reason = MODE_STOPPED, 'tracking error [0.06] rad > [0.05]'
        sec = int(self.t)
        nsec = int(round((self.t - sec) * 1e9))
        js = JointState(name=['joint_1', 'joint_2', 'joint_3'], position=[0.0] * 3,
                        velocity=[0.0] * 3, effort=[0.0] * 3)
        js.header.stamp.sec, js.header.stamp.nanosec = sec, nsec
        cs = ControllerState(mode=self.mode, stop_reason=self.reason)
        cs.header.stamp.sec, cs.header.stamp.nanosec = sec, nsec
        self.pub_cs.publish(cs)
        self.pub_js.publish(js)


def experiments_node(context, tag, root, **extra):
    from irb_identification.experiments import ExperimentsNode
    p = dict(mode='ros', joints=['joint_3'], speeds_rad_s=[1.0, 1.5], hold_max_s=0.6,
             root=str(root), prefix='r', trajectory_topic=f'/traj_{tag}',
             controller_state_topic=f'/cs_{tag}', joint_states_topic=f'/js_{tag}',
             record_topics=[f'/js_{tag}', f'/cs_{tag}'], run_margin_s=0.5,
             run_timeout_s=30.0, plan_status_topic=f'/ps_{tag}', enable_service=f'/en_{tag}')
    p.update(extra)
    return ExperimentsNode(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in p.items()])


def modes_and_stamps(bag, tag):
    msgs = bagio.read_messages(bag, [f'/cs_{tag}', f'/js_{tag}'])
    heads = [controller_state_head(d) for d in msgs[f'/cs_{tag}'].data]
    js = [header_stamp(d) for d in msgs[f'/js_{tag}'].data]
    return np.array([h[0] for h in heads]), np.array([h[1] for h in heads]), np.array(js)


def test_runs_are_timed_on_the_controller_not_the_wall_clock(ctx, tmp_path):
    context, executor = ctx
    tag = uuid.uuid4().hex[:8]
    fake = FakePdPlus(tag, context, busy_s=1.0)
    exp = experiments_node(context, tag, tmp_path)
    executor.add_node(fake)
    executor.add_node(exp)
    bags = exp.run_ros(executor)
    assert [b.name for b in bags] == ['r_joint_3_1p0000', 'r_joint_3_1p5000']
    assert fake.runs == 2 and fake.refused == 0      # it waited for the built-in motion
    durations = [prof.duration for _, prof, _, _ in exp.runs()]
    for bag, duration in zip(bags, durations):
        t, mode, js = modes_and_stamps(bag, tag)
        # the bag starts on the hold before the run (not the built-in motion) ...
        changes = [int(m) for k, m in enumerate(mode) if k == 0 or m != mode[k - 1]]
        assert changes == [MODE_HOLD, MODE_RAMP, MODE_TIME, MODE_HOLD], changes
        # ... holds the whole trajectory (simulated time) ...
        t_time = t[mode == MODE_TIME]
        # the bag resolves the run to its own sample spacing: the double publishes in bursts
        # of per_tick states and the in-process recorder keeps about one per burst, so each
        # end of the TIME stretch is known to one recorded gap (it was compared within 3 T,
        # which failed whenever a burst boundary fell badly: the old flakiness)
        gap = float(np.diff(t).max())
        assert duration - gap - 3 * T <= t_time[-1] - t_time[0] <= duration + 3 * T
        # ... and run_margin_s = 0.5 s of simulated time after HOLD, not much more
        t_hold = t[(mode == MODE_HOLD) & (t > t_time[-1])][0]
        assert t_hold + 0.5 <= js[-1] < t_hold + 0.5 + 5.0
    exp.destroy_node()
    fake.destroy_node()


def test_a_stop_fails_that_run_clearly_and_the_others_still_run(ctx, tmp_path):
    from irb_identification.experiments import RunError
    context, executor = ctx
    tag = uuid.uuid4().hex[:8]
    fake = FakePdPlus(tag, context, busy_s=0.2, stop_in_run=1)
    exp = experiments_node(context, tag, tmp_path)
    executor.add_node(fake)
    executor.add_node(exp)
    with pytest.raises(RunError) as err:
        exp.run_ros(executor)
    text = str(err.value)
    assert '1 of 2 runs failed' in text and 'r_joint_3_1p0000' in text
    assert 'tracking error' in text
    assert fake.runs == 2                            # the second run went ahead (re-enabled)
    _, mode, _ = modes_and_stamps(tmp_path / 'r_joint_3_1p5000', tag)
    changes = [int(m) for k, m in enumerate(mode) if k == 0 or m != mode[k - 1]]
    assert changes == [MODE_STOPPED, MODE_RAMP, MODE_TIME, MODE_HOLD], changes
    exp.destroy_node()
    fake.destroy_node()


def test_no_controller_is_a_bounded_error_not_a_hang(ctx, tmp_path):
    from irb_identification.experiments import RunError
    context, executor = ctx
    tag = uuid.uuid4().hex[:8]
    exp = experiments_node(context, tag, tmp_path, run_timeout_s=1.0)
    executor.add_node(exp)
    with pytest.raises(RunError, match='run_timeout_s'):
        exp.run_ros(executor)
    exp.destroy_node()
