"""Identification from a stream of JointState messages (the `identifier` node's core). No rclpy.

``StreamIdentifier`` keeps the raw CDR payloads it is given (bounded: ``max_messages``; the
rest are counted as dropped), reads `replay`'s end-of-stream status (JSON, see
``replay_status``), decides when the stream is over (``due``: the replay finished and every
message it published arrived, or nothing came for ``quiet_period_s``) and ``compute`` runs the
same code path as the offline `identify` (vectorised decoding, pipeline.identify_joints,
friction_fit.friction_map) and writes the map and the JSON report. A stream that ended short
of what the replay announced (a replay killed midway, lost messages) gives no map unless
partial results are allowed; then the map's source and the report say ``partial``.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from irb_description.friction import FrictionMapError

from .friction_fit import IdentificationError, complete_map, complete_source, friction_map
from .pipeline import PipelineConfig, identify_joints, report_entry, summary_line
from .series import JointStateError, decode_joint_states


def replay_status(state: str, bag: str, topics: dict, published: dict | None = None,
                  reason: str = '', stream: str = '', segments: list | None = None) -> str:
    """The JSON text `replay` publishes on its status topic: ``state`` is playing, finished,
    stopped or failed; ``topics``: messages per topic in the bag (what will be played);
    ``published``: messages published so far; ``stream``: the id of this playback (each
    topic's messages carry the publisher's sequence numbers 1..N); ``segments``: when
    several bags are played as one stream, [{'bag': name, 'topics': {topic: count}}] in
    playing order, so a reader can tell where one bag ends and the next begins (the time
    between two bags is not a loss)."""
    return json.dumps({'state': state, 'bag': str(bag), 'topics': topics,
                       'published': published or {}, 'reason': reason, 'stream': stream,
                       'segments': segments or []})


def split_by_segments(n: int, segments: list, topic: str) -> list[tuple[str, int, int]]:
    """[(bag name, first, end)] index ranges of ``n`` messages of ``topic`` received in
    order, from the replay's ``segments``; [] when they do not add up to ``n`` (then the
    stream is read as one series)."""
    out, start = [], 0
    for seg in segments or []:
        try:
            count = int((seg.get('topics') or {}).get(topic, 0))
            name = Path(str(seg.get('bag', 'bag'))).name
        except (AttributeError, TypeError, ValueError):
            return []
        if count > 0:
            out.append((name, start, start + count))
        start += count
    return out if start == n and len(out) > 1 else []


@dataclass
class StreamConfig:
    """topic: the JointState topic (for the expected count); max_messages: memory bound;
    quiet_period_s [s]: no message for this long ends a stream (0 = only the replay's end
    signal or a service call); allow_partial: write a map from an incomplete stream (marked
    partial); torque_kind: friction or total; joints, name_map: as identify --joints,
    --map-joint; out_map, out_report: where to write; fill_nominal: failed model joints
    from the nominal map (as identify --fill-nominal); plots_dir: one figure per joint
    there ('' = none); complete_from: as identify --complete-from (MAP or 'nominal', '' =
    none)."""

    topic: str = '/joint_states'
    max_messages: int = 2_000_000
    quiet_period_s: float = 2.0
    allow_partial: bool = False
    torque_kind: str = 'total'
    joints: list = field(default_factory=list)
    name_map: dict = field(default_factory=dict)
    out_map: str = 'identified_friction_map.yaml'
    out_report: str = ''
    fill_nominal: bool = False
    plots_dir: str = ''
    pipeline: PipelineConfig = field(default_factory=PipelineConfig)
    complete_from: str = ''

    @property
    def six_joints(self) -> bool:
        """``joints`` names any of joint_4 .. joint_6: the six joints are read (also those
        that stood still) and the model is the six-joint one (six_joint.py)."""
        from .six_joint import uses_wrist
        return uses_wrist(self.joints)


@dataclass
class StreamOutcome:
    """What ``compute`` did: ok (a map was written), the map path, per-joint log lines, the
    error line (if no map), the report written."""

    ok: bool
    map_path: str
    lines: list
    error: str
    report: dict


class StreamIdentifier:
    def __init__(self, config: StreamConfig, model=None):
        self.config = config
        self.model = model
        self.reset()

    def reset(self) -> None:
        self.data: list[bytes] = []
        self.recv_ns: list[int] = []
        self.dropped = 0
        self.last_wall = None          # monotonic time [s] of the last message
        self.status: dict | None = None
        self.computed = False
        self.late = 0                  # messages of a stream already computed (not kept)
        self.seq_first = None          # the publisher's sequence numbers seen
        self.seq_last = None
        self.seq_gaps = 0              # numbers missing between first and last
        self.seq_disorder = 0          # numbers seen out of order or twice
        self._decoded: list = []       # JointSeries of the messages decoded so far (progress)
        self._n_decoded = 0

    # --- input ---------------------------------------------------------------------------
    def add(self, payload: bytes, recv_ns: int, wall_s: float, seq: int | None = None) -> None:
        """One message; ``seq``: its publisher's sequence number (DDS), if known."""
        if self.computed:
            if self.status is not None and seq != 1:
                # the rest of a replayed stream that ended already: never a new stream
                self.late += 1
                return
            self.reset()               # a new stream after a result: start over
        if len(self.data) >= self.config.max_messages:
            self.dropped += 1
        else:
            self.data.append(bytes(payload))
            self.recv_ns.append(int(recv_ns))
        self.last_wall = wall_s
        if seq:
            if self.seq_last is None:
                self.seq_first = self.seq_last = seq
            elif seq == self.seq_last + 1:
                self.seq_last = seq
            elif seq > self.seq_last + 1:
                self.seq_gaps += seq - self.seq_last - 1
                self.seq_last = seq
            else:
                self.seq_disorder += 1

    def on_status(self, text: str) -> None:
        try:
            st = json.loads(text)
        except json.JSONDecodeError:
            return
        if not isinstance(st, dict) or 'state' not in st:
            return
        old = (self.status or {}).get('stream')
        if st['state'] == 'playing' and st.get('stream') != old and (
                self.computed or (self.status is not None and old)):
            self.reset()               # a new playback
        self.status = st

    @property
    def received(self) -> int:
        return len(self.data) + self.dropped

    def expected(self) -> int | None:
        if not self.status:
            return None
        n = self.status.get('topics', {}).get(self.config.topic)
        return int(n) if n is not None else None

    def published(self) -> int | None:
        n = (self.status or {}).get('published', {}).get(self.config.topic)
        return int(n) if n is not None else None

    def due(self, wall_s: float, publishers: int | None = None) -> str | None:
        """Why the stream is over now ('finished', 'stopped', 'failed', 'quiet'), or None.

        After the replay's end status the stream is over once every message it published
        arrived. While the replay's publisher is still there (``publishers`` > 0: reliable
        delivery, it waits for our acknowledgements) nothing else ends it; once it is gone
        (0), or when unknown (None), ``quiet_period_s`` without a message ends it short."""
        if self.computed:
            return None
        st = (self.status or {}).get('state')
        if st == 'failed':
            return 'failed'
        quiet = (self.last_wall is not None and self.config.quiet_period_s > 0
                 and wall_s - self.last_wall >= self.config.quiet_period_s)
        if st in ('finished', 'stopped'):
            pub = self.published()
            target = pub if pub is not None else self.expected()
            if target is not None and self.received >= target:
                return st
            if publishers and publishers > 0:
                return None
            if quiet or self.last_wall is None:
                return st
            return None
        if quiet and not (st == 'playing' and publishers and publishers > 0):
            return 'quiet'
        return None

    def progress(self) -> str:
        exp = self.expected()
        return (f'{self.received} messages received' + (f' of {exp}' if exp else '')
                + (f' ({self.dropped} over max_messages, not kept)' if self.dropped else ''))

    def segment_progress(self) -> list[str]:
        """Constant-speed holds found so far, one line per joint: 'joint_3: 9 holds, |v| =
        0.02, 0.035, ... rad/s' (the sweep's segmentation, segments.find_segments, on what
        was received; the messages are decoded once, incrementally). [] when nothing (or
        nothing decodable) arrived; never raises."""
        from .pipeline import rename
        from .segments import find_segments
        from .series import JointSeries
        try:
            if self._n_decoded < len(self.data):
                new = decode_joint_states(self.data[self._n_decoded:],
                                          self.recv_ns[self._n_decoded:],
                                          keep_locked=self.config.six_joints)
                if self._decoded and new.names != self._decoded[0].names:
                    return []
                self._decoded.append(new)
                self._n_decoded = len(self.data)
            if not self._decoded:
                return []
            parts = self._decoded
            s = JointSeries(np.concatenate([p.t for p in parts]), parts[0].names,
                            *(np.concatenate([getattr(p, f) for p in parts])
                              for f in ('position', 'velocity', 'effort')))
        except (JointStateError, ValueError):
            return []
        s = rename(s, self.config.name_map)
        order = np.argsort(s.t, kind='stable')
        s = JointSeries(s.t[order], s.names, s.position[order], s.velocity[order],
                        s.effort[order])
        lines = []
        for j, name in enumerate(s.names):
            if self.config.joints and name not in self.config.joints:
                continue
            segs = find_segments(s, j, self.config.pipeline.fit.segments)
            speeds = sorted({float(f'{abs(g.speed):.2g}') for g in segs})
            lines.append(f'{name}: {len(segs)} holds' + (
                f", |v| = {', '.join(f'{v:g}' for v in speeds)} rad/s" if speeds else ''))
        return lines

    # --- result ----------------------------------------------------------------------------
    def compute(self, trigger: str, progress=None) -> StreamOutcome:
        """Identify from what was received; write map and report. Never raises for bad
        data: the outcome carries the one-line error."""
        cfg = self.config
        self.computed = True
        exp = self.expected()
        pub = self.published()
        st = (self.status or {}).get('state')
        seq_ok = (self.seq_first in (None, 1) and not self.seq_gaps and not self.seq_disorder
                  and (self.seq_last is None or self.seq_last == self.received))
        complete = (exp is not None and self.received == exp and st == 'finished'
                    and pub in (None, exp) and not self.dropped and seq_ok)
        stream = {'trigger': trigger, 'received': self.received, 'kept': len(self.data),
                  'dropped_over_max': self.dropped, 'expected': exp, 'published': pub,
                  'replay_state': st, 'replay_stream': (self.status or {}).get('stream'),
                  'bag': (self.status or {}).get('bag'), 'complete': complete,
                  'sequence': {'first': self.seq_first, 'last': self.seq_last,
                               'missing': self.seq_gaps, 'out_of_order': self.seq_disorder},
                  'partial': False}
        report = {'out': cfg.out_map, 'stream': stream, 'joints': {}, 'problems': [],
                  'ok': False}
        if st == 'failed':
            reason = (self.status or {}).get('reason') or 'no reason given'
            return self._fail(report, f'replay failed: {reason}; no map')
        why_partial = ''
        if not complete:
            if exp is None:
                why_partial = (f'no end-of-stream signal from replay (ended: {trigger}); '
                               f'{self.received} messages')
            elif self.received != exp or st != 'finished' or self.dropped or pub != exp:
                why_partial = (f'received {self.received} of the {exp} messages the replay '
                               f'announced' + (f' ({pub} published)' if pub is not None
                                               else '')
                               + f' (replay {st or "unknown"}, ended: {trigger})')
            else:
                why_partial = (f'the replay\'s sequence numbers have {self.seq_gaps} missing, '
                               f'{self.seq_disorder} out of order, first '
                               f'{self.seq_first} (a message lost or from elsewhere)')
        # a stream without a replay (live) is complete when it ended quietly or on request
        live = exp is None and trigger in ('quiet', 'service')
        if why_partial and not live:
            if not cfg.allow_partial:
                return self._fail(report, f'incomplete stream: {why_partial}; no map (set '
                                  'allow_partial to write one marked partial)')
            stream['partial'] = True
            report['problems'].append(f'partial: {why_partial}')
        if not self.data:
            return self._fail(report, f'no {cfg.topic} message received')
        try:
            s = decode_joint_states(self.data, self.recv_ns, keep_locked=cfg.six_joints)
        except JointStateError as exc:
            return self._fail(report, f'{cfg.topic}: {exc}')
        finite = (np.isfinite(s.position).all(axis=1) & np.isfinite(s.velocity).all(axis=1)
                  & np.isfinite(s.effort).all(axis=1))
        bad = int(np.count_nonzero(~finite))
        if bad:
            report['problems'].append(f'{bad} samples with NaN or infinite values left out')
            s = type(s)(s.t[finite], s.names, s.position[finite], s.velocity[finite],
                        s.effort[finite])
        stream['nan_samples'] = bad
        label = Path(str((self.status or {}).get('bag') or 'stream')).name
        # several bags played as one stream: one series per bag (as identify reads them), so
        # the time between two bags is not taken for lost samples; only a complete stream
        # (every message, in order) is cut at the counts the replay announced
        parts = split_by_segments(len(self.data), (self.status or {}).get('segments'),
                                  cfg.topic) if complete and not bad else []
        series, labels = [s], [label]
        if parts:
            series = [type(s)(s.t[a:b], s.names, s.position[a:b], s.velocity[a:b],
                              s.effort[a:b]) for _, a, b in parts]
            labels = [name for name, _, _ in parts]
            stream['segments'] = len(parts)
        try:
            results = identify_joints(series, labels, [cfg.torque_kind] * len(series),
                                      cfg.joints or None, cfg.name_map, self.model,
                                      cfg.pipeline, progress=progress)
            for r in results:
                report['joints'][r.name] = report_entry(r)
            source = f'identified by the identifier node from {label}'
            if stream['partial']:
                source = f'PARTIAL ({why_partial}): {source}'
            fill = None
            if cfg.fill_nominal and self.model is not None and all(
                    r.name in self.model.joint_names for r in results):
                fill = self.model.friction
            fmap = friction_map(results, source, fill)
            if cfg.complete_from and self.model is not None:
                fmap = complete_map(fmap, complete_source(cfg.complete_from, self.model),
                                    self.model.joint_names)
        except FrictionMapError as exc:
            return self._fail(report, f'complete_from: {exc}')
        except IdentificationError as exc:
            return self._fail(report, str(exc))
        out = Path(cfg.out_map)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f'.{out.name}.tmp{os.getpid()}')
        fmap.save(tmp)
        os.replace(tmp, out)
        if cfg.plots_dir:
            import re

            from .plots import plot_joint
            Path(cfg.plots_dir).mkdir(parents=True, exist_ok=True)
            for r in results:
                safe = re.sub(r'[^A-Za-z0-9_.-]+', '_', r.name)
                report['joints'][r.name]['plot'] = str(plot_joint(
                    r, Path(cfg.plots_dir) / f'{out.stem}_{safe}.png'))
        trusted = [r.name for r in results if not r.error and not r.degenerate]
        report.update(ok=bool(trusted), identified=trusted,
                      failed=[r.name for r in results if r.error],
                      degenerate=[r.name for r in results if r.degenerate])
        self._write_report(report)
        lines = [summary_line(r) for r in results]
        return StreamOutcome(bool(trusted), str(out), lines, '' if trusted else
                             'no joint has a trusted fit', report)

    def _fail(self, report: dict, message: str) -> StreamOutcome:
        report['error'] = message
        self._write_report(report)
        return StreamOutcome(False, '', [], message, report)

    def _write_report(self, report: dict) -> None:
        path = self.config.out_report or str(Path(self.config.out_map).with_suffix('.json'))
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(json.dumps(report, indent=2, default=float))
