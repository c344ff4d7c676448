"""``plan6``: a six-axis plan along a path file with an orientation block (offline, no ROS graph).

    ros2 run irb_planning plan6 --path-file \
        $(ros2 pkg prefix irb_planning)/share/irb_planning/config/path6_rectangle.yaml \
        --duration 8 --json plan6.json
    ros2 run irb_planning plan6 --path-file glue6.yaml --objective time
    ros2 run irb_planning plan6 --path-file glue6.yaml --duration 8 --energy-model electrical
    ros2 run irb_planning plan6 --path-file glue6.yaml --duration 8 --energy-model electrical \
        --place-lo -0.1 -0.2 -0.1 --place-hi 0.1 0.2 0.1 --place-n 3 3 3

The path file is ``plan --path-file``'s mapping plus an ``orientation`` block
(``irb_description.orientation.orientation_from_spec``): law fixed (rpy or z/x), path_normal
(normal, approach, x_mode, x_ref) or slerp (keyframes). Energy plans minimise the mechanical
energy or the six axes' electrical energy (``--energy-model``; irb_description
config/electrical.yaml). Every plan keeps the smoothness limits as played (joint jerk,
rigid-body torque rate, TCP jerk; config/six_axis_plan.yaml ``jerk_limits``). Prints the plan
(configuration, time-optimal duration, mechanical and electrical energy, peak torques, speeds,
jerks and torque rates of the six joints) and its played check (quintic per joint at 10 kHz,
own DH kinematics: position and orientation error).

Placement (``--place-n``): the task (path and orientation law) moved by every offset of the
box ``--place-lo`` .. ``--place-hi`` [m] (relative to the path file's placement; a translation,
so the tool orientations are the file's), an energy plan of ``--duration`` at each on the coarse
``--place-grid``, checked as played; the map is printed (energy of ``--energy-model`` or the
reason of each refusal); ``--place-refine MIN_STEP`` then searches from the grid's best by
compass steps inside the box (a local search, no bound); the best placement is planned on the
full grid and is the plan printed, written (``--json``) and published. Exit 1 if no placement
can be planned. Exit 0 planned, 1 refused (unreachable, too short, fails the check), 2 bad
arguments or path file.

``--publish``: hands the plan to pdplus (``joints:=6``) as the planner node does: a latched
``trajectory_msgs/JointTrajectory`` of joint_1..6 (positions, velocities, accelerations at the
checked points) on ``/planned_trajectory``, the path file's mapping (its orientation block
included) in ``header.frame_id`` (``irb_description.plan_path``); then waits for pdplus's
verdict on ``/pdplus/plan_status`` as ``plan`` does (exit 3 refused, 4 no verdict). The plan
starts on ``ros2 service call /pdplus/enable std_srvs/srv/Trigger``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time

MIN_GRID, MAX_GRID = 20, 1000      # theta nodes (as the three-axis planner's requests)
EXAMPLE = 'ros2 run irb_planning plan6 --path-file glue6.yaml --duration 8 --json plan6.json'


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog='plan6', description='Six-axis time- or energy-optimal plan along a path file '
        'with a tool-orientation block, checked as played (offline).',
        epilog='example: ' + EXAMPLE)
    p.add_argument('--path-file', required=True,
                   help='YAML path mapping with an orientation block (see the README)')
    p.add_argument('--objective', choices=('energy', 'time'), default='energy',
                   help='energy: minimum mechanical energy at --duration; time: time-optimal')
    p.add_argument('--duration', type=float, default=0.0, help='[s] duration of an energy plan')
    p.add_argument('--energy-model', default='mechanical',
                   choices=('mechanical', 'electrical', 'electrical_none', 'electrical_shared',
                            'electrical_regenerative'),
                   help='the energy an energy plan minimises: mechanical (sum |tau qd|) or '
                   "the six axes' electrical model (electrical: electrical.yaml's DC-bus mode; "
                   'electrical_<mode>: that mode)')
    p.add_argument('--grid', type=int, default=0,
                   help='theta nodes (0 = config/six_axis_plan.yaml grid_size)')
    p.add_argument('--tcp', type=float, nargs=3, default=None, metavar=('X', 'Y', 'Z'),
                   help='[m] TCP offset on tool0 (default: config/six_axis_plan.yaml tcp)')
    p.add_argument('--place-n', type=int, nargs=3, default=None, metavar=('NX', 'NY', 'NZ'),
                   help='placement search: grid points per axis of the offset box (then the '
                   'best placement is the plan)')
    p.add_argument('--place-lo', type=float, nargs=3, default=[-0.1, -0.1, -0.1],
                   metavar=('X', 'Y', 'Z'), help='[m] offset box corner (default -0.1 each)')
    p.add_argument('--place-hi', type=float, nargs=3, default=[0.1, 0.1, 0.1],
                   metavar=('X', 'Y', 'Z'), help='[m] offset box corner (default 0.1 each)')
    p.add_argument('--place-grid', type=int, default=40,
                   help='theta nodes of each placement\'s plan (the best is re-planned on '
                   '--grid)')
    p.add_argument('--place-refine', type=float, default=0.0, metavar='MIN_STEP',
                   help='[m] after the grid, a compass search from its best offset inside the '
                   'box (steps of the grid spacing, halved down to MIN_STEP; 0 = off)')
    p.add_argument('--json', default='', help="write the plan and its points here ('' = no)")
    p.add_argument('--publish', action='store_true',
                   help='publish the plan on /planned_trajectory (latched) for pdplus '
                        'joints:=6 and wait for its verdict')
    p.add_argument('--verdict-timeout', type=float, default=30.0,
                   help='[s] --publish: wait this long for the verdict (0 = do not wait)')
    p.add_argument('--plan-status', default='pdplus/plan_status',
                   help="--publish: the controller's PlanStatus topic ('' = every one)")
    return p.parse_args(argv)


def trajectory_message(points: dict, joint_names, spec: dict, stamp):
    """The plan as pdplus takes it: JointTrajectory of the six joints at the checked points
    (t [s], q, qd, qdd (N, 6)), the path mapping ``spec`` in header.frame_id, ``stamp`` (the
    plan's identity for the verdict)."""
    from irb_description.plan_path import path_frame_id
    from irb_description.stamps import sec_nanosec
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    msg = JointTrajectory(joint_names=list(joint_names))
    msg.header.stamp = stamp
    msg.header.frame_id = path_frame_id(spec)
    for k, t in enumerate(points['t']):
        sec, nsec = sec_nanosec(float(t))
        msg.points.append(JointTrajectoryPoint(
            positions=[float(x) for x in points['q'][k]],
            velocities=[float(x) for x in points['qd'][k]],
            accelerations=[float(x) for x in points['qdd'][k]],
            time_from_start=Duration(sec=sec, nanosec=nsec)))
    return msg


def publish(points: dict, joint_names, spec: dict, a) -> int:
    """Publish the plan (latched) and wait for the controller's verdict (``plan``'s rule)."""
    import rclpy
    from irb_description.node_main import latched_qos, refuse_insecure_start
    from rclpy.executors import SingleThreadedExecutor
    from trajectory_msgs.msg import JointTrajectory

    from .plan_cli import wait_for_verdict
    refuse_insecure_start()
    rclpy.init(args=['plan6', *a.ros_args])
    node = rclpy.create_node('plan6')
    try:
        pub = node.create_publisher(JointTrajectory, 'planned_trajectory', latched_qos())
        msg = trajectory_message(points, joint_names, spec, node.get_clock().now().to_msg())
        pub.publish(msg)
        print(f'published {len(msg.points)} points on {pub.topic_name}', flush=True)
        if a.verdict_timeout <= 0:
            ex = SingleThreadedExecutor()       # give late joiners a moment on the latch
            ex.add_node(node)
            ex.spin_once(timeout_sec=0.5)
            ex.shutdown()
            return 0
        only = node.resolve_topic_name(a.plan_status) if a.plan_status else ''
        if only:        # a controller named: give discovery time to find its status topic
            ex = SingleThreadedExecutor()
            ex.add_node(node)
            until = time.monotonic() + min(a.verdict_timeout, 10.0)
            while node.count_publishers(only) == 0 and time.monotonic() < until:
                ex.spin_once(timeout_sec=0.1)
            ex.shutdown()
        return wait_for_verdict(msg.header.stamp, a.verdict_timeout, only=only)
    except KeyboardInterrupt:
        return 130
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def summary(plan, limits, smooth=None) -> str:
    import numpy as np
    c = plan.check
    kind = 'mechanical' if plan.energy_model == 'mechanical' else 'electrical'
    lines = [f'configuration   {"/".join(plan.configuration)}',
             f'objective       {plan.objective}',
             f'time-optimal    {plan.min_duration:.3f} s',
             f'duration        {plan.duration:.3f} s',
             f'energy model    {plan.energy_model}',
             f'energy          {plan.energy:.2f} J mechanical, '
             f'{plan.electrical_energy:.2f} J electrical as played (optimiser '
             f'{plan.optimizer_energy:.2f} J {kind})',
             f'solve           {plan.solve_time:.2f} s, {plan.iterations} iterations '
             f'(problem built in {plan.build_time:.2f} s)',
             f'points          {len(plan.trajectory["t"])}',
             f'played error    {c.position_error * 1e3:.5f} mm, '
             f'{np.degrees(c.orientation_error):.5f} deg (10 kHz quintic, DH kinematics)',
             'joint           ' + ' '.join(f'{i:>8d}' for i in range(1, 7)),
             'peak torque     ' + ' '.join(f'{v:8.2f}' for v in c.peak_torque) + '  N m',
             '  limit         ' + ' '.join(f'{v:8.2f}' for v in limits.torque),
             'peak speed      ' + ' '.join(f'{v:8.3f}' for v in c.peak_speed) + '  rad/s',
             '  limit         ' + ' '.join(f'{v:8.3f}' for v in limits.velocity)]
    if c.peak_jerk is not None:
        lines += ['peak jerk       ' + ' '.join(f'{v:8.1f}' for v in c.peak_jerk) + '  rad/s^3',
                  'peak torque rate' + ' '.join(f'{v:8.0f}' for v in c.peak_torque_rate)
                  + '  N m/s',
                  f'peak TCP jerk   {c.tcp_jerk_peak:.2f} m/s^3'
                  + (' (blend ends apart: {:.2f})'.format(c.blend['tcp_jerk'])
                     if c.blend else '')]
        if smooth is not None:
            lines += ['  jerk limit    ' + ' '.join(f'{v:8.1f}' for v in smooth.jerk),
                      '  rate limit    ' + ' '.join(f'{v:8.0f}' for v in smooth.torque_rate),
                      f'  TCP jerk limit {smooth.tcp_jerk:g} m/s^3']
    if c.tcp_speed_peak == c.tcp_speed_peak:          # a process block: the band as played
        lines += [f'process         TCP speed {c.tcp_speed_peak:.4f} m/s peak, '
                  f'{c.tcp_speed_low:.4f} m/s lowest beyond the ramps, |TCP acceleration| '
                  f'{c.tcp_accel_peak:.3f} m/s^2 peak (played, within the band)']
    lines += [f'note: {n}' for n in plan.notes]
    return '\n'.join(lines)


def search(planner, spec: dict, a):
    """The placement map of ``a`` (plan6's arguments), printed as it goes."""
    from .six_axis_plan import place, placement_offsets
    offsets = placement_offsets(a.place_lo, a.place_hi, a.place_n)
    unit = 'J ' + ('mechanical' if a.energy_model == 'mechanical' else 'electrical')
    print(f'placement: {len(offsets)} offsets, energy plans of {a.duration:g} s on grid '
          f'{a.place_grid}, {a.energy_model} energy', flush=True)

    def progress(k, m, pt):
        d = ' '.join(f'{x:+.3f}' for x in pt.offset)
        what = f'{pt.energy:10.2f} {unit}' if pt.energy == pt.energy else \
            f'refused: {pt.reason[:120]}'
        print(f'  [{k}/{m}] offset {d} m: {what}', flush=True)
    res = place(planner, spec, offsets, a.duration, a.energy_model, a.place_grid, progress)
    best = res.best
    if best is not None and a.place_refine > 0:
        import numpy as np

        from .six_axis_plan import refine_placement
        lo, hi, n = (np.asarray(v, float) for v in (a.place_lo, a.place_hi, a.place_n))
        step = np.where(n > 1, (hi - lo) / np.maximum(n - 1, 1), (hi - lo) / 2.0)
        print(f'placement: compass search from {" ".join(f"{x:+.3f}" for x in best.offset)} '
              f'm, steps {" ".join(f"{x:.3f}" for x in step)} m halved down to '
              f'{a.place_refine:g} m', flush=True)

        def refine_progress(k, h, pt):
            progress(k, f'search, step {max(h):.3f} m', pt)
        res = refine_placement(planner, spec, res, lo, hi, step, a.place_refine,
                               refine_progress)
        best = res.best
    if best is not None:
        worst = max(p.energy for p in res.planned)
        print(f'placement: best offset {" ".join(f"{x:+.3f}" for x in best.offset)} m, '
              f'{best.energy:.2f} {unit} on grid {a.place_grid} ({len(res.planned)} of '
              f'{len(offsets)} planned; worst {worst:.2f}, {100 * (worst / best.energy - 1):.1f} '
              '% more); planning it on the full grid', flush=True)
        from .six_axis_plan import on_box_edge
        edge = on_box_edge(best.offset, a.place_lo, a.place_hi)
        if edge:
            print('placement: the best offset lies on the box\'s face in '
                  + ', '.join('xyz'[ax] for ax in edge) + ': a lower energy may lie outside '
                  'the box (widen --place-lo/--place-hi)', flush=True)
    return res


def placement_json(res) -> dict:
    return {'energy_model': res.energy_model, 'duration_s': res.duration,
            'grid_size': res.grid_size,
            'best_offset_m': None if res.best is None else res.best.offset.tolist(),
            'points': [{'offset_m': p.offset.tolist(),
                        'energy_j': None if p.energy != p.energy else p.energy,
                        'reason': p.reason} for p in res.points]}


def main(args=None):
    argv = sys.argv[1:] if args is None else list(args)
    # ROS arguments (--ros-args ... [--]) are rclpy's (e.g. -r __ns:=/x for --publish)
    ros_args = []
    if '--ros-args' in argv:
        i = argv.index('--ros-args')
        j = argv.index('--', i) if '--' in argv[i:] else len(argv)
        argv, ros_args = argv[:i] + argv[j + 1:], argv[i:j]
    a = parse_args(argv)
    a.ros_args = ros_args
    import numpy as np
    if a.objective == 'energy' and not (a.duration > 0 and a.duration < float('inf')):
        print('plan6: an energy plan needs a finite --duration > 0 [s]', file=sys.stderr)
        return 2
    if a.grid and not MIN_GRID <= a.grid <= MAX_GRID:
        print(f'plan6: --grid must be 0 (the config\'s) or {MIN_GRID} .. {MAX_GRID}',
              file=sys.stderr)
        return 2
    if a.place_n is not None and (
            a.objective != 'energy' or min(a.place_n) < 1 or np.prod(a.place_n) > 1000
            or not MIN_GRID <= a.place_grid <= MAX_GRID
            or not all(np.isfinite(a.place_lo + a.place_hi))
            or any(h < lo for lo, h in zip(a.place_lo, a.place_hi))):
        print('plan6: --place-n needs an energy plan, 1 .. 1000 points, finite --place-lo <= '
              f'--place-hi and --place-grid {MIN_GRID} .. {MAX_GRID}', file=sys.stderr)
        return 2
    if not (0.0 <= a.place_refine < 1.0) or (a.place_refine > 0 and a.place_n is None):
        print('plan6: --place-refine is a step [m] in 0 .. 1 and needs --place-n',
              file=sys.stderr)
        return 2
    if a.tcp is not None and not all(abs(x) < 1.0 for x in a.tcp):
        print('plan6: --tcp must be finite and within 1 m of tool0', file=sys.stderr)
        return 2
    from .six_axis_plan import (SixAxisPlanError, SixAxisPlanner, read_task_file,
                                task_from_spec, task_process)
    try:
        path, law = read_task_file(a.path_file)
        from irb_description.path import read_path_spec
        spec = read_path_spec(a.path_file)
        process = task_process(spec)
    except SixAxisPlanError as exc:
        print(f'plan6: {exc}', file=sys.stderr)
        return 2
    tcp = None
    if a.tcp is not None:
        from irb_description.six_axis import pose
        tcp = pose(np.eye(3), a.tcp)
    planner = SixAxisPlanner(tcp=tcp)
    placement = None
    if a.place_n is not None:
        placement = search(planner, spec, a)
        if placement.best is None:
            print('plan6: refused: no placement in the box can be planned', file=sys.stderr)
            return 1
        from .six_axis_plan import translated_spec
        spec = translated_spec(spec, placement.best.offset)
        path, law = task_from_spec(spec)
    try:
        prob = planner.problem(path, law, a.grid or None, energy_model=a.energy_model,
                               process=process)
        plan = planner.plan(prob, a.objective, a.duration)
    except SixAxisPlanError as exc:
        print(f'plan6: refused: {exc}', file=sys.stderr)
        return 1
    print(summary(plan, planner.limits, planner.smooth_limits))
    if a.json:
        tr = plan.trajectory
        out = {} if placement is None else {'placement': placement_json(placement)}
        out.update({'configuration': list(plan.configuration), 'objective': plan.objective,
               'duration_s': plan.duration, 'min_duration_s': plan.min_duration,
               'energy_model': plan.energy_model,
               'energy_j': plan.energy, 'electrical_energy_j': plan.electrical_energy,
               'optimizer_energy_j': plan.optimizer_energy,
               'peak_jerk_rad_s3': None if plan.check.peak_jerk is None
               else plan.check.peak_jerk.tolist(),
               'peak_torque_rate_nm_s': None if plan.check.peak_torque_rate is None
               else plan.check.peak_torque_rate.tolist(),
               'tcp_jerk_peak_m_s3': plan.check.tcp_jerk_peak,
               'process': None if not process else {
                   **process, 'played_tcp_speed_peak_m_s': plan.check.tcp_speed_peak,
                   'played_tcp_speed_low_m_s': plan.check.tcp_speed_low,
                   'played_tcp_accel_peak_m_s2': plan.check.tcp_accel_peak},
               'played_position_error_m': plan.check.position_error,
               'played_orientation_error_rad': plan.check.orientation_error,
               'peak_torque_nm': plan.check.peak_torque.tolist(),
               'peak_speed_rad_s': plan.check.peak_speed.tolist(),
               'joint_names': list(planner.kin.joint_names), 'tcp': planner.tcp.tolist(),
               'limits_sources': planner.limits.sources, 'notes': plan.notes,
               'profile': {'theta': plan.profile.theta.tolist(),
                           'theta_dot': plan.profile.theta_dot.tolist()},
               'points': {k: np.asarray(tr[k]).tolist() for k in
                          ('t', 'theta', 'q', 'qd', 'qdd')}})
        try:
            with open(a.json, 'w') as f:
                json.dump(out, f)
        except OSError as exc:
            print(f'plan6: cannot write {a.json}: {exc.strerror}', file=sys.stderr)
            return 2
        print(f'written {a.json}')
    if a.publish:
        return publish(plan.trajectory, planner.kin.joint_names, spec, a)
    return 0


if __name__ == '__main__':
    sys.exit(main())
