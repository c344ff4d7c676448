"""Path error in closed-loop simulation on every path type at gluing/welding TCP speeds.

    python ros2_ws/src/irb_bringup/benchmarks/bench_paths_sim.py [--speeds 0.05 0.15 0.25]
        [--friction file|nominal] [--energy [--band 0.25]] [--paths ...] [--name NAME]
        [--delay-prediction auto|commanded|reference]

Per path (line, arc in a tilted plane, blended polyline, spline, rectangle with blended
corners in a tilted plane) and TCP speed v: the planner's trapezoid along arc length with
cruise speed v (duration L / (0.9 v), 10 % ramps) and, if --energy, the energy-optimal plan
at that duration (with --band b: inside the gluing process band, TCP speed within
(1 -+ b) x the mean speed beyond 40 mm from start and stop, |TCP acceleration| <= 1 m/s^2
(--accel-max), as the main job's rectangle); the plan's message turned into pdplus's
theta-profile exactly as the plan gate does (``profile_from_joint_trajectory``), run by pdplus
(``PdPlusController``, PathTracker for theta) against the simulated plant (irb_control
``Plant``, config/plant.yaml friction, which differs from the nominal model) for the whole
motion. Path error: distance of the
simulated camera's TCP points (100 Hz, 37 um noise) to the path while the controller is in
PATH mode. Compensation: ``file`` = the plant's own map (what a perfect identification
gives), ``nominal`` = the model's map. --delay-prediction: pdplus's delay compensation
(``ControllerConfig.delay_prediction``; default ``auto`` as pdplus runs, ``reference`` = the
thesis's rule everywhere, as before issue 18's fix). Also the largest distance of the plant's
true TCP (FK of its state each period, no camera noise) from the path, and where along the
path [mm] the camera's worst point lies. Writes results/<name>.json and <name>.png.
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np
from irb_control.closed_loop import controller_friction, simulate_closed_loop
from irb_control.pd_plus import ControllerConfig, PdPlusController
from irb_control.plant import Plant, PlantConfig, default_plant_yaml, load_plant_friction
from irb_control.profiles import profile_from_joint_trajectory
from irb_description.model import RobotModel
from irb_description.path import path_from_spec, path_spec, rectangle_path
from irb_planning.planner import Planner, PlannerSettings
from irb_planning.request import PlanError, PlanRequest

RESULTS = Path(__file__).resolve().parent / 'results'
WAY = [[0.55, -0.25, 0.25], [0.8, -0.2, 0.3], [0.85, 0.05, 0.4], [0.7, 0.2, 0.35],
       [0.55, 0.15, 0.3]]
PATHS = {
    'line': dict(type='line', waypoints=[[0.5, -0.2, 0.25], [0.8, 0.25, 0.45]]),
    'arc_tilted': dict(type='arc', center=[0.65, 0.0, 0.3], normal=[0.2, -0.4, 1.0],
                       radius=0.12, start_angle=0.4, sweep=-4.5),
    'polyline': dict(type='polyline', waypoints=WAY, blend_radii=[0.03, 0.05, 0.02]),
    'spline': dict(type='spline', waypoints=WAY),
    'rectangle_tilted': path_spec(rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2,
                                                 0.025)),
}


def plan_request(spec, **kw):
    f = dict(path_type=spec['type'])
    for k in ('center', 'normal', 'waypoints', 'blend_radii'):
        if k in spec:
            f[k] = np.asarray(spec[k], float)
    for k in ('radius', 'start_angle', 'sweep', 'closed'):
        if k in spec:
            f[k] = spec[k]
    return PlanRequest(**f, **kw)


def run_one(model, planner, name, spec, v, objective, friction_mode, plant_friction,
            band=0.0, accel_max=1.0, delay_prediction='auto'):
    path = path_from_spec(spec)
    T = path.length / (0.9 * v)
    process = {}
    if band and objective == 'energy':
        mean = path.length / T
        process = dict(tcp_speed_min=(1 - band) * mean, tcp_speed_max=(1 + band) * mean,
                       tcp_ramp_length=0.04, tcp_accel_max=accel_max)
    try:
        r = planner.plan(plan_request(spec, objective=objective, duration=T, **process))
    except PlanError as exc:
        return {'path': name, 'objective': objective, 'tcp_speed_m_s': v, 'duration_s': T,
                'completed': False, 'planned': False, 'reason': exc.message, **process}
    tr = r.trajectory
    prof = profile_from_joint_trajectory(model, path, tr['t'], tr['q'], tr['qd'], tr['qdd'])
    ff = controller_friction(model, friction_mode,
                             default_plant_yaml() if friction_mode == 'file' else None)
    plant = Plant(model, plant_friction, PlantConfig(seed=7))
    ctrl = PdPlusController(model, path, ControllerConfig(delay_prediction=delay_prediction),
                            ff)
    ctrl.set_path_profile(prof)
    plant.reset(tr['q'][0])
    res = simulate_closed_loop(plant, ctrl, T + 3.0)
    sel = res.motion_mask()
    t_path = res.t[sel]
    cam = (res.cam_t >= t_path[0]) & (res.cam_t <= t_path[-1])
    err = path.distance(res.cam_p[cam]) if cam.any() else np.array([np.nan])
    v_tcp = np.linalg.norm([model.jacobian(q) @ qd for q, qd in zip(res.q[sel], res.qd[sel])],
                           axis=1)
    true_err = path.distance(np.array([model.fk(q) for q in res.q[sel]]))
    worst = res.cam_p[cam][int(np.argmax(err))] if cam.any() else None
    return {'path': name, 'objective': objective, 'tcp_speed_m_s': v, 'duration_s': T,
            'length_m': path.length, 'completed': bool(res.finished()),
            'stop_reason': res.stop_reason, 'camera_points': int(cam.sum()),
            'path_error_mean_mm': float(np.mean(err) * 1e3),
            'path_error_max_mm': float(np.max(err) * 1e3),
            'true_tcp_error_max_mm': float(np.max(true_err) * 1e3),
            'camera_max_at_mm': (float(path.theta_of(worst) * path.length / (2 * np.pi) * 1e3)
                                 if worst is not None else None),
            'delay_prediction': delay_prediction,
            'peak_tcp_speed_m_s': float(v_tcp.max()), 'energy_J': res.energy,
            'plan_energy_J': r.evaluation.energy, 'planned': True, **process}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--speeds', type=float, nargs='+', default=[0.05, 0.15, 0.25])
    ap.add_argument('--friction', default='file', choices=('file', 'nominal'))
    ap.add_argument('--energy', action='store_true', help='also the energy-optimal plans')
    ap.add_argument('--band', type=float, default=0.0,
                    help='energy plans inside a TCP speed band of (1 -+ band) x mean speed')
    ap.add_argument('--accel-max', type=float, default=1.0,
                    help='[m/s^2] |TCP acceleration| bound of --band')
    ap.add_argument('--paths', nargs='+', default=list(PATHS))
    ap.add_argument('--name', default='paths_sim')
    ap.add_argument('--delay-prediction', default='auto',
                    choices=('auto', 'commanded', 'reference'),
                    help="pdplus's delay compensation (ControllerConfig.delay_prediction)")
    a = ap.parse_args()
    model = RobotModel.load()
    planner = Planner(model.copy(), PlannerSettings(grid_size=200))
    _, plant_friction = load_plant_friction(default_plant_yaml(), model.joint_names)
    rows = []
    t0 = time.perf_counter()
    for name in a.paths:
        for v in a.speeds:
            for obj in ('trapezoid', 'energy') if a.energy else ('trapezoid',):
                row = run_one(model, planner, name, PATHS[name], v, obj, a.friction,
                              plant_friction, a.band, a.accel_max, a.delay_prediction)
                rows.append(row)
                if not row['planned']:
                    print(f"{name:18s} {obj:9s} v={v:.2f} m/s: not planned: {row['reason']}",
                          flush=True)
                    continue
                print(f"{name:18s} {obj:9s} v={v:.2f} m/s: mean {row['path_error_mean_mm']:.4f}"
                      f" mm, max {row['path_error_max_mm']:.4f} mm (true TCP "
                      f"{row['true_tcp_error_max_mm']:.4f} mm), done {row['completed']} "
                      f"({time.perf_counter() - t0:.0f} s)", flush=True)
    ok = [r for r in rows if r['completed']]
    data = {'friction_compensation': a.friction, 'band': a.band,
            'delay_prediction': a.delay_prediction,
            'accel_max_m_s2': a.accel_max if a.band else None, 'rows': rows,
            'worst_mean_mm': max(r['path_error_mean_mm'] for r in ok) if ok else None,
            'worst_max_mm': max(r['path_error_max_mm'] for r in ok) if ok else None,
            'all_completed': len(ok) == len(rows), 'elapsed_s': time.perf_counter() - t0}
    import os
    data['load_average'] = os.getloadavg()
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f'{a.name}.json').write_text(json.dumps(data, indent=2))
    plot(rows, RESULTS / f'{a.name}.png')
    print(json.dumps({k: v for k, v in data.items() if k != 'rows'}, indent=2))


def plot(rows, out):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for name in dict.fromkeys(r['path'] for r in rows):
        rr = [r for r in rows if r['path'] == name and r['objective'] == 'trapezoid']
        v = [r['tcp_speed_m_s'] for r in rr]
        ax[0].plot(v, [r['path_error_mean_mm'] for r in rr], 'o-', label=name)
        ax[1].plot(v, [r['path_error_max_mm'] for r in rr], 'o-', label=name)
    ax[0].axhline(0.1, color='k', ls=':', label='goal')
    ax[1].axhline(0.5, color='k', ls=':', label='goal')
    ax[0].set(xlabel='TCP speed [m/s]', ylabel='mean path error [mm]')
    ax[1].set(xlabel='TCP speed [m/s]', ylabel='max path error [mm]')
    ax[0].legend(fontsize=8)
    fig.savefig(out, dpi=100)


if __name__ == '__main__':
    main()
