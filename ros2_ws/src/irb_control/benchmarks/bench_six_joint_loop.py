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

``--lockstep``: the control-loop cost per sample in pdplus's own timing instead
(ControllerState.step_duration: from the state's arrival to the command sent, decoding and
the step included), the simulator in lockstep (it waits for each command, so a loaded machine
costs no sample and causes no stop) and pdplus on simulated time, both on the built-in sine of
joint 1, ``--repeats`` runs of each joint count interleaved (3, 6, 3, 6, ...), fresh processes
each; only samples that sent a command (modes ramp, time, hold) count. Median, p90, p99 per
run and pooled, and their six/three ratios. Writes results/<--out>.json.

``--paired``: the same figure without a simulator and in the very same moments: two pdplus
processes, three and six joints, each in a namespace of its own, driven by this script
alternately sample by sample (a joint state stamped now to one, its command awaited, then
to the other; the order swapped every period; ``--rate`` pairs per second), both on the
built-in sine of joint 1 (time-driven, 0.01 rad: the state stays at the start pose, the
tracking-error limit is 1 rad and the watchdog 1000 samples, so that neither stops). The
simulator's own cost (six joints: ~4x three) is then out of pdplus's figure. Also the round
trip state -> command as this script sees it. Writes results/<--out>.json.

``--inprocess``: ``PdPlusController.step`` alone (perf_counter around the call), no ROS: two
offline closed loops (controller and plant of closed_loop), three joints (the thesis's model,
``step``) and six (config/pdplus_six_axis.yaml, ``_step_n``), stepped alternately period by
period (3 then 6, the order swapped every period) so that both see the machine at the same
moments; ``--repeats`` fresh pairs for each of two motions: 'sine' (the nodes' built-in sine
of joint 1, time-driven, 0.6 rad/s) and 'rectangle' (theta-driven: the gluing rectangle, on
six joints with the nozzle normal to its plane, PathTracker on both), ``--seconds`` each.
Only the steps that sent a command count. Per step the wall time (perf_counter) and the
thread's CPU time (thread_time_ns: without the time the scheduler gave to other processes,
the figure of the code on a loaded machine); median, p10, p90, p99, min per repeat and
pooled, six/three ratios. Writes
results/<--out or six_joint_step_inprocess>.json.
"""
import argparse
import json
import os
import sys
from pathlib import Path

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
RESULTS = Path(__file__).resolve().parent / 'results'


def six_joint_args() -> list:
    """pdplus's -p arguments of config/pdplus_six_axis.yaml's per-joint settings (all of
    them: gains, limits, the wrist stiction measures)."""
    from irb_control.closed_loop import six_axis_controller_config
    c = six_axis_controller_config()
    out = ['-p', 'joints:=6']
    for k in ('kp', 'kd', 'torque_rate_limit_nm_s', 'max_tracking_error_rad',
              'gain_design_inertia_kg_m2'):
        out += ['-p', f'{k}:={list(getattr(c, k))}']
    if c.stribeck_measured:
        out += ['-p', 'stribeck_measured:=[' + ','.join(
            'true' if x else 'false' for x in c.stribeck_measured) + ']']
    out += ['-p', f'stiction_prediction:={str(c.stiction_prediction).lower()}',
            '-p', f'stiction_rest_speed_rad_s:={c.stiction_rest_speed_rad_s}']
    if c.ki is not None:
        out += ['-p', f'ki:={list(c.ki)}', '-p', f'integral_limit_nm:={list(c.integral_limit_nm)}']
    return out


def lockstep_run(joints: int, seconds: float, timeout: float = 120.0) -> dict:
    """One lockstep run of simulator and pdplus with ``joints``; pdplus's step_duration [ms]
    of the samples that sent a command, over ``seconds`` of wall time after the first."""
    import subprocess
    import tempfile
    import time
    import uuid

    import numpy as np
    import rclpy
    from irb_description.node_main import state_qos
    from irb_interfaces.msg import ControllerState
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.serialization import deserialize_message

    from irb_control.process_group import stop_sessions
    ns = f'/step{uuid.uuid4().hex[:8]}'
    ros = ['--ros-args', '-r', f'__ns:={ns}']
    sine = ['-p', 'builtin_profile:=sine', '-p', 'sine_cycles:=1000.0']
    six = six_joint_args() if joints == 6 else []
    start = (['-p', 'joints:=6', '-p', 'initial_positions:=[0.0,0.6,0.2,0.0,-0.5,0.0]']
             if joints == 6 else [])
    logs = []

    def popen(cmd):
        f = tempfile.TemporaryFile('w+')
        logs.append(f)
        return subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, text=True,
                                start_new_session=True)
    procs = [popen(['ros2', 'run', 'irb_control', 'simulator', *ros, '-p', 'mode:=lockstep',
                    *start]),
             popen(['ros2', 'run', 'irb_control', 'pdplus', *ros, '-p', 'use_sim_time:=true',
                    '-p', 'auto_enable:=true', *sine, *six])]
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '0')))
    node = rclpy.create_node(f'step_{uuid.uuid4().hex[:6]}', namespace=ns, context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    raw = []
    node.create_subscription(ControllerState, 'controller_state', raw.append, state_qos(),
                             raw=True)
    out = {'joints': joints, 'load_before': [round(x, 2) for x in os.getloadavg()]}
    try:
        deadline = time.monotonic() + timeout
        while not raw and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.1)
            if any(p.poll() is not None for p in procs):
                break
        n0 = len(raw)
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds and raw:
            ex.spin_once(timeout_sec=0.1)
        out['listen_s'] = time.monotonic() - t0
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        stop_sessions(procs)
        if not raw:
            for name, f in zip(('simulator', 'pdplus'), logs):
                f.seek(0)
                out[f'{name}_log_tail'] = f.read().strip().splitlines()[-5:]
        for f in logs:
            f.close()
    states = [deserialize_message(b, ControllerState) for b in raw[n0:]] if raw else []
    sent = [s for s in states if s.mode in (1, 3, 5) and len(s.tau_command) == joints]
    dur = np.array([s.step_duration for s in sent]) * 1e3
    out.update({'states': len(states), 'samples': int(dur.size),
                'modes_seen': sorted({int(s.mode) for s in states}),
                'load_after': [round(x, 2) for x in os.getloadavg()]})
    if dur.size:
        out.update({'step_ms': dur.tolist(), 'median_ms': float(np.median(dur)),
                    'p90_ms': float(np.percentile(dur, 90)),
                    'p99_ms': float(np.percentile(dur, 99)), 'max_ms': float(dur.max())})
    return out


def paired_run(seconds: float, rate_hz: float = 248.0, warmup_s: float = 2.0,
               timeout: float = 120.0, extra_params: tuple = ()) -> dict:
    """``--paired`` (module docstring): pdplus's step_duration [ms] and the round trip [ms]
    per sample of each joint count, over ``seconds`` after ``warmup_s``."""
    import subprocess
    import tempfile
    import time
    import uuid

    import numpy as np
    import rclpy
    from irb_description.node_main import state_pub_qos, state_qos
    from irb_interfaces.msg import ControllerState
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    from irb_control.process_group import stop_sessions
    uid = uuid.uuid4().hex[:6]
    ns = {3: f'/pair3{uid}', 6: f'/pair6{uid}'}
    q0 = {3: [0.0, 0.9, 0.25], 6: [0.0, 0.6, 0.2, 0.0, -0.5, 0.0]}
    common = ['-p', 'auto_enable:=true', '-p', 'require_axis_status:=false',
              '-p', 'builtin_profile:=sine', '-p', 'sine_amplitude_rad:=0.01',
              '-p', 'sine_cycles:=100000.0', '-p', 'watchdog_missed_samples:=1000']
    extra = {3: ['-p', 'max_tracking_error_rad:=[1.0,1.0,1.0]'],
             6: six_joint_args() + ['-p', 'max_tracking_error_rad:=[1.0,1.0,1.0,1.0,1.0,1.0]']}
    logs = []

    def popen(cmd):
        f = tempfile.TemporaryFile('w+')
        logs.append(f)
        return subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, text=True,
                                start_new_session=True)
    more = [x for p in extra_params for x in ('-p', p)]
    procs = [popen(['ros2', 'run', 'irb_control', 'pdplus', '--ros-args', '-r',
                    f'__ns:={ns[n]}', *common, *extra[n], *more]) for n in (3, 6)]
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '0')))
    node = rclpy.create_node(f'pair_{uid}', context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    pubs, got, raw, rtt = {}, {}, {3: [], 6: []}, {3: [], 6: []}
    sent_at = {}
    for n in (3, 6):
        pubs[n] = node.create_publisher(JointState, f'{ns[n]}/joint_states', state_pub_qos())

        def on_cmd(_m, n=n):
            got[n] = True
            rtt[n].append(time.perf_counter() - sent_at[n])
        node.create_subscription(JointState, f'{ns[n]}/torque_command', on_cmd, state_qos(),
                                 raw=True)
        node.create_subscription(ControllerState, f'{ns[n]}/controller_state', raw[n].append,
                                 state_qos(), raw=True)
    names = {n: [f'joint_{i}' for i in range(1, n + 1)] for n in (3, 6)}

    def send(n):
        m = JointState(name=names[n], position=q0[n], velocity=[0.0] * n)
        s_ = time.time()
        m.header.stamp.sec, m.header.stamp.nanosec = int(s_), int((s_ % 1.0) * 1e9)
        got[n] = False
        sent_at[n] = time.perf_counter()
        pubs[n].publish(m)
    out = {'load_before': [round(x, 2) for x in os.getloadavg()]}
    period = 1.0 / rate_hz
    try:
        deadline = time.monotonic() + timeout     # until both answer (discovery, enable)
        while time.monotonic() < deadline and not (raw[3] and raw[6] and rtt[3] and rtt[6]):
            for n in (3, 6):
                send(n)
            t_end = time.monotonic() + period
            while time.monotonic() < t_end:
                ex.spin_once(timeout_sec=max(t_end - time.monotonic(), 0.0))
            if any(p.poll() is not None for p in procs):
                raise RuntimeError('a pdplus ended')
        t0 = time.monotonic()
        k = 0
        marks = None
        while time.monotonic() - t0 < warmup_s + seconds:
            if marks is None and time.monotonic() - t0 >= warmup_s:
                marks = {n: (len(raw[n]), len(rtt[n])) for n in (3, 6)}
            t_next = time.monotonic() + period
            for n in ((3, 6) if k % 2 == 0 else (6, 3)):
                send(n)
                t_ans = time.monotonic() + 0.05
                while not got[n] and time.monotonic() < t_ans:
                    ex.spin_once(timeout_sec=0.005)
            k += 1
            while time.monotonic() < t_next:
                ex.spin_once(timeout_sec=max(t_next - time.monotonic(), 0.0))
        out['pairs_sent'] = k
    except RuntimeError as exc:
        out['error'] = str(exc)
        marks = None
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        stop_sessions(procs)
        for n, f in zip((3, 6), logs):
            f.seek(0)
            out[f'pdplus{n}_log_tail'] = f.read().strip().splitlines()[-8:]
        for f in logs:
            f.close()
    out['load_after'] = [round(x, 2) for x in os.getloadavg()]
    if marks is None:
        return out
    for n in (3, 6):
        states = [deserialize_message(b, ControllerState) for b in raw[n][marks[n][0]:]]
        dur = np.array([s.step_duration for s in states
                        if s.mode in (1, 3, 5) and len(s.tau_command) == n]) * 1e3
        rt = np.array(rtt[n][marks[n][1]:]) * 1e3
        out[f'{n}_joints'] = {
            'samples': int(dur.size), 'modes_seen': sorted({int(s.mode) for s in states}),
            'step_ms': dur.tolist(), 'round_trip_ms': rt.tolist()}
    return out


def _stats(x) -> dict:
    import numpy as np
    x = np.asarray(x, float)
    if not x.size:
        return {'samples': 0}
    return {'samples': int(x.size), 'median_ms': float(np.median(x)),
            'p90_ms': float(np.percentile(x, 90)), 'p99_ms': float(np.percentile(x, 99)),
            'max_ms': float(x.max())}


def main_paired(a) -> int:
    out = {'benchmark': "pdplus's own step_duration per sample, 3 and 6 joints driven "
                        'alternately sample by sample (--paired)', 'rate_hz': a.rate,
           'load_average_before': os.getloadavg(), 'runs': []}
    pooled = {3: {'step_ms': [], 'round_trip_ms': []}, 6: {'step_ms': [], 'round_trip_ms': []}}
    for r in range(a.repeats):
        res = paired_run(a.seconds, a.rate, extra_params=tuple(a.pdplus_param))
        row = {k: v for k, v in res.items() if not k.endswith('_joints')}
        row['repeat'] = r
        for n in (3, 6):
            d = res.get(f'{n}_joints')
            if not d:
                continue
            for key in ('step_ms', 'round_trip_ms'):
                pooled[n][key] += d[key]
                row[f'{n}_joints_{key[:-3]}'] = _stats(d[key])
            row[f'{n}_joints_modes_seen'] = d['modes_seen']
        if row.get('3_joints_step', {}).get('samples') and \
                row.get('6_joints_step', {}).get('samples'):
            row['step_ratio_six_over_three'] = {
                k: row['6_joints_step'][f'{k}_ms'] / row['3_joints_step'][f'{k}_ms']
                for k in ('median', 'p90', 'p99')}
        print(json.dumps(row), flush=True)
        out['runs'].append(row)
    for key in ('step_ms', 'round_trip_ms'):
        s3, s6 = _stats(pooled[3][key]), _stats(pooled[6][key])
        out[f'pooled_{key[:-3]}'] = {'3_joints': s3, '6_joints': s6}
        if s3['samples'] and s6['samples']:
            out[f'pooled_{key[:-3]}']['ratio_six_over_three'] = {
                k: s6[f'{k}_ms'] / s3[f'{k}_ms'] for k in ('median', 'p90', 'p99')}
    out['load_average_after'] = os.getloadavg()
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f'{a.out}.json').write_text(json.dumps(out, indent=1))
    print(json.dumps({k: out[k] for k in ('pooled_step', 'pooled_round_trip',
                                          'load_average_after') if k in out}, indent=1))
    return 0


def main_lockstep(a) -> int:
    import numpy as np
    out = {'benchmark': "pdplus's own step_duration per sample, lockstep, 3 vs 6 joints "
                        'interleaved', 'load_average_before': os.getloadavg(), 'runs': []}
    for r in range(a.repeats):
        for n in (3, 6):
            res = lockstep_run(n, a.seconds)
            res['repeat'] = r
            print(json.dumps({k: v for k, v in res.items() if k != 'step_ms'}), flush=True)
            out['runs'].append(res)
    pooled = {}
    for n in (3, 6):
        xs = [np.asarray(x['step_ms']) for x in out['runs'] if x['joints'] == n
              and x.get('samples')]
        x = np.concatenate(xs) if xs else np.zeros(0)
        pooled[n] = ({'samples': int(x.size), 'median_ms': float(np.median(x)),
                      'p90_ms': float(np.percentile(x, 90)),
                      'p99_ms': float(np.percentile(x, 99))} if x.size else {'samples': 0})
    out['pooled'] = {f'{n}_joints': pooled[n] for n in (3, 6)}
    if pooled[3].get('samples') and pooled[6].get('samples'):
        out['pooled_ratio_six_over_three'] = {
            k: pooled[6][f'{k}_ms'] / pooled[3][f'{k}_ms'] for k in ('median', 'p90', 'p99')}
    per = []
    for r in range(a.repeats):
        pair = {x['joints']: x for x in out['runs'] if x['repeat'] == r and x.get('samples')}
        if 3 in pair and 6 in pair:
            per.append({k: pair[6][f'{k}_ms'] / pair[3][f'{k}_ms']
                        for k in ('median', 'p90', 'p99')})
    out['ratio_six_over_three_per_repeat'] = per
    for run in out['runs']:
        run.pop('step_ms', None)
    out['load_average_after'] = os.getloadavg()
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f'{a.out}.json').write_text(json.dumps(out, indent=1))
    print(json.dumps({k: out[k] for k in ('pooled', 'pooled_ratio_six_over_three',
                                          'ratio_six_over_three_per_repeat',
                                          'load_average_after') if k in out}, indent=1))
    return 0


def inprocess_pair(motion: str, seconds: float) -> dict:
    """``--inprocess`` (module docstring): one pair of closed loops, stepped alternately;
    the step times [ms] of each joint count."""
    import time

    import numpy as np
    from irb_description.model import RobotModel
    from irb_description.orientation import joint_path6, orientation_from_spec
    from irb_description.path import rectangle_path
    from irb_description.six_axis import SixAxisKinematics, pose
    from irb_description.six_axis_model import SixJointModel

    from irb_control.closed_loop import build_default, build_six_joint
    from irb_control.plant import PlantConfig
    from irb_control.profiles import (default_circle_profile, polynomial_theta_of_time,
                                      profile_from_theta_samples, sine_trajectory)
    tcp = pose(np.eye(3), [0.0, 0.0, 0.10])
    six = _SIX.setdefault('model', SixJointModel(tcp))
    three = _SIX.setdefault('three', RobotModel.load())
    path = rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025)
    if motion == 'rectangle':
        if 'prof6' not in _SIX:
            law = orientation_from_spec({'law': 'path_normal', 'normal': [0.3, 0.1, 1.0],
                                         'x_mode': 'fixed'}, path)
            kin = SixAxisKinematics(tcp=tcp)
            cfg = joint_path6(kin, path, law, np.linspace(0.0, 2 * np.pi, 721)).configuration
            t, th, thd, thdd = polynomial_theta_of_time(max(seconds - 1.0, 2.0))
            _SIX['prof6'] = profile_from_theta_samples(
                six, path, th, thd, thdd, t, grid=1441,
                joints=lambda x: joint_path6(kin, path, law, x, configuration=cfg,
                                             derivatives=True))
            _SIX['prof3'] = default_circle_profile(three, path, max(seconds - 1.0, 2.0))
        prof6, prof3 = _SIX['prof6'], _SIX['prof3']
        p6, c6 = build_six_joint(prof6, path, tcp, friction_mode='file', model=six)
        p3, c3 = build_default('file', model=three, path=path)
        c3.set_path_profile(prof3)
        p3.reset(prof3.q[0])
    else:
        q6 = np.array([0.0, 0.6, 0.2, 0.0, -0.5, 0.0])
        q3 = np.array([0.0, 0.9, 0.25])
        cyc = max(seconds, 1.0) * 0.6 / (2 * np.pi * 0.3)
        tr6 = sine_trajectory(q6, 0, 0.6, cycles=cyc)
        tr3 = sine_trajectory(q3, 0, 0.6, cycles=cyc)
        from irb_control.closed_loop import controller_friction, six_axis_controller_config
        from irb_control.pd_plus import PdPlusController
        from irb_control.plant import Plant, default_plant_yaml, load_plant_friction
        _, pf6 = load_plant_friction(default_plant_yaml(), six.joint_names)
        p6 = Plant(six, pf6, PlantConfig(initial_q=tuple(q6)))
        c6 = PdPlusController(six, path, six_axis_controller_config(),
                              controller_friction(six, 'file', default_plant_yaml()))
        c6.set_time_trajectory(tr6)
        p3, c3 = build_default('file', model=three, path=path)
        c3.set_time_trajectory(tr3)
        p3.reset(q3)
    loops = {3: (p3, c3), 6: (p6, c6)}
    dt = {3: [], 6: []}
    cpu = {3: [], 6: []}
    for _, c in loops.values():
        c.enable()
    perf = time.perf_counter
    tt = time.thread_time_ns
    steps = int(seconds / p3.config.period_s)
    cpu0 = time.process_time()
    stops = {}
    for k in range(steps):
        for n in ((3, 6) if k % 2 == 0 else (6, 3)):
            plant, ctrl = loops[n]
            y = plant.measure()
            c1 = tt()
            t1 = perf()
            o = ctrl.step(y.t, y.q, y.qd)
            t2 = perf()
            c2 = tt()
            if o.publish:
                dt[n].append(t2 - t1)
                cpu[n].append(c2 - c1)
                plant.command(o.tau)
            elif o.mode == 4:
                stops[n] = o.stop_reason
            plant.step()
    return {'motion': motion, 'seconds': seconds, 'periods': steps,
            'cpu_s': time.process_time() - cpu0, 'stops': stops,
            'step_ms': {n: (np.array(dt[n]) * 1e3).tolist() for n in (3, 6)},
            'cpu_ms': {n: (np.array(cpu[n]) * 1e-6).tolist() for n in (3, 6)}}


_SIX = {}


def _istats(x) -> dict:
    import numpy as np
    x = np.asarray(x, float)
    return {'samples': int(x.size), 'min_ms': float(x.min()),
            'p10_ms': float(np.percentile(x, 10)), 'median_ms': float(np.median(x)),
            'p90_ms': float(np.percentile(x, 90)), 'p99_ms': float(np.percentile(x, 99)),
            'max_ms': float(x.max())}


def main_inprocess(a) -> int:
    out = {'benchmark': 'PdPlusController.step alone, 3 and 6 joints stepped alternately in '
                        'one process (--inprocess)', 'commit': _commit(),
           'load_average_before': os.getloadavg(), 'runs': [], 'pooled': {}}
    keys = ('min', 'p10', 'median', 'p90', 'p99')
    for motion in ('sine', 'rectangle'):
        pooled = {3: [], 6: []}
        pooled_cpu = {3: [], 6: []}
        for r in range(a.repeats):
            res = inprocess_pair(motion, a.seconds)
            row = {k: v for k, v in res.items() if k not in ('step_ms', 'cpu_ms')}
            row['repeat'] = r
            row['load'] = os.getloadavg()
            for n in (3, 6):
                pooled[n] += res['step_ms'][n]
                pooled_cpu[n] += res['cpu_ms'][n]
                row[f'{n}_joints'] = _istats(res['step_ms'][n])
                row[f'{n}_joints_cpu'] = _istats(res['cpu_ms'][n])
            row['ratio_six_over_three'] = {
                k: row['6_joints'][f'{k}_ms'] / row['3_joints'][f'{k}_ms'] for k in keys}
            row['cpu_ratio_six_over_three'] = {
                k: row['6_joints_cpu'][f'{k}_ms'] / row['3_joints_cpu'][f'{k}_ms']
                for k in keys}
            print(json.dumps(row), flush=True)
            out['runs'].append(row)
        s3, s6 = _istats(pooled[3]), _istats(pooled[6])
        c3, c6 = _istats(pooled_cpu[3]), _istats(pooled_cpu[6])
        out['pooled'][motion] = {
            '3_joints': s3, '6_joints': s6,
            'ratio_six_over_three': {k: s6[f'{k}_ms'] / s3[f'{k}_ms'] for k in keys},
            '3_joints_cpu': c3, '6_joints_cpu': c6,
            'cpu_ratio_six_over_three': {k: c6[f'{k}_ms'] / c3[f'{k}_ms'] for k in keys}}
    out['load_average_after'] = os.getloadavg()
    RESULTS.mkdir(exist_ok=True)
    name = a.out if a.out != 'six_joint_step_nodes' else 'six_joint_step_inprocess'
    (RESULTS / f'{name}.json').write_text(json.dumps(out, indent=1))
    print(json.dumps({k: out[k] for k in ('pooled', 'load_average_after')}, indent=1))
    return 0


def _commit() -> str:
    import subprocess
    try:
        return subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                              text=True, cwd=os.path.dirname(os.path.abspath(__file__)),
                              timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ''


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--seconds', type=float, default=20.0, help='listening time per run [s]')
    ap.add_argument('--repeats', type=int, default=2, help='runs of each, interleaved')
    ap.add_argument('--rt-priority', type=int, default=20, help='SCHED_FIFO priority, 0 = off')
    ap.add_argument('--lockstep', action='store_true',
                    help="pdplus's own step cost in lockstep runs (module docstring)")
    ap.add_argument('--paired', action='store_true',
                    help='two pdplus (3 and 6 joints) driven alternately (module docstring)')
    ap.add_argument('--rate', type=float, default=248.0, help='--paired: pairs per second')
    ap.add_argument('--pdplus-param', action='append', default=[], metavar='NAME:=VALUE',
                    help='--paired: one more parameter of both pdplus (repeatable)')
    ap.add_argument('--out', default='six_joint_step_nodes',
                    help='--lockstep, --paired: results/<out>.json')
    ap.add_argument('--inprocess', action='store_true',
                    help='PdPlusController.step alone, 3 and 6 joints alternately, no ROS '
                         '(module docstring)')
    a = ap.parse_args(argv)
    if a.inprocess:
        return main_inprocess(a)
    if a.paired:
        return main_paired(a)
    if a.lockstep:
        return main_lockstep(a)
    from run_benchmarks import _loop_run
    six = six_joint_args()
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
