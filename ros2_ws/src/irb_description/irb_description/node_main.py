"""The main() idiom every node of this workspace shares (lives here because every node package
depends on irb_description)."""
from __future__ import annotations

import gc

import rclpy
from rclpy.executors import ExternalShutdownException


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
