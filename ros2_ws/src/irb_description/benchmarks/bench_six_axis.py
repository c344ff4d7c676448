#!/usr/bin/env python3
"""The six-joint geometric chain along paths with a tool-orientation law (issue 30).

    python ros2_ws/src/irb_description/benchmarks/bench_six_axis.py [--samples N]

For each case (path type x orientation law, a 0.10 m straight nozzle as TCP unless the case
says tool0): the TCP poses of the law at N theta samples, the six joints through the
closed-form IK in one configuration (``orientation.joint_path6``), then the position and
orientation error of those joints measured with the thesis's DH kinematics (``dh.py``, no
code shared with the IK). Also the error halfway between the nodes of a --grid profile grid
(irb_control's profiles use 721) when the joints are interpolated there linearly or by cubic
Hermite with dq/dtheta (what a player between the nodes adds), the joints' ranges and the
largest |dq/dtheta|.
Timings: IK per pose along the path (vectorised, one configuration), ``ik`` (all eight
configurations, one pose), ``ik_nearest``, ``ik_config`` and ``ik_one`` (one configuration,
one pose; numpy / plain floats) per call, and the six-joint inverse dynamics
(pinocchio RNEA and the CasADi Function) per call. Peak joint torques and speeds on the main
job's rectangle at constant theta-dot (8 s and 6 s laps). Writes results/six_axis.json.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / 'results'


def cases():
    from irb_description.orientation import FixedOrientation, KeyframeSlerp, PathFrame
    from irb_description.path import (ArcPath, LinePath, PolylinePath, SplinePath,
                                      rectangle_path, thesis_circle)
    from irb_description.six_axis import rot_x, rot_y, rot_z
    down = rot_x(np.pi)
    # the main job's gluing rectangle (irb_bringup config/thesis_run.yaml, full)
    rect = rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025)
    u = np.array([1.0, 0.0, -0.3]) / np.hypot(1.0, 0.3)
    v = np.array([0.0, 1.0, 0.0])
    c = np.array([0.65, 0.0, 0.35])
    spline = SplinePath(np.array([c + a * u + b * v for a, b in
                                  [(-0.1, -0.15), (0.0, -0.05), (0.08, 0.05), (0.0, 0.12),
                                   (-0.1, 0.15)]]))
    zig = PolylinePath(np.array([c + a * u + b * v for a, b in
                                 [(-0.1, -0.15), (0.1, -0.07), (-0.1, 0.0), (0.1, 0.07),
                                  (-0.1, 0.15)]]), [0.02])
    arc = ArcPath(np.array([0.65, 0.1, 0.35]), np.array([0.0, -0.3, 1.0]), 0.1, 0.5, 4.0)
    line = LinePath(np.array([0.55, -0.25, 0.25]), np.array([0.75, 0.2, 0.45]))
    circle = thesis_circle()
    return [
        ('rectangle (main job), path-normal, x fixed', rect, PathFrame(rect, x_mode='fixed'),
         True),
        ('rectangle (main job), path-normal, x fixed, TCP = tool0', rect,
         PathFrame(rect, x_mode='fixed'), False),
        ('rectangle (main job), path-normal, x tangent', rect, PathFrame(rect), True),
        ('circle (thesis), path-normal (tool down), x fixed', circle,
         PathFrame(circle, x_mode='fixed'), True),
        ('arc (tilted plane, 229 deg), path-normal, x tangent', arc, PathFrame(arc), True),
        ('line, slerp over 3 keyframes', line,
         KeyframeSlerp([0.0, np.pi, 2 * np.pi],
                       [down, rot_y(0.4) @ down, rot_z(0.6) @ rot_x(-0.3) @ down]), True),
        ('polyline (zigzag, 20 mm blends), path-normal, x tangent', zig, PathFrame(zig), True),
        ('spline (tilted plane), path-normal, x tangent', spline, PathFrame(spline), True),
        ('spline (tilted plane), fixed orientation', spline,
         FixedOrientation(rot_y(0.2) @ down), True),
    ]


def run_case(name, path, law, nozzle, kin_nozzle, kin_tool0, n, grid):
    from irb_description.orientation import joint_path6, pose_errors, tool_poses
    kin = kin_nozzle if nozzle else kin_tool0
    theta = np.linspace(0.0, 2 * np.pi, n)
    t0 = time.perf_counter()
    jp = joint_path6(kin, path, law, theta)
    t_path = time.perf_counter() - t0
    pos, ori = pose_errors(kin, jp.q, jp.T)
    # joints on the controller's profile grid, interpolated: error at the midpoints
    tg = np.linspace(0.0, 2 * np.pi, grid)
    g = joint_path6(kin, path, law, tg, seed=jp.q[0], derivatives=True)
    tm = 0.5 * (tg[1:] + tg[:-1])
    Tm = tool_poses(path, law, tm)
    pos_m, ori_m = pose_errors(kin, 0.5 * (g.q[1:] + g.q[:-1]), Tm)
    hq = (tg[1] - tg[0]) / 8.0
    q_herm = 0.5 * (g.q[1:] + g.q[:-1]) + hq * (g.dq[:-1] - g.dq[1:])
    pos_h, ori_h = pose_errors(kin, q_herm, Tm)
    dq = np.gradient(jp.q, theta, axis=0)
    return {
        'case': name, 'path_type': type(path).__name__, 'length_m': float(path.length),
        'tcp': 'nozzle 0.10 m' if nozzle else 'tool0', 'samples': n,
        'configuration': list(jp.configuration),
        'position_error_max_mm': float(pos.max() * 1e3),
        'position_error_median_mm': float(np.median(pos) * 1e3),
        'orientation_error_max_deg': float(np.degrees(ori.max())),
        'orientation_error_median_deg': float(np.degrees(np.median(ori))),
        'ik_time_per_pose_us': float(t_path / n * 1e6),
        'wrist_singular_samples': int(jp.wrist_singular.sum()),
        'min_abs_q5_deg': float(np.degrees(np.abs(jp.q[:, 4]).min())),
        'q_min_deg': np.degrees(jp.q.min(axis=0)).round(2).tolist(),
        'q_max_deg': np.degrees(jp.q.max(axis=0)).round(2).tolist(),
        'max_abs_dq_dtheta': np.abs(dq).max(axis=0).round(4).tolist(),
        'grid_nodes': grid,
        'linear_interp_midpoint_position_error_max_mm': float(pos_m.max() * 1e3),
        'linear_interp_midpoint_orientation_error_max_deg': float(np.degrees(ori_m.max())),
        'hermite_interp_midpoint_position_error_max_mm': float(pos_h.max() * 1e3),
        'hermite_interp_midpoint_orientation_error_max_deg': float(np.degrees(ori_h.max())),
    }


def rectangle_torques(kin, n):
    """Peak |tau| and |qd| per joint on the main job's rectangle, nozzle normal to its plane
    (x fixed and x tangent), at constant theta-dot for the main job's 8 s and the quick job's
    6 s, six-joint inverse dynamics without friction; against the assumed limits."""
    from irb_description.orientation import PathFrame, joint_path6
    from irb_description.params import load_dynamics
    from irb_description.path import rectangle_path
    from irb_description.six_axis_dynamics import SixAxisDynamics
    rect = rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025)
    dyn = SixAxisDynamics()
    theta = np.linspace(0.0, 2 * np.pi, n)
    out = {'torque_limit_nm': load_dynamics().torque_limit.tolist(),
           'velocity_limit_deg_s': np.degrees(kin.velocity).round(1).tolist()}
    for x_mode in ('fixed', 'tangent'):
        jp = joint_path6(kin, rect, PathFrame(rect, x_mode=x_mode), theta, derivatives=True)
        for duration in (8.0, 6.0):
            w = 2 * np.pi / duration
            qd, qdd = jp.dq * w, jp.ddq * w**2
            tau = np.array([dyn.inverse_dynamics(q, a, b) for q, a, b in zip(jp.q, qd, qdd)])
            out[f'x_{x_mode}_{duration:g}s'] = {
                'peak_abs_tau_nm': [float(f'{x:.4g}') for x in np.abs(tau).max(axis=0)],
                'peak_abs_qd_deg_s': np.degrees(np.abs(qd).max(axis=0)).round(1).tolist()}
    return out


def time_calls(fn, args_list):
    t = []
    for a in args_list:
        t0 = time.perf_counter()
        fn(*a)
        t.append(time.perf_counter() - t0)
    x = np.asarray(t) * 1e6
    return {'median_us': float(np.median(x)), 'p90_us': float(np.percentile(x, 90)),
            'n': int(x.size)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description='Six-joint chain along paths with orientation laws: DH-checked pose '
        'errors of the closed-form IK, IK and dynamics timings; writes results/six_axis.json.')
    ap.add_argument('--samples', type=int, default=4001, help='theta samples per path [-]')
    ap.add_argument('--grid', type=int, default=721,
                    help="nodes of the profile grid for the interpolation error [-] "
                    "(irb_control's profiles: 721)")
    ap.add_argument('--output', type=Path, default=RESULTS / 'six_axis.json')
    ns = ap.parse_args(argv)
    if ns.samples < 2 or ns.grid < 2:
        ap.error('--samples and --grid must be >= 2')
    from irb_description.six_axis import SixAxisKinematics, pose
    from irb_description.six_axis_dynamics import SixAxisDynamics

    load_start = os.getloadavg()
    kin0 = SixAxisKinematics()
    kin_n = SixAxisKinematics(tcp=pose(np.eye(3), [0.0, 0.0, 0.10]))
    out = {'load_average_start': [round(x, 2) for x in load_start], 'cases': []}
    for name, path, law, nozzle in cases():
        r = run_case(name, path, law, nozzle, kin_n, kin0, ns.samples, ns.grid)
        out['cases'].append(r)
        print(f"{name}: pos {r['position_error_max_mm']:.2e} mm, ori "
              f"{r['orientation_error_max_deg']:.2e} deg, {r['ik_time_per_pose_us']:.1f} us/pose,"
              f" midpoints of {ns.grid} linear: "
              f"{r['linear_interp_midpoint_position_error_max_mm']:.4f} mm / "
              f"{r['linear_interp_midpoint_orientation_error_max_deg']:.4f} deg, Hermite: "
              f"{r['hermite_interp_midpoint_position_error_max_mm']:.2e} mm / "
              f"{r['hermite_interp_midpoint_orientation_error_max_deg']:.2e} deg",
              flush=True)
    out['rectangle_torques'] = rectangle_torques(kin_n, ns.samples)
    print('rectangle torques:', json.dumps(out['rectangle_torques']), flush=True)
    rng = np.random.default_rng(7)
    Q = rng.uniform(kin_n.lower, kin_n.upper, (300, 6))
    T = kin_n.fk(Q)
    out['ik_all_configurations_one_pose'] = time_calls(kin_n.ik, [(t,) for t in T])
    out['ik_nearest_one_pose'] = time_calls(kin_n.ik_nearest, list(zip(T, Q)))
    cfg = ('front', 'up', 'noflip')
    out['ik_config_one_pose'] = time_calls(lambda t, q: kin_n.ik_config(t, cfg, q),
                                           list(zip(T, Q)))
    out['ik_one_plain_floats'] = time_calls(lambda t, q: kin_n.ik_one(t, cfg, q),
                                            list(zip(T, Q)))
    dyn = SixAxisDynamics()
    f = dyn.rnea_function()
    states = [tuple(rng.uniform(-2, 2, (3, 6))) for _ in range(300)]
    out['rnea6_pinocchio'] = time_calls(dyn.inverse_dynamics, states)
    out['rnea6_casadi_function'] = time_calls(lambda q, qd, qdd: f(q, qd, qdd), states)
    out['load_average_end'] = [round(x, 2) for x in os.getloadavg()]
    out['date'] = time.strftime('%Y-%m-%d %H:%M:%S')
    ns.output.parent.mkdir(parents=True, exist_ok=True)
    ns.output.write_text(json.dumps(out, indent=1) + '\n')
    print(json.dumps({k: v for k, v in out.items() if k != 'cases'}, indent=1))
    print(f'wrote {ns.output}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
