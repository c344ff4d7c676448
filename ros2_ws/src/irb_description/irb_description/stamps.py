"""Seconds as ROS (sec, nanosec) pairs (builtin_interfaces Time and Duration fields).

Plain module, no ROS imports. Round the whole time to nanoseconds first, then split it:
splitting first (sec = floor(t), nanosec = round(frac * 1e9) % 1e9) maps a time a hair below
an integer, like the accumulated 2.99999999999998 s, to (2, 0), one second early.
"""
from __future__ import annotations

NS_PER_S = 1_000_000_000


def sec_nanosec(t: float) -> tuple[int, int]:
    """(sec, nanosec) of t [s] rounded to the nearest nanosecond; 0 <= nanosec < 1e9 (for
    t < 0, sec is negative and nanosec still counts forward, as in builtin_interfaces)."""
    return divmod(int(round(t * 1e9)), NS_PER_S)
