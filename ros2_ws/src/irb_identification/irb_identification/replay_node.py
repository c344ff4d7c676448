"""replay: publish a bag's messages on their topics at recorded speed or a rate factor.

    ros2 run irb_identification replay --ros-args -p bag:=bags/run1 -p rate:=2.0 -p clock:=true

Reliable keep-all publishers by default: playback goes as fast as the slowest reliable reader
takes the messages, and nothing is dropped. End of stream: a latched std_msgs/String on
``status_topic`` (JSON, stream.replay_status) with a stream id: ``playing`` with the messages
per topic about to be played, then ``finished`` (or ``stopped`` on Ctrl-C, ``failed`` with the
reason: a missing or damaged bag, a reader that did not acknowledge everything) with the
messages published per topic. Each topic's publisher numbers its messages 1..N (DDS sequence
numbers), so a reader can tell exactly which messages belong to the stream.
"""
from __future__ import annotations

import sys
import threading
import time
import uuid

from irb_description.node_help import NodeSpec, Param, Topic

SPEC = NodeSpec(
    'replay', 'irb_identification',
    "Publish a bag's messages on their topics (raw CDR) at the recorded speed times rate, or "
    'as fast as the slowest reliable reader takes them (rate 0). The bag is checked first '
    '(CRCs, counts): a damaged bag is refused with one line, exit 1, and a failed status.',
    params=(
        Param('bag', '', '', "bag directory to play (required unless 'bags')"),
        Param('bags', [''], '', "several bags played one after the other as one stream "
              "('' = only 'bag')"),
        Param('rate', 1.0, '', 'speed factor; 0 = as fast as the readers take them'),
        Param('clock', False, '', 'publish /clock (rosgraph_msgs/Clock) with the bag time'),
        Param('clock_frequency_hz', 100.0, 'Hz', '/clock rate, in bag time'),
        Param('topics', [''], '', "topics to play ('' = all)"),
        Param('wait_for_subscribers', 0, '', 'wait until every topic (and /clock with '
              'clock:=true) has this many subscribers'),
        Param('wait_timeout_s', 10.0, 's', 'limit of that wait'),
        Param('start_delay_s', 0.2, 's', 'pause before playing'),
        Param('verify', True, '', 'check the whole bag (CRCs, counts) before playing it'),
        Param('reliable', True, '', 'reliable keep-all publishers whatever the recorded QoS '
              '(nothing lost for a reliable reader; playback waits for it)'),
        Param('depth', 100, 'messages', "publisher queue depth when not 'reliable' (keep "
              'last)'),
        Param('drain_timeout_s', 30.0, 's', 'at the end, wait this long at most for reliable '
              'readers to acknowledge everything (else: failed, exit 1)'),
        Param('status_topic', '/replay/status', '', "latched end-of-stream status "
              "(std_msgs/String), '' = none"),
    ),
    publishes=(Topic('<the bag\'s topics>', '(from the bag)', 'raw CDR as recorded'),
               Topic('/replay/status', 'std_msgs/String', 'latched JSON: state, stream id, '
                     'counts announced and published, reason'),
               Topic('/clock', 'rosgraph_msgs/Clock', 'bag time, with clock:=true')),
    example='ros2 run irb_identification replay --ros-args -p bag:=bags/run1 -p rate:=0')


def _make_node_class():
    from rclpy.node import Node
    from rclpy._rclpy_pybind11 import RCLError

    from .bagio import (BagError, bag_info, bag_topics, check_bag, iter_messages,
                        topic_qos)
    from .playback import play
    from .rosutil import declare_params, message_class, qos_from_dicts
    from .stream import replay_status
    from irb_description.node_main import running

    class ReplayNode(Node):
        """Publishers for the bag's topics; ``run`` plays the bag (in a thread in main)."""

        def __init__(self, **kwargs):
            super().__init__('replay', **kwargs)
            p = declare_params(self, SPEC.params)
            self.stream_id = uuid.uuid4().hex[:12]
            self.error = ''              # why playing failed ('' = it did not)
            self.label = p['bag'] or ','.join(b for b in p['bags'] if b)
            self.counts, self.published = {}, {}
            self.status_pub = None
            if p['status_topic']:
                # first: whatever goes wrong below is announced to the readers waiting
                from irb_description.node_main import latched_qos
                from std_msgs.msg import String
                self._String = String
                self.status_pub = self.create_publisher(String, p['status_topic'],
                                                        latched_qos())
            try:
                self._open(p)
            except BagError as exc:
                self.publish_status('failed', str(exc))
                self.flush(timeout_s=2.0, only_status=True)
                raise

        def _open(self, p) -> None:
            self.bag = p['bag']
            self.bags = [b for b in p['bags'] if b]
            if self.bag and self.bags:
                raise BagError("give either 'bag' or 'bags', not both")
            if self.bags:
                self.bag = self.bags[0]
            self.bags = self.bags or [self.bag]
            self.rate = float(p['rate'])
            if self.rate < 0:
                raise BagError(f'rate must be >= 0, not {self.rate:g}')
            self.clock_on = bool(p['clock'])
            self.clock_hz = float(p['clock_frequency_hz'])
            only = [t for t in p['topics'] if t]
            self.wait_subs = int(p['wait_for_subscribers'])
            self.wait_timeout = float(p['wait_timeout_s'])
            self.start_delay = float(p['start_delay_s'])
            self.verify = bool(p['verify'])
            self.reliable = bool(p['reliable'])
            self.depth = int(p['depth'])
            self.drain_timeout = float(p['drain_timeout_s'])
            if not self.bag:
                raise BagError('parameter bag is required (a bag directory)')
            types = bag_topics(self.bag)
            qos = topic_qos(self.bag)
            missing = sorted(set(only) - set(types))
            if missing:
                raise BagError(f'bag {self.bag}: topic(s) {missing} not recorded')
            self.pubs = {}
            for t, ty in types.items():
                if only and t not in only:
                    continue
                q = qos_from_dicts(qos.get(t, []), self.depth)
                if self.reliable:       # keep all: wait for slow readers instead of dropping
                    from rclpy.qos import HistoryPolicy, ReliabilityPolicy
                    q.reliability = ReliabilityPolicy.RELIABLE
                    q.history = HistoryPolicy.KEEP_ALL
                self.pubs[t] = self.create_publisher(message_class(ty), t, q)
            self.counts = {t: 0 for t in self.pubs}
            self.segments = []
            for b in self.bags:
                other = bag_topics(b)
                for t in self.pubs:
                    if t in other and other[t] != types[t]:
                        raise BagError(f'bag {b}: {t} is {other[t]}, in {self.bag} {types[t]}')
                seg = {t: int(c['count']) for t, c in bag_info(b)['topics'].items()
                       if t in self.counts}
                for t, c in seg.items():
                    self.counts[t] += c
                self.segments.append({'bag': str(b), 'topics': seg})
            self.label = self.bag if len(self.bags) == 1 else (
                f'{self.bag} and {len(self.bags) - 1} more')
            self.published = {t: 0 for t in self.pubs}
            self.clock_pub = None
            if self.clock_on:
                from rosgraph_msgs.msg import Clock
                self.clock_pub = self.create_publisher(Clock, '/clock', 10)
            self.stop = threading.Event()
            self.done = threading.Event()
            self.stats = None

        def _wait_for_subscribers(self) -> None:
            deadline = time.monotonic() + self.wait_timeout
            # /clock counts as a topic too: a node on sim time that has not matched it yet
            # would miss the start of the bag's time
            pubs = dict(self.pubs, **({'/clock': self.clock_pub} if self.clock_pub else {}))
            while (self.wait_subs > 0 and time.monotonic() < deadline and not self.stop.is_set()
                   and any(p.get_subscription_count() < self.wait_subs
                           for p in pubs.values())):
                self.stop.wait(0.02)
            short = {t: p.get_subscription_count() for t, p in pubs.items()
                     if p.get_subscription_count() < self.wait_subs}
            if self.wait_subs > 0 and short and not self.stop.is_set():
                self.get_logger().warning(
                    f'playing anyway after wait_timeout_s = {self.wait_timeout:g} s: '
                    + ', '.join(f'{t} has {n} of {self.wait_subs} subscriber(s)'
                                for t, n in short.items())
                    + ' (what they miss is lost for them)')

        def flush(self, timeout_s: float | None = None, only_status: bool = False) -> bool:
            """Wait (up to drain_timeout_s) until reliable readers acknowledged every message
            and the status: the writer's queue dies with this process. False (and one line
            in ``error``) if a reader did not acknowledge everything in time."""
            from rclpy.duration import Duration
            timeout = self.drain_timeout if timeout_s is None else timeout_s
            end = time.monotonic() + timeout
            pubs = [] if only_status else list(getattr(self, 'pubs', {}).values())
            try:
                for pub in [*pubs, self.status_pub]:
                    if pub is None or (only_status and pub.get_subscription_count() == 0):
                        continue
                    while not pub.wait_for_all_acked(Duration(seconds=0.5)):
                        if time.monotonic() > end:
                            if not only_status and not self.error:
                                self.error = (
                                    f'{pub.topic_name}: not every message acknowledged by '
                                    f'its readers within drain_timeout_s = {timeout:g} s '
                                    '(a reader is stuck or gone: it may miss the end)')
                            return False
            except Exception:  # noqa: BLE001 - context already shut down: nothing to wait for
                pass
            return True

        def publish_status(self, state: str, reason: str = '') -> None:
            if self.status_pub is not None:
                self.status_pub.publish(self._String(data=replay_status(
                    state, self.label, self.counts, self.published, reason,
                    stream=self.stream_id,
                    segments=(getattr(self, 'segments', [])
                              if len(getattr(self, 'bags', [])) > 1 else []))))

        def _publish(self, topic: str, data: bytes) -> None:
            """Publish; with ``reliable`` (keep all) a full queue makes the middleware refuse the
            message after its blocking time: then retry, so playback goes as fast as the slowest
            reliable subscriber takes messages (bounded by drain_timeout_s per message)."""
            end = None
            while True:
                try:
                    self.pubs[topic].publish(data)
                    break
                except RCLError:
                    if not self.reliable or self.stop.is_set():
                        raise
                    end = end or time.monotonic() + self.drain_timeout
                    if time.monotonic() > end:
                        raise
                    self.stop.wait(0.002)
            self.published[topic] += 1

        def _publish_clock(self, t_ns: int) -> None:
            from rosgraph_msgs.msg import Clock
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(t_ns, 1_000_000_000)
            self.clock_pub.publish(msg)

        def run(self) -> None:
            """Play the bag once; sets ``done``. A damaged bag ends it with ``error``; a stop
            (Ctrl-C) ends it quietly."""
            state = 'failed'
            try:
                self._play()
                state = 'stopped' if self.stop.is_set() else 'finished'
            except BagError as exc:
                self.error = str(exc)
            except Exception as exc:  # noqa: BLE001 - the thread must report, not print a trace
                if not self.stop.is_set() and running(self.context):
                    self.error = f'playing failed: {type(exc).__name__}: {exc}'
                else:
                    state = 'stopped'
            finally:
                try:
                    if running(self.context) or state != 'failed':
                        self.publish_status(state, self.error)
                except Exception:  # noqa: BLE001 - context gone on shutdown: nothing to tell
                    pass
                self.done.set()

        def _play(self) -> None:
            if self.verify:
                for b in self.bags:
                    self.get_logger().info(check_bag(b).describe())
            self.publish_status('playing')
            self._wait_for_subscribers()
            self.stop.wait(self.start_delay)
            msgs = (m for b in self.bags for m in iter_messages(b) if m[0] in self.pubs)
            self.get_logger().info(f'playing {self.label} at rate {self.rate or "max"}')
            self.stats = play(
                msgs, self._publish, self.rate,
                clock=self._publish_clock if self.clock_pub else None,
                clock_period_ns=int(1e9 / self.clock_hz), stop=self.stop)
            self.get_logger().info(
                f'played {self.stats.messages} messages, {self.stats.bag_span_s:.2f} s of '
                f'bag in {self.stats.wall_s:.2f} s')

    return ReplayNode


def __getattr__(name):
    """``ReplayNode`` on first use (``--help`` must not import rclpy)."""
    if name == 'ReplayNode':
        cls = _make_node_class()
        globals()['ReplayNode'] = cls
        return cls
    raise AttributeError(name)


def main(args=None):
    """Exit 0 when the bag was played and acknowledged (or Ctrl-C); 1 with one line on a bad
    or damaged bag, or when a reliable reader did not take everything."""
    from irb_description.node_help import exit_if_help
    exit_if_help(args, SPEC)
    import rclpy
    from irb_description.node_main import (CONFIG_ERRORS, build_node, ignore_stop_signals,
                                           init, running)
    from rclpy.executors import ExternalShutdownException

    from .bagio import BagError
    init(args)
    try:
        node, interrupted = build_node(__getattr__('ReplayNode'))
    except (BagError, *CONFIG_ERRORS) as exc:
        print(f'replay: {exc}', file=sys.stderr)
        rclpy.try_shutdown()
        return 1
    player = threading.Thread(target=node.run, daemon=True)
    if not interrupted:
        player.start()
    try:
        while not interrupted and running(node.context) and not node.done.is_set():
            rclpy.spin_once(node, timeout_sec=0.1)
    except ExternalShutdownException:
        pass
    finally:
        ignore_stop_signals()
        node.stop.set()
        if player.is_alive():
            player.join(timeout=5.0)
        if not node.flush() and node.error:
            try:
                node.publish_status('failed', node.error)
                node.flush(timeout_s=2.0, only_status=True)
            except Exception:  # noqa: BLE001 - context gone: nothing more to tell
                pass
        error = node.error
        node.destroy_node()
        rclpy.try_shutdown()
    if error:
        print(f'replay: {error}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
