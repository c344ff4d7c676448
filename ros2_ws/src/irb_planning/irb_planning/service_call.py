"""One request to a service from a command-line client, waited for with a bound (rclpy).

Shared by the ``plan`` and ``place --node`` clients: a private node and executor on the
default context, ROS_SECURITY_ENABLE never ignored, the service looked for at most 30 s (or
the timeout if shorter), the answer at most ``timeout``; every way it ends is an exit code and
at most one line on stderr, never a traceback.
"""
from __future__ import annotations

import sys
from typing import Callable


def call_service(srv_type, service: str, request, timeout: float, node_name: str,
                 on_answer: Callable[[object], int], args=None, asking: str = '') -> int:
    """The exit code of ``on_answer(response)`` (run while the node is still up, so that a
    Ctrl-C during it is one too), or 2 when the service is not there or does not answer
    within ``timeout`` [s], 130 on Ctrl-C. ``asking``: printed once the service is found,
    before the request is sent ('' = nothing)."""
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
        executor.spin_until_future_complete(future, timeout_sec=timeout)
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
