"""The main job's six-axis step (issue 30): the gluing rectangle with the nozzle normal to its
plane, planned on six joints, checked as played and run on the six-joint simulator. No rclpy.

1. the task: irb_planning's config/path6_rectangle.yaml (the main job's rectangle, tool z into
   the plane, 0.10 m nozzle of config/six_axis_plan.yaml) unless ``path_file``;
2. ``plan6``'s energy-optimal plan (``SixAxisPlanner.plan``, mechanical energy, nominal
   six-joint friction of irb_description) at the main job's gluing speed: the ``rectangle``
   block's ``duration_s`` unless ``duration_s``;
3. its played check (the planner's, independent DH kinematics: quintic per joint at 10 kHz,
   position and orientation error against the path and the law);
4. the run: pdplus's six-joint PD+ (``irb_control.closed_loop.build_six_joint``, gains of
   config/pdplus_six_axis.yaml, theta-driven, the plan gate's profile
   ``profile_from_joint_trajectory``) on the six-joint plant (config/plant.yaml joints 1-6,
   stick-slip friction, 3-sample delay, encoder noise), in process (offline closed loop, the
   same step order as the two nodes in lockstep), with a friction feed-forward map stated in
   the report (``ff_map``);
5. measured on the plant's true joint angles in PATH mode with the check's kinematics
   (irb_planning ``verify.DHTable``/``PathCurve``, ``six_axis_check.rotation_angle``): path
   error, orientation error (goals 0.3 mm, 0.1 deg: the issue's six-axis tracking goals, which
   it states at 0.25 m/s), mechanical energy int sum |tau qd| dt over PATH mode; one plot.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

GOAL_PATH_MM = 0.3
GOAL_ORIENTATION_DEG = 0.1


def path6_file(name: str = '') -> Path:
    """The six-axis task file: ``name``, or irb_planning's config/path6_rectangle.yaml."""
    if name:
        return Path(name)
    from irb_planning.six_axis_plan import config_path
    return config_path().parent / 'path6_rectangle.yaml'


def six_joint_ff_map(arm_map: str | Path | None, wrist_map: str | Path | None, out: Path,
                     arm_label: str = 'identified by this job') -> tuple[Path, str]:
    """The six-joint feed-forward map pdplus joints:=6 loads, written to ``out``: joints 1-3
    from ``arm_map`` (the main job's identified map; None = nominal), joints 4-6 from
    ``wrist_map`` (an identified wrist map; None = irb_description's nominal wrist_friction);
    ``arm_label`` says where ``arm_map`` comes from.
    Polynomials are dropped (the parametric part is kept): the six-joint PD+ takes the
    wrist's Stribeck term on the measured speed, which needs a parametric map. Returns (path,
    label for the report)."""
    from dataclasses import replace

    import yaml

    from irb_description.friction import FrictionMap, load_friction_map
    from irb_description.six_axis_model import nominal_six_joint_friction
    nominal = nominal_six_joint_friction()
    names = list(nominal.joint_names)
    joints = list(nominal.joints)
    parts = []
    if arm_map is not None:
        arm = load_friction_map(arm_map, names[:3])
        poly = any(j.polynomial_positive is not None for j in arm.joints)
        joints[:3] = [replace(j, polynomial_positive=None, polynomial_negative=None)
                      for j in arm.joints]
        parts.append(f'joints 1-3 {arm_label}' + (' (parametric part)' if poly else ''))
    else:
        parts.append('joints 1-3 nominal')
    if wrist_map is not None:
        wrist = load_friction_map(wrist_map, names[3:])
        joints[3:] = [replace(j, polynomial_positive=None, polynomial_negative=None)
                      for j in wrist.joints]
        raw = yaml.safe_load(Path(wrist_map).read_text())['friction_map']['joints']
        how = ('six-joint sweeps, sample fit; breakaway F_s, v_s' if any(
            'breakaway' in (raw.get(n) or {}) for n in names[3:]) else
            'six-joint sweeps, sample fit')
        parts.append(f'joints 4-6 identified ({how})')
    else:
        parts.append('joints 4-6 nominal wrist_friction (an assumption; plant +20/-15/+25 %)')
    label = ', '.join(parts)
    FrictionMap(tuple(names), tuple(joints), label).save(out)
    return out, label


def identify_wrist(out_dir: Path, speeds, hold_s: float, log=print,
                   breakaway: bool = False) -> tuple[Path, dict]:
    """Wrist sweeps on the six-joint simulator and their sample fit (irb_identification
    six_joint.py, identify --joints joint_4,joint_5,joint_6 --method samples), and with
    ``breakaway`` the breakaway runs' F_s and v_s in the map (``six_joint.add_breakaway``):
    (map path, the fit's figures against the plant's true wrist friction)."""
    from irb_identification import identify
    from irb_identification.offline_sim import SimConfig
    from irb_identification.six_joint import (WRIST_JOINTS, plant_friction_map,
                                              run_six_joint_experiments)
    t0 = time.monotonic()
    bags = run_six_joint_experiments(
        list(WRIST_JOINTS), [float(s) for s in speeds], out_dir / 'bags',
        config=SimConfig(velocity_noise=0.002, effort_noise=0.05, seed=3),
        profile_kwargs=dict(hold_min_s=hold_s, hold_max_s=hold_s), log=lambda s: None)
    path = out_dir / 'wrist_friction_map.yaml'
    args = sum((['--bag', str(b)] for b in bags), []) + [
        '--joints', ','.join(WRIST_JOINTS), '--out', str(path), '--method', 'samples',
        '--effort-lag-s', str(0.6 * 0.004032), '--json', str(out_dir / 'wrist_identify.json'),
        '--plots', str(out_dir / 'plots')]
    rc = identify.main(args)
    if rc != 0:
        raise RuntimeError(f'wrist identification failed (identify exit {rc}, '
                           f'{out_dir / "wrist_identify.json"})')
    extra = {}
    if breakaway:
        from irb_identification.six_joint import add_breakaway
        extra['breakaway'] = add_breakaway(
            path, list(WRIST_JOINTS), SimConfig(velocity_noise=0.002, effort_noise=0.05,
                                                seed=3), log=log)
    from irb_description.friction import load_friction_map
    got = load_friction_map(path, list(WRIST_JOINTS))
    truth = plant_friction_map()
    rows = {n: {'coulomb': g.coulomb, 'viscous': g.viscous, 'static': g.static,
                'stribeck_velocity': g.stribeck_velocity,
                'coulomb_true': t.coulomb, 'viscous_true': t.viscous, 'static_true': t.static,
                'stribeck_velocity_true': t.stribeck_velocity}
            for n, g, t in zip(WRIST_JOINTS, got.joints, truth.joints[3:])}
    log(f'   wrist identified from {len(bags)} sweeps in {time.monotonic() - t0:.0f} s: '
        + ', '.join(f'{n} F_c {r["coulomb"]:.3f} (plant {r["coulomb_true"]:.3f}) N m'
                    for n, r in rows.items()))
    return path, {'bags': len(bags), 'joints': rows, 'wall_time_s': time.monotonic() - t0,
                  **extra}


def run_six_axis_rectangle(block: dict, rect: dict, out: Path, ff_file: Path, ff_label: str,
                           log=print, stiction_prediction: bool = True) -> dict:
    """Plan, check and run (module docstring); ``block``: the config's ``six_axis`` block,
    ``rect``: its ``rectangle`` block (the gluing speed); ``stiction_prediction``: pdplus's
    wrist stiction prediction (irb_control doc/six_joint.md: for an identified wrist map; with
    the nominal one it does worse than without). Returns the figures (JSON-able)
    and writes ``out``/plots/six_axis_rectangle.png. SixAxisPlanError / RuntimeError (one
    line) when the plan is refused."""
    from dataclasses import replace

    from irb_control.closed_loop import (build_six_joint, energy, simulate_closed_loop,
                                         six_axis_controller_config)
    from irb_control.plant import PlantConfig
    from irb_control.profiles import profile_from_joint_trajectory
    from irb_description.params import load_kinematics
    from irb_description.path import read_path_spec
    from irb_description.six_axis_model import SixJointModel
    from irb_planning.six_axis_check import rotation_angle
    from irb_planning.six_axis_plan import SixAxisPlanner, SixAxisSettings, load_config
    from irb_planning.six_axis_plan import task_from_spec
    from irb_planning.verify import DHTable, PathCurve

    spec_file = path6_file(block.get('path_file') or '')
    path, law = task_from_spec(read_path_spec(str(spec_file)))
    duration = float(block.get('duration_s') or rect['duration_s'])
    cfg = load_config()
    settings = SixAxisSettings.from_config(cfg)
    if block.get('grid'):
        settings = replace(settings, grid_size=int(block['grid']))
    if block.get('play_rate_hz'):       # the played check's sampling rate
        settings = replace(settings, play_rate_hz=float(block['play_rate_hz']))
    from .thesis_run import process_text, rectangle_process
    # the gluing band of the three-axis rectangle (TCP speed band beyond the ramps, |a|)
    band = rectangle_process(rect) if block.get('gluing_band', True) else {}
    t0 = time.monotonic()
    planner = SixAxisPlanner(settings, config=cfg)
    prob = planner.problem(path, law, process=band)
    plan = planner.plan(prob, 'energy', duration)
    plan_s = time.monotonic() - t0
    chk = plan.check
    log(f'   six axes: plan6 energy-optimal {plan.duration:.2f} s ({path.length / duration:.3f}'
        f' m/s mean), {plan.energy:.1f} J planned, configuration {"/".join(plan.configuration)}'
        f', {plan_s:.0f} s; played check {chk.position_error * 1e3:.4f} mm, '
        f'{np.degrees(chk.orientation_error):.5f} deg'
        + (f'; {process_text(band)}: played TCP speed {chk.tcp_speed_low:.3f}-'
           f'{chk.tcp_speed_peak:.3f} m/s, |a| {chk.tcp_accel_peak:.2f} m/s^2' if band else
           '; no gluing band'))
    tcp = planner.tcp
    six = SixJointModel(tcp)
    tr = plan.trajectory
    prof = profile_from_joint_trajectory(six, path, tr['t'], tr['q'], tr['qd'], tr['qdd'])
    t1 = time.monotonic()
    plant, ctrl = build_six_joint(
        prof, path, tcp, friction_mode='file', friction_file=ff_file, model=six,
        controller_config=six_axis_controller_config(stiction_prediction=stiction_prediction),
        plant_config=PlantConfig(initial_q=tuple(prof.q[0].tolist()),
                                 seed=int(block.get('seed', 1))))
    r = simulate_closed_loop(plant, ctrl, float(tr['t'][-1]) + 1.5)
    sim_s = time.monotonic() - t1
    k = load_kinematics()
    dh = DHTable(k.dh_a, k.dh_alpha, k.dh_d, k.dh_offset)
    curve = PathCurve(path.point, path.d_point, path.dd_point, bool(path.closed))
    sel = r.mode == 2                                  # PATH mode
    if not sel.any():
        raise RuntimeError(f'six-axis run never reached PATH mode ({r.stop_reason or "?"})')
    Tq = dh.forward(r.q[sel]) @ tcp
    p = Tq[:, :3, 3]
    pos = curve.deviation(p)
    th = np.clip(curve.theta(p), 0.0, 2 * np.pi)
    ori = np.degrees(rotation_angle(np.asarray(law.rotation(th), float), Tq[:, :3, :3]))
    t_path = r.t[sel]
    e_run = energy(t_path, r.tau_applied[sel], r.qd[sel])
    u = (t_path - t_path[0]) / max(t_path[-1] - t_path[0], 1e-9)
    mid = (u >= 0.1) & (u <= 0.9)       # without the plan's start and stop (no gluing band)
    res = {
        'path_file': str(spec_file), 'duration_s': duration,
        'mean_tcp_speed_m_s': path.length / duration, 'length_m': path.length,
        'configuration': list(plan.configuration), 'plan_wall_time_s': plan_s,
        'grid': settings.grid_size, 'planned_energy_j': plan.energy,
        'time_optimal_s': plan.min_duration,
        'played_position_error_mm': chk.position_error * 1e3,
        'played_orientation_error_deg': float(np.degrees(chk.orientation_error)),
        'played_check_ok': bool(chk.ok), 'play_rate_hz': settings.play_rate_hz,
        'played_tolerances': {'position_mm': settings.path_tolerance_m * 1e3,
                              'orientation_deg': settings.orientation_tolerance_deg},
        'friction_ff': ff_label, 'stiction_prediction': bool(stiction_prediction),
        'process': band, 'process_text': process_text(band) if band else '',
        'played_tcp_speed_peak_m_s': float(chk.tcp_speed_peak),
        'played_tcp_speed_low_m_s': float(chk.tcp_speed_low),
        'played_tcp_accel_peak_m_s2': float(chk.tcp_accel_peak),
        'completed': bool(r.finished()),
        'stop_reason': r.stop_reason, 'sim_wall_time_s': sim_s,
        'path_error_max_mm': float(pos.max() * 1e3),
        'path_error_mean_mm': float(pos.mean() * 1e3),
        'orientation_error_max_deg': float(ori.max()),
        'orientation_error_mean_deg': float(ori.mean()),
        'path_error_max_middle_mm': float(pos[mid].max() * 1e3),
        'orientation_error_max_middle_deg': float(ori[mid].max()),
        'executed_energy_j': e_run,
        'goal_path_mm': GOAL_PATH_MM, 'goal_orientation_deg': GOAL_ORIENTATION_DEG}
    res['goal_path_met'] = bool(res['completed'] and res['path_error_max_mm'] <= GOAL_PATH_MM)
    res['goal_orientation_met'] = bool(res['completed'] and res['orientation_error_max_deg']
                                       <= GOAL_ORIENTATION_DEG)
    res['plot'] = str(plot_six_axis(out / 'plots' / 'six_axis_rectangle.png', t_path - t_path[0],
                                    pos * 1e3, ori, res))
    log(f'   six axes run ({ff_label}): path error max {res["path_error_max_mm"]:.3f} mm '
        f'(goal {GOAL_PATH_MM} mm {"met" if res["goal_path_met"] else "NOT met"}), '
        f'orientation max {res["orientation_error_max_deg"]:.3f} deg (goal '
        f'{GOAL_ORIENTATION_DEG} deg {"met" if res["goal_orientation_met"] else "NOT met"}), '
        f'{e_run:.1f} J executed, simulated in {sim_s:.0f} s')
    return res


def plot_six_axis(file: Path, t, pos_mm, ori_deg, res: dict) -> Path:
    """Path error [mm] and orientation error [deg] over the run's PATH phase, goals marked."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    file.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    ax[0].plot(t, pos_mm, lw=0.8)
    ax[0].axhline(GOAL_PATH_MM, color='r', ls='--', lw=0.8, label=f'goal {GOAL_PATH_MM} mm')
    ax[0].set_ylabel('path error [mm]')
    ax[0].legend(loc='upper right')
    ax[1].plot(t, ori_deg, lw=0.8, color='C1')
    ax[1].axhline(GOAL_ORIENTATION_DEG, color='r', ls='--', lw=0.8,
                  label=f'goal {GOAL_ORIENTATION_DEG} deg')
    ax[1].set_ylabel('orientation error [deg]')
    ax[1].set_xlabel('time in PATH mode [s]')
    ax[1].legend(loc='upper right')
    fig.suptitle(f'six axes, nozzle normal to the plane: {res["duration_s"]:.1f} s '
                 f'({res["mean_tcp_speed_m_s"]:.3f} m/s mean), {res["executed_energy_j"]:.1f} J'
                 f'\nFF: {res["friction_ff"]}', fontsize=9)
    fig.tight_layout()
    fig.savefig(file, dpi=110)
    plt.close(fig)
    return file


def six_axis_section(res: dict, out: Path, wrist: dict | None = None) -> list[str]:
    """Markdown lines of the six-axis step for the main report."""
    def met(ok):
        return 'met' if ok else '**not met**'
    rel = Path(res['plot']).relative_to(out) if Path(res['plot']).is_relative_to(out) \
        else res['plot']
    lines = [
        '## Six axes: the rectangle glued with the nozzle normal to its plane', '',
        f'Task `{Path(res["path_file"]).name}` (irb_planning): {res["length_m"]:.3f} m, tool z '
        'into the plane, 0.10 m nozzle. `plan6` energy-optimal (mechanical, nominal six-joint '
        f'friction) at the main job\'s gluing speed: {res["duration_s"]:.2f} s, '
        f'{res["mean_tcp_speed_m_s"]:.3f} m/s mean (time-optimal {res["time_optimal_s"]:.2f} '
        f's), configuration {"/".join(res["configuration"])}, grid {res["grid"]}, planned in '
        f'{res["plan_wall_time_s"]:.0f} s.', '',
        f'Played check (independent DH kinematics, quintic at {res["play_rate_hz"] / 1e3:g} '
        'kHz): position '
        f'{res["played_position_error_mm"]:.4f} mm, orientation '
        f'{res["played_orientation_error_deg"]:.5f} deg (tolerances '
        f'{res["played_tolerances"]["position_mm"]:.2f} mm, '
        f'{res["played_tolerances"]["orientation_deg"]:.2f} deg: '
        f'{"within" if res["played_check_ok"] else "OUTSIDE"}).', '',
        'Run: six-joint PD+ (irb_control config/pdplus_six_axis.yaml) on the six-joint plant, '
        'offline closed loop (in process, the nodes\' step order), friction feed-forward: '
        f'{res["friction_ff"]}; wrist stiction prediction '
        f'{"on" if res.get("stiction_prediction") else "off (it needs an identified wrist map)"}'
        '.', '',
        '| figure | value | goal |', '|---|---|---|',
        f'| path error max / mean [mm] | {res["path_error_max_mm"]:.3f} / '
        f'{res["path_error_mean_mm"]:.3f} | ≤ {res["goal_path_mm"]} mm: '
        f'{met(res["goal_path_met"])} |',
        f'| orientation error max / mean [deg] | {res["orientation_error_max_deg"]:.3f} / '
        f'{res["orientation_error_mean_deg"]:.3f} | ≤ {res["goal_orientation_deg"]} deg: '
        f'{met(res["goal_orientation_met"])} |',
        f'| the same between 10 % and 90 % of the PATH time [mm], [deg] | '
        f'{res["path_error_max_middle_mm"]:.3f}, {res["orientation_error_max_middle_deg"]:.3f}'
        ' | - |',
        f'| energy planned / executed [J] | {res["planned_energy_j"]:.1f} / '
        f'{res["executed_energy_j"]:.1f} | - |',
        f'| completed | {res["completed"]} {res["stop_reason"]} | - |', '',
        'The issue states these goals at 0.25 m/s; here the speed is the main job\'s gluing '
        'speed. Error measured on the plant\'s true joint angles (no camera noise). '
        + (f'Planned with the three-axis rectangle\'s gluing band ({res["process_text"]}), as '
           f'played: TCP speed {res["played_tcp_speed_low_m_s"]:.3f} (lowest beyond the ramps)'
           f' to {res["played_tcp_speed_peak_m_s"]:.3f} m/s, |TCP acceleration| '
           f'{res["played_tcp_accel_peak_m_s2"]:.2f} m/s^2.' if res.get('process') else
           'Planned without a gluing band (six_axis.gluing_band false): the energy-optimal '
           'timing accelerates hard at the start and the stop.'), '']
    if wrist:
        lines += ['Wrist friction identified in this job (six-joint sweeps, sample fit) '
                  'against the plant:', '',
                  '| joint | F_c [N m] | plant | F_v [N m s/rad] | plant |',
                  '|---|---|---|---|---|',
                  *[f'| {n} | {r["coulomb"]:.3f} | {r["coulomb_true"]:.3f} | '
                    f'{r["viscous"]:.3f} | {r["viscous_true"]:.3f} |'
                    for n, r in wrist['joints'].items()], '']
    lines += [f'![six axes]({rel})', '']
    return lines


def six_axis_step(block: dict, rect: dict, out: Path, arm_map: Path | None, log=print
                  ) -> dict:
    """The main job's step: the wrist identified first if ``block['identify_wrist']``
    (``identify_wrist``), the feed-forward map written (``six_joint_ff_map``: joints 1-3 from
    ``arm_map``), then ``run_six_axis_rectangle``. Returns its figures plus ``wrist``."""
    work = out / 'six_axis'
    work.mkdir(parents=True, exist_ok=True)
    wrist_map, wrist = None, None
    if block.get('identify_wrist', False):
        wrist_map, wrist = identify_wrist(work, block.get('wrist_speeds_rad_s',
                                                          [0.1, 0.3, 1.0, 2.0]),
                                          float(block.get('wrist_hold_s', 1.0)), log)
    ff_file, label = six_joint_ff_map(arm_map, wrist_map, work / 'six_joint_ff_map.yaml')
    res = run_six_axis_rectangle(block, rect, out, ff_file, label, log,
                                 stiction_prediction=wrist_map is not None)
    res['ff_map'] = str(ff_file)
    res['wrist'] = wrist
    return res
