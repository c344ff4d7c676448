"""Benchmark: identify from a 10-minute 248 Hz bag (target <= 3 s).

    python ros2_ws/src/irb_identification/benchmarks/bench_identify.py [--minutes 10]

Builds the bag once (offline_sim eq. 4.1 runs on all three joints, back to back, until the
duration is reached; /joint_states and /torque_command at 248 Hz and /camera/tcp at 100 Hz, like
a recorder would write, split every 1.5 s), then times bag -> arrays -> segments -> fits ->
friction-map YAML (and, separately, the plots). Prints JSON and writes it to
benchmarks/results/identify_<minutes>min.json.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
from irb_description.model import RobotModel

from irb_identification.bagio import BagWriter, TopicInfo, qos_profile_dict, serialize, typestore
from irb_identification.friction_fit import FitConfig, friction_map, identify_series
from irb_identification.offline_sim import SimConfig, simulate
from irb_identification.profiles import DEFAULT_SPEEDS, ConstantVelocityProfile
from irb_identification.series import JOINT_STATE, encode_joint_states, read_joint_series

HERE = Path(__file__).resolve().parent


def build_bag(path: Path, minutes: float, model) -> dict:
    """Concatenated runs until ``minutes`` of 248 Hz data; returns bag facts."""
    t_parts, q_parts, qd_parts, tau_parts = [], [], [], []
    t0, total = 0.0, minutes * 60.0
    cfg = SimConfig(velocity_noise=0.002, effort_noise=0.5, seed=3)
    while t0 < total:
        for j in range(3):
            for c in DEFAULT_SPEEDS:
                run = simulate(model, model.friction, ConstantVelocityProfile.for_speed(c), j,
                               config=cfg)
                t_parts.append(run.t + t0)
                q_parts.append(run.q)
                qd_parts.append(run.qd)
                tau_parts.append(run.tau)
                t0 += run.t[-1] + 0.004032
                if t0 >= total:
                    break
            if t0 >= total:
                break
    t = np.concatenate(t_parts)
    t = t[t < total]
    n = len(t)
    q, qd, tau = (np.concatenate(p)[:n] for p in (q_parts, qd_parts, tau_parts))
    start = 1_700_000_000 * 10**9
    t_ns = start + np.round(t * 1e9).astype(np.int64)
    names = model.joint_names
    js = encode_joint_states(t_ns, names, q, qd, tau)
    cmd = encode_joint_states(t_ns, names, q, qd, tau)      # command-sized JointState
    ts = typestore()
    P, H, T, Pt = (ts.types[k] for k in ('geometry_msgs/msg/PointStamped', 'std_msgs/msg/Header',
                                         'builtin_interfaces/msg/Time',
                                         'geometry_msgs/msg/Point'))
    clock = [0.0]
    with BagWriter(path, split_period_s=1.5, clock=lambda: clock[0]) as w:
        be = [qos_profile_dict('best_effort', depth=1)]
        w.add_topic(TopicInfo.for_type('/joint_states', JOINT_STATE, be))
        w.add_topic(TopicInfo.for_type('/torque_command', JOINT_STATE, be))
        w.add_topic(TopicInfo.for_type('/camera/tcp', 'geometry_msgs/msg/PointStamped'))
        next_cam = 0.0
        for k in range(n):
            clock[0] = t[k]
            w.write('/joint_states', int(t_ns[k]), js[k])
            w.write('/torque_command', int(t_ns[k]) + 100_000, cmd[k])
            if t[k] >= next_cam:
                p = model.fk(q[k])
                sec, nsec = divmod(int(t_ns[k]), 10**9)
                w.write('/camera/tcp', int(t_ns[k]) + 200_000, serialize(
                    'geometry_msgs/msg/PointStamped',
                    P(header=H(stamp=T(sec=sec, nanosec=nsec), frame_id='base_link'),
                      point=Pt(x=p[0], y=p[1], z=p[2]))))
                next_cam += 0.01
        facts = {'messages': w.message_count, 'files': len(w.files),
                 'joint_states': n, 'duration_s': float(t[-1] - t[0])}
    facts['bytes'] = sum(f.stat().st_size for f in path.iterdir())
    return facts


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--minutes', type=float, default=10.0)
    ap.add_argument('--repeat', type=int, default=3)
    ap.add_argument('--out', default=None, help='results JSON (default benchmarks/results/)')
    opts = ap.parse_args(argv)
    model = RobotModel.load()
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / 'bench'
        t0 = time.perf_counter()
        facts = build_bag(bag, opts.minutes, model)
        build_s = time.perf_counter() - t0
        times, plot_times = [], []
        for _ in range(opts.repeat):
            t0 = time.perf_counter()
            series = read_joint_series(bag, '/joint_states')
            t_read = time.perf_counter() - t0
            results = identify_series([series], model.joint_names, FitConfig())
            fmap = friction_map(results, 'benchmark')
            fmap.save(Path(tmp) / 'map.yaml')
            times.append((time.perf_counter() - t0, t_read))
            t1 = time.perf_counter()
            from irb_identification.plots import plot_joint
            for r in results:
                plot_joint(r, Path(tmp) / f'{r.name}.png')
            plot_times.append(time.perf_counter() - t1)
    best = min(times)
    out = {
        'benchmark': 'identify_from_bag', 'minutes': opts.minutes, **facts,
        'build_bag_s': round(build_s, 2),
        'identify_s_best': round(best[0], 3), 'read_decode_s_best': round(best[1], 3),
        'identify_s_all': [round(x[0], 3) for x in times],
        'plots_s_best': round(min(plot_times), 3),
        'target_s': 3.0, 'pass': best[0] <= 3.0,
        'speeds_identified': {r.name: len(r.points) for r in results},
        'coulomb': {r.name: round(r.parametric.coulomb, 3) for r in results if r.parametric},
        'machine': {'python': platform.python_version(), 'cpus': os.cpu_count(),
                    'processor': platform.machine()},
    }
    path = Path(opts.out) if opts.out else HERE / 'results' / f'identify_{opts.minutes:g}min.json'
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=2) + '\n')
    print(json.dumps(out, indent=2))
    return out


if __name__ == '__main__':
    main()
