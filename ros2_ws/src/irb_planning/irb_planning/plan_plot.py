"""A plan as a file and as a figure (no ROS imports: messages are read by their fields).

The plan file (JSON, ``FORMAT``) is what ``plan`` writes beside its plot and what
``ros2 run irb_bringup report --plan`` reads: the path it was planned on (a
``irb_description.path.path_from_spec`` mapping), the profile along it (theta [rad],
theta_dot [rad/s] at the nodes) and the trajectory as the controller gets it (t [s]; q, qd,
tau per joint), with the planner's energies. theta is proportional to arc length on every
path type: s = theta L / (2 pi), TCP speed = theta_dot L / (2 pi).

The figure shows the speed along the path in the path's own unit (theta for the thesis
circle, arc length s [m] for every other path) against the trapezoidal baseline at the same
duration (what the planner compares with: ``baselines.trapezoid_profile``), the TCP speed over
time (plan and trapezoid), joint speeds, torques and the mechanical power.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

FORMAT = 'irb_plan/1'


def _xyz(p) -> list[float]:
    return [float(p.x), float(p.y), float(p.z)]


def spec_from_path_msg(p) -> dict:
    """The ``path_from_spec`` mapping of an irb_interfaces/PathSpec message (rclpy or
    rosbags object: read by field names), with the planner's meaning of its defaults."""
    kind = p.type or 'circle'
    if kind == 'circle':
        return dict(type='circle', center=_xyz(p.center), radius=float(p.radius),
                    start_angle=float(p.start_angle), direction=int(p.direction) or 1)
    if kind == 'arc':
        return dict(type='arc', center=_xyz(p.center), normal=_xyz(p.normal),
                    radius=float(p.radius), start_angle=float(p.start_angle),
                    sweep=float(p.sweep) or 2 * math.pi)
    w = [_xyz(x) for x in p.waypoints]
    if kind == 'line':
        return dict(type='line', waypoints=w)
    if kind == 'polyline':
        return dict(type='polyline', waypoints=w,
                    blend_radii=[float(x) for x in p.blend_radii] or [0.0],
                    closed=bool(p.closed))
    return dict(type=kind, waypoints=w, closed=bool(p.closed))


def _seconds(d) -> float:
    return float(d.sec) + 1e-9 * float(d.nanosec)


def plan_record(path_spec: dict, trajectory, theta, theta_dot, theta_ddot=None,
                **meta) -> dict:
    """The plan file's mapping from a path mapping, a JointTrajectory (message fields) and
    the theta profile at the nodes; ``meta``: objective, duration, energy_j, ..."""
    pts = trajectory.points
    rec = {'format': FORMAT, 'path': path_spec,
           'joint_names': list(trajectory.joint_names),
           't': [_seconds(p.time_from_start) for p in pts],
           'q': [list(map(float, p.positions)) for p in pts],
           'qd': [list(map(float, p.velocities)) for p in pts],
           'tau': [list(map(float, p.effort)) for p in pts],
           'theta': [float(x) for x in theta], 'theta_dot': [float(x) for x in theta_dot]}
    if theta_ddot is not None and len(theta_ddot) == len(theta):
        rec['theta_ddot'] = [float(x) for x in theta_ddot]
    rec.update(meta)
    return rec


def record_from_response(resp, path_msg, objective: str) -> dict:
    """The plan file's mapping of a successful PlanPath response and its request's path."""
    from .planner import limit_cost_from_message
    modes = list(resp.electrical_bus_modes)
    cost = limit_cost_from_message(str(getattr(resp, 'message', '')))
    return plan_record(
        spec_from_path_msg(path_msg), resp.trajectory, resp.theta, resp.theta_dot,
        resp.theta_ddot, objective=str(objective), duration_s=float(resp.duration),
        energy_j=float(resp.energy), baseline_energy_j=float(resp.baseline_energy),
        electrical_energy_j=dict(zip(modes, map(float, resp.electrical_energy))),
        baseline_electrical_energy_j=dict(zip(modes,
                                              map(float, resp.baseline_electrical_energy))),
        # what the smoothness limits cost this plan (None: not measured), issue 28
        smoothness_limit_cost=None if cost is None else {
            'quantity': cost['quantity'], 'cost_fraction': cost['cost'],
            'with_limits': cost['with'], 'without_limits': cost['without'],
            'note': cost['note']})


def write_plan_file(out: str | Path, record: dict) -> Path:
    out = Path(out)
    out.write_text(json.dumps(record))
    return out


def read_plan_file(name: str | Path) -> dict:
    """A plan file's mapping, checked; ValueError with one line saying why not."""
    try:
        rec = json.loads(Path(name).read_text())
    except OSError as exc:
        raise ValueError(f'cannot read plan file {name}: {exc.strerror}') from None
    except ValueError as exc:
        raise ValueError(f'plan file {name} is not JSON: {exc}') from None
    if not isinstance(rec, dict) or rec.get('format') != FORMAT:
        raise ValueError(f'plan file {name}: not a plan file of `plan` (format {FORMAT})')
    missing = [k for k in ('path', 't', 'q', 'qd', 'tau', 'theta', 'theta_dot')
               if k not in rec]
    if missing:
        raise ValueError(f'plan file {name}: lacks {missing}')
    return rec


def path_unit(path) -> tuple[str, str, float]:
    """(name, unit, scale) of the path parameter shown for ``path``: the thesis circle's
    angle theta [rad] (scale 1), else the arc length s [m] (scale L / 2 pi)."""
    from irb_description.path import CirclePath
    if type(path) is CirclePath:
        return 'theta', 'rad', 1.0
    return 's', 'm', float(path.length) / (2 * np.pi)


def profile_times(theta, theta_dot, theta_ddot=None) -> np.ndarray:
    """Node times [s] of a theta profile (the planner's exact time law)."""
    from .profile import ThetaProfile
    try:
        return ThetaProfile(np.asarray(theta, float), np.asarray(theta_dot, float),
                            None if theta_ddot is None else np.asarray(theta_ddot, float)).times
    except ValueError:      # node accelerations inconsistent: the linear law
        return ThetaProfile(np.asarray(theta, float), np.asarray(theta_dot, float)).times


def trapezoid(duration: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The planner's trapezoidal baseline at ``duration`` [s]: theta, theta_dot, times."""
    from .baselines import trapezoid_profile
    from .planner import PlannerSettings
    prof = trapezoid_profile(float(duration), PlannerSettings().trapezoid_ramp_fraction)
    return prof.theta, prof.theta_dot, prof.times


def plot_plan_record(out: str | Path, rec: dict, title: str = '') -> Path:
    """The plan's figure (module docstring) as a PNG."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from irb_description.path import path_from_spec
    path = path_from_spec(rec['path'])
    name, unit, k = path_unit(path)
    th, thd = np.asarray(rec['theta'], float), np.asarray(rec['theta_dot'], float)
    t_nodes = profile_times(th, thd, rec.get('theta_ddot'))
    t = np.asarray(rec['t'], float)
    qd, tau = np.asarray(rec['qd'], float), np.asarray(rec['tau'], float)
    duration = float(t[-1]) if t.size else float(t_nodes[-1])
    b_th, b_thd, b_t = trapezoid(duration)
    L = float(path.length) / (2 * np.pi)       # TCP speed = L theta_dot
    fig, ax = plt.subplots(2, 3, figsize=(14, 7), constrained_layout=True)
    a = ax[0, 0]
    a.plot(k * th, k * thd, label='plan')
    a.plot(k * b_th, k * b_thd, '--', label='trapezoid, same duration')
    a.set(xlabel=f'{name} [{unit}]', ylabel=f'd{name}/dt [{unit}/s]',
          title=f'speed along the path ({path.__class__.__name__}, '
                f'L = {path.length:.3f} m)')
    a = ax[0, 1]
    a.plot(t_nodes, L * thd, label='plan')
    a.plot(b_t, L * b_thd, '--', label='trapezoid, same duration')
    a.set(xlabel='t [s]', ylabel='TCP speed [m/s]', title='TCP speed')
    for i in range(qd.shape[1] if qd.ndim == 2 else 0):
        ax[0, 2].plot(t, qd[:, i], label=f'joint {i + 1}')
        ax[1, 0].plot(t, tau[:, i], label=f'joint {i + 1}')
    ax[0, 2].set(xlabel='t [s]', ylabel='qd [rad/s]', title='joint speeds')
    ax[1, 0].set(xlabel='t [s]', ylabel='tau [N m]', title='torques')
    if qd.ndim == 2 and qd.shape == tau.shape:
        ax[1, 1].plot(t, np.abs(tau * qd).sum(axis=1), label='plan')
    ax[1, 1].set(xlabel='t [s]', ylabel='P [W]', title='power sum |tau_i qd_i|')
    ax[1, 2].remove()
    a3 = fig.add_subplot(2, 3, 6, projection='3d')
    pts = path.point(np.linspace(0.0, 2 * np.pi, 400))
    a3.plot(pts[:, 0], pts[:, 1], pts[:, 2], label='path')
    a3.plot(pts[:1, 0], pts[:1, 1], pts[:1, 2], 'o', label='start')
    a3.set(xlabel='x [m]', ylabel='y [m]', zlabel='z [m]', title='path (base_link)')
    a3.legend(fontsize=8)
    for a in ax.ravel()[:5]:
        a.grid(True, alpha=0.3)
        if a.get_legend_handles_labels()[0]:
            a.legend(fontsize=8)
    fig.suptitle(title)
    out = Path(out)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def plane_coordinates(pts: np.ndarray, ref: np.ndarray | None = None):
    """(u, v) [m] of points (N, 3) in the best-fit plane of ``ref`` (default: the points):
    the two main directions of their spread about the mean (for a line: along it, and a
    perpendicular)."""
    ref = np.asarray(pts if ref is None else ref, float)
    c = ref.mean(axis=0)
    _, _, vt = np.linalg.svd(ref - c, full_matrices=False)
    d = np.asarray(pts, float) - c
    return d @ vt[0], d @ vt[1]


def save_plan_outputs(png: str | Path, resp, path_msg, objective: str) -> str:
    """What ``plan`` writes for a successful plan: the plot ``png`` and the plan file beside
    it (``png`` with .json); returns the line to print."""
    rec = record_from_response(resp, path_msg, objective)
    out = plot_plan_record(png, rec, f'{objective}: {resp.duration:.2f} s, {resp.energy:.1f} J '
                                     f'(trapezoid {resp.baseline_energy:.1f} J)')
    plan_file = write_plan_file(Path(png).with_suffix('.json'), rec)
    return f'plot: {out}\nplan file: {plan_file} (ros2 run irb_bringup report --plan)'
