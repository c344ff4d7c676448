"""identifier node (issue 21): replay -> identifier gives the offline identify's map.

In-process: private Context, replay and identifier in one executor, replay's player in its
thread; every wait is on a condition with a generous bound (no sleeps). Oracle for the map:
the offline `identify` on the same bag (a separate reader path: rosbags + the vectorised
decoder), which must agree within 1e-9 when every message arrived.
"""
import json
import threading
import time
import uuid

import numpy as np
import pytest
from irb_description.friction import load_friction_map

rclpy = pytest.importorskip('rclpy')
from rclpy.parameter import Parameter  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from irb_description.output_lines import OutputLines  # noqa: E402
from irb_identification import identify  # noqa: E402
from irb_identification.bagio import BagWriter, TopicInfo, qos_profile_dict  # noqa: E402
from irb_identification.identifier_node import IdentifierNode  # noqa: E402
from irb_identification.offline_sim import SimConfig, simulate  # noqa: E402
from irb_identification.profiles import ConstantVelocityProfile  # noqa: E402
from irb_identification.replay_node import ReplayNode  # noqa: E402
from irb_identification.series import JOINT_STATE, encode_joint_states  # noqa: E402
from irb_identification.stream import StreamConfig, StreamIdentifier, replay_status  # noqa

pytestmark = pytest.mark.ros
SPEEDS = (0.4, 0.6, 0.9, 1.3, 1.8)


def params(**kw):
    return [Parameter(k, value=v) for k, v in kw.items()]


def spin_until(executor, cond, timeout=60.0):
    end = time.monotonic() + timeout
    while not cond() and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    return cond()


@pytest.fixture(scope='module')
def sweep_bag(model, tmp_path_factory):
    """One bag: eq. 4.1 on joint_3 at five speeds back to back (offline plant, noise), like
    a recorder of a whole identification session: 248 Hz, best effort."""
    cfg = SimConfig(velocity_noise=0.002, effort_noise=0.5, seed=5)
    parts, t0 = [], 0.0
    for c in SPEEDS:
        run = simulate(model, model.friction,
                       ConstantVelocityProfile.for_speed(c, stroke_rad=0.4), 2, config=cfg)
        parts.append((run.t + t0, run.q, run.qd, run.tau))
        t0 += run.t[-1] + 0.004032
    t, q, qd, tau = (np.concatenate([p[k] for p in parts]) for k in range(4))
    path = tmp_path_factory.mktemp('ident') / 'session'
    t_ns = 1_700_000_000 * 10**9 + np.round(t * 1e9).astype(np.int64)
    payloads = encode_joint_states(t_ns, list(model.joint_names), q, qd, tau)
    clock = [0.0]
    with BagWriter(path, split_period_s=2.0, clock=lambda: clock[0]) as w:
        w.add_topic(TopicInfo.for_type('/joint_states', JOINT_STATE,
                                       [qos_profile_dict('best_effort', depth=1)]))
        for tk, ns, data in zip(t, t_ns, payloads):
            clock[0] = float(tk)
            w.write('/joint_states', int(ns), data)
    return path, len(t), float(t[-1])


@pytest.fixture(scope='module')
def offline_map(sweep_bag, tmp_path_factory):
    out = tmp_path_factory.mktemp('offline') / 'map.yaml'
    assert identify.main(['--bag', str(sweep_bag[0]), '--out', str(out), '--no-plots',
                          '--joints', 'joint_3']) == 0
    return load_friction_map(out)


def _pair(context, executor, bag, tmp_path, rate, **ident_kw):
    out = tmp_path / f'map_{rate:g}.yaml'
    ident = IdentifierNode(context=context, parameter_overrides=params(
        out_map=str(out), quiet_period_s=5.0, progress_period_s=0.0, joints=['joint_3'],
        **ident_kw))
    player = ReplayNode(context=context, parameter_overrides=params(
        bag=str(bag), rate=float(rate), wait_for_subscribers=1, wait_timeout_s=30.0,
        reliable=True, depth=20000, start_delay_s=0.0))
    executor.add_node(ident)
    executor.add_node(player)
    thread = threading.Thread(target=player.run, daemon=True)
    thread.start()
    return ident, player, thread, out


@pytest.mark.slow
@pytest.mark.parametrize('rate', [1.0, 10.0, 0.0])
def test_replay_into_identifier_gives_the_offline_map(ctx, sweep_bag, offline_map, tmp_path,
                                                      rate):
    context, executor = ctx
    bag, n_msgs, span = sweep_bag
    ident, player, thread, out = _pair(context, executor, bag, tmp_path, rate)
    latched = []
    sub = ident.create_subscription(
        __import__('std_msgs.msg', fromlist=['String']).String, '/identifier/friction_map',
        lambda m: latched.append(m.data),
        __import__('irb_description.node_main', fromlist=['x']).latched_qos())
    assert spin_until(executor, lambda: ident.outcome is not None and str(out) in latched,
                      timeout=span / max(rate, 1.0) + 90.0)
    thread.join(timeout=10)
    outcome = ident.outcome
    assert outcome.ok, outcome.error
    report = outcome.report
    # nothing lost: the identifier counted what the replay announced and published
    assert report['stream']['received'] == report['stream']['expected'] == n_msgs
    assert report['stream']['complete'] and report['stream']['trigger'] == 'finished'
    assert player.published['/joint_states'] == n_msgs
    got = load_friction_map(out)
    assert got.joint_names == offline_map.joint_names
    for a, b in zip(got.joints, offline_map.joints):
        for key in ('coulomb', 'static', 'stribeck_velocity', 'viscous'):
            assert getattr(a, key) == pytest.approx(getattr(b, key), abs=1e-9), key
        assert (a.polynomial_positive is None) == (b.polynomial_positive is None)
        if a.polynomial_positive is not None:
            np.testing.assert_allclose(a.polynomial_positive, b.polynomial_positive,
                                       atol=1e-9)
        np.testing.assert_allclose(a.torque(np.linspace(-2, 2, 41)),
                                   b.torque(np.linspace(-2, 2, 41)), atol=1e-9)
        assert a.valid_range == pytest.approx(b.valid_range, abs=1e-12)
    assert report['joints']['joint_3']['method'] == 'sweep'
    ident.destroy_subscription(sub)
    for node in (ident, player):
        executor.remove_node(node)
        node.destroy_node()


def test_stream_core_bad_inputs(tmp_path, model):
    """Other joint names, no motion, NaN samples, a replay stopped midway: one line each,
    partial only on request and marked partial (the node logs exactly these lines)."""
    def core(**kw):
        return StreamIdentifier(StreamConfig(out_map=str(tmp_path / 'm.yaml'), **kw), model)

    n = 3000
    t_ns = 10**18 + np.arange(n) * 4_032_000
    v = 0.5 * np.sin(np.arange(n) * 0.004032 * 2.0)
    q = np.cumsum(v) * 0.004032
    tf = np.sign(v) * 2 + 0.8 * v
    one = encode_joint_states(t_ns, ['axis'], q[:, None], v[:, None], tf[:, None])
    # other joint names with total torque: refused with the names
    c = core(torque_kind='total')
    for k, d in enumerate(one):
        c.add(d, int(t_ns[k]), 0.0)
    out = c.compute('quiet')
    assert not out.ok and 'axis' in out.error and '--torque-kind friction' in out.error
    assert json.loads((tmp_path / 'm.json').read_text())['error'] == out.error
    # no motion
    c = core(torque_kind='friction')
    still = encode_joint_states(t_ns, ['axis'], q[:, None] * 0, v[:, None] * 0, tf[:, None])
    for k, d in enumerate(still):
        c.add(d, int(t_ns[k]), 0.0)
    out = c.compute('quiet')
    # v_min is relative to the top speed (0 here): the line says so
    assert not out.ok and 'axis: 0 samples above v_min = 0 rad/s' in out.error
    assert '0.02 x the top speed 0 rad/s' in out.error
    assert '|v| seen: 0..0 rad/s' in out.report['joints']['axis']['error']
    # NaN samples are left out and counted; the rest identifies
    bad = v.copy()
    bad[::50] = np.nan
    c = core(torque_kind='friction')
    for k, d in enumerate(encode_joint_states(t_ns, ['axis'], q[:, None], bad[:, None],
                                              tf[:, None])):
        c.add(d, int(t_ns[k]), 0.0)
    out = c.compute('quiet')
    assert out.ok, out.error
    assert out.report['stream']['nan_samples'] == 60
    # a replay stopped midway: announced 3000, got 1000 -> no map unless allowed
    for allow in (False, True):
        c = core(torque_kind='friction', allow_partial=allow)
        c.on_status(replay_status('playing', 'bagX', {'/joint_states': n}))
        for k, d in enumerate(one[:1000]):
            c.add(d, int(t_ns[k]), 1.0)
        c.on_status(replay_status('stopped', 'bagX', {'/joint_states': n},
                                  {'/joint_states': 1000}))
        assert c.due(1.5, publishers=1) == 'stopped'   # every published message arrived
        out = c.compute('stopped')
        if not allow:
            assert not out.ok and 'incomplete stream: received 1000 of the 3000' in out.error
        else:
            assert out.ok and out.report['stream']['partial']
            assert 'PARTIAL' in load_friction_map(tmp_path / 'm.yaml').source


def test_progress_counts_holds_per_joint_and_speed(sweep_bag):
    """Progress while the stream comes in: holds found so far per joint, with their speeds;
    after the whole session joint_3 has its 5 speeds (the profiles', not the code's), one
    hold each way per speed; halfway, fewer. Garbage does not break it."""
    from irb_identification.bagio import iter_messages
    bag, n, _ = sweep_bag
    msgs = [(t, data) for topic, _, t, data in iter_messages(bag) if topic == '/joint_states']
    c = StreamIdentifier(StreamConfig(joints=['joint_3']))
    assert c.segment_progress() == []
    for t, data in msgs[:n // 2]:
        c.add(data, t, 0.0)
    half = c.segment_progress()
    for t, data in msgs[n // 2:]:
        c.add(data, t, 0.0)
    full = c.segment_progress()
    assert len(full) == 1 and full[0].startswith('joint_3: ')
    holds = int(full[0].split(': ')[1].split(' holds')[0])
    assert holds == 2 * len(SPEEDS), full       # one hold each way per speed
    assert full[0].endswith(f"|v| = {', '.join(f'{v:g}' for v in SPEEDS)} rad/s"), full
    assert 0 < int(half[0].split(': ')[1].split(' holds')[0]) < holds, half
    c.add(b'not cdr', 0, 0.0)                 # a message that does not decode: no crash
    assert c.segment_progress() == []


def test_services_compute_and_reset(ctx, tmp_path):
    """~/compute with nothing received: a clear failure, no crash; ~/reset answers."""
    context, executor = ctx
    ident = IdentifierNode(context=context, parameter_overrides=params(
        out_map=str(tmp_path / 'm.yaml'), progress_period_s=0.0, topic='/nobody_here'))
    executor.add_node(ident)
    client = ident.create_client(Trigger, '/identifier/compute')
    assert spin_until(executor, client.service_is_ready, 30.0)
    fut = client.call_async(Trigger.Request())
    assert spin_until(executor, fut.done, 60.0)
    assert not fut.result().success and 'no /nobody_here message' in fut.result().message
    reset = ident.create_client(Trigger, '/identifier/reset')
    assert spin_until(executor, reset.service_is_ready, 30.0)
    fut = reset.call_async(Trigger.Request())
    assert spin_until(executor, fut.done, 30.0) and fut.result().success


def _stream_core(tmp_path, model, n=3000, **kw):
    t_ns = 10**18 + np.arange(n) * 4_032_000
    v = 0.5 * np.sin(np.arange(n) * 0.004032 * 2.0)
    q = np.cumsum(v) * 0.004032
    msgs = encode_joint_states(t_ns, ['axis'], q[:, None], v[:, None],
                               (np.sign(v) * 2 + 0.8 * v)[:, None])
    core = StreamIdentifier(StreamConfig(out_map=str(tmp_path / 'm.yaml'),
                                         torque_kind='friction', **kw), model)
    return core, msgs, t_ns


def test_stream_accounting_never_gives_a_silent_partial_answer(tmp_path, model):
    """The replay announces a count and a stream id, its publisher numbers the messages
    1..N. 'finished' after 3106 of 7500 (the rest still in flight) is not the end while the
    replay's publisher is there; once it is gone the stream is incomplete (no map); what
    arrives late is never a new stream. A hole in the sequence numbers is incomplete even
    when the count matches. A failed replay ends the stream at once with its reason."""
    n = 3000
    core, msgs, t_ns = _stream_core(tmp_path, model, n, quiet_period_s=2.0)
    core.on_status(replay_status('playing', 'bagA', {'/joint_states': n}, stream='s1'))
    for k in range(1106):
        core.add(msgs[k], int(t_ns[k]), 1.0, seq=k + 1)
    core.on_status(replay_status('finished', 'bagA', {'/joint_states': n},
                                 {'/joint_states': n}, stream='s1'))
    assert core.due(100.0, publishers=1) is None      # in flight: wait, whatever the quiet
    assert core.due(100.0, publishers=0) == 'finished'  # the replay is gone: short
    out = core.compute('finished')
    assert not out.ok and 'received 1106 of the 3000' in out.error
    assert not (tmp_path / 'm.yaml').exists()
    for k in range(1106, n):                          # the late rest: not a new stream
        core.add(msgs[k], int(t_ns[k]), 200.0, seq=k + 1)
    assert core.late == n - 1106 and core.due(300.0, publishers=0) is None
    assert not (tmp_path / 'm.yaml').exists()
    # a new playback (new id) starts a new stream; every message: complete, a map
    core.on_status(replay_status('playing', 'bagA', {'/joint_states': n}, stream='s2'))
    for k in range(n):
        core.add(msgs[k], int(t_ns[k]), 400.0, seq=k + 1)
    core.on_status(replay_status('finished', 'bagA', {'/joint_states': n},
                                 {'/joint_states': n}, stream='s2'))
    assert core.due(400.0, publishers=1) == 'finished'
    out = core.compute('finished')
    assert out.ok and out.report['stream']['complete'], out.error
    assert out.report['stream']['sequence'] == {'first': 1, 'last': n, 'missing': 0,
                                                'out_of_order': 0}
    # the count matches but one message is missing and another came twice
    (tmp_path / 'm.yaml').unlink()
    core, msgs, t_ns = _stream_core(tmp_path, model, n)
    core.on_status(replay_status('playing', 'bagB', {'/joint_states': n}, stream='s3'))
    for k in [*range(0, 500), 499, *range(501, n)]:
        core.add(msgs[k], int(t_ns[k]), 1.0, seq=k + 1)
    core.on_status(replay_status('finished', 'bagB', {'/joint_states': n},
                                 {'/joint_states': n}, stream='s3'))
    assert core.due(1.0, publishers=1) == 'finished'
    out = core.compute('finished')
    assert not out.ok and 'sequence numbers have 1 missing, 1 out of order' in out.error
    # a replay that failed (missing or damaged bag): over at once, its reason in the error
    core, msgs, t_ns = _stream_core(tmp_path, model, n)
    core.on_status(replay_status('failed', 'bags/nope', {}, reason='bag bags/nope does not '
                                 'exist', stream='s4'))
    assert core.due(0.0, publishers=0) == 'failed'
    out = core.compute('failed')
    assert not out.ok and out.error == ('replay failed: bag bags/nope does not exist; no map')


def test_several_bags_in_one_stream_are_read_bag_by_bag(tmp_path, model):
    """Two bags played as one stream, 30 s apart: with the replay's segments the identifier
    reads them as two series (as identify reads two bags), so the 30 s between them is no
    'data with gaps'; without segments (an old replay) it is one series and says so; a
    real hole inside a bag is still reported with segments."""
    from irb_identification.stream import split_by_segments
    n = 3000
    core, _, t_ns = _stream_core(tmp_path, model, n)
    t_ns = t_ns.copy()
    t_ns[n // 2:] += 30 * 10**9                         # the second bag, 30 s later
    v = 0.5 * np.sin(np.arange(n) * 0.004032 * 2.0)     # as _stream_core, restamped
    msgs = encode_joint_states(t_ns, ['axis'], (np.cumsum(v) * 0.004032)[:, None],
                               v[:, None], (np.sign(v) * 2 + 0.8 * v)[:, None])
    segs = [{'bag': 'bags/a', 'topics': {'/joint_states': n // 2, '/other': 7}},
            {'bag': 'bags/b', 'topics': {'/joint_states': n - n // 2}}]
    assert split_by_segments(n, segs, '/joint_states') == [('a', 0, n // 2),
                                                           ('b', n // 2, n)]
    assert split_by_segments(n + 1, segs, '/joint_states') == []    # counts must add up

    def run(segments, holes=()):
        core, _, _ = _stream_core(tmp_path, model, n)
        keep = [k for k in range(n) if k not in holes]
        core.on_status(replay_status('playing', 'bags/a', {'/joint_states': len(keep)},
                                     stream='s', segments=segments))
        for j, k in enumerate(keep):
            core.add(msgs[k], int(t_ns[k]), 1.0, seq=j + 1)
        core.on_status(replay_status('finished', 'bags/a', {'/joint_states': len(keep)},
                                     {'/joint_states': len(keep)}, stream='s',
                                     segments=segments))
        out = core.compute('finished')
        assert out.ok, out.error
        return json.dumps(out.report['joints'])

    assert 'data with gaps' not in run(segs)
    assert 'data with gaps' in run([])
    inner = range(200, 260)                             # 60 samples lost inside bag a
    segs_holed = [{'bag': 'bags/a', 'topics': {'/joint_states': n // 2 - len(inner)}},
                  segs[1]]
    text = run(segs_holed, holes=inner)
    assert 'data with gaps' in text and 'bag a' in text and 'bag b' not in text, text


@pytest.mark.slow
def test_processes_replay_as_fast_as_the_identifier_takes(sweep_bag, offline_map, tmp_path,
                                                          domain_id):
    """`ros2 run` processes: replay at rate 0 (as fast as possible) with reliable keep-all
    publishers into the identifier; the slower Python subscriber holds the replay back
    instead of losing messages; the map equals the offline one."""
    import os
    import subprocess
    bag, n_msgs, _ = sweep_bag
    # a domain of its own (70..99; the suite's are 50..69): a subscriber left on /joint_states
    # by another test would satisfy the replay's wait_for_subscribers before the identifier
    env = dict(os.environ, ROS_DOMAIN_ID=str(70 + domain_id % 30), PYTHONUNBUFFERED='1')
    out = tmp_path / 'proc_map.yaml'
    ident = subprocess.Popen(
        ['ros2', 'run', 'irb_identification', 'identifier', '--ros-args', '-p',
         f'out_map:={out}', '-p', 'joints:=[joint_3]', '-p', 'quiet_period_s:=20.0'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
        start_new_session=True)          # the ros2 launcher and the node: one group
    output = OutputLines(ident.stdout)
    try:
        output.wait_for('waiting for publishers', 60)
        replay = subprocess.run(
            ['ros2', 'run', 'irb_identification', 'replay', '--ros-args', '-p', f'bag:={bag}',
             '-p', 'rate:=0', '-p', 'wait_for_subscribers:=1', '-p', 'wait_timeout_s:=120.0'],
            capture_output=True, text=True, env=env, timeout=240)
        assert replay.returncode == 0, replay.stderr
        # the replay played to our subscriber, not into the void after its wait ran out
        assert 'playing anyway' not in replay.stderr, replay.stderr
        try:
            lines = output.wait_for('wrote', 120)
        except AssertionError as exc:     # what the replay saw belongs to the diagnosis
            raise AssertionError(f'{exc}\nreplay said: {replay.stderr[-2000:]}') from None
        assert any(f'{n_msgs} messages received of {n_msgs}' in x for x in lines), lines
        # a replayed stream identified: the identifier exits by itself, 0 (complete, a map)
        assert ident.wait(timeout=60) == 0, output.rest()
    finally:
        if ident.poll() is None:
            os.killpg(ident.pid, __import__('signal').SIGINT)
            ident.wait(timeout=30)
    got = load_friction_map(out)
    for a, b in zip(got.joints, offline_map.joints):
        np.testing.assert_allclose(a.torque(np.linspace(-2, 2, 41)),
                                   b.torque(np.linspace(-2, 2, 41)), atol=1e-9)


@pytest.mark.slow
def test_several_bags_as_one_stream(ctx, model, tmp_path):
    """The main job's pairing: one bag per (joint, speed), replayed with ``bags`` as one
    stream into the identifier: the offline identify's map within its intervals."""
    from irb_identification.offline_sim import write_run_bag
    bags, start = [], 1_700_000_000 * 10**9
    for c in SPEEDS:                 # recorded one after the other: later stamps each
        run = simulate(model, model.friction, ConstantVelocityProfile.for_speed(
            c, stroke_rad=0.4), 2, config=SimConfig(velocity_noise=0.002, effort_noise=0.5,
                                                   seed=9))
        bags.append(write_run_bag(run, tmp_path / f'b_{c}', list(model.joint_names), start))
        start += int(run.t[-1] * 1e9) + 10**9
    off = tmp_path / 'off.yaml'
    assert identify.main(sum((['--bag', str(b)] for b in bags), []) + [
        '--out', str(off), '--no-plots', '--joints', 'joint_3']) == 0
    offline = load_friction_map(off).joints[0]
    context, executor = ctx
    out = tmp_path / 'stream.yaml'
    ident = IdentifierNode(context=context, parameter_overrides=params(
        out_map=str(out), quiet_period_s=5.0, progress_period_s=0.0, joints=['joint_3'],
        fill_nominal=True))
    player = ReplayNode(context=context, parameter_overrides=params(
        bags=[str(b) for b in bags], rate=0.0, wait_for_subscribers=1, reliable=True,
        start_delay_s=0.0))
    executor.add_node(ident)
    executor.add_node(player)
    thread = threading.Thread(target=player.run, daemon=True)
    thread.start()
    assert spin_until(executor, lambda: ident.outcome is not None, 120.0)
    thread.join(timeout=10)
    assert ident.outcome.ok, ident.outcome.error
    stream = ident.outcome.report['stream']
    assert stream['complete'] and stream['received'] == sum(player.counts.values())
    got = load_friction_map(out).joints[0]
    for key in ('coulomb', 'viscous'):
        assert abs(getattr(got, key) - getattr(offline, key)) <= offline.ci95[key], key
    for node in (ident, player):
        executor.remove_node(node)
        node.destroy_node()


def test_missing_bag_fails_the_replay_and_ends_the_identifier(ctx, tmp_path):
    """A replay of a bag that does not exist: one BagError, and a 'failed' status naming it,
    so the identifier ends with that error (exit code 1) instead of waiting forever."""
    from irb_identification.bagio import BagError
    context, executor = ctx
    ident = IdentifierNode(context=context, parameter_overrides=params(
        out_map=str(tmp_path / 'm.yaml'), progress_period_s=0.0))
    executor.add_node(ident)
    assert spin_until(executor, lambda: ident.count_publishers('/replay/status') == 0
                      and ident.count_subscribers('/replay/status') >= 1, 30.0)
    with pytest.raises(BagError, match='nope does not exist'):
        ReplayNode(context=context, parameter_overrides=params(bag=str(tmp_path / 'nope'),
                                                               rate=0))
    assert spin_until(executor, lambda: ident.exit_code is not None, 30.0)
    assert ident.exit_code == 1
    assert ident.outcome.error == f'replay failed: bag {tmp_path / "nope"} does not exist; no map'
    assert not (tmp_path / 'm.yaml').exists()
    executor.remove_node(ident)
    ident.destroy_node()


def test_one_callback_takes_every_waiting_message(ctx):
    """take_waiting: what is queued when the callback runs is taken in that callback, in
    order, each message once (the identifier's throughput behind a reliable replay)."""
    from irb_identification.rosutil import take_waiting
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import UInt32
    context, executor = ctx
    node = rclpy.create_node(f'drain_{uuid.uuid4().hex[:8]}', context=context)
    executor.add_node(node)
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                     history=HistoryPolicy.KEEP_ALL)
    topic = f'/drain_{uuid.uuid4().hex[:8]}'
    got, calls, holder = [], [], {}

    def on_msg(msg):
        calls.append(len(got))
        got.append(msg.data)
        take_waiting(holder['sub'], lambda m: got.append(m.data))
    pub = node.create_publisher(UInt32, topic, qos)
    holder['sub'] = node.create_subscription(UInt32, topic, on_msg, qos)
    assert spin_until(executor, lambda: pub.get_subscription_count() == 1, 30.0)
    for i in range(200):
        pub.publish(UInt32(data=i))
    # published before the executor runs: the first callbacks take what has arrived
    assert spin_until(executor, lambda: len(got) == 200, 30.0)
    assert got == list(range(200))
    assert len(calls) < 200, f'{len(calls)} callbacks for 200 messages'
    node.destroy_node()
