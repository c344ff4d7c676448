"""recorder: record topics into a crash-safe rosbag2 MCAP bag (bags/<name>/), losing nothing
silently.

    ros2 run irb_identification recorder --ros-args -p name:=run1

Every wake of a subscription takes every message waiting in its queue (one executor round
per batch, not per message); the messages go with their log time to a writer thread that does
the MCAP writing, flushing and splitting off the executor. Reliable publishers are read
reliable keep-all. Loss is counted from the publishers' own sequence numbers (DDS
``publication_sequence_number``): a hole is logged when it is seen and, at the end, written
to ``losses.yaml`` in the bag and to metadata.yaml's ``custom_data`` (``lost_messages``).
Log time: the node's clock (the simulated time under ``use_sim_time``, as rosbag2 records).
"""
from __future__ import annotations

import collections
import sys
import threading
import time
from datetime import datetime
from pathlib import Path

from irb_description.node_help import NodeSpec, Param, Topic

DEFAULT_TOPICS = ['/joint_states', '/torque_command', '/controller_state', '/camera/tcp',
                  '/electrical_power', '/tf', '/tf_static', '/robot_description',
                  '/visualization/planned_path', '/visualization/tcp_trace',
                  '/planned_trajectory', '/planned_path', '/pdplus/plan_status']

SPEC = NodeSpec(
    'recorder', 'irb_identification',
    'Record topics into a crash-safe rosbag2-layout MCAP bag <root>/<name>/. Every message '
    'of every subscribed topic is kept; what the middleware lost before the recorder got it '
    "(publishers' sequence numbers) is logged and written to the bag (losses.yaml, "
    'custom_data). Missing topics are waited for. Latched topics are read transient local. '
    'Ctrl-C closes the bag; a SIGKILL loses at most flush_period_s.',
    params=(
        Param('root', '', '', "bag root directory; '' = $IRB_ROOT/bags or ./bags"),
        Param('name', '', '', "bag name; '' = rec_<date>_<time>; never overwritten"),
        Param('topics', list(DEFAULT_TOPICS), '', 'topics to record (missing ones are waited '
              'for)'),
        Param('types', [''], '', "message type per topic ('' = from the graph)"),
        Param('max_bag_size_mib', 100.0, 'MiB', 'close a split file at this size; 0 = one '
              'file'),
        Param('split_period_s', 0.0, 's', 'also close a split file this often; 0 = never'),
        Param('flush_period_s', 0.1, 's', 'write the open chunk out this often (what a '
              'SIGKILL can lose)'),
        Param('chunk_size_kib', 64, 'KiB', 'MCAP chunk size'),
        Param('compression', 'none', '', "'none' or 'zstd' (chunk compression)"),
        Param('queue_depth', 10000, 'messages', 'subscription depth for best-effort '
              'publishers (reliable ones are read keep-all)'),
        Param('discovery_period_s', 0.5, 's', 'look for missing topics this often'),
        Param('progress_period_s', 2.0, 's', 'progress line period; 0 = off'),
        Param('recover_on_start', True, '', 'recover bags in root left incomplete by a killed '
              'recorder'),
    ),
    subscribes=(Topic('<topics>', '(from the graph)', 'raw CDR, QoS matched to the '
                      'publishers'),),
    example='ros2 run irb_identification recorder --ros-args -p name:=run1 '
            "-p topics:='[/joint_states, /torque_command]'",
    notes='Bag: metadata.yaml + <name>_<i>.mcap (readable by ros2 bag, rosbags, mcap, '
          'Foxglove); losses.yaml only when something was lost.')


class LossLedger:
    """Holes in the publishers' sequence numbers, per topic. No rclpy.

    A topic may have several publishers, each numbering its own messages 1, 2, ...; the
    numbers reach the subscriber without the publisher's id, so messages are matched to
    tracks: a number continues the track whose last number is the largest one below it (a
    new track if none is). Exact for one publisher per topic; with several, a hole is given
    to the nearest track."""

    def __init__(self, log=None):
        self.tracks: dict[str, list[int]] = {}
        self.lost: dict[str, int] = {}
        self.holes: dict[str, list[tuple[int, int, int]]] = {}   # (t_ns, first, last) lost
        self.first_seen: dict[str, list[int]] = {}     # first number of each track
        self.log = log

    def see(self, topic: str, seq: int | None, t_ns: int) -> int:
        """Message ``seq`` of ``topic`` received at ``t_ns``; the number lost before it."""
        if not seq:
            return 0
        tracks = self.tracks.setdefault(topic, [])
        if tracks and tracks[-1] == seq - 1:           # the usual case: the same publisher
            tracks[-1] = seq
            return 0
        best = -1
        for i, last in enumerate(tracks):
            if last == seq - 1:
                tracks[i] = seq
                tracks.append(tracks.pop(i))           # most recent track last
                return 0
            if last < seq and (best < 0 or last > tracks[best]):
                best = i
        if best < 0:
            tracks.append(seq)
            self.first_seen.setdefault(topic, []).append(int(seq))
            return 0
        gap = seq - tracks[best] - 1
        first = tracks[best] + 1
        tracks[best] = seq
        self.lost[topic] = self.lost.get(topic, 0) + gap
        self.holes.setdefault(topic, []).append((int(t_ns), first, seq - 1))
        if self.log is not None:
            self.log(f'{topic}: {gap} message(s) lost before the recorder got them '
                     f'(publisher sequence {first}..{seq - 1}, noticed at log time '
                     f'{t_ns * 1e-9:.3f} s)')
        return gap

    @property
    def total(self) -> int:
        return sum(self.lost.values())

    def summary(self) -> str:
        return ', '.join(f'{t} {n}' for t, n in self.lost.items()) or 'none'

    def as_dict(self) -> dict:
        """Losses, and the first sequence number of each publisher (> 1: it published
        before the recorder matched it; not counted as lost)."""
        return {'lost_total': self.total, 'first_sequence_seen': dict(self.first_seen),
                'topics': {
            t: {'lost': self.lost[t], 'holes': [
                {'noticed_at_log_time_ns': h[0], 'publisher_sequence_first': h[1],
                 'publisher_sequence_last': h[2]} for h in self.holes[t]]}
            for t in self.lost}}


class _WriterThread(threading.Thread):
    """Writes queued (topic, t_ns, bytes) to the BagWriter; flushes and splits via tick."""

    def __init__(self, writer, on_error):
        super().__init__(name='bag-writer', daemon=True)
        self.writer = writer
        self.queue = collections.deque()
        self.wake = threading.Event()
        self.stopping = False
        self.on_error = on_error

    def run(self) -> None:
        from .bagio import BagWriteError
        q, w = self.queue, self.writer
        while True:
            self.wake.wait(0.05)
            self.wake.clear()
            try:
                while q:
                    item = q.popleft()
                    if item[0] is None:            # a topic to add, in order with messages
                        w.add_topic(item[2])
                    elif not w.failed:
                        w.write(*item)
                w.tick()
            except BagWriteError as exc:
                self.on_error(exc)
            if self.stopping and not q:
                return


class _TakerThread(threading.Thread):
    """Takes every waiting message of every subscription, round after round, without the
    executor: an executor rebuilds its wait set for every callback (~200 us of CPU here), which
    at 7 topics x 248 Hz (x 2.5 in lockstep) is most of a core. A round that finds nothing
    sleeps ``idle_s``; under load rounds grow, they never fall behind by more than the
    middleware queues hold."""

    def __init__(self, subs: dict, handle, idle_s: float = 0.005, clock_sub=None):
        super().__init__(name='recorder-take', daemon=True)
        self.subs = subs
        self.handle = handle
        self.idle_s = idle_s
        self.stopping = False
        self.rounds = 0
        self.clock_sub = clock_sub
        self.sim_ns = None             # latest /clock [ns] (use_sim_time), None before one

    def _take_clock(self) -> None:
        sub = self.clock_sub
        with sub.handle:
            while True:
                got = sub.handle.take_message(sub.msg_type, True)
                if got is None:
                    return
                self.sim_ns = _clock_ns(got[0])

    def take_round(self, limit: int = 2000) -> int:
        """Every topic in turn: up to ``limit`` waiting messages (the latest /clock first,
        under sim time, so their log time is the time they were taken)."""
        from rclpy.exceptions import InvalidHandle
        n = 0
        for topic, sub in list(self.subs.items()):
            if self.clock_sub is not None:
                self._take_clock()
            try:
                with sub.handle:
                    batch = []
                    while len(batch) < limit:
                        got = sub.handle.take_message(sub.msg_type, True)
                        if got is None:
                            break
                        batch.append(got)
            except InvalidHandle:
                continue
            if batch:
                self.handle(topic, batch)
                n += len(batch)
        self.rounds += 1
        return n

    def run(self) -> None:
        # a round costs ~10 us per topic even when it finds nothing: rounds at most every
        # 2 ms (5 ms when idle); the middleware queues (keep all) hold what comes meanwhile
        while not self.stopping:
            n = self.take_round()
            if n < 100:
                time.sleep(self.idle_s if n == 0 else 0.002)


def _make_node_class():
    from rclpy.node import Node

    class RecorderNode(Node):
        """Subscribes raw to the chosen topics; a writer thread writes the bag."""

        def __init__(self, node_name: str = 'recorder', taps: dict | None = None, **kwargs):
            """``taps`` (in-process use): {topic: callable(bytes)} called with every message
            of that topic when it is taken (the experiments node follows its runs with
            them)."""
            super().__init__(node_name, **kwargs)
            from .bagio import BagWriter
            from .rosutil import declare_params, default_bag_root
            self.taps = dict(taps or {})
            p = declare_params(self, SPEC.params)
            self.p = p
            self.topics = list(p['topics'])
            self.depth = int(p['queue_depth'])
            self.root = Path(p['root']) if p['root'] else default_bag_root()
            self.root.mkdir(parents=True, exist_ok=True)
            if p['recover_on_start']:
                self._recover_leftovers()
            name = p['name'] or datetime.now().strftime('rec_%Y%m%d_%H%M%S')
            self.given_types = {t: ty for t, ty in zip(self.topics, p['types']) if ty}
            self.writer = BagWriter(
                self.root / name, split_period_s=float(p['split_period_s']),
                max_bytes=int(float(p['max_bag_size_mib']) * 2**20),
                flush_period_s=float(p['flush_period_s']),
                chunk_size=int(p['chunk_size_kib']) * 1024, compression=p['compression'],
                custom_data={'recorder': 'irb_identification'})
            self.bag_path = self.writer.path
            self.ledger = LossLedger(log=lambda m: self.get_logger().warning(m))
            self.received: dict[str, int] = {}
            self._failed = ''
            self._thread = _WriterThread(self.writer, self._fail)
            self._thread.start()
            self.subs = {}
            # the subscriptions live on a node no executor spins: the taker thread takes
            # their messages (the clock, timers and discovery stay on this node)
            import rclpy
            self._data_node = rclpy.create_node(
                f'{self.get_name()}_data', namespace=self.get_namespace(),
                context=self.context, start_parameter_services=False,
                enable_rosout=False)
            self._clock = self.get_clock()
            self._sim_time = bool(self.get_parameter('use_sim_time').value)
            clock_sub = None
            if self._sim_time:
                # /clock taken by the taker itself, right before each round: the log time of
                # a message is the simulated time when it was taken (an executor's clock
                # lags by as much as its own backlog on a loaded machine)
                from rclpy.qos import QoSProfile, ReliabilityPolicy
                from rosgraph_msgs.msg import Clock
                clock_sub = self._data_node.create_subscription(
                    Clock, '/clock', _never_called,
                    QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT), raw=True)
            self._taker = _TakerThread(self.subs, self._on_batch, clock_sub=clock_sub)
            self._taker.start()
            self._t0 = time.monotonic()
            self._last = (self._t0, 0)
            self._check_topics()
            # wall-clock timers: under use_sim_time a sim-time timer does not fire before the
            # simulator's /clock runs, and the start of the run would be missed (lockstep:
            # 0.6 s of simulated time at every start, found by bench_recorder)
            from rclpy.clock import Clock, ClockType
            steady = Clock(clock_type=ClockType.STEADY_TIME)
            self.create_timer(float(p['discovery_period_s']), self._check_topics, clock=steady)
            if p['progress_period_s'] > 0:
                self.create_timer(float(p['progress_period_s']), self._progress, clock=steady)
            self.get_logger().info(f'recording {self.topics} into {self.bag_path}')

        def _recover_leftovers(self) -> None:
            from .bagio import BagError, needs_recovery, recover_bag
            for bag in sorted(p for p in self.root.iterdir() if p.is_dir()):
                if list(bag.glob('*.mcap*')) and needs_recovery(bag):
                    try:
                        rep = recover_bag(bag)
                    except (BagError, OSError) as exc:
                        self.get_logger().error(f'not recovered: {bag}: {exc}')
                        continue
                    self.get_logger().warn(
                        f'recovered {bag}: {rep.salvaged_messages} messages salvaged from '
                        f'{rep.salvaged_files}; {"; ".join(rep.problems) or "no problems"}')

        def _check_topics(self) -> None:
            from .bagio import TopicInfo
            from .rosutil import message_class, qos_to_dict, recording_qos
            pending = [t for t in self.topics if t not in self.subs]
            if not pending:
                return
            graph = dict(self.get_topic_names_and_types())
            for topic in pending:
                msgtype = self.given_types.get(topic) or (graph.get(topic) or [None])[0]
                if msgtype is None:
                    continue
                pubs = self.get_publishers_info_by_topic(topic)
                if not pubs:
                    # only subscribers so far: wait for a publisher, whose QoS decides ours
                    # (a reliable guess would never match a best-effort publisher)
                    continue
                info = TopicInfo.for_type(topic, msgtype, [qos_to_dict(e.qos_profile)
                                                           for e in pubs])
                self.received[topic] = 0
                self._thread.queue.append((None, 0, info))
                qos = recording_qos(pubs, self.depth)
                self.subs[topic] = self._data_node.create_subscription(
                    message_class(msgtype), topic, _never_called, qos, raw=True)
                self.get_logger().info(
                    f'subscribed to {topic} [{msgtype}] ({qos.reliability.name.lower()}, '
                    f'{qos.history.name.lower()}, {qos.durability.name.lower()})')

        def _on_batch(self, topic: str, batch: list) -> None:
            """Messages taken from ``topic``'s queue: log time (the node's clock: simulated
            under use_sim_time, read once per batch), loss check, to the writer, taps."""
            if self._sim_time:
                t = self._taker.sim_ns
                if t is None:                  # no /clock yet: the node's clock (0)
                    t = self._clock.now().nanoseconds
            else:
                t = time.time_ns()
            see = self.ledger.see
            queue = self._thread.queue
            tap = self.taps.get(topic)
            for data, info in batch:
                seq = info.get('publication_sequence_number') or 0
                see(topic, seq, t)
                queue.append((topic, t, data, seq))
                if tap is not None:
                    tap(data)
            self.received[topic] += len(batch)
            self._thread.wake.set()

        def _fail(self, exc) -> None:
            """Writing failed (a full disk): one line, stop recording (main exits 1)."""
            self._failed = str(exc)
            try:
                self.get_logger().error(f'recording stopped: {exc}')
            except Exception:  # noqa: BLE001 - logging after shutdown
                print(f'[recorder] recording stopped: {exc}', file=sys.stderr)

        @property
        def failed(self) -> str:
            return self._failed or self.writer.failed

        @property
        def counts(self) -> dict:
            """Messages taken per topic (written or queued for writing)."""
            return self.received

        def _progress(self) -> None:
            now = time.monotonic()
            n = sum(self.received.values())
            rate = (n - self._last[1]) / max(now - self._last[0], 1e-9)
            self._last = (now, n)
            per = ', '.join(f'{t} {c}' for t, c in self.received.items())
            missing = [t for t in self.topics if t not in self.subs]
            self.get_logger().info(
                f'{n} msgs, {rate:.0f} msg/s, {self.writer.bytes_written / 2**20:.2f} MiB, '
                f'{len(self.writer.files) + 1} files, {len(self._thread.queue)} queued, '
                f'lost {self.ledger.total}, {now - self._t0:.0f} s'
                + (f' | {per}' if per else '') + (f' | waiting for {missing}' if missing
                                                  else ''))

        def close(self) -> None:
            """Take what is waiting, write what is queued and the losses (losses.yaml,
            custom_data), close the bag."""
            import yaml
            if self._taker.is_alive():
                self._taker.stopping = True
                self._taker.join()
                # what arrived meanwhile; bounded, a running graph never stops sending
                for _ in range(5):
                    if not self._taker.take_round():
                        break
            self._thread.stopping = True
            self._thread.wake.set()
            self._thread.join()
            lost = self.ledger.as_dict()
            self.writer.custom_data['lost_messages'] = str(self.ledger.total)
            self.writer.custom_data['lost_per_topic'] = self.ledger.summary()
            if self.ledger.total:
                try:
                    (self.bag_path / 'losses.yaml').write_text(
                        yaml.safe_dump(lost, sort_keys=False))
                except OSError as exc:
                    self._fail(f'losses.yaml not written ({exc.strerror or exc})')
            self.writer.close()
            text = (f'closed {self.bag_path}: {self.writer.message_count} messages in '
                    f'{len(self.writer.files)} files; lost before the recorder: '
                    f'{self.ledger.summary()}'
                    + (' (writing had failed: see above)' if self.failed else ''))
            if self.context.ok():
                if self.ledger.total:
                    self.get_logger().warning(text)
                else:
                    self.get_logger().info(text)
            else:                              # after Ctrl-C the rosout publisher is gone
                print(f'[recorder] {text}', file=sys.stderr)

        def destroy_node(self):
            self._taker.stopping = True
            if self._taker.is_alive():
                self._taker.join()
            self._data_node.destroy_node()
            return super().destroy_node()

    return RecorderNode


def _clock_ns(data: bytes) -> int:
    """Time [ns] of a serialized rosgraph_msgs/Clock (CDR header, int32 sec, uint32 nsec)."""
    import struct
    sec, nsec = struct.unpack_from('<iI' if data[1] else '>iI', data, 4)
    return sec * 1_000_000_000 + nsec


def _never_called(msg) -> None:
    """Callback of the recorder's subscriptions: their node is never spun."""


def __getattr__(name):
    """``RecorderNode`` on first use (``--help`` must not import rclpy)."""
    if name == 'RecorderNode':
        cls = _make_node_class()
        globals()['RecorderNode'] = cls
        return cls
    raise AttributeError(name)


def drain(executor, node, quiet_s: float = 0.05, limit_s: float = 2.0) -> None:
    """After a stop request: take what already arrived until nothing came for ``quiet_s``
    [s], at most ``limit_s`` [s]."""
    end = time.monotonic() + limit_s
    while time.monotonic() < end and not node.failed:
        before = sum(node.received.values())
        executor.spin_once(timeout_sec=quiet_s)
        if sum(node.received.values()) == before:
            return


def main(args=None):
    """Exit 0 after Ctrl-C (bag closed); 1 with one line when the bag cannot be created or
    writing fails (a full disk: what was written is kept)."""
    from irb_description.node_help import exit_if_help
    exit_if_help(args, SPEC)
    import rclpy
    from irb_description.node_main import (CONFIG_ERRORS, build_node, ignore_stop_signals,
                                           init, spin_until_signal)
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    from .bagio import BagError
    init(args)
    try:
        node, interrupted = build_node(__getattr__('RecorderNode'))
    except (BagError, OSError, *CONFIG_ERRORS) as exc:
        text = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        print(f'recorder: {text}', file=sys.stderr)
        rclpy.try_shutdown()
        return 1
    executor = None
    try:
        if not interrupted:
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            # the signal ends the loop between callbacks (never inside a take)
            spin_until_signal(executor, until=lambda: bool(node.failed))
            if not node.failed:
                drain(executor, node)
    except ExternalShutdownException:
        pass
    except Exception:  # noqa: BLE001 - rclpy errors after Ctrl-C shut the context down
        if node.context.ok():
            raise
    finally:
        ignore_stop_signals()        # a second Ctrl-C must not cut the closing of the bag
        if executor is not None:
            executor.shutdown()
        node.close()
        node.destroy_node()
        rclpy.try_shutdown()
    if node.failed:
        print(f'recorder: {node.failed}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
