"""Benchmark: replay (rate 0, as fast as the reader takes them) into the identifier, as
processes: messages/s, and whether every map equals the offline `identify`'s map.

    python ros2_ws/src/irb_identification/benchmarks/bench_replay_identifier.py \
        --runs 20 --burners 2 --repeat 4

The bag: eq. 4.1 on joint_3 at five speeds back to back (offline plant, noise), ``--repeat``
times (about 7,500 joint states each). The offline map comes from `identify` on the same bag
(rosbags reader, vectorised decoder). Each run: the identifier (`ros2 run`, exit_after_stream)
and a replay with ``rate:=0``; a run is ``equal`` (exit 0, map equal to the offline one within
1e-9 N m on -2..2 rad/s), ``refused`` (non-zero exit with a reason on its log: counted, not a
silent difference) or ``silent`` (exit 0 and a different or missing map: the failure this
benchmark looks for). messages/s = played messages / the replay's play time (paced by the
identifier, reliable keep-all). Burners: ``python -c 'while 1: pass'``. Prints JSON and writes
benchmarks/results/replay_identifier_<burners>b.json.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SPEEDS = (0.4, 0.6, 0.9, 1.3, 1.8)


def build_bag(path: Path, repeat: int) -> int:
    from irb_description.model import RobotModel

    from irb_identification.bagio import BagWriter, TopicInfo, qos_profile_dict
    from irb_identification.offline_sim import SimConfig, simulate
    from irb_identification.profiles import ConstantVelocityProfile
    from irb_identification.series import JOINT_STATE, encode_joint_states
    model = RobotModel.load()
    parts, t0 = [], 0.0
    for r in range(repeat):
        for c in SPEEDS:
            run = simulate(model, model.friction, ConstantVelocityProfile.for_speed(
                c, stroke_rad=0.4), 2, config=SimConfig(velocity_noise=0.002,
                                                        effort_noise=0.5, seed=5 + r))
            parts.append((run.t + t0, run.q, run.qd, run.tau))
            t0 += run.t[-1] + 0.004032
    t, q, qd, tau = (np.concatenate([p[k] for p in parts]) for k in range(4))
    t_ns = 1_700_000_000 * 10**9 + np.round(t * 1e9).astype(np.int64)
    payloads = encode_joint_states(t_ns, list(model.joint_names), q, qd, tau)
    with BagWriter(path, max_bytes=100 << 20) as w:
        w.add_topic(TopicInfo.for_type('/joint_states', JOINT_STATE,
                                       [qos_profile_dict('best_effort', depth=1)]))
        for ns, data in zip(t_ns, payloads):
            w.write('/joint_states', int(ns), data)
    return len(t)


def maps_equal(a_path: Path, b_path: Path) -> bool:
    from irb_description.friction import load_friction_map
    a, b = load_friction_map(a_path), load_friction_map(b_path)
    v = np.linspace(-2, 2, 41)
    return a.joint_names == b.joint_names and all(
        np.allclose(x.torque(v), y.torque(v), atol=1e-9, rtol=0)
        for x, y in zip(a.joints, b.joints))


def one_run(bag: Path, offline: Path, work: Path, k: int, env: dict) -> dict:
    out = work / f'map_{k}.yaml'
    ident = subprocess.Popen(
        ['ros2', 'run', 'irb_identification', 'identifier', '--ros-args', '-p',
         f'out_map:={out}', '-p', 'joints:=[joint_3]', '-p', 'progress_period_s:=0.0'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
        start_new_session=True)
    t_start = time.monotonic()
    lines = []
    try:
        for line in ident.stdout:                 # until it listens
            lines.append(line)
            if 'waiting for publishers' in line:
                break
        replay = subprocess.run(
            ['ros2', 'run', 'irb_identification', 'replay', '--ros-args', '-p', f'bag:={bag}',
             '-p', 'rate:=0', '-p', 'wait_for_subscribers:=1', '-p', 'wait_timeout_s:=120.0'],
            capture_output=True, text=True, env=env, timeout=600)
        rest, _ = ident.communicate(timeout=600)
        lines += rest.splitlines(keepends=True)
    finally:
        if ident.poll() is None:
            os.killpg(ident.pid, signal.SIGKILL)
            ident.wait()
    played = re.search(r'played (\d+) messages, ([\d.]+) s of bag in ([\d.]+) s',
                       replay.stderr + replay.stdout)
    rate = int(played.group(1)) / float(played.group(3)) if played else None
    report = {}
    if out.with_suffix('.json').exists():
        report = json.loads(out.with_suffix('.json').read_text())
    equal = out.exists() and maps_equal(out, offline)
    if ident.returncode == 0 and equal:
        verdict = 'equal'
    elif ident.returncode != 0:
        verdict = 'refused'
    else:
        verdict = 'silent'
    errs = [x.strip() for x in lines if 'ERROR' in x or 'error' in x.lower()][-2:]
    return {'run': k, 'verdict': verdict, 'identifier_rc': ident.returncode,
            'replay_rc': replay.returncode, 'messages_per_s': rate,
            'play_wall_s': float(played.group(3)) if played else None,
            'received': report.get('stream', {}).get('received'),
            'expected': report.get('stream', {}).get('expected'),
            'complete': report.get('stream', {}).get('complete'),
            'error': report.get('error') or (errs[-1] if errs else ''),
            'wall_s': time.monotonic() - t_start,
            'replay_stderr_tail': (replay.stderr.strip().splitlines() or [''])[-1]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--runs', type=int, default=20)
    ap.add_argument('--burners', type=int, default=2)
    ap.add_argument('--repeat', type=int, default=4, help='the five-speed session, times')
    args = ap.parse_args()
    # a timeout's SIGTERM ends the run through its finally (the burners are killed)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    from irb_identification import identify
    work = Path(tempfile.mkdtemp(prefix='bench_ri_'))
    bag = work / 'session'
    n = build_bag(bag, args.repeat)
    offline = work / 'offline.yaml'
    assert identify.main(['--bag', str(bag), '--out', str(offline), '--no-plots',
                          '--joints', 'joint_3']) == 0
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    burners = [subprocess.Popen([sys.executable, '-c', 'while 1: pass'])
               for _ in range(args.burners)]
    runs, loads = [], []

    def summary() -> dict:
        rates = [r['messages_per_s'] for r in runs if r['messages_per_s']]
        return {
            'messages_in_bag': n, 'runs': len(runs), 'runs_asked': args.runs,
            'burners': args.burners,
            'equal': sum(r['verdict'] == 'equal' for r in runs),
            'refused_with_reason': sum(r['verdict'] == 'refused' for r in runs),
            'silent_differences': sum(r['verdict'] == 'silent' for r in runs),
            'messages_per_s': {'median': float(np.median(rates)) if rates else None,
                               'min': float(np.min(rates)) if rates else None,
                               'max': float(np.max(rates)) if rates else None},
            'loadavg_1min': {'median': float(np.median(loads)), 'min': float(min(loads)),
                             'max': float(max(loads))} if loads else None,
            'per_run': runs, 'date': time.strftime('%Y-%m-%d %H:%M:%S'),
            'cpus': os.cpu_count(),
            'commit': subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=HERE,
                                     capture_output=True, text=True).stdout.strip()}
    res = HERE / 'results'
    res.mkdir(exist_ok=True)
    out = res / f'replay_identifier_{args.burners}b.json'
    try:
        for k in range(args.runs):
            runs.append(one_run(bag, offline, work, k, env))
            loads.append(os.getloadavg()[0])
            print(json.dumps(runs[-1]), file=sys.stderr, flush=True)
            out.write_text(json.dumps(summary(), indent=2) + '\n')   # after every run
    finally:
        for b in burners:
            b.kill()
            b.wait()
    text = json.dumps(summary(), indent=2)
    print(text)
    out.write_text(text + '\n')
    import shutil
    shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
