"""Run a node graph as separate processes and stop it cleanly (no ROS imports).

PyPI has no launch_ros, so the bring-up is this small supervisor: it starts each node as a
process (normally `ros2 run <pkg> <exe> --ros-args ...`), prefixes and forwards its output,
and when any required process exits, or on SIGINT/SIGTERM, stops the others with SIGINT, then
SIGTERM, then SIGKILL after bounded waits.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field


@dataclass(frozen=True)
class ProcessSpec:
    """One process: ``name`` for logs, ``cmd`` argv, ``required``: its exit stops the graph."""

    name: str
    cmd: tuple[str, ...]
    required: bool = True
    env: dict = field(default_factory=dict)


def interrupt(proc: subprocess.Popen) -> None:
    """Ctrl-C for a process started in a session of its own (``start_new_session``): SIGINT to
    its whole group, once each, as a terminal does (``ros2 run`` does not forward it)."""
    try:
        os.killpg(proc.pid, signal.SIGINT)
    except ProcessLookupError:
        pass


def stop_sessions(procs: list, timeout_s: float = 10.0, log=None) -> None:
    """Stop processes each started in a session of its own: SIGINT to every group (as a
    terminal's Ctrl-C; `ros2 run` does not forward it), then SIGTERM, then SIGKILL, each
    after ``timeout_s`` [s] (5 s for SIGKILL) for those still alive."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        alive = [p for p in procs if p.poll() is None]
        if not alive:
            break
        for p in alive:
            try:
                os.killpg(p.pid, sig)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + (timeout_s if sig != signal.SIGKILL else 5.0)
        for p in alive:
            try:
                p.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
        if log is not None and sig != signal.SIGINT and any(p.poll() is not None
                                                            for p in alive):
            log(f'needed {signal.Signals(sig).name} to stop some processes')


def ros2_run_cmd(package: str, executable: str, params_file: str | None = None,
                 params: dict | None = None, remaps: dict | None = None,
                 node_name: str | None = None, extra: tuple[str, ...] = ()) -> tuple[str, ...]:
    """argv of `ros2 run package executable [extra] --ros-args ...`."""
    cmd = ['ros2', 'run', package, executable, *extra]
    ros_args = []
    if params_file:
        ros_args += ['--params-file', params_file]
    for k, v in (params or {}).items():
        if isinstance(v, bool):
            v = 'true' if v else 'false'
        ros_args += ['-p', f'{k}:={v}']
    for k, v in (remaps or {}).items():
        ros_args += ['-r', f'{k}:={v}']
    if node_name:
        ros_args += ['-r', f'__node:={node_name}']
    if ros_args:
        cmd += ['--ros-args', *ros_args]
    return tuple(cmd)


class ProcessGroup:
    """Start, watch and stop a set of processes; use as a context manager."""

    def __init__(self, specs: list[ProcessSpec], log=print, stream=None,
                 stop_timeout_s: float = 10.0):
        self.specs = list(specs)
        self.log = log
        self.stream = stream if stream is not None else sys.stdout
        self.stop_timeout_s = stop_timeout_s
        self.procs: dict[str, subprocess.Popen] = {}
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()
        self.failed: str | None = None        # name of the required process that ended first

    def __enter__(self) -> 'ProcessGroup':
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def _pump(self, name: str, pipe) -> None:
        for line in iter(pipe.readline, ''):
            with self._lock:
                self.stream.write(f'[{name}] {line}')
                self.stream.flush()
        pipe.close()

    def start(self) -> None:
        for spec in self.specs:
            self._launch(spec)

    def add(self, spec: ProcessSpec) -> None:
        """Start one more process in the running group."""
        if spec.name in self.procs:
            raise ValueError(f'a process named {spec.name!r} already exists')
        self.specs.append(spec)
        self._launch(spec)

    def _launch(self, spec: ProcessSpec) -> None:
        env = dict(os.environ, PYTHONUNBUFFERED='1', **spec.env)
        proc = subprocess.Popen(list(spec.cmd), stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, env=env,
                                start_new_session=True)
        self.procs[spec.name] = proc
        t = threading.Thread(target=self._pump, args=(spec.name, proc.stdout), daemon=True)
        t.start()
        self._threads.append(t)
        self.log(f'started {spec.name} (pid {proc.pid}): {" ".join(spec.cmd)}')

    def poll(self) -> str | None:
        """Name of a required process that has exited (recorded in ``failed``), else None."""
        for spec in self.specs:
            proc = self.procs.get(spec.name)
            if spec.required and proc is not None and proc.poll() is not None:
                if self.failed is None:
                    self.failed = spec.name
                    self.log(f'{spec.name} exited with code {proc.returncode}')
                return spec.name
        return None

    def wait_until(self, condition, timeout_s: float, period_s: float = 0.05) -> bool:
        """Poll ``condition()`` until true (True) or timeout / a required process died (False)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if condition():
                return True
            if self.poll() is not None:
                return False
            time.sleep(period_s)
        return bool(condition())

    def stop_one(self, name: str) -> int:
        """Stop one process (SIGINT, SIGTERM, SIGKILL) and forget it; returns its exit code."""
        self._stop([self.procs[name]])
        self.specs = [s for s in self.specs if s.name != name]
        return self.procs.pop(name).returncode

    def stop(self) -> dict[str, int]:
        """Stop every process (SIGINT, then SIGTERM, then SIGKILL); returns exit codes."""
        self._stop(list(self.procs.values()))
        for t in self._threads:
            t.join(timeout=2.0)
        return {name: p.returncode for name, p in self.procs.items()}

    def _stop(self, procs: list) -> None:
        stop_sessions(procs, self.stop_timeout_s, self.log)
