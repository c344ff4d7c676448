"""recorder: record topics into a crash-safe rosbag2 MCAP bag (bags/<name>/).

    ros2 run irb_identification recorder --ros-args -p name:=run1
"""
from __future__ import annotations

import sys
import time
from datetime import datetime
from pathlib import Path

import rclpy
from irb_description.node_main import build_node, ignore_stop_signals, init, spin_until_signal
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from .bagio import BagError, BagWriteError, BagWriter, TopicInfo, needs_recovery, recover_bag
from .rosutil import default_bag_root, message_class, qos_to_dict, subscription_qos

DEFAULT_TOPICS = ['/joint_states', '/torque_command', '/controller_state', '/camera/tcp']


class RecorderNode(Node):
    """Subscribes raw to the chosen topics and writes their CDR bytes to a BagWriter."""

    def __init__(self, node_name: str = 'recorder', taps: dict | None = None, **kwargs):
        """``taps`` (in-process use): {topic: callable(bytes)} called with every message of
        that topic after it is written (the experiments node follows its runs with them)."""
        super().__init__(node_name, **kwargs)
        self.taps = dict(taps or {})

        def param(name, default, text):
            return self.declare_parameter(name, default, ParameterDescriptor(
                description=text)).value

        root = param('root', '', 'bag root directory; empty: $IRB_ROOT/bags or ./bags')
        name = param('name', '', 'bag name; empty: rec_<date>_<time>')
        self.topics = list(param('topics', DEFAULT_TOPICS, 'topics to record'))
        types = list(param('types', [''], "message type per topic ('' = from the graph)"))
        split = param('split_period_s', 1.5, '[s] close a split file this often (crash loss)')
        chunk = param('chunk_size_kib', 64, '[KiB] MCAP chunk size')
        compression = param('compression', 'none', "'none' or 'zstd' (chunk compression)")
        self.depth = param('queue_depth', 1000, 'subscription queue depth [messages]')
        discovery = param('discovery_period_s', 0.5, '[s] look for missing topics this often')
        progress = param('progress_period_s', 2.0, '[s] progress report period; 0 = off')
        recover = param('recover_on_start', True,
                        'recover bags in root left incomplete by a killed recorder')

        self.root = Path(root) if root else default_bag_root()
        self.root.mkdir(parents=True, exist_ok=True)
        if recover:
            self._recover_leftovers()
        name = name or datetime.now().strftime('rec_%Y%m%d_%H%M%S')
        self.given_types = {t: ty for t, ty in zip(self.topics, types) if ty}
        self.writer = BagWriter(self.root / name, split_period_s=split,
                                chunk_size=int(chunk) * 1024, compression=compression,
                                custom_data={'recorder': 'irb_identification'})
        self.bag_path = self.writer.path
        self.subs = {}
        self._t0 = time.monotonic()
        self._last = (self._t0, 0)
        self._check_topics()
        self.create_timer(discovery, self._check_topics)
        self.create_timer(0.1, self._housekeeping)
        if progress > 0:
            self.create_timer(progress, self._progress)
        self.get_logger().info(f'recording {self.topics} into {self.bag_path}')

    def _recover_leftovers(self) -> None:
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
                # only subscribers so far: wait for a publisher, whose QoS decides ours (a
                # reliable guess would never match a best-effort publisher appearing later)
                continue
            info = TopicInfo.for_type(topic, msgtype, [qos_to_dict(p.qos_profile)
                                                       for p in pubs])
            self.writer.add_topic(info)
            self.subs[topic] = self.create_subscription(
                message_class(msgtype), topic, self._callback(topic),
                subscription_qos(pubs, self.depth), raw=True)
            self.get_logger().info(f'subscribed to {topic} [{msgtype}]')

    def _callback(self, topic: str):
        write = self._write
        clock = self.get_clock()
        tap = self.taps.get(topic)

        def cb(data: bytes) -> None:
            write(topic, clock.now().nanoseconds, data)

        def cb_tap(data: bytes) -> None:
            write(topic, clock.now().nanoseconds, data)
            tap(data)
        return cb if tap is None else cb_tap

    def _write(self, topic: str, t_ns: int, data: bytes) -> None:
        if self.writer.failed:
            return
        try:
            self.writer.write(topic, t_ns, data)
        except BagWriteError as exc:
            self._fail(exc)

    def _fail(self, exc) -> None:
        """Writing failed (a full disk): one line, stop recording (main ends with exit 1)."""
        self.get_logger().error(f'recording stopped: {exc}')

    @property
    def failed(self) -> str:
        return self.writer.failed

    def _housekeeping(self) -> None:
        if self.writer.failed:
            return
        try:
            if not self.writer.maybe_split():
                self.writer.flush()
        except BagWriteError as exc:
            self._fail(exc)

    def _progress(self) -> None:
        now = time.monotonic()
        n = self.writer.message_count
        rate = (n - self._last[1]) / max(now - self._last[0], 1e-9)
        self._last = (now, n)
        per = ', '.join(f'{t} {c}' for t, c in self.writer.counts.items())
        missing = [t for t in self.topics if t not in self.subs]
        self.get_logger().info(
            f'{n} msgs, {rate:.0f} msg/s, {self.writer.bytes_written / 2**20:.2f} MiB, '
            f'{len(self.writer.files)} files, {now - self._t0:.0f} s'
            + (f' | {per}' if per else '') + (f' | waiting for {missing}' if missing else ''))

    def close(self) -> None:
        self.writer.close()
        text = (f'closed {self.bag_path}: {self.writer.message_count} messages in '
                f'{len(self.writer.files)} files'
                + (' (writing had failed: see above)' if self.writer.failed else ''))
        if self.context.ok():
            self.get_logger().info(text)
        else:                              # after Ctrl-C the rosout publisher is gone
            print(f'[recorder] {text}', file=sys.stderr)


def drain(executor, node, quiet_s: float = 0.05, limit_s: float = 2.0) -> None:
    """After a stop request: write what already arrived (a recorder that trails a fast graph,
    e.g. a lockstep simulator on a loaded machine, has up to ``queue_depth`` messages per topic
    waiting) until nothing came for ``quiet_s`` [s], at most ``limit_s`` [s]."""
    end = time.monotonic() + limit_s
    while time.monotonic() < end and not node.failed:
        before = sum(node.writer.counts.values())
        executor.spin_once(timeout_sec=quiet_s)
        if sum(node.writer.counts.values()) == before:
            return


def main(args=None):
    """Exit 0 after Ctrl-C (bag closed); 1 with one line when the bag cannot be created or
    writing fails (a full disk: the closed splits are kept)."""
    init(args)
    try:
        node, interrupted = build_node(RecorderNode)
    except (BagError, OSError) as exc:
        text = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        print(f'recorder: {text}', file=sys.stderr)
        rclpy.try_shutdown()
        return 1
    executor = None
    try:
        if not interrupted:
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            # the signal ends the loop between callbacks (never inside a write)
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
