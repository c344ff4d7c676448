#!/usr/bin/env python3
"""Benchmark: sequence-to-reply latency through axis_bridge + pdplus at 248 Hz.

Starts fake_axis_computer (real time, the clock master), axis_bridge and pdplus as separate
processes on loopback, runs for --seconds, and reads the axis computer's statistics: latency
from sending a STATE to receiving the COMMAND with the same sequence number (p50/p99/max) and
missed cycles. Prints JSON and writes benchmarks/results/axis_bridge_loop.json.

    python ros2_ws/src/irb_control/benchmarks/bench_axis_bridge.py [--seconds 30]
"""
from __future__ import annotations

import argparse
import json
import os
import random
import sys
import tempfile
import time
from pathlib import Path

from irb_control.process_group import ProcessGroup, ProcessSpec, ros2_run_cmd

RESULTS = Path(__file__).resolve().parent / 'results'


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seconds', type=float, default=30.0)
    ns = ap.parse_args()
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(1, 90)))
    tmp = Path(tempfile.mkdtemp())
    stats = tmp / 'axis_stats.json'
    remap = {'__ns': '/bench'}
    ports = {'state_port': 6610, 'command_port': 6611}
    specs = [
        ProcessSpec('bridge', ros2_run_cmd('irb_control', 'axis_bridge', params=ports,
                                           remaps=remap)),
        ProcessSpec('pdplus', ros2_run_cmd('irb_control', 'pdplus', remaps=remap,
                                           params={'profile_duration_s': 10.0,
                                                   'auto_enable': True})),
        # the axis computer waits for nothing: it idles on brakes until pdplus answers
        ProcessSpec('axis', ros2_run_cmd('irb_control', 'fake_axis_computer', remaps=remap,
                                         params={**ports, 'duration_s': ns.seconds,
                                                 'stats_path': str(stats)}), required=False),
    ]
    load_start = [round(x, 2) for x in os.getloadavg()]
    quiet = open(tmp / 'log.txt', 'w')
    with ProcessGroup(specs, log=lambda m: print(m, file=sys.stderr), stream=quiet) as group:
        done = group.wait_until(stats.exists, timeout_s=ns.seconds + 60)
        if not done:
            print(f'benchmark failed: {group.failed or "timeout"} (log {tmp}/log.txt)',
                  file=sys.stderr)
            return 1
        time.sleep(0.5)   # benchmark script, not a test: let the file be complete
    s = json.loads(stats.read_text())
    cycles = s['cycles']
    out = {'benchmark': 'axis_bridge_loop', 'seconds': ns.seconds, 'rate_hz': 248,
           'cycles': cycles, 'answered': s['answered'], 'missed_cycles': s['missed'],
           'missed_fraction': s['missed_fraction'], 'latency_ms': s['latency_ms'],
           'axis_error_at_end': s['error'], 'machine_cores': os.cpu_count(),
           'load_average_1_5_15_min_at_start': load_start,
           'load_average_1_5_15_min_at_end': [round(x, 2) for x in os.getloadavg()],
           'goal': {'p99_ms_below': 1.0, 'missed_fraction_below': 0.001}}
    out['goal_met'] = bool(s['latency_ms'] and s['latency_ms']['p99'] < 1.0
                           and s['missed_fraction'] < 0.001)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / 'axis_bridge_loop.json').write_text(json.dumps(out, indent=2))
    print(json.dumps(out, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
