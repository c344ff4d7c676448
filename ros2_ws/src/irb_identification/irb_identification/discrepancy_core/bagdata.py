"""Bags of measured runs <-> arrays: /joint_states, /torque_command, /camera/tcp. No rclpy.

``RunData`` holds one bag: encoder samples (t, q, qd, effort = applied torque), the torque
commands (stamp = the answered joint state's stamp) and the camera's TCP points. PointStamped
payloads are encoded/decoded with a fixed CDR layout (one template, stamps and floats patched),
like ``series.encode_joint_states``.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..bagio import BagError, BagWriter, TopicInfo, qos_profile_dict
from ..gaps import GapConfig, SeriesCheck
from ..series import JOINT_STATE, encode_joint_states

POINT_STAMPED = 'geometry_msgs/msg/PointStamped'
TOPIC_STATE = '/joint_states'
TOPIC_COMMAND = '/torque_command'
TOPIC_CAMERA = '/camera/tcp'


@dataclass
class RunData:
    """One measured run (bag). N encoder samples, K commands, M camera samples, SI units.

    t (N,) [s]; q (N, 3) [rad]; qd (N, 3) [rad/s]; effort (N, 3) [N m] (applied torque of
    the period ending at t); cmd_t (K,) [s], cmd (K, 3) [N m]; cam_t (M,) [s], cam_p (M, 3)
    [m] in base_link; name: bag name; meta: the bag's custom data; filled (N,) bool or None:
    samples interpolated into a short gap (run_pieces), not measured.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    effort: np.ndarray
    cmd_t: np.ndarray
    cmd: np.ndarray
    cam_t: np.ndarray
    cam_p: np.ndarray
    name: str = ''
    meta: dict | None = None
    filled: np.ndarray | None = None


def _point_template(frame_id: str) -> tuple[bytes, int]:
    from ..bagio import serialize, typestore
    ts = typestore([POINT_STAMPED])
    msg = ts.types[POINT_STAMPED](
        header=ts.types['std_msgs/msg/Header'](
            stamp=ts.types['builtin_interfaces/msg/Time'](sec=0, nanosec=0),
            frame_id=frame_id),
        point=ts.types['geometry_msgs/msg/Point'](x=1.0, y=2.0, z=3.0))
    raw = serialize(POINT_STAMPED, msg)
    off = raw.index(struct.pack('<3d', 1.0, 2.0, 3.0))
    return raw, off


def encode_points(t_ns: np.ndarray, p: np.ndarray, frame_id: str = 'base_link') -> list[bytes]:
    """CDR PointStamped payloads (M,) for stamps t_ns (M,) [ns] and points p (M, 3) [m]."""
    raw, off = _point_template(frame_id)
    out = []
    for tn, pt in zip(np.asarray(t_ns, np.int64), np.asarray(p, float)):
        b = bytearray(raw)
        struct.pack_into('<iI', b, 4, int(tn // 1_000_000_000), int(tn % 1_000_000_000))
        struct.pack_into('<3d', b, off, *pt)
        out.append(bytes(b))
    return out


def decode_points(data: list[bytes], log_t_ns) -> tuple[np.ndarray, np.ndarray]:
    """(t (M,) [s], p (M, 3) [m]) from PointStamped payloads (stamp, or log time if 0)."""
    from ..bagio import deserialize
    t = np.empty(len(data))
    p = np.empty((len(data), 3))
    for i, (d, lt) in enumerate(zip(data, log_t_ns)):
        m = deserialize(POINT_STAMPED, d)
        ns = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
        t[i] = (ns if ns > 0 else lt) * 1e-9
        p[i] = (m.point.x, m.point.y, m.point.z)
    order = np.argsort(t, kind='stable')
    return t[order], p[order]


def write_run(path: str | Path, joint_names: list[str], t: np.ndarray, q: np.ndarray,
              qd: np.ndarray, effort: np.ndarray, cmd_t: np.ndarray, cmd: np.ndarray,
              cam_t: np.ndarray, cam_p: np.ndarray, start_ns: int = 1_700_000_000 * 10**9,
              custom_data: dict[str, str] | None = None) -> Path:
    """Write one run as a rosbag2 MCAP bag (topics as the live stack records them)."""
    ns = lambda tt: start_ns + np.round(np.asarray(tt) * 1e9).astype(np.int64)  # noqa: E731
    t_ns, c_ns, k_ns = ns(t), ns(cmd_t), ns(cam_t)
    js = encode_joint_states(t_ns, joint_names, q, qd, effort)
    z = np.zeros_like(cmd)
    cs = encode_joint_states(c_ns, joint_names, z, z, cmd) if len(cmd) else []
    ps = encode_points(k_ns, cam_p)
    events = sorted([(int(a), 0, i) for i, a in enumerate(t_ns)]
                    + [(int(a), 1, i) for i, a in enumerate(c_ns)]
                    + [(int(a), 2, i) for i, a in enumerate(k_ns)])
    topics = (TOPIC_STATE, TOPIC_COMMAND, TOPIC_CAMERA)
    payloads = (js, cs, ps)
    clock = [0.0]
    with BagWriter(path, split_period_s=1e9, clock=lambda: clock[0],
                   custom_data=dict(custom_data or {})) as w:
        w.add_topic(TopicInfo.for_type(TOPIC_STATE, JOINT_STATE,
                                       [qos_profile_dict('best_effort', depth=1)]))
        w.add_topic(TopicInfo.for_type(TOPIC_COMMAND, JOINT_STATE,
                                       [qos_profile_dict('best_effort', depth=1)]))
        w.add_topic(TopicInfo.for_type(TOPIC_CAMERA, POINT_STAMPED, [qos_profile_dict()]))
        for tn, kind, i in events:
            w.write(topics[kind], tn, payloads[kind][i])
    return Path(path)


def read_run(path: str | Path, joint_names: list[str]) -> RunData:
    """RunData of a bag (or a main-job run bag with its ``_drive`` companion, see
    readers.py); BagError names the bag, the topic and what is missing.

    Measured q, qd and effort come from /joint_states (required, joints selected by name:
    a six-joint message is fine); the commanded torque from /torque_command (effort only;
    may be missing: the command channel is then empty); /camera/tcp may be missing.
    """
    from ..readers import joint_series, read_topics
    path = Path(path)
    msgs, src = read_topics(path, [TOPIC_STATE], optional=[TOPIC_COMMAND, TOPIC_CAMERA])
    js = joint_series(msgs[TOPIC_STATE], src[TOPIC_STATE], joints=joint_names)
    if TOPIC_COMMAND in msgs and msgs[TOPIC_COMMAND].data:
        cs = joint_series(msgs[TOPIC_COMMAND], src[TOPIC_COMMAND], ('effort',), joint_names)
        cmd_t, cmd = cs.t, cs.effort
        ok = np.all(np.isfinite(cmd), axis=1)
        cmd_t, cmd = cmd_t[ok], cmd[ok]
    else:
        cmd_t, cmd = np.empty(0), np.empty((0, 3))
    if TOPIC_CAMERA in msgs and msgs[TOPIC_CAMERA].data:
        if msgs[TOPIC_CAMERA].msgtype != POINT_STAMPED:
            raise BagError(f'bag {src[TOPIC_CAMERA]}: {TOPIC_CAMERA} is '
                           f'{msgs[TOPIC_CAMERA].msgtype}, not {POINT_STAMPED}')
        cam_t, cam_p = decode_points(msgs[TOPIC_CAMERA].data, msgs[TOPIC_CAMERA].t_ns)
    else:
        cam_t, cam_p = np.empty(0), np.empty((0, 3))
    return RunData(js.t, js.position, js.velocity, js.effort, cmd_t, cmd, cam_t, cam_p,
                   path.name)


def run_pieces(run: RunData, gaps: GapConfig = GapConfig(), label: str | None = None
               ) -> tuple[list[RunData], list[SeriesCheck]]:
    """A run checked for gaps and duplicates (gaps.py) and cut into what can be analysed.

    Joint states: duplicates dropped; the run is split at every gap longer than
    ``gaps.split_s()`` into pieces of at least ``gaps.min_segment_s`` (each analysed as a run
    of its own: no filter, derivative or spline crosses a gap); inside a piece the few
    missing samples of short gaps are interpolated onto the even grid the residual filters
    need. Commands and camera: duplicates dropped, their gaps reported; a piece keeps the
    commands and camera samples of its own time span, and residuals.prepare_run does not
    interpolate commands across a command gap. Returns (pieces, checks of the three
    series; ``label`` names the bag in them). Raises gaps.GapError (one line) when
    ``on_gap`` is 'refuse' and the joint states have a gap, or when no piece is long
    enough.
    """
    from ..gaps import check_series, fill_grid
    label = label or run.name or 'run'
    chk, keep, segs = check_series(run.t, label, TOPIC_STATE, gaps)
    checks = [chk]
    t, q, qd, eff = run.t[keep], run.q[keep], run.qd[keep], run.effort[keep]
    cmd_t, cmd = run.cmd_t, run.cmd
    if len(cmd_t) > 1:
        soft = GapConfig(**{**gaps.__dict__, 'on_gap': 'segment', 'min_segment_s': 0.0})
        cchk, ckeep, _ = check_series(cmd_t, label, TOPIC_COMMAND, soft)
        checks.append(cchk)
        cmd_t, cmd = cmd_t[ckeep], cmd[ckeep]
    cam_t, cam_p = run.cam_t, run.cam_p
    if len(cam_t) > 2:
        soft = GapConfig(**{**gaps.__dict__, 'on_gap': 'segment', 'min_segment_s': 0.0,
                            'period_s': float(np.median(np.diff(cam_t)))})
        kchk, kkeep, _ = check_series(cam_t, label, TOPIC_CAMERA, soft)
        checks.append(kchk)
        cam_t, cam_p = cam_t[kkeep], cam_p[kkeep]
    if chk.clean and len(segs) == 1 and segs[0] == (0, len(t)):
        return [RunData(t, q, qd, eff, cmd_t, cmd, cam_t, cam_p, run.name, run.meta)], checks
    pieces = []
    for i, (a, b) in enumerate(segs):
        tn, arr, filled = fill_grid(t[a:b], {'q': q[a:b], 'qd': qd[a:b], 'effort': eff[a:b]},
                                    chk.period_s, smooth=('q',))
        lo, hi = tn[0], tn[-1]
        c = (cmd_t >= lo - 0.1) & (cmd_t <= hi)
        k = (cam_t >= lo) & (cam_t <= hi)
        name = f'{run.name}[{i + 1}/{len(segs)}]' if len(segs) > 1 else run.name
        pieces.append(RunData(tn, arr['q'], arr['qd'], arr['effort'], cmd_t[c], cmd[c],
                              cam_t[k], cam_p[k], name, dict(run.meta or {}), filled))
    return pieces, checks
