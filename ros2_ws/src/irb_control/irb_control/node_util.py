"""Small helpers shared by the node files (parameters with descriptions, QoS)."""
from __future__ import annotations

from rcl_interfaces.msg import ParameterDescriptor
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
