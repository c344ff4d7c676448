"""One run from its bag: read what was recorded, compute its figures, plot, write Markdown.

No ROS imports (bags are read with irb_identification.bagio). Used by ``report`` (any run, any
path) and by the main job (``thesis_run``: its per-run figures and reports).

Inputs, each optional except /joint_states (sensor_msgs/JointState, effort = applied torque):
/torque_command (commanded torque), /controller_state (modes, tracking errors, theta),
/camera/tcp (measured TCP), /electrical_power (per axis and total_<bus mode> [W]),
/planned_path + /planned_trajectory + /planned_theta_profile (the plan), also from a sibling
bag ``<bag>_drive`` (the main job records the drive side there). What is missing is said in
``RunData.notes`` and the figures that need it are skipped.

Analysis window: where the controller followed the plan (MODE_PATH or MODE_TIME), else the
whole recording. Inside it: mechanical energy E = int sum_i |tau_i qd_i| dt (thesis eq. 6.9,
trapezoidal rule on the joint-state stamps), electrical energy int P dt per bus mode, camera
path error = distance of each camera point from the planned path, placed along the path by
its nearest point (arc length s), joint tracking errors (q_ref - q, the controller's), the TCP
speed |J(q) qd| from the measured joints. A series with a gap > MAX_SAMPLE_GAP_S inside the
window is named in ``RunData.gaps`` (figures across a gap interpolate over it).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: [s] a gap between samples above this inside the window is reported (the recorder lost
#: samples or the publisher stalled); samples come every 4.032 ms (camera every 10 ms)
MAX_SAMPLE_GAP_S = 0.05
#: [s] two topics' stamps of the same instant, converted to float seconds on different paths
#: (sec + 1e-9 nanosec, ns * 1e-9), may differ by a step of the double (2.4e-7 s at 1.7e9 s):
#: the window takes samples this close to its ends (samples are >= 1 ms apart)
STAMP_TOLERANCE_S = 1e-6
DRIVE_SUFFIX = '_drive'
JOINT_STATE = 'sensor_msgs/msg/JointState'
CONTROLLER_STATE = 'irb_interfaces/msg/ControllerState'
POINT = 'geometry_msgs/msg/PointStamped'


@dataclass
class RunData:
    """What a run's bag holds, as arrays (times [s], bag clock); None where not recorded."""

    bag: str
    joint_names: list
    topics: dict = field(default_factory=dict)       # {topic: (bag, count)}
    js_t: np.ndarray | None = None
    q: np.ndarray | None = None
    qd: np.ndarray | None = None
    tau: np.ndarray | None = None
    cmd_t: np.ndarray | None = None
    cmd_tau: np.ndarray | None = None
    ctrl_t: np.ndarray | None = None
    mode: np.ndarray | None = None
    q_error: np.ndarray | None = None
    qd_error: np.ndarray | None = None
    stops: list = field(default_factory=list)         # [(t, reason)]
    cam_t: np.ndarray | None = None
    cam_p: np.ndarray | None = None
    power_t: np.ndarray | None = None
    power_names: list = field(default_factory=list)
    power: np.ndarray | None = None
    plan: dict | None = None                          # plan file mapping (plan_plot)
    plan_source: str = ''
    notes: list = field(default_factory=list)
    gaps: list = field(default_factory=list)          # [(series, start [s], length [s])]
    window: tuple = (0.0, 0.0)
    window_kind: str = ''


def _stamp(m) -> float:
    return m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec


def _times(msgs, t_ns) -> np.ndarray:
    """Header stamps [s] (log time where a stamp is zero)."""
    st = np.array([_stamp(m) for m in msgs], float)
    return np.where(st > 0, st, np.asarray(t_ns, float) * 1e-9)


def _sorted(t, *arrays):
    o = np.argsort(t, kind='stable')
    return (t[o], *[a[o] for a in arrays])


def _columns(msgs, names: list, attr: str, topic: str) -> np.ndarray:
    """(N, len(names)) of the JointState field ``attr`` picked by joint name."""
    have = list(msgs[0].name)
    missing = [n for n in names if n not in have]
    if missing:
        raise ValueError(f'{topic} has no {missing} (has {have})')
    idx = [have.index(n) for n in names]
    out = np.full((len(msgs), len(names)), np.nan)
    for k, m in enumerate(msgs):
        v = np.asarray(getattr(m, attr), float)
        if list(m.name) != have:
            idx_k = [list(m.name).index(n) if n in m.name else None for n in names]
            out[k] = [v[i] if i is not None and i < v.size else np.nan for i in idx_k]
        elif v.size == len(have):
            out[k] = v[idx]
    if np.all(np.isnan(out)):
        raise ValueError(f'{topic} carries no {attr} for {names}')
    return out


def find_gaps(t: np.ndarray, t0: float, t1: float, limit: float = MAX_SAMPLE_GAP_S
              ) -> list[tuple[float, float]]:
    """[(start [s], length [s])] of the gaps > ``limit`` between sorted stamps ``t`` in
    [t0, t1], counting the window's ends (a series that starts late or ends early)."""
    t = np.asarray(t, float)
    t = t[(t >= t0 - 1e-9) & (t <= t1 + 1e-9)]
    edges = np.concatenate([[t0], t, [t1]])
    d = np.diff(edges)
    return [(float(edges[i]), float(d[i])) for i in np.flatnonzero(d > limit)]


def read_run(bag: str | Path, joint_names: list, plan: dict | None = None,
             plan_source: str = '', progress=lambda s: None,
             topics: tuple | None = None) -> RunData:
    """RunData of ``bag`` (and its ``<bag>_drive`` sibling); ``plan``: a plan file's mapping
    (overrides the plan in the bag); ``topics``: read only these. Raises bagio.BagError if
    the bag cannot be read at all, ValueError if it has no usable /joint_states."""
    from irb_identification.bagio import bag_topics, read_messages, topic_qos, typestore

    def names(b: Path):
        # the topics from metadata.yaml: opening the bag's reader parses every split file's
        # QoS (0.1-0.3 s per file); a missing or broken bag raises the reader's own error
        if not (b / 'metadata.yaml').is_file():
            return bag_topics(b)
        return topic_qos(b)
    bag = Path(bag)
    run = RunData(str(bag), list(joint_names))
    sources = {t: bag for t in names(bag)}
    drive = Path(str(bag) + DRIVE_SUFFIX)
    if drive.is_dir() and (drive / 'metadata.yaml').is_file():
        for t in names(drive):
            sources.setdefault(t, drive)
    if topics is not None:
        sources = {t: b for t, b in sources.items() if t in topics}
    store = typestore([JOINT_STATE, CONTROLLER_STATE, POINT, 'irb_interfaces/msg/PathSpec',
                       'trajectory_msgs/msg/JointTrajectory',
                       'std_msgs/msg/Float64MultiArray'])

    if '/joint_states' not in sources:
        raise ValueError(f'bag {bag}: no /joint_states (has {sorted(sources)}): nothing to '
                         'report')
    wanted = ['/joint_states', '/torque_command', '/controller_state', '/camera/tcp',
              '/electrical_power', '/planned_path', '/planned_trajectory',
              '/planned_theta_profile']
    raws = {}
    for src in dict.fromkeys(sources.values()):        # one pass over each bag
        mine = [t for t in wanted if sources.get(t) == src]
        if mine:
            progress(f'reading {", ".join(mine)} from {src.name}')
            raws.update(read_messages(src, mine))

    def load(topic):
        if topic not in raws:
            return None, None
        raw = raws[topic]
        run.topics[topic] = (str(sources[topic]), len(raw.data))
        progress(f'{topic}: {len(raw.data)} messages')
        return [store.deserialize_cdr(d, raw.msgtype) for d in raw.data], raw.t_ns

    from irb_identification.series import JOINT_STATE as JS, decode_joint_states
    raw = raws['/joint_states']
    if raw.msgtype != JS or not raw.data:
        raise ValueError(f'bag {bag}: /joint_states is {raw.msgtype} with {len(raw.data)} '
                         'messages: nothing to report')
    try:
        js = decode_joint_states(raw.data, raw.t_ns).select(list(joint_names))
    except ValueError as exc:
        raise ValueError(f'bag {bag}: /joint_states: {exc}') from None
    run.topics['/joint_states'] = (str(sources['/joint_states']), len(js.t))
    progress(f'/joint_states: {len(js.t)} messages')
    run.js_t, run.q, run.qd, run.tau = js.t, js.position, js.velocity, js.effort
    msgs, t_ns = load('/torque_command')
    if msgs:
        try:
            run.cmd_t, run.cmd_tau = _sorted(_times(msgs, t_ns),
                                             _columns(msgs, joint_names, 'effort',
                                                      '/torque_command'))
        except ValueError as exc:
            run.notes.append(f'/torque_command unusable: {exc}')
    msgs, t_ns = load('/controller_state')
    if msgs:
        n = len(joint_names)

        def col(attr):
            return np.array([np.resize(np.asarray(getattr(m, attr), float), n)
                             if len(getattr(m, attr)) == n else np.full(n, np.nan)
                             for m in msgs])
        run.ctrl_t, run.mode, run.q_error, run.qd_error = _sorted(
            _times(msgs, t_ns), np.array([m.mode for m in msgs], int), col('q_error'),
            col('qd_error'))
        last = ''
        for t, m in sorted(zip(_times(msgs, t_ns), msgs), key=lambda x: x[0]):
            if m.stop_reason and m.stop_reason != last:
                run.stops.append((float(t), str(m.stop_reason)))
            last = m.stop_reason
    msgs, t_ns = load('/camera/tcp')
    if msgs:
        run.cam_t, run.cam_p = _sorted(_times(msgs, t_ns), np.array(
            [[m.point.x, m.point.y, m.point.z] for m in msgs], float).reshape(-1, 3))
    msgs, t_ns = load('/electrical_power')
    if msgs:
        run.power_names = list(msgs[0].name)
        run.power_t, run.power = _sorted(_times(msgs, t_ns), np.array(
            [np.resize(np.asarray(m.effort, float), len(run.power_names)) for m in msgs]))
    if plan is not None:
        run.plan, run.plan_source = plan, plan_source
    else:
        run.plan, run.plan_source = _plan_in_bag(load, run)
    _window(run)
    return run


def _plan_in_bag(load, run: RunData):
    """The last plan the bag holds (/planned_path + /planned_trajectory, with
    /planned_theta_profile if recorded) as a plan file mapping; (None, '') without one."""
    from irb_planning.plan_plot import plan_record, spec_from_path_msg
    paths, _ = load('/planned_path')
    trajs, _ = load('/planned_trajectory')
    if not paths:
        return None, ''
    spec = spec_from_path_msg(paths[-1])
    if not trajs:
        run.notes.append('/planned_path recorded without /planned_trajectory: the path is '
                         'known, the planned timing is not')
        return {'path': spec}, '/planned_path'
    prof, _ = load('/planned_theta_profile')
    th = thd = thdd = []
    if prof:
        d = np.asarray(prof[-1].data, float)
        if d.size % 4 == 0 and d.size:
            _, th, thd, thdd = d.reshape(4, -1)
    return (plan_record(spec, trajs[-1], th, thd, thdd),
            '/planned_path, /planned_trajectory in the bag')


def _window(run: RunData) -> None:
    """The analysis window and the gaps of every series inside it."""
    t = run.js_t
    if run.mode is not None and np.any(np.isin(run.mode, (2, 3))):
        phases = path_phases(run.ctrl_t, run.mode)
        run.window = phases[-1]
        run.window_kind = 'controller following the plan (modes path/time)'
        if len(phases) > 1:
            run.notes.append(f'{len(phases)} path phases in the bag (from t = '
                             + ', '.join(f'{a - t.min():.2f}' for a, _ in phases)
                             + ' s after the first joint state): this report covers the last')
        after = run.mode[run.ctrl_t > run.window[1]]
        if not np.any(np.isin(after, (4, 5))):
            run.notes.append('the recording ends while the controller still follows the plan '
                             '(no hold or stop after it): the run may be cut short')
        planned = (run.plan or {}).get('t') or []
        if len(planned) > 1 and abs((run.window[1] - run.window[0]) - planned[-1]) > max(
                0.1 * planned[-1], 0.2):
            run.notes.append(f'the path phase lasts {run.window[1] - run.window[0]:.2f} s, the '
                             f'plan {planned[-1]:.2f} s: this run may not have executed this '
                             'plan (planned figures for comparison only)')
    else:
        run.window = (float(t.min()), float(t.max()))
        run.window_kind = 'whole recording'
        run.notes.append('no /controller_state in path or time mode: figures over the whole '
                         'recording' if run.mode is None or run.mode.size
                         else 'no controller states: figures over the whole recording')
    t0, t1 = run.window
    for name, ts in (('/joint_states', run.js_t), ('/torque_command', run.cmd_t),
                     ('/controller_state', run.ctrl_t), ('/camera/tcp', run.cam_t),
                     ('/electrical_power', run.power_t)):
        if ts is not None and ts.size:
            run.gaps += [(name, a, d) for a, d in find_gaps(ts, t0, t1)]


def path_phases(t: np.ndarray, mode: np.ndarray) -> list[tuple[float, float]]:
    """[(first, last) stamp [s]] of each stretch of consecutive controller states in path or
    time mode (sorted stamps ``t``, modes ``mode``)."""
    on = np.isin(mode, (2, 3)).astype(int)
    edges = np.diff(np.concatenate([[0], on, [0]]))
    return [(float(t[a]), float(t[b - 1])) for a, b in zip(np.flatnonzero(edges == 1),
                                                          np.flatnonzero(edges == -1))]


# --- figures ----------------------------------------------------------------------------------
def mechanical_energy(t: np.ndarray, tau: np.ndarray, qd: np.ndarray, t0: float, t1: float
                      ) -> float:
    """E = int_t0^t1 sum_i |tau_i qd_i| dt [J], trapezoidal rule on the samples inside."""
    sel = (t >= t0 - STAMP_TOLERANCE_S) & (t <= t1 + STAMP_TOLERANCE_S)
    return float(np.trapezoid(np.abs(tau[sel] * qd[sel]).sum(axis=1), t[sel]))


def path_errors(path, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distance [m], arc length s [m] of the nearest path point) of points p (M, 3)."""
    from irb_control.closed_loop import path_distance
    p = np.asarray(p, float).reshape(-1, 3)
    if not p.size:
        return np.zeros(0), np.zeros(0)
    s = np.asarray(path.theta_of(p), float) * path.length / (2 * np.pi)
    return np.asarray(path_distance(path, p), float), s


def noise_floor(sigma_m: float) -> float:
    """Mean distance [m] of a point with isotropic noise ``sigma_m`` per axis from the curve
    it lies on: the noise in the curve's normal plane is Rayleigh, mean sigma sqrt(pi / 2)."""
    return float(sigma_m) * float(np.sqrt(np.pi / 2))


@dataclass
class RunFigs:
    """A run's figures inside its window (NaN / None where the data are missing)."""

    duration: float = float('nan')
    energy: float = float('nan')
    energy_all: float = float('nan')
    electrical: dict = field(default_factory=dict)     # {channel: J}
    t_tcp: np.ndarray | None = None                     # joint-state times from t0 [s]
    tcp: np.ndarray | None = None                       # FK of measured joints (N, 3)
    tcp_speed: np.ndarray | None = None                 # |J qd| [m/s]
    cam_t: np.ndarray | None = None
    cam_err: np.ndarray | None = None
    cam_s: np.ndarray | None = None
    fk_err: np.ndarray | None = None
    fk_s: np.ndarray | None = None
    tracking_rms: np.ndarray | None = None              # [rad] per joint
    tracking_max: np.ndarray | None = None
    torque_rms_diff: np.ndarray | None = None           # measured - commanded [N m]
    planned_speed: tuple | None = None                  # (t, TCP speed) of the plan
    path: object = None
    lines: list = field(default_factory=list)           # what could not be computed


def run_figs(run: RunData, model, path=None) -> RunFigs:
    """The figures of ``run`` (``path``: an irb_description path; default: the plan's)."""
    from irb_description.path import path_from_spec
    f = RunFigs()
    t0, t1 = run.window
    f.duration = t1 - t0
    sel = (run.js_t >= t0 - STAMP_TOLERANCE_S) & (run.js_t <= t1 + STAMP_TOLERANCE_S)
    f.energy = mechanical_energy(run.js_t, run.tau, run.qd, t0, t1)
    f.energy_all = mechanical_energy(run.js_t, run.tau, run.qd, -np.inf, np.inf)
    f.t_tcp = run.js_t[sel] - t0
    q, qd = run.q[sel], run.qd[sel]
    f.tcp = np.array([model.fk(x) for x in q]).reshape(-1, 3)
    f.tcp_speed = np.array([np.linalg.norm(model.jacobian(x) @ v) for x, v in zip(q, qd)])
    if path is None and run.plan and 'path' in run.plan:
        path = path_from_spec(run.plan['path'])
    f.path = path
    if path is None:
        f.lines.append('no planned path (no --plan, no /planned_path in the bag): no path '
                       'error, no planned path in the plots')
    else:
        f.fk_err, f.fk_s = path_errors(path, f.tcp)
        if run.cam_t is None:
            f.lines.append('no /camera/tcp: no camera path error (the error from the '
                           'measured joints is shown)')
        else:
            c = (run.cam_t >= t0) & (run.cam_t <= t1)
            f.cam_t = run.cam_t[c] - t0
            f.cam_err, f.cam_s = path_errors(path, run.cam_p[c])
    if path is not None and run.plan and len(run.plan.get('theta_dot', [])) > 1:
        from irb_planning.plan_plot import profile_times    # TCP speed = L theta_dot / 2 pi
        f.planned_speed = (profile_times(run.plan['theta'], run.plan['theta_dot'],
                                         run.plan.get('theta_ddot')),
                           path.length / (2 * np.pi) * np.asarray(run.plan['theta_dot']))
    elif run.plan and 't' in run.plan and len(run.plan['t']):
        tp = np.asarray(run.plan['t'], float)
        qp, qdp = np.asarray(run.plan['q'], float), np.asarray(run.plan['qd'], float)
        if qp.ndim == 2 and qp.shape[1] == len(run.joint_names):
            f.planned_speed = (tp, np.array([np.linalg.norm(model.jacobian(x) @ v)
                                             for x, v in zip(qp, qdp)]))
    if run.q_error is not None:
        c = (run.ctrl_t >= t0) & (run.ctrl_t <= t1)
        e = run.q_error[c]
        if e.size and np.any(np.isfinite(e)):
            f.tracking_rms = np.sqrt(np.nanmean(e ** 2, axis=0))
            f.tracking_max = np.nanmax(np.abs(e), axis=0)
    else:
        f.lines.append('no /controller_state: no joint tracking errors, no controller modes')
    if run.cmd_t is not None and run.cmd_t.size > 1:
        c = (run.cmd_t >= t0) & (run.cmd_t <= t1)
        if c.sum() > 1:
            cmd = np.column_stack([np.interp(run.js_t[sel], run.cmd_t[c], run.cmd_tau[c, i])
                                   for i in range(run.cmd_tau.shape[1])])
            f.torque_rms_diff = np.sqrt(np.nanmean((run.tau[sel] - cmd) ** 2, axis=0))
    else:
        f.lines.append('no /torque_command: no commanded torque')
    if run.power is None:
        f.lines.append('no /electrical_power: no electrical energy')
    else:
        c = (run.power_t >= t0) & (run.power_t <= t1)
        if c.sum() > 1:
            for i, name in enumerate(run.power_names):
                f.electrical[name] = float(np.trapezoid(run.power[c, i], run.power_t[c]))
        else:
            f.lines.append('/electrical_power has no samples inside the window')
    return f


# --- plots and Markdown -----------------------------------------------------------------------
def _modes_legend() -> str:
    from irb_control.pd_plus import MODE_NAMES
    return ', '.join(f'{k} {v}' for k, v in sorted(MODE_NAMES.items()))


def plot_run(run: RunData, f: RunFigs, out_dir: Path, sigma_m: float, label: str = ''
             ) -> dict[str, str]:
    """The run's PNGs in ``out_dir``: {key: file}."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from irb_planning.plan_plot import path_unit, plane_coordinates
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {}
    t0, t1 = run.window
    names = run.joint_names

    def save(fig, key):
        fig.tight_layout()
        fig.savefig(out_dir / f'{key}.png', dpi=100)
        plt.close(fig)
        files[key] = str(out_dir / f'{key}.png')

    def span(ax):
        ax.axvspan(0.0, t1 - t0, color='0.9', zorder=0)
        ax.grid(alpha=0.3)

    # planned against measured TCP path
    fig = plt.figure(figsize=(12, 5))
    a3 = fig.add_subplot(1, 2, 1, projection='3d')
    a2 = fig.add_subplot(1, 2, 2)
    ref = f.tcp
    if f.path is not None:
        pp = f.path.point(np.linspace(0.0, 2 * np.pi, 600))
        ref = pp
        a3.plot(*pp.T, 'k--', lw=1, label='planned path')
        a2.plot(*plane_coordinates(pp, pp), 'k--', lw=1, label='planned path')
    a3.plot(*f.tcp.T, lw=1, label='measured (joints, FK)')
    a2.plot(*plane_coordinates(f.tcp, ref), lw=1, label='measured (joints, FK)')
    if f.cam_err is not None:
        c = (run.cam_t >= t0) & (run.cam_t <= t1)
        a3.plot(*run.cam_p[c].T, '.', ms=1.5, label='camera')
        a2.plot(*plane_coordinates(run.cam_p[c], ref), '.', ms=1.5, label='camera')
    a3.set(xlabel='x [m]', ylabel='y [m]', zlabel='z [m]', title='TCP path (base_link)')
    u, v = plane_coordinates(ref, ref)
    flat = np.ptp(v) < 0.1 * np.ptp(u)         # a line: v magnified to show the deviation
    a2.set(xlabel='u [m]', ylabel='v [m]', aspect='auto' if flat else 'equal',
           title="in the path's plane (its two main directions)"
                 + (', v magnified' if flat else ''))
    a2.grid(alpha=0.3)
    a2.legend(fontsize=8)
    fig.suptitle(f'{label} planned against measured TCP path, inside the window')
    save(fig, 'tcp_path')
    # path error along the path and over time
    if f.fk_err is not None:
        name, unit, k = path_unit(f.path)
        scale = (2 * np.pi / f.path.length) if name == 'theta' else 1.0
        fig, ax = plt.subplots(2, 1, figsize=(10, 6.5))
        if f.cam_err is not None:
            ax[0].plot(scale * f.cam_s, 1e3 * f.cam_err, '.', ms=2, label='camera')
            ax[1].plot(f.cam_t, 1e3 * f.cam_err, lw=0.8, label='camera')
        ax[0].plot(scale * f.fk_s, 1e3 * f.fk_err, '.', ms=1, label='measured joints (FK)')
        ax[1].plot(f.t_tcp, 1e3 * f.fk_err, lw=0.8, label='measured joints (FK)')
        for a in ax:
            a.axhline(1e3 * noise_floor(sigma_m), color='r', ls=':',
                      label=f'camera noise floor {1e6 * noise_floor(sigma_m):.0f} um '
                            f'(sigma {1e6 * sigma_m:.0f} um per axis)')
            a.set(ylabel='path error [mm]')
            a.grid(alpha=0.3)
            a.legend(fontsize=8)
        ax[0].set(xlabel=f'{name} along the path [{unit}]', title='path error along the path')
        ax[1].set(xlabel='time from window start [s]', title='path error over time')
        save(fig, 'path_error')
    # joint tracking errors
    if run.q_error is not None:
        fig, ax = plt.subplots(len(names), 1, figsize=(10, 2 + 1.6 * len(names)),
                               sharex=True)
        for i, a in enumerate(np.atleast_1d(ax)):
            a.plot(run.ctrl_t - t0, 1e3 * run.q_error[:, i], lw=0.8)
            a.set(ylabel=f'{names[i]} q_ref - q [mrad]')
            span(a)
        np.atleast_1d(ax)[-1].set_xlabel('time from window start [s] (grey: window)')
        fig.suptitle('joint tracking errors (the controller\'s)')
        save(fig, 'tracking')
    # commanded against measured torque
    fig, ax = plt.subplots(len(names), 1, figsize=(10, 2 + 1.6 * len(names)), sharex=True)
    for i, a in enumerate(np.atleast_1d(ax)):
        a.plot(run.js_t - t0, run.tau[:, i], lw=0.8, label='measured (joint_states effort)')
        if run.cmd_t is not None:
            a.plot(run.cmd_t - t0, run.cmd_tau[:, i], lw=0.8, ls='--', label='commanded')
        a.set(ylabel=f'{names[i]} [N m]')
        span(a)
    np.atleast_1d(ax)[0].legend(fontsize=8)
    np.atleast_1d(ax)[-1].set_xlabel('time from window start [s] (grey: window)')
    fig.suptitle('commanded against measured torque')
    save(fig, 'torque')
    # modes and TCP speed
    fig, ax = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    if run.mode is not None:
        ax[0].step(run.ctrl_t - t0, run.mode, where='post')
        for t, reason in run.stops:
            ax[0].axvline(t - t0, color='r', lw=0.8)
    ax[0].set(ylabel='mode', title=f'controller modes ({_modes_legend()})', yticks=range(6))
    ax[1].plot(f.t_tcp, f.tcp_speed, lw=0.8, label='measured |J(q) qd|')
    if f.planned_speed is not None:
        ax[1].plot(*f.planned_speed, '--', label='planned (plan t = 0 at the window start)')
    ax[1].set(xlabel='time from window start [s]', ylabel='TCP speed [m/s]', title='TCP speed')
    ax[1].legend(fontsize=8)
    for a in ax:
        span(a)
    save(fig, 'modes_speed')
    # power
    fig, ax = plt.subplots(figsize=(10, 3.8))
    sel = (run.js_t >= t0) & (run.js_t <= t1)
    ax.plot(run.js_t[sel] - t0, np.abs(run.tau[sel] * run.qd[sel]).sum(axis=1),
            label=f'mechanical sum |tau qd|: {f.energy:.1f} J')
    if run.power is not None:
        c = (run.power_t >= t0) & (run.power_t <= t1)
        for i, n in enumerate(run.power_names):
            if n.startswith('total_'):
                ax.plot(run.power_t[c] - t0, run.power[c, i], lw=0.8,
                        label=f'electrical {n}: {f.electrical.get(n, float("nan")):.1f} J')
    ax.set(xlabel='time from window start [s]', ylabel='power [W]', title='power')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save(fig, 'power')
    return files


def _mx(x) -> str:
    return '–' if x is None or not np.size(x) else f'{1e3 * float(np.max(x)):.3f}'


def _mm(x) -> str:
    return '–' if x is None or not np.size(x) else f'{1e3 * float(np.mean(x)):.3f}'


def run_markdown(run: RunData, f: RunFigs, plots: dict, out: Path, sigma_m: float,
                 title: str) -> list[str]:
    """The run's Markdown lines (PNGs linked relative to ``out``'s folder)."""
    from .run_report import link_path
    rel = lambda p: link_path(p, out.parent)       # noqa: E731
    t0, t1 = run.window
    names = run.joint_names
    lines = [f'# {title}', '', f'Bag: `{run.bag}`', '',
             f'Window: {run.window_kind}, {f.duration:.3f} s, from '
             f'{t0 - run.js_t[0]:.3f} s after the first joint state (times in the plots '
             f'count from the window start). Plan: {run.plan_source or "none"}.', '',
             '| topic | messages | from |', '|---|---|---|',
             *[f'| {k} | {n} | `{Path(b).name}` |' for k, (b, n) in run.topics.items()], '']
    if run.gaps:
        lines += ['**Gaps in the recorded series inside the window** (> '
                  f'{1e3 * MAX_SAMPLE_GAP_S:.0f} ms; figures across them interpolate):', '',
                  *[f'- {s}: {d:.3f} s missing from t = {a - t0:.3f} s' for s, a, d in
                    run.gaps], '']
    else:
        lines += [f'No gap > {1e3 * MAX_SAMPLE_GAP_S:.0f} ms in any series inside the window.',
                  '']
    if run.stops:
        lines += ['Controller stops: ' + '; '.join(f'{t - t0:.3f} s: {r}'
                                                   for t, r in run.stops), '']
    cant = f.lines + run.notes
    if cant:
        lines += ['Not computed / notes:', '', *[f'- {x}' for x in cant], '']
    lines += ['## Energy', '', '| figure | value |', '|---|---|',
              f'| mechanical E = ∫Σ\\|τq̇\\|dt in the window [J] | {f.energy:.2f} |',
              f'| mechanical, whole recording [J] | {f.energy_all:.2f} |',
              *[f'| electrical {k} in the window [J] | {v:.2f} |'
                for k, v in f.electrical.items() if k.startswith('total_')],
              *([f'| electrical, axes only (sum, no standby) [J] | '
                 f'{sum(v for k, v in f.electrical.items() if not k.startswith("total_")):.2f}'
                 ' |'] if f.electrical else []),
              *([f'| planned (plan file / bag) [J] | {run.plan["energy_j"]:.2f} |']
                if run.plan and 'energy_j' in run.plan else []),
              f'| peak TCP speed [m/s] | {np.max(f.tcp_speed, initial=0.0):.4f} |', '',
              f'![power]({rel(plots["power"])})', '']
    lines += ['## Path', '']
    if f.fk_err is not None:
        lines += ['| path error | mean [mm] | max [mm] | samples |', '|---|---|---|---|',
                  *([f'| camera | {_mm(f.cam_err)} | '
                     f'{_mx(f.cam_err)} | {f.cam_err.size} |']
                    if f.cam_err is not None else []),
                  f'| measured joints (FK) | {_mm(f.fk_err)} | '
                  f'{_mx(f.fk_err)} | {f.fk_err.size} |', '',
                  f'Camera noise floor: a point with {1e6 * sigma_m:.0f} um noise per axis lies '
                  f'on average {1e6 * noise_floor(sigma_m):.0f} um from the path it is on '
                  '(red line): errors near it are noise.', '',
                  f'![path error]({rel(plots["path_error"])})', '']
    lines += [f'![TCP path]({rel(plots["tcp_path"])})', '', '## Tracking and torque', '']
    if f.tracking_rms is not None:
        lines += ['| joint | tracking RMS [mrad] | max [mrad] | torque RMS measured - '
                  'commanded [N m] |', '|---|---|---|---|',
                  *[f'| {n} | {1e3 * f.tracking_rms[i]:.3f} | {1e3 * f.tracking_max[i]:.3f} | '
                    + (f'{f.torque_rms_diff[i]:.2f}' if f.torque_rms_diff is not None
                       else '–') + ' |' for i, n in enumerate(names)], '']
    if 'tracking' in plots:
        lines += [f'![tracking]({rel(plots["tracking"])})', '']
    lines += [f'![torque]({rel(plots["torque"])})', '',
              f'![modes and TCP speed]({rel(plots["modes_speed"])})', '']
    return lines


def summary(run: RunData, f: RunFigs) -> dict:
    """The run's figures as JSON-ready numbers."""
    def num(x):
        return None if x is None else float(x)
    return {'bag': run.bag, 'window_s': list(run.window), 'window_kind': run.window_kind,
            'duration_s': f.duration, 'mechanical_energy_j': f.energy,
            'mechanical_energy_all_j': f.energy_all, 'electrical_energy_j': f.electrical,
            'camera_path_error_mean_mm': num(None if f.cam_err is None or not f.cam_err.size
                                             else 1e3 * f.cam_err.mean()),
            'fk_path_error_mean_mm': num(None if f.fk_err is None or not f.fk_err.size
                                         else 1e3 * f.fk_err.mean()),
            'tracking_rms_mrad': (None if f.tracking_rms is None
                                  else (1e3 * f.tracking_rms).tolist()),
            'peak_tcp_speed_m_s': float(np.max(f.tcp_speed, initial=0.0)),
            'gaps': [{'series': s, 'start_s': a - run.window[0], 'length_s': d}
                     for s, a, d in run.gaps],
            'not_computed': f.lines + run.notes, 'plan': run.plan_source}


def write_run_report(run: RunData, model, out_dir: Path, sigma_m: float, title: str,
                     path=None, progress=lambda s: None) -> tuple[Path, RunFigs]:
    """Figures, PNGs, ``report.md`` and ``summary.json`` of one run in ``out_dir``."""
    import json
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    progress('computing figures (forward kinematics of every joint state)')
    f = run_figs(run, model, path)
    progress('plotting')
    plots = plot_run(run, f, out_dir, sigma_m)
    md = out_dir / 'report.md'
    md.write_text('\n'.join(run_markdown(run, f, plots, md, sigma_m, title)))
    (out_dir / 'summary.json').write_text(json.dumps(summary(run, f), indent=2))
    return md, f
