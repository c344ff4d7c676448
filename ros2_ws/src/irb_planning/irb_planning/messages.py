"""Conversions between PlanPath / PlaceTask messages and the planning core's dataclasses.

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
from irb_interfaces.srv import PlaceTask, PlanPath
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from .placement import PlacementResult, Region, bound_gap_pct, coverage
from .planner import PlanResult
from .request import PATH_CIRCLE, PlanRequest

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


def place_task_from_msg(msg: PlaceTask.Request, defaults: dict) -> dict:
    """PlaceTask.Request -> the arguments of ``placement.search`` (task, region, n,
    coarse_grid, refine, min_step, min_tilt_step, starts, bounds). ``defaults`` holds the
    node's values for the fields a request leaves 0 (coarse_grid, n, refine, min_step,
    min_tilt_step, starts: 1 when absent; its upper limit is the node's check). Raises
    ValueError with one line when the task or region is not one (the planner's own
    validation of the placed circle comes after)."""
    p = msg.path
    if p.type not in ('', PATH_CIRCLE):
        raise ValueError(f"placement takes a circle task (path.type 'circle'), got {p.type!r}")
    if not (np.isfinite(msg.duration) and msg.duration > 0):
        raise ValueError(f'duration must be > 0 s, got {msg.duration}')
    lo = np.array([msg.lo.x, msg.lo.y, msg.lo.z], float)
    hi = np.array([msg.hi.x, msg.hi.y, msg.hi.z], float)
    region = Region(lo, hi, tuple(float(x) for x in msg.rotations),
                    tuple(float(x) for x in msg.tilt_x), tuple(float(x) for x in msg.tilt_y))
    n = tuple(int(k) or int(d) for k, d in zip(msg.grid_points, defaults['n']))
    if min(n) < 1:
        raise ValueError(f'grid_points must be >= 1 per axis, got {list(n)}')
    steps = dict(min_step=float(msg.min_step) or defaults['min_step'],
                 min_tilt_step=float(msg.min_tilt_step) or defaults['min_tilt_step'])
    for name, value in steps.items():
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f'{name} must be > 0, got {value}')
    task = PlanRequest(radius=p.radius, start_angle=p.start_angle, direction=int(p.direction),
                       duration=msg.duration, energy_model=msg.energy_model,
                       friction_map=msg.friction_map, grid_size=int(msg.grid_size))
    return dict(task=task, region=region, n=n,
                coarse_grid=int(msg.coarse_grid_size) or int(defaults['coarse_grid']),
                refine=int(msg.refine) or int(defaults['refine']),
                starts=int(msg.starts) or int(defaults.get('starts', 1)),
                bounds=bool(msg.bounds), **steps)


def fill_place_map(resp: PlaceTask.Response, res: PlacementResult,
                   fixed_electrical: float = float('nan')) -> PlaceTask.Response:
    """The energy map, the certificate, the evidence (``fill_place_evidence``) and the
    search figures of ``res`` into ``resp`` (also for a search that found nothing: the map
    says why)."""
    E = np.asarray(res.energy, float)
    tilts = (np.asarray(res.tilts, float) if res.tilts is not None
             else np.zeros((E.shape[3], 2)))
    resp.map_shape = [int(k) for k in E.shape]
    resp.map_x, resp.map_y, resp.map_z = (np.asarray(a, float).tolist()
                                          for a in (res.xs, res.ys, res.zs))
    resp.map_rotation = np.asarray(res.rotations, float).tolist()
    resp.map_tilt_x, resp.map_tilt_y = tilts[:, 0].tolist(), tilts[:, 1].tolist()
    resp.map_energy = E.ravel().tolist()
    reason = [''] * E.size
    for idx, text in res.reasons.items():
        reason[int(np.ravel_multi_index(idx, E.shape))] = text
    resp.map_reason = reason
    resp.region_lower_bound = float(res.region_lower_bound)
    resp.possible_improvement_pct = float(res.possible_improvement_pct)
    resp.lipschitz = (np.asarray(res.lipschitz, float).tolist() if res.lipschitz is not None
                      else [])
    resp.cells_covered, resp.cells_total = int(res.cells_covered), int(res.cells_total)
    resp.evaluations = int(res.evaluations)
    resp.search_time = float(res.wall_time)
    return fill_place_evidence(resp, res, fixed_electrical)


def fill_place_evidence(resp: PlaceTask.Response, res: PlacementResult,
                        fixed_electrical: float = float('nan')) -> PlaceTask.Response:
    """The global evidence of ``res`` into ``resp``: per compass search its start, end and
    energy (flat arrays, 3 per start for centres and orientations; NaN ends where a start
    was refused on the full grid), the multi-start spread, the convex bounds (NaN when not
    computed), the nearest-point coverage (``placement.coverage`` of the map; computed here
    when the search ended before it) and ``fixed_electrical`` [J] (NaN: mechanical)."""
    nan3 = [float('nan')] * 3
    runs = list(res.starts or [])
    resp.start_center = [float(x) for r in runs for x in r['start_center']]
    resp.start_coarse_energy = [float(r.get('coarse_energy', float('nan'))) for r in runs]
    resp.start_local_minimum = [bool(r.get('local_minimum', False)) for r in runs]
    resp.end_center = [float(x) for r in runs for x in (r.get('end_center') or nan3)]
    resp.end_orientation = [float(x) for r in runs
                            for x in (r.get('end_orientation') or nan3)]
    resp.end_energy = [float(r.get('end_energy', float('nan'))) for r in runs]
    resp.multistart_spread_pct = float(res.multistart_spread_pct)
    resp.grid_bound_floor = float(res.grid_bound_floor)
    resp.best_lower_bound = float(res.best_lower_bound)
    resp.bound_gap_pct = bound_gap_pct(res)
    cov = res.energy_coverage or coverage([res.xs, res.ys, res.zs], res.energy)
    resp.covered_share = float(cov['covered_fraction'])
    resp.refused_share = float(cov['uncovered_fraction'])
    resp.fixed_electrical_energy = float(fixed_electrical)
    return resp


def fill_place_response(resp: PlaceTask.Response, res: PlacementResult, nodes: dict,
                        fixed_electrical: float = float('nan')) -> PlaceTask.Response:
    """A successful search into ``resp``: the best placement, its plan (the PlanPath fields,
    by ``fill_response``), the map, the certificate and the evidence."""
    fill_response(resp, res.best_plan, nodes)
    c = np.asarray(res.best_center, float)
    resp.best_center = Point(x=c[0], y=c[1], z=c[2])
    resp.best_rotation = float(res.best_rotation)
    resp.best_tilt_x, resp.best_tilt_y = (float(x) for x in res.best_tilt)
    resp.best_energy = float(res.best_energy)
    resp.best_path = path_msg(res.best_plan.request)
    resp.error_code = PlaceTask.Response.ERROR_NONE
    return fill_place_map(resp, res, fixed_electrical)


def placement_from_msg(resp: PlaceTask.Response) -> PlacementResult:
    """The map, best placement, certificate and evidence (starts, spread, bounds,
    coverage shares) of a PlaceTask response as a ``PlacementResult`` (no plan, no
    per-point bounds): what ``placement.plot_map`` draws and ``place`` prints."""
    shape = tuple(int(k) for k in resp.map_shape)
    E = np.asarray(resp.map_energy, float).reshape(shape)
    reasons = {tuple(int(i) for i in np.unravel_index(k, shape)): text
               for k, text in enumerate(resp.map_reason) if text}
    found = resp.success
    c = resp.best_center
    return PlacementResult(
        np.asarray(resp.map_x, float), np.asarray(resp.map_y, float),
        np.asarray(resp.map_z, float), np.asarray(resp.map_rotation, float), E, reasons,
        best_center=np.array([c.x, c.y, c.z]) if found else None,
        best_rotation=float(resp.best_rotation), best_energy=float(resp.best_energy),
        region_lower_bound=float(resp.region_lower_bound),
        possible_improvement_pct=float(resp.possible_improvement_pct),
        lipschitz=np.asarray(resp.lipschitz, float) if len(resp.lipschitz) else None,
        cells_covered=int(resp.cells_covered), cells_total=int(resp.cells_total),
        evaluations=int(resp.evaluations), wall_time=float(resp.search_time),
        measure=resp.energy_model or 'mechanical',
        tilts=np.stack([np.asarray(resp.map_tilt_x, float),
                        np.asarray(resp.map_tilt_y, float)], axis=-1).reshape(-1, 2),
        best_tilt=np.array([resp.best_tilt_x, resp.best_tilt_y], float),
        starts=_starts_from_msg(resp),
        multistart_spread_pct=float(resp.multistart_spread_pct),
        grid_bound_floor=float(resp.grid_bound_floor),
        best_lower_bound=float(resp.best_lower_bound),
        energy_coverage=dict(covered_fraction=float(resp.covered_share),
                             uncovered_fraction=float(resp.refused_share)))


def _starts_from_msg(resp: PlaceTask.Response) -> list:
    """The per-start dicts of ``PlacementResult.starts`` from the flat arrays."""
    k = len(resp.end_energy)
    sc, ec, eo = (np.asarray(a, float).reshape(k, 3)
                  for a in (resp.start_center, resp.end_center, resp.end_orientation))
    out = []
    for i in range(k):
        ended = bool(np.isfinite(resp.end_energy[i]))
        out.append(dict(start_center=sc[i].tolist(),
                        coarse_energy=float(resp.start_coarse_energy[i]),
                        local_minimum=bool(resp.start_local_minimum[i]),
                        end_center=ec[i].tolist() if ended else None,
                        end_orientation=eo[i].tolist() if ended else None,
                        end_energy=float(resp.end_energy[i])))
    return out
