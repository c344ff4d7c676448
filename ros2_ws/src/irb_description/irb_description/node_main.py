"""What every node of this workspace shares: the main() idiom, parameters with descriptions, the
QoS of the 248 Hz and latched topics, a spin loop that ends on a signal between callbacks
(lives here because every node package depends on irb_description)."""
from __future__ import annotations

import gc
import os
import signal
import sys
import threading
from pathlib import Path

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy_impl
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from .node_help import exit_if_help


def run_node(make_node, spin, args=None, spec=None) -> None:
    """The Jazzy main idiom, robust to Ctrl-C at any moment, also while the node is built.

    ``spec`` (a ``node_help.NodeSpec`` or a usage text): ``--help`` prints it and exits 0
    before anything starts.

    ``make_node()`` creates the node, ``spin(node)`` runs it (and owns its executor); spin
    loops run while ``running()``. The first SIGINT or SIGTERM only requests the stop (see
    ``init``): the loop ends between callbacks, the node is destroyed with its context still
    valid (statistics written, files closed, last log lines published) and the exit code is
    0; later signals are ignored, so a second Ctrl-C cannot cut the clean-up.
    """
    if spec is not None:
        exit_if_help(args, spec)
    init(args)
    node = None
    refused = ''
    try:
        try:
            node, interrupted = build_node(make_node)
        except CONFIG_ERRORS as exc:
            # a parameter of the wrong type, a value the node refuses, a file it cannot read:
            # one line naming it, exit 2 (no traceback)
            refused = _one_line(exc)
        else:
            if not interrupted:
                # everything built so far lives as long as the node: out of the collector's
                # way, so that a full collection in the 248 Hz loop does not walk it (a few ms
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
    if refused:
        name = getattr(spec, 'executable', '') or Path(sys.argv[0]).name
        print(f'{name}: {refused}', file=sys.stderr, flush=True)
        sys.exit(2)


def config_errors() -> tuple:
    from rclpy.exceptions import (InvalidParameterTypeException,
                                  InvalidParameterValueException, ParameterException)
    return (InvalidParameterTypeException, InvalidParameterValueException, ParameterException,
            ValueError, FileNotFoundError)


CONFIG_ERRORS = config_errors()


def _one_line(exc: BaseException) -> str:
    text = ' '.join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 400 else text[:397] + '...'


_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_stop = threading.Event()


def init(args=None) -> None:
    """rclpy.init for a node's main(): SIGINT/SIGTERM handled here, not by rclpy.

    rclpy's own handler shuts the context down from a thread of its own at any moment, so a
    callback (or a loop between callbacks) meets "publisher's context is invalid" errors,
    and a KeyboardInterrupt raised inside a running callback is logged by the executor as a
    FATAL failure with its traceback. Here the first signal only sets the stop request that
    ``running()`` reports (so the loops end between callbacks); later ones are ignored."""
    refuse_insecure_start()
    for s in _SIGNALS:
        signal.signal(s, _first_signal)
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except _rclpy_impl.RCLError as exc:
        if not security_requested():
            raise
        # Enforce strategy: no keystore / enclave for this node -> one line, no traceback
        _refuse(f'ROS_SECURITY_ENABLE=true but the security set-up failed: '
                f'{str(exc).splitlines()[0]}')


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


_ARRAY_TYPES = {'bool[]': Parameter.Type.BOOL_ARRAY, 'int[]': Parameter.Type.INTEGER_ARRAY,
                'double[]': Parameter.Type.DOUBLE_ARRAY,
                'string[]': Parameter.Type.STRING_ARRAY}


def coerce_overrides(node, params) -> None:
    """Let a parameter take the types a user types: ``rate:=0`` for a double (an integer on
    the command line), ``[1, 2]`` for a double array. rclpy refuses an INTEGER override of a
    DOUBLE parameter (InvalidParameterTypeException); the override is converted to the
    declared type before declaring."""
    overrides = getattr(node, '_parameter_overrides', None)
    if not overrides:
        return
    for p in params:
        given = overrides.get(p.name)
        if given is None:
            continue
        v = given.value
        if isinstance(p.default, float) and isinstance(v, int) and not isinstance(v, bool):
            overrides[p.name] = Parameter(p.name, Parameter.Type.DOUBLE, float(v))
        elif (isinstance(p.default, list) and p.default and isinstance(p.default[0], float)
              and isinstance(v, (list, tuple)) and v
              and all(isinstance(x, int) and not isinstance(x, bool) for x in v)):
            overrides[p.name] = Parameter(p.name, Parameter.Type.DOUBLE_ARRAY,
                                          [float(x) for x in v])


def declare_params(node: Node, params, only=None) -> dict:
    """Declare every ``node_help.Param`` of ``params`` (a ``NodeSpec``'s ``params``) with its
    description and unit; {name: value} (the value given on the command line or in a params
    file, else the default; an integer given for a double is taken as that double).
    ``only``: names to declare (None: all)."""
    coerce_overrides(node, params)
    out = {}
    for p in params:
        if only is not None and p.name not in only:
            continue
        desc = ParameterDescriptor(description=p.described())
        if isinstance(p.default, list) and not p.default:
            value = node.declare_parameter(p.name, _ARRAY_TYPES[p.type], desc).value
            out[p.name] = list(value) if value is not None else []
        else:
            out[p.name] = node.declare_parameter(p.name, p.default, desc).value
    return out


def state_qos() -> QoSProfile:
    """Subscriptions of the 248 Hz state and command topics (the control loop and its
    observers): best effort, keep last 1 -- a lost sample is never resent (the next one,
    4 ms later, is newer), nothing queues behind a slow link."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)


# 248 Hz publishers keep the last 250 samples (1 s at 248 Hz, ~60 kB per topic): what a reliable
# reader on another host (the recorder) can still have resent after a lost packet or a stall
# of its own. Measured with the recorder behind 1 ms links (irb_bringup/test/test_hosts.py,
# lockstep at ~700 states/s): at 1 % loss depth 1 lost 13-18 of ~1700 joint states per run
# (a lost packet is gone), depth 100 0-2; at load 11 depth 100 once lost a burst of 33 (the
# recorder fell behind by more than the depth), depth 250 none in 5 runs at load 9-11.
# Keep-last never blocks the publisher, whatever the depth.
# Raised to 2500 (10 s at 248 Hz, ~0.4 MB per topic) for issue 31: a recorder in lockstep
# beside two CPU burners (7 topics, load 25) lost 3.8 % with 250 and 0.43 % with 2500, all of
# it to samples the publisher had already overwrote while the recorder got no CPU
# (irb_identification/benchmarks/RESULTS.md).
STATE_PUB_DEPTH = 2500


def state_pub_qos() -> QoSProfile:
    """Publishers of the 248 Hz state and command topics: reliable, keep last
    ``STATE_PUB_DEPTH``, volatile. A reliable writer matches both best-effort readers (the
    loop: ``state_qos``, served without acknowledgements or resends) and reliable ones (the
    ROS default of ``ros2 topic echo``, rqt, user nodes, the recorder; a best-effort writer
    gives those only an incompatible-QoS warning). Keep-last never blocks ``publish``: a
    reader that falls further behind than the depth skips samples instead of slowing the
    loop."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=STATE_PUB_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def latched_qos() -> QoSProfile:
    """Plans: reliable, transient local, keep last 1 (late joiners get the last plan)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


SECURITY_REFUSED_EXIT = 3


def security_requested() -> bool:
    """ROS_SECURITY_ENABLE=true (rcl's test: exactly the string 'true')."""
    return os.environ.get('ROS_SECURITY_ENABLE', '') == 'true'


def _prefixes() -> list[Path]:
    seen, out = set(), []
    for var in ('AMENT_PREFIX_PATH', 'CMAKE_PREFIX_PATH'):
        for d in os.environ.get(var, '').split(os.pathsep):
            if d and d not in seen:
                seen.add(d)
                out.append(Path(d))
    out.append(Path(sys.prefix))
    return out


def middleware_security_support(rmw: str | None = None) -> tuple[bool | None, str]:
    """(supported, evidence) for DDS security in the RMW this process will load: False with
    the evidence when the build says it has none, None when it cannot tell.

    rmw_fastrtps: Fast DDS writes its build options into ``include/fastrtps/config.h``
    (``HAVE_SECURITY``), and an rmw_fastrtps_shared_cpp compiled without security carries
    the message it returns when a keystore is given ("doesn't have the security
    libraries"). The PyPI wheels have HAVE_SECURITY 0; ROS 2 Jazzy's Debian packages 1."""
    rmw = (rmw or os.environ.get('RMW_IMPLEMENTATION')
           or rclpy.get_rmw_implementation_identifier())
    if not rmw.startswith('rmw_fastrtps'):
        return None, f'{rmw}: not inspected'
    for prefix in _prefixes():
        for lib in sorted((prefix / 'lib').glob('librmw_fastrtps_shared_cpp.so*')):
            try:
                if b"doesn't have the security libraries" in lib.read_bytes():
                    return False, f'{lib} was built without DDS security'
            except OSError:
                continue
        for header in (prefix / 'include' / 'fastrtps' / 'config.h',
                       prefix / 'include' / 'fastdds' / 'config.h'):
            try:
                text = header.read_text()
            except OSError:
                continue
            for line in text.splitlines():
                parts = line.split()
                if parts[:2] == ['#define', 'HAVE_SECURITY'] and len(parts) > 2:
                    return parts[2] != '0', f'{header}: HAVE_SECURITY {parts[2]}'
    return None, f'{rmw}: no build information found'


def _refuse(text: str) -> None:
    print(f'refusing to start: {text}', file=sys.stderr, flush=True)
    raise SystemExit(SECURITY_REFUSED_EXIT)


def refuse_insecure_start() -> None:
    """Never run open when the user asked for security: with ROS_SECURITY_ENABLE=true a
    middleware without DDS security ends the process with one line (exit 3), and rcl's
    strategy is set to Enforce, so a missing keystore or enclave fails instead of falling
    back to an unsecured participant (rcl's Permissive default does that). Called by
    ``init``; tools that call rclpy.init themselves call it first."""
    if not security_requested():
        return
    supported, evidence = middleware_security_support()
    if supported is False:
        _refuse(f'ROS_SECURITY_ENABLE=true but this middleware has no DDS security '
                f'({evidence}); install ROS 2 with SROS2 support (README, "deployment on '
                f'several machines") or unset ROS_SECURITY_ENABLE')
    if os.environ.get('ROS_SECURITY_STRATEGY') != 'Enforce':
        os.environ['ROS_SECURITY_STRATEGY'] = 'Enforce'


def spin_until_signal(executor, timeout_sec: float = 0.1, until=None) -> None:
    """spin_once loop while ``running()`` and not ``until()``: a stop request (SIGINT/SIGTERM
    after ``init``) ends it between callbacks, within ``timeout_sec``. Also the way to drive
    an EventsExecutor or a MultiThreadedExecutor (their spin() does not see the request)."""
    context = getattr(executor, 'context', None)    # the EventsExecutor has none
    while running(context) and not (until is not None and until()):
        executor.spin_once(timeout_sec=timeout_sec)
