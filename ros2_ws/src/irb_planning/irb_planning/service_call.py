"""One request to a service from a command-line client, waited for with a bound (rclpy).

Shared by the ``plan`` and ``place --node`` clients: a private node and executor on the
default context, ROS_SECURITY_ENABLE never ignored, the service looked for at most 30 s (or
the timeout if shorter), the answer at most ``timeout``; every way it ends is an exit code and
at most one line on stderr, never a traceback. While it waits for the answer it watches the
service: a server that goes away (its node destroyed or its process ended) ends the wait after
``GONE_GRACE`` s instead of at the timeout, which was up to an hour for a placement search.
A server killed with SIGKILL is seen gone only when DDS notices its participant's lease
expired (Fast DDS: 20 s by default); a clean exit is seen at once.
"""
from __future__ import annotations

import sys
import time
from typing import Callable

#: how often the wait for the answer checks that the service is still there [s]
WATCH_PERIOD = 0.5
#: how long the service must have been gone before the wait gives up [s]
GONE_GRACE = 1.0


def call_service(srv_type, service: str, request, timeout: float, node_name: str,
                 on_answer: Callable[[object], int], args=None, asking: str = '') -> int:
    """The exit code of ``on_answer(response)`` (run while the node is still up, so that a
    Ctrl-C during it is one too), or 2 when the service is not there or does not answer
    within ``timeout`` [s] or goes away before answering, 130 on Ctrl-C. ``asking``: printed
    once the service is found, before the request is sent ('' = nothing)."""
    import rclpy
    from irb_description.node_main import refuse_insecure_start
    from rclpy.executors import SingleThreadedExecutor
    refuse_insecure_start()        # ROS_SECURITY_ENABLE=true is never ignored
    rclpy.init(args=args)
    node = rclpy.create_node(node_name)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        client = node.create_client(srv_type, service)
        if not client.wait_for_service(timeout_sec=min(timeout, 30.0)):
            print(f'service {service} not available', file=sys.stderr)
            return 2
        if asking:
            print(asking, flush=True)
        future = client.call_async(request)
        deadline = time.monotonic() + timeout
        gone_since = None
        while not future.done() and time.monotonic() < deadline:
            executor.spin_until_future_complete(
                future, timeout_sec=min(WATCH_PERIOD, max(deadline - time.monotonic(), 0.0)))
            if future.done():
                break
            if client.service_is_ready():
                gone_since = None
            elif gone_since is None:
                gone_since = time.monotonic()
            elif time.monotonic() - gone_since >= GONE_GRACE:
                print(f'service {service} went away before answering', file=sys.stderr)
                return 2
        if not future.done():
            print(f'no answer within {timeout:g} s', file=sys.stderr)
            return 2
        return on_answer(future.result())
    except KeyboardInterrupt:
        return 130
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
