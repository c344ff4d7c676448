#!/usr/bin/env python3
"""Benchmarks of irb_control; each prints JSON and writes it (and plots) to results/.

    python benchmarks/run_benchmarks.py loop      # simulator <-> pdplus, two processes, 248 Hz
    python benchmarks/run_benchmarks.py handover  # the loop while 20k-point plans arrive and
                                                  # during enable (issue 32)
    python benchmarks/run_benchmarks.py accuracy  # path accuracy + energy, no/nominal/true FF
    python benchmarks/run_benchmarks.py speed     # offline simulation speed
    python benchmarks/run_benchmarks.py all

Needs `source scripts/env.sh`; `loop` also ROS_DOMAIN_ID / ROS_AUTOMATIC_DISCOVERY_RANGE.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))   # echo_floor beside this file

RESULTS = Path(__file__).resolve().parent / 'results'
MODES = ('none', 'nominal', 'file')
MODE_LABEL = {'none': 'no FF', 'nominal': 'nominal FF', 'file': 'true-plant FF'}


def _write(name: str, data: dict) -> None:
    RESULTS.mkdir(parents=True, exist_ok=True)
    data.setdefault('load_average_1_5_15_min_at_end', [round(x, 2) for x in os.getloadavg()])
    data.setdefault('machine_cores', os.cpu_count())
    text = json.dumps(data, indent=2)
    (RESULTS / f'{name}.json').write_text(text)
    print(text)


# --- (1) loop timing ------------------------------------------------------------------------
def _cpu_s(pid: int) -> float:
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def _fifo_permitted() -> bool:
    """Can this process's children use SCHED_FIFO? (tried on a short-lived child)"""
    try:
        return subprocess.run(['chrt', '-f', '1', 'true'], capture_output=True,
                              timeout=10).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


def bench_loop(duration: float = 20.0, rt_priority: int = 20, repeats: int = 1) -> dict:
    """Runs with default scheduling (``repeats`` of them: on a shared VM one run's p99 varies
    by +-0.2 ms), then one with ``realtime_priority:=rt_priority`` on simulator and pdplus
    (skipped, with the reason, when SCHED_FIFO is not permitted or rt_priority is 0). The
    first default run's figures are at the top level of loop.json, every default run's p99
    under 'default_runs', the realtime run's under 'realtime_priority_run'."""
    from echo_floor import measure as echo_floor
    runs, echoes = [], []
    for _ in range(max(repeats, 1)):
        # the transport's floor right before each loop run, same duration: the machine's state
        # moves p99 by +-0.2 ms, so only a ratio measured together compares like with like
        echoes.append(echo_floor(duration))
        runs.append(_loop_run(duration, 0))
    out = runs[0]
    p99 = [r['state_to_command_latency_ms (simulator side)']['p99'] for r in runs]
    echo_p99 = [e['round_trip_ms']['p99'] for e in echoes]
    out['echo_floor'] = echoes[0]
    out['default_runs'] = {
        'p99_ms': p99, 'p50_ms': [r['state_to_command_latency_ms (simulator side)']['p50']
                                  for r in runs],
        'missed_fraction': [r['missed_fraction'] for r in runs],
        'echo_p99_ms': echo_p99,
        'p99_loop_over_p99_echo': [a / b for a, b in zip(p99, echo_p99)],
        'goal_met': f"{sum(bool(r['goal_met']) for r in runs)} of {len(runs)}"}
    if rt_priority and _fifo_permitted():
        out['realtime_priority_run'] = _loop_run(duration, rt_priority)
    else:
        out['realtime_priority_run'] = {'skipped': 'rt_priority 0' if not rt_priority else
                                        'SCHED_FIFO not permitted here (chrt -f 1 failed)'}
    rt = out['realtime_priority_run']
    out['goal_met_with_realtime_priority'] = rt.get('goal_met')
    _write('loop', out)
    return out


def _loop_run(duration: float, rt_priority: int, pdplus_args: tuple = (),
              simulator_args: tuple = (), tag: str = '') -> dict:
    """One loop run; ``pdplus_args``/``simulator_args``: more ROS arguments of each node
    (bench_six_joint_loop: joints:=6), ``tag``: in the log and stats file names."""
    import rclpy
    from irb_interfaces.msg import ControllerState

    from irb_control.node_util import make_executor
    from irb_description.node_main import state_qos
    ns = f'/bench{os.getpid()}'
    stats_path = RESULTS / f'loop_simulator_stats{tag}.json'
    RESULTS.mkdir(parents=True, exist_ok=True)
    common = ['--ros-args', '-r', f'__ns:={ns}', '-p', f'realtime_priority:={rt_priority}']
    # the nodes' output goes to files (a pipe nobody reads could fill and block a node)
    tag = (f'_rt{rt_priority}' if rt_priority else '') + tag
    logs = {n: open(RESULTS / f'loop_{n}{tag}.log', 'w') for n in ('pdplus', 'simulator')}
    ctrl = subprocess.Popen([sys.executable, '-m', 'irb_control.pdplus_node', *common,
                             '-p', 'profile_duration_s:=10.0', '-p', 'auto_enable:=true',
                             *pdplus_args],
                            stdout=logs['pdplus'], stderr=subprocess.STDOUT, text=True)
    sim = subprocess.Popen([sys.executable, '-m', 'irb_control.simulator_node', *common,
                            '-p', 'mode:=realtime', '-p', f'stats_path:={stats_path}',
                            *simulator_args],
                           stdout=logs['simulator'], stderr=subprocess.STDOUT, text=True)
    rclpy.init()
    node = rclpy.create_node('bench_listener')
    states = []
    # the listener is an observer on the same 2 cores: it keeps the serialized messages (no
    # message objects while the loop runs) and decodes them afterwards; the light
    # EventsExecutor
    node.create_subscription(ControllerState, f'{ns}/controller_state', states.append,
                             state_qos(), raw=True)
    ex = make_executor('events')
    ex.add_node(node)
    t_end = time.monotonic() + 60.0
    while not states and time.monotonic() < t_end:
        ex.spin_once(timeout_sec=0.1)
    cpu0 = {'simulator': _cpu_s(sim.pid), 'pdplus': _cpu_s(ctrl.pid)}
    load_start = [round(x, 2) for x in os.getloadavg()]
    n0 = len(states)
    t0 = time.monotonic()
    while time.monotonic() - t0 < duration:
        ex.spin_once(timeout_sec=0.1)
    cpu1 = {'simulator': _cpu_s(sim.pid), 'pdplus': _cpu_s(ctrl.pid)}
    wall = time.monotonic() - t0
    steps = max(len(states) - n0, 1)
    for p in (sim, ctrl):           # simulator first: its statistics end while pdplus runs
        p.send_signal(signal.SIGINT)
        p.wait(timeout=30)
    for f in logs.values():
        f.close()
    ex.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    sim_stats = json.loads(stats_path.read_text())
    from rclpy.serialization import deserialize_message
    states = [deserialize_message(b, ControllerState) for b in states]
    dur = np.array([s.step_duration for s in states[n0:]]) * 1e3
    modes = [int(s.mode) for s in states[n0:]]
    expected_steps = wall / 0.004032
    out = {
        'benchmark': 'loop timing, simulator <-> pdplus, 2 processes, real time 248 Hz',
        'realtime_priority': rt_priority,
        'listen_wall_s': round(wall, 2),
        'state_to_command_latency_ms (simulator side)': sim_stats['latency_ms'],
        'missed_deadlines (command not back before next tick)': sim_stats['missed_deadlines'],
        'steps (simulator)': sim_stats['steps'],
        'missed_fraction': sim_stats['missed_deadlines'] / max(sim_stats['steps'], 1),
        'max_consecutive_missed': sim_stats['max_consecutive_missed'],
        'pdplus_missed_deadlines_counter': int(states[-1].missed_deadlines) if states else None,
        'pdplus_step_compute_ms': {'p50': float(np.percentile(dur, 50)),
                                   'p99': float(np.percentile(dur, 99)),
                                   'max': float(dur.max())},
        'controller_states_received_fraction': steps / expected_steps,
        'cpu_per_step_ms': {k: (cpu1[k] - cpu0[k]) / expected_steps * 1e3 for k in cpu0},
        'modes_seen': sorted(set(modes)),
        'goal': 'p99 < 1 ms, < 0.1 % missed, never 3 in a row',
        'load_average_1_5_15_min_at_start': load_start,
    }
    lat = sim_stats['latency_ms']
    out['goal_met'] = bool(lat and lat['p99'] < 1.0 and out['missed_fraction'] < 0.001
                           and out['max_consecutive_missed'] < 3)
    out['load_average_1_5_15_min_at_end'] = [round(x, 2) for x in os.getloadavg()]
    return out


# --- (1b) the loop while plans arrive and during enable (issue 32) --------------------------
def _plan_20k(model, spec: dict, points: int, duration: float, stamp_sec: int):
    """A JointTrajectory of ``points`` points along the path ``spec`` (polynomial speed law),
    carrying its path (irb_description.plan_path), as the planner sends plans."""
    from irb_description.path import path_from_spec
    from irb_description.plan_path import path_frame_id
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from irb_control.profiles import polynomial_theta_of_time, profile_from_theta_samples
    t, th, thd, thdd = polynomial_theta_of_time(duration, n=points)
    prof = profile_from_theta_samples(model, path_from_spec(spec), th, thd, thdd, t,
                                      grid=points)
    msg = JointTrajectory(joint_names=['joint_1', 'joint_2', 'joint_3'])
    msg.header.stamp.sec = stamp_sec
    msg.header.frame_id = path_frame_id(spec)
    for k in range(points):
        p = JointTrajectoryPoint(positions=prof.q[k].tolist(), velocities=prof.qd[k].tolist(),
                                 accelerations=prof.qdd[k].tolist())
        p.time_from_start.sec = int(prof.t[k])
        p.time_from_start.nanosec = int(round((prof.t[k] % 1) * 1e9))
        msg.points.append(p)
    return msg


def _machine_floor(seconds: float, rt_priority: int) -> dict | None:
    """machine_floor.py in its own process (the loop's scheduling): the host's own stalls."""
    if seconds <= 0:
        return None
    r = subprocess.run([sys.executable, str(Path(__file__).with_name('machine_floor.py')),
                        '--seconds', str(seconds), '--priority', str(rt_priority)],
                       capture_output=True, text=True, timeout=seconds + 60)
    return json.loads(r.stdout) if r.returncode == 0 else {'error': r.stderr.strip()[-300:]}


def bench_handover(cycles: int = 4, points: int = 20000, rt_priority: int = 0,
                   floor_s: float = 20.0) -> dict:
    """simulator (real time) + pdplus as processes; a listener records every joint state and
    every torque command (reliable, bytes only) with its arrival time. ``cycles`` times, while
    pdplus holds the end of the previous motion: a ``points``-point plan on a new path is
    published (window: 0.2 s before to 1 s after pdplus's verdict), then ``~/enable`` is
    called (window: 0.2 s before the call to 1 s after it: ramp construction and the first
    ramp steps), and the motion runs to its hold. Per window: states that got no command
    (by stamp), the state -> command latency at the listener, pdplus's step time; the same
    for quiet windows of equal length while holding (the baseline)."""
    import rclpy
    from irb_description.model import RobotModel
    from irb_description.node_main import latched_qos
    from irb_interfaces.msg import ControllerState, PlanStatus
    from rclpy.serialization import deserialize_message
    from std_srvs.srv import Trigger
    from trajectory_msgs.msg import JointTrajectory

    from irb_control.node_util import make_executor
    model = RobotModel.load()
    paths = [{'type': 'line', 'waypoints': [[0.55, -0.10, 0.30], [0.75, 0.10, 0.30]]},
             {'type': 'arc', 'center': [0.65, 0.0, 0.25], 'normal': [0.0, 0.0, 1.0],
              'radius': 0.08, 'start_angle': 0.0, 'sweep': 3.0}]
    plans = [_plan_20k(model, paths[k % 2], points, 3.0, 100 + k) for k in range(cycles)]
    floor_before = _machine_floor(floor_s, rt_priority)
    ns = f'/handover{os.getpid()}'
    RESULTS.mkdir(parents=True, exist_ok=True)
    common = ['--ros-args', '-r', f'__ns:={ns}', '-p', f'realtime_priority:={rt_priority}']
    logs = {n: open(RESULTS / f'handover_{n}.log', 'w') for n in ('pdplus', 'simulator')}
    ctrl = subprocess.Popen([sys.executable, '-m', 'irb_control.pdplus_node', *common,
                             '-p', 'profile_duration_s:=3.0', '-p', 'auto_enable:=false',
                             '-p', f'max_plan_points:={points}', '-p', 'gc_report_ms:=2.0'],
                            stdout=logs['pdplus'], stderr=subprocess.STDOUT, text=True)
    sim_stats = RESULTS / 'handover_simulator_stats.json'
    sim = subprocess.Popen([sys.executable, '-m', 'irb_control.simulator_node', *common,
                            '-p', 'mode:=realtime', '-p', f'stats_path:={sim_stats}',
                            '-p', 'stats_per_state:=true'],
                           stdout=logs['simulator'], stderr=subprocess.STDOUT, text=True)
    rclpy.init()
    node = rclpy.create_node('bench_handover')
    cs, verdicts = [], []
    clock = time.monotonic
    node.create_subscription(ControllerState, f'{ns}/controller_state',
                             lambda b: cs.append((clock(), b)), 1000, raw=True)
    node.create_subscription(PlanStatus, f'{ns}/pdplus/plan_status',
                             lambda m: verdicts.append((clock(), m)), latched_qos())
    pub = node.create_publisher(JointTrajectory, f'{ns}/planned_trajectory', latched_qos())
    enable = node.create_client(Trigger, f'{ns}/pdplus/enable')
    ex = make_executor('single')
    ex.add_node(node)

    def spin_until(cond, limit):
        end = clock() + limit
        while not cond() and clock() < end:
            ex.spin_once(timeout_sec=0.02)
        return cond()

    def mode():
        return deserialize_message(cs[-1][1], ControllerState).mode if cs else None

    reset = node.create_client(Trigger, f'{ns}/simulator/reset')
    platform_stops = []

    def call_enable():
        for _ in range(100):                    # until the drives' status has reached it
            fut = enable.call_async(Trigger.Request())
            spin_until(fut.done, 30.0)
            r = fut.result()
            if r.success:
                return r
            if 'reset it first' in r.message:   # the simulator braked (a platform stall)
                platform_stops.append(r.message)
                f = reset.call_async(Trigger.Request())
                spin_until(f.done, 30.0)
            elif 'axis status' not in r.message:
                return r
            spin_until(lambda: False, 0.2)
        return r
    events = []          # (kind, t_start, t_end) windows on the listener's clock
    load_start = [round(x, 2) for x in os.getloadavg()]
    try:
        assert enable.wait_for_service(timeout_sec=60.0), 'pdplus did not come up'
        spin_until(lambda: len(cs) > 250, 60.0)
        r = call_enable()                                    # the built-in circle first
        assert r.success, r.message
        while not spin_until(lambda: mode() == ControllerState.MODE_HOLD, 60.0):
            assert mode() == ControllerState.MODE_STOPPED and len(platform_stops) < 10, \
                'no hold'
            platform_stops.append(deserialize_message(cs[-1][1], ControllerState).stop_reason)
            assert call_enable().success
        for k, plan in enumerate(plans):
            spin_until(lambda: False, 1.0)
            t = clock()
            events.append(('quiet', t, t + 1.2))
            spin_until(lambda: False, 1.3)
            n = len(verdicts)
            t0 = clock()
            pub.publish(plan)
            assert spin_until(lambda: len(verdicts) > n and verdicts[-1][1].plan_stamp.sec ==
                              plan.header.stamp.sec, 120.0), 'no verdict'
            tv = verdicts[-1][0]
            assert verdicts[-1][1].accepted, verdicts[-1][1].reason
            events.append(('plan', tv - 0.2, tv + 1.0))
            events.append(('plan_whole', t0, tv + 1.0))
            spin_until(lambda: False, 1.2)
            t1 = clock()
            r = call_enable()
            assert r.success, r.message
            events.append(('enable', t1 - 0.2, t1 + 1.0))
            assert spin_until(lambda: mode() == ControllerState.MODE_RAMP, 10.0)
            assert spin_until(lambda: mode() in (ControllerState.MODE_HOLD,
                                                 ControllerState.MODE_STOPPED), 60.0)
            if mode() == ControllerState.MODE_STOPPED:       # a stop: recorded, go on
                events.append(('stopped', clock(), clock()))
                platform_stops.append(deserialize_message(cs[-1][1],
                                                          ControllerState).stop_reason)
                assert call_enable().success
                assert spin_until(lambda: mode() in (ControllerState.MODE_HOLD,
                                                     ControllerState.MODE_STOPPED), 60.0)
        spin_until(lambda: False, 1.3)
    finally:
        for p in (sim, ctrl):
            p.send_signal(signal.SIGINT)
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
        for f in logs.values():
            f.close()
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    steps = [(t, deserialize_message(b, ControllerState)) for t, b in cs]
    run_minutes = (steps[-1][0] - steps[0][0]) / 60.0 if len(steps) > 1 else float('nan')
    floor_after = _machine_floor(floor_s, rt_priority)
    # pdplus's garbage collections over 2 ms (gc_report_ms), from its log
    gc_ms = [float(x) for x in re.findall(r'collection took ([0-9.]+) ms',
                                          (RESULTS / 'handover_pdplus.log').read_text())]

    # the simulator's own record: when each state went out and when its answer came back
    # (CLOCK_MONOTONIC, the same clock in every process of the host; the listener's arrival
    # times lag on a loaded machine)
    per_state = json.loads(sim_stats.read_text())['per_state_monotonic_s_latency_ms']

    def window(kind, a, b):
        ss = [(t, lat) for t, lat in per_state if a <= t <= b]
        unanswered = sum(1 for _, lat in ss if lat is None)
        lat = [x for _, x in ss if x is not None]
        dur = [1e3 * m.step_duration for t, m in steps if a <= t <= b]
        modes = sorted({int(m.mode) for t, m in steps if a <= t <= b})
        return {'kind': kind, 'states': len(ss), 'unanswered': unanswered, 'modes': modes,
                # when in the window [s from its start] each unanswered state went out
                'unanswered_at_s': [round(t - a, 4) for t, lat in ss if lat is None][:20],
                'latency_ms_p50': float(np.median(lat)) if lat else None,
                'latency_ms_max': float(max(lat)) if lat else None,
                'pdplus_step_ms_max': float(max(dur)) if dur else None}
    wins = [window(*e) for e in events if e[0] != 'stopped']
    # a window in which pdplus was stopped (a platform stall: see stops_and_refusals_seen)
    # answers nothing by design: counted apart
    summary = {'windows_with_a_stop': sum(1 for x in wins if ControllerState.MODE_STOPPED
                                          in x['modes'])}
    for kind in ('quiet', 'plan', 'plan_whole', 'enable'):
        w = [x for x in wins if x['kind'] == kind
             and ControllerState.MODE_STOPPED not in x['modes']]
        if w:
            summary[kind] = {
                'windows': len(w), 'unanswered_total': sum(x['unanswered'] for x in w),
                'windows_with_unanswered': sum(1 for x in w if x['unanswered']),
                'unanswered_per_1000_states': round(
                    1e3 * sum(x['unanswered'] for x in w) / max(1, sum(x['states'] for x in w)),
                    2),
                'latency_ms_max': max(x['latency_ms_max'] or 0.0 for x in w),
                'latency_ms_p50_median': float(np.median([x['latency_ms_p50'] for x in w
                                                          if x['latency_ms_p50']])),
                'pdplus_step_ms_max': max(x['pdplus_step_ms_max'] or 0.0 for x in w)}
    modes = [int(m.mode) for _, m in steps]
    stops = sum(1 for a, b in zip(modes, modes[1:])
                if b == ControllerState.MODE_STOPPED and a != b)
    out = {'benchmark': 'handover: the 248 Hz loop while plans arrive and during enable '
                        '(simulator real time + pdplus; unanswered states and state -> command '
                        "latency from the simulator's own per-state record)",
           'plan_points': points, 'cycles': cycles, 'realtime_priority': rt_priority,
           'stopped': any(e[0] == 'stopped' for e in events),
           'stops_and_refusals_seen': platform_stops,
           'stop_reasons': sorted({m.stop_reason for _, m in steps if m.stop_reason}),
           'modes_seen': sorted(set(modes)), 'summary': summary, 'windows': wins,
           # the host's own stalls against the run's stops, per minute
           'machine_floor_before': floor_before, 'machine_floor_after': floor_after,
           'pdplus_gc_over_2ms': {'count': len(gc_ms), 'max_ms': max(gc_ms, default=None)},
           # stops = pdplus's controller_state entering STOPPED (its own or the drive's)
           'stops': stops, 'run_minutes': round(run_minutes, 3),
           'stops_per_minute': round(stops / run_minutes, 2)
           if np.isfinite(run_minutes) and run_minutes > 0 else None,
           'load_average_1_5_15_min_at_start': load_start}
    _write('handover' + (f'_rt{rt_priority}' if rt_priority else ''), out)
    return out


# --- (2)+(3) accuracy and energy --------------------------------------------------------------
def _run(model, mode: str, traj=None, circle_duration: float = 10.0):
    from irb_control.closed_loop import build_default, controller_friction, simulate_closed_loop
    from irb_control.pd_plus import ControllerConfig, PdPlusController
    from irb_control.plant import default_plant_yaml
    plant, ctrl = build_default(mode, duration_s=circle_duration, model=model)
    if traj is not None:
        ctrl = PdPlusController(model, ctrl.path, ControllerConfig(),
                                controller_friction(model, mode, default_plant_yaml()))
        ctrl.set_time_trajectory(traj)
        return simulate_closed_loop(plant, ctrl, traj.duration + 1.0)
    return simulate_closed_loop(plant, ctrl, circle_duration + 3.0)


def _stats(x: np.ndarray) -> dict:
    return {'mean_mm': float(np.mean(x) * 1e3), 'rms_mm': float(np.sqrt(np.mean(x**2)) * 1e3),
            'max_mm': float(np.max(x) * 1e3)}


def bench_accuracy(plots: bool = True) -> dict:
    from irb_description.model import RobotModel

    from irb_control.closed_loop import polyline_distance
    from irb_control.profiles import sine_trajectory
    model = RobotModel.load()
    out = {'benchmark': 'path accuracy and energy, offline closed loop',
           'metrics': 'circle: camera point to nearest circle point; sine (time-driven): '
                      'camera point to FK(q_ref) at the same time (primary) and to the '
                      'nearest point of the reference curve; joint error = q_ref - q (true)',
           'plant_friction': 'config/plant.yaml (differs from nominal)', 'circle': {},
           'sine': {}}
    figs = []
    for T in (10.0, 15.0):
        key = f'{T:g}s'
        out['circle'][key] = {}
        runs = {}
        for mode in MODES:
            r = _run(model, mode, circle_duration=T)
            runs[mode] = r
            e = r.path_error_camera()
            je = r.joint_error()[r.motion_mask()]
            out['circle'][key][mode] = {
                'camera_path_error': _stats(e),
                'joint_error_max_mrad': (np.nanmax(np.abs(je), axis=0) * 1e3).round(3).tolist(),
                'joint_error_rms_mrad': (np.sqrt(np.nanmean(je**2, axis=0)) * 1e3).round(3)
                .tolist(),
                'energy_j': r.energy, 'motion_time_s': float(r.t[-1] - r.path_start_time()),
                'stop_reason': r.stop_reason}
        base = out['circle'][key]['none']['camera_path_error']['mean_mm']
        for mode in ('nominal', 'file'):
            m = out['circle'][key][mode]['camera_path_error']['mean_mm']
            out['circle'][key][mode]['path_error_reduction_vs_none'] = 1 - m / base
        figs.append((f'circle_{key}', runs))
    q0 = None
    for joint in range(3):
        for v in (0.1, 0.5, 1.0):
            key = f'joint{joint + 1}_{v:g}rad_s'
            out['sine'][key] = {}
            runs = {}
            for mode in MODES:
                if q0 is None:
                    from irb_control.plant import PlantConfig
                    q0 = np.array(PlantConfig().initial_q)
                traj = sine_trajectory(q0, joint, v, amplitude=0.2, cycles=1.0)
                r = _run(model, mode, traj=traj)
                runs[mode] = r
                ref_curve = np.array([model.fk(q) for q in traj.q[::2]])
                sel = r.cam_t >= r.path_start_time()
                e_near = polyline_distance(ref_curve, r.cam_p[sel])
                e = _same_time_error(model, r, sel)
                je = r.joint_error()[r.motion_mask()][:, joint]
                out['sine'][key][mode] = {
                    'camera_path_error': _stats(e),
                    'camera_nearest_point_error': _stats(e_near),
                    'joint_error_max_mrad': float(np.nanmax(np.abs(je)) * 1e3),
                    'joint_error_rms_mrad': float(np.sqrt(np.nanmean(je**2)) * 1e3),
                    'energy_j': r.energy, 'stop_reason': r.stop_reason}
            base = out['sine'][key]['none']['camera_path_error']['mean_mm']
            for mode in ('nominal', 'file'):
                m = out['sine'][key][mode]['camera_path_error']['mean_mm']
                out['sine'][key][mode]['path_error_reduction_vs_none'] = 1 - m / base
            if v == 0.5:
                figs.append((f'sine_{key}', runs))
    if plots:
        out['plots'] = [_plot(name, runs, model) for name, runs in figs]
    _write('accuracy', out)
    return out


def _same_time_error(model, r, sel) -> np.ndarray:
    """|camera point - FK(q_ref)| (M,) [m] at the camera times; q_ref logged at t_k is the
    reference for t_k + n T (n = prediction samples)."""
    m = r.motion_mask()
    t_ref = r.t[m] + r.prediction_samples * 0.004032
    tc = r.cam_t[sel]
    ok = (tc >= t_ref[0]) & (tc <= t_ref[-1])
    q = np.column_stack([np.interp(tc[ok], t_ref, r.q_ref[m][:, j]) for j in range(3)])
    p_ref = np.array([model.fk(qi) for qi in q])
    return np.linalg.norm(r.cam_p[sel][ok] - p_ref, axis=1)


def _plot(name: str, runs: dict, model) -> str:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from irb_control.closed_loop import circle_distance
    fig, axes = plt.subplots(len(runs), 2, figsize=(11, 2.6 * len(runs)), squeeze=False)
    for row, (mode, r) in zip(axes, runs.items()):
        t0 = r.path_start_time()
        sel = r.cam_t >= t0
        if name.startswith('circle'):
            e = circle_distance(r.path, r.cam_p[sel])
            tc = r.cam_t[sel]
        else:
            e = _same_time_error(model, r, sel)
            tc = r.cam_t[sel][:len(e)]
        row[0].plot(tc - t0, e * 1e3, lw=0.7)
        row[0].set_ylabel('path error [mm]')
        row[0].set_title(f'{MODE_LABEL[mode]}: camera, mean {np.mean(e) * 1e3:.3f} mm')
        m = r.motion_mask()
        je = r.joint_error()[m] * 1e3
        for j in range(3):
            row[1].plot(r.t[m] - t0, je[:, j], lw=0.7, label=f'joint {j + 1}')
        row[1].set_ylabel('joint error [mrad]')
        row[1].set_title(f'{MODE_LABEL[mode]}: encoders')
        row[1].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel('time since start of motion [s]')
    fig.suptitle(f'{name} (cf. thesis figs. 4.6-4.20)')
    fig.tight_layout()
    path = RESULTS / f'{name}.png'
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return str(path.relative_to(RESULTS.parent.parent))


# --- (4) offline speed ------------------------------------------------------------------------
def bench_speed(repeats: int = 5) -> dict:
    from irb_description.model import RobotModel

    from irb_control.closed_loop import build_default, simulate_closed_loop
    model = RobotModel.load()
    load_start = [round(x, 2) for x in os.getloadavg()]
    closed_runs, plant_runs = [], []
    for _ in range(repeats):
        plant, ctrl = build_default('nominal', duration_s=10.0, model=model)
        t = time.perf_counter()
        r = simulate_closed_loop(plant, ctrl, 10.5, stop_when_done=None)
        closed_runs.append((time.perf_counter() - t) / len(r.t))
        plant.reset(np.array(plant.config.initial_q))
        g = model.gravity(plant.state.q)
        n = 2480
        t = time.perf_counter()
        for k in range(n):
            plant.measure()
            plant.command(g + np.array([40.0, 30.0, 15.0]) * np.sin(0.01 * k))
            plant.step()
        plant_runs.append((time.perf_counter() - t) / n)
    T = plant.config.period_s
    # median over the repeats (the machine is shared: the load average is recorded)
    closed, plant_only = float(np.median(closed_runs)), float(np.median(plant_runs))
    out = {'benchmark': 'offline simulation speed (1 core)',
           'closed_loop_x_real_time': T / closed,
           'closed_loop_us_per_step': closed * 1e6,
           'plant_only_x_real_time': T / plant_only,
           'plant_only_us_per_step': plant_only * 1e6,
           'repeats': repeats, 'statistic': 'median of the repeats',
           'closed_loop_x_real_time_each': [round(T / x, 1) for x in closed_runs],
           'plant_only_x_real_time_each': [round(T / x, 1) for x in plant_runs],
           'substeps': plant.config.substeps, 'goal': '>= 100x real time',
           'load_average_1_5_15_min_at_start': load_start}
    _write('speed', out)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('which', choices=['loop', 'handover', 'accuracy', 'speed', 'all'])
    ap.add_argument('--handover-cycles', type=int, default=4)
    ap.add_argument('--handover-points', type=int, default=20000)
    ap.add_argument('--handover-rt-priority', type=int, default=0)
    ap.add_argument('--handover-floor-seconds', type=float, default=20.0,
                    help="the machine's own floor (machine_floor.py) before and after [s]")
    ap.add_argument('--loop-seconds', type=float, default=20.0)
    ap.add_argument('--loop-rt-priority', type=int, default=20,
                    help='realtime_priority of the second loop run (0: no second run)')
    ap.add_argument('--loop-repeats', type=int, default=1,
                    help='loop: number of runs with default scheduling')
    ap.add_argument('--no-plots', action='store_true')
    a = ap.parse_args(argv)
    if a.which in ('speed', 'all'):
        bench_speed()
    if a.which in ('accuracy', 'all'):
        bench_accuracy(not a.no_plots)
    if a.which in ('loop', 'all'):
        bench_loop(a.loop_seconds, a.loop_rt_priority, a.loop_repeats)
    if a.which in ('handover', 'all'):
        bench_handover(a.handover_cycles, a.handover_points, a.handover_rt_priority,
                       a.handover_floor_seconds)


if __name__ == '__main__':
    main()
