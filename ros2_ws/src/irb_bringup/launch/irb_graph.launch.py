"""Launch file for full ROS 2 installs: the same graph as `ros2 run irb_bringup bringup`.

    ros2 launch irb_bringup irb_graph.launch.py [config:=/path/to/bringup.yaml]

Both read config/bringup.yaml through irb_bringup.graph_spec.
"""
from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from irb_bringup.graph_spec import load_graph


def _nodes(context):
    nodes = load_graph(LaunchConfiguration('config').perform(context))
    return [Node(package=n.package, executable=n.executable, name=n.name, output='screen',
                 parameters=[n.parameters] if n.parameters else []) for n in nodes]


def generate_launch_description():
    default = str(Path(get_package_share_directory('irb_bringup')) / 'config'
                  / 'bringup.yaml')
    return LaunchDescription([
        DeclareLaunchArgument('config', default_value=default,
                              description='graph YAML shared with the bringup executable'),
        OpaqueFunction(function=_nodes),
    ])
