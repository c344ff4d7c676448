#!/usr/bin/env python3
"""Live identification of a wrist joint through the nodes (issue 30): the simulator with
``joints:=6`` in lockstep, pdplus ``joints:=6`` (config/pdplus.yaml + pdplus_six_axis.yaml,
time-driven, no friction feed-forward), ``experiments mode:=ros`` sweeping one wrist joint, and
the ``identifier`` listening to the live /joint_states (``joints``: that joint, ``method``
samples, ``complete_from`` nominal); ~/compute at the end. Compares with the plant's friction
(irb_control config/plant.yaml).

    python ros2_ws/src/irb_bringup/benchmarks/bench_live_six_joint.py \
        [--joint joint_6] [--speeds 0.1 0.3 0.6 1.0] [--hold 1.0]

Prints JSON and writes benchmarks/results/live_six_joint_<joint>.json. Not a test: about a
minute of wall time at load 9 (doc/six_joint.md).
"""
import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / 'results'


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--joint', default='joint_6', choices=('joint_4', 'joint_5', 'joint_6'))
    ap.add_argument('--speeds', type=float, nargs='+', default=[0.1, 0.3, 0.6, 1.0],
                    help='[rad/s] sweep speeds')
    ap.add_argument('--hold', type=float, default=1.0, help='[s] constant-speed hold')
    a = ap.parse_args(argv)
    import rclpy
    import yaml
    from irb_control.plant import config_path
    from irb_control.process_group import ProcessGroup, ProcessSpec, ros2_run_cmd
    from irb_description.friction import load_friction_map
    from rclpy.executors import SingleThreadedExecutor
    from std_srvs.srv import Trigger

    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    tmp = Path(tempfile.mkdtemp(prefix='live_six_'))
    fmap, report = tmp / 'live.yaml', tmp / 'live.json'
    merged = {}
    for name in ('pdplus.yaml', 'pdplus_six_axis.yaml'):
        merged.update(yaml.safe_load(config_path(name).read_text())['pdplus']['ros__parameters'])
    merged.update(use_sim_time=True, reference_mode='time', friction_mode='none',
                  builtin_profile='none')
    params = tmp / 'pdplus.yaml'
    params.write_text(yaml.safe_dump({'/**': {'ros__parameters': merged}}))
    out = {'joint': a.joint, 'speeds_rad_s': a.speeds, 'hold_s': a.hold,
           'load_average_before': os.getloadavg()}
    t0 = time.monotonic()
    specs = [
        ProcessSpec('simulator', ros2_run_cmd('irb_control', 'simulator', params={
            'mode': 'lockstep', 'lockstep_wait_s': 0.5, 'joints': 6,
            'initial_positions': '[0.0, 0.5, -0.8, 0.0, 0.0, 0.0]'})),
        ProcessSpec('pdplus', ros2_run_cmd('irb_control', 'pdplus', params_file=str(params))),
        ProcessSpec('identifier', ros2_run_cmd('irb_identification', 'identifier', params={
            'out_map': str(fmap), 'out_report': str(report), 'joints': f"['{a.joint}']",
            'method': 'samples', 'quiet_period_s': 0.0, 'effort_lag_s': 0.0024192,
            'complete_from': 'nominal'}))]
    experiments = ProcessSpec('experiments', ros2_run_cmd(
        'irb_identification', 'experiments', params={
            'mode': 'ros', 'use_sim_time': True, 'root': str(tmp / 'bags'), 'prefix': 'live',
            'joints': f"['{a.joint}']", 'speeds_rad_s': str([float(s) for s in a.speeds]),
            'hold_max_s': a.hold, 'hold_min_s': a.hold}), required=False)
    lines = []

    class Sink:
        def write(self, text):
            lines.append(text)

        def flush(self):
            pass
    group = ProcessGroup(specs, log=lines.append, stream=Sink())
    group.start()
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        if not group.wait_until(lambda: any(
                str(ln).startswith('[identifier]') and 'subscribed to' in str(ln)
                for ln in list(lines)), 120.0):
            raise RuntimeError('the identifier did not subscribe')
        group.add(experiments)
        group.wait_until(lambda: group.procs['experiments'].poll() is not None, 900.0,
                         period_s=0.5)
        out['experiments_exit'] = group.procs['experiments'].returncode
        if out['experiments_exit'] != 0:
            raise RuntimeError('experiments failed: ' + ''.join(map(str, lines))[-1500:])
        node = rclpy.create_node('bench_live_six', context=context)
        ex = SingleThreadedExecutor(context=context)
        ex.add_node(node)
        client = node.create_client(Trigger, '/identifier/compute')
        if not client.wait_for_service(timeout_sec=60.0):
            raise RuntimeError('no /identifier/compute')
        fut = client.call_async(Trigger.Request())
        ex.spin_until_future_complete(fut, timeout_sec=180.0)
        out['compute'] = fut.result().message if fut.done() else 'no answer'
    except RuntimeError as exc:
        out['error'] = str(exc)
    finally:
        group.stop()
        context.try_shutdown()
    out['wall_time_s'] = time.monotonic() - t0
    out['load_average_after'] = os.getloadavg()
    if 'error' not in out:
        rep = json.loads(report.read_text())
        names = [f'joint_{i}' for i in range(1, 7)]
        got = load_friction_map(fmap, names)
        plant = load_friction_map(config_path('plant.yaml'), names)
        i = names.index(a.joint)
        out.update(received=rep['stream']['received'], method=rep['joints'][a.joint]['method'],
                   coulomb=got.joints[i].coulomb, coulomb_plant=plant.joints[i].coulomb,
                   viscous=got.joints[i].viscous, viscous_plant=plant.joints[i].viscous,
                   map_joints=list(got.joint_names))
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f'live_six_joint_{a.joint}.json').write_text(json.dumps(out, indent=1))
    print(json.dumps(out, indent=1))
    return 0 if 'error' not in out else 1


if __name__ == '__main__':
    sys.exit(main())
