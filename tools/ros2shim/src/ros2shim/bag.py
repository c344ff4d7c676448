"""``ros2 bag info|play|record`` onto the project's bag tools.

``info`` reads the bag with rosbags (imported here, lazily); ``play`` and ``record`` run the
project's ``replay`` and ``recorder`` (``ros2 run irb_identification replay|recorder
--ros-args ...``) with the parameters that mean what ros2 bag's options mean.
"""

from __future__ import annotations

import os
from pathlib import Path

from . import fmt


class BagInfoError(Exception):
    """The bag cannot be summarised (one line)."""


def _metadata(bag: Path) -> dict:
    import yaml
    try:
        data = yaml.safe_load((bag / 'metadata.yaml').read_text())
        return data['rosbag2_bagfile_information']
    except FileNotFoundError:
        raise BagInfoError(
            f"bag '{bag}': no metadata.yaml (still being recorded, or left by a killed "
            'recorder: the recorder recovers it when it starts again in that folder)') from None
    except (OSError, yaml.YAMLError, KeyError, TypeError) as exc:
        raise BagInfoError(f"bag '{bag}': unreadable metadata.yaml ({exc})") from None


def bag_summary(path: str) -> dict:
    """The fields of ``fmt.format_bag_info`` for a bag directory or a single .mcap file,
    read with rosbags (the bag's files are opened, so a missing or damaged file is an
    error, not a silently wrong summary)."""
    try:
        from rosbags.rosbag2 import Reader
        from rosbags.rosbag2.errors import ReaderError
    except ImportError:
        raise BagInfoError('ros2 bag info needs the Python package rosbags') from None
    bag = Path(path)
    if not bag.exists():
        raise BagInfoError(f"bag '{path}' does not exist")
    meta = _metadata(bag) if bag.is_dir() else None
    try:
        reader = Reader(bag)
        reader.open()
    except (ReaderError, OSError, ValueError) as exc:
        raise BagInfoError(f"bag '{path}': {exc}") from None
    try:
        topics = sorted((c.topic, c.msgtype, c.msgcount,
                         getattr(c.ext, 'serialization_format', 'cdr'))
                        for c in reader.connections)
        count = reader.message_count
        if meta is not None:
            files = list(meta.get('relative_file_paths') or [])
            storage = meta.get('storage_identifier', '')
            start = int(meta['starting_time']['nanoseconds_since_epoch'])
            duration = int(meta['duration']['nanoseconds'])
            sizes = [bag / f for f in files]
        else:
            files, storage = [bag.name], bag.suffix.lstrip('.')
            start = reader.start_time if count else 0
            duration = max(reader.end_time - 1 - start, 0) if count else 0
            sizes = [bag]
        return {'files': files, 'storage_id': storage,
                'size_bytes': sum(p.stat().st_size for p in sizes if p.exists()),
                'ros_distro': reader.ros_distro, 'duration_ns': duration, 'start_ns': start,
                'end_ns': start + duration, 'message_count': count, 'topics': topics}
    finally:
        reader.close()


def info(args) -> int:
    print(fmt.format_bag_info(bag_summary(args.bag_path)))
    return 0


def record_command(args, cwd: str, all_topics=None) -> list:
    """The ``ros2 run`` arguments of the recorder for ``ros2 bag record``."""
    topics = list(args.topics or []) + list(args.topics_opt or [])
    if args.all:
        topics = list(all_topics or [])
    return ['irb_identification', 'recorder', *fmt.record_ros_args(topics, args.output, cwd)]


def play_command(args, cwd: str) -> list:
    """The ``ros2 run`` arguments of the replay for ``ros2 bag play``."""
    return ['irb_identification', 'replay', *fmt.play_ros_args(
        args.bag_path, cwd, rate=args.rate, clock=args.clock or None, topics=args.topics,
        delay=args.delay)]


def discover_topics(spin_time: float) -> list:
    """Every topic on the graph now (``ros2 bag record -a``): the recorder records a fixed
    list, so a topic that appears later is not recorded."""
    from .graph import Session
    with Session() as s:
        found = s.wait_graph(s.node.get_topic_names_and_types, timeout=spin_time)
    return sorted(name for name, _ in found if not fmt.is_hidden(name))


def cwd() -> str:
    return os.getcwd()
