#!/usr/bin/env python3
"""The 248 Hz loop simulator <-> pdplus on six joints against three, in the same run (issue 30).

    python ros2_ws/src/irb_control/benchmarks/bench_six_joint_loop.py [--seconds 20]
        [--repeats 2] [--rt-priority 20]

``run_benchmarks.py loop``'s run (two processes, simulator in real time, both SCHED_FIFO at
``--rt-priority`` where granted, state -> command latency at the simulator), alternately with
``joints:=3`` and ``joints:=6`` (config/pdplus_six_axis.yaml's per-joint settings), both
running the built-in sine on joint 1 (time-driven: the same motion and the same reference
path for both; the wrist holds on six). Goal: the six-joint p99 at most 1.2x the
three-joint one. Writes results/six_joint_loop.json; summary in RESULTS.md.
"""
import argparse
import json
import os
import sys
from pathlib import Path

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
RESULTS = Path(__file__).resolve().parent / 'results'


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--seconds', type=float, default=20.0, help='listening time per run [s]')
    ap.add_argument('--repeats', type=int, default=2, help='runs of each, interleaved')
    ap.add_argument('--rt-priority', type=int, default=20, help='SCHED_FIFO priority, 0 = off')
    a = ap.parse_args(argv)
    from run_benchmarks import _loop_run

    from irb_control.closed_loop import six_axis_controller_config
    c = six_axis_controller_config()
    six = ['-p', 'joints:=6']
    for k in ('kp', 'kd', 'torque_rate_limit_nm_s', 'max_tracking_error_rad'):
        six += ['-p', f'{k}:={list(getattr(c, k))}']
    sine = ['-p', 'builtin_profile:=sine', '-p', 'sine_cycles:=20.0']
    out = {'load_average_before': os.getloadavg(), 'runs': []}
    for r in range(a.repeats):
        for n in (3, 6):
            res = _loop_run(a.seconds, a.rt_priority, tuple(sine + (six if n == 6 else [])),
                            ('-p', 'joints:=6') if n == 6 else (), tag=f'_j{n}')
            res['joints'] = n
            out['runs'].append(res)
            lat = res['state_to_command_latency_ms (simulator side)']
            print(json.dumps({'joints': n, 'repeat': r, 'latency_ms': lat,
                              'modes': res['modes_seen'],
                              'step_ms': res['pdplus_step_compute_ms']}), flush=True)
    p99 = {n: [r['state_to_command_latency_ms (simulator side)']['p99'] for r in out['runs']
               if r['joints'] == n] for n in (3, 6)}
    out['p99_ms'] = p99
    out['p99_ratio_six_over_three_per_repeat'] = [b / a_ for a_, b in zip(p99[3], p99[6])]
    out['load_average_after'] = os.getloadavg()
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / 'six_joint_loop.json').write_text(json.dumps(out, indent=1))
    print(json.dumps({k: out[k] for k in ('p99_ms', 'p99_ratio_six_over_three_per_repeat',
                                          'load_average_after')}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
