"""Axis bridge + fake axis computer (+ pdplus) as separate processes on loopback UDP.

Round trip with the unchanged controller, every fault kind, link loss and recovery, and the
safe reaction at both ends (axis computer latches and brakes; the bridge reports it; reset).
"""
import os
import signal
import socket
import subprocess
import tempfile
import time
import uuid

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from irb_interfaces.msg import ControllerState  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from irb_description.node_main import state_qos  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def free_udp_ports(n):
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(n)]
    for s in socks:
        s.bind(('127.0.0.1', 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def stop(proc):
    """Ctrl-C as a terminal sends it (SIGINT to the session's group: `ros2 run`, which does
    not forward it, and the node, once each); SIGKILL to the group after 20 s."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)      # Ctrl-C: the whole group, once
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    log = getattr(proc, 'log', None)
    if log is None:
        return proc.stdout.read() if proc.stdout else ''
    log.seek(0)
    return log.read()


def popen_logged(cmd, **kw):
    """Popen with the child's output in a file (``proc.log``, read by ``stop``): a pipe read
    only at the end fills (64 KiB) and the node then blocks in its logger, control loop and
    all."""
    log = tempfile.TemporaryFile(mode='w+')
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, text=True, **kw)
    proc.log = log
    return proc


class Graph:
    """Starts processes in a private namespace; a listener node with a bounded wait helper."""

    def __init__(self):
        self.ns = f'/ax{uuid.uuid4().hex[:8]}'
        self.state_port, self.command_port = free_udp_ports(2)
        self.procs = {}
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
        self.node = rclpy.create_node(f'axis_test_{uuid.uuid4().hex[:6]}', context=self.ctx)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.diag = {}
        self.logs = {}
        self.node.create_subscription(DiagnosticArray, f'{self.ns}/axis_bridge/status',
                                      self._on_diag, 10)

    def _on_diag(self, msg):
        self.diag = {kv.key: kv.value for kv in msg.status[0].values}

    def start(self, name, exe, *params):
        cmd = ['ros2', 'run', 'irb_control', exe, '--ros-args', '-r', f'__ns:={self.ns}',
               '-p', f'state_port:={self.state_port}', '-p', f'command_port:={self.command_port}',
               *[x for p in params for x in ('-p', p)]]
        self.procs[name] = popen_logged(cmd, start_new_session=True)

    def wait(self, condition, timeout_s=60.0):
        """Spin until condition() holds or ``timeout_s`` of wall time have passed."""
        deadline = time.monotonic() + timeout_s
        while not condition():
            if time.monotonic() > deadline:
                return False
            self.ex.spin_once(timeout_sec=0.02)
        return True

    def stop_all(self) -> str:
        """Stop every process; their output, last 1500 characters each (for a failure's
        message: what the nodes said is the diagnosis)."""
        self.logs.update({n: stop(p) for n, p in self.procs.items() if n not in self.logs})
        return '\n'.join(f'--- {n}:\n{log[-1500:]}' for n, log in self.logs.items())

    def close(self):
        self.stop_all()
        logs = self.logs
        self.ex.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)
        return logs


@pytest.fixture
def graph():
    g = Graph()
    yield g
    g.close()


def _modes(states):
    """The controller's mode changes (and a stop reason) for assertion messages."""
    out = []
    for s in states:
        if not out or out[-1][0] != s.mode:
            out.append((s.mode, s.stop_reason))
    return out


def test_pdplus_runs_unchanged_against_the_bridge(stall_retries):
    # This test is about the data path (UDP <-> ROS, sequence echo, pdplus unchanged), not
    # about the timing limits: on this shared 2-vCPU VM the bare rclpy echo between two
    # processes had stalls of up to 17 ms on an idle machine (echo_floor.py, 2026-11-24), and
    # the 3-cycle limits then stopped the robot correctly in 2 of 3 quiet runs. The limits
    # are 25 cycles (~100 ms) here; the 3-cycle reactions are tested in the fault test below
    # and in the cores' tests, and their rate is measured by bench_safety.py soak. A CI VM
    # stalled 332 ms once: a stop from the watchdog or the axis computer's comm timeout is
    # the correct reaction, and the scenario then runs again on fresh processes
    # (stall_retries); any other stop fails at once.
    stall_retries(lambda: _data_path_once(stall_retries))


def _data_path_once(retries):
    graph = Graph()
    try:
        _data_path(graph, retries)
    finally:
        graph.close()


def _data_path(graph, retries):
    graph.start('axis', 'fake_axis_computer', 'miss_limit:=25')
    graph.start('bridge', 'axis_bridge')
    # auto_enable (on here; off by default) starts the ramp once the joint states have been
    # steady for auto_enable_settle_s and torque_command has a subscriber (the bridge). Without
    # that gate about one start in twenty ended in a correct, latched safe stop: a 17 ms gap while
    # DDS discovery was still going on (watchdog), or commands nobody received yet (the axis
    # computer braked).
    graph.procs['pdplus'] = popen_logged(
        ['ros2', 'run', 'irb_control', 'pdplus', '--ros-args', '-r', f'__ns:={graph.ns}',
         '-p', 'profile_duration_s:=10.0', '-p', 'watchdog_missed_samples:=25',
         '-p', 'auto_enable:=true'], start_new_session=True)
    states = []
    graph.node.create_subscription(ControllerState, f'{graph.ns}/controller_state',
                                   states.append, state_qos())

    def stalled():
        """A stop by the watchdog, or the axis computer's comm-timeout latch: the machine."""
        stops = [s.stop_reason for s in states if s.mode == ControllerState.MODE_STOPPED]
        if (stops and retries.is_stall(stops[0])) or graph.diag.get('axis_error') == '1':
            raise retries.Stall(f'{_modes(states)}, axis_error {graph.diag.get("axis_error")}')
    reached = (ControllerState.MODE_PATH, ControllerState.MODE_STOPPED)
    graph.wait(lambda: any(s.mode in reached for s in states), 90)    # a stop ends the wait
    if not any(s.mode == ControllerState.MODE_PATH for s in states):
        stalled()
        raise AssertionError(f'pdplus never reached the path through the bridge: '
                             f'{_modes(states)}, {graph.diag}\n{graph.stop_all()}')
    if not graph.wait(lambda: int(graph.diag.get('commands_sent', 0)) > 400, 60):
        stalled()
        raise AssertionError(f'fewer than 400 commands sent: {graph.diag}, {_modes(states)}')
    if graph.diag['axis_error'] != '0' or states[-1].mode != ControllerState.MODE_PATH:
        stalled()
    assert graph.diag['axis_error'] == '0' and graph.diag['link_up'] == 'True', \
        f'{graph.diag}, {_modes(states)}'
    last = states[-1]
    assert last.mode == ControllerState.MODE_PATH, last.stop_reason
    assert np.abs(np.asarray(last.q_error)).max() < 0.01       # tracking through UDP


def test_faults_link_loss_and_safe_reactions(graph):
    faults = ['fault_drop:=0.02', 'fault_delay:=0.02', 'fault_duplicate:=0.03',
              'fault_reorder:=0.02', 'fault_corrupt:=0.03', 'fault_nan:=0.03', 'miss_limit:=6']
    graph.start('axis', 'fake_axis_computer', *faults)
    graph.start('bridge', 'axis_bridge')
    # a minimal controller in this process: hold the pose with a PD law on joint_states
    cmd_pub = graph.node.create_publisher(JointState, f'{graph.ns}/torque_command', state_qos())
    hold = {}
    answering = [True]

    def on_state(msg):
        q, qd = np.array(msg.position), np.array(msg.velocity)
        hold.setdefault('q', q)
        if not answering[0]:
            return
        tau = 4000.0 * (hold['q'] - q) - 300.0 * qd
        out = JointState(name=list(msg.name), effort=tau.tolist())
        out.header.stamp = msg.header.stamp
        cmd_pub.publish(out)
    graph.node.create_subscription(JointState, f'{graph.ns}/joint_states', on_state,
                                   state_qos())

    # every fault kind shows in the bridge's counters; no command is ever sent for junk
    def counters_seen():
        d = graph.diag
        return all(int(d.get(f'rejected_{k}', 0)) > 0
                   for k in ('duplicate', 'stale', 'crc', 'nan'))
    assert graph.wait(counters_seen, 90), graph.diag
    assert graph.wait(lambda: int(graph.diag["commands_sent"]) > 100, 30), graph.diag

    # link loss: freeze the axis computer; the bridge reports the loss, then the recovery
    axis = graph.procs['axis'].pid                  # process group: ros2 run and the node
    os.killpg(axis, signal.SIGSTOP)
    try:
        assert graph.wait(lambda: graph.diag.get('link_up') == 'False', 30), graph.diag
    finally:
        os.killpg(axis, signal.SIGCONT)
    assert graph.wait(lambda: graph.diag.get('link_up') == 'True', 30), graph.diag
    assert int(graph.diag['link_losses']) >= 1
    # the frozen cycles were missed: the axis computer braked and latched the timeout error
    assert graph.wait(lambda: graph.diag.get('axis_error') == '1', 30), graph.diag
    assert graph.diag['axis_motors_on'] == 'False'

    # reset through the bridge clears the latched error while commands flow
    reset = graph.node.create_client(Trigger, f'{graph.ns}/axis_bridge/reset')
    assert reset.wait_for_service(timeout_sec=30)
    fut = reset.call_async(Trigger.Request())
    graph.ex.spin_until_future_complete(fut, timeout_sec=30)
    assert fut.result().success
    assert graph.wait(lambda: graph.diag.get('axis_error') == '0', 30), graph.diag

    # the controller goes silent: the axis computer brakes and latches again
    answering[0] = False
    assert graph.wait(lambda: graph.diag.get('axis_error') == '1', 30), graph.diag
    logs = graph.close()
    assert 'link lost' in logs['bridge'] and 'link recovered' in logs['bridge']
    assert 'brakes engaged' in logs['axis']
