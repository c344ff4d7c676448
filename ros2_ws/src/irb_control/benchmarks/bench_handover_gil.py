#!/usr/bin/env python3
"""How long building a plan's profile keeps another thread from running (issue 32), outside
ROS: a thread wakes every 1 ms (as the control thread waits for its next state) and records
how late it runs, while the main thread builds the controller's profile from a plan's arrays
as pdplus's reader thread does: (a) in one piece, as before (``PathProfile(**arrays)`` /
``TimeTrajectory``: checks, table, interpolation cache, ``.tolist()`` of the whole table), (b)
in slices (``profiles.build_sliced``). Switch interval as in the loop nodes (0.5 ms) and
Python's default (5 ms). Also, independent of the machine's load: the CPU time [ms] of the
longest piece the builder runs without releasing the interpreter lock (the whole build, or
the longest slice), measured with the builder thread's own CPU clock. Prints JSON, writes
results/handover_gil.json.

    python ros2_ws/src/irb_control/benchmarks/bench_handover_gil.py [--points 20000] [--repeats 10]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / 'results'


def arrays(n: int, kind: str) -> dict:
    rng = np.random.default_rng(1)
    t = np.linspace(0.0, 10.0, n)
    q, qd, qdd = rng.random((n, 3)), rng.random((n, 3)), rng.random((n, 3))
    if kind == 'time':
        return dict(t=t, q=q, qd=qd, qdd=qdd)
    return dict(theta=np.linspace(0.0, 6.28, n), theta_dot=1.0 + rng.random(n),
                theta_ddot=rng.random(n), q=q, qd=qd, qdd=qdd, t=t)


def lateness_while(build, period: float = 1e-3) -> float:
    """Largest lateness [ms] of a 1 ms periodic thread while ``build()`` runs."""
    late, stop = [], threading.Event()

    def ticker():
        nxt = time.perf_counter() + period
        while not stop.is_set():
            time.sleep(max(nxt - time.perf_counter(), 0.0))
            late.append(time.perf_counter() - nxt)
            nxt += period
    th = threading.Thread(target=ticker)
    th.start()
    time.sleep(0.02)
    n0 = len(late)
    build()
    time.sleep(0.005)
    stop.set()
    th.join()
    return 1e3 * max(late[n0:]) if len(late) > n0 else float('nan')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--points', type=int, default=20000)
    ap.add_argument('--repeats', type=int, default=10)
    a = ap.parse_args(argv)
    from irb_control.profiles import PathProfile, TimeTrajectory, build_sliced
    load = [round(x, 2) for x in os.getloadavg()]
    out = {'benchmark': 'lateness of a 1 ms periodic thread while a plan profile is built',
           'points': a.points, 'repeats': a.repeats, 'load_average_1_5_15_min_at_start': load,
           'max_lateness_ms': {}}
    keep = []
    from irb_control import profiles
    for kind, cls in (('path', PathProfile), ('time', TimeTrajectory)):
        arr = arrays(a.points, kind)
        whole, sliced = [], []
        for _ in range(a.repeats):
            c = time.thread_time()
            keep.append(cls(**arr))
            whole.append(time.thread_time() - c)
            pieces, last = [], [time.thread_time()]

            def pause():
                now = time.thread_time()
                pieces.append(now - last[0])
                time.sleep(0)
                last[0] = time.thread_time()
            keep.append(profiles.build_sliced(cls, arr, 256, pause))
            pieces.append(time.thread_time() - last[0])
            sliced.append(max(pieces))
            keep.clear()
        out.setdefault('longest_lock_hold_cpu_ms', {})[kind] = {
            'whole_median': round(1e3 * float(np.median(whole)), 3),
            'whole_max': round(1e3 * float(np.max(whole)), 3),
            'sliced_longest_slice_median': round(1e3 * float(np.median(sliced)), 3),
            'sliced_longest_slice_max': round(1e3 * float(np.max(sliced)), 3)}
    for interval in (0.005, 0.0005):
        sys.setswitchinterval(interval)
        for kind, cls in (('path', PathProfile), ('time', TimeTrajectory)):
            arr = arrays(a.points, kind)
            for how in ('whole', 'sliced'):
                def build():
                    keep.append(cls(**arr) if how == 'whole' else build_sliced(cls, arr))
                lat = [lateness_while(build) for _ in range(a.repeats)]
                keep.clear()
                out['max_lateness_ms'][f'{kind}_{how}_switch_{interval * 1e3:g}ms'] = {
                    'median': round(float(np.median(lat)), 3),
                    'max': round(float(np.max(lat)), 3)}
    out['load_average_1_5_15_min_at_end'] = [round(x, 2) for x in os.getloadavg()]
    RESULTS.mkdir(parents=True, exist_ok=True)
    text = json.dumps(out, indent=2)
    (RESULTS / 'handover_gil.json').write_text(text)
    print(text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
