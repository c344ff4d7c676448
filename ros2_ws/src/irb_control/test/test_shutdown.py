"""One Ctrl-C stops every node of this package cleanly; a second one is harmless (issue 14,
defect 11: fake_axis_computer printed a traceback, exited 254 and wrote no statistics; the
simulator silently skipped its statistics file).

Each executable is started with `ros2 run` in a session of its own and interrupted the way a
terminal does it: SIGINT to the whole process group (`ros2 run` and the node, once each).
"""
import json
import os
import signal
import socket
import subprocess
import uuid

import pytest
from irb_control.process_group import stop_sessions
from irb_description.output_lines import OutputLines

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def free_udp_ports(n):
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(n)]
    for s in socks:
        s.bind(('127.0.0.1', 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def start(exe, *params, ns=None):
    cmd = ['ros2', 'run', 'irb_control', exe, '--ros-args', '-r',
           f'__ns:={ns or "/sd" + uuid.uuid4().hex[:8]}',
           *[x for p in params for x in ('-p', p)]]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)


def wait_for_line(proc, needle, timeout=60.0):
    """Read the output until a line contains ``needle`` (bounded); the lines read so far."""
    if not hasattr(proc, 'lines'):
        proc.lines = OutputLines(proc.stdout)
    return proc.lines.wait_for(needle, timeout)


def interrupt(proc, times):
    """``times`` Ctrl-C, the second 50 ms after the first (during the clean-up); exit code and
    the rest of the output."""
    os.killpg(proc.pid, signal.SIGINT)
    if times > 1:
        try:
            proc.wait(timeout=0.05)
        except subprocess.TimeoutExpired:
            try:
                os.killpg(proc.pid, signal.SIGINT)
            except ProcessLookupError:
                pass
    try:
        code = proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        raise AssertionError('did not stop within 30 s of Ctrl-C')
    return code, (proc.lines.rest() if hasattr(proc, 'lines') else proc.stdout.read())


@pytest.mark.parametrize('times', [1, 2])
@pytest.mark.parametrize('exe, ready', [('simulator', 'simulator:'),
                                        ('fake_axis_computer', 'fake axis computer:'),
                                        ('pdplus', 'pdplus:'),
                                        ('axis_bridge', 'axis_bridge:')])
def test_ctrl_c_stops_cleanly(tmp_path, exe, ready, times):
    stats = tmp_path / 'stats.json'
    params = []
    if exe in ('simulator', 'fake_axis_computer'):
        params.append(f'stats_path:={stats}')
    if exe in ('fake_axis_computer', 'axis_bridge'):
        state, command = free_udp_ports(2)
        params += [f'state_port:={state}', f'command_port:={command}']
    proc = start(exe, *params)
    try:
        before = ''.join(wait_for_line(proc, ready))
        code, after = interrupt(proc, times)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    out = before + after
    assert_clean(code, out)
    if exe in ('simulator', 'fake_axis_computer'):
        assert stats.exists(), out
        assert json.loads(stats.read_text())           # the statistics were written


def assert_clean(code, out):
    assert code == 0, out
    for word in ('Traceback', 'Exception', 'FATAL', 'Error'):
        assert word not in out.replace('error bits', ''), out


def test_ctrl_c_while_callbacks_run(tmp_path):
    # the simulator interrupted while pdplus's commands arrive at 248 Hz: a signal that raised
    # KeyboardInterrupt inside a running command callback was logged by the EventsExecutor as
    # a FATAL "Exception in 'subscriptions' callback" with its traceback (seen in thesis_run)
    ns = f'/sd{uuid.uuid4().hex[:8]}'
    for k in range(3):
        ctrl = start('pdplus', 'auto_enable:=true', 'require_axis_status:=false', ns=ns)
        sim = start('simulator', f'stats_path:={tmp_path / f"s{k}.json"}', ns=ns)
        try:
            # the loop is closed: the simulator took a command (its brakes released)
            before = ''.join(wait_for_line(sim, 'brakes released'))
            code, after = interrupt(sim, 1)
            assert_clean(code, before + after)
            stats = json.loads((tmp_path / f's{k}.json').read_text())
            # command callbacks ran (answers to the latest state, or late ones on a loaded
            # machine, which the simulator ignores as the axis computer does)
            assert stats['answered'] + stats['stale_commands_ignored'] > 0, stats
        finally:
            stop_sessions([sim, ctrl], 30.0)
