"""Recorder and replay under faults (issue 14, defects 11 and 12): a full disk, a damaged bag,
Ctrl-C in the middle of playing.

The full disk is a small tmpfs mounted for the test (needs root; skipped with the reason
otherwise). Processes are started in sessions of their own and interrupted as a terminal does.
"""
import os
import signal
import subprocess
import time
import uuid
from pathlib import Path

import pytest

rclpy = pytest.importorskip('rclpy')
from sensor_msgs.msg import JointState  # noqa: E402

from irb_description.output_lines import popen_lines  # noqa: E402
from irb_identification import bagio  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]


@pytest.fixture
def tiny_disk(tmp_path):
    """A 384 KiB tmpfs (root only)."""
    mnt = tmp_path / 'tiny'
    mnt.mkdir()
    res = subprocess.run(['mount', '-t', 'tmpfs', '-o', 'size=384k', 'tmpfs', str(mnt)],
                         capture_output=True, text=True)
    if res.returncode != 0:
        pytest.skip(f'cannot mount a small tmpfs here (needs root): {res.stderr.strip()}')
    yield mnt
    subprocess.run(['umount', '-l', str(mnt)], capture_output=True)


def _exe(name):
    from ament_index_python.packages import get_package_prefix
    return str(Path(get_package_prefix('irb_identification')) / 'lib' / 'irb_identification'
               / name)


def _js(k):
    m = JointState(name=['joint_1', 'joint_2', 'joint_3'], position=[float(k), 0.0, 0.0],
                   velocity=[0.0] * 3, effort=[0.0] * 3)
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(k * 4_032_000, 1_000_000_000)
    return m


def test_bag_writer_on_a_full_disk_keeps_the_closed_splits(tiny_disk):
    info = bagio.TopicInfo.for_type('/js', 'sensor_msgs/msg/JointState', [])
    from rclpy.serialization import serialize_message
    data = serialize_message(_js(1)) + b'\0' * 200
    t = [0.0]
    w = bagio.BagWriter(tiny_disk / 'full', split_period_s=0.05, chunk_size=4096,
                        clock=lambda: t[0])
    w.add_topic(info)
    with pytest.raises(bagio.BagWriteError) as exc:
        for k in range(100000):
            t[0] = k * 0.004
            w.write('/js', k * 4_032_000, data)
    assert 'No space left' in str(exc.value) and 'kept' in str(exc.value)
    with pytest.raises(bagio.BagWriteError):
        w.write('/js', 1, data)                       # refused from now on, one reason
    w.close()                                          # no exception
    assert w.files, 'some splits were closed before the disk filled'
    assert not list((tiny_disk / 'full').glob('*.tmp'))
    kept = bagio.read_messages(tiny_disk / 'full')['/js']
    assert len(kept.data) == sum(f.count for f in w.files)
    # recovery on the full disk: no crash, no .tmp left, the open split kept for later
    report = bagio.recover_bag(tiny_disk / 'full')
    assert not list((tiny_disk / 'full').glob('*.tmp'))
    assert report.problems or report.salvaged_files


def test_recorder_process_on_a_full_disk(tiny_disk, ctx):
    # defect 12: two tracebacks; the next start crashed in recovery and left a .tmp file
    context, executor = ctx
    topic = f'/js_full_{uuid.uuid4().hex[:6]}'
    node = rclpy.create_node(f'fullpub_{uuid.uuid4().hex[:6]}', context=context)
    pub = node.create_publisher(JointState, topic, 100)
    executor.add_node(node)
    cmd = [_exe('recorder'), '--ros-args', '-p', f'root:={tiny_disk}', '-p', 'name:=full',
           '-p', f'topics:=[{topic}]', '-p', 'types:=[sensor_msgs/msg/JointState]',
           '-p', 'split_period_s:=0.2', '-r', f'__node:=rec_{uuid.uuid4().hex[:6]}']
    proc = popen_lines(cmd, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        big = _js(0)
        big.name = big.name + [f'x{i:04d}' for i in range(400)]       # ~5 KiB a message
        k = 0
        while proc.poll() is None and time.monotonic() < deadline:
            big.position[0] = float(k)
            pub.publish(big)
            k += 1
            executor.spin_once(timeout_sec=0.002)
        code = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    out = proc.out.rest()
    assert code == 1, out
    assert 'Traceback' not in out and out.count('No space left') >= 1, out
    assert 'recorder: bag' in out and 'kept' in out
    # a clean start afterwards in the same root (another name): its recovery of the full
    # bag does not crash or leave a .tmp file; on the still-full disk it says so in one line
    second = [x.replace('name:=full', 'name:=second') for x in cmd]
    again = popen_lines(second, start_new_session=True)
    lines = again.out
    try:                                       # it ends with one line, or starts recording
        lines.wait_for('recording [', 60)
    except AssertionError:
        pass
    if again.poll() is None:                   # it started recording after all: stop it
        os.killpg(again.pid, signal.SIGINT)
    code2 = again.wait(timeout=30)
    out2 = ''.join(lines.lines) + lines.rest()
    assert 'Traceback' not in out2, out2
    assert code2 in (0, 1) and (code2 == 0 or out2.strip().splitlines()[-1].startswith(
        'recorder: ')), out2
    assert not list(tiny_disk.rglob('*.tmp'))
    node.destroy_node()


def _start(args):
    return popen_lines([_exe('replay'), '--ros-args', *args, '-r',
                        f'__node:=rp_{uuid.uuid4().hex[:6]}'], start_new_session=True)


@pytest.fixture
def small_bag(tmp_path):
    from rclpy.serialization import serialize_message
    info = bagio.TopicInfo.for_type('/js_rp', 'sensor_msgs/msg/JointState', [])
    with bagio.BagWriter(tmp_path / 'bag', split_period_s=100.0) as w:
        w.add_topic(info)
        for k in range(2000):                          # 8 s of 248 Hz
            w.write('/js_rp', 1_000_000_000 + k * 4_032_000, serialize_message(_js(k)))
    return tmp_path / 'bag'


def test_replay_refuses_a_damaged_bag_with_one_line(small_bag):
    # defect 11: replay exited 0 on a chunk CRC error
    f = next(small_bag.glob('*.mcap'))
    data = bytearray(f.read_bytes())
    data[len(data) // 2] ^= 0xFF                       # inside a chunk
    f.write_bytes(bytes(data))
    proc = _start(['-p', f'bag:={small_bag}', '-p', 'rate:=0.0'])
    code = proc.wait(timeout=60)
    out = proc.out.rest()
    assert code == 1, out
    assert 'Traceback' not in out
    assert 'replay: bag' in out and 'damaged' in out


@pytest.mark.parametrize('times', [1, 2])
def test_ctrl_c_while_playing_is_quiet(small_bag, times):
    # defect 11: a traceback on every stop mid-playback
    proc = _start(['-p', f'bag:={small_bag}', '-p', 'rate:=1.0'])
    lines = proc.out
    lines.wait_for('playing', 60)
    os.killpg(proc.pid, signal.SIGINT)
    if times > 1:
        try:
            proc.wait(timeout=0.05)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGINT)
    code = proc.wait(timeout=30)
    out = ''.join(lines.lines) + lines.rest()
    assert code == 0 and 'Traceback' not in out, out
