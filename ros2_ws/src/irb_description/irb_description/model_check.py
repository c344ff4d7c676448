"""`ros2 run irb_description model_check`: check the model and print the thesis circle's figures.

Checks that the URDF is in sync with the YAML, that every inertia is physically consistent,
and that FK agrees with the DH table; then prints joint ranges, path length, peak speeds and
torques and the energy of the thesis circle (centre (0.6, 0, 0.13) m, r 0.15 m) at the given
periods. Exit code 1 when a check fails. ``--json`` prints the figures as JSON instead.
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from .circle_report import circle_report
from .dh import dh_forward
from .model import RobotModel
from .params import load_dynamics, load_kinematics, urdf_path
from .path import CirclePath
from .urdf_gen import generate_urdf


def inertia_problems(name: str, inertia: np.ndarray) -> list[str]:
    """Reasons why a (3, 3) inertia about the CoM is not physical ([] when it is)."""
    problems = []
    if not np.allclose(inertia, inertia.T):
        problems.append(f'{name}: inertia not symmetric')
    ev = np.linalg.eigvalsh(0.5 * (inertia + inertia.T))
    if ev.min() <= 0:
        problems.append(f'{name}: inertia not positive definite (eigenvalues {ev})')
    a, b, c = np.sort(ev)
    if a + b < c * (1 - 1e-12):
        problems.append(f'{name}: principal moments violate the triangle inequality')
    return problems


def run_checks(model: RobotModel) -> list[str]:
    """All model checks; returns the failures."""
    failures = []
    if urdf_path().read_text() != generate_urdf(load_kinematics(), load_dynamics()):
        failures.append('URDF out of date with config/*.yaml (run generate_urdf)')
    for link in model.dynamics.links:
        failures += inertia_problems(link.name, link.inertia)
    k = model.kinematics
    rng = np.random.default_rng(1)
    for _ in range(50):
        q6 = rng.uniform(k.lower, k.upper)
        err = np.abs(model.fk_full(q6) - dh_forward(q6, k.dh_a, k.dh_alpha, k.dh_d,
                                                     k.dh_offset)).max()
        if err > 1e-9:
            failures.append(f'FK differs from the DH table by {err:.2e} at q = {q6}')
            break
    return failures


def main(args=None) -> int:
    parser = argparse.ArgumentParser(
        prog='ros2 run irb_description model_check',
        description='Check the model (URDF in sync with the YAML, inertias physical, FK equal '
        'to the DH table) and print joint ranges, path length, peak speeds, torques and '
        'energy of a horizontal circle (default the thesis circle). Exit 1 when a check '
        'fails or the circle is unreachable.',
        epilog='example: ros2 run irb_description model_check --radius 0.1 --periods 5 10')
    parser.add_argument('--center', type=float, nargs=3, default=[0.6, 0.0, 0.13],
                        metavar=('X', 'Y', 'Z'), help='circle centre [m]')
    parser.add_argument('--radius', type=float, default=0.15, help='circle radius [m]')
    parser.add_argument('--periods', type=float, nargs='+', default=[10.0, 15.0],
                        help='circle periods to evaluate [s]')
    parser.add_argument('--json', action='store_true', help='print JSON')
    ns = parser.parse_args(args)

    model = RobotModel.load()
    failures = run_checks(model)
    try:
        path = CirclePath(np.array(ns.center), ns.radius)
        reports = [circle_report(model, path, p) for p in ns.periods]
    except ValueError as exc:   # includes UnreachableError
        print(f'model_check: circle not usable: {exc}', file=sys.stderr)
        return 1

    if ns.json:
        out = {'checks_failed': failures, 'circle': {'center': ns.center, 'radius': ns.radius,
               'path_length_m': path.length}, 'runs': [
            {'period_s': r.period, 'q_min_deg': np.degrees(r.q_min).tolist(),
             'q_max_deg': np.degrees(r.q_max).tolist(),
             'joint_path_length_rad': r.joint_path_length.tolist(),
             'peak_speed_rad_s': r.peak_speed.tolist(),
             'peak_torque_nm': r.peak_torque.tolist(), 'energy_j': r.energy}
            for r in reports]}
        print(json.dumps(out, indent=2))
        return 1 if failures else 0

    dyn = model.dynamics
    print('IRB 1600-6/1.2 model (irb_description)')
    print(f'  URDF: {model.urdf}')
    print(f'  moving mass {sum(lk.mass for lk in dyn.links):.2f} kg in links '
          + ', '.join(f'{lk.name} {lk.mass:.2f} kg' for lk in dyn.links))
    print(f'  flange at q = 0: {np.round(model.fk(np.zeros(3)), 4).tolist()} m')
    print('checks: ' + ('all passed (URDF in sync, inertias physical, FK = DH table)'
                        if not failures else f'{len(failures)} FAILED'))
    for f in failures:
        print(f'  FAILED: {f}')
    print(f'\nthesis circle: centre {ns.center} m, radius {ns.radius} m, '
          f'path length {path.length:.4f} m')
    r0 = reports[0]
    names = model.joint_names
    print(f'  {"joint":8s} {"min [deg]":>10s} {"max [deg]":>10s} {"travel [deg]":>13s}')
    for i, n in enumerate(names):
        print(f'  {n:8s} {np.degrees(r0.q_min[i]):10.3f} {np.degrees(r0.q_max[i]):10.3f} '
              f'{np.degrees(r0.joint_path_length[i]):13.3f}')
    vlim, tlim = model.limits.velocity, model.limits.torque
    for r in reports:
        print(f'  period {r.period:g} s at constant theta-speed: energy {r.energy:.1f} J')
        for i, n in enumerate(names):
            print(f'    {n}: peak speed {r.peak_speed[i]:.3f} rad/s '
                  f'({100 * r.peak_speed[i] / vlim[i]:.1f} % of limit), '
                  f'peak torque {r.peak_torque[i]:.1f} N m ({100 * r.peak_torque[i] / tlim[i]:.1f}'
                  ' % of limit)')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
