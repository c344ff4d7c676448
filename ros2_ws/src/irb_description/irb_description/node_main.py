"""What every node of this workspace shares: the main() idiom, parameters with descriptions, the
QoS of the 248 Hz and latched topics, a spin loop that ends on a signal between callbacks
(lives here because every node package depends on irb_description)."""
from __future__ import annotations

import gc
import signal
import threading

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


def run_node(make_node, spin, args=None) -> None:
    """The Jazzy main idiom, robust to Ctrl-C at any moment, also while the node is built.

    ``make_node()`` creates the node, ``spin(node)`` runs it (and owns its executor).
    """
    rclpy.init(args=args)
    node = None
    try:
        node = make_node()
        # everything built so far lives as long as the node: out of the collector's way, so
        # that a full collection in the 248 Hz loop does not walk it (a few ms otherwise)
        gc.collect()
        gc.freeze()
        spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


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
