"""recorder and replay in-process (private Context), and the recorder under SIGKILL."""
import signal
import subprocess
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from irb_identification import bagio  # noqa: E402
from irb_identification.offline_sim import SimConfig, run_experiments  # noqa: E402
from irb_identification.recorder_node import RecorderNode  # noqa: E402
from irb_identification.replay_node import ReplayNode  # noqa: E402
from irb_identification.series import read_joint_series  # noqa: E402
from irb_description.output_lines import popen_lines  # noqa: E402

pytestmark = pytest.mark.ros
CONFIG = Path(__file__).resolve().parents[1] / 'config'


def spin_until(executor, cond, timeout=30.0):
    """spin_once until cond() or timeout; returns cond()."""
    end = time.monotonic() + timeout
    while not cond() and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    return cond()


def joint_state(k):
    m = JointState()
    m.header.stamp.sec, m.header.stamp.nanosec = 1000 + k // 248, (k % 248) * 4_032_000
    m.name = ['joint_1', 'joint_2', 'joint_3']
    m.position = [float(k), 0.5, -0.5]
    m.velocity = [0.1, 0.2, 0.3]
    m.effort = [1.0, 2.0, float(k)]
    return m


def params(**kw):
    from rclpy.parameter import Parameter
    return [Parameter(k, value=v) for k, v in kw.items()]


def test_config_matches_declared_defaults(ctx, tmp_path):
    """config/*.yaml carries the same values the nodes declare."""
    context, _ = ctx
    rec = RecorderNode(context=context, parameter_overrides=params(
        root=str(tmp_path), name='cfg'))
    conf = yaml.safe_load((CONFIG / 'recorder.yaml').read_text())['recorder']['ros__parameters']
    for k, v in conf.items():
        if k not in ('root', 'name'):
            assert rec.get_parameter(k).value == v or list(rec.get_parameter(k).value) == v, k
    rec.close()
    rec.destroy_node()
    conf = yaml.safe_load((CONFIG / 'replay.yaml').read_text())['replay']['ros__parameters']
    assert set(conf) >= {'bag', 'rate', 'clock', 'topics'}
    from irb_identification.experiments import ExperimentsNode
    exp = ExperimentsNode(context=context)
    conf = yaml.safe_load((CONFIG / 'experiments.yaml').read_text())['experiments'][
        'ros__parameters']
    for k, v in conf.items():
        got = exp.get_parameter(k).value
        assert (list(got) if isinstance(got, (list, tuple)) or hasattr(got, 'tolist')
                else got) == v, k
    exp.destroy_node()


def test_experiments_offline_then_identify(tmp_path, bag_check, domain_id):
    """The experiments executable (offline) writes one bag per run; identify reads them."""
    from irb_identification import experiments, identify
    rc = experiments.main(['--ros-args', '-p', f'root:={tmp_path}', '-p', 'prefix:=e',
                           '-p', 'joints:=[joint_2]', '-p', 'speeds_rad_s:=[0.1, 0.5, 1.0, 1.5]'])
    assert rc == 0
    bags = sorted(tmp_path.glob('e_joint_2_*'))
    assert [b.name for b in bags] == ['e_joint_2_0p1000', 'e_joint_2_0p5000',
                                      'e_joint_2_1p0000', 'e_joint_2_1p5000']
    for b in bags:
        bag_check(b, decode_limit=20)
    out = tmp_path / 'map.yaml'
    assert identify.main(sum((['--bag', str(b)] for b in bags), [])
                         + ['--out', str(out), '--no-plots']) == 2     # joints 1, 3 missing
    from irb_description.friction import load_friction_map
    assert load_friction_map(out).joint_names == ('joint_2',)


def test_record_then_replay_round_trip(ctx, tmp_path, bag_check):
    """Publish JointState + PointStamped, record raw, then replay the bag (rate 0 and 2) and
    record the replay again: identical payloads, with /clock."""
    from geometry_msgs.msg import PointStamped
    from rosgraph_msgs.msg import Clock
    context, executor = ctx
    tag = uuid.uuid4().hex[:8]
    js_topic, cam_topic = f'/js_{tag}', f'/cam_{tag}'
    pub_node = rclpy.create_node(f'pub_{tag}', context=context)
    be = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    pub = pub_node.create_publisher(JointState, js_topic, be)
    cam = pub_node.create_publisher(PointStamped, cam_topic, 10)
    rec = RecorderNode(context=context, parameter_overrides=params(
        root=str(tmp_path), name='live', topics=[js_topic, cam_topic, '/never_published'],
        progress_period_s=0.5, split_period_s=0.3))
    executor.add_node(pub_node)
    executor.add_node(rec)
    assert spin_until(executor, lambda: pub.get_subscription_count() > 0
                      and cam.get_subscription_count() > 0), 'recorder did not subscribe'
    sent = 0

    def tick():
        nonlocal sent
        pub.publish(joint_state(sent))
        if sent % 10 == 0:
            p = PointStamped()
            p.point.x = float(sent)
            cam.publish(p)
        sent += 1
    timer = pub_node.create_timer(1 / 248, tick)
    assert spin_until(executor, lambda: rec.writer.counts.get(js_topic, 0) >= 300)
    timer.cancel()
    n_js = rec.writer.counts[js_topic]
    # let in-flight messages arrive (bounded, condition-based)
    spin_until(executor, lambda: rec.writer.counts[js_topic] >= sent, timeout=2.0)
    with pytest.raises(bagio.BagExistsError):
        RecorderNode(context=context, parameter_overrides=params(
            root=str(tmp_path), name='live', topics=[js_topic]))
    executor.remove_node(rec)
    rec.close()
    rec.destroy_node()
    counts = bag_check(tmp_path / 'live')
    assert counts[js_topic] >= n_js >= 300 and counts[cam_topic] >= 25
    assert len(yaml.safe_load((tmp_path / 'live' / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']['relative_file_paths']) >= 2
    series = read_joint_series(tmp_path / 'live', js_topic)
    ks = series.position[:, 0]
    assert np.all(np.diff(ks) > 0)             # in order, no duplicates
    np.testing.assert_allclose(series.effort[:, 2], ks)
    qos = bagio.topic_qos(tmp_path / 'live')[js_topic]
    assert qos[0]['reliability'] == 'best_effort'

    # --- replay into a second recorder, as fast as possible, with /clock
    rec2 = RecorderNode(context=context, parameter_overrides=params(
        root=str(tmp_path), name='replayed', topics=[js_topic, '/clock'],
        types=['sensor_msgs/msg/JointState', 'rosgraph_msgs/msg/Clock'],
        progress_period_s=0.0))
    clocks = []
    pub_node.create_subscription(Clock, '/clock', clocks.append, 100)
    player = ReplayNode(context=context, parameter_overrides=params(
        bag=str(tmp_path / 'live'), rate=0.0, clock=True, topics=[js_topic],
        wait_for_subscribers=1, start_delay_s=0.3))
    executor.add_node(rec2)
    executor.add_node(player)
    # both /clock readers (rec2 and this test's) matched before playing: at rate 0 the bag
    # is over in well under a second, less than discovery takes on a loaded machine
    assert spin_until(executor, lambda: player.clock_pub.get_subscription_count() >= 2), \
        'the /clock readers did not match'
    import threading
    th = threading.Thread(target=player.run)
    th.start()
    total = counts[js_topic]
    got = spin_until(executor, lambda: rec2.writer.counts[js_topic] >= total, timeout=30)
    th.join(timeout=30)
    assert player.stats.messages == total
    executor.remove_node(rec2)
    rec2.close()
    assert got, f'replayed {rec2.writer.counts[js_topic]} of {total}'
    live = bagio.read_messages(tmp_path / 'live', [js_topic])[js_topic]
    stamps = [c.clock.sec * 10**9 + c.clock.nanosec for c in clocks]
    assert stamps and live.t_ns[0] <= stamps[0] and stamps[-1] <= live.t_ns[-1]
    assert np.all(np.diff(stamps) >= 10_000_000)           # 100 Hz of bag time
    a = live.data
    b = bagio.read_messages(tmp_path / 'replayed', [js_topic])[js_topic].data
    assert a == b                              # raw bytes survive record -> replay -> record
    bag_check(tmp_path / 'replayed')
    for n in (player, rec2, pub_node):
        n.destroy_node()


def test_replay_rate_timing(ctx, tmp_path, model, bag_check):
    """rate 2 plays a 1.2 s bag in about 0.6 s of wall time."""
    context, executor = ctx
    from irb_identification.profiles import ConstantVelocityProfile
    import irb_identification.offline_sim as osim
    prof = ConstantVelocityProfile(0.5, 8.0, 0.3, settle_s=0.1)
    run = osim.simulate(model, model.friction, prof, 0)
    bag = osim.write_run_bag(run, tmp_path / 'sim', model.joint_names)
    bag_check(bag)
    player = ReplayNode(context=context, parameter_overrides=params(
        bag=str(bag), rate=2.0, start_delay_s=0.0))
    player.run()
    s = player.stats
    assert s.messages == len(run.t)
    assert s.wall_s == pytest.approx(s.bag_span_s / 2, abs=0.1)
    player.destroy_node()
    # asked to wait for a subscriber nobody provides: plays after the bound and says so;
    # rate 0 given as an integer, as a user types rate:=0
    player = ReplayNode(context=context, parameter_overrides=params(
        bag=str(bag), rate=0, start_delay_s=0.0, wait_for_subscribers=1,
        wait_timeout_s=0.3, topics=['/joint_states']))
    said = []

    class Log:
        def info(self, m):
            pass

        def warning(self, m):
            said.append(m)
    player.get_logger = Log
    assert player.rate == 0.0 and isinstance(player.get_parameter('rate').value, float)
    player.run()
    assert player.stats.messages == len(run.t)
    assert any('playing anyway after wait_timeout_s = 0.3 s: /joint_states has 0 of 1'
               in m for m in said), said
    player.destroy_node()
    with pytest.raises(bagio.BagError, match='not recorded'):
        ReplayNode(context=context, parameter_overrides=params(bag=str(bag),
                                                               topics=['/nope']))


def _recorder_cmd(root, name, topic, *extra):
    from ament_index_python.packages import get_package_prefix
    exe = Path(get_package_prefix('irb_identification')) / 'lib' / 'irb_identification' / \
        'recorder'
    return [str(exe), '--ros-args', '-p', f'root:={root}', '-p', f'name:={name}',
            '-p', f'topics:=[{topic}]', '-p', 'types:=[sensor_msgs/msg/JointState]',
            '-r', f'__node:=rec_{uuid.uuid4().hex[:6]}', *extra]


@pytest.mark.slow
def test_sigkill_loses_at_most_a_tenth_of_a_second(ctx, tmp_path, bag_check, capsys):
    """A recorder process killed with SIGKILL: its bag (one open split: splits close by size)
    holds everything published up to 0.1 s (flush_period_s) + 0.15 s (delivery on a loaded
    machine) before the kill; a reader recovers it by itself and says so; the next start
    refuses to overwrite the bag."""
    context, executor = ctx
    tag = uuid.uuid4().hex[:8]
    topic = f'/js_kill_{tag}'
    node = rclpy.create_node(f'killpub_{tag}', context=context)
    pub = node.create_publisher(JointState, topic, 100)
    executor.add_node(node)
    proc = popen_lines(_recorder_cmd(tmp_path, 'killed', topic))
    try:
        assert spin_until(executor, lambda: pub.get_subscription_count() > 0, 60), \
            'recorder did not subscribe'
        sent_at = []

        def tick():
            pub.publish(joint_state(len(sent_at)))
            sent_at.append(time.monotonic())
        node.create_timer(1 / 248, tick)
        assert spin_until(executor, lambda: len(sent_at) and sent_at[-1] - sent_at[0] > 3.0,
                          30)
        proc.send_signal(signal.SIGKILL)
        killed_at = time.monotonic()
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    bag = tmp_path / 'killed'
    assert list(bag.glob('*.mcap.active')), 'expected an unfinished split'
    ks = read_joint_series(bag, topic).position[:, 0].astype(int)
    assert 'recovered (left by a killed recorder)' in capsys.readouterr().err
    assert not list(bag.glob('*.mcap.active'))
    counts = bag_check(bag)
    must_have = sum(1 for t in sent_at if t < killed_at - 0.25)
    assert ks.max() + 1 >= must_have, (ks.max(), must_have, len(sent_at))
    assert np.all(np.diff(ks) == 1) and ks[0] == 0 and counts[topic] == len(ks)
    again = subprocess.run(_recorder_cmd(tmp_path, 'killed', topic), capture_output=True,
                           text=True, timeout=60)
    assert again.returncode == 1 and 'exists already' in again.stderr
    node.destroy_node()


def test_offline_experiment_bags_replayable(tmp_path, model, bag_check):
    bags = run_experiments(model, model.friction, [2], [0.5], tmp_path, log=lambda s: None,
                           config=SimConfig())
    assert bag_check(bags[0])['/joint_states'] > 100


def test_topic_seen_first_through_a_subscriber_is_recorded_once_published(
        ctx, tmp_path, bag_check):
    """Only a subscriber exists when the recorder starts; the best-effort publisher comes
    later. The recorder must wait for it and match its QoS (a reliable guess never would)."""
    context, executor = ctx
    tag = uuid.uuid4().hex[:8]
    topic = f'/late_{tag}'
    be = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    other = rclpy.create_node(f'other_{tag}', context=context)
    other.create_subscription(JointState, topic, lambda m: None, be)
    rec = RecorderNode(context=context, parameter_overrides=params(
        root=str(tmp_path), name='late', topics=[topic], discovery_period_s=0.1))
    executor.add_node(other)
    executor.add_node(rec)
    assert spin_until(executor, lambda: rec.count_subscribers(topic) >= 1
                      and len(other.get_subscriptions_info_by_topic(topic)) >= 1)
    spin_until(executor, lambda: topic in rec.subs, timeout=1.0)   # give discovery a chance
    assert topic not in rec.subs, 'subscribed before any publisher existed'
    pub = other.create_publisher(JointState, topic, be)
    assert spin_until(executor, lambda: pub.get_subscription_count() >= 2)
    timer = other.create_timer(1 / 248, lambda: pub.publish(joint_state(0)))
    assert spin_until(executor, lambda: rec.writer.counts.get(topic, 0) >= 20)
    timer.cancel()
    executor.remove_node(rec)
    rec.destroy_node()
    other.destroy_node()
    bag_check(tmp_path / 'late')


def test_loss_ledger_tracks_publishers_and_names_holes():
    """Pure: sequence holes per topic, when seen; two publishers on one topic are two tracks;
    a publisher first seen at n > 1 (it published before the recorder) is noted, not lost."""
    from irb_identification.recorder_node import LossLedger
    said = []
    led = LossLedger(log=said.append)
    for s in (1, 2, 3, 7, 8):
        led.see('/a', s, s * 10)
    assert led.lost == {'/a': 3} and led.holes['/a'] == [(70, 4, 6)]
    assert said == ['/a: 3 message(s) lost before the recorder got them (publisher sequence '
                    '4..6, noticed at log time 0.000 s)']
    for s in (1, 1, 2, 2, 3, 3):                       # two publishers in step
        led.see('/b', s, 0)
    led.see('/c', 40, 0)                               # joined late
    led.see('/c', 41, 0)
    assert '/b' not in led.lost and '/c' not in led.lost
    d = led.as_dict()
    assert d['lost_total'] == 3 and d['first_sequence_seen']['/c'] == [40]


def test_recorder_keeps_every_message_of_seven_topics_at_248_hz(ctx, tmp_path, bag_check):
    """7 topics at 248 Hz for 3 s into an in-process recorder: every message, once, in order
    of its publisher's count (k in the payload, checked with the mcap reader) and numbered
    1..N in the MCAP sequence field; nothing reported lost; a latched topic published before
    the recorder existed is in the bag too."""
    from mcap.reader import make_reader
    from rclpy.qos import DurabilityPolicy, HistoryPolicy
    from std_msgs.msg import String
    context, executor = ctx
    tag = uuid.uuid4().hex[:8]
    topics = [f'/seven_{tag}_{i}' for i in range(7)]
    node = rclpy.create_node(f'seven_{tag}', context=context)
    state = QoSProfile(depth=250, reliability=ReliabilityPolicy.RELIABLE,
                       history=HistoryPolicy.KEEP_LAST)
    pubs = [node.create_publisher(JointState, t, state) for t in topics]
    latched_topic = f'/latched_{tag}'
    latched = node.create_publisher(String, latched_topic, QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    latched.publish(String(data='urdf'))
    executor.add_node(node)
    rec = RecorderNode(context=context, parameter_overrides=params(
        root=str(tmp_path), name='seven', topics=[*topics, latched_topic],
        discovery_period_s=0.1, progress_period_s=0.0))
    executor.add_node(rec)
    assert spin_until(executor, lambda: all(p.get_subscription_count() for p in pubs)
                      and latched_topic in rec.subs)
    n_ticks = 744                                     # 3 s at 248 Hz
    sent = [0]

    def tick():
        if sent[0] < n_ticks:
            m = joint_state(sent[0])
            for p in pubs:
                p.publish(m)
            sent[0] += 1
    timer = node.create_timer(1 / 248, tick)
    assert spin_until(executor, lambda: all(rec.counts.get(t, 0) >= n_ticks for t in topics)
                      and rec.counts.get(latched_topic, 0) == 1, timeout=60)
    timer.cancel()
    executor.remove_node(rec)
    rec.close()
    rec.destroy_node()
    bag = tmp_path / 'seven'
    counts = bag_check(bag)
    assert all(counts[t] == n_ticks for t in topics) and counts[latched_topic] == 1
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['custom_data']['lost_messages'] == '0'
    assert not (bag / 'losses.yaml').exists()
    from mcap_ros2.decoder import DecoderFactory
    ks, seqs = {t: [] for t in topics}, {t: [] for t in topics}
    for rel in info['relative_file_paths']:
        with open(bag / rel, 'rb') as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for _, ch, msg, ros in reader.iter_decoded_messages(topics=topics):
                ks[ch.topic].append(int(ros.position[0]))
                seqs[ch.topic].append(msg.sequence)
    for t in topics:
        assert sorted(ks[t]) == list(range(n_ticks)), t
        assert sorted(seqs[t]) == list(range(1, n_ticks + 1)), t
    node.destroy_node()


def test_recorder_on_sim_time_subscribes_before_the_clock_runs(ctx, tmp_path):
    """use_sim_time and no /clock yet (a recorder started before the simulator): topics that
    appear are still subscribed (discovery runs on the wall clock), and the log time is the
    simulated time of the latest /clock."""
    from rosgraph_msgs.msg import Clock
    from rclpy.parameter import Parameter
    context, executor = ctx
    tag = uuid.uuid4().hex[:8]
    topic = f'/simtime_{tag}'
    rec = RecorderNode(context=context, parameter_overrides=[
        *params(root=str(tmp_path), name='sim', topics=[topic], discovery_period_s=0.1,
                progress_period_s=0.0), Parameter('use_sim_time', value=True)])
    executor.add_node(rec)
    node = rclpy.create_node(f'simpub_{tag}', context=context)
    pub = node.create_publisher(JointState, topic, 10)
    clock = node.create_publisher(Clock, '/clock', 10)
    executor.add_node(node)
    assert spin_until(executor, lambda: topic in rec.subs, 15.0), 'not subscribed'
    assert spin_until(executor, lambda: pub.get_subscription_count() >= 1)
    c = Clock()
    c.clock.sec = 5000
    got = lambda: rec.counts.get(topic, 0) >= 1  # noqa: E731
    end = time.monotonic() + 15
    while not got() and time.monotonic() < end:     # /clock first, then the message
        clock.publish(c)
        executor.spin_once(timeout_sec=0.02)
        if rec._taker.sim_ns == 5000 * 10**9:
            pub.publish(joint_state(0))
    assert got()
    executor.remove_node(rec)
    rec.close()
    rec.destroy_node()
    t = bagio.read_messages(tmp_path / 'sim', [topic])[topic].t_ns
    assert t[0] == 5000 * 10**9
    node.destroy_node()
