"""pdplus's plan gate: plans are received, decoded and checked in a process of their own.

Why a process and not a thread: in one Python process a thread that merely *takes* a large
JointTrajectory holds the interpreter lock for the whole copy. Measured here (2 cores): while a
200 000-point plan (22 MB) arrived in a raw subscription on a second thread, a 1 ms loop on the
main thread was held up by up to 238 ms (p99 unchanged, max 9 ms -> 238 ms). Decoding it with
rclpy took seconds on top. The control step may wait on nothing but its input, so pdplus
starts this gate as a child process (``python -m irb_control.plan_gate CONFIG``): it subscribes
to the plan topic with its own DDS participant, decodes, converts (trajectory_io), checks
(plan_checks: size, consistency, limits, feed-forward torque) and writes each outcome to its
stdout as one length-prefixed pickle: ``{'ok': True, 'kind': 'path'|'time', 'arrays': {...},
'summary': {...}}`` (plus ``'path'`` and ``'tracker'`` objects when the plan carries the path
it was planned on: irb_description.plan_path) or ``{'ok': False, 'reason': str}``. pdplus
reads them on a thread of its own (a blocking read: no interpreter lock held while waiting),
builds the (bounded) profile and offers it to the controller, which keeps it pending until
enable.

The child ends when pdplus ends: its stdin is a pipe from pdplus (EOF -> exit) and, on Linux,
PR_SET_PDEATHSIG delivers SIGTERM if pdplus dies. It runs at a lower priority (nice 10).
"""
from __future__ import annotations

import json
import os
import pickle
import signal
import struct
import subprocess
import sys
import threading
from dataclasses import asdict, dataclass, field

import numpy as np
from irb_description.trajectory_rules import GATE_MAX_ACCELERATION_RAD_S2, GATE_TORQUE_FRACTION

_HEADER = struct.Struct('<I')


@dataclass(frozen=True)
class GateConfig:
    """Everything the child needs (JSON on its command line)."""

    topic: str = '/planned_trajectory'
    node_name: str = 'pdplus_plan_gate'
    namespace: str = '/'
    path_center: tuple = (0.6, 0.0, 0.13)
    path_radius: float = 0.15
    path_start_angle: float = 0.0
    path_direction: int = 1
    path_file: str = ''               # YAML path spec; '' = the circle above
    time_driven: bool = False
    min_theta_dot: float = 0.05
    velocity_limit_fraction: float = 1.0
    max_points: int = 20000
    # the defaults are the planners' rule too (irb_description.trajectory_rules): one source
    max_acceleration: float = GATE_MAX_ACCELERATION_RAD_S2
    torque_fraction: float = GATE_TORQUE_FRACTION
    friction_mode: str = 'nominal'
    friction_map_file: str = ''
    joints: int = 3                   # 6: the six-joint model (pdplus joints:=6)
    tcp_xyz: tuple = (0.0, 0.0, 0.0)  # joints 6: the TCP in tool0 [m]
    domain_id: int = 0
    extra_ros_args: list = field(default_factory=list)


# --- the check itself (no ROS; used by the child and by the tests) -------------------------
def check_message_arrays(names: list[str], t: np.ndarray, pos: np.ndarray, vel, acc,
                         model, path, cfg: GateConfig, friction=None) -> dict:
    """Turn a plan's arrays into a checked profile description (see module docstring).

    names: the message's joint names; t (N,) [s]; pos/vel/acc (N, J) or None (vel/acc
    missing -> differentiated, as trajectory_io does). Raises PlanRejected / ProfileError.
    """
    from .plan_checks import PlanLimits, PlanRejected, check_joint_plan, check_size
    from .profiles import (PathProfile, TimeTrajectory, profile_from_joint_trajectory,
                           profile_from_theta_samples)
    from .trajectory_io import THETA_JOINT
    lim = model.limits
    limits = PlanLimits(lim.lower, lim.upper, lim.velocity * cfg.velocity_limit_fraction,
                        lim.torque, cfg.max_acceleration, cfg.torque_fraction, cfg.max_points)
    check_size(len(t), limits)
    t = np.asarray(t, float)
    if pos is None:
        raise PlanRejected('plan points need positions')
    pos = np.asarray(pos, float)
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise PlanRejected('time_from_start must be finite and strictly increasing')
    vel = np.gradient(pos, t, axis=0) if vel is None else np.asarray(vel, float)
    acc = np.gradient(vel, t, axis=0) if acc is None else np.asarray(acc, float)
    ff = None if friction is False else _feed_forward(model, friction)
    fields = ('theta', 'theta_dot', 'theta_ddot', 'q', 'qd', 'qdd', 't')
    if list(names) == [THETA_JOINT]:
        if model.nq != 3:
            raise PlanRejected('a theta plan gives the joints of the three-axis model only: '
                               f'a {model.nq}-joint pdplus needs plans of its joints')
        th, thd, thdd = pos[:, 0], vel[:, 0], acc[:, 0]
        # the theta law checked like a joint: consistent, no step, theta_dot >= 0
        one = PlanLimits(np.array([-1e9]), np.array([1e9]), np.array([1e3]),
                         np.array([np.inf]), 1e6, 1.0, cfg.max_points)
        check_joint_plan(t, th[:, None], thd[:, None], thdd[:, None], one)
        if np.any(thd < 0):
            raise PlanRejected('theta_dot < 0: the theta-driven controller only moves forward')
        prof = profile_from_theta_samples(model, path, th, thd, thdd, t, cfg.min_theta_dot)
        summary = check_joint_plan(prof.t, prof.q, prof.qd, prof.qdd, limits, ff,
                                   consistency=False)
        kind, arrays = 'path', {k: getattr(prof, k) for k in fields}
    else:
        try:
            idx = [list(names).index(n) for n in model.joint_names]
        except ValueError:
            raise PlanRejected(f'joint_names {list(names)} must be [theta] or contain '
                               f'{model.joint_names}') from None
        jt, jq, jqd, jqdd = t - t[0], pos[:, idx], vel[:, idx], acc[:, idx]
        summary = check_joint_plan(jt, jq, jqd, jqdd, limits, ff)
        if cfg.time_driven:
            kind, arrays = 'time', {'t': jt, 'q': jq, 'qd': jqd, 'qdd': jqdd}
        else:
            prof = profile_from_joint_trajectory(model, path, jt, jq, jqd, jqdd,
                                                 cfg.min_theta_dot)
            kind, arrays = 'path', {k: getattr(prof, k) for k in fields}
    # the objects the controller will hold are built here once, to fail early
    (TimeTrajectory if kind == 'time' else PathProfile)(**arrays)
    return {'kind': kind, 'arrays': arrays, 'summary': summary}


def _feed_forward(model, friction):
    """(q, qd, qdd) (N, 3) -> the controller's feed-forward M qdd + C qd + g + tau_f(qd)."""
    def ff(q, qd, qdd):
        out = np.array([model.inverse_dynamics(q[k], qd[k], qdd[k])
                        for k in range(q.shape[0])])
        return out if friction is None else out + friction.torque(qd)
    return ff


def profile_from_result(result: dict, sliced: bool = False):
    """The controller's profile object from a gate result (in pdplus). ``sliced``: built in
    small pieces that let other threads run in between (``profiles.build_sliced``): pdplus's
    reader thread must not hold the interpreter lock for milliseconds while the control
    thread waits for it; its new objects frozen for the garbage collector before it runs
    again."""
    from .profiles import PathProfile, TimeTrajectory, build_sliced
    cls = TimeTrajectory if result['kind'] == 'time' else PathProfile
    return (build_sliced(cls, result['arrays'], freeze=True) if sliced
            else cls(**result['arrays']))


# --- the parent's side ----------------------------------------------------------------------
class PlanGate:
    """Start the child and hand each of its results to ``on_result(dict)`` from a reader
    thread; ``on_exit(text)`` if the child ends on its own."""

    def __init__(self, cfg: GateConfig, on_result, on_exit=None):
        self.cfg = cfg
        self.on_result = on_result
        self.on_exit = on_exit
        self._stopping = False
        self.proc = subprocess.Popen(
            [sys.executable, '-m', 'irb_control.plan_gate', json.dumps(asdict(cfg))],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            start_new_session=True)    # a terminal's Ctrl-C is for pdplus, not for the gate
        self._reader = threading.Thread(target=self._read, name='plan_gate_reader',
                                        daemon=True)
        self._reader.start()

    def _read(self):
        out = self.proc.stdout
        while True:
            head = out.read(_HEADER.size)
            if len(head) < _HEADER.size:
                break
            (n,) = _HEADER.unpack(head)
            body = out.read(n)
            if len(body) < n:
                break
            try:
                result = pickle.loads(body)
            except Exception as exc:  # noqa: BLE001 - a broken frame must not kill the reader
                result = {'ok': False, 'reason': f'unreadable result from the gate: {exc}'}
            self.on_result(result)
        code = self.proc.wait()
        if not self._stopping and self.on_exit is not None:
            self.on_exit(f'plan gate process ended (exit code {code}): no new plans accepted')

    def stop(self, timeout: float = 5.0) -> None:
        self._stopping = True
        if self.proc.poll() is None:
            try:
                self.proc.stdin.close()          # EOF: the child exits on its own
                self.proc.wait(timeout)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()


# --- the child ------------------------------------------------------------------------------
def _write(result: dict) -> None:
    body = pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL)
    sys.stdout.buffer.write(_HEADER.pack(len(body)) + body)
    sys.stdout.buffer.flush()


def _die_with_parent() -> None:
    try:
        import ctypes
        ctypes.CDLL('libc.so.6').prctl(1, signal.SIGTERM)     # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass

    def watch_stdin():
        while sys.stdin.buffer.read(4096):
            pass
        os._exit(0)                                           # pdplus closed the pipe
    threading.Thread(target=watch_stdin, daemon=True).start()


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    cfg = GateConfig(**json.loads(argv[0]))
    _die_with_parent()
    try:
        os.nice(10)
    except OSError:
        pass
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # the terminal's Ctrl-C is for pdplus
    import rclpy
    from irb_description.node_main import latched_qos
    from irb_description.path import CirclePath, load_path_file, path_from_spec
    from irb_description.path_tracking import PathTracker
    from irb_description.plan_path import path_spec_from_frame_id
    from rclpy.executors import ExternalShutdownException
    from trajectory_msgs.msg import JointTrajectory

    from .closed_loop import controller_friction
    from .plan_checks import PlanRejected
    from .profiles import ProfileError
    rclpy.init(args=['--ros-args', *cfg.extra_ros_args], domain_id=cfg.domain_id)
    from .node_util import joint_model
    model = joint_model(cfg.joints, cfg.tcp_xyz)
    path = (load_path_file(cfg.path_file) if cfg.path_file else
            CirclePath(np.array(cfg.path_center, float), cfg.path_radius,
                       cfg.path_start_angle, int(cfg.path_direction)))
    friction = controller_friction(model, cfg.friction_mode, cfg.friction_map_file)
    node = rclpy.create_node(cfg.node_name, namespace=cfg.namespace)

    def on_plan(msg: JointTrajectory):
        spec = None
        try:
            n = len(msg.points)
            from .plan_checks import PlanLimits, check_size
            check_size(n, PlanLimits(*(np.zeros(model.nq),) * 4, max_points=cfg.max_points))
            t = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec
                          for p in msg.points])

            def column(attr):
                rows = [list(getattr(p, attr)) for p in msg.points]
                if any(len(r) == 0 for r in rows):
                    return None
                if len({len(r) for r in rows}) != 1 or len(rows[0]) < len(msg.joint_names):
                    raise PlanRejected(f'point {attr} lengths differ from joint_names')
                return np.array(rows, float)
            # the path the plan was planned on travels in header.frame_id (plan_path); a
            # plan without one is on the configured path
            spec = path_spec_from_frame_id(msg.header.frame_id)
            if spec is not None and cfg.joints == 6:
                # a six-axis plan's path carries its tool-orientation law: theta is estimated
                # on the geometry (the joints already carry the orientation)
                spec = {k: v for k, v in spec.items() if k != 'orientation'}
            try:
                plan_path = path if spec is None else path_from_spec(spec)
            except ValueError as exc:
                raise PlanRejected(f"the plan's path is not valid: {exc}") from None
            result = check_message_arrays(list(msg.joint_names), t, column('positions'),
                                          column('velocities'), column('accelerations'),
                                          model, plan_path, cfg, friction)
            if spec is not None and result['kind'] == 'path':
                # built here once (a spline's arc-length table took 0.8 s, a tracker 6-13 ms
                # here): pdplus unpickles them in well under a millisecond
                result['path'] = plan_path
                result['tracker'] = (None if type(plan_path) is CirclePath
                                     else PathTracker(plan_path))
                result['path_type'] = spec.get('type', 'circle')
            result['ok'] = True
        except (PlanRejected, ProfileError, ValueError) as exc:
            reason = str(exc)
            if 'does not follow the path' in reason and spec is None:
                reason += ("; the plan carries no path of its own (header.frame_id, as the "
                           "planner sets it), so it must lie on pdplus's configured path")
            result = {'ok': False, 'reason': reason, 'points': len(msg.points)}
        result['stamp'] = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        _write(result)
    node.create_subscription(JointTrajectory, cfg.topic, on_plan, latched_qos())
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
