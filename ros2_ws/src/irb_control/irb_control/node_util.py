"""Helpers of the loop nodes: realtime scheduling, executors, spin (declare, QoS and
spin_until_signal live in irb_description.node_main, shared by every node package)."""
from __future__ import annotations

import gc
import os
import queue
import sys
import threading
import time

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from irb_description.node_help import Param
from irb_description.node_main import declare_params, spin_until_signal


#: the real-time parameters of every loop node (simulator, pdplus, axis_bridge)
REALTIME_PARAMS = (
    Param('realtime_priority', 0, '', 'SCHED_FIFO priority 1-99 of the process threads '
          '(executor and DDS); 0 = normal scheduling. Needs CAP_SYS_NICE or an rtprio limit; '
          'a warning, not an error, when refused'),
    Param('cpu_dma_latency_us', -1, 'us', 'while the node runs, ask the kernel (PM QoS, '
          '/dev/cpu_dma_latency) to keep the CPUs out of idle states slower to leave than '
          'this; 0 = no deep idle (idle CPUs poll: lowest wake-up latency, more power); -1 = '
          'leave alone. Needs write access to /dev/cpu_dma_latency; a warning when refused'),
    Param('cpu_affinity', [], '', 'CPUs the process threads may run on; [] = all',
          type='int[]'),
)


def declare_realtime(node: Node) -> tuple[int, list[int], int]:
    """Declare ``realtime_priority``, ``cpu_affinity`` and ``cpu_dma_latency_us`` (the same
    on every loop node, ``REALTIME_PARAMS``) and return their values; ValueError for a
    priority outside 0-99, a negative CPU or a latency below -1."""
    v = declare_params(node, REALTIME_PARAMS)
    prio, cpus, lat = int(v['realtime_priority']), v['cpu_affinity'], int(v['cpu_dma_latency_us'])
    prio, cpus = int(prio), [int(c) for c in cpus]
    if not 0 <= prio <= 99:
        raise ValueError(f'realtime_priority must be 0 (off) or 1-99, not {prio}')
    if any(c < 0 for c in cpus):
        raise ValueError(f'cpu_affinity: CPU numbers are >= 0, got {cpus}')
    if lat < -1:
        raise ValueError(f'cpu_dma_latency_us must be -1 (leave alone) or >= 0, not {lat}')
    return prio, cpus, lat


_LATENCY_REQUESTS = []     # open /dev/cpu_dma_latency files: the request lasts while open


def hold_cpu_latency(us: int, path: str = '/dev/cpu_dma_latency') -> str:
    """Ask the kernel's PM QoS to keep CPU wake-up latency <= ``us`` microseconds for as long
    as this process lives (the file stays open; closing it, or the process ending, drops the
    request). On a VM or a laptop an idle CPU otherwise sleeps in a halt state it takes
    milliseconds to leave: measured on the 2-core CI VM with the bare rclpy echo
    (benchmarks/echo_floor.py), round trip p99 1.5 -> 0.8 ms and max 11.8 -> 4.9 ms.
    Returns '' when done, else the reason it was refused (never raises)."""
    import struct
    try:
        f = open(path, 'wb', buffering=0)
        f.write(struct.pack('i', int(us)))
    except OSError as exc:
        return str(exc)
    _LATENCY_REQUESTS.append(f)
    return ''


def fifo_refusal(priority: int) -> str:
    """'' when this process may run SCHED_FIFO at ``priority`` (1-99), else why not (tried on
    the calling thread and undone at once; nothing else changes)."""
    if priority <= 0:
        return 'realtime_priority is 0'
    try:
        policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        os.sched_setscheduler(0, policy, param)
        return ''
    except (OSError, AttributeError) as exc:
        return f'SCHED_FIFO {priority} not granted ({exc})'


def process_threads() -> list[int]:
    """Thread ids of this process (the executor thread and the DDS threads)."""
    try:
        return sorted(int(t) for t in os.listdir('/proc/self/task'))
    except OSError:
        return [threading.get_native_id()]


def apply_realtime(priority: int, cpus=(), logger=None, threads=None,
                   cpu_latency_us: int = -1) -> dict:
    """SCHED_FIFO ``priority`` (1-99; 0 = leave the scheduling alone) and CPU affinity
    ``cpus`` ([] = leave alone) for ``threads`` (default: every thread of the process now:
    the executor thread and the middleware's receive threads, which are on the
    state -> command path). Threads created later inherit from their creator.

    Never raises for a refusal (no CAP_SYS_NICE / rtprio limit, a CPU that does not exist):
    logs a warning through ``logger`` and reports it. Returns {'priority': applied priority
    or 0, 'cpus': applied CPU list or [], 'warnings': [...]}.
    """
    threads = process_threads() if threads is None else list(threads)
    out = {'priority': 0, 'cpus': [], 'cpu_dma_latency_us': -1, 'warnings': []}

    def warn(text):
        out['warnings'].append(text)
        if logger is not None:
            logger.warning(text)
    if cpus:
        try:
            for tid in threads:
                os.sched_setaffinity(tid, cpus)
            out['cpus'] = sorted(os.sched_getaffinity(0))
        except (OSError, ValueError) as exc:
            warn(f'cpu_affinity {list(cpus)} not applied ({exc}); running on all CPUs')
    if priority:
        before = []
        try:
            param = os.sched_param(priority)
            for tid in threads:
                before.append((tid, os.sched_getscheduler(tid), os.sched_getparam(tid)))
                os.sched_setscheduler(tid, os.SCHED_FIFO, param)
            out['priority'] = priority
        except (OSError, AttributeError) as exc:
            for tid, policy, old in before:      # all or nothing
                try:
                    os.sched_setscheduler(tid, policy, old)
                except OSError:
                    pass
            warn(f'realtime_priority {priority} (SCHED_FIFO) not permitted here ({exc}); '
                 f'running with normal scheduling. Grant CAP_SYS_NICE or an rtprio limit '
                 f'(ulimit -r / limits.conf), or set realtime_priority to 0')
    if cpu_latency_us >= 0:
        why = hold_cpu_latency(cpu_latency_us)
        if why:
            warn(f'cpu_dma_latency_us {cpu_latency_us} not applied ({why}); idle CPUs may '
                 f'take milliseconds to wake up. Needs write access to /dev/cpu_dma_latency')
        else:
            out['cpu_dma_latency_us'] = int(cpu_latency_us)
    if logger is not None and (out['priority'] or out['cpus']
                               or out['cpu_dma_latency_us'] >= 0):
        logger.info(f"realtime: {len(threads)} threads, SCHED_FIFO priority "
                    f"{out['priority'] or 'off'}, CPUs {out['cpus'] or 'all'}, CPU wake-up "
                    f"latency " + (f"<= {out['cpu_dma_latency_us']} us"
                                   if out['cpu_dma_latency_us'] >= 0 else 'not set'))
    return out


#: interpreter-lock switch interval of the loop nodes [s] (Python's default: 5 ms)
SWITCH_INTERVAL_S = 0.0005


def short_switch_interval() -> None:
    """A thread of Python code that holds the interpreter lock gives it up to a waiting
    thread only after the switch interval: 5 ms by default, more than a period at 248 Hz. The
    loop nodes' other threads (log writer, plan reader, watchdog) run Python code; with 0.5 ms
    the control thread gets the lock within a fraction of a period (call it in main, not on
    import: it is process-wide)."""
    sys.setswitchinterval(SWITCH_INTERVAL_S)


def make_executor(kind: str, context=None):
    """'events': rclpy's EventsExecutor (faster; drive it with spin_once), else single."""
    if kind == 'events':
        try:
            from rclpy.experimental import EventsExecutor
            return EventsExecutor(context=context)
        except ImportError:
            pass
    return SingleThreadedExecutor(context=context)


def spin_with(executor_kind: str, realtime: tuple[int, list[int], int] = (0, [], -1)):
    """spin(node) for run_node: an executor of ``executor_kind`` driven by spin_until_signal;
    ``realtime`` = (priority, cpus, cpu wake-up latency [us]) applied to the process's
    threads first (apply_realtime)."""
    def spin(node):
        executor = make_executor(executor_kind)
        executor.add_node(node)
        apply_realtime(*realtime[:2], logger=node.get_logger(), cpu_latency_us=realtime[2])
        try:
            spin_until_signal(executor)
        finally:
            executor.shutdown()
    return spin


class GcWatch:
    """Times every cyclic garbage collection of the process (``gc.callbacks``) and reports
    those longer than ``limit_s`` through ``report(text)`` (a LogThread's ``warn``: never
    written on the thread that collected). A collection runs on whichever thread allocated
    when a generation's threshold was reached, the control thread included, and holds the
    interpreter lock throughout: a diagnostic for steps far longer than their computation.
    ``worst_s`` and ``count`` (collections over the limit) are kept for statistics."""

    def __init__(self, limit_s: float, report):
        self.limit_s, self._report = float(limit_s), report
        self._t0 = 0.0
        self.worst_s, self.count = 0.0, 0
        gc.callbacks.append(self._cb)

    def _cb(self, phase: str, info: dict) -> None:
        if phase == 'start':
            self._t0 = time.perf_counter()
            return
        dt = time.perf_counter() - self._t0
        self.worst_s = max(self.worst_s, dt)
        if dt > self.limit_s:
            self.count += 1
            self._report(f"gc: a generation-{info.get('generation')} collection took "
                         f"{dt * 1e3:.2f} ms on thread {threading.current_thread().name} "
                         f"({info.get('collected')} collected)")

    def close(self) -> None:
        if self._cb in gc.callbacks:
            gc.callbacks.remove(self._cb)


class LogThread:
    """A node's log lines written on a thread of their own.

    rclpy's logger looks up its caller's source file on every call (``inspect.getframeinfo``:
    realpath, stat and lstat of the file): 1-2 ms per line measured here, far more on a
    loaded machine or a slow file system. On the control thread that time is a stall: the
    line "mode idle -> ramp" after the first ramp step is the likeliest cause of the 23 and
    87 ms first ramp steps that latched "stall: no valid joint_states processed" (issue 32).
    ``info``/``warn``/``error`` only queue the line (a few microseconds); ``throttle_s``
    drops lines of the same ``key`` (default: the text's first 40 characters) within that
    time. ``flush()`` waits until every queued line is written (tests, shutdown)."""

    def __init__(self, get_logger):
        self._get_logger = get_logger       # called in the thread (tests may replace it)
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._last: dict = {}
        self._idle = threading.Event()
        self._idle.set()
        self._thread = threading.Thread(target=self._run, name='log_writer', daemon=True)
        self._thread.start()

    def info(self, text: str, throttle_s: float = 0.0, key=None) -> None:
        self._put('info', text, throttle_s, key)

    def warn(self, text: str, throttle_s: float = 0.0, key=None) -> None:
        self._put('warn', text, throttle_s, key)

    def error(self, text: str, throttle_s: float = 0.0, key=None) -> None:
        self._put('error', text, throttle_s, key)

    def _put(self, severity, text, throttle_s, key) -> None:
        if throttle_s > 0:
            key = (severity, text[:40]) if key is None else key
            now = time.monotonic()
            if now - self._last.get(key, -1e18) < throttle_s:
                return
            self._last[key] = now
        self._idle.clear()
        self._q.put((severity, text))

    def flush(self, timeout: float = 10.0) -> bool:
        return self._idle.wait(timeout)

    def _run(self) -> None:
        while True:
            severity, text = self._q.get()
            logger = self._get_logger()
            # one call site per severity: rclpy refuses a severity change at the same site
            if severity == 'error':
                logger.error(text)
            elif severity == 'warn':
                logger.warning(text)
            else:
                logger.info(text)
            if self._q.empty():
                self._idle.set()


def joint_model(joints: int, tcp_xyz=(0.0, 0.0, 0.0)):
    """The model of a node's ``joints`` parameter: 3 = the thesis's ``RobotModel`` (joints
    4-6 locked), 6 = ``SixJointModel`` with the TCP ``tcp_xyz`` [m] in tool0 (issue 30)."""
    import numpy as np
    if joints == 3:
        from irb_description.model import RobotModel
        return RobotModel.load()
    if joints != 6:
        raise ValueError(f'joints must be 3 or 6, not {joints}')
    from irb_description.six_axis_model import SixJointModel
    xyz = np.asarray(tcp_xyz, float)
    if xyz.shape != (3,) or not np.all(np.isfinite(xyz)):
        raise ValueError(f'tcp_xyz must be 3 finite numbers [m], not {list(tcp_xyz)}')
    tcp = np.eye(4)
    tcp[:3, 3] = xyz
    return SixJointModel(tcp)
