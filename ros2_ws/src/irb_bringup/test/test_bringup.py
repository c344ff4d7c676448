"""bringup: the shared graph file, a real graph up and down, a failing node."""
import os
import signal
import subprocess
import threading
from pathlib import Path

import pytest

from irb_bringup.graph_spec import load_graph

PKG = Path(__file__).resolve().parent.parent


def test_default_graph_file_lists_the_thesis_nodes():
    nodes = load_graph(PKG / 'config' / 'bringup.yaml')
    assert [n.name for n in nodes] == ['simulator', 'pdplus', 'planner', 'state_publisher',
                                       'recorder']
    # the drawing and the recording are optional, the control loop and the planner not
    assert [n.name for n in nodes if not n.required] == ['state_publisher', 'recorder']


def test_launch_file_reads_the_same_graph():
    text = (PKG / 'launch' / 'irb_graph.launch.py').read_text()
    assert 'from irb_bringup.graph_spec import load_graph' in text
    assert "'bringup.yaml'" in text


@pytest.mark.parametrize('text, reason', [
    ('[]', 'list "nodes"'),
    ('nodes: [{name: a, package: p}]', 'lacks'),
    ('nodes: [{name: a, package: p, executable: e}, {name: a, package: p, executable: e}]',
     'duplicate'),
])
def test_bad_graph_files(tmp_path, text, reason):
    f = tmp_path / 'g.yaml'
    f.write_text(text)
    with pytest.raises(ValueError, match=reason):
        load_graph(f)


class Output:
    """Collects a process's output on a thread; wait() blocks until a line appears."""

    def __init__(self, proc):
        self.text = ''
        self.cond = threading.Condition()
        threading.Thread(target=self._read, args=(proc,), daemon=True).start()

    def _read(self, proc):
        for line in proc.stdout:
            with self.cond:
                self.text += line
                self.cond.notify_all()

    def wait(self, needle, timeout):
        with self.cond:
            return self.cond.wait_for(lambda: needle in self.text, timeout)


def start(config):
    return subprocess.Popen(['ros2', 'run', 'irb_bringup', 'bringup', '--config',
                             str(config)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True,
                            env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST'))


@pytest.mark.ros
def test_graph_comes_up_and_stops_cleanly_on_ctrl_c(tmp_path):
    cfg = tmp_path / 'g.yaml'
    cfg.write_text('nodes:\n'
                   '  - {name: simulator, package: irb_control, executable: simulator,\n'
                   '     parameters: {mode: realtime}}\n'
                   '  - {name: pdplus, package: irb_control, executable: pdplus,\n'
                   '     parameters: {auto_enable: false}}\n')
    proc = start(cfg)
    out = Output(proc)
    try:
        assert out.wait('[pdplus]', 60) and out.wait('[simulator]', 60), out.text
        os.killpg(proc.pid, signal.SIGINT)      # Ctrl-C: the whole group, once
        assert proc.wait(timeout=60) == 0, out.text
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert out.wait('stopping the graph', 5)
    assert 'Traceback' not in out.text, out.text


@pytest.mark.ros
def test_a_failing_node_stops_the_graph(tmp_path):
    cfg = tmp_path / 'g.yaml'
    cfg.write_text('nodes:\n'
                   '  - {name: simulator, package: irb_control, executable: simulator}\n'
                   '  - {name: broken, package: irb_control, executable: no_such_exe}\n')
    proc = start(cfg)
    out = Output(proc)
    try:
        assert proc.wait(timeout=60) == 1, out.text
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert out.wait('broken failed', 5), out.text
