"""Helpers of the loop nodes: realtime scheduling, executors, spin (declare, QoS and
spin_until_signal live in irb_description.node_main, shared by every node package)."""
from __future__ import annotations

import os
import threading

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from irb_description.node_main import declare, spin_until_signal


def declare_realtime(node: Node) -> tuple[int, list[int]]:
    """Declare ``realtime_priority`` and ``cpu_affinity`` (the same on every loop node) and
    return their values; ValueError for a priority outside 0-99 or a negative CPU."""
    prio = declare(node, 'realtime_priority', 0,
                   'SCHED_FIFO priority 1-99 of the process threads (executor and DDS); 0 = '
                   'normal scheduling. Needs CAP_SYS_NICE or an rtprio limit; a warning, not '
                   'an error, when refused')
    cpus = declare(node, 'cpu_affinity', Parameter.Type.INTEGER_ARRAY,
                   'CPUs the process threads may run on; [] = all') or []
    prio, cpus = int(prio), [int(c) for c in cpus]
    if not 0 <= prio <= 99:
        raise ValueError(f'realtime_priority must be 0 (off) or 1-99, not {prio}')
    if any(c < 0 for c in cpus):
        raise ValueError(f'cpu_affinity: CPU numbers are >= 0, got {cpus}')
    return prio, cpus


def process_threads() -> list[int]:
    """Thread ids of this process (the executor thread and the DDS threads)."""
    try:
        return sorted(int(t) for t in os.listdir('/proc/self/task'))
    except OSError:
        return [threading.get_native_id()]


def apply_realtime(priority: int, cpus=(), logger=None, threads=None) -> dict:
    """SCHED_FIFO ``priority`` (1-99; 0 = leave the scheduling alone) and CPU affinity
    ``cpus`` ([] = leave alone) for ``threads`` (default: every thread of the process now:
    the executor thread and the middleware's receive threads, which are on the
    state -> command path). Threads created later inherit from their creator.

    Never raises for a refusal (no CAP_SYS_NICE / rtprio limit, a CPU that does not exist):
    logs a warning through ``logger`` and reports it. Returns {'priority': applied priority
    or 0, 'cpus': applied CPU list or [], 'warnings': [...]}.
    """
    threads = process_threads() if threads is None else list(threads)
    out = {'priority': 0, 'cpus': [], 'warnings': []}

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
    if logger is not None and (out['priority'] or out['cpus']):
        logger.info(f"realtime: {len(threads)} threads, SCHED_FIFO priority "
                    f"{out['priority'] or 'off'}, CPUs {out['cpus'] or 'all'}")
    return out


def make_executor(kind: str, context=None):
    """'events': rclpy's EventsExecutor (faster; drive it with spin_once), else single."""
    if kind == 'events':
        try:
            from rclpy.experimental import EventsExecutor
            return EventsExecutor(context=context)
        except ImportError:
            pass
    return SingleThreadedExecutor(context=context)


def spin_with(executor_kind: str, realtime: tuple[int, list[int]] = (0, [])):
    """spin(node) for run_node: an executor of ``executor_kind`` driven by spin_until_signal;
    ``realtime`` = (priority, cpus) applied to the process's threads first (apply_realtime)."""
    def spin(node):
        executor = make_executor(executor_kind)
        executor.add_node(node)
        apply_realtime(*realtime, logger=node.get_logger())
        try:
            spin_until_signal(executor)
        finally:
            executor.shutdown()
    return spin
