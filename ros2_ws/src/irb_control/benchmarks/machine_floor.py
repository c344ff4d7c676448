"""The machine's own floor for a 248 Hz loop: how late a thread that does nothing but wake
every 4.032 ms is woken, with the loop's scheduling (SCHED_FIFO at --priority when permitted).

    python ros2_ws/src/irb_control/benchmarks/machine_floor.py --seconds 60 --priority 20

No ROS, no Python work between wake-ups: a wake-up later than the simulator's command timeout
(12.1 ms = 3 periods) here is a stall that no code of the loop can avoid on this host (another
process at equal or higher priority, the hypervisor taking the virtual CPU: ``steal`` in
/proc/stat). Prints JSON (and writes it with --out): wake-up lateness percentiles, counts above
one period, 5 ms and 12.1 ms, their rate per minute, the host's steal time over the run.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

PERIOD_S = 0.004032
COMMAND_TIMEOUT_S = 0.0121          # the simulator's "no command for ..." limit (3 periods)


def _steal_ticks() -> int | None:
    try:
        with open('/proc/stat') as f:
            return int(f.readline().split()[8])
    except (OSError, IndexError, ValueError):
        return None


def measure(seconds: float, priority: int) -> dict:
    fifo = 'not asked'
    if priority > 0:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            fifo = f'SCHED_FIFO {priority}'
        except (OSError, AttributeError) as exc:
            fifo = f'refused: {exc}'
    n = max(1, int(seconds / PERIOD_S))
    late = [0.0] * n
    steal0, t0 = _steal_ticks(), time.monotonic()
    due = t0
    for k in range(n):
        due += PERIOD_S
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        late[k] = time.monotonic() - due
    wall = time.monotonic() - t0
    steal1 = _steal_ticks()
    s = sorted(late)
    minutes = wall / 60.0

    def count(limit):
        return sum(1 for x in late if x > limit)
    return {
        'benchmark': 'machine floor: wake-up lateness of an idle 4.032 ms periodic thread',
        'scheduling': fifo, 'seconds': round(wall, 2), 'wakeups': n,
        'late_ms': {'p50': s[n // 2] * 1e3, 'p99': s[int(0.99 * (n - 1))] * 1e3,
                    'p999': s[int(0.999 * (n - 1))] * 1e3, 'max': s[-1] * 1e3},
        'late_over_one_period': count(PERIOD_S), 'late_over_5ms': count(0.005),
        'late_over_command_timeout': count(COMMAND_TIMEOUT_S),
        'per_minute_over_one_period': round(count(PERIOD_S) / minutes, 2),
        'per_minute_over_command_timeout': round(count(COMMAND_TIMEOUT_S) / minutes, 2),
        'steal_s_all_cpus': (None if steal0 is None or steal1 is None
                             else (steal1 - steal0) / os.sysconf('SC_CLK_TCK')),
        'load_average_1_5_15_min_at_end': [round(x, 2) for x in os.getloadavg()],
        'cores': os.cpu_count()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=60.0)
    ap.add_argument('--priority', type=int, default=20,
                    help='SCHED_FIFO priority (0: the default scheduler)')
    ap.add_argument('--out', default='', help='also write the JSON here')
    a = ap.parse_args(argv)
    if not a.seconds > 0:
        print('machine_floor: --seconds must be > 0', file=sys.stderr)
        return 2
    out = measure(a.seconds, a.priority)
    text = json.dumps(out, indent=2)
    print(text)
    if a.out:
        Path(a.out).write_text(text + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
