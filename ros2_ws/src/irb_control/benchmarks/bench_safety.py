#!/usr/bin/env python3
"""Safety benchmarks of the control path (issue 14); each prints JSON and writes it to results/.

    python benchmarks/bench_safety.py plans              # step latency while big plans arrive
    python benchmarks/bench_safety.py soak --minutes 30 [--path sim|axis] [--load]

plans: simulator (real time) + pdplus on the built-in 10 s circle, repeated; 20 s without
plans, then 20 s during which plans of 2 000, 20 000 and 200 000 points arrive on
/planned_trajectory (published by a separate process). Reported from pdplus's own
ControllerState (step_duration: its compute time per step) and from the simulator's statistics
(state -> command round trip, missed deadlines, stale commands): p50/p99/max of each window,
stops, brakes. Goal: p99 and max unchanged within noise; no stop, brake or comm timeout.

soak: the graph runs continuously (simulator + pdplus + recorder, or fake axis computer +
axis bridge + pdplus + recorder); a driver enables pdplus again after every motion; every stop
is recorded with its reason (and the drives are reset). ``--load`` adds a process that keeps one
core busy. Result: stops per hour, by reason.

Needs `source scripts/env.sh`; ROS_DOMAIN_ID / ROS_AUTOMATIC_DISCOVERY_RANGE as you want them.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / 'results'


def _write(name: str, data: dict) -> dict:
    RESULTS.mkdir(parents=True, exist_ok=True)
    data['load_average_1_5_15_min_at_end'] = [round(x, 2) for x in os.getloadavg()]
    data['machine_cores'] = os.cpu_count()
    text = json.dumps(data, indent=2)
    (RESULTS / f'{name}.json').write_text(text + '\n')
    print(text)
    return data


def _free_udp_ports(n):
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(n)]
    for s in socks:
        s.bind(('127.0.0.1', 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


class Graph:
    """Processes (`ros2 run`, own sessions, output to log files) and a driver node."""

    def __init__(self, name: str):
        import rclpy
        from irb_interfaces.msg import AxisStatus, ControllerState
        from rclpy.executors import SingleThreadedExecutor

        from irb_description.node_main import latched_qos, state_qos
        self.ns = f'/{name}{uuid.uuid4().hex[:6]}'
        self.logdir = Path(tempfile.mkdtemp(prefix=f'{name}_'))
        self.procs = {}
        self.rclpy = rclpy
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node(f'{name}_driver', namespace=self.ns, context=self.ctx)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.states, self.axis = [], None
        self.node.create_subscription(ControllerState, 'controller_state', self.states.append,
                                      state_qos(), raw=True)
        self.node.create_subscription(AxisStatus, 'axis_status',
                                      lambda m: setattr(self, 'axis', m), latched_qos())

    def start(self, name, package, exe, *params, extra=()):
        cmd = ['ros2', 'run', package, exe, *extra, '--ros-args', '-r', f'__ns:={self.ns}',
               *[x for p in params for x in ('-p', p)]]
        log = open(self.logdir / f'{name}.log', 'w')
        self.procs[name] = (subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                             start_new_session=True), log)

    def spin(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.02)

    def until(self, cond, timeout):
        end = time.monotonic() + timeout
        while not cond() and time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.02)
        return cond()

    def call(self, service, timeout=10.0):
        from std_srvs.srv import Trigger
        cli = self.node.create_client(Trigger, service)
        try:
            if not cli.wait_for_service(timeout_sec=timeout):
                return None
            fut = cli.call_async(Trigger.Request())
            self.until(fut.done, timeout)
            return fut.result() if fut.done() else None
        finally:
            self.node.destroy_client(cli)

    def close(self):
        for p, log in self.procs.values():
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGINT)
        for p, log in self.procs.values():
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
            log.close()
        self.ex.shutdown()
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.ctx)


def _decode(states):
    from irb_interfaces.msg import ControllerState
    from rclpy.serialization import deserialize_message
    return [deserialize_message(b, ControllerState) for b in states]


def _stats(x):
    x = np.asarray(x, float)
    if not x.size:
        return None
    return {'n': int(x.size), 'p50': float(np.percentile(x, 50)),
            'p99': float(np.percentile(x, 99)), 'max': float(x.max())}


# --- plans ------------------------------------------------------------------------------------
PUBLISHER = r'''
import sys, time
import numpy as np
import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
ns, sizes = sys.argv[1], [int(x) for x in sys.argv[2].split(',')]
rclpy.init()
node = rclpy.create_node('big_plans', namespace=ns)
pub = node.create_publisher(JointTrajectory, 'planned_trajectory', QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL))
data = []
for n in sizes:               # a slow sine on joint 1 from the circle's start, n points
    msg = JointTrajectory(joint_names=['joint_1', 'joint_2', 'joint_3'])
    t = np.linspace(0.0, 60.0, n)
    for k in range(n):
        p = JointTrajectoryPoint(positions=[0.05 * np.sin(0.1 * t[k]), 0.9, 0.25],
                                 velocities=[0.005 * np.cos(0.1 * t[k]), 0.0, 0.0],
                                 accelerations=[-0.0005 * np.sin(0.1 * t[k]), 0.0, 0.0])
        p.time_from_start.sec = int(t[k])
        p.time_from_start.nanosec = int(round((t[k] % 1) * 1e9))
        msg.points.append(p)
    data.append(serialize_message(msg))
print('ready', flush=True)
sys.stdin.readline()
for n, d in zip(sizes, data):
    pub.publish(d)
    print(f'published {n}', flush=True)
    t_end = time.monotonic() + 5.0
    while time.monotonic() < t_end:
        rclpy.spin_once(node, timeout_sec=0.1)
sys.stdin.readline()
'''


def _plans_run(window_s: float, sizes: list[int] | None) -> dict:
    """One graph: enable the circle, then ``window_s`` s (with plans published from a separate
    process right after the enable if ``sizes``); pdplus's and the simulator's figures."""
    g = Graph('plans')
    pub = None
    if sizes:
        pub = subprocess.Popen([sys.executable, '-c', PUBLISHER, g.ns,
                                ','.join(map(str, sizes))], stdin=subprocess.PIPE,
                               stdout=subprocess.PIPE, text=True, start_new_session=True)
    stats = g.logdir / 'sim_stats.json'
    try:
        g.start('simulator', 'irb_control', 'simulator', 'mode:=realtime', f'stats_path:={stats}')
        g.start('pdplus', 'irb_control', 'pdplus', 'profile_duration_s:=30.0',
                'auto_enable:=false')
        if pub is not None:
            assert pub.stdout.readline().strip() == 'ready'
        assert g.until(lambda: g.axis is not None and g.states, 60), 'graph did not come up'
        res = g.call('pdplus/enable')
        assert res is not None and res.success, res
        g.spin(1.0)                                 # into the ramp and the path
        n0 = len(g.states)
        if pub is not None:
            pub.stdin.write('\n')
            pub.stdin.flush()
        g.spin(window_s)
        st = _decode(g.states[n0:])
    finally:
        g.close()
        if pub is not None:
            if pub.poll() is None:
                os.killpg(pub.pid, signal.SIGKILL)
            pub.wait()
    logs = (g.logdir / 'pdplus.log').read_text()
    return {'step_duration_ms': _stats([s.step_duration * 1e3 for s in st]),
            'stops': sorted({s.stop_reason for s in st if s.mode == 4}),
            'modes_seen': sorted({int(s.mode) for s in st}),
            'simulator': json.loads(stats.read_text()),
            'plan_verdicts': [ln.split(']: ', 1)[-1] for ln in logs.splitlines()
                              if 'planned_trajectory' in ln]}


def bench_plans(window_s: float = 20.0) -> dict:
    sizes = [2000, 20000, 200000]
    out = {'benchmark': 'pdplus while plans of 2k, 20k, 200k points arrive (two runs of the '
                        'same graph: without, and with the plans published during the path)',
           'window_s': window_s, 'plan_sizes': sizes,
           'no plans': _plans_run(window_s, None),
           'plans arriving': _plans_run(window_s, sizes)}
    a, b = (out[k]['simulator']['latency_ms'] for k in ('no plans', 'plans arriving'))
    out['round_trip_ratio_p99'] = b['p99'] / a['p99']
    out['round_trip_ratio_max'] = b['max'] / a['max']
    return _write('plans_arriving', out)


# --- soak -------------------------------------------------------------------------------------
def bench_soak(minutes: float, path: str, load: bool, rt: int = 0,
               latency_us: int = -1) -> dict:
    g = Graph('soak')
    rtp = ((f'realtime_priority:={rt}',) if rt else ()) + (
        (f'cpu_dma_latency_us:={latency_us}',) if latency_us >= 0 else ())
    loader = None
    if load:
        loader = subprocess.Popen([sys.executable, '-c', 'while True: pass'],
                                  start_new_session=True)
    bagroot = Path(tempfile.mkdtemp(prefix='soak_bags_'))
    sim_stats = bagroot / 'simulator_stats.json'
    load_start = [round(x, 2) for x in os.getloadavg()]
    out = None
    try:
        if path == 'axis':
            sp, cp = _free_udp_ports(2)
            g.start('axis', 'irb_control', 'fake_axis_computer', f'state_port:={sp}',
                    f'command_port:={cp}')
            g.start('bridge', 'irb_control', 'axis_bridge', f'state_port:={sp}',
                    f'command_port:={cp}', *rtp)
            reset = 'axis_bridge/reset'
        else:
            g.start('simulator', 'irb_control', 'simulator', 'mode:=realtime',
                    f'stats_path:={sim_stats}', *rtp)
            reset = 'simulator/reset'
        g.start('pdplus', 'irb_control', 'pdplus', 'profile_duration_s:=10.0',
                'auto_enable:=false', *rtp)
        g.start('recorder', 'irb_identification', 'recorder', f'root:={bagroot}',
                'name:=soak', 'split_period_s:=5.0')
        assert g.until(lambda: g.axis is not None and g.states, 90), 'graph did not come up'
        stops, motions = [], 0
        t0 = time.monotonic()
        end = t0 + 60.0 * minutes
        from irb_interfaces.msg import ControllerState
        from rclpy.serialization import deserialize_message
        while time.monotonic() < end:
            if g.axis is not None and g.axis.error:
                g.call(reset)
                g.until(lambda: not g.axis.error, 10)
            res = g.call('pdplus/enable')
            if res is None or not res.success:
                g.spin(0.5)
                continue
            motions += 1
            n0 = len(g.states)
            last = [None]

            def done():
                for b in g.states[max(n0, len(g.states) - 5):]:
                    last[0] = deserialize_message(b, ControllerState)
                return (last[0] is not None and len(g.states) - n0 > 300
                        and last[0].mode in (4, 5))
            g.until(lambda: done() or time.monotonic() > end, 60)
            if last[0] is not None and last[0].mode == 4:
                stops.append({'t_s': round(time.monotonic() - t0, 1),
                              'reason': last[0].stop_reason})
            del g.states[:]
        hours = (time.monotonic() - t0) / 3600
        reasons = {}
        for s in stops:
            key = s['reason'].split(':')[0]
            reasons[key] = reasons.get(key, 0) + 1
        out = {'benchmark': f'soak: {path} path + pdplus + recorder, enabled again after '
                            'every motion', 'minutes': minutes, 'path': path,
               'cpu_load_process': load, 'realtime_priority': rt,
               'cpu_dma_latency_us': latency_us, 'motions': motions,
               'stops': len(stops),
               'stops_per_hour': len(stops) / hours if hours else None,
               'stops_by_reason': reasons, 'stop_list': stops[:50],
               'load_average_1_5_15_min_at_start': load_start}
    finally:
        if loader is not None:
            os.killpg(loader.pid, signal.SIGKILL)
            loader.wait()
        g.close()
        if out is not None and sim_stats.exists():
            # the simulator's own view: how late its states went out (a stalled simulator
            # process is a gap the watchdog sees), late commands it ignored
            out['simulator'] = json.loads(sim_stats.read_text())
        subprocess.run(['rm', '-rf', str(bagroot)])
    return _write(f'soak_{path}{"_loaded" if load else ""}{f"_rt{rt}" if rt else ""}'
                  f'{f"_lat{latency_us}" if latency_us >= 0 else ""}', out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest='what', required=True)
    p = sub.add_parser('plans')
    p.add_argument('--window-s', type=float, default=20.0)
    s = sub.add_parser('soak')
    s.add_argument('--minutes', type=float, default=30.0)
    s.add_argument('--path', choices=('sim', 'axis'), default='sim')
    s.add_argument('--load', action='store_true', help='keep one core busy meanwhile')
    s.add_argument('--realtime-priority', type=int, default=0,
                   help='SCHED_FIFO priority for the loop nodes (0 = normal scheduling)')
    s.add_argument('--cpu-dma-latency-us', type=int, default=-1,
                   help='the loop nodes\' cpu_dma_latency_us (-1 = leave alone, 0 = no deep '
                        'idle)')
    a = ap.parse_args()
    if a.what == 'plans':
        bench_plans(a.window_s)
    else:
        bench_soak(a.minutes, a.path, a.load, a.realtime_priority, a.cpu_dma_latency_us)


if __name__ == '__main__':
    main()
