"""Conversions between PlanPath messages and the planning core's dataclasses.

``/planned_theta_profile`` (std_msgs/Float64MultiArray): a 4 x N row-major matrix, layout
dim[0] = 'rows: t_s, theta_rad, theta_dot_rad_s, theta_ddot_rad_s2' (size 4, stride 4 N),
dim[1] = 'nodes' (size N, stride N). The planner's profiles have theta_ddot linear in theta
between nodes (b = theta_dot^2 quadratic, profile.ThetaProfile); the rows hold node values.
"""
from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Point, Vector3
from irb_description.stamps import sec_nanosec
from irb_interfaces.msg import PathSpec
from irb_interfaces.srv import PlanPath
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from .planner import PlanResult
from .request import PlanRequest

PROFILE_ROWS = 'rows: t_s, theta_rad, theta_dot_rad_s, theta_ddot_rad_s2'


def request_from_msg(msg: PlanPath.Request) -> PlanRequest:
    """PlanPath.Request -> PlanRequest (no validation here; the planner validates)."""
    p = msg.path
    return PlanRequest(
        center=np.array([p.center.x, p.center.y, p.center.z], float), radius=p.radius,
        start_angle=p.start_angle, direction=int(p.direction), objective=msg.objective,
        duration=msg.duration, time_weight=msg.time_weight,
        fourier_order=int(msg.fourier_order), grid_size=int(msg.grid_size),
        limit_scaling=msg.limit_scaling, friction_map=msg.friction_map,
        boundary=msg.boundary, path_type=p.type or PathSpec.TYPE_CIRCLE,
        normal=np.array([p.normal.x, p.normal.y, p.normal.z], float), sweep=p.sweep,
        waypoints=np.array([[w.x, w.y, w.z] for w in p.waypoints], float).reshape(-1, 3),
        blend_radii=np.asarray(p.blend_radii, float), closed=bool(p.closed),
        energy_model=msg.energy_model, tcp_speed_max=msg.tcp_speed_max,
        tcp_speed_min=msg.tcp_speed_min, tcp_accel_max=msg.tcp_accel_max,
        tcp_ramp_length=msg.tcp_ramp_length)


def path_msg(req: PlanRequest) -> PathSpec:
    """The request's path as a PathSpec."""
    c = np.asarray(req.center, float)
    n = np.asarray(req.normal, float)
    return PathSpec(type=req.path_type, center=Point(x=c[0], y=c[1], z=c[2]),
                    radius=float(req.radius), start_angle=float(req.start_angle),
                    direction=int(req.direction), normal=Vector3(x=n[0], y=n[1], z=n[2]),
                    sweep=float(req.sweep),
                    waypoints=[Point(x=float(w[0]), y=float(w[1]), z=float(w[2]))
                               for w in np.asarray(req.waypoints, float).reshape(-1, 3)],
                    blend_radii=np.atleast_1d(np.asarray(req.blend_radii, float)).tolist(),
                    closed=bool(req.closed))


def path_msg_from_spec(spec: dict) -> PathSpec:
    """A PathSpec from the plain mapping of a path YAML file (``irb_description.path``'s
    ``path_from_spec`` keys: type, center, radius, start_angle, direction, normal, sweep,
    waypoints, blend_radii, closed). ValueError if the mapping is not a valid path."""
    from irb_description.path import path_from_spec
    path_from_spec(spec)                                 # the same checks as the planner
    c = [float(x) for x in spec.get('center', [0.0, 0.0, 0.0])]
    n = [float(x) for x in spec.get('normal', [0.0, 0.0, 0.0])]
    br = spec.get('blend_radii', [])
    return PathSpec(type=spec.get('type', 'circle') or 'circle',
                    center=Point(x=c[0], y=c[1], z=c[2]),
                    radius=float(spec.get('radius', 0.0)),
                    start_angle=float(spec.get('start_angle', 0.0)),
                    direction=int(spec.get('direction', 1)),
                    normal=Vector3(x=n[0], y=n[1], z=n[2]),
                    sweep=float(spec.get('sweep', 0.0)),
                    waypoints=[Point(x=float(w[0]), y=float(w[1]), z=float(w[2]))
                               for w in spec.get('waypoints', [])],
                    blend_radii=[float(x) for x in np.atleast_1d(br)],
                    closed=bool(spec.get('closed', False)))


def _duration(t: float) -> Duration:
    sec, nanosec = sec_nanosec(t)
    return Duration(sec=sec, nanosec=nanosec)


def trajectory_msg(result: PlanResult, nodes: dict) -> JointTrajectory:
    """JointTrajectory at the checked points (the profile's nodes and, where needed for a
    quintic interpolation to stay on the path, points between them): positions, velocities,
    accelerations, effort."""
    traj = JointTrajectory(joint_names=list(result.joint_names))
    for k, t in enumerate(nodes['t']):
        traj.points.append(JointTrajectoryPoint(
            positions=nodes['q'][k].tolist(), velocities=nodes['qd'][k].tolist(),
            accelerations=nodes['qdd'][k].tolist(), effort=nodes['tau'][k].tolist(),
            time_from_start=_duration(float(t))))
    return traj


def theta_profile_msg(result: PlanResult) -> Float64MultiArray:
    """The theta profile as a 4 x N Float64MultiArray (layout in the module docstring)."""
    pr = result.profile
    data = np.vstack([pr.times, pr.theta, pr.theta_dot, pr.theta_ddot_nodes])
    n = pr.theta.size
    msg = Float64MultiArray(data=data.ravel().tolist())
    msg.layout.dim = [MultiArrayDimension(label=PROFILE_ROWS, size=4, stride=4 * n),
                      MultiArrayDimension(label='nodes', size=n, stride=n)]
    return msg


def fill_response(resp: PlanPath.Response, result: PlanResult, nodes: dict
                  ) -> PlanPath.Response:
    """Copy a successful plan into the service response."""
    ev, base, ver = result.evaluation, result.baseline, result.verification
    resp.success = True
    resp.error_code = PlanPath.Response.ERROR_NONE
    resp.message = '; '.join([f'{result.objective} plan, {ver.duration:.3f} s, '
                              f'{ver.energy:.2f} J as played, {len(nodes["t"])} points, '
                              f'path error <= {ver.max_path_deviation * 1e6:.1f} um']
                             + result.notes)
    resp.trajectory = trajectory_msg(result, nodes)
    resp.theta = result.profile.theta.tolist()
    resp.theta_dot = result.profile.theta_dot.tolist()
    resp.theta_ddot = result.profile.theta_ddot_nodes.tolist()
    resp.theta_interpolation = (PlanPath.Response.INTERPOLATION_QUADRATIC
                                if result.profile.quadratic
                                else PlanPath.Response.INTERPOLATION_LINEAR)
    resp.energy = ver.energy
    resp.optimizer_energy = float(result.optimizer_energy)
    resp.min_duration = float(result.min_duration)
    resp.duration = ev.duration
    resp.peak_torque = ver.peak_torque.tolist()
    resp.solve_time = float(result.solve_time)
    resp.iterations = int(result.iterations)
    resp.solver_status = result.status
    modes = ('none', 'shared', 'regenerative')
    if ver.electrical:
        resp.electrical_bus_modes = list(modes)
        resp.electrical_energy = [float(ver.electrical[f'total_{m}']) for m in modes]
        resp.copper_energy = float(ver.electrical['copper'])
        resp.standby_energy = float(ver.electrical['standby'])
    resp.optimizer_electrical_energy = float(result.optimizer_electrical_energy)
    resp.energy_model = result.request.energy_model
    resp.tcp_speed_peak = float(ver.tcp_speed_peak)
    resp.tcp_speed_low = float(ver.tcp_speed_low)
    resp.tcp_accel_peak = float(ver.tcp_accel_peak)
    if base is not None and base.electrical:
        resp.baseline_electrical_energy = [float(base.electrical[f'total_{m}'])
                                           for m in modes]
    if base is not None:
        resp.baseline_energy = base.energy
        resp.baseline_duration = base.duration
        resp.baseline_peak_torque = base.peak_torque.tolist()
        resp.baseline_feasible = base.ok
    return resp


def profile_from_msg(msg: Float64MultiArray) -> dict:
    """Inverse of theta_profile_msg: {'t', 'theta', 'theta_dot', 'theta_ddot'} arrays (N,)."""
    n = msg.layout.dim[1].size
    data = np.asarray(msg.data, float).reshape(4, n)
    return dict(zip(('t', 'theta', 'theta_dot', 'theta_ddot'), data))
