"""Small helpers shared by the node files (parameters with descriptions, QoS)."""
from __future__ import annotations

import signal
import threading

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy)


def declare(node: Node, name: str, default, description: str):
    """Declare a parameter with a description (units in brackets) and return its value."""
    return node.declare_parameter(name, default, ParameterDescriptor(
        description=description)).value


def state_qos() -> QoSProfile:
    """248 Hz state and command topics: best effort, keep last 1."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)


def latched_qos() -> QoSProfile:
    """Plans: reliable, transient local, keep last 1 (late joiners get the last plan)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def make_executor(kind: str, context=None):
    """'events': rclpy's EventsExecutor (faster; drive it with spin_once), else single."""
    if kind == 'events':
        try:
            from rclpy.experimental import EventsExecutor
            return EventsExecutor(context=context)
        except ImportError:
            pass
    return SingleThreadedExecutor(context=context)


def spin_until_signal(executor, timeout_sec: float = 0.1) -> None:
    """spin_once loop that ends on SIGINT/SIGTERM *between* callbacks.

    A KeyboardInterrupt raised inside a callback is caught and logged by the executor as a
    failure; here the signal only sets a flag, so the node shuts down cleanly. Also the way
    to drive an EventsExecutor (its spin() ignores SIGTERM).
    """
    stop = threading.Event()
    previous = {s: signal.signal(s, lambda *_: stop.set())
                for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        while rclpy.ok() and not stop.is_set():
            executor.spin_once(timeout_sec=timeout_sec)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def run_node(make_node, spin, args=None) -> None:
    """The Jazzy main idiom, robust to Ctrl-C at any moment, also while the node is built.

    ``make_node()`` creates the node, ``spin(node)`` runs it (and owns its executor).
    """
    rclpy.init(args=args)
    node = None
    try:
        node = make_node()
        spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


def spin_with(executor_kind: str):
    """spin(node) for run_node: an executor of ``executor_kind`` driven by spin_until_signal."""
    def spin(node):
        executor = make_executor(executor_kind)
        executor.add_node(node)
        try:
            spin_until_signal(executor)
        finally:
            executor.shutdown()
    return spin
