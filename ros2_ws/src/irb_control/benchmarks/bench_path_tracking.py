#!/usr/bin/env python3
"""Cost of the path-parameter estimate inside pdplus, per 248 Hz step (issue 18 goal 0.05 ms).

    python ros2_ws/src/irb_control/benchmarks/bench_path_tracking.py

For the thesis circle (atan2) and for a tilted rectangle with blended corners, a spline and a
line (PathTracker): the time of ``PdPlusController._theta_of(q)`` alone (FK included, as in
the controller) and of the tracker's ``update`` alone, over the joint states of a closed-loop
run along each path (so the estimate moves as in the loop); and the whole ``step``. Median,
90th percentile and max of 5 repeats of all samples; writes results/path_tracking.json.
"""
import json
import os
import time
from pathlib import Path

import numpy as np
from irb_description.model import RobotModel
from irb_description.path import LinePath, SplinePath, rectangle_path, thesis_circle

from irb_control.closed_loop import controller_friction, simulate_closed_loop
from irb_control.pd_plus import ControllerConfig, PdPlusController
from irb_control.plant import Plant, PlantConfig, default_plant_yaml, load_plant_friction
from irb_control.profiles import default_circle_profile

RESULTS = Path(__file__).resolve().parent / 'results'


def main():
    model = RobotModel.load()
    _, pf = load_plant_friction(default_plant_yaml(), model.joint_names)
    paths = {'thesis_circle (atan2)': thesis_circle(),
             'rectangle_tilted': rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2,
                                                0.025),
             'spline': SplinePath([[0.55, -0.25, 0.25], [0.8, -0.2, 0.3], [0.85, 0.05, 0.4],
                                   [0.7, 0.2, 0.35], [0.55, 0.15, 0.3]]),
             'line': LinePath([0.5, -0.2, 0.25], [0.8, 0.25, 0.45])}
    out = {'load_average_before': os.getloadavg(), 'paths': {}}
    for name, path in paths.items():
        ctrl = PdPlusController(model, path, ControllerConfig(),
                                controller_friction(model, 'file', default_plant_yaml()))
        prof = default_circle_profile(model, path, 6.0)
        ctrl.set_path_profile(prof)
        plant = Plant(model, pf, PlantConfig())
        plant.reset(prof.q[0])
        res = simulate_closed_loop(plant, ctrl, 8.0)
        sel = res.motion_mask()
        qs, thetas = res.q_meas[sel], res.theta[sel]
        pts = [model.fk(q) for q in qs]
        est, trk, whole = [], [], []
        for _ in range(5):
            for q, th in zip(qs, thetas):
                ctrl._theta = float(th)
                t0 = time.perf_counter()
                ctrl._theta_of(q)
                est.append(time.perf_counter() - t0)
            if ctrl._tracker is not None:
                for p, th in zip(pts, thetas):
                    t0 = time.perf_counter()
                    ctrl._tracker.update(p, float(th))
                    trk.append(time.perf_counter() - t0)
        # whole controller step on a fresh run (the closed loop's own timing)
        ctrl2 = PdPlusController(model, path, ControllerConfig(),
                                 controller_friction(model, 'file', default_plant_yaml()))
        ctrl2.set_path_profile(prof)
        plant2 = Plant(model, pf, PlantConfig())
        plant2.reset(prof.q[0])
        ctrl2.enable()
        for _ in range(int(7.0 / 0.004032)):
            y = plant2.measure()
            t0 = time.perf_counter()
            o = ctrl2.step(y.t, y.q, y.qd)
            whole.append(time.perf_counter() - t0)
            if o.publish:
                plant2.command(o.tau)
            plant2.step()

        def stats(x):
            x = np.array(x) * 1e3
            return {'median_ms': float(np.median(x)), 'p90_ms': float(np.percentile(x, 90)),
                    'max_ms': float(x.max()), 'samples': int(x.size)} if x.size else None
        out['paths'][name] = {'theta_of_incl_fk': stats(est), 'tracker_update': stats(trk),
                              'controller_step': stats(whole),
                              'path_error_mean_mm': float(np.mean(res.path_error_camera())
                                                          * 1e3)}
        print(name, json.dumps(out['paths'][name]), flush=True)
    out['load_average_after'] = os.getloadavg()
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / 'path_tracking.json').write_text(json.dumps(out, indent=2))
    print(f"written {RESULTS / 'path_tracking.json'}")


if __name__ == '__main__':
    main()
