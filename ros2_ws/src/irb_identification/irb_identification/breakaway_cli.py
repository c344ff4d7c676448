"""breakaway: static friction F_s and Stribeck velocity v_s of joints from breakaway runs.

    ros2 run irb_identification breakaway --map MAP.yaml --out NEW.yaml \\
        [--joints joint_4,joint_5,joint_6] [--pairs 3] [--rate 0.1] [--json REPORT.json] \\
        [--plant PLANT_YAML] [--seed N]

Sweeps hold 0.1 rad/s and more and see no Stribeck dip of the wrist (v_s 0.03-0.07 rad/s):
a map that ``identify`` made from them has F_s = F_c. This runs, on irb_control's six-joint
simulator, ``--pairs`` runs per direction and joint: the other joints held by the PD+, the
joint's torque preloaded to 0.9 F_c beyond its static load and raised by ``--rate`` N m/s
until it has moved 0.02 rad; ``breakaway.fit_breakaway`` fits F_s and v_s (with the map's F_c
and F_v) to where and how each run leaves rest. NEW.yaml is MAP.yaml with those joints'
``static`` and ``stribeck_velocity`` replaced (a ``breakaway`` block per joint with the
figures). Simulator only: on a robot the ramp needs pdplus to hand one joint's torque to the
experiment, which it does not do yet. Exit 0 = written; 2 = bad arguments or input, a run or
a fit failed (one line, nothing written).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from irb_description.node_help import own_args


def main(args=None) -> int:
    argv = own_args(args)
    p = argparse.ArgumentParser(prog='breakaway', description=__doc__.split('\n\n')[0])
    p.add_argument('--map', required=True, help='friction map with F_c, F_v of the joints '
                   '(identify --out)')
    p.add_argument('--out', required=True, help='the map with F_s, v_s (must not exist)')
    p.add_argument('--joints', default='joint_4,joint_5,joint_6', help='comma-separated')
    p.add_argument('--pairs', type=int, default=3, help='runs per direction and joint')
    p.add_argument('--rate', type=float, default=0.1, help='torque ramp [N m/s]')
    p.add_argument('--json', default=None, help='report (JSON)')
    p.add_argument('--plant', default=None, help="the simulated plant's friction YAML "
                   '(default irb_control config/plant.yaml)')
    p.add_argument('--seed', type=int, default=3, help='noise seed of the first run')
    a = p.parse_args(argv)
    try:
        return _run(a)
    except Exception as exc:        # one line, nothing written (the map is written last)
        print(f'breakaway: {exc}', file=sys.stderr)
        return 2


def _run(a) -> int:
    src, out = Path(a.map), Path(a.out)
    if not src.is_file():
        raise ValueError(f'--map {src}: no such file')
    if out.exists():
        raise ValueError(f'--out {out} exists: choose a new file (nothing is overwritten)')
    if a.pairs < 1 or not (0.0 < a.rate <= 10.0):
        raise ValueError('--pairs must be >= 1 and --rate in (0, 10] N m/s')
    joints = [j.strip() for j in a.joints.split(',') if j.strip()]
    from .offline_sim import SimConfig
    from .six_joint import SixJointIdentificationModel, add_breakaway, plant_friction_map
    model = SixJointIdentificationModel()
    friction = plant_friction_map(a.plant, joint_names=model.joint_names)
    print(f'breakaway: {len(joints)} joints x {a.pairs} pairs on the six-joint simulator '
          f'(plant friction {a.plant or "irb_control config/plant.yaml"})', flush=True)
    figs = add_breakaway(src, joints, SimConfig(velocity_noise=0.002, effort_noise=0.05,
                                                seed=a.seed),
                         rate_nm_s=a.rate, pairs=a.pairs, friction=friction, model=model,
                         log=lambda s: print(s.strip(), flush=True), out_path=out)
    if a.json:
        Path(a.json).write_text(json.dumps({'map': str(src), 'out': str(out),
                                            'joints': figs}, indent=1))
    print(f'breakaway: wrote {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
