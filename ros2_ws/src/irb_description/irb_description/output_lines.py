"""Lines of a child process's output, read by a thread of their own (no ROS imports).

Used by tests and tools that start nodes with ``ros2 run`` and wait for a log line.
"""
from __future__ import annotations

import queue
import threading
import time


class OutputLines:
    """The lines of a child's text pipe, read by a thread of their own: ``wait_for(needle,
    timeout)`` returns the lines up to the first one holding ``needle`` (or raises
    AssertionError with what was read). Polling the pipe with ``select`` and then
    ``readline`` loses lines: readline buffers every line that arrived with the first, and
    ``select`` never reports them again (a test waited 120 s for a line already read)."""

    def __init__(self, pipe):
        self._q: queue.Queue = queue.Queue()
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._pump, args=(pipe,), daemon=True)
        self._thread.start()

    def _pump(self, pipe) -> None:
        for line in iter(pipe.readline, ''):
            self._q.put(line)
        self._q.put(None)                     # end of output

    def _next(self, timeout: float) -> str | None:
        """The next line (kept in ``lines``), or None when the output has ended or nothing
        came within ``timeout`` [s] (0: only what is already there)."""
        try:
            line = self._q.get(timeout=timeout) if timeout > 0 else self._q.get_nowait()
        except queue.Empty:
            return None
        if line is None:
            self._q.put(None)                 # stays ended for the next caller
            return None
        self.lines.append(line)
        return line

    def wait_for(self, needle: str, timeout: float) -> list[str]:
        seen, end = [], time.monotonic() + timeout
        while (left := end - time.monotonic()) > 0:
            line = self._next(left)
            if line is None:
                break
            seen.append(line)
            if needle in line:
                return seen
        raise AssertionError(f'{needle!r} not seen within {timeout:g} s: '
                             f'{"".join(seen)[-2000:]}')

    def rest(self, timeout: float = 30.0) -> str:
        """Everything until the output ends (bounded)."""
        self._thread.join(timeout)
        out = []
        while (line := self._next(0)) is not None:
            out.append(line)
        return ''.join(out)


def popen_lines(cmd, **popen_kw):
    """``subprocess.Popen(cmd)`` with stdout and stderr merged into one text pipe that an
    ``OutputLines`` (``proc.out``) drains from the start. A pipe read only at the end fills
    at 64 KiB and the child then blocks in its logger, executor and all (a pdplus that logged
    a line per refused ~/enable never took the simulator's latched state)."""
    import subprocess
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            **popen_kw)
    proc.out = OutputLines(proc.stdout)
    return proc
