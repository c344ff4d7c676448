"""ctl: see and command the running graph from a shell (pdplus, the drive, the main topics).

    ros2 run irb_bringup ctl status     # mode, latched stop/error with reasons, plan verdict,
                                        # drive state, rates of the main topics
    ros2 run irb_bringup ctl enable     # pdplus ~/enable: start, or leave a latched stop
    ros2 run irb_bringup ctl stop       # pdplus ~/stop: safe stop, latched until enable
    ros2 run irb_bringup ctl reset      # clear the drive's latched error (simulator or
                                        # axis_bridge ~/reset; pdplus's ~/reset if it has one)
    ros2 run irb_bringup ctl hold       # pdplus ~/hold: controlled stop along the path,
                                        # then hold the pose (motors on, nothing latched)
    ros2 run irb_bringup ctl enable --wait   # enable, then wait until the motion it started
                                        # has ended (hold or idle); exit 1 if pdplus stops
    ros2 run irb_bringup ctl wait path  # until pdplus is in that mode (at once if it is);
                                        # exit 1 if it stops. To wait for a motion to end,
                                        # use ctl enable --wait

Exit codes: 0 done; 1 refused by the node (its message is printed); 2 node or service not
there, or no answer within --timeout. Every wait is bounded. The text and the rates come from
ctl_core (no rclpy); this file only collects messages and calls services.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

COMMANDS = ('status', 'enable', 'stop', 'reset', 'hold', 'wait')
#: the graph is taken as discovered once pdplus's services are unchanged this long [s]
SETTLE_S = 1.0
#: [s] how long status waits, once every topic is matched on its side, for the last sample of
#: a latched topic that has a publisher: discovery matches the two sides separately, and a
#: reader can be matched seconds before the writer sends it anything (measured: the
#: simulator's axis_status reached a new reader 1.1-2.2 s or 3.7 s after it started, the
#: latter one DDS heartbeat period later; a 1 s wait printed a status without the drive)
LATCHED_WAIT_S = 5.0


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog='ros2 run irb_bringup ctl',
        description=__doc__.splitlines()[0].split(': ', 1)[1].capitalize(),
        epilog='Exit codes: 0 done, 1 refused by the node (its message printed), 2 node or '
               'service not there or no answer within --timeout.',
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('command', choices=COMMANDS, help='status: what pdplus, its plan and the '
                   'drive report, and the rates of the main topics; enable|stop|hold: '
                   "pdplus's std_srvs/Trigger service of that name; reset: the drive's "
                   '~/reset (and pdplus\'s, where it has one); wait MODE: until pdplus '
                   'reports MODE (idle, ramp, path, time, hold, stopped)')
    p.add_argument('mode', nargs='?', default='',
                   help='wait: the mode to wait for (done at once if pdplus is in it; to '
                   'wait for the end of a motion: ctl enable --wait)')
    p.add_argument('--pdplus', default='/pdplus', help='the controller node; its namespace is '
                   'that of the topics and of the drive (default: /pdplus)')
    p.add_argument('--timeout', type=float, default=10.0,
                   help='longest wait for the node and for each answer [s] (default: 10; '
                   'wait: for the mode)')
    p.add_argument('--wait', action='store_true',
                   help='enable: then follow /controller_state until the motion ends (hold '
                   'or idle; exit 1 with the reason if pdplus stops); bounded by '
                   '--motion-timeout')
    p.add_argument('--motion-timeout', type=float, default=300.0,
                   help='enable --wait: longest wait for the motion to end [s] (default: 300)')
    p.add_argument('--window', type=float, default=1.0,
                   help='status: how long the topic rates are measured [s] (default: 1)')
    return p.parse_args(argv)


def _split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """(argparse's arguments, rclpy's: everything from --ros-args on)."""
    if '--ros-args' in argv:
        i = argv.index('--ros-args')
        return argv[:i], argv[i:]
    return argv, []


class _Session:
    """rclpy on the default context with one hidden node and an executor."""

    def __init__(self, ros_args):
        import rclpy
        from irb_description.node_main import refuse_insecure_start
        from rclpy.executors import SingleThreadedExecutor
        refuse_insecure_start()
        self.rclpy = rclpy
        rclpy.init(args=['ctl', *ros_args])
        self.node = rclpy.create_node(f'_irb_ctl_{os.getpid()}',
                                      start_parameter_services=False)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        self.rclpy.try_shutdown()

    def spin_for(self, seconds: float, until=None) -> bool:
        """Spin ``seconds`` [s], or until ``until()`` is true (then True)."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if until is not None and until():
                return True
            self.executor.spin_once(timeout_sec=min(0.05, max(end - time.monotonic(), 0.0)))
        return until is not None and bool(until())


def _graph(session, pdplus: str):
    """(pdplus on the graph, its Trigger services (short names), the drives' ~/reset)."""
    from irb_bringup.ctl_core import DRIVES, join_name, split_node
    node = session.node
    ns, name = split_node(pdplus)
    seen = (name, ns) in node.get_node_names_and_namespaces()
    services = dict(node.get_service_names_and_types())
    trigger = 'std_srvs/srv/Trigger'
    prefix = join_name(ns, name) + '/'
    own = sorted(s[len(prefix):] for s, t in services.items()
                 if s.startswith(prefix) and trigger in t and '/' not in s[len(prefix):])
    drives = [join_name(ns, f'{d}/reset') for d in DRIVES
              if trigger in services.get(join_name(ns, f'{d}/reset'), [])]
    return seen, own, drives


def _discover(session, pdplus: str, timeout: float, ready):
    """Watch the graph until ``ready(found, settled)`` (``found``: what _graph returns,
    ``settled``: unchanged for SETTLE_S [s]; discovery brings services one by one, slowly on
    a loaded host), at most ``timeout`` [s]; return the last ``found``."""
    end = time.monotonic() + timeout
    last, since = None, time.monotonic()
    while True:
        now = time.monotonic()
        found = _graph(session, pdplus)
        if found != last:
            last, since = found, now
        if ready(found, now - since >= SETTLE_S) or now >= end:
            return found
        session.spin_for(0.05)


def _ready(command: str):
    """When the graph has shown enough for ``command``."""
    from irb_bringup.ctl_core import PDPLUS_SERVICES

    def ready(found, settled):
        seen, services, drives = found
        if command == 'status':
            return seen and settled
        if command == 'reset':         # the drive's reset, and pdplus's if it has one
            return bool(drives) and (settled or 'reset' in services)
        wanted = PDPLUS_SERVICES[command]
        return seen and (wanted in services
                         or (settled and {'enable', 'stop'} <= set(services)))
    return ready


def _to_dict(msg, fields) -> dict:
    return {f: getattr(msg, f) for f in fields}


def status(a, ros_args) -> int:
    from irb_bringup import ctl_core as core
    from irb_interfaces.msg import AxisStatus, ControllerState, PlanStatus
    from irb_description.node_main import latched_qos
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState
    s = _Session(ros_args)
    try:
        ns, _ = core.split_node(a.pdplus)
        pdplus = core.join_name(*core.split_node(a.pdplus))
        arrivals = {t: [] for t in core.MAIN_TOPICS}
        last = {}
        types = {'joint_states': JointState, 'torque_command': JointState,
                 'controller_state': ControllerState}

        def on_raw(topic):
            def cb(data):
                arrivals[topic].append(time.monotonic())
                if topic == 'controller_state':
                    last['controller_state'] = data
            return cb
        subs = [s.node.create_subscription(types[t], core.join_name(ns, t), on_raw(t),
                                           qos_profile_sensor_data, raw=True)
                for t in core.MAIN_TOPICS]
        subs.append(s.node.create_subscription(
            PlanStatus, core.join_name(pdplus, 'plan_status'),
            lambda m: last.__setitem__('plan', m), latched_qos()))
        subs.append(s.node.create_subscription(
            AxisStatus, core.join_name(ns, 'axis_status'),
            lambda m: last.__setitem__('axis', m), latched_qos()))

        def matched():
            """Every topic's publishers on the graph are matched by our subscription (the
            rates start only then: matching takes seconds on a loaded host)."""
            return all(sub.get_publisher_count() >= s.node.count_publishers(sub.topic_name)
                       for sub in subs)
        latched = {'plan': core.join_name(pdplus, 'plan_status'),
                   'axis': core.join_name(ns, 'axis_status')}

        matched_at = []

        def latched_in():
            """Every latched topic that has a publisher has delivered its last message
            (matching alone does not mean the transient-local sample has arrived yet), or
            LATCHED_WAIT_S has passed since everything matched: a publisher that has published
            nothing yet (pdplus before its first plan) delivers nothing to wait for."""
            if all(key in last or s.node.count_publishers(topic) == 0
                   for key, topic in latched.items()):
                return True
            if not matched_at:
                matched_at.append(time.monotonic())
            return time.monotonic() - matched_at[0] >= min(LATCHED_WAIT_S, a.timeout)
        seen, services, drives = _discover(
            s, a.pdplus, a.timeout,
            lambda found, settled: (_ready('status')(found, settled) and matched()
                                    and latched_in()))
        for times in arrivals.values():
            times.clear()
        s.spin_for(a.window)
        snap = core.Snapshot(pdplus=pdplus, pdplus_seen=seen, services=services,
                             drive_resets=drives, window_s=a.window,
                             rates=[core.topic_rate(core.join_name(ns, t), arrivals[t])
                                    for t in core.MAIN_TOPICS])
        if 'controller_state' in last:
            msg = deserialize_message(last['controller_state'], ControllerState)
            snap.controller = _to_dict(msg, ('mode', 'stop_reason', 'missed_deadlines',
                                             'rejected_inputs'))
        if 'plan' in last:
            snap.plan = _to_dict(last['plan'], ('accepted', 'reason', 'points', 'duration',
                                                'accepted_count', 'refused_count'))
        if 'axis' in last:
            snap.axis = _to_dict(last['axis'], ('motors_on', 'brakes_engaged', 'error',
                                                'error_text', 'source'))
    finally:
        s.close()
    print(core.format_status(snap))
    code = core.status_code(snap)
    if code != core.OK:
        print(f'pdplus {pdplus} not found within {a.timeout:g} s (is the graph running, '
              'with the same ROS_DOMAIN_ID?)', file=sys.stderr)
    return code


def trigger(a, ros_args) -> int:
    """Call the Trigger service(s) of ``a.command``; print each answer."""
    from irb_bringup import ctl_core as core
    from irb_planning.service_call import call_service
    from std_srvs.srv import Trigger
    s = _Session(ros_args)
    try:
        seen, services, drives = _discover(s, a.pdplus, a.timeout, _ready(a.command))
        if a.command == 'enable' and a.wait and seen and 'enable' in services:
            return _enable_and_wait(s, a)
    finally:
        s.close()
    pdplus = core.join_name(*core.split_node(a.pdplus))
    if a.command == 'reset':
        targets = core.reset_services(services, pdplus, drives)
        if not targets:
            print('reset: no ~/reset service on the graph (neither pdplus nor a simulator or '
                  f'axis_bridge in its namespace) within {a.timeout:g} s', file=sys.stderr)
            return core.UNAVAILABLE
    else:
        if not seen:
            print(f'{a.command}: {pdplus} not found within {a.timeout:g} s (is the graph '
                  'running, with the same ROS_DOMAIN_ID?)', file=sys.stderr)
            return core.UNAVAILABLE
        if core.PDPLUS_SERVICES[a.command] not in services:
            print(core.missing_service_text(a.command, pdplus, services), file=sys.stderr)
            return core.UNAVAILABLE
        targets = [core.join_name(pdplus, core.PDPLUS_SERVICES[a.command])]
    worst = core.OK
    for service in targets:
        def answered(resp, service=service):
            code, text = core.trigger_outcome(a.command, service, resp.success, resp.message)
            print(text, file=sys.stdout if code == core.OK else sys.stderr)
            return code
        code = call_service(Trigger, service, Trigger.Request(), a.timeout, '_irb_ctl',
                            answered, ['ctl', *ros_args])
        worst = max(worst, code)
    return worst


class _ModeFollower:
    """The ``wait_outcome`` of pdplus's /controller_state, message by message."""

    def __init__(self, session, pdplus: str, target: str, after_motion: bool | None = None):
        from irb_bringup import ctl_core as core
        from irb_interfaces.msg import ControllerState
        from rclpy.qos import qos_profile_sensor_data
        self.core, self.target, self.after_motion = core, target, after_motion
        self.moving, self.code, self.mode, self.reason = False, None, None, ''
        ns, _ = core.split_node(pdplus)
        self.sub = session.node.create_subscription(
            ControllerState, core.join_name(ns, 'controller_state'), self.on_state,
            qos_profile_sensor_data)

    def on_state(self, msg):
        from irb_control.pd_plus import MODE_NAMES
        if self.code is not None:
            return
        name = MODE_NAMES.get(msg.mode, str(msg.mode))
        if name not in self.core.RESTING:
            self.moving = True
        self.mode, self.reason = name, msg.stop_reason
        self.code = self.core.wait_outcome(self.target, msg.mode, msg.stop_reason,
                                           self.moving, self.after_motion)

    def verdict(self, timeout: float) -> int:
        core = self.core
        if self.code == core.OK:
            print(f'pdplus: {self.target}')
            return core.OK
        if self.code == core.REFUSED:
            print(f'pdplus stopped: {self.reason or "(no reason given)"} '
                  '(ctl status; ctl enable to go on)', file=sys.stderr)
            return core.REFUSED
        seen = f'last mode {self.mode}' if self.mode else 'no /controller_state'
        print(f'wait {self.target}: not reached within {timeout:g} s ({seen})',
              file=sys.stderr)
        return core.UNAVAILABLE


def _enable_and_wait(s, a) -> int:
    """enable --wait: follow /controller_state from before the call, so a short motion cannot
    end before the wait begins; done when pdplus rests again (hold, or idle) after moving."""
    from irb_bringup import ctl_core as core
    from std_srvs.srv import Trigger
    pdplus = core.join_name(*core.split_node(a.pdplus))
    follow = {'hold': _ModeFollower(s, a.pdplus, 'hold', after_motion=True),
              'idle': _ModeFollower(s, a.pdplus, 'idle', after_motion=True)}
    client = s.node.create_client(Trigger, core.join_name(pdplus, 'enable'))
    if not client.wait_for_service(timeout_sec=a.timeout):
        print(f'service {pdplus}/enable not available', file=sys.stderr)
        return core.UNAVAILABLE
    future = client.call_async(Trigger.Request())
    if not s.spin_for(a.timeout, until=future.done):
        print(f'enable: no answer from {pdplus}/enable within {a.timeout:g} s',
              file=sys.stderr)
        return core.UNAVAILABLE
    resp = future.result()
    code, text = core.trigger_outcome('enable', f'{pdplus}/enable', resp.success,
                                      resp.message)
    print(text, file=sys.stdout if code == core.OK else sys.stderr, flush=True)
    if code != core.OK:
        return code
    s.spin_for(a.motion_timeout,
               until=lambda: any(f.code is not None for f in follow.values()))
    done = [f for f in follow.values() if f.code is not None]
    return (done[0] if done else follow['hold']).verdict(a.motion_timeout)


def wait(a, ros_args) -> int:
    """Follow pdplus's /controller_state until ``wait_outcome`` decides (bounded)."""
    s = _Session(ros_args)
    try:
        follow = _ModeFollower(s, a.pdplus, a.mode)
        s.spin_for(a.timeout, until=lambda: follow.code is not None)
    finally:
        s.close()
    return follow.verdict(a.timeout)


def main(args=None):
    argv = list(sys.argv[1:] if args is None else args)
    mine, ros_args = _split_ros_args(argv)
    a = parse_args(mine)
    if a.wait and a.command != 'enable':
        print('ctl: --wait goes with enable (ctl enable --wait)', file=sys.stderr)
        return 2
    if a.timeout <= 0 or a.window <= 0 or a.motion_timeout <= 0:
        print('ctl: --timeout, --window and --motion-timeout must be > 0', file=sys.stderr)
        return 2
    if (a.command == 'wait') != bool(a.mode):
        print('ctl: a mode goes with wait and only with wait (ctl wait hold)', file=sys.stderr)
        return 2
    if a.command == 'wait' and a.mode not in ('idle', 'ramp', 'path', 'time', 'hold',
                                               'stopped'):
        print(f'ctl wait: unknown mode {a.mode!r} (idle, ramp, path, time, hold, stopped)',
              file=sys.stderr)
        return 2
    try:
        if a.command == 'status':
            return status(a, ros_args)
        if a.command == 'wait':
            return wait(a, ros_args)
        return trigger(a, ros_args)
    except KeyboardInterrupt:
        return 130


if __name__ == '__main__':
    sys.exit(main())
