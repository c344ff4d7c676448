#!/usr/bin/env python3
"""State -> command latency and missed deadlines with pdplus and the simulator on different
hosts (network namespaces, irb_bringup.hosts) at 0, 1 and 5 ms one-way link delay, against
both on one host, in the same run (cases interleaved, ``--repeats`` rounds). Prints JSON and
writes results/bench_hosts.json. Needs root and `source scripts/env.sh`.

    sudo -E nice -n 10 python benchmarks/bench_hosts.py [--duration 15] [--repeats 2]

Cases: `same_host` (simulator + pdplus in one namespace), `same_host_remote_recorder` (the
same, plus a recorder on a third host behind a 10 ms / 1 % link: a reliable reader of the loop
topics across a lossy network; its delivery latency and missing samples from its bag),
`hosts_0ms` (pdplus on a second host, veth link),
`hosts_0ms_emulated` (the same through linkemu at 0 ms: the emulator's own cost, only where
netem is missing), `hosts_1ms`, `hosts_5ms` (one-way delay on pdplus's link, each direction:
the round trip grows by 2 x delay). pdplus runs its built-in 10 s circle (auto_enable:=true). The
figures are the simulator's (its stats_path): latency of the command that answers each state,
missed deadlines (no answer before the next tick), commands that came too late (stale).
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / 'results'
REC_DELAY_MS, REC_LOSS = 10.0, 0.01          # the recorder's link: the network


def _ros2_run(pkg, exe, params):
    from irb_control.process_group import ros2_run_cmd
    return list(ros2_run_cmd(pkg, exe, params=params))


def _case(name, duration, rt, domain, tmp: Path) -> dict:
    from irb_bringup import hosts
    stats = tmp / f'{name}_stats.json'
    stats.unlink(missing_ok=True)
    env = dict(os.environ, PYTHONUNBUFFERED='1', **hosts.host_env(domain))
    procs, logs = [], []
    with hosts.Cell() as cell:
        try:
            cell.add_host('sim')
            ctl = 'sim'
            delay = {'hosts_1ms': 1.0, 'hosts_5ms': 5.0}.get(name, 0.0)
            if name.startswith('hosts_'):
                ctl = 'ctl'
                if name == 'hosts_0ms_emulated':
                    cell.add_host('ctl', emulate=True)
                else:
                    cell.add_host('ctl', delay_ms=delay)
            link = (hosts.link_emulation() if delay or name == 'hosts_0ms_emulated'
                    else 'veth')

            def start(host, argv, tag):
                log = open(tmp / f'{name}_{tag}.log', 'w')
                logs.append(log)
                procs.append(subprocess.Popen(cell.wrap(host, argv), env=env, stdout=log,
                                              stderr=subprocess.STDOUT,
                                              start_new_session=True))
            start(ctl, _ros2_run('irb_control', 'pdplus', {
                'realtime_priority': rt, 'profile_duration_s': 10.0,
                'auto_enable': True}), 'pdplus')
            bag = None
            if name == 'same_host_remote_recorder':
                cell.add_host('rec', delay_ms=REC_DELAY_MS, loss=REC_LOSS)
                bag = tmp / 'bags' / f'{name}_{time.time_ns()}'
                start('rec', _ros2_run('irb_identification', 'recorder', {
                    'root': str(bag.parent), 'name': bag.name,
                    'recover_on_start': False}), 'recorder')
            start('sim', _ros2_run('irb_control', 'simulator', {
                'mode': 'realtime', 'realtime_priority': rt, 'stats_path': str(stats)}),
                'simulator')
            load0 = [round(x, 2) for x in os.getloadavg()]
            t0 = time.monotonic()
            while time.monotonic() - t0 < duration and all(p.poll() is None for p in procs):
                time.sleep(0.2)       # a benchmark's wall-clock window, not a test wait
        finally:
            # what the nodes said while the loop ran (stopping the simulator trips pdplus's
            # watchdog): safe stops, latched errors
            pd_log = (tmp / f'{name}_pdplus.log').read_text(errors='replace').splitlines()
            sim_log = (tmp / f'{name}_simulator.log').read_text(errors='replace').splitlines()
            sim_first = procs[-1:] + procs[:-1]
            for p in sim_first:      # simulator first: its statistics end while pdplus runs
                if p.poll() is None:
                    os.killpg(p.pid, signal.SIGINT)
                    try:
                        p.wait(timeout=30)
                    except subprocess.TimeoutExpired:
                        os.killpg(p.pid, signal.SIGKILL)
                        p.wait(timeout=10)
            for log in logs:
                log.close()
    s = json.loads(stats.read_text()) if stats.exists() else {}
    stops = [ln.split(']: ', 1)[-1] for ln in pd_log
             if any(w in ln.lower() for w in ('stop', 'watchdog', 'error'))][:3]
    faults = [ln.split(']: ', 1)[-1] for ln in sim_log if 'latched' in ln.lower()][:2]
    steps = max(int(s.get('steps', 0)), 1)
    remote = _remote_delivery(bag) if bag is not None else None
    return {'remote_recorder': remote,'case': name, 'link': link, 'one_way_delay_ms': delay,
            'latency_ms': s.get('latency_ms'), 'steps': s.get('steps'),
            'answered': s.get('answered'),
            'missed_deadlines': s.get('missed_deadlines'),
            'missed_fraction': (s.get('missed_deadlines') or 0) / steps,
            'max_consecutive_missed': s.get('max_consecutive_missed'),
            'stale_commands_ignored': s.get('stale_commands_ignored'),
            'state_publish_late_ms': s.get('state_publish_late_ms'),
            'pdplus_stop_lines': stops, 'simulator_fault_lines': faults,
            'load_average_at_start': load0}


def _remote_delivery(bag: Path) -> dict:
    """/joint_states as the recorder on the third host got them: delivery latency (its
    receive time, the bag's log time, minus the simulator's stamp: one machine, one clock) and
    the samples missing between the first and the last."""
    import numpy as np
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    from irb_identification.bagio import BagError, read_messages
    try:
        m = read_messages(bag, ['/joint_states'])['/joint_states']
    except BagError as exc:
        return {'error': str(exc)}
    stamps = np.array([(lambda h: h.stamp.sec + 1e-9 * h.stamp.nanosec)(
        deserialize_message(b, JointState).header) for b in m.data])
    lat = (np.array(m.t_ns) * 1e-9 - stamps) * 1e3
    steps = np.round(np.diff(np.sort(stamps)) / 0.004032).astype(int)
    return {'link_one_way_delay_ms': REC_DELAY_MS, 'link_loss': REC_LOSS,
            'received': int(stamps.size), 'missing': int(np.sum(np.maximum(steps - 1, 0))),
            'delivery_latency_ms': {'p50': float(np.percentile(lat, 50)),
                                    'p99': float(np.percentile(lat, 99)),
                                    'max': float(lat.max())},
            'delivery_latency_ms_second_half': {
                'p50': float(np.percentile(lat[lat.size // 2:], 50)),
                'p99': float(np.percentile(lat[lat.size // 2:], 99))}}


def _summary(runs: list[dict]) -> dict:
    out = {}
    for name in dict.fromkeys(r['case'] for r in runs):
        rs = [r for r in runs if r['case'] == name]
        p50 = [r['latency_ms']['p50'] for r in rs if r['latency_ms']]
        p99 = [r['latency_ms']['p99'] for r in rs if r['latency_ms']]
        out[name] = {
            'link': rs[0]['link'], 'one_way_delay_ms': rs[0]['one_way_delay_ms'],
            'latency_p50_ms_median': statistics.median(p50) if p50 else None,
            'latency_p99_ms_median': statistics.median(p99) if p99 else None,
            'latency_p99_ms_runs': [round(x, 3) for x in p99],
            'missed_fraction_runs': [round(r['missed_fraction'], 4) for r in rs],
            'answered_fraction_runs': [round((r['answered'] or 0) / max(r['steps'] or 1, 1), 4)
                                       for r in rs],
            'stopped_runs': sum(bool(r['pdplus_stop_lines'] or r['simulator_fault_lines'])
                                for r in rs),
            'first_stop_or_fault': next((r['simulator_fault_lines'][:1] + r['pdplus_stop_lines']
                                         for r in rs if r['pdplus_stop_lines']
                                         or r['simulator_fault_lines']), []),
        }
        if rs[0]['remote_recorder'] is not None:
            out[name]['remote_recorder_runs'] = [r['remote_recorder'] for r in rs]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--duration', type=float, default=15.0, help='[s] per case')
    ap.add_argument('--repeats', type=int, default=2, help='rounds of all cases')
    ap.add_argument('--rt-priority', type=int, default=20,
                    help='SCHED_FIFO priority of simulator and pdplus (0 = normal)')
    ap.add_argument('--cases', default='', help='comma-separated subset of the cases')
    ap.add_argument('--logs', default='', help='keep node logs here (default: discarded)')
    a = ap.parse_args(argv)
    from irb_bringup import hosts
    why = hosts.unavailable()
    if why:
        print(f'bench_hosts: {why}', file=sys.stderr)
        return 2
    cases = ['same_host', 'same_host_remote_recorder', 'hosts_0ms', 'hosts_1ms', 'hosts_5ms']
    if hosts.link_emulation() == 'linkemu':
        cases.insert(3, 'hosts_0ms_emulated')
    if a.cases:
        cases = a.cases.split(',')
    domain = int(os.environ.get('ROS_DOMAIN_ID', '0'))
    runs = []
    with tempfile.TemporaryDirectory(prefix='bench_hosts_') as tmp:
        if a.logs:
            tmp = a.logs
            Path(tmp).mkdir(parents=True, exist_ok=True)
        for k in range(a.repeats):
            for name in cases:
                print(f'[bench_hosts] round {k + 1}/{a.repeats}: {name}', file=sys.stderr,
                      flush=True)
                runs.append(_case(name, a.duration, a.rt_priority, domain, Path(tmp)))
    data = {'benchmark': 'state -> command latency and missed deadlines, pdplus and simulator '
                         'on one host vs on two hosts (network namespaces) at 0/1/5 ms',
            'duration_s_per_case': a.duration, 'repeats': a.repeats,
            'realtime_priority': a.rt_priority, 'link_emulation': hosts.link_emulation(),
            'fastdds_profile': str(hosts.fastdds_profile()),
            'summary': _summary(runs), 'runs': runs,
            'load_average_1_5_15_min_at_end': [round(x, 2) for x in os.getloadavg()],
            'machine_cores': os.cpu_count()}
    RESULTS.mkdir(parents=True, exist_ok=True)
    text = json.dumps(data, indent=2)
    (RESULTS / 'bench_hosts.json').write_text(text)
    print(text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
