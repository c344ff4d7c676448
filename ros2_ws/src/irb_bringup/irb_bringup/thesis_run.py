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
   compensation, recorded; and (config ``six_axis``, issue 30) the same rectangle with the
   nozzle normal to its plane on six joints: plan6's energy-optimal plan at the same gluing
   speed, its played check, and its run on the six-joint simulator (offline closed loop, in
   process; six_axis_phase.py);
6. the energy story (issue 17 item 6): the best placement of the thesis circle inside the
   config's region (``placement``; irb_planning.placement.search in process, with the
   identified map), its energy-optimal plan executed by pdplus following the circle at the
   best centre (``placement.execute``), recorded;
7. a one-page report (Markdown + PNG) under runs/<run id>/, bags under bags/<run id>_*: the
   thesis comparison, plus the electrical energy of the executed circles (the simulator's
   ``electrical_power`` in the bags, every DC-bus mode), the best placement against the
   trapezoid at the thesis placement, and per cycle and per year at the config's
   ``duty_cycle`` (kWh and cost); each executed run also gets its own report under
   runs/<run id>/runs/<label>/, written by the code of ``report`` (run_analysis).
Ctrl-C or any node's failure stops the graph cleanly; a second run never overwrites a first.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from functools import partial
from pathlib import Path

import numpy as np
import yaml

PHASES = 8


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


_T0 = time.monotonic()


def log(text):
    """One progress line, with the wall time since the job started."""
    print(f'[thesis_run {time.monotonic() - _T0:6.1f} s] {text}', flush=True)


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
             process=None, center=None, energy_model=''):
        """Plan on the thesis circle of ``cfg`` (or the same circle about ``center`` [m]), or
        on ``path`` (a PathSpec) for ``duration`` [s]; ``process``: PlanPath's
        process-constraint fields (tcp_speed_max, ...); ``energy_model``: what 'energy'
        minimises ('' = mechanical)."""
        if not self.spin_until(lambda: self.client.service_is_ready(), 60, group):
            raise RuntimeError('planner service plan_path did not come up')
        req = self.PlanPath.Request()
        if path is not None:
            req.path = path
        else:
            req.path.type = 'circle'
            req.path.center.x, req.path.center.y, req.path.center.z = (
                float(v) for v in (cfg['center_m'] if center is None else center))
            req.path.radius = float(cfg['radius_m'])
            req.path.direction = 1
        req.objective = objective
        req.duration = float(cfg['circle_duration_s'] if duration is None else duration)
        req.grid_size = int(cfg['planner_grid'])
        req.friction_map = str(friction_map)
        req.energy_model = str(energy_model)
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
    ap = argparse.ArgumentParser(prog='thesis_run', description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
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
    plant_el = plant_yaml.parent / 'plant_electrical.yaml'   # what the simulator draws
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
        from .energy_report import check_duty
        check_duty(cfg['duty_cycle'], float(cfg['circle_duration_s']))
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

        def execute(g, label, objective, friction, path=None, duration=None, process=None,
                    center=None, energy_model=''):
            # one recorder per run, all topics; a bag that misses samples (the recorder's own
            # loss ledger, or a gap in the path phase) fails the job: data is never lost
            # quietly, and no run is repeated to hide it
            name = f'{run_id}_{label}'
            run_once(g, label, name, objective, friction, path, duration, process, center,
                     energy_model)
            try:
                run_complete(bags / name)
            except ValueError as exc:
                raise RuntimeError(f'{label}: {exc}') from None
            executed[label] = str(bags / name)
            log(f'   {label}: done, bag {bags / name}')

        def run_once(g, label, name, objective, friction, path, duration, process, center,
                     energy_model):
            link.modes.clear()
            recorders = {'rec_' + label: (name, RECORDED_TOPICS)}
            for proc, (bag, topics) in recorders.items():
                g.add(ProcessSpec(proc, ros2_run_cmd(
                    'irb_identification', 'recorder', params={
                        'root': str(bags), 'name': bag, 'topics': str(list(topics))})))
            if not g.wait_until(lambda: all(lines.has(proc, f'subscribed to {t}')
                                            for proc, (_, topics) in recorders.items()
                                            for t in topics if t in AWAITED_TOPICS), 60):
                raise RuntimeError(f'recorders for {label} did not subscribe')
            plans[label] = link.plan(cfg, objective, friction, g, path, duration, process,
                                     center, energy_model)
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
            for proc in recorders:
                g.stop_one(proc)
            if not ok or link.modes[-1] == 4:
                raise RuntimeError(f'{label} run did not complete (modes {link.modes}, '
                                   f'{link.stop_reason or g.failed or "timeout"})')

        def controller(friction_mode, path_file=None, center=None):
            # auto_enable off: the built-in profile must not start before the plan arrives
            params = {'use_sim_time': True, 'friction_mode': friction_mode,
                      'auto_enable': False}
            if path_file is not None:
                params['path_file'] = str(path_file)
            if center is not None:        # the thesis circle about another centre [m]
                params['path_center'] = str([float(v) for v in center])
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

        # 5, six axes (issue 30): the rectangle with the nozzle normal to its plane, in process
        six_axis = None
        six_cfg = cfg.get('six_axis') or {}
        if six_cfg.get('enabled', False):
            from .six_axis_phase import six_axis_step
            t_phase = time.monotonic()
            log(f'5/{PHASES} six axes: the rectangle with the nozzle normal to its plane '
                '(irb_planning path6_rectangle.yaml), plan6 energy-optimal at the gluing speed, '
                'played check, run on the six-joint simulator (in process)')
            six_axis = six_axis_step(six_cfg, rect, out, fmap, log)
            six_axis['step_wall_time_s'] = time.monotonic() - t_phase
            log(f'   six axes: {six_axis["step_wall_time_s"]:.0f} s')

        # 6 ---------------------------------------------------------------------------------
        from .energy_report import placement_study
        pl = cfg['placement']
        t_phase = time.monotonic()
        log(f'6/{PHASES} best placement of the {cfg["circle_duration_s"]} s circle: centre in '
            f'the box {pl["lo_m"]} .. {pl["hi_m"]} m, grid {pl["n"]}, {pl["energy_model"]} '
            'energy (in process, identified map)')
        placement = placement_study(cfg, fmap, out / 'plots', log, plant_bus_mode(plant_el))
        log(f'   search: {placement["evaluations"]} plans in {placement["wall_time_s"]:.0f} s, '
            f'{placement["unreachable"]} of {placement["grid_points"]} grid points '
            'unreachable')
        if placement.get('error'):
            log(f'   placement: {placement["error"]} (reported; the best placement is not '
                'executed)')
        elif pl.get('execute', True):
            best = placement['best']['center_m']
            log(f'   best centre {np.round(best, 3).tolist()} m: executing its energy-optimal '
                'plan with the identified compensation')
            g = graph([sim, controller('file', center=best), planner])
            execute(g, 'best_energy_ff', 'energy', fmap, center=best,
                    energy_model=placement['measure'])
            g.stop()
        placement['phase_wall_time_s'] = time.monotonic() - t_phase
        log(f'   phase 6: {placement["phase_wall_time_s"]:.0f} s')

        # 7 ---------------------------------------------------------------------------------
        cycle = None
        cc = cfg.get('cycle') or {}
        if cc.get('enabled', False):
            from .cycle_phase import run_cycle_phase
            t_phase = time.monotonic()
            log(f'7/{PHASES} work cycle: motion durations and power modes within the takt '
                '(irb_planning cycle, in process, electrical model)')
            cycle = run_cycle_phase(cc, cfg['rectangle'], cfg['duty_cycle'], out / 'cycle', log)
            st = cycle['study']
            log(f'   {st["energy_j"]:.1f} J per cycle at takt {st["takt_s"]:g} s against '
                f'{st["baseline_a_j"]:.1f} J (A) and {st["baseline_b_j"]:.1f} J (B): '
                f'{st["saving_vs_a_percent"]:.1f} % less than A; phase 7: '
                f'{time.monotonic() - t_phase:.0f} s')
        else:
            log(f'7/{PHASES} work cycle: off in this configuration (cycle.enabled)')

        # 8 ---------------------------------------------------------------------------------
        log(f'8/{PHASES} report')
        write_report(run_id, out, cfg, executed, plans, fmap, plant_yaml, sweep_bags,
                     time.monotonic() - t_start, rect_file, placement, plant_el, cycle,
                     six_axis)
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


#: what each run's recorder records into the run's bag: what the report measures, the drive
#: side (commanded torques) and the simulator's electrical_power (issue 17). Until issue 31
#: a second recorder took the last two, and a run with holes was run again; the recorder now
#: takes every waiting message on each wake and writes on its own thread (0 lost of 7 topics
#: in real time; irb_identification/benchmarks/RESULTS.md), so one recorder holds them all
RECORDED_TOPICS = ('/joint_states', '/controller_state', '/camera/tcp', '/torque_command',
                   '/electrical_power')
#: a run starts once its recorders subscribed to these (/torque_command is not awaited: it
#: may appear only once pdplus is enabled)
AWAITED_TOPICS = ('/joint_states', '/controller_state', '/camera/tcp', '/electrical_power')


def run_complete(bag: Path) -> None:
    """ValueError if a run's bag lost messages (the recorder's own ledger, losses.yaml) or
    misses samples of its path phase (joint states, electrical power)."""
    import yaml
    from irb_identification.series import read_joint_series

    from .energy_report import electrical_figures
    from .run_report import check_gap, path_window
    losses = Path(bag) / 'losses.yaml'
    if losses.is_file():
        lost = yaml.safe_load(losses.read_text()) or {}
        raise ValueError(f'bag {bag}: the recorder lost {lost.get("lost_total", "some")} '
                         f'messages (see {losses})')
    t0, t1 = path_window(bag)
    check_gap(read_joint_series(bag).t, t0, t1, '/joint_states', bag)
    electrical_figures(bag, 'check', 0.0, (t0, t1))


def plant_bus_mode(plant_electrical_yaml: Path) -> str:
    """The DC-bus mode of the simulated plant's electrical parameters."""
    return str(yaml.safe_load(Path(plant_electrical_yaml).read_text())['bus']['mode'])


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


def rectangle_spec(rect: dict) -> dict:
    """The gluing contour of the config's ``rectangle`` block as a path mapping, with its
    process constraints as the ``process`` block (absent if none are set)."""
    from irb_description.path import PROCESS_KEY, path_spec, rectangle_path
    path = rectangle_path(rect['center_m'], rect['normal'], float(rect['width_m']),
                          float(rect['height_m']), float(rect['blend_radius_m']))
    spec = path_spec(path)
    band = rectangle_process(rect)
    if band:
        spec[PROCESS_KEY] = band
    return spec


def write_rectangle(rect: dict, out: Path) -> Path:
    """``rectangle_spec`` as a path YAML file (what pdplus's path_file and the plan client
    read; the plan client takes the process constraints from its ``process`` block)."""
    out.write_text(yaml.safe_dump(rectangle_spec(rect), default_flow_style=None))
    return out


def write_report(run_id, out, cfg, executed, plans, fmap, plant_yaml, sweep_bags, elapsed,
                 rect_file=None, placement=None, plant_el=None, cycle=None, six_axis=None):
    """Figures from the bags, plots, report.md and summary.json; ``placement``: phase 6's
    block (energy_report.placement_study), ``plant_el``: the simulator's electrical YAML,
    ``cycle``: phase 7's work-cycle study (cycle_phase.run_cycle_phase) or None,
    ``six_axis``: the six-axis step's figures (six_axis_phase.six_axis_step) or None."""
    from irb_description.friction import load_friction_map
    from irb_description.model import RobotModel
    from irb_description.path import CirclePath, load_path_file, path_spec
    from irb_planning.plan_plot import plan_record, plot_plan_record

    from .run_report import (markdown_report, plot_runs, rectangle_section, run_figures,
                             saving_percent)
    center, radius = np.array(cfg['center_m'], float), float(cfg['radius_m'])
    rect = load_path_file(rect_file) if rect_file is not None else None
    best = (placement or {}).get('best')
    centers = {'best_energy_ff': np.asarray(best['center_m'], float) if best else None}
    figs = {k: (run_figures(v, k, path=rect) if k.startswith('rect_')
                else run_figures(v, k, centers.get(k, center), radius))
            for k, v in executed.items()}
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
    resp = plans['energy_ff']        # the figure of `plan` (plan_plot): trapezoid, TCP speed
    (out / 'plots').mkdir(parents=True, exist_ok=True)
    plan_plot = plot_plan_record(out / 'plots' / 'plan.png', plan_record(
        path_spec(CirclePath(center, radius, 0.0, 1)), resp.trajectory, resp.theta,
        resp.theta_dot, resp.theta_ddot), f'energy plan: {resp.duration:.2f} s, '
        f'{resp.energy:.1f} J (trapezoid {resp.baseline_energy:.1f} J)')
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
    energy_summary = {}
    if placement is not None and plant_el is not None:
        sections, energy_summary = energy_sections(out, cfg, executed, figs, plans,
                                                   placement, plant_el)
    if 'rect_energy_ff' in figs and 'rect_trapezoid_ff' in figs:
        rect_plots = plot_runs([figs['rect_energy_ff'], figs['rect_trapezoid_ff']],
                               out / 'plots' / 'rectangle')
        sections += rectangle_section(figs['rect_energy_ff'], figs['rect_trapezoid_ff'],
                                     rect_plots, plans['rect_energy_ff'],
                                     plans['rect_trapezoid_ff'], cfg['rectangle'], rect,
                                     out / 'report.md',
                                     process_text(rectangle_process(cfg['rectangle'])))
    paths = {k: (rect if k.startswith('rect_') else CirclePath(
        np.asarray(centers.get(k) if centers.get(k) is not None else center, float), radius,
        0.0, 1)) for k in executed}
    if six_axis is not None:
        from .six_axis_phase import six_axis_section
        sections += six_axis_section(six_axis, out, six_axis.get('wrist'))
    if cycle is not None:
        from .cycle_phase import cycle_section
        sections += cycle_section(cycle, out)
    sections += per_run_reports(out, executed, plans, paths)
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
    summary.update({k: v for k, v in energy_summary.items() if k != 'log'})
    if six_axis is not None:
        summary['six_axis_rectangle'] = six_axis
    if cycle is not None:
        st = cycle['study']
        summary['work_cycle'] = {k: st[k] for k in (
            'takt_s', 'energy_j', 'baseline_a_j', 'baseline_b_j', 'saving_vs_a_percent',
            'saving_vs_b_percent', 'goal_met', 'lower_bound_j', 'gap_percent', 'per_year',
            'parameter_for_goal', 'ceiling_all_rest_in_bus_off_percent')}
        summary['work_cycle']['plan_json'] = cycle['plan_json']
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
    for text in energy_summary.get('log', []):
        log(f'   {text}')


def per_run_reports(out: Path, executed: dict, plans: dict, paths: dict) -> list[str]:
    """Each executed run's own report under out/runs/<label>/ by the code of ``report``
    (run_analysis), with the plan the planner answered; the Markdown lines linking them."""
    from irb_control.plant import PlantConfig
    from irb_description.model import RobotModel
    from irb_description.path import path_spec
    from irb_planning.plan_plot import plan_record, write_plan_file

    from .run_analysis import read_run, write_run_report
    from .run_report import link_path
    model = RobotModel.load()
    lines = ['## Per-run reports', '',
             'Each executed run on its own, by the code of `ros2 run irb_bringup report --bag '
             '<bag>` (planned against measured TCP path, path error along the path, tracking, '
             'commanded against measured torque, modes, TCP speed, energy):', '']
    for label, bag in executed.items():
        resp = plans[label]
        plan = plan_record(path_spec(paths[label]), resp.trajectory, resp.theta,
                           resp.theta_dot, resp.theta_ddot, duration_s=float(resp.duration),
                           energy_j=float(resp.energy))
        (out / 'runs' / label).mkdir(parents=True, exist_ok=True)
        write_plan_file(out / 'runs' / label / 'plan.json', plan)   # for `report --plan`
        run = read_run(bag, model.joint_names, plan, "the planner's answer")
        md, f = write_run_report(run, model, out / 'runs' / label,
                                 PlantConfig().camera_noise_m, f'Run {label}', paths[label])
        cam = ('' if f.cam_err is None or not f.cam_err.size
               else f', camera path error mean {1e3 * f.cam_err.mean():.3f} mm')
        gaps = f', {len(run.gaps)} gap(s) in the recording' if run.gaps else ''
        lines.append(f'- [{label}]({link_path(md, out)}): {f.duration:.2f} s, '
                     f'{f.energy:.1f} J mechanical{cam}{gaps}')
    return lines + ['']


def energy_sections(out, cfg, executed, figs, plans, placement, plant_el):
    """The report's energy story (issue 17 item 6) and its summary.json entries: electrical
    energy of the executed circles, the best placement, per cycle and per year."""
    from .energy_report import (BUS_MODES, duty_section, electrical_figures,
                                electrical_section, per_year, placement_section,
                                plot_electrical, saving_percent)
    from .run_report import link_path, path_window
    el = yaml.safe_load(Path(plant_el).read_text())
    mode, standby = str(el['bus']['mode']), float(el['controller']['standby_power_w'])

    rel = partial(link_path, base=out)
    labels = [k for k in ('energy_ff', 'trapezoid_ff', 'best_energy_ff') if k in executed]
    elec = {k: electrical_figures(executed[k], k, standby,
                                  path_window(executed[k])) for k in labels}
    plot = plot_electrical(list(elec.values()), mode, out / 'plots' / 'electrical_power.png')

    def planned(resp):
        return {'mechanical': resp.energy,
                **dict(zip(resp.electrical_bus_modes, resp.electrical_energy))}
    rows = {'energy-optimal timing (mechanical objective), the executed plan':
            planned(plans['energy_ff']),
            'trapezoid, the executed plan': planned(plans['trapezoid_ff'])}
    eo = placement.get('electrical_objective') or {}
    if mode in eo:
        rows[f'energy-optimal timing for the electrical model ({eo["energy_model"]}), '
             'in process'] = eo
    T = float(cfg['circle_duration_s'])
    cycle = {k: {m: r.cycle_energy(m, T) for m in BUS_MODES} for k, r in elec.items()}
    lines = electrical_section(elec, {k: figs[k].energy for k in labels}, rows, mode, plot,
                               rel, T)
    exe = None
    if 'best_energy_ff' in elec:
        exe = {'bag': executed['best_energy_ff'], 'mode': mode,
               'mechanical': figs['best_energy_ff'].energy,
               'electrical': cycle['best_energy_ff'][mode],
               'trapezoid_mechanical': figs['trapezoid_ff'].energy,
               'trapezoid_electrical': cycle['trapezoid_ff'][mode],
               'path_error_mean_mm': figs['best_energy_ff'].err_mean_mm}
        placement['executed'] = exe
    lines += placement_section(placement, placement.get('plot'), rel)
    duty = cfg['duty_cycle']
    motions = [('trapezoid, thesis placement', 'trapezoid_ff'),
               ('energy-optimal timing, thesis placement', 'energy_ff'),
               ('energy-optimal timing, best placement', 'best_energy_ff')]
    if exe:
        measure = f'executed, plant parameters, bus `{mode}`'
        duty_rows = [(name, per_year(cycle[k][mode], duty),
                      per_year(figs[k].energy, duty)) for name, k in motions]
    else:       # the best placement was not run: every row the planner's figures
        measure = f'planned, the planner\'s electrical model, bus `{mode}`'
        src = [placement['trapezoid_thesis'], placement['optimal_thesis'],
               placement.get('best')]
        duty_rows = [(name, per_year(v[mode], duty), per_year(v['mechanical'], duty))
                     for (name, _), v in zip(motions, src) if v]
    lines += duty_section(duty, duty_rows, measure)
    summary = {
        'plant_bus_mode': mode,
        'electrical_energy_j': {k: r.energy for k, r in elec.items()},
        'electrical_power_bags': {k: r.bag for k, r in elec.items()},
        'electrical_standby_j': {k: r.standby for k, r in elec.items()},
        'electrical_cycle_j': cycle,
        'electrical_saving_percent': {m: saving_percent(cycle['energy_ff'][m],
                                                        cycle['trapezoid_ff'][m])
                                      for m in BUS_MODES},
        'planned_energy_j': rows,
        'placement': dict(placement),
        'duty_cycle': {**duty, 'measure': measure,
                       'rows': {name: {'electrical': e, 'mechanical': m}
                                for name, e, m in duty_rows}}}
    motors = {k: r.energy[mode] - r.standby for k, r in elec.items()}
    log_lines = [f'electrical ({mode}) per {T:g} s cycle: optimal '
                 f'{cycle["energy_ff"][mode]:.1f} J, trapezoid '
                 f'{cycle["trapezoid_ff"][mode]:.1f} J, saving '
                 f'{summary["electrical_saving_percent"][mode]:.2f} %; without standby '
                 f'{motors["energy_ff"]:.1f} vs {motors["trapezoid_ff"]:.1f} J '
                 f'({saving_percent(motors["energy_ff"], motors["trapezoid_ff"]):.2f} %)']
    if placement.get('best'):
        b, t = placement['best'], placement['trapezoid_thesis']
        log_lines.append(
            f'best placement {np.round(b["center_m"], 3).tolist()} m: planned '
            f'{b["mechanical"]:.1f} J mechanical '
            f'({saving_percent(b["mechanical"], t["mechanical"]):.1f} % below the trapezoid '
            f'at the thesis placement, {t["mechanical"]:.1f} J), {b[mode]:.1f} J '
            f'electrical ({saving_percent(b[mode], t[mode]):.1f} %); certificate '
            f'{placement["certificate"]["possible_improvement_pct"]:.2f} % over '
            f'{placement["certificate"]["cells_covered"]}/'
            f'{placement["certificate"]["cells_total"]} cells; '
            f'{placement["unreachable"]} unreachable grid points')
    if exe:
        log_lines.append(f'best placement executed: {exe["mechanical"]:.1f} J mechanical '
                         f'({saving_percent(exe["mechanical"], exe["trapezoid_mechanical"]):.1f}'
                         f' % below the executed trapezoid), {exe["electrical"]:.1f} J '
                         f'electrical per cycle '
                         f'({saving_percent(exe["electrical"], exe["trapezoid_electrical"]):.1f}'
                         ' %)')
    for name, e, m in duty_rows:
        log_lines.append(f'{name}: {e["cycle_j"]:.1f} J/cycle, {e["year_kwh"]:.1f} kWh/year, '
                         f'{e["year_cost"]:.2f} {duty.get("currency", "EUR")}/year')
    summary['log'] = log_lines
    return lines, summary


if __name__ == '__main__':
    sys.exit(main())
