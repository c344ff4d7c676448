"""import_log: a CSV friction log (any robot) -> a rosbag2 MCAP bag that `identify` reads.

    ros2 run irb_identification import_log log.csv.gz --out bags/axis2 --time-column time \\
        --joint axis_2:q2:qd2:tau2 [--joint ...] [--torque-kind friction|total] \\
        [--accel-column axis_2:qdd2 ...]

One ``sensor_msgs/JointState`` per row on ``/joint_states`` with the log's joint names, its
stamps (``--time-column`` in seconds, kept to the nanosecond; log time = stamp), position,
velocity and effort; with ``--accel-column`` also ``/joint_accelerations`` (a JointState whose
``position`` array holds q_dd [rad/s^2], same names and stamps). ``--torque-kind`` goes into
the bag's ``custom_data`` (``irb_identification.torque_kind``) so `identify` knows whether the
effort is the friction torque or the total joint torque. Bad input (missing column,
non-numeric or NaN cell, time not strictly increasing, an existing --out) is one line and
exit code 1; the bag is written into a temporary directory next to --out and renamed at the
end, so nothing half-written is ever left under --out.
"""
from __future__ import annotations

import argparse
import csv
import gzip
import io
import os
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from irb_description.node_help import own_args

TORQUE_KIND_KEY = 'irb_identification.torque_kind'
ACCEL_TOPIC = '/joint_accelerations'


class ImportError_(ValueError):
    """Bad input; the message is the one line printed."""


@dataclass(frozen=True)
class JointSpec:
    name: str
    pos: str
    vel: str
    torque: str


def parse_joint(spec: str) -> JointSpec:
    parts = spec.split(':')
    if len(parts) != 4 or not all(parts):
        raise ImportError_(f'--joint {spec!r}: expected <joint_name>:<pos_col>:<vel_col>:'
                           '<torque_col>')
    return JointSpec(*parts)


def _open_text(path: Path):
    raw = open(path, 'rb')
    head = raw.read(2)
    raw.seek(0)
    if head == b'\x1f\x8b':
        return io.TextIOWrapper(gzip.GzipFile(fileobj=raw), encoding='utf-8', newline='')
    return io.TextIOWrapper(raw, encoding='utf-8', newline='')


def read_columns(path: Path, columns: list[str], progress=None) -> dict[str, np.ndarray]:
    """The named columns of a CSV (optionally gzip) file as float arrays; ImportError_ names
    the file, row and column of the first bad cell."""
    if not path.is_file():
        raise ImportError_(f'{path}: no such file')
    try:
        with _open_text(path) as f:
            sample = f.read(4096)
            f.seek(0)
            try:
                dialect = csv.Sniffer().sniff(sample, delimiters=',;\t ')
            except csv.Error:
                dialect = csv.excel
            reader = csv.reader(f, dialect)
            header = [h.strip() for h in next(reader, [])]
            if not header:
                raise ImportError_(f'{path}: empty file (no header row)')
            missing = [c for c in columns if c not in header]
            if missing:
                raise ImportError_(f'{path}: no column {", ".join(missing)} '
                                   f'(columns: {", ".join(header)})')
            idx = [header.index(c) for c in columns]
            out = [[] for _ in columns]
            for row_no, row in enumerate(reader, start=2):
                if not row or all(not c.strip() for c in row):
                    continue
                for k, i in enumerate(idx):
                    cell = row[i].strip() if i < len(row) else ''
                    try:
                        x = float(cell)
                    except ValueError:
                        raise ImportError_(f'{path}: row {row_no}, column {columns[k]}: '
                                           f'not a number ({cell[:20]!r})') from None
                    if not np.isfinite(x):
                        raise ImportError_(f'{path}: row {row_no}, column {columns[k]}: '
                                           f'{cell} (NaN or infinite)')
                    out[k].append(x)
                if progress and row_no % 500_000 == 0:
                    progress(f'{row_no} rows read')
    except (OSError, EOFError, gzip.BadGzipFile, UnicodeDecodeError) as exc:
        raise ImportError_(f'{path}: unreadable ({exc})') from None
    except csv.Error as exc:
        raise ImportError_(f'{path}: not a CSV file ({exc})') from None
    return {c: np.asarray(v, float) for c, v in zip(columns, out)}


def summary(t: np.ndarray, names: list[str], vel: np.ndarray) -> list[str]:
    """What was read: rows, duration, rate and its jitter, speed range per joint."""
    dt = np.diff(t)
    lines = [f'{len(t)} rows, {t[-1] - t[0]:.3f} s from t = {t[0]:.6g} s']
    if len(dt):
        lines.append(f'rate {1 / np.median(dt):.1f} Hz (median step {1e3 * np.median(dt):.3f} '
                     f'ms, jitter: std {1e3 * dt.std():.3f} ms, min {1e3 * dt.min():.3f} ms, '
                     f'max {1e3 * dt.max():.3f} ms)')
    for k, n in enumerate(names):
        s = np.abs(vel[:, k])
        lines.append(f'{n}: |v| {s.min():.4g}..{s.max():.4g} rad/s (median {np.median(s):.4g}),'
                     f' v from {vel[:, k].min():.4g} to {vel[:, k].max():.4g} rad/s')
    return lines


def import_log(path: str | Path, out: str | Path, time_column: str, joints: list[JointSpec],
               torque_kind: str = 'friction', accel: dict[str, str] | None = None,
               progress=None) -> list[str]:
    """Write the bag; returns the summary lines. Raises ImportError_ on bad input."""
    from .bagio import BagWriter, TopicInfo, qos_profile_dict
    from .series import JOINT_STATE, encode_joint_states

    path, out = Path(path), Path(out)
    accel = dict(accel or {})
    names = [j.name for j in joints]
    if len(set(names)) != len(names):
        raise ImportError_(f'joint names repeat: {names}')
    unknown = [n for n in accel if n not in names]
    if unknown:
        raise ImportError_(f'--accel-column for {unknown}: not among the --joint names {names}')
    if torque_kind not in ('friction', 'total'):
        raise ImportError_(f'--torque-kind {torque_kind!r}: friction or total')
    if out.exists():
        raise ImportError_(f'{out} exists already, not overwriting')
    cols = [time_column] + [c for j in joints for c in (j.pos, j.vel, j.torque)]
    cols += [accel[n] for n in names if n in accel]
    data = read_columns(path, list(dict.fromkeys(cols)), progress)
    t = data[time_column]
    if len(t) < 2:
        raise ImportError_(f'{path}: {len(t)} data row(s), need at least 2')
    bad = np.flatnonzero(np.diff(t) <= 0)
    if len(bad):
        i = int(bad[0])
        raise ImportError_(f'{path}: column {time_column} not strictly increasing at data '
                           f'row {i + 2} ({t[i]!r} then {t[i + 1]!r})')
    if t[0] < 0:
        raise ImportError_(f'{path}: column {time_column} starts at {t[0]} s < 0 '
                           '(ROS stamps are non-negative)')
    pos = np.column_stack([data[j.pos] for j in joints])
    vel = np.column_stack([data[j.vel] for j in joints])
    eff = np.column_stack([data[j.torque] for j in joints])
    t_ns = np.round(t * 1e9).astype(np.int64)
    if np.any(np.diff(t_ns) <= 0):
        raise ImportError_(f'{path}: two stamps closer than 1 ns')
    tmp = out.with_name(f'.{out.name}.importing-{os.getpid()}')
    shutil.rmtree(tmp, ignore_errors=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {TORQUE_KIND_KEY: torque_kind, 'source': f'import_log {path.name}',
            'time_column': time_column}
    try:
        clock = [0.0]
        with BagWriter(tmp, split_period_s=60.0, clock=lambda: clock[0],
                       custom_data=meta) as w:
            w.add_topic(TopicInfo.for_type('/joint_states', JOINT_STATE,
                                           [qos_profile_dict('reliable', depth=1000)]))
            if accel:
                w.add_topic(TopicInfo.for_type(ACCEL_TOPIC, JOINT_STATE,
                                               [qos_profile_dict('reliable', depth=1000)]))
                acc = np.column_stack([data[accel[n]] if n in accel
                                       else np.full(len(t), np.nan) for n in names])
            step = 200_000
            for a in range(0, len(t), step):
                b = min(a + step, len(t))
                payloads = encode_joint_states(t_ns[a:b], names, pos[a:b], vel[a:b], eff[a:b])
                acc_p = (encode_joint_states(t_ns[a:b], names, acc[a:b],
                                             np.zeros((b - a, len(names))),
                                             np.zeros((b - a, len(names))))
                         if accel else None)
                for i, ns in enumerate(t_ns[a:b]):
                    clock[0] = (ns - t_ns[0]) * 1e-9
                    w.write('/joint_states', int(ns), payloads[i])
                    if acc_p is not None:
                        w.write(ACCEL_TOPIC, int(ns), acc_p[i])
                if progress:
                    progress(f'{b} of {len(t)} messages written')
        os.rename(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return summary(t, names, vel)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='import_log', description=__doc__.split('\n\n')[0])
    p.add_argument('log', help='CSV file (optionally gzip-compressed), header row with names')
    p.add_argument('--out', required=True, help='bag directory to create')
    p.add_argument('--time-column', required=True, help='time column [s], strictly increasing')
    p.add_argument('--joint', action='append', required=True, metavar='NAME:POS:VEL:TORQUE',
                   help='a joint and its columns (repeatable): position [rad], velocity '
                   '[rad/s], torque [N m]')
    p.add_argument('--torque-kind', default='friction', choices=('friction', 'total'),
                   help='the torque column is the friction torque (default) or the total '
                   'joint torque (identify then subtracts the rigid-body model: only for '
                   'joints irb_description knows, see identify --map-joint)')
    p.add_argument('--accel-column', action='append', default=[], metavar='NAME:COL',
                   help='measured acceleration [rad/s^2] of a joint (repeatable)')
    return p


def main(args=None) -> int:
    argv = own_args(args)
    opts = _parser().parse_args(argv)
    try:
        joints = [parse_joint(s) for s in opts.joint]
        accel = {}
        for s in opts.accel_column:
            name, sep, col = s.partition(':')
            if not sep or not name or not col:
                raise ImportError_(f'--accel-column {s!r}: expected <joint_name>:<column>')
            accel[name] = col
        lines = import_log(opts.log, opts.out, opts.time_column, joints, opts.torque_kind,
                           accel, progress=lambda m: print(f'import_log: {m}', flush=True))
    except ImportError_ as exc:
        print(f'import_log: {exc}', file=sys.stderr)
        return 1
    except OSError as exc:
        print(f'import_log: cannot write {opts.out}: {exc.strerror or exc}', file=sys.stderr)
        return 1
    for line in lines:
        print(f'import_log: {line}')
    print(f'import_log: wrote {opts.out} ({opts.torque_kind} torque)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
