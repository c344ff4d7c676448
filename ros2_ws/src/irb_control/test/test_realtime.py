"""realtime_priority / cpu_affinity: applied to every thread when permitted, a warning (never
an exception) when refused."""
import os
import signal
import subprocess
import sys
import threading
import uuid

import pytest

from irb_control import node_util
from irb_control.node_util import apply_realtime, hold_cpu_latency, process_threads
from irb_description.output_lines import OutputLines


class _Log:
    def __init__(self):
        self.warnings, self.infos = [], []

    def warning(self, text):
        self.warnings.append(text)

    def info(self, text):
        self.infos.append(text)


def _fifo_permitted() -> bool:
    return subprocess.run(['chrt', '-f', '1', 'true'], capture_output=True).returncode == 0


@pytest.fixture
def helper_thread():
    """A thread of this process that only waits: the object of the scheduling changes."""
    ready, done = threading.Event(), threading.Event()
    tid = []

    def run():
        tid.append(threading.get_native_id())
        ready.set()
        done.wait(30.0)
    th = threading.Thread(target=run, daemon=True)
    th.start()
    assert ready.wait(10.0)
    yield tid[0]
    done.set()
    th.join(10.0)


def test_off_changes_nothing(helper_thread):
    log = _Log()
    before = os.sched_getscheduler(helper_thread)
    out = apply_realtime(0, [], log, threads=[helper_thread])
    assert out == {'priority': 0, 'cpus': [], 'cpu_dma_latency_us': -1, 'warnings': []}
    assert os.sched_getscheduler(helper_thread) == before and not log.infos


def test_refused_priority_is_a_warning_and_rolls_back(monkeypatch):
    calls = []
    policy = {1: os.SCHED_OTHER, 2: os.SCHED_OTHER}

    def setscheduler(tid, pol, param):
        if tid == 2 and pol == os.SCHED_FIFO:
            raise PermissionError(1, 'Operation not permitted')
        calls.append((tid, pol))
        policy[tid] = pol
    monkeypatch.setattr(os, 'sched_setscheduler', setscheduler)
    monkeypatch.setattr(os, 'sched_getscheduler', lambda tid: policy[tid])
    monkeypatch.setattr(os, 'sched_getparam', lambda tid: os.sched_param(0))
    log = _Log()
    out = apply_realtime(20, [], log, threads=[1, 2])
    assert out['priority'] == 0 and len(log.warnings) == 1
    assert 'not permitted' in log.warnings[0] and 'realtime_priority' in log.warnings[0]
    assert policy == {1: os.SCHED_OTHER, 2: os.SCHED_OTHER}      # thread 1 restored
    assert (1, os.SCHED_FIFO) in calls


def test_nonexistent_cpu_is_a_warning(helper_thread):
    log = _Log()
    before = os.sched_getaffinity(helper_thread)
    out = apply_realtime(0, [4095], log, threads=[helper_thread])
    assert out['cpus'] == [] and 'cpu_affinity' in log.warnings[0]
    assert os.sched_getaffinity(helper_thread) == before


@pytest.mark.skipif(not _fifo_permitted(), reason='SCHED_FIFO not permitted here')
def test_priority_and_affinity_applied(helper_thread):
    log = _Log()
    cpu = min(os.sched_getaffinity(0))
    out = apply_realtime(7, [cpu], log, threads=[helper_thread])
    try:
        assert out == {'priority': 7, 'cpus': out['cpus'], 'cpu_dma_latency_us': -1,
                       'warnings': []}
        assert os.sched_getscheduler(helper_thread) == os.SCHED_FIFO
        assert os.sched_getparam(helper_thread).sched_priority == 7
        assert os.sched_getaffinity(helper_thread) == {cpu}
        assert log.infos and 'SCHED_FIFO priority 7' in log.infos[0]
    finally:
        os.sched_setscheduler(helper_thread, os.SCHED_OTHER, os.sched_param(0))


def test_cpu_latency_request_is_written_and_held(tmp_path):
    """The PM QoS request: a native int32 written to the file, which stays open (closing
    it would drop the request); a path that cannot be opened is a reason, not a raise."""
    import struct
    f = tmp_path / 'cpu_dma_latency'
    f.write_bytes(b'')
    assert hold_cpu_latency(0, str(f)) == ''
    assert f.read_bytes() == struct.pack('i', 0)
    assert any(h.name == str(f) and not h.closed for h in node_util._LATENCY_REQUESTS)
    assert 'No such file' in hold_cpu_latency(0, str(tmp_path / 'none' / 'x'))


def test_cpu_latency_refused_is_a_warning(monkeypatch):
    monkeypatch.setattr(node_util, 'hold_cpu_latency', lambda us: 'Permission denied')
    log = _Log()
    out = apply_realtime(0, [], log, threads=[], cpu_latency_us=0)
    assert out['cpu_dma_latency_us'] == -1
    assert len(log.warnings) == 1 and 'cpu_dma_latency_us 0 not applied' in log.warnings[0]
    out = apply_realtime(0, [], log, threads=[])         # -1 (default): not asked for
    assert out['cpu_dma_latency_us'] == -1 and len(log.warnings) == 1


def test_process_threads_lists_this_thread():
    assert threading.get_native_id() in process_threads()


@pytest.mark.ros
def test_simulator_process_runs_with_the_parameter():
    """The executable with realtime_priority:=5: every thread SCHED_FIFO 5 when permitted,
    else the warning; it runs and stops cleanly either way."""
    pytest.importorskip('rclpy')
    proc = subprocess.Popen(
        [sys.executable, '-m', 'irb_control.simulator_node', '--ros-args', '-r',
         f'__ns:=/rt{uuid.uuid4().hex[:8]}', '-p', 'realtime_priority:=5'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        line = OutputLines(proc.stdout).wait_for('SCHED_FIFO', 60.0)[-1]
        if _fifo_permitted():
            assert 'SCHED_FIFO priority 5' in line
            tids = [int(t) for t in os.listdir(f'/proc/{proc.pid}/task')]
            assert tids and all(os.sched_getscheduler(t) == os.SCHED_FIFO for t in tids)
        else:
            assert 'not permitted' in line
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            rc = proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            rc = proc.wait()
    assert rc == 0, proc.stdout.read()
