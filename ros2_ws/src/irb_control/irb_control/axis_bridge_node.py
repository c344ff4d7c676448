"""`ros2 run irb_control axis_bridge`: the axis computer's UDP torque protocol <-> ROS.

Receives STATE packets (only from the configured axis computer address and port; others are
dropped and counted), publishes /joint_states exactly as the simulator does (stamped with this
host's ROS clock at reception, so that pdplus can judge its age) and the drives' status on
/axis_status, and answers each state with the controller's /torque_command carrying the
state's sequence number and session (logic in axis_bridge_core.BridgeCore, protocol in
doc/axis_protocol.md).
"""
from __future__ import annotations

import socket
import threading
import time

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from irb_description.model import RobotModel
from irb_description.node_help import NodeSpec, Param, Topic
from irb_description.node_main import (declare_params, latched_qos, run_node, state_pub_qos,
                                       state_qos)
from irb_description.robot_state import six_joint_names, six_joints
from irb_interfaces.msg import AxisStatus
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from .axis_bridge_core import BridgeCore
from .axis_protocol import MODE_NAMES, MODE_TORQUE, error_text
from .node_util import (REALTIME_PARAMS, LogThread, declare_realtime, short_switch_interval,
                        spin_with)


SPEC = NodeSpec(
    'axis_bridge', 'irb_control',
    "Connects pdplus to a real (or fake) axis computer over the UDP torque protocol "
    "(doc/axis_protocol.md): STATE packets -> /joint_states and /axis_status; each state is "
    "answered with the latest /torque_command that carries that state's stamp (any other is "
    "refused, counted and logged), within one cycle. Always real time (the axis computer is "
    "the clock master).",
    params=(
        Param('bind_address', '127.0.0.1', '', 'local address for STATE packets'),
        Param('state_port', 6510, '', 'local UDP port for STATE packets'),
        Param('axis_address', '127.0.0.1', '', 'axis computer address for COMMAND packets '
              '(the only peer trusted)'),
        Param('command_port', 6511, '', "axis computer's UDP port for COMMAND packets"),
        Param('link_timeout_s', 0.1, 's', 'no valid state for longer: link lost'),
        Param('max_command_age_s', 0.004032, 's', 'never send a command for a state older '
              'than this'),
        Param('status_period_s', 0.5, 's', 'period of /axis_bridge/status and /axis_status'),
        Param('seq_window', 250, 'cycles', 'states further ahead in sequence are a jump, '
              'adopted only after resync_confirm in a row'),
        Param('resync_confirm', 3, '', 'consecutive states of a new session (or after a '
              'jump) before the bridge follows it'),
        Param('executor', 'events', '', "'events' (rclpy EventsExecutor, faster) or 'single'"),
        *REALTIME_PARAMS),
    subscribes=(Topic('torque_command', 'sensor_msgs/JointState',
                      'effort [N m], header.stamp = the answered state'),),
    publishes=(Topic('joint_states', 'sensor_msgs/JointState', 'q, qd, measured torque'),
               Topic('axis_status', 'irb_interfaces/AxisStatus', 'drives (latched)'),
               Topic('axis_bridge/status', 'diagnostic_msgs/DiagnosticArray',
                     'link, counters')),
    services=(Topic('~/reset', 'std_srvs/Trigger', 'commands carry reset = 1 until the axis '
                    'computer reports no error'),),
    example='ros2 run irb_control axis_bridge --ros-args -p axis_address:=192.168.125.1')


class AxisBridge(Node):
    """UDP socket thread for states, subscription for commands, timer for link supervision."""

    def __init__(self, **kwargs):
        super().__init__('axis_bridge', **kwargs)
        P = declare_params(self, [x for x in SPEC.params if x not in REALTIME_PARAMS])
        self.bind_address, self.state_port = P['bind_address'], P['state_port']
        self.axis_address, self.command_port = P['axis_address'], P['command_port']
        link_timeout, max_age = P['link_timeout_s'], P['max_command_age_s']
        status_period, window = P['status_period_s'], P['seq_window']
        confirm, self.executor_kind = P['resync_confirm'], P['executor']
        self.realtime = declare_realtime(self)       # (priority, cpus, latency): main
        self.log = LogThread(lambda: self.get_logger())      # lines of the command path
        self.core = BridgeCore(link_timeout, max_age, window, confirm)
        self.peer = (self.axis_address, self.command_port)
        self.joint_names = RobotModel.load().joint_names
        self.lock = threading.Lock()
        self.last_key: int | None = None
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((self.bind_address, self.state_port))
        self.sock.settimeout(0.05)
        self.pub_state = self.create_publisher(JointState, 'joint_states', state_pub_qos())
        self.pub_status = self.create_publisher(DiagnosticArray, 'axis_bridge/status', 10)
        self.pub_axis = self.create_publisher(AxisStatus, 'axis_status', latched_qos())
        self._axis_key = None
        self.create_subscription(JointState, 'torque_command', self.on_command, state_qos())
        self.create_service(Trigger, '~/reset', self.on_reset)
        self.create_timer(0.02, self.on_timer)
        self.create_timer(status_period, self.publish_status)
        self.running = True
        self.rx = threading.Thread(target=self.receive_loop, daemon=True)
        self.rx.start()
        self.get_logger().info(
            f'axis_bridge: states on {self.bind_address}:{self.state_port}, commands to '
            f'{self.axis_address}:{self.command_port}')

    def receive_loop(self) -> None:
        while self.running:
            try:
                data, source = self.sock.recvfrom(2048)
            except socket.timeout:
                continue
            except OSError:
                return
            if source != self.peer:
                with self.lock:
                    self.core.stats.rejected['foreign_peer'] += 1
                continue
            stamp_ns = self.get_clock().now().nanoseconds
            with self.lock:
                state, event = self.core.on_datagram(data, time.monotonic())
                if state is not None:
                    self.last_key = stamp_ns
                # a requested reset reaches the axis computer also while no controller
                # commands (pdplus is stopped after the fault that latched the error)
                reset = self.core.reset_command(time.monotonic())
            if reset is not None:
                self.sock.sendto(reset, self.peer)
            if event:
                self.get_logger().info(f'link {event}: states arriving (seq {state.seq}, '
                                       f'session {state.session:#010x})')
            if state is not None:
                self._axis_status(state)
                msg = JointState()
                msg.header.stamp = Time(sec=stamp_ns // 1_000_000_000,
                                        nanosec=stamp_ns % 1_000_000_000)
                # all six joints, as the axis computer reports them
                msg.name = list(six_joint_names())
                msg.position, msg.velocity, msg.effort = six_joints(state.q, state.qd, state.tau)
                self.pub_state.publish(msg)

    def _axis_status(self, state, force: bool = False) -> None:
        """/axis_status from the axis computer's own report, on change (and periodically)."""
        key = (state.motors_on, state.mode, state.error)
        if key == self._axis_key and not force:
            return
        self._axis_key = key
        m = AxisStatus(motors_on=bool(state.motors_on), brakes_engaged=not state.motors_on,
                       error=int(state.error), error_text=error_text(state.error),
                       source='axis_bridge')
        m.header.stamp = self.get_clock().now().to_msg()
        self.pub_axis.publish(m)
        if state.error:
            self.get_logger().error(f'axis computer error {state.error:#x}: '
                                    f'{m.error_text} (reset with ~/reset)')
        elif state.mode != MODE_TORQUE and not state.motors_on:
            self.get_logger().info('axis computer idle on its brakes')

    def on_command(self, msg: JointState) -> None:
        key = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        tau = np.zeros(6)
        try:
            idx = [list(msg.name).index(n) for n in self.joint_names] if msg.name else [0, 1, 2]
            tau[:3] = [msg.effort[i] for i in idx]
        except (ValueError, IndexError):
            tau[:] = np.nan                       # counted and never sent by the core
        with self.lock:
            if key != self.last_key:              # answers an older state: too late
                self.core.stats.late_commands += 1
                newest = self.last_key
                self.log.warn(
                    f'torque_command refused ({self.core.stats.late_commands} late so far): it '
                    f'answers the state stamped {key * 1e-9:.6f} s, '
                    + (f'{(newest - key) * 1e-6:.1f} ms older than the newest state'
                       if newest is not None and key < newest else 'not the newest state'),
                    throttle_s=1.0, key='late')
                return
            data = self.core.on_command(tau, time.monotonic(), key)
        if data is not None:
            self.sock.sendto(data, self.peer)

    def on_reset(self, request, response):
        with self.lock:
            self.core.request_reset()
        response.success = True
        response.message = 'commands carry reset = 1 until the axis computer reports no error'
        return response

    def on_timer(self) -> None:
        with self.lock:
            event = self.core.check_link(time.monotonic())
        if event == 'lost':
            self.get_logger().error(
                f'link lost: no valid state for {self.core.link_timeout_s} s; sending nothing '
                'until states return')

    def publish_status(self) -> None:
        with self.lock:
            s = self.core.stats
            st = self.core.last_state
            values = {'link_up': self.core.link_up, 'states': s.states,
                      'commands_sent': s.commands_sent, 'late_commands': s.late_commands,
                      'unanswered': s.unanswered, 'link_losses': s.link_losses,
                      **{f'rejected_{k}': v for k, v in s.rejected.items()}}
            values['resyncs'] = s.resyncs
            if st is not None:
                values.update(axis_seq=st.seq, axis_session=f'{st.session:#010x}',
                              axis_motors_on=st.motors_on,
                              axis_mode=MODE_NAMES.get(st.mode, str(st.mode)),
                              axis_error=st.error)
        level = (DiagnosticStatus.OK if values['link_up'] and not values.get('axis_error')
                 else DiagnosticStatus.ERROR)
        status = DiagnosticStatus(level=level, name='axis_bridge', hardware_id='axis_computer',
                                  message='link up' if values['link_up'] else 'link down',
                                  values=[KeyValue(key=k, value=str(v))
                                          for k, v in values.items()])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_status.publish(msg)
        if st is not None:
            self._axis_status(st, force=True)

    def destroy_node(self):
        self.running = False
        self.sock.close()
        self.rx.join(timeout=1.0)
        return super().destroy_node()


def main(args=None):
    short_switch_interval()
    run_node(AxisBridge, lambda node: spin_with(node.executor_kind, node.realtime)(node), args,
             spec=SPEC)


if __name__ == '__main__':
    main()
