"""The node graph across hosts: three network namespaces on one bridge (irb_bringup.hosts),
simulator + pdplus on `ctrl`, the planner and the operator's client on `ws`, the recorder on
`rec`; discovery with ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET and the UDP-only Fast DDS profile.
The main job's circle is planned on `ws`, checked and executed by pdplus on `ctrl`, recorded on
`rec` (the recorder starts after the plan: the latched plan must still reach it).

Links of `ws` and `rec`: IRB_HOSTS_DELAY_MS (default 1) and IRB_HOSTS_LOSS (default 0) in
each direction -- netem where the kernel has it, the user-space linkemu otherwise. Needs root;
skipped with the reason elsewhere."""
import json
import os
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from irb_bringup import hosts
from irb_bringup.linkemu import DelayLine

HERE = Path(__file__).resolve().parent
PERIOD = 0.004032
# The simulator in lockstep (simulated time on /clock, one step per command), as the main job
# runs it: the graph, the plan, the bag and the safety path are what this test checks, and
# they must not depend on how loaded the machine is. In real time on this shared 2-core
# machine (load 6-9) the loop met 16-33 ms gaps and safe stops in 4 of 5 runs at normal or
# SCHED_FIFO priority, with or without remote hosts. The real-time loop figures, same host
# against across hosts, are benchmarks/bench_hosts.py's. IRB_HOSTS_SIM_MODE=realtime runs
# this test in real time.
SIM_MODE = os.environ.get('IRB_HOSTS_SIM_MODE', 'lockstep')


# --- the link emulator's core (pure) ----------------------------------------------------------
def test_delay_line_keeps_order_and_delay():
    import random
    line = DelayLine(0.005, 0.0, random.Random(1))
    t = np.sort(np.random.default_rng(3).uniform(0.0, 0.1, 200))    # irregular arrivals
    for i, ti in enumerate(t):
        line.push(float(ti), str(i).encode())
    out, now = [], 0.0
    while line.next_due() is not None:
        now = line.next_due()
        out += [(now, f) for f in line.pop_due(now)]
    assert [int(f) for _, f in out] == list(range(200))
    np.testing.assert_allclose([o[0] for o in out], t + 0.005, atol=1e-12)
    assert line.pop_due(1e9) == [] and line.passed == 200 and line.dropped == 0


def test_delay_line_loss_rate():
    import random
    line = DelayLine(0.0, 0.05, random.Random(7))
    kept = sum(line.push(0.0, b'x') for _ in range(20000))
    assert line.dropped + kept == 20000
    assert abs(line.dropped / 20000 - 0.05) < 0.006         # binomial: sigma 0.0015
    with pytest.raises(ValueError):
        DelayLine(0.0, 1.0, random.Random(1))


# --- the hosts --------------------------------------------------------------------------------
def _skip_reason():
    why = hosts.unavailable()
    if why:
        return why
    if hosts.link_emulation() is None:
        return 'no tc netem and no /dev/net/tun: links cannot be delayed here'
    return None


needs_hosts = pytest.mark.skipif(_skip_reason() is not None, reason=str(_skip_reason()))


@needs_hosts
def test_link_delay_seen_by_plain_udp():
    """The emulated link is what the hosts see (independent of DDS): a round trip between a
    delayed host and an undelayed one takes about 2 x the delay longer."""
    with hosts.Cell() as cell:
        cell.add_host('a')
        cell.add_host('b')
        cell.add_host('c', delay_ms=2.0)
        near = cell.udp_rtt_ms('a', 'b')
        far = cell.udp_rtt_ms('a', 'c')
    # the fastest of 20 round trips: load on the shared machine only ever adds to it
    assert len(near) >= 18 and len(far) >= 18
    assert min(near) < 1.0, near
    assert 4.0 <= min(far) < 4.0 + 2.0, far          # 2 x 2 ms + user-space forwarding


class _Lines:
    def __init__(self):
        self.lines, self.lock = [], threading.Lock()
        self.added = threading.Condition(self.lock)

    def write(self, text):
        with self.lock:
            self.lines.append(text)
            self.added.notify_all()

    def flush(self):
        pass

    def wait_for(self, prefix, needle, timeout_s):
        """True once a line of ``prefix`` holds ``needle`` (woken by each new line, bounded)."""
        def seen():
            return any(ln.startswith(f'[{prefix}]') and needle in ln for ln in self.lines)
        with self.lock:
            return self.added.wait_for(seen, timeout_s)

    def has(self, prefix, needle):
        with self.lock:
            return any(ln.startswith(f'[{prefix}]') and needle in ln for ln in self.lines)

    def tail(self, n=60):
        with self.lock:
            return ''.join(self.lines[-n:])


class _Operator:
    """cell_operator.py on a host: one command in, one JSON line out (bounded waits)."""

    def __init__(self, argv, env):
        self.proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, env=env,
                                     start_new_session=True)
        self.out: queue.Queue = queue.Queue()
        self.log: list[str] = []
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self):
        for line in self.proc.stdout:
            self.log.append(line)
            if line.startswith('{'):
                self.out.put(json.loads(line))

    def ask(self, cmd, timeout):
        self.proc.stdin.write(cmd + '\n')
        self.proc.stdin.flush()
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                return self.out.get(timeout=0.5)
            except queue.Empty:
                if self.proc.poll() is not None and self.out.empty():
                    break
        raise AssertionError(f'operator gave no answer to {cmd!r}: {"".join(self.log)}')

    def close(self):
        if self.proc.poll() is None:
            try:
                self.proc.stdin.write('quit\n')
                self.proc.stdin.close()
                self.proc.wait(timeout=15)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait(timeout=5)


def _drained(lines):
    """The recorder's last two progress lines (every 0.5 s) give the same counts. The topics
    after '|' come in the order they were first seen (the CI of ed9dcb4 had /torque_command
    first: a filter on '| /joint_states' never held)."""
    with lines.lock:
        prog = [ln.split('|', 1)[1] for ln in lines.lines
                if ln.startswith('[recorder]') and '/joint_states' in ln.partition('|')[2]]
    return len(prog) >= 2 and prog[-1] == prog[-2]


def _stamps(msgs, typ):
    from rclpy.serialization import deserialize_message
    decoded = [deserialize_message(b, typ) for b in msgs.data]
    return decoded, np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
                              for m in decoded])


def _missing(stamps):
    """Samples missing between the first and the last stamp of a 248 Hz stream."""
    steps = np.round(np.diff(np.sort(stamps)) / PERIOD).astype(int)
    return int(np.sum(np.maximum(steps - 1, 0))), int(np.sum(steps == 0))


@needs_hosts
@pytest.mark.slow
@pytest.mark.ros
def test_circle_across_three_hosts(tmp_path):
    from irb_control.process_group import ProcessGroup, ProcessSpec, ros2_run_cmd
    from irb_identification.bagio import read_messages, verify_bag
    from irb_interfaces.msg import ControllerState
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory

    delay = float(os.environ.get('IRB_HOSTS_DELAY_MS', '1'))
    loss = float(os.environ.get('IRB_HOSTS_LOSS', '0'))
    domain = int(os.environ.get('ROS_DOMAIN_ID', '0'))
    env = hosts.host_env(domain)
    stats = tmp_path / 'simulator_stats.json'
    lines = _Lines()
    group = operator = None
    with hosts.Cell() as cell:
        try:
            cell.add_host('ctrl')
            cell.add_host('ws', delay_ms=delay, loss=loss)
            cell.add_host('rec', delay_ms=delay, loss=loss)

            def spec(name, host, argv, required=True):
                return ProcessSpec(name, tuple(cell.wrap(host, argv)), required, env)
            group = ProcessGroup([
                spec('simulator', 'ctrl', ros2_run_cmd('irb_control', 'simulator', params={
                    'mode': SIM_MODE, 'stats_path': str(stats)})),
                spec('pdplus', 'ctrl', ros2_run_cmd('irb_control', 'pdplus', params={
                    'auto_enable': False, 'use_sim_time': SIM_MODE == 'lockstep'})),
                spec('planner', 'ws', ros2_run_cmd('irb_planning', 'planner'))],
                log=lambda m: None, stream=lines)
            group.start()
            operator = _Operator(cell.wrap('ws', [sys.executable, str(HERE / 'cell_operator.py')]),
                                 dict(os.environ, PYTHONUNBUFFERED='1', **env))
            # 1. the plan crosses ws -> ctrl: planned on ws, checked by pdplus's gate on ctrl
            plan = operator.ask('plan', 120)
            assert plan.get('accepted'), (plan, lines.tail())
            # 2. the recorder starts on rec after the plan: the latched plan still arrives
            topics = ['/joint_states', '/torque_command', '/controller_state',
                      '/planned_trajectory']
            group.add(spec('recorder', 'rec', ros2_run_cmd('irb_identification', 'recorder',
                           params={'root': str(tmp_path / 'bags'), 'name': 'cell',
                                   'topics': str(topics), 'recover_on_start': False,
                                   'progress_period_s': 0.5}),
                           required=False))
            assert group.wait_until(lambda: all(lines.has('recorder', f'subscribed to {t}')
                                                for t in topics), 60), lines.tail()
            # 3. the circle, commanded from ws, runs on ctrl
            run = operator.ask('enable', 90)
            assert run.get('done') and run['modes'][-1] == 5, (run, lines.tail())
            # 4. sources first, then the recorder once it has written all it received
            sim_code = group.stop_one('simulator')
            pd_code = group.stop_one('pdplus')
            assert group.wait_until(lambda: _drained(lines), 30), lines.tail()
            assert (sim_code, pd_code) == (0, 0), lines.tail()
            assert group.stop_one('recorder') == 0, lines.tail()
        finally:
            if operator is not None:
                operator.close()
            codes = group.stop() if group is not None else {}
    assert all(c == 0 for c in codes.values()), (codes, lines.tail())

    # the bag on rec, read back with the project's reader (rosbags) and CRC-checked (mcap)
    bag = tmp_path / 'bags' / 'cell'
    assert verify_bag(bag) > 0
    msgs = read_messages(bag, topics)
    plans = msgs['/planned_trajectory'].data
    from rclpy.serialization import deserialize_message
    assert len(plans) == 1
    assert len(deserialize_message(plans[0], JointTrajectory).points) == plan['points']
    _, js = _stamps(msgs['/joint_states'], JointState)
    cs, cs_t = _stamps(msgs['/controller_state'], ControllerState)
    gaps = np.round(np.diff(js) / PERIOD).astype(int)
    assert _missing(js) == (0, 0), ('joint states lost or doubled on the way to rec',
                                    len(js), js[0], js[-1], gaps[gaps != 1].tolist(),
                                    np.flatnonzero(gaps != 1).tolist())
    assert _missing(cs_t) == (0, 0), 'controller states lost or doubled on the way to rec'
    modes = [int(m.mode) for m in cs]
    assert {1, 2, 5} <= set(modes) and 4 not in modes   # ramp, path, hold; never stopped
    # the joint states (all of them at 248 Hz: _missing above) cover the whole motion: the
    # ramp and the 6 s circle, first to last step. (It was
    # js[-1] - js[0] > 6.5, which also counted idle states before the enable.) pdplus holds
    # once theta is within end_tolerance_rad (1e-3) of the end: since the plans' rest ends
    # move with constant jerk (issue 28, theta ~ t^3) that last 1e-3 rad takes ~60 ms, so
    # the path mode ends up to 0.1 s before the plan's 6 s (5.94 s measured).
    motion = cs_t[np.isin(modes, (1, 2))]
    ramp_t = cs_t[np.asarray(modes) == 1]
    path_t = cs_t[np.asarray(modes) == 2]
    assert js[0] <= motion[0] and js[-1] >= motion[-1]
    assert ramp_t.size and ramp_t[-1] < path_t[0]         # ramp first (its length: test_pd_plus)
    assert 6.0 - 0.1 <= path_t[-1] - path_t[0] <= 6.0 + PERIOD, path_t[[0, -1]]
    # every state of the motion (ramp, path) has its command in the bag, by stamp
    _, cmd_t = _stamps(msgs['/torque_command'], JointState)
    moving_t = cs_t[np.isin([int(m.mode) for m in cs], (1, 2))]
    ns = lambda t: np.round(np.asarray(t) * 1e6).astype(np.int64)     # noqa: E731
    assert moving_t.size > 6.0 / PERIOD
    assert np.isin(ns(moving_t), ns(cmd_t)).all(), 'commands of the motion missing on rec'

    # the loop on ctrl: every state of the motion answered by a command
    s = json.loads(stats.read_text())
    moving = [m.header.stamp for m in cs if int(m.mode) in (1, 2)]
    assert s['answered'] >= len(moving) > 6.0 / PERIOD, s


@needs_hosts
@pytest.mark.slow
@pytest.mark.ros
def test_link_failure_between_simulator_and_pdplus_stops_with_the_reason(tmp_path):
    """The loop split over two hosts (simulator on `robot`, pdplus and the operator on `rt`):
    the link of `robot` goes down in the middle of the circle; pdplus's watchdog stops the
    motion and says why (the stop reason on controller_state, seen on `rt`)."""
    from irb_control.process_group import ProcessGroup, ProcessSpec, ros2_run_cmd
    env = hosts.host_env(int(os.environ.get('ROS_DOMAIN_ID', '0')))
    lines = _Lines()
    group = operator = None
    with hosts.Cell() as cell:
        try:
            robot = cell.add_host('robot')
            cell.add_host('rt')

            def spec(name, host, argv):
                return ProcessSpec(name, tuple(cell.wrap(host, argv)), True, env)
            group = ProcessGroup([
                spec('simulator', 'robot', ros2_run_cmd('irb_control', 'simulator', params={
                    'mode': SIM_MODE})),
                spec('pdplus', 'rt', ros2_run_cmd('irb_control', 'pdplus', params={
                    'auto_enable': False, 'use_sim_time': SIM_MODE == 'lockstep',
                    'profile_duration_s': 10.0}))], log=lambda m: None, stream=lines)
            group.start()
            operator = _Operator(cell.wrap('rt', [sys.executable, str(HERE / 'cell_operator.py')]),
                                 dict(os.environ, PYTHONUNBUFFERED='1', **env))
            started = operator.ask('start', 120)
            assert started.get('moving'), (started, lines.tail())
            # the cable is pulled: the robot host's interface goes down
            subprocess.run(cell.wrap(robot, ['ip', 'link', 'set', robot.ifname, 'down']),
                           check=True, timeout=10)
            end = operator.ask('wait_end', 90)
            assert end.get('done') and end['modes'][-1] == 4, (end, lines.tail())
            assert 'watchdog' in end['stop_reason'], end
            # pdplus's own log line comes through its output pipe, which can trail the
            # controller_state that ended the wait: wait for it too (bounded)
            assert lines.wait_for('pdplus', 'watchdog', 30.0), lines.tail()
        finally:
            if operator is not None:
                operator.close()
            if group is not None:
                group.stop()
