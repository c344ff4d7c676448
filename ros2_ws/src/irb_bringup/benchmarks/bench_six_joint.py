#!/usr/bin/env python3
"""Six-joint tracking and control-step cost in the offline closed loop (issue 30).

    python ros2_ws/src/irb_bringup/benchmarks/bench_six_joint.py [--seeds 1 2 3]
        [--repeats 3] [--energy] [--out six_joint]

Tracking: the main job's gluing rectangle with the nozzle normal to its plane
(irb_planning config/path6_rectangle.yaml, 0.10 m nozzle of config/six_axis_plan.yaml) at a
TCP speed of 0.25 m/s: the planner's trapezoid along arc length (cruise 0.25 m/s, 10 % ramps,
``baselines.trapezoid_profile``, T = L / (0.9 v), the convention of irb_bringup's
bench_paths_sim), made into the six joints' message points by the six-axis planner
(``SixAxisPlanner.trajectory``: IK along the path, points until the played check is within
half its tolerances), turned into pdplus's theta-profile as the plan gate does
(``profile_from_joint_trajectory``), run by the six-joint PD+ on the six-joint plant
(``closed_loop.build_six_joint``) with the plant's own friction as feed-forward ('file', what
a perfect identification gives; bench_paths_sim's convention) and with the nominal map.
Measured on the plant's TRUE joint angles every period in PATH mode by the independent check's
kinematics (irb_planning ``verify.DHTable``: the thesis's DH table, not pinocchio; projection
``verify.PathCurve``; orientation against the law at the projected theta,
``six_axis_check.rotation_angle``). Goals: 0.3 mm and 0.1 deg. ``--energy``: also the
energy-optimal plan of the same mean speed (not a constant-speed motion).

Step cost: ``PdPlusController.step`` alone (perf_counter around the call) on six joints (the
tracking run above) and on three joints (the thesis's model on the same tilted rectangle, the
default polynomial profile of 6 s, PathTracker as on six), interleaved, ``--repeats`` runs
each in the same process; median, p90, p99, max and the p99 ratio (goal <= 1.2).
Writes results/<out>.json; summary in RESULTS.md.
"""
import argparse
import json
import os
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / 'results'
SPEED = 0.25


def parse(argv):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--seeds', type=int, nargs='+', default=[1, 2, 3],
                    help='plant noise seeds of the tracking runs')
    ap.add_argument('--repeats', type=int, default=3, help='interleaved step-cost runs each')
    ap.add_argument('--energy', action='store_true', help='also the energy-optimal plan')
    ap.add_argument('--out', default='six_joint', help='results/<out>.json')
    ap.add_argument('--no-prediction', action='store_true',
                    help='tracking without the stiction prediction (the config otherwise)')
    ap.add_argument('--identified-wrist', metavar='DIR', default=None,
                    help='also with an identified wrist: six-joint sweeps of joints 4-6 on '
                         'the offline simulator and their sample fit into DIR (the main '
                         "job's identify_wrist), joints 1-3 the plant's own map")
    ap.add_argument('--breakaway', action='store_true',
                    help='with --identified-wrist: also breakaway runs of joints 4-6 (a '
                         'slow torque ramp from rest each way) for F_s and v_s')
    ap.add_argument('--modes', nargs='+', default=['file', 'nominal'],
                    choices=['file', 'nominal', 'identified'],
                    help="feed-forward maps: 'file' the plant's own, 'nominal', "
                         "'identified' (needs --identified-wrist)")
    ap.add_argument('--no-step-cost', action='store_true', help='tracking only')
    ap.add_argument('--plain-pd', action='store_true',
                    help="tracking without config/pdplus_six_axis.yaml's wrist stiction "
                         'measures (no integral, Stribeck term on the reference blend)')
    a = ap.parse_args(argv)
    if 'identified' in a.modes and not a.identified_wrist:
        ap.error("--modes identified needs --identified-wrist DIR")
    if a.breakaway and not a.identified_wrist:
        ap.error('--breakaway needs --identified-wrist DIR')
    if a.identified_wrist and 'identified' not in a.modes:
        a.modes.append('identified')
    return a


def main(argv=None):
    a = parse(argv)
    import numpy as np
    from irb_description.model import RobotModel
    from irb_description.params import load_kinematics
    from irb_description.path import read_path_spec
    from irb_description.six_axis_model import SixJointModel
    from irb_planning.baselines import trapezoid_profile
    from irb_planning.six_axis_check import rotation_angle
    from irb_planning.six_axis_plan import SixAxisPlanner, config_path, task_from_spec
    from irb_planning.verify import DHTable, PathCurve

    from irb_control.closed_loop import (build_default, build_six_joint, simulate_closed_loop,
                                         six_axis_controller_config)
    from irb_control.plant import PlantConfig
    from irb_control.profiles import default_circle_profile, profile_from_joint_trajectory

    out = {'load_average_before': os.getloadavg(), 'speed_m_s': SPEED,
           'controller': 'plain PD+' if a.plain_pd else 'config/pdplus_six_axis.yaml'
           + (' without stiction_prediction' if a.no_prediction else '')}
    cc = (six_axis_controller_config(ki=None, integral_limit_nm=None, stribeck_measured=None,
                                     stiction_prediction=False)
          if a.plain_pd else six_axis_controller_config(stiction_prediction=False)
          if a.no_prediction else six_axis_controller_config())
    out['controller_config'] = {k: getattr(cc, k) for k in (
        'kp', 'kd', 'ki', 'integral_limit_nm', 'stribeck_measured', 'stiction_prediction',
        'dither_amplitude_nm', 'dither_period_samples')}
    spec_file = config_path().parent / 'path6_rectangle.yaml'
    path, law = task_from_spec(read_path_spec(str(spec_file)))
    t0 = time.perf_counter()
    planner = SixAxisPlanner()
    prob = planner.problem(path, law)
    T = path.length / (0.9 * SPEED)
    plans = {'trapezoid': planner.trajectory(prob, trapezoid_profile(T, 0.1))[0]}
    if a.energy:
        plans['energy'] = planner.plan(prob, 'energy', path.length / SPEED).trajectory
    out['planning_s'] = time.perf_counter() - t0
    tcp = planner.tcp
    six = SixJointModel(tcp)
    k = load_kinematics()
    dh = DHTable(k.dh_a, k.dh_alpha, k.dh_d, k.dh_offset)
    curve = PathCurve(path.point, path.d_point, path.dd_point, bool(path.closed))

    def measure(r):
        sel = r.mode == 2                               # PATH mode
        Tq = dh.forward(r.q[sel]) @ tcp
        p = Tq[:, :3, 3]
        pos = curve.deviation(p)
        th = np.clip(curve.theta(p), 0.0, 2 * np.pi)
        R = np.asarray(law.rotation(th), float)
        ori = rotation_angle(R, Tq[:, :3, :3])
        # the tool axis (nozzle, tool z) alone: the orientation error without the spin about it
        tilt = np.arccos(np.clip(np.einsum('ij,ij->i', R[:, :, 2], Tq[:, :3, 2]), -1.0, 1.0))
        v = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(r.t[sel])
        je = np.nanmax(np.abs(r.joint_error()[sel]), axis=0)
        return {'completed': bool(r.finished()), 'stop_reason': r.stop_reason,
                'samples': int(sel.sum()),
                'path_error_max_mm': float(pos.max() * 1e3),
                'path_error_p99_mm': float(np.percentile(pos, 99) * 1e3),
                'path_error_mean_mm': float(pos.mean() * 1e3),
                'orientation_error_max_deg': float(np.degrees(ori.max())),
                'orientation_error_p99_deg': float(np.degrees(np.percentile(ori, 99))),
                'orientation_error_mean_deg': float(np.degrees(ori.mean())),
                'tool_axis_tilt_max_deg': float(np.degrees(tilt.max())),
                'tool_axis_tilt_p99_deg': float(np.degrees(np.percentile(tilt, 99))),
                'worst_position_at_s': float(r.t[sel][int(np.argmax(pos))]),
                'worst_orientation_at_s': float(r.t[sel][int(np.argmax(ori))]),
                'tcp_speed_max_m_s': float(v.max()), 'tcp_speed_mean_m_s': float(v.mean()),
                'joint_error_max_rad': je.tolist(), 'energy_J': float(r.energy)}

    maps = {'file': None, 'nominal': None}
    if a.identified_wrist:
        from irb_control.plant import default_plant_yaml

        from irb_bringup.six_axis_phase import identify_wrist, six_joint_ff_map
        wdir = Path(a.identified_wrist)
        wdir.mkdir(parents=True, exist_ok=True)
        wrist_map, info = identify_wrist(wdir, [0.1, 0.3, 1.0, 2.0], 1.0, log=print,
                                         breakaway=a.breakaway)
        maps['identified'], label = six_joint_ff_map(
            default_plant_yaml(), wrist_map, wdir / 'ff_map.yaml',
            arm_label="the plant's own (config/plant.yaml)")
        out['identified_wrist'] = {'map': str(maps['identified']), 'label': label, **info}
    out['tracking'] = []
    profiles = {}
    for name, tr in plans.items():
        prof = profile_from_joint_trajectory(six, path, tr['t'], tr['q'], tr['qd'], tr['qdd'])
        profiles[name] = (prof, float(tr['t'][-1]))
        for mode in a.modes:
            for seed in a.seeds:
                plant, ctrl = build_six_joint(
                    prof, path, tcp, friction_mode='file' if mode == 'identified' else mode,
                    friction_file=maps[mode], model=six, controller_config=cc,
                    plant_config=PlantConfig(initial_q=tuple(prof.q[0].tolist()), seed=seed))
                r = simulate_closed_loop(plant, ctrl, float(tr['t'][-1]) + 1.5)
                row = {'plan': name, 'friction_ff': mode, 'seed': seed,
                       'duration_s': float(tr['t'][-1]), 'points': int(len(tr['t'])),
                       **measure(r)}
                out['tracking'].append(row)
                print(json.dumps({k: row[k] for k in (
                    'plan', 'friction_ff', 'seed', 'path_error_max_mm',
                    'orientation_error_max_deg', 'tool_axis_tilt_max_deg', 'stop_reason')}),
                    flush=True)

    if a.no_step_cost:
        out['load_average_after'] = os.getloadavg()
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / f'{a.out}.json').write_text(json.dumps(out, indent=1))
        return 0
    # --- step cost, six vs three joints, interleaved ---------------------------------------
    three = RobotModel.load()
    prof6, dur6 = profiles['trapezoid']
    prof3 = default_circle_profile(three, path, 6.0)

    def timed(n):
        if n == 6:
            plant, ctrl = build_six_joint(prof6, path, tcp, friction_mode='file', model=six)
            dur = dur6 + 1.0
        else:
            plant, ctrl = build_default('file', model=three, path=path)
            ctrl.set_path_profile(prof3)
            plant.reset(prof3.q[0])
            dur = 7.0
        ctrl.enable()
        dt, moving = [], []
        for _ in range(int(dur / plant.config.period_s)):
            y = plant.measure()
            t1 = time.perf_counter()
            o = ctrl.step(y.t, y.q, y.qd)
            dt.append(time.perf_counter() - t1)
            moving.append(o.mode in (1, 2))
            if o.publish:
                plant.command(o.tau)
            plant.step()
        return np.array(dt)[np.array(moving)]
    samples = {3: [], 6: []}
    for _ in range(a.repeats):
        for n in (3, 6):
            samples[n].append(timed(n))

    def stats(xs):
        x = np.concatenate(xs) * 1e3
        return {'min_ms': float(x.min()), 'p10_ms': float(np.percentile(x, 10)),
                'median_ms': float(np.median(x)), 'p90_ms': float(np.percentile(x, 90)),
                'p99_ms': float(np.percentile(x, 99)), 'max_ms': float(x.max()),
                'samples': int(x.size),
                'p99_per_run_ms': [float(np.percentile(r * 1e3, 99)) for r in xs]}
    out['step_cost'] = {'three_joints': stats(samples[3]), 'six_joints': stats(samples[6])}
    s3, s6 = out['step_cost']['three_joints'], out['step_cost']['six_joints']
    out['step_cost']['p99_ratio_six_over_three'] = s6['p99_ms'] / s3['p99_ms']
    for k in ('min', 'p10', 'median'):
        out['step_cost'][f'{k}_ratio_six_over_three'] = s6[f'{k}_ms'] / s3[f'{k}_ms']
    out['load_average_after'] = os.getloadavg()
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f'{a.out}.json').write_text(json.dumps(out, indent=1))
    print(json.dumps({'step_cost': out['step_cost'], 'load': out['load_average_after']},
                     indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
