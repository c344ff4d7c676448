"""Bag writer, recovery and readers: round trips through tmp_path with synthetic stamps."""
import shutil

import numpy as np
import pytest
import yaml

from irb_identification import bagio
from irb_identification.series import JOINT_STATE, decode_joint_states, encode_joint_states

NAMES = ['joint_1', 'joint_2', 'joint_3']
T0 = 1_700_000_000 * 10**9


def point_stamped(k):
    ts = bagio.typestore()
    P = ts.types['geometry_msgs/msg/PointStamped']
    H = ts.types['std_msgs/msg/Header']
    T = ts.types['builtin_interfaces/msg/Time']
    Pt = ts.types['geometry_msgs/msg/Point']
    return bagio.serialize('geometry_msgs/msg/PointStamped', P(
        header=H(stamp=T(sec=k, nanosec=0), frame_id='base_link'),
        point=Pt(x=0.6 + k * 1e-3, y=0.0, z=0.13)))


def controller_state(k):
    """Serialized by rclpy (so the field list follows irb_interfaces as installed)."""
    ControllerState = pytest.importorskip('irb_interfaces.msg').ControllerState
    from rclpy.serialization import serialize_message
    m = ControllerState()
    m.mode = 2
    m.theta = 0.1 * k
    m.q_ref = [float(k)] * 3
    return serialize_message(m)


def write_demo(path, n=600, split=0.5, close=True):
    clock = [0.0]
    w = bagio.BagWriter(path, split_period_s=split, clock=lambda: clock[0], chunk_size=4096)
    w.add_topic(bagio.TopicInfo.for_type('/joint_states', JOINT_STATE,
                                         [bagio.qos_profile_dict('best_effort', depth=1)]))
    w.add_topic(bagio.TopicInfo.for_type('/camera/tcp', 'geometry_msgs/msg/PointStamped'))
    t = np.arange(n) * 4_032_000 + T0
    q = np.outer(np.arange(n), [1.0, 2.0, 3.0]) * 1e-3
    js = encode_joint_states(t, NAMES, q, q, q)
    for k in range(n):
        clock[0] = k * 0.004032
        w.write('/joint_states', int(t[k]), js[k])
        if k % 3 == 0:
            w.write('/camera/tcp', int(t[k]) + 1000, point_stamped(k))
        if k == n // 2:        # a topic appearing mid-recording
            w.add_topic(bagio.TopicInfo.for_type('/controller_state',
                                                 'irb_interfaces/msg/ControllerState'))
        if k > n // 2 and k % 10 == 0:
            w.write('/controller_state', int(t[k]) + 2000, controller_state(k))
    if close:
        w.close()
    else:
        w.flush()
    return w, q


def test_round_trip_two_readers(tmp_path, bag_check):
    w, q = write_demo(tmp_path / 'demo')
    counts = bag_check(tmp_path / 'demo')
    assert counts == {'/joint_states': 600, '/camera/tcp': 200, '/controller_state': 29}
    info = yaml.safe_load((tmp_path / 'demo' / 'metadata.yaml').read_text())
    files = info['rosbag2_bagfile_information']['relative_file_paths']
    assert len(files) == 5 and files[0] == 'demo_0.mcap'      # 2.4 s split every 0.5 s
    assert not list((tmp_path / 'demo').glob('*.active'))
    msgs = bagio.read_messages(tmp_path / 'demo', ['/joint_states'])['/joint_states']
    js = decode_joint_states(msgs.data, msgs.t_ns)
    np.testing.assert_array_equal(js.position, q)
    cs = bagio.read_messages(tmp_path / 'demo', ['/controller_state'])['/controller_state']
    assert cs.msgtype == 'irb_interfaces/msg/ControllerState'
    from irb_interfaces.msg import ControllerState
    from rclpy.serialization import deserialize_message
    m = deserialize_message(cs.data[0], ControllerState)       # CDR padding is not zeroed
    assert m.mode == 2 and list(m.q_ref) == [310.0] * 3
    cam = bagio.read_messages(tmp_path / 'demo', ['/camera/tcp'])['/camera/tcp']
    m = bagio.deserialize(cam.msgtype, cam.data[1])
    assert m.point.x == pytest.approx(0.603) and m.header.frame_id == 'base_link'
    meta = bagio.bag_info(tmp_path / 'demo')
    assert meta['topics']['/camera/tcp']['type'] == 'geometry_msgs/msg/PointStamped'


@pytest.mark.parametrize('msgtype', ['sensor_msgs/msg/JointState',
                                     'geometry_msgs/msg/PointStamped',
                                     'trajectory_msgs/msg/JointTrajectory'])
def test_type_hash_matches_rosidl(msgtype):
    """The RIHS01 hash written to the bag equals rosidl's generated one (share/.../*.json)."""
    import json
    path = bagio._msg_file(msgtype)
    if path is None or not path.with_suffix('.json').is_file():
        pytest.skip(f'no rosidl type description of {msgtype} installed')
    desc = json.loads(path.with_suffix('.json').read_text())
    hashes = {h['type_name']: h['hash_string'] for h in desc['type_hashes']}
    _, rihs = bagio.message_definition(msgtype)
    assert hashes[msgtype] == rihs


def test_refuses_overwrite(tmp_path):
    (tmp_path / 'x').mkdir()
    with pytest.raises(bagio.BagExistsError, match='exists already'):
        bagio.BagWriter(tmp_path / 'x')


def test_recover_unclosed_bag(tmp_path, bag_check):
    """A writer that never closes (as if SIGKILLed): closed splits stay readable, recovery
    salvages the flushed chunks of the active split."""
    w, _ = write_demo(tmp_path / 'killed', close=False)
    bag = tmp_path / 'killed'
    active = list(bag.glob('*.mcap.active'))
    assert len(active) == 1
    # a live writer's bag is never touched by recovery
    assert bagio.bag_in_use(bag) and not bagio.needs_recovery(bag)
    with pytest.raises(bagio.BagError, match='being recorded'):
        bagio.recover_bag(bag)
    w._lock.close()                                   # what the OS does on SIGKILL
    assert not bagio.bag_in_use(bag)
    # what is on disk right now is readable without recovery: the closed splits
    before = bag_check(bag)
    assert 0 < before['/joint_states'] < 600
    # cut the active file mid-record as a kill during a write would
    data = active[0].read_bytes()
    active[0].write_bytes(data[:len(data) - 37])
    assert bagio.needs_recovery(bag)
    report = bagio.recover_bag(bag)
    assert report.salvaged_files == [active[0].name[:-len('.active')]]
    assert report.metadata_rebuilt and report.problems
    after = bag_check(bag)
    assert before['/joint_states'] < after['/joint_states'] <= 600
    assert not bagio.needs_recovery(bag)
    assert bagio.recover_bag(bag).metadata_rebuilt is False    # idempotent


def test_recover_rebuilds_missing_metadata(tmp_path, bag_check, capsys):
    write_demo(tmp_path / 'm')
    (tmp_path / 'm' / 'metadata.yaml').unlink()
    assert bagio.recover_bag(tmp_path / 'm').metadata_rebuilt
    assert bag_check(tmp_path / 'm')['/joint_states'] == 600
    # a reader meeting such a bag recovers it itself and says so
    (tmp_path / 'm' / 'metadata.yaml').unlink()
    assert len(bagio.read_messages(tmp_path / 'm')['/joint_states'].t_ns) == 600
    assert 'recovered (left by a killed recorder)' in capsys.readouterr().err
    empty = tmp_path / 'empty'
    empty.mkdir()
    with pytest.raises(bagio.BagError, match='no metadata.yaml'):
        bagio.read_messages(empty)


def test_clear_errors(tmp_path, bag_check):
    with pytest.raises(bagio.BagError, match='does not exist'):
        bagio.read_messages(tmp_path / 'nope')
    write_demo(tmp_path / 'ok')
    bag_check(tmp_path / 'ok')
    with pytest.raises(bagio.BagError, match=r"\['/torque_command'\] not recorded"):
        bagio.read_messages(tmp_path / 'ok', ['/joint_states', '/torque_command'])
    # corrupt: flip bytes in the middle of a split file
    bad = tmp_path / 'bad'
    shutil.copytree(tmp_path / 'ok', bad)
    f = bad / 'ok_1.mcap'
    data = bytearray(f.read_bytes())
    data[len(data) // 2:len(data) // 2 + 64] = b'\xff' * 64
    f.write_bytes(bytes(data))
    with pytest.raises(bagio.BagError, match=r'bag .*bad: ok_1.mcap is damaged'):
        bagio.read_messages(bad)
    # truncated: a split cut in half
    trunc = tmp_path / 'trunc'
    shutil.copytree(tmp_path / 'ok', trunc)
    f = trunc / 'ok_2.mcap'
    f.write_bytes(f.read_bytes()[:f.stat().st_size // 2])
    with pytest.raises(bagio.BagError, match=r'bag .*trunc: ok_2.mcap is .*truncated'):
        bagio.read_messages(trunc)
    for reader in (bagio.bag_info, bagio.bag_topics, lambda p: list(bagio.iter_messages(p)),
                   bagio.verify_bag):
        with pytest.raises(bagio.BagError, match='trunc: ok_2.mcap'):
            reader(trunc)


def _no_crc_bag(path, n=500):
    """A bag written by a plain MCAP writer without any CRC (other tools do that)."""
    from mcap.writer import CompressionType, Writer
    info = bagio.TopicInfo.for_type('/p', 'geometry_msgs/msg/PointStamped', [])
    path.mkdir()
    with open(path / 'x_0.mcap', 'wb') as f:
        w = Writer(f, chunk_size=2048, compression=CompressionType.NONE, enable_crcs=False,
                   enable_data_crcs=False)
        w.start(profile='ros2', library='test')
        sid = w.register_schema(info.msgtype, 'ros2msg', info.msgdef.encode())
        cid = w.register_channel('/p', 'cdr', sid, {})
        for k in range(n):
            w.add_message(cid, 10**9 + k * 4_032_000, point_stamped(k), 10**9 + k * 4_032_000)
        w.finish()
    bagio.write_metadata(path, bagio.metadata_dict(
        [bagio.FileStats('x_0.mcap', 10**9, 10**9 + (n - 1) * 4_032_000, n)], [info],
        {'/p': n}))
    return path


def test_crc_status_is_what_it_is(tmp_path):
    """present and valid / absent / invalid: a bag without CRCs is never 'valid'; 16 flipped
    bytes are an error in every reader; so is a bag whose counts disagree."""
    write_demo(tmp_path / 'ok')
    ok = bagio.check_bag(tmp_path / 'ok')
    assert ok.crc == 'valid' and ok.messages == 600 + 200 + 29
    assert 'CRCs present and valid' in ok.describe()
    plain = bagio.check_bag(_no_crc_bag(tmp_path / 'plain'))
    assert plain.crc == 'absent' and plain.messages == 500
    assert 'no CRCs' in plain.describe() and 'valid' not in plain.describe()
    # 16 bytes flipped inside a chunk of a bag with CRCs
    bad = tmp_path / 'flip'
    shutil.copytree(tmp_path / 'ok', bad)
    f = sorted(bad.glob('*.mcap'))[1]
    data = bytearray(f.read_bytes())
    for i in range(16):
        data[200 + 37 * i] ^= 0x5A
    f.write_bytes(bytes(data))
    for reader in (bagio.check_bag, bagio.read_messages, bagio.bag_info):
        with pytest.raises(bagio.BagError, match=f'flip: {f.name} is damaged'):
            reader(bad)
    # a bag without CRCs whose structure is damaged: counts disagree -> error
    broken = _no_crc_bag(tmp_path / 'broken')
    meta = broken / 'metadata.yaml'
    meta.write_text(meta.read_text().replace('message_count: 500', 'message_count: 501'))
    with pytest.raises(bagio.BagError, match='metadata.yaml says 501'):
        bagio.read_messages(broken)


def test_size_split_and_flush_period(tmp_path):
    """Splits close by size (not by time unless asked); the open chunk is written out every
    flush_period_s, so what a kill leaves is salvageable up to then."""
    clock = [0.0]
    w = bagio.BagWriter(tmp_path / 's', max_bytes=20_000, clock=lambda: clock[0],
                        flush_period_s=0.1, chunk_size=1 << 20)
    w.add_topic(bagio.TopicInfo.for_type('/p', 'geometry_msgs/msg/PointStamped', []))
    for k in range(1000):
        clock[0] = k * 0.004
        w.write('/p', 10**9 + k * 4_032_000, point_stamped(k))
        w.tick()
    sizes = len(point_stamped(0))
    assert len(w.files) == (1000 * sizes) // 20_000       # closed by size only
    active = next((tmp_path / 's').glob('*.active'))
    w._lock.close()                                       # as after SIGKILL
    rep = bagio.recover_bag(tmp_path / 's')
    assert rep.salvaged_files == [active.name[:-len('.active')]]
    got = bagio.read_messages(tmp_path / 's')['/p'].t_ns
    # every message older than 0.1 s of writer clock survived the "kill"
    assert len(got) >= 1000 - 0.1 / 0.004 - 1
    assert got == sorted(got) and got[0] == 10**9


def test_iter_messages_is_time_ordered_across_splits_and_agrees_with_rosbags(tmp_path):
    """The chunk-index reader of iter_messages (replay's source): the same messages as
    rosbags' reader, each once, in log-time order also where split files and chunks overlap
    in time (log times up to 20 ms out of order, splits every 0.4 s, small chunks)."""
    import random
    from rosbags.rosbag2 import Reader
    rng = random.Random(3)
    clock = [0.0]
    with bagio.BagWriter(tmp_path / 'o', split_period_s=0.4, chunk_size=1024,
                         clock=lambda: clock[0]) as w:
        for t in ('/a', '/b'):
            w.add_topic(bagio.TopicInfo.for_type(t, 'geometry_msgs/msg/PointStamped', []))
        for k in range(1500):
            clock[0] = k * 0.004
            w.write('/a' if k % 3 else '/b', T0 + k * 4_032_000 + rng.randint(-20, 20) * 10**6,
                    point_stamped(k))
            w.tick()
    got = list(bagio.iter_messages(tmp_path / 'o'))
    with Reader(tmp_path / 'o') as r:
        ref = [(c.topic, c.msgtype, t, bytes(d)) for c, t, d in r.messages()]
    assert sorted(got) == sorted(ref) and len(got) == 1500
    ts = [m[2] for m in got]
    assert all(a <= b for a, b in zip(ts, ts[1:]))
