"""`ros2 run irb_bringup cycle_run --plan D --cycles N --out O`: run a planned work cycle
repeatedly on the simulator and measure its energy (issue 29 item 4).

D is the output of `ros2 run irb_planning cycle` (cycle_plan.json and motions/). Every cycle:
each motion's plan goes to pdplus (/planned_trajectory, sent while the step before runs),
pdplus is enabled and runs it; each station waits in its planned power mode through pdplus's
~/power_<mode> services (the simulator's drives do the transitions), hold requested so that
it is back when the station ends. By default the tool brings up the simulator (lockstep, the
robot starting on its brakes at the cycle's first pose) and pdplus itself; --attach uses a
running graph instead (then --warmup cycles first bring the robot to the cycle).
Measured: the energy per cycle and per step from the simulator's electrical_power
(total_<bus> of the plan's energy model), against the plan and against the plan re-evaluated
on the plant's electrical model as executed (irb_bringup.cycle_exec names the terms); the
sag at each brake release from /joint_states; latched stops. Writes O/cycle_run.json,
O/cycle_run.md and O/cycle_run.png. Exit 0 done (the figures say whether the goals are
met), 1 a run that failed (a latched stop, a node that died, a timeout, lost samples),
2 bad arguments or plan.
"""
from __future__ import annotations

import argparse
import os
import struct
import sys
import threading
import time
from pathlib import Path

from irb_description.node_help import own_args

EXAMPLE = ('ros2 run irb_planning cycle --cycle $(ros2 pkg prefix irb_planning)/share/'
           'irb_planning/config/cycle_gluing.yaml --out cyc && '
           'ros2 run irb_bringup cycle_run --plan cyc --cycles 3 --out cyc_run')
PERIOD_S = 0.004032
#: [rad/s] a deeper mode is requested once every joint is slower (pdplus refuses at 0.01)
REST_SPEED = 0.008


def parse_args(argv):
    p = argparse.ArgumentParser(prog='cycle_run', description=__doc__.splitlines()[0],
                                epilog='example: ' + EXAMPLE)
    p.add_argument('--plan', required=True, help='cycle plan: the --out directory of '
                   'irb_planning cycle, or its cycle_plan.json')
    p.add_argument('--cycles', type=int, default=3, help='cycles measured (default 3)')
    p.add_argument('--out', required=True, help='output directory (created)')
    p.add_argument('--attach', action='store_true', help='use a running simulator and '
                   'pdplus instead of bringing them up')
    p.add_argument('--warmup', type=int, default=-1, help='cycles run first and not '
                   'measured (default: 0, or 1 with --attach)')
    p.add_argument('--sim-mode', default='paced', choices=('lockstep', 'paced'),
                   help="simulator mode when brought up: 'paced' (default: lockstep on /clock, "
                   "every state answered, simulated time at most --rate x the wall clock) or "
                   "'lockstep' (as fast as pdplus answers, and unbounded while the drives are "
                   'off in a deeper mode: the requests of a station then land later)')
    p.add_argument('--rate', type=float, default=1.0,
                   help='paced: simulated seconds per wall-clock second (default 1)')
    p.add_argument('--ramp-s', type=float, default=0.05,
                   help="[s] pdplus's shortest ramp from hold to a plan's start when brought "
                   'up (the robot is at the start already; default 0.05, pdplus\'s own 0.5)')
    p.add_argument('--step-timeout', type=float, default=120.0,
                   help='[s] wall time a step may take before the run is abandoned')
    p.add_argument('--friction-map', default='',
                   help="friction map for pdplus's compensation when brought up ('' = its "
                   "nominal); e.g. an identified map, or irb_control's config/plant.yaml "
                   "(the simulated plant's own: a perfect identification)")
    p.add_argument('--plant-electrical', default='',
                   help="the simulator's electrical parameters (plant_electrical_file; '' = "
                   "irb_control's config/plant_electrical.yaml): the predictions' plant model")
    p.add_argument('--pdplus', default='pdplus', help="pdplus's node name (default pdplus)")
    p.add_argument('--no-plot', action='store_true', help='write no PNG')
    p.add_argument('--save-series', action='store_true',
                   help='also write series.npz: electrical_power total (t, w) and joint '
                   'positions (t, q) as received, and pdplus\'s mode changes')
    p.add_argument('--verbose', action='store_true', help="echo the nodes' output")
    a = p.parse_args(argv)
    if a.cycles < 1 or a.ramp_s <= 0 or a.step_timeout <= 0 or a.rate <= 0:
        p.error('--cycles must be >= 1, --ramp-s, --step-timeout and --rate > 0')
    if a.warmup < 0:
        a.warmup = 1 if a.attach else 0
    return a


class RunFailed(RuntimeError):
    """The run cannot go on (one line)."""


def _controller_mode(data: bytes):
    """(stamp [s], mode, stop_reason) of a serialized irb_interfaces/ControllerState (only
    these fields are read)."""
    e = '<' if data[1] else '>'
    sec, nsec = struct.unpack_from(e + 'iI', data, 4)
    (n,) = struct.unpack_from(e + 'I', data, 12)
    o = 16 + n
    mode = data[o]
    o += 1
    o = 4 + ((o - 4 + 3) & ~3)
    (rl,) = struct.unpack_from(e + 'I', data, o)
    reason = data[o + 4:o + 4 + max(rl - 1, 0)].decode(errors='replace')
    return sec + nsec * 1e-9, mode, reason


class Runner:
    """The tool's ROS node: records electrical_power, joint_states and pdplus's modes; sends
    plans, enables, requests power modes."""

    def __init__(self, pdplus: str, bus: str):
        import rclpy
        from irb_control.cdr import JointStateDecoder
        from irb_description.node_main import latched_qos, refuse_insecure_start
        from irb_interfaces.msg import AxisStatus, PlanStatus
        from rclpy.experimental import EventsExecutor
        from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile,
                               ReliabilityPolicy)
        from sensor_msgs.msg import JointState
        from std_srvs.srv import Trigger
        from trajectory_msgs.msg import JointTrajectory
        from irb_interfaces.msg import ControllerState
        self.rclpy, self.Trigger = rclpy, Trigger
        self.ctx = rclpy.Context()
        refuse_insecure_start()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node('cycle_run', context=self.ctx)
        self.cv = threading.Condition()
        self.total_key = f'total_{bus}'
        self.p_t, self.p_w = [], []
        self.q_t, self.q = [], []
        self.modes = []                 # (stamp, mode, reason) on change
        self.mode, self.stop_reason = None, ''
        self.now = 0.0                  # simulated time of the newest joint state [s]
        self.speed = float('inf')       # its largest joint speed [rad/s]
        self.axis = None
        self.plan_status = None
        self._dec_p, self._dec_q = JointStateDecoder(), JointStateDecoder()
        self._p_idx = self._q_idx = None
        rel = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=20000,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
        n = self.node
        n.create_subscription(JointState, 'electrical_power', self._on_power, rel, raw=True)
        n.create_subscription(JointState, 'joint_states', self._on_joints, rel, raw=True)
        n.create_subscription(ControllerState, 'controller_state', self._on_state, rel,
                              raw=True)
        n.create_subscription(AxisStatus, 'axis_status', self._on_axis, latched_qos())
        n.create_subscription(PlanStatus, f'{pdplus}/plan_status', self._on_plan_status,
                              latched_qos())
        self.pub_plan = n.create_publisher(JointTrajectory, 'planned_trajectory',
                                           latched_qos())
        self.clients = {name: n.create_client(Trigger, f'{pdplus}/{name}')
                        for name in ('enable', 'power_hold', 'power_brakes', 'power_bus_off',
                                     'power_hibernate')}
        # the events executor (about 60 us a callback against 200 us): the simulator runs
        # several times faster than real time in a deeper power mode, and a reader that falls
        # behind decides late (its spin() ran nothing here: a spin_once loop)
        self.ex = EventsExecutor(context=self.ctx)
        self.ex.add_node(n)
        self._spin = threading.Thread(target=self._spin_loop, daemon=True)
        self._spin.start()

    def _spin_loop(self):
        try:
            while self.rclpy.ok(context=self.ctx):
                self.ex.spin_once(timeout_sec=0.1)
        except Exception:  # noqa: BLE001 - shut down under the spin
            pass

    # --- callbacks ---------------------------------------------------------------------
    def _on_power(self, data):
        sec, nsec, names, _, _, effort = self._dec_p.decode(data)
        if self._p_idx is None:
            if self.total_key not in names:
                return
            self._p_idx = names.index(self.total_key)
        with self.cv:
            self.p_t.append(sec + nsec * 1e-9)
            self.p_w.append(effort[self._p_idx])

    def _on_joints(self, data):
        sec, nsec, names, pos, vel, _ = self._dec_q.decode(data)
        if self._q_idx is None:
            self._q_idx = [names.index(f'joint_{k}') for k in (1, 2, 3)]
        i = self._q_idx
        with self.cv:
            self.now = sec + nsec * 1e-9
            self.q_t.append(self.now)
            self.q.append((pos[i[0]], pos[i[1]], pos[i[2]]))
            if len(vel) == len(pos):
                self.speed = max(abs(vel[i[0]]), abs(vel[i[1]]), abs(vel[i[2]]))
            self.cv.notify_all()

    def _on_state(self, data):
        t, mode, reason = _controller_mode(data)
        if mode != self.mode:
            with self.cv:
                self.mode = mode
                self.modes.append((t, mode, reason))
                if reason:
                    self.stop_reason = reason
                self.cv.notify_all()

    def _on_axis(self, msg):
        with self.cv:
            self.axis = msg
            self.cv.notify_all()

    def _on_plan_status(self, msg):
        with self.cv:
            self.plan_status = msg
            self.cv.notify_all()

    # --- waits and requests ----------------------------------------------------------------
    def wait(self, cond, timeout_s: float, what: str, group=None):
        deadline = time.monotonic() + timeout_s
        with self.cv:
            while not cond():
                if self.mode == 4 and what != 'stop':
                    raise RunFailed(f'pdplus latched a stop while {what}: {self.stop_reason}')
                if group is not None and group.poll() is not None:
                    raise RunFailed(f'{group.failed} exited while {what}')
                left = deadline - time.monotonic()
                if left <= 0:
                    raise RunFailed(f'timeout ({timeout_s:g} s wall) while {what}')
                self.cv.wait(min(left, 0.2))

    def call(self, name: str, timeout_s: float, group=None, retry_if: str = '') -> str:
        """Call pdplus/<name>; a refusal whose text holds ``retry_if`` is asked again on the
        next joint state (until ``timeout_s``), any other is RunFailed."""
        c = self.clients[name]
        self.wait(c.service_is_ready, timeout_s, f'waiting for pdplus/{name}', group)
        deadline = time.monotonic() + timeout_s
        while True:
            fut = c.call_async(self.Trigger.Request())
            done = threading.Event()
            fut.add_done_callback(lambda f: done.set())
            if not done.wait(timeout_s):
                raise RunFailed(f'pdplus/{name} gave no answer in {timeout_s:g} s')
            r = fut.result()
            if r.success:
                return r.message
            if not retry_if or retry_if not in r.message or time.monotonic() > deadline:
                raise RunFailed(f'pdplus/{name} refused: {r.message}')
            t = self.now
            self.wait(lambda: self.now > t, timeout_s, f'retrying pdplus/{name}', group)

    def send_plan(self, step, stamp_ns: int):
        from irb_description.plan_path import path_frame_id
        from irb_description.stamps import sec_nanosec
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
        from builtin_interfaces.msg import Duration
        tr = step.trajectory
        msg = JointTrajectory(joint_names=['joint_1', 'joint_2', 'joint_3'])
        qdd = tr.get('qdd')
        for k, t in enumerate(tr['t']):
            s, ns = sec_nanosec(float(t))
            msg.points.append(JointTrajectoryPoint(
                positions=tr['q'][k].tolist(), velocities=tr['qd'][k].tolist(),
                accelerations=[] if qdd is None else qdd[k].tolist(),
                effort=tr['tau'][k].tolist(), time_from_start=Duration(sec=s, nanosec=ns)))
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        msg.header.frame_id = path_frame_id(step.path_spec)
        self.pub_plan.publish(msg)
        return msg.header.stamp

    def close(self):
        try:
            self.ex.shutdown(timeout_sec=1.0)
            self.node.destroy_node()
        finally:
            self.rclpy.try_shutdown(context=self.ctx)
            self._spin.join(timeout=2.0)


def execute(runner: Runner, plan, modes, cycles: int, warmup: int, timeout: float, group,
            say, rec: dict) -> None:
    """Run warmup + cycles cycles; ``rec`` collects, cycle by cycle, the events (per step
    StepEvents), the cycle windows, the brake releases and the lateness of the timed
    requests [simulated s] (``finish`` turns it into the result, of a failed run too)."""
    from .cycle_exec import MOTION, StepEvents, schedule
    acts = schedule(plan, modes)
    steps = plan.steps
    state = {'sent': {}, 'stamp': time.time_ns()}
    releases, cycles_ev, windows, late = [], [], [], []
    rec.update(cycles_ev=cycles_ev, windows=windows, releases=releases, late=late,
               holds={}, steps=steps, warmup=warmup)
    r = runner

    def send(i):
        state['stamp'] += 1000
        stamp = r.send_plan(steps[i], state['stamp'])
        state['sent'][i] = stamp

    def accepted(i):
        stamp = state['sent'][i]
        r.wait(lambda: r.plan_status is not None and r.plan_status.plan_stamp == stamp,
               timeout, f'waiting for pdplus to check the plan of {steps[i].name}', group)
        if not r.plan_status.accepted:
            raise RunFailed(f'pdplus refused the plan of {steps[i].name}: '
                            f'{r.plan_status.reason}')

    def until(t_sim, what):
        r.wait(lambda: r.now >= t_sim, timeout, what, group)
        late.append(r.now - t_sim)

    first = next(i for i, s in enumerate(steps) if s.kind == MOTION)
    send(first)
    t_cycle = None
    for k in range(warmup + cycles):
        ev = [None] * len(steps)
        holds, t_mode, t_hold, running = {}, {}, {}, None
        for a in acts:
            s = steps[a.step]
            if a.kind == 'enable':
                accepted(a.step)
                if t_cycle is not None and a.t_s == 0.0:
                    until(t_cycle, f'waiting to start cycle {k + 1}')
                n_modes = len(r.modes)
                r.call('enable', timeout, group)
                # the ramp starts on the next sample: its stamp is the step's start
                r.wait(lambda: any(m == 1 for _, m, _ in r.modes[n_modes:]), timeout,
                       f'waiting for the ramp of {s.name}', group)
                t_ramp = next(t for t, m, _ in r.modes[n_modes:] if m == 1)
                if t_cycle is None:
                    t_cycle = t_ramp
                r.wait(lambda: any(m == 2 for _, m, _ in r.modes[n_modes:]), timeout,
                       f'waiting for the path of {s.name}', group)
                t_path = next(t for t, m, _ in r.modes[n_modes:] if m == 2)
                ev[a.step] = StepEvents(t_ramp, None, t_path=t_path)
                running = (a.step, n_modes)
            elif a.kind == 'send':
                send(a.step)            # waits pending in pdplus while this motion runs
                i, n_modes = running
                r.wait(lambda: any(m == 5 for _, m, _ in r.modes[n_modes:]), timeout,
                       f'running {steps[i].name}', group)
                holds[i] = next(t for t, m, _ in r.modes[n_modes:] if m == 5)
            elif a.kind == 'mode':
                if a.mode == 'hold':
                    until(t_cycle + a.t_s, f'waiting in {s.mode} at {s.name}')
                    t_hold[a.step] = r.now
                    releases.append(r.now)
                    r.call('power_hold', timeout, group)
                else:
                    # brakes only at rest: a fast motion's end is declared (theta at the
                    # end) while the arm still settles; pdplus checks |qd| < 0.01 rad/s
                    r.wait(lambda: r.speed < REST_SPEED, timeout,
                           f'waiting for rest before {a.mode} at {s.name}', group)
                    t_mode[a.step] = r.now
                    r.call(f'power_{a.mode}', timeout, group, retry_if='not at rest')
            elif a.kind == 'released':
                r.wait(lambda: r.axis is not None and not r.axis.brakes_engaged
                       and r.mode == 5, timeout, f'waiting for the brakes to open at '
                       f'{s.name}', group)
            elif a.kind == 'wait':
                until(t_cycle + a.t_s, f'waiting at {s.name}')
        # a station starts where the motion before it holds at its end
        t_next = t_cycle + plan.takt_s
        for i, s in enumerate(steps):
            if s.kind != MOTION:
                ev[i] = StepEvents(holds[i - 1], None, t_mode=t_mode.get(i),
                                   t_hold=t_hold.get(i))
        windows.append((t_cycle, t_next))
        cycles_ev.append(ev)
        rec['holds'] = holds
        say(f'cycle {k + 1}/{warmup + cycles}{" (warm-up)" if k < warmup else ""} done at '
            f'{r.now:.2f} s simulated')
        t_cycle = t_next


def finish(rec: dict) -> dict | None:
    """The completed cycles of ``rec`` (after the warm-up): events with every step's window
    closed (each step ends where the next starts, a motion's hold at its end being its own;
    the last cycle's last step at its cycle's end or its motion's end), windows, releases,
    lateness; None without a completed measured cycle."""
    from .cycle_exec import MOTION
    cycles_ev, windows, warmup = rec.get('cycles_ev', []), rec.get('windows', []), \
        rec.get('warmup', 0)
    if len(windows) <= warmup:
        return None
    steps, holds = rec['steps'], rec['holds']
    end = windows[-1][1]
    if steps[-1].kind == MOTION and holds.get(len(steps) - 1, end) > end:
        end = holds[len(steps) - 1]          # the last motion ran past its cycle's end
    flat = [e for ev in cycles_ev for e in ev]
    for j, e in enumerate(flat):
        e.t1 = flat[j + 1].t0 if j + 1 < len(flat) else end
    late = rec['late']
    return {'events': cycles_ev[warmup:], 'windows': windows[warmup:],
            'releases': rec['releases'], 'end_s': max(end, windows[-1][1]),
            'late_s': late[len(late) * warmup // len(windows):]}


def main(args=None):
    argv = own_args(args)
    a = parse_args(argv)
    from .cycle_exec import CycleRunError, load_plan
    try:
        plan = load_plan(a.plan)
    except CycleRunError as exc:
        print(f'cycle_run: {exc}', file=sys.stderr)
        return 2
    out = Path(a.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f'cycle_run: cannot create {out}: {exc.strerror}', file=sys.stderr)
        return 2
    try:
        return run(a, plan, out)
    except KeyboardInterrupt:
        print('cycle_run: interrupted', file=sys.stderr)
        return 130


def run(a, plan, out: Path) -> int:
    import json
    import numpy as np
    from .cycle_exec import (CycleRunError, compare_cycle, first_gap, load_models, markdown,
                             plan_predictions, plot, sag_at_release, summarise)
    t_start = time.monotonic()

    def say(text):
        print(f'[cycle_run {time.monotonic() - t_start:6.1f} s] {text}', flush=True)
    models = load_models(plan.power_modes_file, a.plant_electrical,
                         plan.electrical_config)
    preds = plan_predictions(plan, models)
    say(f'plan {plan.source}: {len(plan.steps)} steps, takt {plan.takt_s:g} s, '
        f'{plan.energy_j:.1f} J per cycle planned ({plan.bus} bus); on the plant\'s '
        f'electrical model {sum(p["plant_model_j"] for p in preds):.1f} J')
    group = None
    runner = None
    tail = []
    rec = {}
    stops, result, rc = [], None, 0
    try:
        if not a.attach:
            from irb_control.process_group import ProcessGroup, ProcessSpec, ros2_run_cmd
            q0 = plan.motions[0].q_start
            sp = {'mode': a.sim_mode, 'lockstep_wait_s': 0.5, 'lockstep_rate': float(a.rate),
                  'initial_positions': str([float(x) for x in q0])}
            if a.plant_electrical:
                sp['plant_electrical_file'] = a.plant_electrical
            sim = ProcessSpec('simulator', ros2_run_cmd('irb_control', 'simulator',
                                                        params=sp))
            pd = ProcessSpec('pdplus', ros2_run_cmd('irb_control', 'pdplus', params={
                'use_sim_time': True, 'auto_enable': False, 'builtin_profile': 'none',
                'ramp_min_duration_s': float(a.ramp_s),
                **({'friction_mode': 'file', 'friction_map_file': a.friction_map}
                   if a.friction_map else {})}))

            class Echo:
                def write(self, text):
                    tail.append(text)
                    del tail[:-20]
                    if a.verbose:
                        sys.stdout.write(text)

                def flush(self):
                    sys.stdout.flush()
            group = ProcessGroup([sim, pd], log=say if a.verbose else (lambda m: None),
                                 stream=Echo())
            group.start()
            say(f'simulator ({a.sim_mode}) and pdplus started')
        runner = Runner(a.pdplus, plan.bus)
        runner.wait(lambda: runner.axis is not None and runner.now > 0, 60.0,
                    'waiting for the simulator (axis_status, joint_states)', group)
        runner.wait(lambda: runner.mode is not None, 60.0, 'waiting for pdplus', group)
        say(f'graph up; running {a.warmup} warm-up + {a.cycles} measured cycles')
        execute(runner, plan, models.plant_modes, a.cycles, a.warmup, a.step_timeout,
                group, say, rec)
        ex = finish(rec)
        runner.wait(lambda: runner.p_t and runner.p_t[-1] >= ex['end_s'] and
                    runner.q_t[-1] >= ex['end_s'], 60.0, 'waiting for the last samples',
                    group)
    except RunFailed as exc:
        say(f'FAILED: {exc}')
        if group is not None and group.failed and not a.verbose:
            sys.stderr.write(''.join(tail[-10:]))
        stops = [runner.stop_reason] if runner is not None and runner.stop_reason else []
        ex, rc = finish(rec), 1
        if ex is not None:
            say(f'the {len(ex["windows"])} cycles completed before are measured')
    finally:
        if runner is not None:
            with runner.cv:
                pt, pw = np.array(runner.p_t), np.array(runner.p_w)
                qt, qq = np.array(runner.q_t), np.array(runner.q)
                stops_seen = [(t, r) for t, m, r in runner.modes if m == 4]
                modes_seen = [(t, m) for t, m, _ in runner.modes]
            runner.close()
        if group is not None:
            group.stop()
    if runner is None:
        return 1
    stops += [r for _, r in stops_seen if r not in stops]
    if a.save_series:
        np.savez_compressed(out / 'series.npz', power_t=pt, power_w=pw, joints_t=qt,
                            joints_q=qq, modes=np.array(modes_seen, float).reshape(-1, 2))
    cycles, sags = [], []
    if ex is not None:
        try:
            o = np.argsort(pt, kind='stable')
            pt, pw = pt[o], pw[o]
            lo = ex['windows'][0][0]
            sel = pt >= lo - 1.0
            gap = first_gap(pt[sel], PERIOD_S)
            if gap is not None:
                raise CycleRunError(f'electrical_power lost samples: a gap of {gap[1]:.4f} s '
                                    f'at {gap[0]:.4f} s')
            for k, (ev, win) in enumerate(zip(ex['events'], ex['windows'])):
                try:
                    cycles.append(compare_cycle(plan, models, preds, ev, win, pt, pw,
                                                PERIOD_S))
                except CycleRunError as exc:
                    if rc == 0:
                        raise
                    say(f'cycle {k + 1} not measured: {exc}')
                    break
            ends = [e.t0 for ev in ex['events'] for e in ev] + [ex['end_s']]
            for t_rel in ex['releases']:
                if t_rel < lo:
                    continue
                t_end = min((t for t in ends if t > t_rel + 1e-9), default=ex['end_s'])
                sags.append(sag_at_release(qt, qq, t_rel, t_end).tolist())
        except CycleRunError as exc:
            say(f'FAILED: {exc}')
            rc = 1
    summary = summarise(cycles, plan, sags, stops)
    load = ' '.join(f'{x:.1f}' for x in os.getloadavg())
    result = {'plan': plan.source,
              'sim_mode': 'attached' if a.attach else a.sim_mode + (
                  f' at {a.rate:g}x' if a.sim_mode == 'paced' else ''),
              'ramp_s': a.ramp_s, 'friction_map': a.friction_map or 'nominal',
              'warmup': a.warmup, 'cycles_requested': a.cycles,
              'wall_time_s': time.monotonic() - t_start, 'load': load,
              'summary': summary, 'plan_predictions': preds, 'cycles': cycles,
              'sags_rad': sags, 'failed': rc != 0,
              'decision_late_s': ({'median': float(np.median(ex['late_s'])),
                                   'max': float(np.max(ex['late_s']))}
                                  if ex is not None and ex['late_s'] else None)}
    if cycles and not a.no_plot:
        result['png'] = str(plot(result, out / 'cycle_run.png'))
    (out / 'cycle_run.json').write_text(json.dumps(result, indent=1, default=float))
    (out / 'cycle_run.md').write_text(markdown(result))
    if cycles:
        mp = summary['measured_vs_planned_percent']
        say(f'{len(cycles)} cycles: measured {summary["measured_median_j"]:.1f} J vs planned '
            f'{plan.energy_j:.1f} J per cycle: {mp["median"]:+.2f} % median, '
            f'{mp["worst"]:+.2f} % worst; against the plant-model prediction '
            f'{summary["measured_vs_predicted_percent"]["median"]:+.2f} %; terms '
            + ', '.join(f'{k} {v:+.1f} J' for k, v in summary['terms_median_j'].items())
            + f'; sag max {summary["sag_at_release_mrad"]["max"]} mrad; '
            f'{summary["stops"]} stops')
    say(f'written {out / "cycle_run.json"}, {out / "cycle_run.md"}')
    return rc


if __name__ == '__main__':
    sys.exit(main())
