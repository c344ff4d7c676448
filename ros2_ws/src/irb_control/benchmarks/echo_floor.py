#!/usr/bin/env python3
"""The transport's floor for the 248 Hz loop: a bare rclpy echo between two processes.

    python benchmarks/echo_floor.py [--seconds 20]          # prints JSON (also used by
                                                              # run_benchmarks.py loop)

The same shape as the control loop without any of its work: this process publishes a
serialized sensor_msgs/JointState (3 joints) every 4.032 ms on the steady clock and waits for
its echo; a child process (``--echo``) takes each message raw and publishes the same bytes
back. Same QoS (irb_description.node_main.state_qos), same executor (EventsExecutor driven by
spin_once) and the same raw (serialized) path as simulator and pdplus. Reported: round trip
p50/p99/max [ms] and echoes missing before the next tick. ``run_benchmarks.py loop`` measures
it in the same run as the loop, so that "p99 loop / p99 echo" compares like with like on a
machine whose state moves p99 by +-0.2 ms.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

PERIOD_S = 0.004032


def _echo(ns: str) -> None:
    """Child: /ping (raw) -> /pong (the same bytes), until SIGINT/SIGTERM."""
    import rclpy
    from irb_description.node_main import init, running, state_qos
    from sensor_msgs.msg import JointState

    from irb_control.node_util import make_executor
    init()
    node = rclpy.create_node('echo', namespace=ns)
    pub = node.create_publisher(JointState, 'pong', state_qos())
    node.create_subscription(JointState, 'ping', pub.publish, state_qos(), raw=True)
    ex = make_executor('events')
    ex.add_node(node)
    print('echo: ready', flush=True)
    try:
        while running():
            ex.spin_once(timeout_sec=0.1)
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


def measure(seconds: float = 20.0) -> dict:
    """Round trips of ``seconds`` at 248 Hz against an echo child process (rclpy must not be
    initialised in this process yet; it is shut down again at the end)."""
    import rclpy
    from irb_description.node_main import state_qos
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from irb_control.node_util import make_executor
    from irb_control.process_group import stop_sessions
    ns = f'/echo{os.getpid()}'
    child = subprocess.Popen([sys.executable, __file__, '--echo', ns], stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True, start_new_session=True)
    rclpy.init()
    node = rclpy.create_node('ping', namespace=ns)
    pub = node.create_publisher(JointState, 'ping', state_qos())
    sent: dict[int, float] = {}
    rtt: list[float] = []
    late = [0]

    def on_pong(data: bytes) -> None:
        k = int.from_bytes(data[4:8], 'little')          # header.stamp.sec = sequence
        t = sent.pop(k, None)
        if t is not None:
            rtt.append(time.monotonic() - t)
    node.create_subscription(JointState, 'pong', on_pong, state_qos(), raw=True)
    ex = make_executor('events')
    ex.add_node(node)
    msg = JointState(name=['joint_1', 'joint_2', 'joint_3'], position=[0.1, 0.2, 0.3],
                     velocity=[0.0, 0.0, 0.0], effort=[1.0, 2.0, 3.0])
    try:
        assert child.stdout.readline().startswith('echo: ready'), 'echo child did not start'
        end = time.monotonic() + 30.0                    # discovery: until the first echo
        while pub.get_subscription_count() == 0 and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        k = 0
        t0 = next_tick = time.monotonic()
        warm = 1.0                                        # first second not counted
        while next_tick - t0 < seconds + warm:
            now = time.monotonic()
            if now < next_tick:
                ex.spin_once(timeout_sec=next_tick - now)
                continue
            if sent and next_tick - t0 > warm:
                late[0] += len(sent)                      # not back before this tick
            sent.clear()
            if next_tick - t0 <= warm:
                rtt.clear()
            k += 1
            msg.header.stamp.sec = k
            data = serialize_message(msg)
            sent[k] = time.monotonic()
            pub.publish(data)
            next_tick += PERIOD_S
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
        stop_sessions([child], 20.0)
    x = np.array(rtt) * 1e3
    ticks = int(seconds / PERIOD_S)
    return {'benchmark': 'bare rclpy echo, 2 processes, raw JointState, 248 Hz',
            'round_trip_ms': {'n': int(x.size), 'p50': float(np.percentile(x, 50)),
                              'p99': float(np.percentile(x, 99)), 'max': float(x.max())},
            'missed_fraction': late[0] / max(ticks, 1),
            'load_average_1_5_15_min_at_end': [round(v, 2) for v in os.getloadavg()]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seconds', type=float, default=20.0)
    ap.add_argument('--echo', metavar='NAMESPACE', help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.echo:
        _echo(a.echo)
    else:
        print(json.dumps(measure(a.seconds), indent=2))


if __name__ == '__main__':
    main()
