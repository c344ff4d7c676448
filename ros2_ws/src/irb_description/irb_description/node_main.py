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

    ``make_node()`` creates the node, ``spin(node)`` runs it (and owns its executor). The
    first SIGINT or SIGTERM stops the node (KeyboardInterrupt out of ``spin``) and blocks both
    signals from then on: a second Ctrl-C during the clean-up (closing files, writing
    statistics) changes nothing, and the exit code is 0.
    """
    install_stop_signals()
    rclpy.init(args=args)
    node = None
    try:
        try:
            node, interrupted = build_node(make_node)
            if interrupted:
                raise KeyboardInterrupt
            # everything built so far lives as long as the node: out of the collector's way,
            # so that a full collection in the 248 Hz loop does not walk it (a few ms
            # otherwise)
            gc.collect()
            gc.freeze()
            spin(node)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            ignore_stop_signals()
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
            ignore_stop_signals()   # rclpy's shutdown restores the handlers it replaced
    except KeyboardInterrupt:       # raised just before the signals were ignored: cleaned up
        pass


_SIGNALS = {signal.SIGINT, signal.SIGTERM}


_state = {'deferring': False, 'pending': False}


def build_node(make_node):
    """(node, interrupted): ``make_node()`` with a Ctrl-C (handled by ``install_stop_signals``)
    deferred until the node exists, so that a KeyboardInterrupt can never fall between its
    construction and the caller holding it (whose clean-up would then be skipped).
    ``interrupted``: a Ctrl-C came meanwhile (rclpy's own handler may also have shut the
    context down: a construction that failed because of that is an interruption too)."""
    _state['deferring'] = True
    try:
        node = make_node()
    except BaseException:
        if _state['pending'] or not rclpy.ok():
            raise KeyboardInterrupt from None
        raise
    finally:
        _state['deferring'] = False
    return node, _state['pending'] or not node.context.ok()


def ignore_stop_signals() -> None:
    """SIGINT and SIGTERM ignored by the whole process (every thread) from now on; Python's
    finalisation keeps SIG_IGN, so a late Ctrl-C cannot kill the exiting process either."""
    for s in _SIGNALS:
        signal.signal(s, signal.SIG_IGN)


def install_stop_signals() -> None:
    """Call before rclpy.init (main thread): the first SIGINT/SIGTERM raises
    KeyboardInterrupt once (after rclpy's own handler, which it chains to), later ones are
    ignored, so a second Ctrl-C cannot interrupt the clean-up."""
    for s in _SIGNALS:
        signal.signal(s, _first_signal)


def _first_signal(signum, frame):
    ignore_stop_signals()
    if _state['deferring']:             # inside build_node: raised there, once the node exists
        _state['pending'] = True
        return
    raise KeyboardInterrupt


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


def spin_until_signal(executor, timeout_sec: float = 0.1, until=None) -> None:
    """spin_once loop that ends on SIGINT/SIGTERM *between* callbacks (or when ``until()``).

    A KeyboardInterrupt raised inside a callback is caught and logged by the executor as a
    failure; here the signal only sets a flag, so the node shuts down cleanly. Also the way
    to drive an EventsExecutor (its spin() ignores SIGTERM).
    """
    stop = threading.Event()
    previous = {s: signal.signal(s, lambda *_: stop.set())
                for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        while rclpy.ok() and not stop.is_set() and not (until is not None and until()):
            executor.spin_once(timeout_sec=timeout_sec)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
