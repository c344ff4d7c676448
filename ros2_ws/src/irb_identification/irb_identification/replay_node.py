"""replay: publish a bag's messages on their topics at recorded speed or a rate factor.

    ros2 run irb_identification replay --ros-args -p bag:=bags/run1 -p rate:=2.0 -p clock:=true

End of stream: a latched std_msgs/String on ``status_topic`` (JSON, stream.replay_status):
``playing`` with the messages per topic about to be played, then ``finished`` (or ``stopped``
on Ctrl-C, ``failed`` on a damaged bag) with the messages published per topic.
"""
from __future__ import annotations

import sys
import threading
import time

import rclpy
from irb_description.node_main import build_node, ignore_stop_signals, init, running
from rcl_interfaces.msg import ParameterDescriptor
from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from .bagio import BagError, bag_info, bag_topics, iter_messages, topic_qos, verify_bag
from .playback import play
from .rosutil import message_class, qos_from_dicts
from .stream import replay_status


class ReplayNode(Node):
    """Publishers for the bag's topics; ``run`` plays the bag (in a thread in main)."""

    def __init__(self, **kwargs):
        super().__init__('replay', **kwargs)

        def param(name, default, text):
            return self.declare_parameter(name, default, ParameterDescriptor(
                description=text)).value

        self.bag = param('bag', '', "bag directory to play (required unless 'bags')")
        self.bags = [b for b in param('bags', [''], 'several bags played one after the other '
                                      "as one stream ('' = only 'bag')") if b]
        if self.bag and self.bags:
            raise BagError("give either 'bag' or 'bags', not both")
        if self.bags:
            self.bag = self.bags[0]
        self.bags = self.bags or [self.bag]
        self.rate = float(param('rate', 1.0, 'speed factor; 0 = as fast as possible'))
        self.clock_on = param('clock', False, 'publish /clock (rosgraph_msgs/Clock) bag time')
        self.clock_hz = float(param('clock_frequency_hz', 100.0, '[Hz] /clock rate, bag time'))
        only = [t for t in param('topics', [''], "topics to play ('' = all)") if t]
        self.wait_subs = int(param('wait_for_subscribers', 0,
                                   'wait until every topic has this many subscribers'))
        self.wait_timeout = float(param('wait_timeout_s', 10.0, '[s] limit of that wait'))
        self.start_delay = float(param('start_delay_s', 0.2, '[s] pause before playing'))
        self.verify = bool(param('verify', True, 'read the whole bag with CRC checks before '
                                 'playing it (a damaged bag is refused, not half played)'))
        self.reliable = bool(param('reliable', False, 'publish reliable whatever the recorded '
                                   'QoS (no loss to a matched reliable subscriber)'))
        self.depth = int(param('depth', 100, 'publisher queue depth (keep last)'))
        self.drain_timeout = float(param('drain_timeout_s', 30.0, '[s] at the end, wait this '
                                         'long at most for reliable subscribers to '
                                         'acknowledge everything'))
        status_topic = param('status_topic', '/replay/status',
                             "latched end-of-stream status (std_msgs/String), '' = none")
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
        for b in self.bags:
            other = bag_topics(b)
            for t in self.pubs:
                if t in other and other[t] != types[t]:
                    raise BagError(f'bag {b}: {t} is {other[t]}, in {self.bag} {types[t]}')
            for t, c in bag_info(b)['topics'].items():
                if t in self.counts:
                    self.counts[t] += int(c['count'])
        self.label = self.bag if len(self.bags) == 1 else (
            f'{self.bag} and {len(self.bags) - 1} more')
        self.published = {t: 0 for t in self.pubs}
        self.status_pub = None
        if status_topic:
            from irb_description.node_main import latched_qos
            from std_msgs.msg import String
            self._String = String
            self.status_pub = self.create_publisher(String, status_topic, latched_qos())
        self.clock_pub = None
        if self.clock_on:
            from rosgraph_msgs.msg import Clock
            self.clock_pub = self.create_publisher(Clock, '/clock', 10)
        self.stop = threading.Event()
        self.done = threading.Event()
        self.stats = None
        self.error = ''              # why playing failed ('' = it did not)

    def _wait_for_subscribers(self) -> None:
        deadline = time.monotonic() + self.wait_timeout
        while (self.wait_subs > 0 and time.monotonic() < deadline and not self.stop.is_set()
               and any(p.get_subscription_count() < self.wait_subs
                       for p in self.pubs.values())):
            self.stop.wait(0.02)
        short = {t: p.get_subscription_count() for t, p in self.pubs.items()
                 if p.get_subscription_count() < self.wait_subs}
        if self.wait_subs > 0 and short and not self.stop.is_set():
            self.get_logger().warning(
                f'playing anyway after wait_timeout_s = {self.wait_timeout:g} s: '
                + ', '.join(f'{t} has {n} of {self.wait_subs} subscriber(s)'
                            for t, n in short.items())
                + ' (what they miss is lost for them)')

    def flush(self) -> None:
        """Wait (up to drain_timeout_s) until reliable subscribers acknowledged every message
        and the status: the writer's queue dies with this process, and a slow reader (keep
        all) has not taken everything yet when the last message is published."""
        from rclpy.duration import Duration
        end = time.monotonic() + self.drain_timeout
        try:
            for pub in [*self.pubs.values(), self.status_pub]:
                while pub is not None and not pub.wait_for_all_acked(Duration(seconds=0.5)):
                    if time.monotonic() > end:
                        self.get_logger().warning(
                            f'{pub.topic_name}: not every message acknowledged within '
                            f'drain_timeout_s = {self.drain_timeout:g} s')
                        break
        except Exception:  # noqa: BLE001 - context already shut down: nothing to wait for
            pass

    def publish_status(self, state: str, reason: str = '') -> None:
        if self.status_pub is not None:
            self.status_pub.publish(self._String(data=replay_status(
                state, self.label, self.counts, self.published, reason)))

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
            n = sum(verify_bag(b) for b in self.bags)
            self.get_logger().info(f'{self.label}: {n} messages, CRCs valid')
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


def main(args=None):
    """Exit 0 when the bag was played (or Ctrl-C), 1 with one line on a bad or damaged bag."""
    init(args)
    try:
        node, interrupted = build_node(ReplayNode)
    except BagError as exc:
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
        node.flush()
        error = node.error
        node.destroy_node()
        rclpy.try_shutdown()
    if error:
        print(f'replay: {error}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
