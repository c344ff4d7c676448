"""`ros2 run irb_bringup thesis_run [--quick]`: the thesis's story in one command.

On the simulator, each phase a node graph of separate processes (irb_control.process_group):
1. identification sweeps (eq. 4.1) through pdplus in time-driven mode, one bag per run;
2. the recorded bags replayed (one stream, as fast as the identifier takes them) into the
   `identifier` node -> friction map + plots (the offline `identify`'s code path);
3. the thesis circle planned energy-optimally and as the trapezoidal baseline at the same
   duration, both executed by pdplus with the identified compensation, recorded;
4. the energy-optimal circle again with no compensation;
5. a real-looking task: a gluing contour, a rectangle with blended corners in a tilted plane
   (config ``rectangle``), planned energy-optimally and as the trapezoid along arc length at
   the same duration, both executed by pdplus (following that path) with the identified
   compensation, recorded;
6. a one-page report (Markdown + PNG) under runs/<run id>/, bags under bags/<run id>_*.
Ctrl-C or any node's failure stops the graph cleanly; a second run never overwrites a first.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np
import yaml

PHASES = 6


class Lines:
    """Output sink of a ProcessGroup: echoes lines (or not) and keeps them per process."""

    def __init__(self, echo):
        self.echo = echo
        self.lines: list[str] = []
        self.lock = threading.Lock()

    def write(self, text):
        with self.lock:
            self.lines.append(text)
        if self.echo:
            sys.stdout.write(text)

    def flush(self):
        sys.stdout.flush()

    def count(self, prefix, needle):
        with self.lock:
            return sum(ln.startswith(f'[{prefix}]') and needle in ln for ln in self.lines)

    def has(self, prefix, needle):
        return self.count(prefix, needle) > 0


def log(text):
    print(f'[thesis_run] {text}', flush=True)


def repo_root() -> Path:
    return Path(os.environ.get('IRB_ROOT', os.getcwd())).resolve()


def new_run_id(runs: Path) -> str:
    base = time.strftime('%Y%m%d_%H%M%S')
    rid, k = base, 1
    while (runs / rid).exists():
        k += 1
        rid = f'{base}_{k}'
    return rid


class Link:
    """The pipeline's own ROS node: plan requests and controller-state watching."""

    def __init__(self):
        import rclpy
        from irb_description.node_main import latched_qos, refuse_insecure_start, state_qos
        from irb_interfaces.msg import ControllerState, PlanStatus
        from irb_interfaces.srv import PlanPath
        from rclpy.executors import SingleThreadedExecutor
        from std_srvs.srv import Trigger
        self.rclpy = rclpy
        self.PlanPath = PlanPath
        self.ctx = rclpy.Context()
        refuse_insecure_start()        # ROS_SECURITY_ENABLE=true is never ignored
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node('thesis_run', context=self.ctx)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.modes: list[int] = []
        self.stop_reason = ''
        self.node.create_subscription(ControllerState, 'controller_state', self._on_state,
                                      state_qos())
        self.plan_status = None
        self.node.create_subscription(PlanStatus, 'pdplus/plan_status',
                                      lambda m: setattr(self, 'plan_status', m), latched_qos())
        self.client = self.node.create_client(PlanPath, 'plan_path')
        self.Trigger = Trigger
        self.enable_client = self.node.create_client(Trigger, 'pdplus/enable')

    def _on_state(self, msg):
        if not self.modes or self.modes[-1] != msg.mode:
            self.modes.append(msg.mode)
        if msg.stop_reason:
            self.stop_reason = msg.stop_reason

    def spin_until(self, cond, timeout_s, group=None) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if cond():
                return True
            if group is not None and group.poll() is not None:
                return False
            self.ex.spin_once(timeout_sec=0.05)
        return cond()

    def plan(self, cfg, objective, friction_map, group, path=None, duration=None,
             process=None):
        """Plan on the thesis circle of ``cfg``, or on ``path`` (a PathSpec) for ``duration``
        [s]; ``process``: PlanPath's process-constraint fields (tcp_speed_max, ...)."""
        if not self.spin_until(lambda: self.client.service_is_ready(), 60, group):
            raise RuntimeError('planner service plan_path did not come up')
        req = self.PlanPath.Request()
        if path is not None:
            req.path = path
        else:
            req.path.type = 'circle'
            req.path.center.x, req.path.center.y, req.path.center.z = cfg['center_m']
            req.path.radius = float(cfg['radius_m'])
            req.path.direction = 1
        req.objective = objective
        req.duration = float(cfg['circle_duration_s'] if duration is None else duration)
        req.grid_size = int(cfg['planner_grid'])
        req.friction_map = str(friction_map)
        for field, value in (process or {}).items():
            setattr(req, field, float(value))
        fut = self.client.call_async(req)
        if not self.spin_until(fut.done, 300, group):
            raise RuntimeError(f'planner gave no answer for the {objective} plan')
        resp = fut.result()
        if not resp.success:
            raise RuntimeError(f'planner refused the {objective} plan: {resp.message}')
        return resp

    def enable(self, group):
        """Start the motion on the plan pdplus holds (pdplus runs with auto_enable off)."""
        if not self.spin_until(lambda: self.enable_client.service_is_ready(), 60, group):
            raise RuntimeError('pdplus enable service did not come up')
        fut = self.enable_client.call_async(self.Trigger.Request())
        if not self.spin_until(fut.done, 30, group) or not fut.result().success:
            raise RuntimeError('pdplus refused to enable: '
                               f'{fut.result().message if fut.done() else "no answer"}')

    def close(self):
        self.ex.shutdown()
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.ctx)


def main(args=None) -> int:
    from ament_index_python.packages import get_package_share_directory
    from irb_control.process_group import ProcessGroup, ProcessSpec, ros2_run_cmd
    share = Path(get_package_share_directory('irb_bringup'))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--quick', action='store_true', help='short version (CI end-to-end test)')
    ap.add_argument('--config', default=str(share / 'config' / 'thesis_run.yaml'))
    ap.add_argument('--root', default=None, help='where bags/ and runs/ go (default: repo)')
    ap.add_argument('--verbose', action='store_true', help="echo every node's output")
    a = ap.parse_args(args)
    cfg = yaml.safe_load(Path(a.config).read_text())['quick' if a.quick else 'full']
    root = Path(a.root).resolve() if a.root else repo_root()
    runs, bags = root / 'runs', root / 'bags'
    run_id = new_run_id(runs)
    out = runs / run_id
    out.mkdir(parents=True)
    log(f'run {run_id}: report and plots in {out}, bags in {bags}/{run_id}_*')
    t_start = time.monotonic()
    lines = Lines(a.verbose)
    plant_yaml = Path(get_package_share_directory('irb_control')) / 'config' / 'plant.yaml'
    # lockstep: simulated time waits for pdplus; lockstep_wait_s is only the wall time after
    # which a silent pdplus counts as a missed sample. 50 ms (the default) latched "no command
    # for 16 ms" while the planner solved the rectangle on the same 2 cores
    sim = ProcessSpec('simulator', ros2_run_cmd(
        'irb_control', 'simulator', params={'mode': 'lockstep',
                                            'lockstep_wait_s': cfg['lockstep_wait_s']}))
    link = None
    groups = []

    def graph(specs):
        g = ProcessGroup(specs, log=lambda m: log(m) if a.verbose else None, stream=lines)
        groups.append(g)
        g.start()
        return g

    try:
        # 1 ---------------------------------------------------------------------------------
        log(f'1/{PHASES} identification sweeps: {len(cfg["joints"])} joints x '
            f'{len(cfg["speeds_rad_s"])} speeds through pdplus (time-driven, no FF)')
        prefix = f'{run_id}_friction'
        pdplus = ProcessSpec('pdplus', ros2_run_cmd('irb_control', 'pdplus', params={
            'use_sim_time': True, 'reference_mode': 'time', 'friction_mode': 'none'}))
        experiments = ProcessSpec('experiments', ros2_run_cmd(
            'irb_identification', 'experiments', params={
                'mode': 'ros', 'use_sim_time': True, 'root': str(bags), 'prefix': prefix,
                'joints': str(list(cfg['joints'])),
                'speeds_rad_s': str([float(s) for s in cfg['speeds_rad_s']]),
                'hold_max_s': float(cfg['hold_max_s']),
                'hold_min_s': float(cfg.get('hold_min_s', 0.6))}), required=False)
        g = graph([sim, pdplus, experiments])
        n_runs = len(cfg['joints']) * len(cfg['speeds_rad_s'])
        done = g.wait_until(lambda: g.procs['experiments'].poll() is not None,
                            cfg['phase_timeout_s'], period_s=0.5)
        rc = g.procs['experiments'].returncode
        g.stop()
        if not done or rc != 0:
            raise RuntimeError(f'identification sweeps failed ({g.failed or "rc " + str(rc)})')
        sweep_bags = sorted(str(p) for p in bags.glob(f'{prefix}_*') if p.is_dir())
        log(f'   {len(sweep_bags)} of {n_runs} bags recorded '
            f'({time.monotonic() - t_start:.0f} s so far)')

        # 2 ---------------------------------------------------------------------------------
        log(f'2/{PHASES} identify: replay -> identifier, friction map from the bags')
        fmap, ident_json = out / 'friction_map.yaml', out / 'identify.json'
        identifier = ProcessSpec('identifier', ros2_run_cmd(
            'irb_identification', 'identifier', params={
                'out_map': str(fmap), 'out_report': str(ident_json), 'fill_nominal': True,
                'plots_dir': str(out / 'friction'), 'quiet_period_s': 30.0,
                'effort_lag_s': float(cfg.get('effort_lag_s', 0.0))}))
        replay = ProcessSpec('replay', ros2_run_cmd('irb_identification', 'replay', params={
            'bags': str(list(sweep_bags)), 'topics': "['/joint_states']", 'rate': 0.0,
            'reliable': True, 'wait_for_subscribers': 1, 'wait_timeout_s': 60.0}),
            required=False)
        g = graph([identifier, replay])
        done = g.wait_until(ident_json.exists, cfg['phase_timeout_s'], period_s=0.5)
        g.stop()
        ident = json.loads(ident_json.read_text()) if done else {}
        stream = ident.get('stream', {})
        if not done or not fmap.exists() or ident.get('error'):
            raise RuntimeError('identifier failed: '
                               + (ident.get('error') or g.failed or 'no result in time'))
        log(f'   identifier received {stream.get("received")} of {stream.get("expected")} '
            'replayed /joint_states messages')
        if ident.get('failed') or ident.get('degenerate'):
            log('   some joints not identified, nominal values used for them (see report)')
        for name, entry in ident['joints'].items():   # rejected holds, one-sided speeds, ...
            for w in entry.get('warnings', []):
                log(f'   {w}')
        log(f'   map written: {fmap}')

        # 3, 4 ------------------------------------------------------------------------------
        link = Link()
        executed = {}
        plans = {}

        def execute(g, label, objective, friction, path=None, duration=None, process=None):
            name = f'{run_id}_{label}'
            link.modes.clear()
            g.add(ProcessSpec(f'rec_{label}', ros2_run_cmd(
                'irb_identification', 'recorder', params={'root': str(bags), 'name': name})))
            if not g.wait_until(lambda: all(lines.has(f'rec_{label}', f'subscribed to {t}')
                                            for t in ('/joint_states', '/controller_state',
                                                      '/camera/tcp')), 60):
                raise RuntimeError(f'recorder for {label} did not subscribe')
            plans[label] = link.plan(cfg, objective, friction, g, path, duration, process)
            stamp = plans[label].trajectory.header.stamp
            # pdplus checks every plan (its plan gate) and says so on ~/plan_status; the verdict
            # is the one about this plan (its stamp), not a count: each phase starts a new
            # pdplus whose counters start at zero again
            if not link.spin_until(lambda: link.plan_status is not None
                                   and link.plan_status.plan_stamp == stamp, 60, g):
                raise RuntimeError(f'pdplus gave no verdict on the {label} plan')
            if not link.plan_status.accepted:
                raise RuntimeError(f'pdplus refused the {label} plan: '
                                   f'{link.plan_status.reason}')
            link.enable(g)
            ok = link.spin_until(lambda: 2 in link.modes and link.modes[-1] in (4, 5),
                                 cfg['phase_timeout_s'], g)
            # keep recording the hold a little: in lockstep the recorder trails the graph
            link.spin_until(lambda: False, float(cfg['record_margin_s']), g)
            g.stop_one(f'rec_{label}')
            if not ok or link.modes[-1] == 4:
                raise RuntimeError(f'{label} run did not complete (modes {link.modes}, '
                                   f'{link.stop_reason or g.failed or "timeout"})')
            executed[label] = str(bags / name)
            log(f'   {label}: done, bag {bags / name}')

        def controller(friction_mode, path_file=None):
            # auto_enable off: the built-in profile must not start before the plan arrives
            params = {'use_sim_time': True, 'friction_mode': friction_mode,
                      'auto_enable': False}
            if path_file is not None:
                params['path_file'] = str(path_file)
            if friction_mode == 'file':
                params['friction_map_file'] = str(fmap)
            return ProcessSpec('pdplus', ros2_run_cmd('irb_control', 'pdplus', params=params))

        # the identified map lives in this run's directory: let the planner read it there
        planner = ProcessSpec('planner', ros2_run_cmd(
            'irb_planning', 'planner', params={'friction_map_dirs': f"['{out}']"}))
        log(f'3/{PHASES} energy-optimal and trapezoidal circles '
            f'({cfg["circle_duration_s"]} s) with the identified compensation')
        g = graph([sim, controller('file'), planner])
        execute(g, 'energy_ff', 'energy', fmap)
        execute(g, 'trapezoid_ff', 'trapezoid', fmap)
        g.stop()
        log(f'4/{PHASES} energy-optimal circle without compensation')
        g = graph([sim, controller('none'), planner])
        execute(g, 'energy_noff', 'energy', fmap)
        g.stop()

        # 5 ---------------------------------------------------------------------------------
        rect = cfg['rectangle']
        rect_file = write_rectangle(rect, out / 'rectangle_path.yaml')
        from irb_planning.messages import path_msg_from_spec
        rect_msg = path_msg_from_spec(yaml.safe_load(rect_file.read_text()))
        band = rectangle_process(rect)
        log(f'5/{PHASES} gluing contour: {rect["width_m"]} x {rect["height_m"]} m rectangle, '
            f'{rect["blend_radius_m"] * 1e3:.0f} mm blends, tilted plane, '
            f'{rect["duration_s"]} s, energy-optimal and trapezoidal, identified FF; '
            + (process_text(band) or 'no process constraints'))
        g = graph([sim, controller('file', rect_file), planner])
        execute(g, 'rect_energy_ff', 'energy', fmap, rect_msg, float(rect['duration_s']),
                band)
        execute(g, 'rect_trapezoid_ff', 'trapezoid', fmap, rect_msg, float(rect['duration_s']),
                band)
        g.stop()

        # 6 ---------------------------------------------------------------------------------
        log(f'6/{PHASES} report')
        write_report(run_id, out, cfg, executed, plans, fmap, plant_yaml, sweep_bags,
                     time.monotonic() - t_start, rect_file)
        log(f'done in {time.monotonic() - t_start:.0f} s: {out / "report.md"}')
        return 0
    except KeyboardInterrupt:
        log('interrupted: stopping the node graph')
        return 130
    except Exception as exc:  # noqa: BLE001 - any failure ends the job with a clear line
        log(f'FAILED: {exc}')
        tail = ''.join(lines.lines[-30:])
        if tail and not a.verbose:
            print(tail, file=sys.stderr)
        return 1
    finally:
        for g in groups:
            g.stop()
        if link is not None:
            link.close()


#: the rectangle block's process-constraint keys -> PlanPath request fields
PROCESS_KEYS = {'tcp_speed_max_m_s': 'tcp_speed_max', 'tcp_speed_min_m_s': 'tcp_speed_min',
                'tcp_accel_max_m_s2': 'tcp_accel_max', 'tcp_ramp_length_m': 'tcp_ramp_length'}


def rectangle_process(rect: dict) -> dict:
    """The config's process constraints of the gluing contour as PlanPath fields ({} if
    none are set)."""
    return {field: float(rect[key]) for key, field in PROCESS_KEYS.items() if key in rect}


def process_text(band: dict) -> str:
    """The process constraints in words ('' if none)."""
    parts = []
    if band.get('tcp_speed_min') or band.get('tcp_speed_max'):
        parts.append(f'bead speed {band.get("tcp_speed_min", 0.0):g}-'
                     f'{band.get("tcp_speed_max", float("inf")):g} m/s beyond '
                     f'{band.get("tcp_ramp_length", 0.0) * 1e3:.0f} mm from start and stop')
    if band.get('tcp_accel_max'):
        parts.append(f'|TCP acceleration| <= {band["tcp_accel_max"]:g} m/s^2')
    return ', '.join(parts)


def write_rectangle(rect: dict, out: Path) -> Path:
    """The gluing contour of the config's ``rectangle`` block as a path YAML file (what
    pdplus's path_file and the plan client read), with its process constraints as the
    file's ``process`` block (the plan client takes them from there)."""
    from irb_description.path import PROCESS_KEY, path_spec, rectangle_path
    path = rectangle_path(rect['center_m'], rect['normal'], float(rect['width_m']),
                          float(rect['height_m']), float(rect['blend_radius_m']))
    spec = path_spec(path)
    band = rectangle_process(rect)
    if band:
        spec[PROCESS_KEY] = band
    out.write_text(yaml.safe_dump(spec, default_flow_style=None))
    return out


def write_report(run_id, out, cfg, executed, plans, fmap, plant_yaml, sweep_bags, elapsed,
                 rect_file=None):
    """Figures from the bags, plots, report.md and summary.json."""
    from irb_description.friction import load_friction_map
    from irb_description.model import RobotModel
    from irb_description.path import load_path_file
    from irb_planning.plot import plot_plan

    from .run_report import (markdown_report, plot_runs, rectangle_section, run_figures,
                             saving_percent)
    center, radius = np.array(cfg['center_m'], float), float(cfg['radius_m'])
    rect = load_path_file(rect_file) if rect_file is not None else None
    figs = {k: (run_figures(v, k, path=rect) if k.startswith('rect_')
                else run_figures(v, k, center, radius)) for k, v in executed.items()}
    plots = plot_runs([figs['energy_ff'], figs['trapezoid_ff'], figs['energy_noff']],
                      out / 'plots')
    names = RobotModel.load().joint_names
    ident = load_friction_map(fmap, names)
    plant = load_friction_map(plant_yaml, names)
    rows = [(n, f'{j.coulomb:.2f} ± {j.ci95.get("coulomb", float("nan")):.2f}',
             f'{j.viscous:.2f} ± {j.ci95.get("viscous", float("nan")):.2f}', f'{j.static:.2f}',
             f'{p.coulomb:.2f} / {p.viscous:.2f} / {p.static:.2f}',
             f'{j.valid_range[0]:.3g}-{j.valid_range[1]:.3g}')
            for n, j, p in zip(names, ident.joints, plant.joints)]
    resp = plans['energy_ff']
    pts = resp.trajectory.points
    t = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in pts])
    plan_plot = plot_plan(out / 'plots' / 'plan.png', np.array(resp.theta),
                          np.array(resp.theta_dot), t, np.array([p.velocities for p in pts]),
                          np.array([p.effort for p in pts]),
                          f'energy plan: {resp.duration:.2f} s, {resp.energy:.1f} J')
    plan_rows = [(k, p.energy, p.duration, np.round(p.peak_torque, 1).tolist(), p.solve_time)
                 for k, p in plans.items()]
    bags = {'identification sweeps': f'{len(sweep_bags)} bags, '
            f'{Path(sweep_bags[0]).parent}/{run_id}_friction_*', **executed}
    notes = [f'pipeline time {elapsed:.0f} s; simulator in lockstep on simulated time',
             'plant friction (irb_control config/plant.yaml) differs from the nominal model '
             'on purpose; the rigid-body model is exact in this simulator, so compensation '
             'looks better than on the real robot',
             'without regeneration the work against gravity, int |g(q)^T qd| dt = '
             'int |g(Phi)^T Phi\'| dtheta, depends on the path only, not on the timing; it '
             'dominates this circle (joint 2), which bounds what any speed profile can save '
             'in this model']
    ident_json = json.loads((out / 'identify.json').read_text())
    st = ident_json.get('stream', {})
    notes.append(f'identification ran as replay -> identifier node: {st.get("received")} of '
                 f'{st.get("expected")} /joint_states messages of {len(sweep_bags)} bags '
                 f'received, stream complete: {st.get("complete")}')
    for name, entry in ident_json['joints'].items():
        rej = entry.get('rejected_segments', [])
        if rej:
            notes.append(f'identification, {name}: {len(rej)} hold(s) rejected for a '
                         'stick-slip signature (identify.json, rejected_segments)')
    sections = []
    if 'rect_energy_ff' in figs and 'rect_trapezoid_ff' in figs:
        rect_plots = plot_runs([figs['rect_energy_ff'], figs['rect_trapezoid_ff']],
                               out / 'plots' / 'rectangle')
        sections = rectangle_section(figs['rect_energy_ff'], figs['rect_trapezoid_ff'],
                                     rect_plots, plans['rect_energy_ff'],
                                     plans['rect_trapezoid_ff'], cfg['rectangle'], rect,
                                     out / 'report.md',
                                     process_text(rectangle_process(cfg['rectangle'])))
    markdown_report(run_id, figs['energy_ff'], figs['trapezoid_ff'], figs['energy_noff'],
                    plots, rows, sorted(str(p) for p in (out / 'friction').glob('*.png')),
                    plan_rows, str(plan_plot), bags, notes, out / 'report.md', sections)
    summary = {k: {'energy_j': f.energy, 'duration_s': f.duration,
                   'path_error_mean_mm': f.err_mean_mm, 'path_error_max_mm': f.err_max_mm,
                   'bag': f.bag} for k, f in figs.items()}
    summary['energy_saving_percent'] = saving_percent(figs['energy_ff'].energy,
                                                      figs['trapezoid_ff'].energy)
    summary['path_error_reduction_percent'] = 100 * (
        figs['energy_noff'].err_mean_mm - figs['energy_ff'].err_mean_mm) \
        / figs['energy_noff'].err_mean_mm
    if 'rect_energy_ff' in figs and 'rect_trapezoid_ff' in figs:
        summary['rectangle_energy_saving_percent'] = saving_percent(
            figs['rect_energy_ff'].energy, figs['rect_trapezoid_ff'].energy)
        summary['rectangle_planned_saving_percent'] = saving_percent(
            plans['rect_energy_ff'].energy, plans['rect_trapezoid_ff'].energy)
        summary['rectangle_process'] = rectangle_process(cfg['rectangle'])
        for k in ('rect_energy_ff', 'rect_trapezoid_ff'):
            summary[k].update(planned_energy_j=plans[k].energy,
                              planned_tcp_speed_low_m_s=plans[k].tcp_speed_low,
                              planned_tcp_speed_peak_m_s=plans[k].tcp_speed_peak,
                              planned_tcp_accel_peak_m_s2=plans[k].tcp_accel_peak)
    summary['elapsed_s'] = elapsed
    (out / 'summary.json').write_text(json.dumps(summary, indent=2))
    for k in ('energy_saving_percent', 'path_error_reduction_percent',
              'rectangle_energy_saving_percent'):
        if k in summary:
            log(f'   {k}: {summary[k]:.1f}')
    for k in ('rect_energy_ff', 'rect_trapezoid_ff'):
        if k in figs:
            log(f'   {k}: {figs[k].energy:.1f} J executed ({plans[k].energy:.1f} J planned), '
                f'path error mean {figs[k].err_mean_mm:.3f} mm, max {figs[k].err_max_mm:.3f} mm')


if __name__ == '__main__':
    sys.exit(main())
