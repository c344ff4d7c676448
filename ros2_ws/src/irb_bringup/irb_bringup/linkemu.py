"""A delay-and-loss link between two TAP devices, for test hosts where the kernel has no
`sch_netem` (tc's delay/loss queue; this project's CI VMs are built without it and without
loadable modules, so nothing can be installed to get it).

    python -m irb_bringup.linkemu --a TAP_A --b TAP_B [--delay-ms 5] [--loss 0.01] [--seed 1]

Creates the two TAP devices, prints ``ready`` and then moves every Ethernet frame from one to
the other after ``delay_ms`` (constant, so order is kept), dropping each with probability
``loss`` independently in each direction -- what `tc qdisc add ... netem delay D loss L`
does on both ends of a link. Ends on SIGINT/SIGTERM. Frames are copied in user space: even
at 0 ms this adds roughly 0.05-0.3 ms per direction on a loaded 2-core machine (measured by
irb_bringup/benchmarks/bench_hosts.py, case `hosts_0ms_emulated`). ``hosts.Cell`` uses
netem when the kernel has it and this otherwise. The math (``DelayLine``) has no I/O.
"""
from __future__ import annotations

import argparse
import collections
import fcntl
import os
import random
import select
import signal
import struct
import sys
import time

TUNSETIFF = 0x400454ca
IFF_TAP = 0x0002
IFF_NO_PI = 0x1000
MAX_FRAME = 65536


class DelayLine:
    """One direction of the link: frames pushed at ``now`` come out at ``now + delay_s``, in
    order, each dropped with probability ``loss`` (the random source is given)."""

    def __init__(self, delay_s: float, loss: float, rng: random.Random):
        if delay_s < 0 or not 0.0 <= loss < 1.0:
            raise ValueError(f'delay must be >= 0 and loss in [0, 1) (got {delay_s}, {loss})')
        self.delay_s = delay_s
        self.loss = loss
        self.rng = rng
        self.queue: collections.deque[tuple[float, bytes]] = collections.deque()
        self.passed = self.dropped = 0

    def push(self, now: float, frame: bytes) -> bool:
        if self.loss and self.rng.random() < self.loss:
            self.dropped += 1
            return False
        self.queue.append((now + self.delay_s, frame))
        return True

    def next_due(self) -> float | None:
        return self.queue[0][0] if self.queue else None

    def pop_due(self, now: float) -> list[bytes]:
        out = []
        while self.queue and self.queue[0][0] <= now:
            out.append(self.queue.popleft()[1])
        self.passed += len(out)
        return out


def open_tap(name: str) -> int:
    fd = os.open('/dev/net/tun', os.O_RDWR)
    fcntl.ioctl(fd, TUNSETIFF, struct.pack('16sH', name.encode(), IFF_TAP | IFF_NO_PI))
    return fd


def serve(fa: int, fb: int, delay_s: float, loss: float, seed: int, stop) -> dict:
    """Forward between the two TAP file descriptors until ``stop()``."""
    rng = random.Random(seed)
    lines = {fa: (DelayLine(delay_s, loss, rng), fb), fb: (DelayLine(delay_s, loss, rng), fa)}
    while not stop():
        dues = [d for d in (line.next_due() for line, _ in lines.values()) if d is not None]
        timeout = 0.2 if not dues else max(0.0, min(dues) - time.monotonic())
        try:
            readable, _, _ = select.select([fa, fb], [], [], timeout)
        except InterruptedError:
            continue
        now = time.monotonic()
        for fd in readable:
            try:
                lines[fd][0].push(now, os.read(fd, MAX_FRAME))
            except OSError:
                pass
        now = time.monotonic()
        for line, out in lines.values():
            for frame in line.pop_due(now):
                try:
                    os.write(out, frame)
                except OSError:         # the other side is down: the frame is lost
                    pass
    return {'a_to_b': {'passed': lines[fa][0].passed, 'dropped': lines[fa][0].dropped},
            'b_to_a': {'passed': lines[fb][0].passed, 'dropped': lines[fb][0].dropped}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--a', required=True, help='TAP device name (created)')
    ap.add_argument('--b', required=True, help='TAP device name (created)')
    ap.add_argument('--delay-ms', type=float, default=0.0, help='[ms] each direction')
    ap.add_argument('--loss', type=float, default=0.0, help='drop probability, each direction')
    ap.add_argument('--seed', type=int, default=1)
    a = ap.parse_args(argv)
    stopped = []
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, lambda *_: stopped.append(True))
    try:
        fa, fb = open_tap(a.a), open_tap(a.b)
    except OSError as exc:
        print(f'linkemu: cannot create TAP devices {a.a}, {a.b}: {exc}', file=sys.stderr)
        return 1
    print('ready', flush=True)
    try:
        counts = serve(fa, fb, a.delay_ms * 1e-3, a.loss, a.seed, lambda: bool(stopped))
    except ValueError as exc:
        print(f'linkemu: {exc}', file=sys.stderr)
        return 2
    print(f'linkemu: {counts}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
