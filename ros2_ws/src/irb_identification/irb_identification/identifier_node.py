"""identifier: friction maps from a replayed (or live) /joint_states stream.

    ros2 run irb_identification identifier --ros-args -p out_map:=runs/map.yaml
    ros2 run irb_identification replay --ros-args -p bag:=bags/run1 -p wait_for_subscribers:=1 \\
        -p reliable:=true

A thin adapter around stream.StreamIdentifier (the same identification code path as the
offline `identify`): raw subscription to ``topic`` with the QoS of the publishers it finds
(best effort if any is: the simulator; reliable otherwise: `replay` with ``reliable``),
`replay`'s latched status, services ``~/compute`` and ``~/reset`` (std_srvs/Trigger); the map
path on the latched ``~/friction_map`` (std_msgs/String) when a map was written.
"""
from __future__ import annotations

import sys
import time

from irb_description.node_help import NodeSpec, Param, Topic

SPEC = NodeSpec(
    'identifier', 'irb_identification',
    'Friction maps from a replayed (or live) JointState stream: the offline identify\'s code '
    "path. A replayed stream is complete when every message the replay announced arrived "
    '(its count, and the publisher\'s sequence numbers 1..N without a hole); otherwise no map '
    '(or, with allow_partial, one marked PARTIAL) and, with exit_after_stream, exit 1.',
    params=(
        Param('topic', '/joint_states', '', 'JointState topic (effort = torque)'),
        Param('status_topic', '/replay/status', '', "replay's latched end-of-stream status "
              '(std_msgs/String)'),
        Param('out_map', 'identified_friction_map.yaml', '', 'friction-map YAML to write'),
        Param('out_report', '', '', "JSON report, '' = next to out_map (.json)"),
        Param('torque_kind', 'total', '', 'total (effort = joint torque) or friction'),
        Param('method', 'auto', '', 'auto | sweep | samples'),
        Param('joints', [''], '', "joints to identify ('' = all); naming any of joint_4..6 "
              'reads all six and uses the six-joint model (as identify --joints)'),
        Param('map_joint', [''], '', "renames 'BAG_NAME:NAME' as identify --map-joint"),
        Param('effort_lag_s', 0.0, 's', 'the effort acted this long before its stamp'),
        Param('min_speeds', 4, '', 'fewest speeds per joint (sweep)'),
        Param('v_min', 0.01, 'rad/s', 'slowest sample used (samples)'),
        Param('quiet_period_s', 2.0, 's', 'no message this long ends a live stream (a '
              'replayed one only once its replay is gone); 0 = never'),
        Param('max_messages', 2_000_000, 'messages', 'kept at most (memory bound)'),
        Param('allow_partial', False, '', 'write a map (marked partial) from an incomplete '
              'stream'),
        Param('exit_after_stream', True, '', 'exit after a replayed stream: 0 with a map '
              'from the complete stream, 1 otherwise (live streams: keep running)'),
        Param('progress_period_s', 5.0, 's', 'progress log period, 0 = off'),
        Param('queue_depth', 10000, 'messages', 'subscription depth (best-effort '
              'publishers; reliable ones are read keep-all)'),
        Param('fill_nominal', False, '', "failed model joints from irb_description's nominal "
              'map (said so in the source)'),
        Param('plots_dir', '', '', "one figure per joint there, '' = none"),
        Param('complete_from', '', '', "add the model's joints not identified from this map "
              "('nominal' = irb_description's; as identify --complete-from), '' = none"),
    ),
    subscribes=(Topic('/joint_states', 'sensor_msgs/JointState', 'the stream (param topic)'),
                Topic('/replay/status', 'std_msgs/String', "replay's status (latched)")),
    publishes=(Topic('~/friction_map', 'std_msgs/String', 'latched path of the map written'),),
    services=(Topic('~/compute', 'std_srvs/Trigger', 'identify from what arrived so far'),
              Topic('~/reset', 'std_srvs/Trigger', 'forget the stream')),
    example='ros2 run irb_identification identifier --ros-args -p out_map:=runs/map.yaml\n'
            'ros2 run irb_identification replay --ros-args -p bag:=bags/run1 -p rate:=0 '
            '-p wait_for_subscribers:=1')


def _make_node_class():
    from irb_description.node_main import latched_qos
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, ReliabilityPolicy
    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    from .friction_fit import FitConfig
    from .pipeline import PipelineConfig
    from .rosutil import declare_params, subscription_qos
    from .sample_fit import SampleFitConfig
    from .segments import SegmentConfig
    from .stream import StreamConfig, StreamIdentifier

    class IdentifierNode(Node):
        def __init__(self, **kwargs):
            super().__init__('identifier', **kwargs)
            p = declare_params(self, SPEC.params)
            self.exit_code = None      # set after a replayed stream (exit_after_stream)
            self.p = p
            name_map = {}
            for spec in p['map_joint']:
                if spec:
                    a, sep, b = spec.partition(':')
                    if not sep or not a or not b:
                        raise ValueError(f'map_joint {spec!r}: expected BAG_NAME:NAME')
                    name_map[a] = b
            from irb_description.model import RobotModel
            config = StreamConfig(
                topic=p['topic'], max_messages=int(p['max_messages']),
                quiet_period_s=float(p['quiet_period_s']), allow_partial=bool(p['allow_partial']),
                torque_kind=p['torque_kind'], joints=[j for j in p['joints'] if j],
                name_map=name_map, out_map=p['out_map'], out_report=p['out_report'],
                fill_nominal=bool(p['fill_nominal']), plots_dir=p['plots_dir'],
                complete_from=p['complete_from'],
                pipeline=PipelineConfig(
                    method=p['method'],
                    fit=FitConfig(min_speeds=int(p['min_speeds']),
                                  segments=SegmentConfig(effort_lag_s=float(p['effort_lag_s']))),
                    samples=SampleFitConfig(v_min=float(p['v_min']))))
            if config.six_joints:     # joints 4-6 asked for: the six-joint model
                from .six_joint import SixJointIdentificationModel
                model = SixJointIdentificationModel()
            else:
                model = RobotModel.load()
            self.core = StreamIdentifier(config, model)
            self.map_pub = self.create_publisher(String, '~/friction_map', latched_qos())
            self.create_subscription(String, p['status_topic'], self._on_status, latched_qos())
            self.create_service(Trigger, '~/compute', self._srv_compute)
            self.create_service(Trigger, '~/reset', self._srv_reset)
            self.sub = None
            self.outcome = None
            self._late_said = 0
            from rclpy.clock import Clock, ClockType
            steady = Clock(clock_type=ClockType.STEADY_TIME)    # also under use_sim_time
            self.create_timer(0.1, self._tick, clock=steady)
            if p['progress_period_s'] > 0:
                self.create_timer(float(p['progress_period_s']), self._progress, clock=steady)
            self.get_logger().info(f'waiting for publishers of {p["topic"]}')

        def _subscribe_when_published(self) -> None:
            pubs = self.get_publishers_info_by_topic(self.p['topic'])
            if not pubs:
                return
            qos = subscription_qos(pubs, int(self.p['queue_depth']))
            if qos.reliability == ReliabilityPolicy.RELIABLE:
                # keep all: a full queue is not acknowledged, so a reliable publisher (replay)
                # waits for this node instead of losing what it cannot take yet
                qos.history = HistoryPolicy.KEEP_ALL
            self.sub = self.create_subscription(
                _joint_state_class(), self.p['topic'], self._on_msg, qos, raw=True)
            self.get_logger().info(f'subscribed to {self.p["topic"]} '
                                   f'({qos.reliability.name.lower()}, '
                                   f'{qos.history.name.lower()}, depth {qos.depth})')

        def _on_msg(self, data: bytes, info) -> None:
            """This message and every one waiting behind it, in one executor round (an
            executor round per message, ~200 us here, would cap the rate)."""
            from rclpy.exceptions import InvalidHandle
            add = self.core.add
            now_ns, wall = time.time_ns(), time.monotonic()
            add(data, now_ns, wall, info.get('publication_sequence_number'))
            sub, n = self.sub, 1
            try:
                with sub.handle:
                    while n < 20_000:
                        got = sub.handle.take_message(sub.msg_type, True)
                        if got is None:
                            break
                        add(got[0], now_ns, wall, got[1].get('publication_sequence_number'))
                        n += 1
            except InvalidHandle:          # destroyed meanwhile (shutdown)
                pass

        def _on_status(self, msg: String) -> None:
            self.core.on_status(msg.data)

        def _tick(self) -> None:
            if self.sub is None:
                self._subscribe_when_published()
            pubs = self.sub.get_publisher_count() if self.sub is not None else 0
            why = self.core.due(time.monotonic(), pubs)
            if why:
                self._compute(why)
            elif self.core.late and self.core.computed and self.core.late != self._late_said:
                self._late_said = self.core.late
                self.get_logger().warning(
                    f'{self.core.late} message(s) of the stream already identified arrived '
                    'after it ended: not used (the result above stays as it is)')

        def _progress(self) -> None:
            if self.sub is not None and not self.core.received and not self.core.computed:
                st = (self.core.status or {}).get('state', 'none')
                self.get_logger().info(
                    f'no message yet on {self.p["topic"]}: {self.sub.get_publisher_count()} '
                    f'publisher(s) matched, replay status {st}')
            if self.core.received and not self.core.computed:
                self.get_logger().info(self.core.progress())
                for line in self.core.segment_progress():
                    self.get_logger().info(f'  {line}')

        def _compute(self, trigger: str):
            log = self.get_logger()
            log.info(f'stream ended ({trigger}): {self.core.progress()}; identifying')
            out = self.core.compute(trigger, progress=lambda m: log.info(m))
            for line in out.lines:
                log.info(line)
            if out.error:
                log.error(out.error)
            if out.map_path:
                self.map_pub.publish(String(data=out.map_path))
                log.info(f'wrote {out.map_path}')
            self.outcome = out
            if (self.p['exit_after_stream'] and self.core.status is not None
                    and trigger != 'service'):
                complete = bool(out.report.get('stream', {}).get('complete'))
                self.exit_code = 0 if out.ok and complete else 1
                if self.exit_code:
                    log.error(f'exiting with 1: {out.error or "the stream was incomplete"}')
            return out

        def _srv_compute(self, request, response):
            out = self._compute('service')
            response.success = bool(out.ok)
            response.message = out.map_path if out.ok else out.error
            return response

        def _srv_reset(self, request, response):
            self.core.reset()
            self.outcome = None
            response.success = True
            response.message = 'reset'
            return response

    return IdentifierNode


def __getattr__(name):
    """``IdentifierNode`` on first use (``--help`` must not import rclpy)."""
    if name == 'IdentifierNode':
        cls = _make_node_class()
        globals()['IdentifierNode'] = cls
        return cls
    raise AttributeError(name)


def _joint_state_class():
    from sensor_msgs.msg import JointState
    return JointState


def main(args=None):
    from irb_description.node_help import exit_if_help
    exit_if_help(args, SPEC)
    from irb_description.node_main import run_node, spin_until_signal
    from rclpy.executors import SingleThreadedExecutor
    code = [0]

    def spin(node):
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        spin_until_signal(executor, until=lambda: node.exit_code is not None)
        code[0] = node.exit_code or 0
    try:
        run_node(__getattr__('IdentifierNode'), spin, args)
    except ValueError as exc:
        print(f'identifier: {exc}', file=sys.stderr)
        return 1
    return code[0]


if __name__ == '__main__':
    sys.exit(main())
