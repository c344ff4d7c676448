"""Which bags and topics the offline tools read, and the quantity each topic carries. No rclpy.

The project records bags in three shapes, and every reader accepts all of them:

* one bag from ``recorder`` (default topics /joint_states, /torque_command, /controller_state,
  /camera/tcp, ...);
* the main job's run bags ``bags/<id>_<run>`` (/joint_states, /controller_state, /camera/tcp)
  with the drive side in the companion ``bags/<id>_<run>_drive`` (/torque_command,
  /electrical_power): a topic missing in one is read from the other;
* an ``excite`` output folder: a directory of bags (``excite_00_...``), expanded to them.

Measured position, velocity and effort (the applied torque) come from /joint_states; the
commanded torque from /torque_command (a JointState with effort only). Errors name the bag,
the topic and what is missing (``BagError``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .bagio import BagError, TopicMessages, bag_topics, read_messages
from .gaps import GapConfig, SeriesCheck, check_series
from .series import FIELDS, JOINT_STATE, JointSeries, JointStateError, decode_joint_states

COMPANION_SUFFIX = '_drive'
STATE_TOPIC = '/joint_states'
COMMAND_TOPIC = '/torque_command'
#: what each topic is read for (error messages)
QUANTITY = {STATE_TOPIC: 'measured position, velocity and effort',
            COMMAND_TOPIC: 'commanded torque (effort only)'}


def is_bag(path: Path) -> bool:
    return path.is_dir() and (path / 'metadata.yaml').is_file()


def expand_bags(paths) -> list[Path]:
    """Bag directories of ``paths``: a bag stays; a folder of bags (excite's output, or a
    ``bags/`` root) becomes its bags in name order, without companions (``X_drive`` beside
    ``X``: read through ``X``). Anything else is returned as it is (the reader's error then
    names it)."""
    out = []
    for p in map(Path, paths):
        if is_bag(p) or not p.is_dir() or list(p.glob('*.mcap*')):
            out.append(p)
            continue
        inner = sorted(c for c in p.iterdir() if is_bag(c))
        names = {c.name for c in inner}
        inner = [c for c in inner if not (c.name.endswith(COMPANION_SUFFIX)
                                          and c.name[:-len(COMPANION_SUFFIX)] in names)]
        out.extend(inner or [p])
    return out


def not_a_bag(path: Path) -> str | None:
    """Why ``path`` is not a bag a reader can open (None if it may be one): a directory with
    neither metadata.yaml, nor split files, nor bags inside is named as such instead of as
    'left by a killed recorder'."""
    if not path.exists():
        return f'bag {path} does not exist'
    if path.is_dir() and not is_bag(path) and not list(path.glob('*.mcap*')):
        return (f'{path} is not a bag (no metadata.yaml, no .mcap files) and holds no bags')
    return None


def companion(bag: Path) -> Path | None:
    """The other half of a main-job run: ``X_drive`` for ``X`` and ``X`` for ``X_drive``."""
    bag = Path(bag)
    other = (bag.with_name(bag.name[:-len(COMPANION_SUFFIX)])
             if bag.name.endswith(COMPANION_SUFFIX)
             else bag.with_name(bag.name + COMPANION_SUFFIX))
    return other if is_bag(other) else None


def topic_sources(bag) -> dict[str, tuple[Path, str]]:
    """{topic: (bag holding it, msgtype)} of a bag and its companion (the bag first)."""
    bag = Path(bag)
    why = not_a_bag(bag)
    if why:
        raise BagError(why)
    out = {t: (bag, m) for t, m in bag_topics(bag).items()}
    other = companion(bag)
    if other is not None:
        for t, m in bag_topics(other).items():
            out.setdefault(t, (other, m))
    return out


def read_topics(bag, topics, optional=()) -> tuple[dict[str, TopicMessages], dict[str, Path]]:
    """Messages of ``topics`` (required) and ``optional`` topics (if present) from the bag or
    its companion; ({topic: messages}, {topic: bag it came from}). BagError names the bag,
    the topic, what it is read for and the topics there are."""
    bag = Path(bag)
    src = topic_sources(bag)
    for t in topics:
        if t not in src:
            other = companion(bag)
            where = f'{bag}' + (f' or {other}' if other else '')
            raise BagError(f'bag {where}: no {t} (needed for the '
                           f'{QUANTITY.get(t, "data")}); topics: {", ".join(sorted(src))}')
    wanted = [t for t in list(topics) + list(optional) if t in src]
    by_bag: dict[Path, list[str]] = {}
    for t in wanted:
        by_bag.setdefault(src[t][0], []).append(t)
    msgs = {}
    for b, ts in by_bag.items():
        msgs.update(read_messages(b, ts))
    return msgs, {t: src[t][0] for t in wanted}


def joint_series(msgs: TopicMessages, bag, require=FIELDS,
                 joints: list[str] | None = None, keep_locked: bool = False) -> JointSeries:
    """JointSeries of one JointState topic; errors name the bag, the topic and what it
    lacks. ``joints``: select these columns by name (others, e.g. locked joints 4-6, are
    dropped). ``keep_locked``: joints 4-6 stay even where they stood still (six joints)."""
    topic = msgs.topic
    if msgs.msgtype != JOINT_STATE:
        raise BagError(f'bag {bag}: {topic} is {msgs.msgtype}, not {JOINT_STATE}')
    if not msgs.data:
        raise BagError(f'bag {bag}: {topic} has no messages')
    try:
        s = decode_joint_states(msgs.data, msgs.t_ns, require, joints, keep_locked)
        return s.select(list(joints)) if joints else s
    except JointStateError as exc:
        what = QUANTITY.get(topic)
        raise BagError(f'bag {bag}: {topic}: {exc}' + (f' (read for the {what})' if what
                                                        else '')) from None


def read_joint_states(bag, topic: str = STATE_TOPIC, joints: list[str] | None = None,
                      keep_locked: bool = False) -> JointSeries:
    """Measured joint states (position, velocity, effort) of ``topic`` in a bag or its
    companion (``keep_locked``: joints 4-6 also where they stood still)."""
    msgs, src = read_topics(bag, [topic])
    return joint_series(msgs[topic], src[topic], FIELDS, joints, keep_locked)


def dedupe(series: JointSeries, keep: np.ndarray) -> JointSeries:
    """The series without the samples ``keep`` marks False (duplicates)."""
    if keep.all():
        return series
    return JointSeries(series.t[keep], series.names, series.position[keep],
                       series.velocity[keep], series.effort[keep])


def checked(series: JointSeries, bag, topic: str, config: GapConfig = GapConfig()
            ) -> tuple[JointSeries, SeriesCheck, list[tuple[int, int]]]:
    """(series without duplicates, its check, usable segments); GapError to refuse."""
    chk, keep, segs = check_series(series.t, str(bag), topic, config)
    return dedupe(series, keep), chk, segs


def stamps(msgs: TopicMessages) -> np.ndarray:
    """(N,) [s] times of a topic's messages: header stamps for a type whose first field is
    a std_msgs/Header (where non-zero), else the log times; sorted."""
    log = np.asarray(msgs.t_ns, np.int64)
    t = log.copy()
    has_header = False
    try:
        from .bagio import typestore
        fields = typestore([msgs.msgtype]).fielddefs[msgs.msgtype][1]
        has_header = bool(fields) and fields[0][0] == 'header'
    except Exception:  # noqa: BLE001 - an unknown type: log times
        has_header = False
    if has_header and msgs.data:
        head = np.frombuffer(b''.join(d[4:12] for d in msgs.data), np.uint8).reshape(-1, 8)
        sec = head[:, :4].copy().view('<i4')[:, 0].astype(np.int64)
        nsec = head[:, 4:].copy().view('<u4')[:, 0].astype(np.int64)
        st = sec * 1_000_000_000 + nsec
        t = np.where(st > 0, st, log)
    return np.sort(t) * 1e-9


def check_topic(bag, topic: str, config: GapConfig = GapConfig(),
                period_s: float | None = None) -> SeriesCheck:
    """Gaps and duplicates of any stamped topic of a bag (or its companion) against
    ``period_s`` (default config.period_s; the check uses the median step when it is far
    off, e.g. the camera's 100 Hz). GapError (one line) when config.on_gap is 'refuse' and
    there is a gap. For reports: ``.summary()``, ``.as_dict()``."""
    msgs, src = read_topics(bag, [topic])
    soft = config if config.on_gap == 'refuse' else GapConfig(
        **{**config.__dict__, 'min_segment_s': 0.0})
    chk, _, _ = check_series(stamps(msgs[topic]), str(src[topic]), topic, soft, period_s)
    return chk


def copy_bag(src, dst, keep=None, topics=None) -> Path:
    """A copy of bag ``src`` at ``dst`` (must not exist) with the messages of ``topics`` (all
    if None) that ``keep(topic, index in topic, log time [ns])`` accepts (all if None): to
    split a bag by topic or to make a lossy copy for tests."""
    from .bagio import BagWriter, TopicInfo, topic_qos
    msgs = read_messages(src, topics)
    qos = topic_qos(src)
    events = sorted((t, topic, i) for topic, m in msgs.items() for i, t in enumerate(m.t_ns))
    with BagWriter(dst, split_period_s=1e9) as w:
        for topic, m in msgs.items():
            w.add_topic(TopicInfo.for_type(topic, m.msgtype, qos.get(topic, [])))
        for t, topic, i in events:
            if keep is None or keep(topic, i, t):
                w.write(topic, t, msgs[topic].data[i])
    return Path(dst)


__all__ = ['COMMAND_TOPIC', 'STATE_TOPIC', 'check_topic', 'checked', 'companion', 'copy_bag',
           'dedupe', 'expand_bags', 'joint_series', 'not_a_bag', 'read_joint_states',
           'read_topics', 'stamps', 'topic_sources']
