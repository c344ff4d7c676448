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


def default_bag_root() -> Path:
    """$IRB_ROOT/bags (scripts/env.sh sets IRB_ROOT), else ./bags."""
    root = os.environ.get('IRB_ROOT')
    return Path(root) / 'bags' if root else Path.cwd() / 'bags'
