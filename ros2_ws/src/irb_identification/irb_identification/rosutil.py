"""Small rclpy helpers shared by the recorder, replay and experiments nodes."""
from __future__ import annotations

import importlib
import os
from pathlib import Path

from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy)


def message_class(msgtype: str):
    """The Python class of 'pkg/msg/Name' (rosidl_runtime_py is not on PyPI)."""
    pkg, kind, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{pkg}.{kind}'), name)


def qos_to_dict(qos: QoSProfile) -> dict:
    """A publisher's QoS in the bag metadata form (see bagio.qos_profile_dict)."""
    from .bagio import qos_profile_dict
    return qos_profile_dict(qos.reliability.name.lower(), qos.durability.name.lower(),
                            qos.depth, qos.history.name.lower())


def qos_from_dicts(profiles: list[dict], depth: int = 100) -> QoSProfile:
    """QoS to publish a recorded topic with: reliable unless every recorded publisher was
    best effort, transient local only if every one was."""
    best_effort = bool(profiles) and all(p.get('reliability') == 'best_effort'
                                         for p in profiles)
    latched = bool(profiles) and all(p.get('durability') == 'transient_local'
                                     for p in profiles)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def subscription_qos(endpoints, depth: int = 1000) -> QoSProfile:
    """QoS that matches every current publisher (rosbag2's adaptation): best effort if any
    publisher is, transient local if all are."""
    any_be = any(e.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for e in endpoints)
    all_tl = bool(endpoints) and all(
        e.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for e in endpoints)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.BEST_EFFORT if any_be else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if all_tl else DurabilityPolicy.VOLATILE)


def recording_qos(endpoints, depth: int = 10000) -> QoSProfile:
    """What the recorder subscribes with: ``subscription_qos``, and keep-all when reliable
    (a full queue is not acknowledged, so a reliable keep-all publisher waits for the
    recorder and a keep-last one's loss shows as a hole in its sequence numbers)."""
    qos = subscription_qos(endpoints, depth)
    if qos.reliability == ReliabilityPolicy.RELIABLE:
        qos.history = HistoryPolicy.KEEP_ALL
    return qos


def declare_params(node, params) -> dict:
    """``node_main.declare_params`` (which coerces the overrides itself)."""
    from irb_description.node_main import declare_params as declare
    return declare(node, params)


def default_bag_root() -> Path:
    """$IRB_ROOT/bags (scripts/env.sh sets IRB_ROOT), else ./bags."""
    root = os.environ.get('IRB_ROOT')
    return Path(root) / 'bags' if root else Path.cwd() / 'bags'


def take_waiting(sub, handle, limit: int = 10_000) -> int:
    """Hand every message already waiting in ``sub``'s queue to ``handle`` (called from
    ``sub``'s own callback); returns how many. rclpy's executor rebuilds its wait set for each
    message it dispatches: on the 2-vCPU VM a subscriber with one callback per message took
    ~530 messages/s from a reliable keep-all replay, which waits for it (the main job's 70,022
    joint states: 163 s). Taking the rest of the queue in the callback, as the executor itself
    takes one (``Subscription.handle.take_message``), took the same 70,022 in 3.7 s. ``limit``
    bounds one callback, so timers and services still run in between."""
    from rclpy.exceptions import InvalidHandle
    n = 0
    try:
        with sub.handle:
            while n < limit:
                got = sub.handle.take_message(sub.msg_type, sub.raw)
                if got is None:
                    break
                handle(got[0])
                n += 1
    except InvalidHandle:          # destroyed meanwhile (shutdown): nothing left to take
        pass
    return n
