"""Timing of bag replay, independent of rclpy: when to publish what."""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Callable, Iterable


@dataclass
class PlaybackStats:
    """Messages published, bag time span played [s], wall time used [s], worst lateness [s]."""

    messages: int = 0
    bag_span_s: float = 0.0
    wall_s: float = 0.0
    max_late_s: float = 0.0


def play(messages: Iterable[tuple[str, str, int, bytes]],
         publish: Callable[[str, bytes], None], rate: float = 1.0,
         clock: Callable[[int], None] | None = None, clock_period_ns: int = 10_000_000,
         stop: threading.Event | None = None,
         now: Callable[[], float] = time.monotonic,
         sleep: Callable[[float], None] = time.sleep) -> PlaybackStats:
    """Publish (topic, type, log time [ns], bytes) messages in order.

    rate: 1 = recorded speed, 2 = twice as fast, 0 = as fast as possible. ``clock(t_ns)`` is
    called with the bag time before a message whenever ``clock_period_ns`` of bag time have
    passed (the /clock publisher). ``stop`` ends playback early.
    """
    if rate < 0:
        raise ValueError('rate must be >= 0')
    stats = PlaybackStats()
    t_first = wall0 = None
    last_clock = None
    t_ns = 0
    for topic, _, t_ns, data in messages:
        if stop is not None and stop.is_set():
            break
        if t_first is None:
            t_first, wall0 = t_ns, now()
        if rate > 0:
            due = wall0 + (t_ns - t_first) * 1e-9 / rate
            wait = due - now()
            while wait > 0:
                sleep(min(wait, 0.05))
                if stop is not None and stop.is_set():
                    break
                wait = due - now()
            stats.max_late_s = max(stats.max_late_s, -wait)
        if clock is not None and (last_clock is None or t_ns - last_clock >= clock_period_ns):
            clock(t_ns)
            last_clock = t_ns
        publish(topic, data)
        stats.messages += 1
    if t_first is not None:
        stats.bag_span_s = (t_ns - t_first) * 1e-9
        stats.wall_s = now() - wall0
    return stats
