"""simulator + pdplus as two processes (`ros2 run`, lockstep on /clock): the robot follows the
thesis circle; this test only listens (controller state and camera)."""
import os
import signal
import subprocess
import time
import uuid

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import PointStamped  # noqa: E402
from irb_interfaces.msg import ControllerState  # noqa: E402
from irb_description.path import thesis_circle  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.task import Future  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from irb_control.closed_loop import circle_distance  # noqa: E402
from irb_description.node_main import state_qos  # noqa: E402
from irb_description.output_lines import popen_lines  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def _stop(proc):
    """Ctrl-C as a terminal sends it (SIGINT to the session's group: `ros2 run` and the node,
    once each), SIGKILL to the group after 20 s."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)      # Ctrl-C: the whole group, once
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


@pytest.fixture
def processes():
    ns = f'/tp{uuid.uuid4().hex[:8]}'
    common = ['--ros-args', '-r', f'__ns:={ns}']
    # lockstep_wait_s: wall time per command before a silent pdplus counts as a miss; 50 ms
    # latched "no command for 16 ms" in a fresh-clone CI run on a jittery 2-vCPU VM
    sim = popen_lines(['ros2', 'run', 'irb_control', 'simulator', *common,
                       '-p', 'mode:=lockstep', '-p', 'lockstep_wait_s:=0.5'],
                      start_new_session=True)
    ctrl = popen_lines(['ros2', 'run', 'irb_control', 'pdplus', *common,
                        '-p', 'use_sim_time:=true', '-p', 'friction_mode:=nominal',
                        '-p', 'profile_duration_s:=10.0', '-p', 'auto_enable:=false'],
                       start_new_session=True)
    yield ns, sim, ctrl
    _stop(ctrl)
    _stop(sim)


def enable_when_ready(ex, enable, timeout_s: float = 30.0):
    """Call pdplus's ~/enable; while it refuses only because the simulator's latched
    axis_status has not reached it yet (on a loaded machine that can come after its first
    controller states), ask again, bounded. Returns the last response."""
    from std_srvs.srv import Trigger
    deadline = time.monotonic() + timeout_s
    while True:
        # a call unanswered for 5 s is sent again: a response can be lost while the server's
        # reply writer has not matched this client yet (a fresh-clone CI: no answer in 120 s)
        for _ in range(6):
            fut = enable.call_async(Trigger.Request())
            ex.spin_until_future_complete(fut, timeout_sec=5.0)
            if fut.done():
                break
        assert fut.done(), 'no answer from ~/enable in 6 calls of 5 s'
        res = fut.result()
        if res.success or 'no axis status' not in res.message or time.monotonic() > deadline:
            return res
        ex.spin_once(timeout_sec=0.1)


def test_robot_follows_circle_across_processes(processes):
    ns, sim, ctrl = processes
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    node = rclpy.create_node(f'listener_{uuid.uuid4().hex[:6]}', context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        done = Future()
        states, cams = [], []

        def on_state(m):
            states.append(m)
            if m.mode in (ControllerState.MODE_HOLD, ControllerState.MODE_STOPPED) \
                    and not done.done():
                done.set_result(m)
        # reliable and deep, as the recorder reads it: the count below is pdplus's, not what
        # a best-effort depth-1 reader of this test kept on a loaded machine (1109 of ~2480)
        node.create_subscription(ControllerState, f'{ns}/controller_state', on_state,
                                 QoSProfile(depth=2500, reliability=ReliabilityPolicy.RELIABLE))
        node.create_subscription(PointStamped, f'{ns}/camera/tcp', cams.append,
                                 QoSProfile(depth=200))
        # start the motion once this listener is connected: enable service of pdplus
        from std_srvs.srv import Trigger
        enable = node.create_client(Trigger, f'{ns}/pdplus/enable')
        assert enable.wait_for_service(timeout_sec=60.0), 'pdplus did not come up'
        first = Future()
        node.create_timer(0.05, lambda: first.set_result(True) if states and cams
                          and not first.done() else None)
        ex.spin_until_future_complete(first, timeout_sec=60.0)
        assert first.done(), 'no controller state / camera messages'
        res = enable_when_ready(ex, enable)
        assert res.success, res
        ex.spin_until_future_complete(done, timeout_sec=120.0)
        assert done.done(), 'no end of motion within 120 s'
        final = done.result()
        assert final.mode == ControllerState.MODE_HOLD, final.stop_reason
        path_states = [s for s in states if s.mode == ControllerState.MODE_PATH]
        assert len(path_states) > 1500                      # ~2480 samples in 10 s
        theta = np.array([s.theta for s in path_states])
        assert theta.max() > 6.2
        t0 = path_states[0].header.stamp.sec + path_states[0].header.stamp.nanosec * 1e-9
        pts = np.array([[c.point.x, c.point.y, c.point.z] for c in cams
                        if c.header.stamp.sec + c.header.stamp.nanosec * 1e-9 > t0])
        assert len(pts) > 500
        err = circle_distance(thesis_circle(), pts)
        assert np.mean(err) < 1.5e-3 and np.max(err) < 4e-3
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        _stop(ctrl)
        _stop(sim)
    assert sim.wait(timeout=20) == 0, sim.out.rest()
    assert ctrl.wait(timeout=20) == 0, ctrl.out.rest()


def test_a_stalled_pdplus_ends_latched_and_answers_no_old_state(stall_retries, tmp_path):
    """pdplus frozen for 1 s (SIGSTOP) in the middle of the path, then resumed: it must end
    in a latched stop (its own stall or the watchdog) and never answer the states that waited
    in its queue (issue 14, defect 3: it resumed silently in 5 of 7 runs, answering old
    states). Real time: simulator and pdplus on the steady clock. A stop from a stall of the
    machine before the freeze (the fresh-clone CI run of 2026-11-24: modes 4, 4, 4 with a
    40 ms watchdog) is correct but not the subject: the scenario runs again on fresh
    processes (stall_retries). Issue 32: checked on the simulator's side too, from its own
    per-state record (when each state went out, whether and how late its answer was
    applied): no command answering a state older than pdplus's watchdog limit acted on the
    robot."""
    stall_retries(lambda: _stall_once(stall_retries, tmp_path))


def _stall_once(retries, tmp_path):
    import json
    from std_srvs.srv import Trigger
    ns = f'/st{uuid.uuid4().hex[:8]}'
    stats_path = tmp_path / f'sim_stats_{ns[1:]}.json'
    limit_s = 10.5 * 0.004032          # pdplus's watchdog limit here (10 samples + 1/2)
    common = ['--ros-args', '-r', f'__ns:={ns}']
    # the subject is pdplus's own stall detection (its limits unchanged); the simulator's
    # command timeout is 10 cycles so that platform jitter before the freeze does not latch it
    sim = popen_lines(['ros2', 'run', 'irb_control', 'simulator', *common,
                       '-p', 'mode:=realtime', '-p', 'command_timeout_s:=0.04032',
                       '-p', f'stats_path:={stats_path}', '-p', 'stats_per_state:=true'],
                      start_new_session=True)
    # pdplus's watchdog at 10 samples (40 ms): with 3, a platform stall during the ramp
    # latched a correct stop before the freeze in a fresh-clone suite run (modes 4, 4, 4 ...);
    # a 1 s freeze trips either, and its own stall detection is unchanged
    ctrl = popen_lines(['ros2', 'run', 'irb_control', 'pdplus', *common,
                        '-p', 'profile_duration_s:=10.0', '-p', 'auto_enable:=false',
                        '-p', 'watchdog_missed_samples:=10'],
                       start_new_session=True)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    node = rclpy.create_node(f'stall_{uuid.uuid4().hex[:6]}', context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        states, ages = [], []
        node.create_subscription(ControllerState, f'{ns}/controller_state', states.append,
                                 state_qos())

        def on_cmd(m):      # age of the state a command answers, on arrival here
            ages.append((time.monotonic(), node.get_clock().now().nanoseconds * 1e-9
                         - (m.header.stamp.sec + m.header.stamp.nanosec * 1e-9)))
        node.create_subscription(JointState, f'{ns}/torque_command', on_cmd, state_qos())
        enable = node.create_client(Trigger, f'{ns}/pdplus/enable')
        assert enable.wait_for_service(timeout_sec=60.0), 'pdplus did not come up'

        def until(cond, timeout):
            deadline = time.monotonic() + timeout
            while not cond() and time.monotonic() < deadline:
                ex.spin_once(timeout_sec=0.02)
            return cond()
        assert until(lambda: bool(states), 60), 'no controller state'
        res = enable_when_ready(ex, enable)
        assert res.success, res
        reached = (ControllerState.MODE_PATH, ControllerState.MODE_STOPPED)
        if not until(lambda: states[-1].mode in reached, 30) \
                or states[-1].mode != ControllerState.MODE_PATH:
            stops = [s.stop_reason for s in states if s.mode == ControllerState.MODE_STOPPED]
            if stops and retries.is_stall(stops[0]):
                raise retries.Stall(f'before the freeze: {stops[0]}')
            raise AssertionError([(s.mode, s.stop_reason) for s in states[-5:]])
        os.killpg(ctrl.pid, signal.SIGSTOP)
        t_stop = time.monotonic()
        try:
            ctrl.wait(timeout=1.0)            # frozen: it does not end
        except subprocess.TimeoutExpired:
            pass
        os.killpg(ctrl.pid, signal.SIGCONT)
        t_cont = time.monotonic()
        assert until(lambda: states[-1].mode == ControllerState.MODE_STOPPED, 30), \
            'pdplus did not latch a stop after its stall'
        assert until(lambda: False, 0.5) is False       # keep listening half a second
        reason = [s.stop_reason for s in states if s.mode == ControllerState.MODE_STOPPED][0]
        assert 'stall' in reason or 'watchdog' in reason, reason
        assert states[-1].mode == ControllerState.MODE_STOPPED            # latched
        # commands pdplus computed after the stall (arriving more than 50 ms after SIGCONT:
        # one published just before the freeze may still be delivered right after it) answer
        # no state older than the watchdog limit (3.5 periods) plus the way here
        late = [age for t, age in ages if t > t_cont + 0.05]
        assert t_cont - t_stop >= 1.0
        assert not late or max(late) < 0.05, max(late)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        _stop(ctrl)
        _stop(sim)
    # the simulator's side (its statistics, written at its shutdown): every state it sent
    # from just before the freeze to after the resume, and the answers it applied. An answer
    # is applied only to the newest state sent; none may answer a state older than the limit
    stats = json.loads(stats_path.read_text())
    per_state = stats['per_state_monotonic_s_latency_ms']
    around = [(t, lat) for t, lat in per_state if t_stop - 0.1 <= t <= t_cont + 0.1]
    frozen = [lat for t, lat in around if t_stop + limit_s < t < t_cont]
    # states sent while pdplus was frozen: 248 Hz over ~0.96 s is ~237
    assert len(frozen) > 200 and all(lat is None for lat in frozen), \
        (len(frozen), [lat for lat in frozen if lat is not None][:5], sim.out.rest()[-3000:])
    applied = [(t, lat) for t, lat in around if lat is not None]
    assert all(lat < limit_s * 1e3 for _, lat in applied), max(applied, key=lambda x: x[1])
    # nothing applied after the resume answers a state sent before it
    assert not [t for t, lat in applied if t < t_cont and t + lat * 1e-3 > t_cont]
    print(f"freeze {t_cont - t_stop:.3f} s: simulator states around it {len(around)}, "
          f"answers applied {len(applied)} (max {max((x[1] for x in applied), default=0):.2f}"
          f" ms after their state), refused as not answering the newest state "
          f"{stats['stale_commands_ignored']} (whole run)")
