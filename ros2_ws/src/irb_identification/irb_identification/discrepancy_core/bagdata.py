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

from ..bagio import BagError, BagWriter, TopicInfo, qos_profile_dict, read_messages
from ..series import JOINT_STATE, decode_joint_states, encode_joint_states

POINT_STAMPED = 'geometry_msgs/msg/PointStamped'
TOPIC_STATE = '/joint_states'
TOPIC_COMMAND = '/torque_command'
TOPIC_CAMERA = '/camera/tcp'


@dataclass
class RunData:
    """One measured run (bag). N encoder samples, K commands, M camera samples, SI units.

    t (N,) [s]; q (N, 3) [rad]; qd (N, 3) [rad/s]; effort (N, 3) [N m] (applied torque of
    the period ending at t); cmd_t (K,) [s], cmd (K, 3) [N m]; cam_t (M,) [s], cam_p (M, 3)
    [m] in base_link; name: bag name; meta: the bag's custom data.
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
    """RunData of a bag; BagError names a missing topic or a malformed message.

    /joint_states is required; /torque_command and /camera/tcp may be missing (their
    channels are then empty and the workflow skips them).
    """
    from ..bagio import bag_topics
    from ..series import JointStateError
    path = Path(path)
    present = bag_topics(path)
    if TOPIC_STATE not in present:
        raise BagError(f'bag {path}: no {TOPIC_STATE} (has {sorted(present)})')
    wanted = [tp for tp in (TOPIC_STATE, TOPIC_COMMAND, TOPIC_CAMERA) if tp in present]
    msgs = read_messages(path, wanted)
    try:
        js = decode_joint_states(msgs[TOPIC_STATE].data, msgs[TOPIC_STATE].t_ns).select(
            joint_names)
        if TOPIC_COMMAND in msgs and msgs[TOPIC_COMMAND].data:
            cs = decode_joint_states(msgs[TOPIC_COMMAND].data, msgs[TOPIC_COMMAND].t_ns
                                     ).select(joint_names)
            cmd_t, cmd = cs.t, cs.effort
        else:
            cmd_t, cmd = np.empty(0), np.empty((0, 3))
    except JointStateError as exc:
        raise BagError(f'bag {path}: {exc}') from exc
    if TOPIC_CAMERA in msgs and msgs[TOPIC_CAMERA].data:
        if present[TOPIC_CAMERA] != POINT_STAMPED:
            raise BagError(f'bag {path}: {TOPIC_CAMERA} is {present[TOPIC_CAMERA]}')
        cam_t, cam_p = decode_points(msgs[TOPIC_CAMERA].data, msgs[TOPIC_CAMERA].t_ns)
    else:
        cam_t, cam_p = np.empty(0), np.empty((0, 3))
    return RunData(js.t, js.position, js.velocity, js.effort, cmd_t, cmd, cam_t, cam_p,
                   path.name)
