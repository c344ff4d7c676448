"""The verbs that talk to the ROS graph: ``ros2 topic list|echo|hz|info``, ``ros2 service
list|call``. rclpy is imported inside each verb (this package itself depends on nothing): where
it is missing the verb says so in one line. Formats and statistics live in ``fmt.py``.

Every verb runs one hidden node (``_ros2cli_<pid>``, as ros2cli's direct node) and ends on
Ctrl-C without a traceback (exit 2, as ros2cli: ``rc = signal.SIGINT``).
"""

from __future__ import annotations

import importlib
import os
import signal
import sys
import time
from collections import deque

from . import fmt

#: how often graph queries are repeated while waiting for discovery [s]
POLL_S = 0.05
#: a topic's endpoints are taken as all discovered once unchanged this long [s]
SETTLE_S = 1.0


class CliError(Exception):
    """A failure reported in one line on stderr with exit code 1."""


def _import_rclpy():
    try:
        import rclpy
    except ImportError:
        raise CliError('this command needs rclpy (source the workspace, e.g. '
                       '`source scripts/env.sh`)') from None
    return rclpy


class Session:
    """rclpy initialised, one hidden node and an executor; closed on exit."""

    def __init__(self):
        rclpy = _import_rclpy()
        try:    # the project's rule: ROS_SECURITY_ENABLE=true is never ignored
            from irb_description.node_main import refuse_insecure_start
        except ImportError:
            refuse_insecure_start = None
        if refuse_insecure_start is not None:
            refuse_insecure_start()
        from rclpy.executors import SingleThreadedExecutor
        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(f'_ros2cli_{os.getpid()}', context=self.context,
                                      start_parameter_services=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        try:
            self.executor.shutdown()
            self.node.destroy_node()
        finally:
            self.rclpy.try_shutdown(context=self.context)
        return False

    def spin(self, timeout: float) -> None:
        self.executor.spin_once(timeout_sec=timeout)

    def wait_stable(self, query, settle: float, timeout: float):
        """Repeat ``query()`` until its result is non-empty and unchanged for ``settle``
        [s] (discovery brings a topic's endpoints one by one), at most ``timeout`` [s]."""
        end = time.monotonic() + timeout
        last, since = None, None
        while True:
            result = query()
            now = time.monotonic()
            if result != last:
                last, since = result, now
            elif result and now - since >= settle:
                return result
            if now >= end:
                return result
            self.spin(min(POLL_S, end - now))

    def wait_graph(self, query, until=None, timeout: float = 1.0):
        """Repeat ``query()`` (a graph lookup) every POLL_S until ``until(result)`` is true
        or ``timeout`` [s] passed; return the last result. Without ``until``: wait the
        whole ``timeout`` (list verbs: discovery has no end to wait for)."""
        end = time.monotonic() + timeout
        while True:
            result = query()
            if until is not None and until(result):
                return result
            left = end - time.monotonic()
            if left <= 0:
                return result
            self.spin(min(POLL_S, left))


def _interrupted(run):
    """Run ``run()`` and map Ctrl-C (and rclpy's shutdown on SIGINT) to exit code 2."""
    try:
        from rclpy.executors import ExternalShutdownException
    except ImportError:
        ExternalShutdownException = KeyboardInterrupt  # noqa: N806
    try:
        return run()
    except (KeyboardInterrupt, ExternalShutdownException):
        return int(signal.SIGINT)


def import_type(type_name: str, kind: str):
    """The Python class of 'pkg/msg/Name' (kind 'msg') or 'pkg/srv/Name' (kind 'srv')."""
    pkg, given_kind, name = fmt.split_type(type_name)
    if given_kind and given_kind != kind:
        raise CliError(f"The passed type '{type_name}' is not a {kind} type")
    try:
        return getattr(importlib.import_module(f'{pkg}.{kind}'), name)
    except (ImportError, AttributeError):
        raise CliError(f"The {'message' if kind == 'msg' else 'service'} type "
                       f"'{type_name}' is invalid") from None


def _topic_types(session, topic: str, timeout: float):
    """The types of ``topic`` once it is on the graph (waiting up to ``timeout`` [s]), or
    []."""
    def query():
        return dict(session.node.get_topic_names_and_types()).get(topic, [])
    return session.wait_graph(query, until=bool, timeout=timeout)


def _echo_qos(session, topic: str):
    """ros2cli's choice: reliable if every publisher is, transient local if every one is
    (so latched topics are received), else best effort / volatile; depth 10."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    pubs = session.node.get_publishers_info_by_topic(topic)
    reliable = bool(pubs) and all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE
                                  for p in pubs)
    latched = bool(pubs) and all(
        p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in pubs)
    return QoSProfile(depth=10,
                      reliability=(ReliabilityPolicy.RELIABLE if reliable
                                   else ReliabilityPolicy.BEST_EFFORT),
                      durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                                  else DurabilityPolicy.VOLATILE))


def _wait_names(s, query, timeout: float):
    """Names and types found within ``timeout`` [s]: a list has no end to wait for, and on
    a loaded host a node missed by the first discovery burst is announced again only ~3 s
    later (Fast DDS), so the whole time (3.5 s by default) is waited."""
    return s.wait_graph(query, timeout=timeout)


# --- ros2 topic ------------------------------------------------------------------------------
def topic_list(args) -> int:
    with Session() as s:
        result = _wait_names(s, s.node.get_topic_names_and_types, args.spin_time)
    lines = fmt.format_names_and_types(result, args.show_types, args.include_hidden_topics)
    if args.count_topics:
        print(len(lines))
    else:
        for line in lines:
            print(line)
    return 0


def topic_info(args) -> int:
    topic = fmt.expand_name(args.topic_name)
    with Session() as s:
        def query():
            types = dict(s.node.get_topic_names_and_types()).get(topic, [])
            pubs = s.node.get_publishers_info_by_topic(topic)
            subs = [i for i in s.node.get_subscriptions_info_by_topic(topic)
                    if i.node_name != s.node.get_name()]
            return types, pubs, subs

        def key():
            """What must stop changing: the endpoints (as printed) and the nodes; () while
            the topic is not on the graph."""
            types, pubs, subs = query()
            if not types:
                return ()
            return (tuple(types), tuple(str(p) for p in pubs), tuple(str(p) for p in subs),
                    tuple(sorted(s.node.get_node_names_and_namespaces())))
        result = s.wait_stable(key, SETTLE_S, args.spin_time)
        if not result:
            raise CliError(f"Unknown topic '{topic}'")
        types, pubs, subs = query()
    print(fmt.format_topic_info(types, pubs, subs, args.verbose), end='' if args.verbose
          else '\n')
    return 0


def _resolve_type(s, topic: str, given: str | None, timeout: float):
    if given:
        return import_type(given, 'msg')
    types = _topic_types(s, topic, timeout)
    if not types:
        raise CliError(f'WARNING: topic [{topic}] does not appear to be published yet; '
                       'Could not determine the type for the passed topic')
    if len(types) > 1:
        raise CliError(f"Cannot echo topic '{topic}', as it contains more than one type: "
                       f"[{', '.join(types)}]")
    return import_type(types[0], 'msg')


def topic_echo(args) -> int:
    topic = fmt.expand_name(args.topic_name)
    truncate = None if args.full_length else args.truncate_length

    def run():
        with Session() as s:
            cls = _resolve_type(s, topic, args.message_type, args.spin_time)
            received = []

            def cb(msg):
                data = fmt.select_field(
                    fmt.message_to_dict(msg, truncate, args.no_arr, args.no_str), args.field)
                text = (fmt.dict_to_yaml(data, args.flow_style)
                        if isinstance(data, (dict, list)) else f'{data}\n')
                print(text, end='---\n', flush=True)
                received.append(1)

            s.wait_graph(lambda: s.node.get_publishers_info_by_topic(topic), until=bool,
                         timeout=args.spin_time)      # the QoS follows the publishers'
            s.node.create_subscription(cls, topic, cb, _echo_qos(s, topic))
            end = None if args.timeout is None else time.monotonic() + args.timeout
            while not (args.once and received):
                left = None if end is None else end - time.monotonic()
                if left is not None and left <= 0:
                    break
                s.spin(0.1 if left is None else min(0.1, left))
            if args.once and not received:
                raise CliError(f'no message on {topic} within {args.timeout:g} s')
        return 0
    return _interrupted(run)


def topic_hz(args) -> int:
    topic = fmt.expand_name(args.topic_name)

    def run():
        from rclpy.qos import qos_profile_sensor_data
        with Session() as s:
            if args.message_type:       # not ros2cli's syntax: kept for scripts
                cls = import_type(args.message_type, 'msg')
            else:
                types = _topic_types(s, topic, args.spin_time)
                if not types:
                    print(f'WARNING: topic [{topic}] does not appear to be published yet',
                          file=sys.stderr, flush=True)
                    while not types:
                        types = _topic_types(s, topic, 1.0)
                cls = import_type(types[0], 'msg')
            times = deque(maxlen=args.window)
            total = [0]

            def cb(_data):
                times.append(time.monotonic())
                total[0] += 1

            s.node.create_subscription(cls, topic, cb, qos_profile_sensor_data, raw=True)
            reported, due = 0, time.monotonic() + 1.0
            while True:
                s.spin(max(0.0, min(0.1, due - time.monotonic())))
                if time.monotonic() < due:
                    continue
                due += 1.0
                stats = fmt.rate_stats(times)
                if stats is None:
                    continue            # nothing to say before two messages arrived
                if total[0] == reported:
                    print('no new messages', flush=True)
                else:
                    print(fmt.format_hz(stats), flush=True)
                reported = total[0]
    return _interrupted(run)


# --- ros2 service ----------------------------------------------------------------------------
def service_list(args) -> int:
    with Session() as s:
        result = _wait_names(s, s.node.get_service_names_and_types, args.spin_time)
    lines = fmt.format_names_and_types(result, args.show_types, args.include_hidden_services)
    if args.count_services:
        print(len(lines))
    else:
        for line in lines:
            print(line)
    return 0


def _service_request(cls, values: str | None):
    request = cls.Request()
    if values:
        import yaml
        try:
            data = yaml.safe_load(values)
        except yaml.YAMLError as exc:
            raise CliError(f'the values are not YAML: {exc}'.splitlines()[0]) from None
        if data is not None:
            try:
                fmt.fill_message(request, data)
            except ValueError as exc:
                raise CliError(str(exc)) from None
    return request


def service_call(args) -> int:
    service = fmt.expand_name(args.service_name)
    cls = import_type(args.service_type, 'srv')
    request = _service_request(cls, args.values)

    def run():
        with Session() as s:
            client = s.node.create_client(cls, service)
            end = None if args.timeout is None else time.monotonic() + args.timeout
            if not client.wait_for_service(timeout_sec=min(1.0, args.timeout or 1.0)):
                print('waiting for service to become available...', flush=True)
                while not client.wait_for_service(timeout_sec=1.0):
                    if end is not None and time.monotonic() > end:
                        raise CliError(f'service {service} not available within '
                                       f'{args.timeout:g} s')
            print(f'requester: making request: {fmt.format_request(request)}\n', flush=True)
            future = client.call_async(request)
            while not future.done():
                if end is not None and time.monotonic() > end:
                    raise CliError(f'no answer from {service} within {args.timeout:g} s')
                s.spin(0.1)
            print(f'response:\n{future.result()!r}\n', flush=True)
        return 0
    return _interrupted(run)
