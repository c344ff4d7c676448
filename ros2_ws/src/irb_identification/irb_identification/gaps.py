"""Gaps and duplicates in sampled series, and what readers do about them. No rclpy.

A recorder that lost messages leaves holes in a 248 Hz series; a reader that differentiates,
filters or averages across a hole computes something else than it claims (a one-sample hole
in a second difference is an acceleration of v / T: hundreds of N m of "residual"; a 1 s hole
bridged by a spline is a TCP error of centimetres). Every reader of the package therefore
checks the stamps of each series it uses against the nominal sample period and then

* drops duplicates (a step shorter than ``duplicate_factor`` x period: the same message twice);
* bridges short holes (at most ``bridge_samples`` missing samples in a row) where the method
  needs an even grid, by interpolating the missing samples (``fill_grid``), and otherwise uses
  the real stamps (time-weighted means, gradients over the real steps);
* splits the series at longer gaps (``GapConfig.split_s``) into segments that are analysed
  separately: nothing is differentiated, filtered, interpolated or averaged across them;
  segments shorter than ``min_segment_s`` are left out (counted);
* or, with ``on_gap='refuse'``, refuses any series with a gap (``GapError``: one line naming
  the bag, the topic, the gap's time and length).

A result computed from a series with gaps says so: ``SeriesCheck.summary()`` is the line the
tools print and ``SeriesCheck.as_dict()`` the entry of their JSON/YAML reports.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: nominal sample period of the joint states and torque commands [s] (DESIGN.md §5, 248 Hz)
NOMINAL_PERIOD_S = 0.004032
ON_GAP = ('segment', 'refuse')


class GapError(ValueError):
    """A series has a gap the reader refuses (one line: bag, topic, gap time and length)."""


@dataclass(frozen=True)
class GapConfig:
    """How readers treat holes in a series.

    period_s [s]: nominal sample period (when a series' median step differs from it by more
    than ``period_tolerance`` [-], e.g. an imported 1 kHz log, the median step is used and
    the check says so); gap_factor [-]: a step longer than gap_factor x period is a gap (at
    least one sample missing); bridge_samples [-]: gaps of at most this many missing samples
    are bridged (interpolated where an even grid is needed), longer ones split the series
    (0: every gap splits); duplicate_factor [-]: a step shorter than this x period makes the
    later sample a duplicate (dropped); min_segment_s [s]: shorter segments between
    splitting gaps are not analysed; on_gap: 'segment' (split and go on) or 'refuse' (any
    gap is an error).
    """

    period_s: float = NOMINAL_PERIOD_S
    gap_factor: float = 1.5
    bridge_samples: int = 3
    duplicate_factor: float = 0.5
    min_segment_s: float = 0.5
    on_gap: str = 'segment'
    period_tolerance: float = 0.25

    def __post_init__(self):
        if self.on_gap not in ON_GAP:
            raise ValueError(f"on_gap must be one of {', '.join(ON_GAP)}, not {self.on_gap!r}")
        if not self.period_s > 0 or not self.gap_factor > 1 or self.bridge_samples < 0:
            raise ValueError('gaps: period_s > 0, gap_factor > 1 and bridge_samples >= 0 '
                             'required')

    def split_s(self, period_s: float | None = None) -> float:
        """[s] steps at least this long split a series (more than bridge_samples missing)."""
        return (self.bridge_samples + self.gap_factor) * (period_s or self.period_s)


#: the splitting threshold of the default configuration [s] (segments.SegmentConfig uses it)
DEFAULT_SPLIT_S = GapConfig().split_s()


@dataclass(frozen=True)
class Gap:
    """A hole: it starts after the sample at ``t`` [s] (absolute stamp), lasts ``length_s``
    [s] (the step between the samples around it) and ``missing`` samples are not there."""

    t: float
    length_s: float
    missing: int
    splits: bool


@dataclass
class SeriesCheck:
    """What a reader found in one series: stamps checked against the period used."""

    bag: str
    topic: str
    samples: int
    period_s: float
    t0: float = 0.0
    duration_s: float = 0.0
    gaps: list[Gap] = field(default_factory=list)
    duplicates: int = 0
    period_note: str = ''
    segments: int = 1
    left_out_s: float = 0.0        # time in segments too short to analyse [s]
    handling: str = 'segment'
    bridge_note: str = ''          # the splitting threshold in words

    @property
    def missing(self) -> int:
        return int(sum(g.missing for g in self.gaps))

    @property
    def missing_fraction(self) -> float:
        expected = self.samples + self.missing
        return self.missing / expected if expected else 0.0

    @property
    def clean(self) -> bool:
        return not self.gaps and not self.duplicates

    def largest(self) -> Gap | None:
        return max(self.gaps, key=lambda g: g.length_s) if self.gaps else None

    def gap_text(self, g: Gap) -> str:
        return (f'gap of {g.length_s:.3f} s at t = {g.t - self.t0:.3f} s (stamp {g.t:.6f} s, '
                f'{g.missing} samples missing at the {self.period_s * 1e3:.3f} ms period)')

    def summary(self) -> str:
        """One line: bag, topic and what is missing (or 'complete')."""
        head = f'bag {self.bag}: {self.topic}'
        if self.clean:
            return f'{head}: {self.samples} samples, no gap, no duplicate' + (
                f' ({self.period_note})' if self.period_note else '')
        parts = []
        if self.gaps:
            big = self.largest()
            parts.append(f'{len(self.gaps)} gap(s), {self.missing} samples missing '
                         f'({100 * self.missing_fraction:.2f} %), largest: {self.gap_text(big)}')
        if self.duplicates:
            parts.append(f'{self.duplicates} duplicate(s) dropped')
        split = sum(g.splits for g in self.gaps)
        if split:
            parts.append(f'analysed in {self.segments} segment(s) split at {split} gap(s) '
                         f'longer than {self.bridge_note}'
                         + (f', {self.left_out_s:.2f} s in too short segments left out'
                            if self.left_out_s else ''))
        elif self.gaps:
            parts.append('short gaps bridged')
        if self.period_note:
            parts.append(self.period_note)
        return f'{head}: ' + '; '.join(parts)

    def as_dict(self, max_listed: int = 20) -> dict:
        big = self.largest()
        return {'bag': self.bag, 'topic': self.topic, 'samples': self.samples,
                'period_s': self.period_s, 'gaps': len(self.gaps),
                'missing_samples': self.missing, 'missing_fraction': self.missing_fraction,
                'duplicates_dropped': self.duplicates,
                'largest_gap_s': big.length_s if big else 0.0,
                'largest_gap_at_s': (big.t - self.t0) if big else None,
                'segments': self.segments, 'left_out_s': self.left_out_s,
                'handling': self.handling, 'complete': self.clean,
                'listed_gaps': [{'t_s': g.t - self.t0, 'stamp_s': g.t, 'length_s': g.length_s,
                                 'missing': g.missing, 'splits': g.splits}
                                for g in sorted(self.gaps, key=lambda g: -g.length_s)
                                [:max_listed]],
                'summary': self.summary()}


def period_of(t: np.ndarray, config: GapConfig) -> tuple[float, str]:
    """(period used [s], note): the nominal period, or the median step if it is far off."""
    steps = np.diff(np.asarray(t, float))
    steps = steps[steps > 0]
    if not len(steps):
        return config.period_s, ''
    med = float(np.median(steps))
    if abs(med / config.period_s - 1.0) > config.period_tolerance:
        # not this project's clock (an imported log, jittery stamps): a step is a gap only
        # against the longest ordinary step, else plain jitter (steps of 0.4-1.6 ms around a
        # 1 ms median) would split the series every few samples
        spacing = max(float(np.quantile(steps, IRREGULAR_QUANTILE)), med)
        return spacing, (f'median step {med * 1e3:.3f} ms is not the nominal '
                         f'{config.period_s * 1e3:.3f} ms: gaps measured against the longest '
                         f'ordinary step ({spacing * 1e3:.3f} ms, the '
                         f'{IRREGULAR_QUANTILE * 100:g}th percentile)')
    return config.period_s, ''


#: series off the nominal period: the step quantile taken as their longest ordinary step
IRREGULAR_QUANTILE = 0.99


_EQUAL_STAMPS_S = 1e-9       # [s] stamps closer than this are the same stamp


def duplicate_mask(t: np.ndarray, period_s: float, config: GapConfig) -> np.ndarray:
    """(N,) True for samples to keep: a sample closer than duplicate_factor x period to the
    last kept one is a duplicate (t sorted)."""
    t = np.asarray(t, float)
    keep = np.ones(len(t), bool)
    if len(t) < 2:
        return keep
    close = np.diff(t) < config.duplicate_factor * period_s
    if not close.any():
        return keep
    last = t[0]
    for i in range(1, len(t)):            # rare: only reached with duplicates present
        if t[i] - last < config.duplicate_factor * period_s:
            keep[i] = False
        else:
            last = t[i]
    return keep


def find_gaps(t: np.ndarray, period_s: float, config: GapConfig) -> list[Gap]:
    """Gaps of sorted, duplicate-free stamps t (N,) [s] at ``period_s``."""
    t = np.asarray(t, float)
    if len(t) < 2:
        return []
    d = np.diff(t)
    idx = np.flatnonzero(d > config.gap_factor * period_s)
    split = config.split_s(period_s)
    return [Gap(float(t[i]), float(d[i]), max(1, int(round(d[i] / period_s)) - 1),
                bool(d[i] >= split)) for i in idx]


def segment_bounds(t: np.ndarray, period_s: float, config: GapConfig
                   ) -> list[tuple[int, int]]:
    """[start, end) index ranges of sorted, duplicate-free t between splitting gaps."""
    t = np.asarray(t, float)
    if not len(t):
        return []
    cut = np.flatnonzero(np.diff(t) >= config.split_s(period_s)) + 1
    edges = np.concatenate([[0], cut, [len(t)]])
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def check_series(t: np.ndarray, bag: str, topic: str, config: GapConfig = GapConfig(),
                 period_s: float | None = None) -> tuple[SeriesCheck, np.ndarray,
                                                         list[tuple[int, int]]]:
    """Check stamps t (N,) [s] (sorted) of ``topic`` in ``bag``.

    Returns (check, keep mask (N,) without duplicates, usable [start, end) segments of the
    kept samples, each at least min_segment_s long). Raises GapError with one line when
    ``on_gap`` is 'refuse' and there is a gap, or when no segment is long enough.
    ``period_s`` overrides the nominal period (e.g. the camera's).
    """
    t = np.asarray(t, float)
    cfg = config if period_s is None else GapConfig(**{**config.__dict__, 'period_s': period_s})
    period, note = period_of(t, cfg)
    # off the nominal clock only equal stamps are duplicates (jitter brings close ones)
    keep = duplicate_mask(t, period if not note else _EQUAL_STAMPS_S / cfg.duplicate_factor,
                          cfg)
    tk = t[keep]
    gaps = find_gaps(tk, period, cfg)
    chk = SeriesCheck(str(bag), topic, int(len(tk)), period, float(tk[0]) if len(tk) else 0.0,
                      float(tk[-1] - tk[0]) if len(tk) else 0.0, gaps,
                      int(len(t) - len(tk)), note, handling=cfg.on_gap,
                      bridge_note=f'{cfg.split_s(period) * 1e3:.1f} ms '
                                  f'({cfg.bridge_samples} missing samples)')
    if gaps and cfg.on_gap == 'refuse':
        raise GapError(f'bag {bag}: {topic}: {chk.gap_text(chk.largest())}; '
                       f'{len(gaps)} gap(s), {chk.missing} samples missing in all (refused: '
                       'on_gap refuse; segment analyses around gaps)')
    bounds = segment_bounds(tk, period, cfg)
    usable = [(a, b) for a, b in bounds if tk[b - 1] - tk[a] >= cfg.min_segment_s]
    chk.segments = len(usable)
    chk.left_out_s = float(sum(tk[b - 1] - tk[a] for a, b in bounds if (a, b) not in usable))
    if not usable:
        big = chk.largest()
        raise GapError(f'bag {bag}: {topic}: no stretch of {cfg.min_segment_s:g} s without a '
                       'gap longer than ' f'{cfg.split_s(period) * 1e3:.1f} ms ('
                       + (chk.gap_text(big) if big else f'{len(tk)} samples only')
                       + f'; {len(gaps)} gap(s), {chk.missing} samples missing)')
    return chk, keep, usable


def fill_grid(t: np.ndarray, arrays: dict[str, np.ndarray], period_s: float,
              smooth: tuple[str, ...] = ()) -> tuple[np.ndarray, dict[str, np.ndarray],
                                                     np.ndarray]:
    """One segment (no splitting gap) on an even grid: the samples that are there keep their
    stamps and values; each missing one (a step of about k periods has k - 1) is put at
    evenly spaced times between its neighbours and interpolated: cubic (C2 spline) for the
    names in ``smooth`` (positions), linear for the others. Returns (t (M,), arrays (M, ...),
    filled mask (M,))."""
    from scipy.interpolate import CubicSpline
    t = np.asarray(t, float)
    d = np.diff(t)
    k = np.maximum(np.rint(d / period_s).astype(int), 1) if len(t) > 1 else np.zeros(0, int)
    if not len(t) or np.all(k == 1):
        return t, dict(arrays), np.zeros(len(t), bool)
    # new times: for step i with k_i sub-steps, t_i + j d_i / k_i, j = 1..k_i
    reps = np.repeat(np.arange(len(d)), k)
    j = np.concatenate([np.arange(1, n + 1) for n in k])
    tn = np.concatenate([t[:1], t[reps] + j * (d[reps] / k[reps])])
    filled = np.concatenate([[False], j != k[reps]])
    tn[~filled] = t                       # exact original stamps (no rounding)
    out = {}
    for name, a in arrays.items():
        a = np.asarray(a, float)
        if name in smooth and len(t) >= 4:
            out[name] = CubicSpline(t, a, axis=0)(tn)
        elif a.ndim == 1:
            out[name] = np.interp(tn, t, a)
        else:
            out[name] = np.stack([np.interp(tn, t, a[:, c]) for c in range(a.shape[1])], 1)
        out[name][~filled] = a
    return tn, out, filled


__all__ = ['NOMINAL_PERIOD_S', 'DEFAULT_SPLIT_S', 'GapConfig', 'GapError', 'Gap',
           'SeriesCheck', 'check_series', 'duplicate_mask', 'fill_grid', 'find_gaps',
           'period_of', 'segment_bounds']
