#!/usr/bin/env python3
"""Six-axis plan end to end on the nodes: plan6 -> pdplus (joints 6) -> simulator (joints 6).

    python ros2_ws/src/irb_bringup/benchmarks/bench_six_joint_nodes.py
        [--path-file F] [--duration 8] [--grid 0] [--out six_joint_nodes]
    python ros2_ws/src/irb_bringup/benchmarks/bench_six_joint_nodes.py --plan trapezoid \
        [--speed 0.25] [--friction file] [--out six_joint_nodes_trapezoid_file]

The command sequence of doc/six_joint.md, as processes (``ros2 run``, a private namespace,
the simulator in lockstep on /clock so that the machine's load cannot cost samples):
the simulator with ``joints:=6`` at ``--start`` pose, pdplus with config/pdplus.yaml +
config/pdplus_six_axis.yaml (``builtin_profile:=none``), then ``plan6 --publish`` (the
six-axis energy plan of ``--path-file`` in ``--duration`` s, latched on /planned_trajectory;
it waits for pdplus's verdict), then ``~/enable``; the run ends when pdplus holds the end pose.
``--plan trapezoid``: instead of plan6, the issue's tracking goal's plan (as
bench_six_joint.py builds it): the trapezoid along arc length at ``--speed`` (10 % ramps,
T = L / (0.9 v)) made into six-joint points by ``SixAxisPlanner.trajectory``, published here
latched on /planned_trajectory as ``plan6 --publish`` does (``plan6_cli.trajectory_message``),
pdplus's verdict awaited on its plan_status. ``--friction``: pdplus's friction feed-forward,
'nominal' (the model's map) or 'file' (config/plant.yaml: the simulated plant's own friction,
what a perfect identification gives).

Measured on the simulator's /joint_states (joints by name) while pdplus is in PATH mode
(its /controller_state, by the sim-time stamps), with the independent check's kinematics
(irb_planning ``verify.DHTable``: the DH table, not pinocchio; ``verify.PathCurve``; the
orientation law at the projected theta, ``six_axis_check.rotation_angle``): path error
[mm] and orientation error [deg], max / p99 / mean, and the tool axis's (nozzle's) tilt
[deg] alone (the angle between the law's and the played tool z: the orientation error
without the spin about the nozzle, which is joint 6's). Writes results/<out>.json.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
import uuid
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / 'results'
START = (0.0, 0.6, 0.2, 0.0, -0.5, 0.0)       # [rad] the simulator's start pose (doc)
MODE_PATH, MODE_STOPPED, MODE_HOLD = 2, 4, 5


def parse(argv):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--path-file', default='', help="six-axis path file ('' = irb_planning "
                    'config/path6_rectangle.yaml)')
    ap.add_argument('--duration', type=float, default=8.0, help='[s] the energy plan')
    ap.add_argument('--grid', type=int, default=0, help="plan6 --grid (0 = the config's)")
    ap.add_argument('--tcp', type=float, nargs=3, default=[0.0, 0.0, 0.1], help='[m]')
    ap.add_argument('--start', type=float, nargs=6, default=list(START), help='[rad]')
    ap.add_argument('--timeout', type=float, default=300.0, help='[s] bound of the whole run')
    ap.add_argument('--plain-pd', action='store_true', help="without pdplus_six_axis.yaml's "
                    'integral and measured-speed Stribeck term')
    ap.add_argument('--plan', choices=('energy', 'trapezoid'), default='energy',
                    help="plan6's energy plan in --duration, or the trapezoid at --speed")
    ap.add_argument('--speed', type=float, default=0.25, help='[m/s] --plan trapezoid')
    ap.add_argument('--friction', choices=('nominal', 'file'), default='nominal',
                    help="pdplus friction_mode ('file': config/plant.yaml, the plant's own)")
    ap.add_argument('--friction-file', default='', help="with --friction file: this map of "
                    "joints 1-6 ('' = config/plant.yaml), e.g. bench_six_joint.py "
                    "--identified-wrist DIR's DIR/ff_map.yaml")
    ap.add_argument('--out', default='six_joint_nodes', help="results/<out>.json ('' = none)")
    return ap.parse_args(argv)


def measure(js_t, js_q, cs_t, cs_mode, path_file: str, tcp_xyz) -> dict:
    """Path and orientation errors of the joint states (t (N,), q (N, 6)) taken while the
    controller states (t (M,), mode (M,)) say PATH; the path file's path and law."""
    import numpy as np
    from irb_description.params import load_kinematics
    from irb_description.six_axis import pose
    from irb_planning.six_axis_check import rotation_angle
    from irb_planning.six_axis_plan import read_task_file
    from irb_planning.verify import DHTable, PathCurve
    path, law = read_task_file(path_file)
    k = load_kinematics()
    dh = DHTable(k.dh_a, k.dh_alpha, k.dh_d, k.dh_offset)
    curve = PathCurve(path.point, path.d_point, path.dd_point, bool(path.closed))
    tcp = pose(np.eye(3), np.asarray(tcp_xyz, float))
    js_t, js_q = np.asarray(js_t, float), np.asarray(js_q, float)
    cs_t, cs_mode = np.asarray(cs_t, float), np.asarray(cs_mode, int)
    # the controller's mode at each joint state: the latest controller state at or before it
    idx = np.searchsorted(cs_t, js_t, side='right') - 1
    sel = (idx >= 0) & (cs_mode[np.clip(idx, 0, None)] == MODE_PATH)
    if not sel.any():
        return {'samples': 0}
    Tq = dh.forward(js_q[sel]) @ tcp
    p = Tq[:, :3, 3]
    pos = curve.deviation(p)
    th = np.clip(curve.theta(p), 0.0, 2 * np.pi)
    R = np.asarray(law.rotation(th), float)
    ori = np.degrees(rotation_angle(R, Tq[:, :3, :3]))
    tilt = np.degrees(np.arccos(np.clip(np.einsum('ij,ij->i', R[:, :, 2], Tq[:, :3, 2]),
                                        -1.0, 1.0)))
    v = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.maximum(np.diff(js_t[sel]), 1e-9)
    return {'samples': int(sel.sum()), 'path_s': float(js_t[sel][-1] - js_t[sel][0]),
            'path_error_max_mm': float(pos.max() * 1e3),
            'path_error_p99_mm': float(np.percentile(pos, 99) * 1e3),
            'path_error_mean_mm': float(pos.mean() * 1e3),
            'orientation_error_max_deg': float(ori.max()),
            'orientation_error_p99_deg': float(np.percentile(ori, 99)),
            'orientation_error_mean_deg': float(ori.mean()),
            'tool_axis_tilt_max_deg': float(tilt.max()),
            'tool_axis_tilt_p99_deg': float(np.percentile(tilt, 99)),
            'tool_axis_tilt_mean_deg': float(tilt.mean()),
            'worst_position_at_s': float(js_t[sel][int(np.argmax(pos))]),
            'worst_orientation_at_s': float(js_t[sel][int(np.argmax(ori))]),
            'tcp_speed_mean_m_s': float(np.median(v))}


def trapezoid_points(path_file: str, tcp_xyz, speed: float) -> dict:
    """bench_six_joint.py's plan: the trapezoid along arc length at ``speed`` [m/s] (10 %
    ramps, T = L / (0.9 v)) as six-joint points (t, q, qd, qdd) by the six-axis planner."""
    import numpy as np
    from irb_description.six_axis import pose
    from irb_planning.baselines import trapezoid_profile
    from irb_planning.six_axis_plan import SixAxisPlanner, read_task_file
    path, law = read_task_file(path_file)
    planner = SixAxisPlanner(tcp=pose(np.eye(3), np.asarray(tcp_xyz, float)))
    prob = planner.problem(path, law)
    tr = planner.trajectory(prob, trapezoid_profile(path.length / (0.9 * speed), 0.1))[0]
    return {k: np.asarray(tr[k]) for k in ('t', 'q', 'qd', 'qdd')}


def _publish_plan(node, ex, points: dict, path_file: str, timeout: float) -> str:
    """Publish ``points`` latched on planned_trajectory (as plan6 --publish) and wait for
    pdplus's verdict on its plan_status: '' accepted, else why not."""
    from irb_description.node_main import latched_qos
    from irb_description.path import read_path_spec
    from irb_interfaces.msg import PlanStatus
    from irb_planning.plan6_cli import trajectory_message
    from trajectory_msgs.msg import JointTrajectory
    pub = node.create_publisher(JointTrajectory, 'planned_trajectory', latched_qos())
    msg = trajectory_message(points, [f'joint_{i}' for i in range(1, 7)],
                             read_path_spec(path_file), node.get_clock().now().to_msg())
    key = (msg.header.stamp.sec, msg.header.stamp.nanosec)
    verdict = []
    node.create_subscription(PlanStatus, 'pdplus/plan_status',
                             lambda m: verdict.append(m) if (m.plan_stamp.sec,
                                                             m.plan_stamp.nanosec) == key
                             else None, latched_qos())
    pub.publish(msg)
    deadline = time.monotonic() + timeout
    while not verdict and time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.1)
    if not verdict:
        return f'no verdict on the plan within {timeout:g} s'
    return '' if verdict[0].accepted else f'refused: {verdict[0].reason}'


def run(path_file: str, duration: float, grid: int = 0, tcp_xyz=(0.0, 0.0, 0.1),
        start=START, timeout: float = 300.0, log=print, plain_pd: bool = False,
        plan: str = 'energy', speed: float = 0.25, friction: str = 'nominal',
        friction_file: str = '') -> dict:
    """The sequence on the nodes (module docstring); the figures and how the run went."""
    import subprocess
    import tempfile

    import rclpy
    from irb_description.node_main import state_qos
    from irb_interfaces.msg import ControllerState
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger

    from irb_control.plant import config_path
    from irb_control.process_group import stop_sessions

    ns = f'/six{uuid.uuid4().hex[:8]}'
    ros = ['--ros-args', '-r', f'__ns:={ns}']
    tcp = '[' + ','.join(repr(float(x)) for x in tcp_xyz) + ']'
    t_wall = time.monotonic()
    deadline = t_wall + timeout
    out = {'namespace': ns, 'path_file': path_file, 'plan': plan, 'friction_ff': friction,
           'tcp_xyz': list(tcp_xyz), 'start_rad': list(start), 'load_before': os.getloadavg()}
    if plan == 'energy':
        out['duration_s'] = duration
    else:
        t0 = time.monotonic()
        points = trapezoid_points(path_file, tcp_xyz, speed)
        out.update({'speed_m_s': speed, 'duration_s': float(points['t'][-1]),
                    'points': int(len(points['t'])), 'trajectory_s': time.monotonic() - t0})

    logs = []
    # pdplus.yaml + pdplus_six_axis.yaml for a namespaced node: the files' key is the node's
    # name without namespace, so one file of their merged parameters under '/**'
    import yaml
    merged = {}
    for name in ('pdplus.yaml', 'pdplus_six_axis.yaml'):
        merged.update(yaml.safe_load(config_path(name).read_text())['pdplus']['ros__parameters'])
    if plain_pd:
        for k in ('ki', 'integral_limit_nm', 'stribeck_measured', 'stiction_prediction',
                  'stiction_rest_speed_rad_s'):
            merged.pop(k, None)
    if friction == 'file':
        merged['friction_mode'] = 'file'
        merged['friction_map_file'] = friction_file or str(config_path('plant.yaml'))
    out['pdplus_parameters'] = merged
    params = tempfile.NamedTemporaryFile('w', suffix='.yaml', delete=False)
    yaml.safe_dump({'/**': {'ros__parameters': merged}}, params)
    params.close()

    def popen(cmd):     # output to a file (a pipe nobody reads could block the node)
        f = tempfile.TemporaryFile('w+')
        logs.append(f)
        return subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, text=True,
                                start_new_session=True)
    procs = [popen(['ros2', 'run', 'irb_control', 'simulator', *ros, '-p', 'joints:=6',
                    '-p', f'tcp_xyz:={tcp}', '-p', 'mode:=lockstep',
                    '-p', 'initial_positions:=[' + ','.join(repr(float(x)) for x in start) + ']']),
             popen(['ros2', 'run', 'irb_control', 'pdplus', *ros,
                    '--params-file', params.name,
                    '-p', 'use_sim_time:=true', '-p', 'builtin_profile:=none',
                    '-p', f'tcp_xyz:={tcp}', '-p', 'auto_enable:=false'])]
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '0')))
    node = rclpy.create_node(f'six_nodes_{uuid.uuid4().hex[:6]}', namespace=ns, context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    js_t, js_q, cs_t, cs_mode, stops = [], [], [], [], []
    names = [f'joint_{i}' for i in range(1, 7)]

    def on_js(m):
        if all(n in m.name for n in names):
            js_t.append(m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec)
            js_q.append([m.position[m.name.index(n)] for n in names])

    def on_cs(m):
        cs_t.append(m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec)
        cs_mode.append(m.mode)
        if m.mode == MODE_STOPPED and m.stop_reason:
            stops.append(m.stop_reason)
    node.create_subscription(JointState, 'joint_states', on_js, state_qos())
    node.create_subscription(ControllerState, 'controller_state', on_cs, QoSProfile(depth=1000))
    enable = node.create_client(Trigger, 'pdplus/enable')
    try:
        # the plan, handed over by plan6 (waits for pdplus's verdict itself)
        while not enable.wait_for_service(timeout_sec=1.0):
            if any(p.poll() is not None for p in procs) or time.monotonic() > deadline:
                raise RuntimeError('pdplus/enable not available (a node ended or timeout)')
        if plan == 'trapezoid':
            why = _publish_plan(node, ex, points, path_file, 60.0)
            out['plan_verdict'] = why or 'accepted'
            if why:
                raise RuntimeError(f'the trapezoid plan: {why}')
        cmd = ['ros2', 'run', 'irb_planning', 'plan6', '--path-file', path_file,
               '--duration', f'{duration:g}', '--tcp', *(f'{x:g}' for x in tcp_xyz),
               '--publish', '--verdict-timeout', '60', *(['--grid', str(grid)] if grid else []),
               *ros]
        if plan == 'energy':
            t0 = time.monotonic()
            res = subprocess.run(cmd, capture_output=True, text=True,
                                 timeout=max(deadline - time.monotonic(), 1.0))
            out['plan6_s'] = time.monotonic() - t0
            out['plan6_exit'] = res.returncode
            out['plan6_output'] = (res.stdout + res.stderr).strip().splitlines()[-4:]
            log('\n'.join(out['plan6_output']))
            if res.returncode != 0:
                raise RuntimeError(f'plan6 exit {res.returncode}: {out["plan6_output"]}')
        # enable (asked again while only the simulator's latched axis status is missing)
        while True:
            fut = enable.call_async(Trigger.Request())
            ex.spin_until_future_complete(fut, timeout_sec=30.0)
            r = fut.result()
            if r is None:
                raise RuntimeError('no answer from pdplus/enable')
            if r.success or 'no axis status' not in r.message or time.monotonic() > deadline:
                break
            ex.spin_once(timeout_sec=0.1)
        out['enable'] = r.message
        if not r.success:
            raise RuntimeError(f'enable refused: {r.message}')
        seen_path = False
        while time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.1)
            seen_path = seen_path or MODE_PATH in cs_mode[-50:]
            if stops or (seen_path and cs_mode and cs_mode[-1] == MODE_HOLD):
                break
        out['completed'] = bool(seen_path and cs_mode and cs_mode[-1] == MODE_HOLD)
        out['stop_reason'] = stops[0] if stops else ''
    except (RuntimeError, subprocess.TimeoutExpired) as exc:
        out['completed'] = False
        out['error'] = str(exc)
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        stop_sessions(procs)
        if not out.get('completed'):        # the nodes' last lines, to say why
            for name, f in zip(('simulator', 'pdplus'), logs):
                f.seek(0)
                out[f'{name}_log_tail'] = f.read().strip().splitlines()[-5:]
        for f in logs:
            f.close()
        os.unlink(params.name)
    out['wall_s'] = time.monotonic() - t_wall
    out['load_after'] = os.getloadavg()
    out.update(measure(js_t, js_q, cs_t, cs_mode, path_file, tcp_xyz))
    return out


def main(argv=None):
    a = parse(argv)
    if not a.path_file:
        from irb_planning.six_axis_plan import config_path
        a.path_file = str(config_path().parent / 'path6_rectangle.yaml')
    if a.friction_file and (a.friction != 'file' or not Path(a.friction_file).is_file()):
        print('bench_six_joint_nodes: --friction-file needs --friction file and an existing '
              'map', file=sys.stderr)
        return 2
    if not (0.0 < a.speed < 2.0):
        print('bench_six_joint_nodes: --speed must be in (0, 2) m/s', file=sys.stderr)
        return 2
    out = run(a.path_file, a.duration, a.grid, a.tcp, a.start, a.timeout, plain_pd=a.plain_pd,
              plan=a.plan, speed=a.speed, friction=a.friction, friction_file=a.friction_file)
    print(json.dumps(out, indent=1))
    if a.out:
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / f'{a.out}.json').write_text(json.dumps(out, indent=1))
    return 0 if out.get('completed') else 1


if __name__ == '__main__':
    sys.exit(main())
