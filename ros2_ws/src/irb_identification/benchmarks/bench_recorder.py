"""Benchmark: recorder loss (lost / expected) at 1, 4 and 7 topics of 248 Hz, real time and
lockstep, quiet and beside CPU burners.

    python ros2_ws/src/irb_identification/benchmarks/bench_recorder.py \
        --topics 7 --mode lockstep --burners 2 --seconds 60

A publisher process sends N topics of sensor_msgs/JointState (position[0] = its own count k,
header stamp = k x 4.032 ms of simulated time) with the simulator's QoS (reliable, keep last
STATE_PUB_DEPTH: 2500 since issue 31, --pub-depth): ``realtime`` at 248 Hz of wall time;
``lockstep`` as fast as ``--speed`` x real time
(2.5: the lockstep simulator beside pdplus on this machine) with /clock, the recorder on
simulated time. The recorder is the ``recorder`` executable (its own process). Loss is counted
from outside the recorder: the publisher's count per topic against the bag, read with the
``mcap`` library (not bagio), every k present once; and the log times against the stamps
(lockstep: log time = simulated time). Burners: ``python -c 'while 1: pass'``. Prints JSON and
writes it to benchmarks/results/recorder_<topics>t_<mode>_<burners>b.json.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
PERIOD_NS = 4_032_000


def publisher(args) -> int:
    """The publisher process: N topics, stops after --seconds of wall time; writes counts."""
    import rclpy
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    rclpy.init()
    node = rclpy.create_node('bench_pub')
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=args.pub_depth,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    topics = [f'/bench/t{i}' for i in range(args.topics)]
    pubs = [node.create_publisher(JointState, t, qos) for t in topics]
    clock = node.create_publisher(Clock, '/clock', 10) if args.mode == 'lockstep' else None
    end = time.monotonic() + 60
    while any(p.get_subscription_count() < 1 for p in pubs) and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    # the writer sees the reader before the reader has matched the writer: what is sent in
    # between is dropped by the reader (discovery, not recording); start 1 s later
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    msg = JointState()
    msg.name = ['joint_1', 'joint_2', 'joint_3', 'joint_4', 'joint_5', 'joint_6']
    msg.velocity = [0.1] * 6
    msg.effort = [1.0] * 6
    c = Clock()
    k = 0
    t0 = time.monotonic()
    step = 0.004032 / (args.speed if args.mode == 'lockstep' else 1.0)
    while time.monotonic() - t0 < args.seconds:
        due = t0 + k * step
        while True:
            wait = due - time.monotonic()
            if wait <= 0:
                break
            time.sleep(min(wait, 0.002))
        t_ns = 1_000_000_000_000 + k * PERIOD_NS
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 10**9)
        msg.position = [float(k), 0.0, 0.0, 0.0, 0.0, 0.0]
        if clock is not None:
            c.clock.sec, c.clock.nanosec = msg.header.stamp.sec, msg.header.stamp.nanosec
            clock.publish(c)
        for p in pubs:
            p.publish(msg)
        k += 1
    wall = time.monotonic() - t0
    # keep the writers (and their history) alive until the recorder acknowledged
    from rclpy.duration import Duration
    for p in pubs:
        p.wait_for_all_acked(Duration(seconds=5.0))
    Path(args.out).write_text(json.dumps({'published_per_topic': k, 'topics': topics,
                                          'wall_s': wall, 'rate_hz': k / wall}))
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def _group_cpu_s(pgid: int) -> float | None:
    """CPU time [s] (user + system) of the processes of a process group (the recorder and
    its `ros2 run` launcher), from /proc."""
    total, tick = 0.0, os.sysconf('SC_CLK_TCK')
    for d in Path('/proc').iterdir():
        if not d.name.isdigit():
            continue
        try:
            fields = (d / 'stat').read_text().rsplit(')', 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid:                     # field 5 of stat: the process group
            total += (int(fields[11]) + int(fields[12])) / tick
    return total


def read_bag(bag: Path, topics: list[str]) -> dict:
    """Per topic: k values (position[0]) and (log time, stamp) pairs, via the mcap reader."""
    import yaml
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    out = {t: {'k': [], 'log_minus_stamp_ns': []} for t in topics}
    for rel in info['relative_file_paths']:
        with open(bag / rel, 'rb') as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
            for _, channel, message, ros in reader.iter_decoded_messages(topics=topics):
                s = ros.header.stamp
                out[channel.topic]['k'].append(int(ros.position[0]))
                out[channel.topic]['log_minus_stamp_ns'].append(
                    message.log_time - (s.sec * 10**9 + s.nanosec))
    return out, info


def run_case(args) -> dict:
    import numpy as np
    import yaml
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    tmp = Path(tempfile.mkdtemp(prefix='bench_rec_'))
    burners = [subprocess.Popen([sys.executable, '-c', 'while 1: pass'])
               for _ in range(args.burners)]
    topics = [f'/bench/t{i}' for i in range(args.topics)]
    rec = pub = None
    try:
        rec = subprocess.Popen(
            ['ros2', 'run', 'irb_identification', 'recorder', '--ros-args',
             '-p', f'root:={tmp}', '-p', 'name:=bench', '-p', f'topics:={topics}',
             '-p', f'use_sim_time:={"true" if args.mode == "lockstep" else "false"}',
             '-p', 'progress_period_s:=5.0'],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
            start_new_session=True)
        counts_file = tmp / 'pub.json'
        pub = subprocess.run(
            [sys.executable, __file__, '--role', 'publisher', '--topics', str(args.topics),
             '--mode', args.mode, '--seconds', str(args.seconds), '--speed', str(args.speed),
             '--pub-depth', str(args.pub_depth),
             '--out', str(counts_file)], env=env, timeout=args.seconds + 180)
        load = os.getloadavg()
        cpu_s = _group_cpu_s(rec.pid)
        os.killpg(rec.pid, signal.SIGINT)
        rec_out, _ = rec.communicate(timeout=120)
    finally:
        for b in burners:
            b.kill()
            b.wait()
        if rec is not None and rec.poll() is None:
            os.killpg(rec.pid, signal.SIGKILL)
            rec.wait()
    sent = json.loads(counts_file.read_text())
    got, info = read_bag(tmp / 'bench', topics)
    per = {}
    n = sent['published_per_topic']
    for t in topics:
        ks = np.array(got[t]['k'])
        present = np.unique(ks)
        lost = n - len(present)
        missing = np.setdiff1d(np.arange(n), present)
        first = int(present.min()) if len(present) else n
        last = int(present.max()) if len(present) else -1
        inside = int(np.count_nonzero((missing > first) & (missing < last)))
        per[t] = {'expected': n, 'recorded': int(len(ks)), 'lost': int(lost),
                  'missed_before_first': first, 'lost_inside': inside,
                  'missed_after_last': n - 1 - last,
                  'duplicates': int(len(ks) - len(present)),
                  'largest_gap_s': float(np.max(np.diff(np.sort(present))) * 0.004032)
                  if len(present) > 1 else None,
                  'first_missing_k': missing[:5].tolist()}
        if args.mode == 'lockstep' and len(ks):
            d = np.array(got[t]['log_minus_stamp_ns']) * 1e-9
            per[t]['log_time_minus_stamp_s'] = {'median': float(np.median(d)),
                                                'min': float(d.min()), 'max': float(d.max())}
    losses = (tmp / 'bench' / 'losses.yaml')
    lost_total = sum(v['lost'] for v in per.values())
    inside_total = sum(v['lost_inside'] for v in per.values())
    expected = n * len(topics)
    result = {
        'case': f'{args.topics} topics, {args.mode}, {args.burners} burners',
        'topics': args.topics, 'mode': args.mode, 'burners': args.burners,
        'seconds': args.seconds, 'publisher_depth': args.pub_depth,
        'speed': args.speed if args.mode == 'lockstep' else 1.0,
        'publisher_rate_hz': sent['rate_hz'], 'expected': expected, 'lost': lost_total,
        'lost_fraction': lost_total / max(expected, 1),
        'lost_inside': inside_total,
        'missed_at_start_or_end': lost_total - inside_total,
        'recorder_cpu_s': cpu_s,
        'recorder_cpu_us_per_message': 1e6 * cpu_s / max(expected, 1),
        'recorder_reported_lost': int(info.get('custom_data', {}).get('lost_messages', -1)),
        'losses_yaml_lost_total': (yaml.safe_load(losses.read_text())['lost_total']
                                   if losses.exists() else 0),
        'split_files': len(info['relative_file_paths']),
        'per_topic': per, 'loadavg_1_5_15': load, 'publisher_rc': pub.returncode,
        'recorder_tail': rec_out.strip().splitlines()[-3:],
        'date': time.strftime('%Y-%m-%d %H:%M:%S'), 'cpus': os.cpu_count(),
        'commit': subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=HERE,
                                 capture_output=True, text=True).stdout.strip()}
    if not args.keep:
        import shutil
        shutil.rmtree(tmp, ignore_errors=True)
    else:
        result['bag'] = str(tmp / 'bench')
    return result


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--role', default='bench', choices=('bench', 'publisher'))
    ap.add_argument('--topics', type=int, default=7)
    ap.add_argument('--mode', default='realtime', choices=('realtime', 'lockstep'))
    ap.add_argument('--burners', type=int, default=0)
    ap.add_argument('--seconds', type=float, default=60.0)
    ap.add_argument('--speed', type=float, default=2.5, help='lockstep: x real time')
    ap.add_argument('--out', default='')
    ap.add_argument('--keep', action='store_true', help='keep the bag (its path in the JSON)')
    ap.add_argument('--pub-depth', type=int, default=2500,
                    help="publishers' keep-last depth (the simulator's STATE_PUB_DEPTH: 2500)")
    args = ap.parse_args()
    # a timeout's SIGTERM ends the run through its finally (the burners are killed)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    if args.role == 'publisher':
        return publisher(args)
    result = run_case(args)
    text = json.dumps(result, indent=2)
    print(text)
    res = HERE / 'results'
    res.mkdir(exist_ok=True)
    tag = '' if args.pub_depth == 250 else f'_depth{args.pub_depth}'   # older files: 250
    (res / f'recorder_{args.topics}t_{args.mode}_{args.burners}b{tag}.json').write_text(
        text + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
