"""rosbag2-layout MCAP bags: crash-safe split writer, recovery, readers. No rclpy.

Bag layout (the rosbag2 directory layout, storage ``mcap``, metadata version 9)::

    <root>/<name>/
      metadata.yaml              rewritten atomically (tmp + rename) after every closed split
      <name>_0.mcap              closed split files: chunked MCAP with CRCs, summary, index
      <name>_1.mcap
      <name>_2.mcap.active       the split being written; renamed to .mcap when it closes

Crash safety: a split is closed (footer, summary, CRCs) every ``split_period_s`` (2 s), so a
writer killed by SIGKILL loses at most the open split; ``metadata.yaml`` always lists only
closed, complete files, so ``ros2 bag info/play``, rosbags and any MCAP reader open what is on
disk. ``recover_bag`` additionally salvages the complete chunks of a left-over ``.active`` file
(written every ``flush``) and rebuilds ``metadata.yaml`` from the MCAP files (a reindex).

Messages are stored as the raw CDR bytes received from the middleware (serialization ``cdr``),
with the message definition (``ros2msg``) and RIHS01 type hash of each topic, as rosbag2 does.
"""
from __future__ import annotations

import fcntl
import os
import re
import struct
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Iterator

import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

ROS_DISTRO = 'jazzy'
METADATA_VERSION = 9
ACTIVE_SUFFIX = '.active'
LOCK_NAME = '.recording.lock'     # flock held by a live writer; released by the OS on kill
_NS = 1_000_000_000


class BagError(RuntimeError):
    """A bag is missing, incomplete, corrupt, or lacks what was asked of it."""


class BagExistsError(BagError):
    """The target bag directory exists already (the writer never overwrites)."""


# --- QoS and message definitions -------------------------------------------------------------
def qos_profile_dict(reliability: str = 'reliable', durability: str = 'volatile',
                     depth: int = 10, history: str = 'keep_last') -> dict:
    """One offered QoS profile in the metadata-v9 form (strings as rosbag2 writes them)."""
    zero = {'sec': 0, 'nsec': 0}
    return {'history': history, 'depth': int(depth), 'reliability': reliability,
            'durability': durability, 'deadline': dict(zero), 'lifespan': dict(zero),
            'liveliness': 'automatic', 'liveliness_lease_duration': dict(zero),
            'avoid_ros_namespace_conventions': False}


_BUILTIN = {'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
            'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring', 'time', 'duration'}


def _msg_file(msgtype: str) -> Path | None:
    pkg, _, name = msgtype.split('/')
    prefixes = os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)
    for prefix in filter(None, prefixes):
        path = Path(prefix) / 'share' / pkg / 'msg' / f'{name}.msg'
        if path.is_file():
            return path
    return None


def _register_msg(store, msgtype: str) -> None:
    """Register ``msgtype`` and its dependencies from .msg files found via AMENT_PREFIX_PATH."""
    from rosbags.typesys import get_types_from_msg
    if msgtype in store.fielddefs:
        return
    path = _msg_file(msgtype)
    if path is None:
        raise BagError(f'message type {msgtype}: not in the Jazzy type store and no '
                       f'share/.../msg file on AMENT_PREFIX_PATH')
    text = path.read_text()
    pkg = msgtype.split('/')[0]
    for line in text.splitlines():
        line = line.split('#', 1)[0].strip()
        if not line:
            continue
        base = re.sub(r'(\[.*\]|<=\d+)$', '', line.split()[0])
        if base in _BUILTIN or base.startswith(('string<=', 'wstring<=')):
            continue
        if '/' in base:
            dep_pkg, dep = base.split('/')[0], base.split('/')[-1]
        else:
            dep_pkg, dep = pkg, base
        dep_type = f'{dep_pkg}/msg/{dep}'
        if dep_type != msgtype and dep_type not in store.fielddefs:
            _register_msg(store, dep_type)
    store.register(get_types_from_msg(text, msgtype))


_STORE = None


def typestore(msgtypes: Iterable[str] = ()):
    """The rosbags Jazzy type store, extended with ``msgtypes`` read from .msg files."""
    global _STORE
    from rosbags.typesys import Stores, get_typestore
    if _STORE is None:
        _STORE = get_typestore(Stores.ROS2_JAZZY)
    for t in msgtypes:
        _register_msg(_STORE, t)
    return _STORE


def message_definition(msgtype: str) -> tuple[str, str]:
    """(concatenated ros2msg definition, RIHS01 hash) of e.g. 'sensor_msgs/msg/JointState'."""
    store = typestore([msgtype])
    msgdef, _ = store.generate_msgdef(msgtype, ros_version=2)
    return msgdef, store.hash_rihs01(msgtype)


@dataclass(frozen=True)
class TopicInfo:
    """A recorded topic: name, type, definition, type hash and offered QoS profiles."""

    name: str
    msgtype: str
    msgdef: str
    type_hash: str
    qos: tuple[dict, ...] = ()
    serialization_format: str = 'cdr'

    @classmethod
    def for_type(cls, name: str, msgtype: str, qos: Iterable[dict] = (),
                 type_hash: str | None = None) -> 'TopicInfo':
        """Definition and hash looked up from the type store / .msg files."""
        msgdef, rihs01 = message_definition(msgtype)
        return cls(name, msgtype, msgdef, type_hash or rihs01, tuple(qos))


# --- metadata.yaml -----------------------------------------------------------------------------
@dataclass
class FileStats:
    """One closed split file: relative path, first/last log time [ns], message count."""

    path: str
    start_ns: int
    end_ns: int
    count: int


def metadata_dict(files: list[FileStats], topics: list[TopicInfo], counts: dict[str, int],
                  custom_data: dict[str, str] | None = None) -> dict:
    """The rosbag2 metadata (version 9) of a bag made of ``files`` (closed, in order)."""
    start = min((f.start_ns for f in files if f.count), default=0)
    end = max((f.end_ns for f in files if f.count), default=0)
    return {'rosbag2_bagfile_information': {
        'version': METADATA_VERSION,
        'storage_identifier': 'mcap',
        'duration': {'nanoseconds': max(0, end - start)},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': sum(f.count for f in files),
        'topics_with_message_count': [
            {'topic_metadata': {'name': t.name, 'type': t.msgtype,
                                'serialization_format': t.serialization_format,
                                'offered_qos_profiles': [dict(q) for q in t.qos],
                                'type_description_hash': t.type_hash},
             'message_count': int(counts.get(t.name, 0))} for t in topics],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [f.path for f in files],
        'files': [{'path': f.path,
                   'starting_time': {'nanoseconds_since_epoch': f.start_ns},
                   'duration': {'nanoseconds': max(0, f.end_ns - f.start_ns)},
                   'message_count': f.count} for f in files],
        'custom_data': dict(custom_data or {}),
        'ros_distro': ROS_DISTRO,
    }}


def write_metadata(bag: Path, meta: dict) -> None:
    """Write ``metadata.yaml`` atomically (tmp file, fsync, rename); on failure (a full disk)
    the old file stays and no tmp file is left."""
    tmp = bag / 'metadata.yaml.tmp'
    try:
        with open(tmp, 'w') as f:
            yaml.safe_dump(meta, f, sort_keys=False)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, bag / 'metadata.yaml')
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


# --- writer -----------------------------------------------------------------------------------
class _Split:
    """One open MCAP split file."""

    def __init__(self, path: Path, topics: list[TopicInfo], chunk_size: int, compression: str,
                 opened_at: float):
        self.final = path
        self.active = path.with_name(path.name + ACTIVE_SUFFIX)
        self.stream = open(self.active, 'xb')
        comp = CompressionType.ZSTD if compression == 'zstd' else CompressionType.NONE
        self.mcap = McapWriter(self.stream, chunk_size=chunk_size, compression=comp,
                               enable_crcs=True, enable_data_crcs=True)
        self.mcap.start(profile='ros2', library='irb_identification')
        self.channels: dict[str, int] = {}
        self.schemas: dict[str, int] = {}
        self.opened_at = opened_at
        self.stats = FileStats(path.name, 0, 0, 0)
        for t in topics:
            self.add_topic(t)

    def add_topic(self, t: TopicInfo) -> None:
        if t.msgtype not in self.schemas:
            self.schemas[t.msgtype] = self.mcap.register_schema(
                t.msgtype, 'ros2msg', t.msgdef.encode())
        self.channels[t.name] = self.mcap.register_channel(
            t.name, t.serialization_format, self.schemas[t.msgtype],
            {'offered_qos_profiles': yaml.safe_dump([dict(q) for q in t.qos]),
             'topic_type_hash': t.type_hash})

    def write(self, topic: str, t_ns: int, data: bytes) -> None:
        s = self.stats
        if s.count == 0:
            s.start_ns = s.end_ns = t_ns
        s.start_ns, s.end_ns = min(s.start_ns, t_ns), max(s.end_ns, t_ns)
        s.count += 1
        self.mcap.add_message(self.channels[topic], t_ns, data, t_ns)

    def flush(self) -> None:
        self.mcap.flush()

    def close(self, serialized_metadata: str) -> FileStats:
        self.mcap.add_metadata('rosbag2', {'serialized_metadata': serialized_metadata,
                                           'ROS_DISTRO': ROS_DISTRO})
        self.mcap.finish()
        self.stream.flush()
        os.fsync(self.stream.fileno())
        self.stream.close()
        os.replace(self.active, self.final)
        return self.stats


class BagWriteError(BagError):
    """Writing the bag failed (typically a full disk); the message names the bag, what is kept
    and why. The writer is then ``failed``: further writes are refused, ``close`` keeps the
    closed splits listed and leaves the open one for ``recover_bag``."""


class BagWriter:
    """Crash-safe rosbag2 MCAP writer that splits every ``split_period_s`` of wall time.

    ``write(topic, t_ns, data)`` takes raw CDR bytes and a log time [ns]. Call ``maybe_split``
    periodically (the recorder does, from a timer) so that a quiet bag still closes its split;
    ``write`` calls it too. ``close`` finishes the last split. Never overwrites: the bag
    directory must not exist (``BagExistsError``). An OSError while writing (a full disk)
    becomes one ``BagWriteError``; see there.
    """

    def __init__(self, path: str | Path, split_period_s: float = 2.0,
                 chunk_size: int = 64 * 1024, compression: str = 'none',
                 clock: Callable[[], float] = time.monotonic,
                 custom_data: dict[str, str] | None = None):
        self.path = Path(path)
        if self.path.exists():
            raise BagExistsError(f'bag {self.path} exists already, not overwriting')
        if compression not in ('none', 'zstd'):
            raise ValueError(f"compression must be 'none' or 'zstd', not {compression!r}")
        if split_period_s <= 0:
            raise ValueError('split_period_s must be > 0')
        self.path.mkdir(parents=True)
        self._lock = open(self.path / LOCK_NAME, 'w')
        fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        self._lock.write(f'{os.getpid()}\n')
        self._lock.flush()
        self.split_period_s = float(split_period_s)
        self.chunk_size = int(chunk_size)
        self.compression = compression
        self.clock = clock
        self.custom_data = dict(custom_data or {})
        self.topics: dict[str, TopicInfo] = {}
        self.counts: dict[str, int] = {}
        self.files: list[FileStats] = []
        self.bytes_written = 0
        self._split: _Split | None = None
        self._index = 0
        self._closed = False
        self.failed = ''               # why writing stopped ('' = it did not)
        write_metadata(self.path, self._metadata())

    @property
    def message_count(self) -> int:
        return sum(self.counts.values())

    def add_topic(self, topic: TopicInfo) -> None:
        """Register a topic (before or between writes)."""
        if topic.name in self.topics:
            raise BagError(f'topic {topic.name} registered twice')
        self.topics[topic.name] = topic
        self.counts[topic.name] = 0
        if self._split is not None:
            self._split.add_topic(topic)

    def write(self, topic: str, t_ns: int, data: bytes) -> None:
        """Append one serialized message with log time ``t_ns`` [ns]."""
        if self._closed:
            raise BagError(f'bag {self.path} is closed')
        if self.failed:
            raise BagWriteError(self.failed)
        if topic not in self.topics:
            raise BagError(f'topic {topic} not registered')
        with self._guard():
            self.maybe_split()
            if self._split is None:
                self._split = _Split(self.path / f'{self.path.name}_{self._index}.mcap',
                                     list(self.topics.values()), self.chunk_size,
                                     self.compression, self.clock())
                self._index += 1
            self._split.write(topic, int(t_ns), data)
        self.counts[topic] += 1
        self.bytes_written += len(data)

    def _guard(self):
        """OSError (e.g. ENOSPC) -> BagWriteError once, the writer marked failed."""
        writer = self

        class _Guard:
            def __enter__(self):
                return self

            def __exit__(self, typ, exc, tb):
                if typ is not None and issubclass(typ, OSError) and not writer.failed:
                    kept = sum(f.count for f in writer.files)
                    writer.failed = (f'bag {writer.path}: writing failed '
                                     f'({exc.strerror or exc}); {len(writer.files)} closed '
                                     f'split(s) with {kept} messages are kept, the open split '
                                     'is left for recovery (the next recorder start in this '
                                     'root salvages it)')
                    raise BagWriteError(writer.failed) from None
                return False
        return _Guard()

    def maybe_split(self) -> bool:
        """Close the open split if it is older than ``split_period_s``; True if it did."""
        if self._split is None or self.clock() - self._split.opened_at < self.split_period_s:
            return False
        with self._guard():
            self._close_split()
        return True

    def flush(self) -> None:
        """Write the open chunk to disk (``recover_bag`` can salvage flushed chunks)."""
        if self._split is not None and not self.failed:
            with self._guard():
                self._split.flush()

    def close(self) -> None:
        """Close the last split and write the final metadata.yaml. After a failure the open
        split is left as ``.active`` for ``recover_bag`` (never an exception here)."""
        if self._closed:
            return
        if self._split is not None and not self.failed:
            try:
                with self._guard():
                    self._close_split()
            except BagWriteError:
                pass
        if self._split is not None:
            try:
                self._split.stream.close()
            except OSError:
                pass
            self._split = None
        self._closed = True
        (self.path / LOCK_NAME).unlink(missing_ok=True)
        self._lock.close()

    def _metadata(self, extra: FileStats | None = None) -> dict:
        files = self.files + ([extra] if extra else [])
        counts = self.counts
        return metadata_dict(files, list(self.topics.values()), counts, self.custom_data)

    def _close_split(self) -> None:
        split, self._split = self._split, None
        meta = self._metadata(split.stats)['rosbag2_bagfile_information']
        self.files.append(split.close(yaml.safe_dump(meta, sort_keys=False)))
        # counts of topics include only messages in closed files from here on
        write_metadata(self.path, self._metadata())

    def __enter__(self) -> 'BagWriter':
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# --- recovery ---------------------------------------------------------------------------------
@dataclass
class RecoveryReport:
    """What ``recover_bag`` did: salvaged files and messages, dropped bytes, problems."""

    salvaged_files: list[str] = field(default_factory=list)
    salvaged_messages: int = 0
    metadata_rebuilt: bool = False
    problems: list[str] = field(default_factory=list)


def _salvage(active: Path) -> tuple[list[Schema], list[Channel], list[Message], str | None]:
    """Records of a truncated MCAP file up to the first incomplete or corrupt record."""
    schemas, channels, messages, problem = [], [], [], None
    try:
        with open(active, 'rb') as f:
            reader = StreamReader(f, emit_chunks=True, validate_crcs=True)
            for rec in reader.records:
                recs = breakup_chunk(rec, validate_crc=True) if isinstance(rec, Chunk) else [rec]
                for r in recs:
                    if isinstance(r, Schema):
                        schemas.append(r)
                    elif isinstance(r, Channel):
                        channels.append(r)
                    elif isinstance(r, Message):
                        messages.append(r)
    except (McapError, ValueError, EOFError, OSError, struct.error) as exc:
        problem = f'{active.name}: stopped at {type(exc).__name__}: {exc}'
    return schemas, channels, messages, problem


def _file_stats(path: Path) -> tuple[FileStats, list[TopicInfo], dict[str, int]]:
    with open(path, 'rb') as f:
        summary = make_reader(f, validate_crcs=True).get_summary()
    if summary is None:
        raise BagError(f'{path.name}: no summary section')
    st = summary.statistics
    topics, counts = [], {}
    for cid, ch in summary.channels.items():
        sc = summary.schemas[ch.schema_id]
        qos = tuple(yaml.safe_load(ch.metadata.get('offered_qos_profiles', '[]')) or [])
        topics.append(TopicInfo(ch.topic, sc.name, sc.data.decode(),
                                ch.metadata.get('topic_type_hash', ''), qos,
                                ch.message_encoding))
        counts[ch.topic] = counts.get(ch.topic, 0) + st.channel_message_counts.get(cid, 0)
    return (FileStats(path.name, st.message_start_time, st.message_end_time, st.message_count),
            topics, counts)


def recover_bag(path: str | Path) -> RecoveryReport:
    """Make a bag left by a killed writer complete: salvage ``.active`` splits, reindex.

    Every complete record of an ``.active`` split (flushed chunks, CRC-checked) is rewritten
    into a closed ``.mcap`` file; then ``metadata.yaml`` is rebuilt from all ``.mcap`` files
    of the directory. Idempotent; a bag that needs nothing is left untouched.
    """
    bag = Path(path)
    if not bag.is_dir():
        raise BagError(f'bag {bag} does not exist')
    if bag_in_use(bag):
        raise BagError(f'bag {bag} is being recorded right now; not recovering it')
    report = RecoveryReport()
    (bag / LOCK_NAME).unlink(missing_ok=True)
    for tmp in bag.glob('*.tmp'):            # half-written by an earlier failed attempt
        tmp.unlink()
    for active in sorted(bag.glob(f'*.mcap{ACTIVE_SUFFIX}')):
        schemas, channels, messages, problem = _salvage(active)
        if problem:
            report.problems.append(problem)
        final = active.with_name(active.name[:-len(ACTIVE_SUFFIX)])
        if messages and channels:
            tmp = final.with_name(final.name + '.tmp')
            try:
                _write_salvaged(tmp, schemas, channels, messages)
            except OSError as exc:
                tmp.unlink(missing_ok=True)
                report.problems.append(f'{active.name}: not recovered, writing failed '
                                       f'({exc.strerror or exc}); left as it is for a later '
                                       'attempt')
                continue
            os.replace(tmp, final)
            report.salvaged_files.append(final.name)
            report.salvaged_messages += len(messages)
        active.unlink()
    meta_path = bag / 'metadata.yaml'
    listed = set()
    if meta_path.is_file():
        try:
            info = yaml.safe_load(meta_path.read_text())['rosbag2_bagfile_information']
            listed = set(info.get('relative_file_paths') or [])
        except (yaml.YAMLError, KeyError, TypeError):
            listed = None
    on_disk = sorted(bag.glob('*.mcap'), key=_split_index)
    if listed is None or listed != {p.name for p in on_disk} or report.salvaged_files:
        files, topics, counts = [], {}, {}
        for p in on_disk:
            try:
                fs, tps, cnt = _file_stats(p)
            except (BagError, McapError, ValueError, OSError) as exc:
                report.problems.append(f'{p.name}: unreadable, left out ({exc})')
                continue
            files.append(fs)
            for t in tps:
                topics.setdefault(t.name, t)
            for k, v in cnt.items():
                counts[k] = counts.get(k, 0) + v
        try:
            write_metadata(bag, metadata_dict(files, list(topics.values()), counts))
        except OSError as exc:
            report.problems.append(f'metadata.yaml not rebuilt ({exc.strerror or exc})')
            return report
        report.metadata_rebuilt = True
    return report


def _write_salvaged(tmp: Path, schemas, channels, messages) -> None:
    """The salvaged records as a closed, CRC-checked MCAP file ``tmp``."""
    with open(tmp, 'wb') as f:
        w = McapWriter(f, compression=CompressionType.NONE, enable_data_crcs=True)
        w.start(profile='ros2', library='irb_identification recover')
        for s in schemas:
            w.register_schema(s.name, s.encoding, s.data)
        ids = {}
        by_schema = {s.id: i for i, s in enumerate(schemas, start=1)}
        for c in channels:
            ids[c.id] = w.register_channel(c.topic, c.message_encoding,
                                           by_schema.get(c.schema_id, 0), c.metadata)
        for m in messages:
            if m.channel_id in ids:
                w.add_message(ids[m.channel_id], m.log_time, m.data, m.publish_time,
                              m.sequence)
        w.finish()
        f.flush()
        os.fsync(f.fileno())


def _split_index(p: Path) -> tuple[int, str]:
    m = re.search(r'_(\d+)\.mcap$', p.name)
    return (int(m.group(1)) if m else -1, p.name)


def bag_in_use(path: str | Path) -> bool:
    """True while a live BagWriter (any process) holds the bag's lock."""
    lock = Path(path) / LOCK_NAME
    if not lock.is_file():
        return False
    with open(lock) as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        fcntl.flock(f, fcntl.LOCK_UN)
    return False


def needs_recovery(path: str | Path) -> bool:
    """True if the bag is not being written and has a left-over ``.active`` split or no
    metadata.yaml."""
    bag = Path(path)
    if bag_in_use(bag):
        return False
    return bool(list(bag.glob(f'*.mcap{ACTIVE_SUFFIX}'))) or not (bag / 'metadata.yaml').is_file()


# --- reading ----------------------------------------------------------------------------------
@dataclass
class TopicMessages:
    """Raw messages of one topic: log times [ns] (N,) and CDR payloads (N,)."""

    topic: str
    msgtype: str
    t_ns: list[int]
    data: list[bytes]


def _open_reader(path: Path):
    from rosbags.rosbag2 import Reader
    from rosbags.rosbag2.errors import ReaderError
    if not path.exists():
        raise BagError(f'bag {path} does not exist')
    if path.is_dir() and not (path / 'metadata.yaml').is_file():
        hint = (' (left by a killed recorder: start a recorder with this root and '
                'recover_on_start:=true, its default, or call irb_identification.bagio.'
                'recover_bag)' if needs_recovery(path) else '')
        raise BagError(f'bag {path}: no metadata.yaml{hint}')
    try:
        reader = Reader(path)
        reader.open()
    except (ReaderError, OSError, ValueError, KeyError, yaml.YAMLError) as exc:
        raise BagError(f'bag {path}: cannot open ({type(exc).__name__}: {exc})') from exc
    except Exception as exc:  # rosbags raises assorted errors on corrupt files
        raise BagError(f'bag {path}: corrupt or truncated ({type(exc).__name__}: {exc})'
                       ) from exc
    return reader


def bag_topics(path: str | Path) -> dict[str, str]:
    """{topic: msgtype} of a bag."""
    reader = _open_reader(Path(path))
    try:
        return {c.topic: c.msgtype for c in reader.connections}
    finally:
        reader.close()


def read_messages(path: str | Path, topics: Iterable[str] | None = None
                  ) -> dict[str, TopicMessages]:
    """Raw messages of ``topics`` (all if None) in log-time order.

    Raises BagError naming the problem: missing bag/metadata, corrupt or truncated file,
    or a requested topic that is not in the bag.
    """
    path = Path(path)
    reader = _open_reader(path)
    try:
        conns = reader.connections
        present = {c.topic for c in conns}
        wanted = set(present if topics is None else topics)
        missing = sorted(wanted - present)
        if missing:
            raise BagError(f'bag {path}: topic(s) {missing} not recorded '
                           f'(bag has {sorted(present)})')
        out = {c.topic: TopicMessages(c.topic, c.msgtype, [], []) for c in conns
               if c.topic in wanted}
        sel = [c for c in conns if c.topic in wanted]
        try:
            for conn, t, raw in reader.messages(connections=sel):
                m = out[conn.topic]
                m.t_ns.append(t)
                m.data.append(bytes(raw))
        except BagError:
            raise
        except Exception as exc:
            raise BagError(f'bag {path}: corrupt or truncated while reading '
                           f'({type(exc).__name__}: {exc})') from exc
        return out
    finally:
        reader.close()


def verify_bag(path: str | Path) -> int:
    """Read every split file of a bag with CRC validation (chunks and data sections, the
    mcap library's own reader); the number of messages, or BagError naming the file and the
    damage. rosbags' reader does not check CRCs: a bag with a damaged chunk played as if
    nothing were wrong."""
    bag = Path(path)
    try:
        info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
        files = list(info['relative_file_paths'])
    except (OSError, yaml.YAMLError, KeyError, TypeError) as exc:
        raise BagError(f'bag {bag}: unreadable metadata.yaml ({type(exc).__name__})') from None
    count = 0
    for rel in files:
        try:
            with open(bag / rel, 'rb') as f:
                for rec in StreamReader(f, emit_chunks=True, validate_crcs=True).records:
                    for r in (breakup_chunk(rec, validate_crc=True) if isinstance(rec, Chunk)
                              else [rec]):
                        count += isinstance(r, Message)
        except (McapError, ValueError, EOFError, OSError, struct.error) as exc:
            raise BagError(f'bag {bag}: {rel} is damaged ({type(exc).__name__}: {exc})') \
                from None
    return count


def iter_messages(path: str | Path) -> Iterator[tuple[str, str, int, bytes]]:
    """(topic, msgtype, log time [ns], CDR bytes) of every message in log-time order."""
    reader = _open_reader(Path(path))
    try:
        for conn, t, raw in reader.messages():
            yield conn.topic, conn.msgtype, t, bytes(raw)
    finally:
        reader.close()


def bag_info(path: str | Path) -> dict:
    """Summary like ``ros2 bag info``: duration [s], counts, topics with types and counts."""
    reader = _open_reader(Path(path))
    try:
        return {'path': str(path), 'duration_s': reader.duration / _NS,
                'start_ns': reader.start_time, 'message_count': reader.message_count,
                'topics': {c.topic: {'type': c.msgtype, 'count': c.msgcount}
                           for c in reader.connections}}
    finally:
        reader.close()


def topic_qos(path: str | Path) -> dict[str, list[dict]]:
    """{topic: offered QoS profiles} from a bag's metadata.yaml (v9 lists or v8 strings)."""
    bag = Path(path)
    try:
        info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    except (OSError, yaml.YAMLError, KeyError, TypeError) as exc:
        raise BagError(f'bag {bag}: unreadable metadata.yaml ({exc})') from exc
    out = {}
    for entry in info.get('topics_with_message_count') or []:
        tm = entry['topic_metadata']
        qos = tm.get('offered_qos_profiles') or []
        if isinstance(qos, str):
            qos = yaml.safe_load(qos) or []
        out[tm['name']] = [q for q in qos if isinstance(q, dict)]
    return out


def serialize(msgtype: str, msg) -> bytes:
    """CDR bytes of a rosbags message object (tests and offline tools)."""
    return bytes(typestore([msgtype]).serialize_cdr(msg, msgtype))


def deserialize(msgtype: str, data: bytes):
    """A rosbags message object from CDR bytes."""
    return typestore([msgtype]).deserialize_cdr(data, msgtype)


__all__ = ['BagError', 'BagExistsError', 'BagWriter', 'FileStats', 'bag_in_use', 'RecoveryReport',
           'TopicInfo', 'TopicMessages', 'bag_info', 'bag_topics', 'deserialize',
           'iter_messages', 'message_definition', 'metadata_dict',
           'needs_recovery',
           'qos_profile_dict', 'read_messages', 'recover_bag', 'serialize', 'topic_qos',
           'typestore',
           'write_metadata']
