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
from rclpy.signals import SignalHandlerOptions


def run_node(make_node, spin, args=None) -> None:
    """The Jazzy main idiom, robust to Ctrl-C at any moment, also while the node is built.

    ``make_node()`` creates the node, ``spin(node)`` runs it (and owns its executor); spin
    loops run while ``running()``. The first SIGINT or SIGTERM only requests the stop (see
    ``init``): the loop ends between callbacks, the node is destroyed with its context still
    valid (statistics written, files closed, last log lines published) and the exit code is
    0; later signals are ignored, so a second Ctrl-C cannot cut the clean-up.
    """
    init(args)
    node = None
    try:
        node, interrupted = build_node(make_node)
        if not interrupted:
            # everything built so far lives as long as the node: out of the collector's way,
            # so that a full collection in the 248 Hz loop does not walk it (a few ms
            # otherwise)
            gc.collect()
            gc.freeze()
            spin(node)
    except ExternalShutdownException:
        pass
    finally:
        ignore_stop_signals()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_stop = threading.Event()


def init(args=None) -> None:
    """rclpy.init for a node's main(): SIGINT/SIGTERM handled here, not by rclpy.

    rclpy's own handler shuts the context down from a thread of its own at any moment, so a
    callback (or a loop between callbacks) meets "publisher's context is invalid" errors,
    and a KeyboardInterrupt raised inside a running callback is logged by the executor as a
    FATAL failure with its traceback. Here the first signal only sets the stop request that
    ``running()`` reports (so the loops end between callbacks); later ones are ignored."""
    for s in _SIGNALS:
        signal.signal(s, _first_signal)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)


def _first_signal(signum, frame):
    ignore_stop_signals()
    _stop.set()


def stop_requested() -> bool:
    """True once SIGINT or SIGTERM came (after ``init``)."""
    return _stop.is_set()


def running(context=None) -> bool:
    """The condition of every spin loop: the context is valid and no stop was requested."""
    return not _stop.is_set() and rclpy.ok(context=context)


def build_node(make_node):
    """(node, interrupted): ``make_node()``, and whether a stop was requested before or during
    it (the caller destroys the node and exits 0 then)."""
    node = make_node()
    return node, not running(node.context)


def ignore_stop_signals() -> None:
    """SIGINT and SIGTERM ignored by the whole process (every thread) from now on; Python's
    finalisation keeps SIG_IGN, so a late Ctrl-C cannot kill the exiting process either."""
    for s in _SIGNALS:
        signal.signal(s, signal.SIG_IGN)


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
    """spin_once loop while ``running()`` and not ``until()``: a stop request (SIGINT/SIGTERM
    after ``init``) ends it between callbacks, within ``timeout_sec``. Also the way to drive
    an EventsExecutor or a MultiThreadedExecutor (their spin() does not see the request)."""
    context = getattr(executor, 'context', None)    # the EventsExecutor has none
    while running(context) and not (until is not None and until()):
        executor.spin_once(timeout_sec=timeout_sec)
