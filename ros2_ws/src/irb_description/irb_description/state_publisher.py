"""`ros2 run irb_description state_publisher`: /tf from /joint_states through the URDF, latched
/tf_static and /robot_description, and the planned path and the TCP trace as markers.

A robot_state_publisher for the PyPI-wheel ROS 2 (which has none), so that Foxglove, RViz and
bags can draw the robot. Thin adapter over ``robot_state.TfTree`` and ``robot_state.Trace``.
"""
from __future__ import annotations

from .node_help import NodeSpec, Param, Topic

SPEC = NodeSpec(
    'state_publisher', 'irb_description',
    'Publishes /tf (each joint\'s transform, stamped with the joint state\'s stamp) for every '
    '/joint_states message, latched /tf_static (fixed joints) and /robot_description (the '
    'URDF), the planned path (forward kinematics of /planned_trajectory) and the TCP\'s '
    'recent trail as visualization_msgs/MarkerArray. Joints 4-6 missing from a joint state '
    'sit at their locked position; a state without one of joints 1-3 is skipped (warning).',
    params=(
        Param('urdf_file', '', '', 'URDF to publish and to compute with; empty: the '
              "package's urdf/irb1600_6_12.urdf"),
        Param('root_frame', 'base_link', '', 'frame of the markers'),
        Param('tcp_frame', 'tool0', '', 'frame whose origin the TCP trace and the planned '
              'path follow'),
        Param('markers', True, '', 'publish the planned-path and TCP-trace markers'),
        Param('trace_duration_s', 10.0, 's', 'length of the TCP trace (stamp time)'),
        Param('trace_sample_period_s', 0.02, 's', 'one trace point per this much stamp time'),
        Param('trace_rate_hz', 10.0, 'Hz', 'trace publications per second of stamp time'),
        Param('path_line_width_m', 0.004, 'm', 'width of the planned-path line'),
        Param('trace_line_width_m', 0.003, 'm', 'width of the TCP-trace line'),
    ),
    subscribes=(
        Topic('joint_states', 'sensor_msgs/msg/JointState', 'joint positions by name '
              '(reliable, keep last 250)'),
        Topic('planned_trajectory', 'trajectory_msgs/msg/JointTrajectory',
              'the planner\'s trajectory (latched)'),
    ),
    publishes=(
        Topic('/tf', 'tf2_msgs/msg/TFMessage', 'parent -> child of every movable joint, '
              'one message per joint state, its stamp'),
        Topic('/tf_static', 'tf2_msgs/msg/TFMessage', 'fixed joints (latched)'),
        Topic('robot_description', 'std_msgs/msg/String', 'the URDF (latched)'),
        Topic('visualization/planned_path', 'visualization_msgs/msg/MarkerArray',
              'TCP line of the planned trajectory (latched)'),
        Topic('visualization/tcp_trace', 'visualization_msgs/msg/MarkerArray',
              'the TCP\'s recent trail, at trace_rate_hz'),
    ),
    example='ros2 run irb_description state_publisher --ros-args -p trace_duration_s:=20.0',
)

TF_DEPTH = 2500         # as the 248 Hz state publishers (node_main.STATE_PUB_DEPTH)
PATH_COLOR = (0.1, 0.6, 1.0, 1.0)
TRACE_COLOR = (1.0, 0.2, 0.2, 1.0)


def _make_node_class():
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Point, TransformStamped
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import ColorRGBA, String
    from tf2_msgs.msg import TFMessage
    from trajectory_msgs.msg import JointTrajectory
    from visualization_msgs.msg import Marker, MarkerArray

    from .node_main import declare_params, latched_qos, state_pub_qos
    from .params import urdf_path
    from .robot_state import JointStateReader, TfEncoder, TfTree, Trace

    def transform_msg(stamp, parent, child, t, q) -> TransformStamped:
        m = TransformStamped()
        m.header.stamp = stamp
        m.header.frame_id = parent
        m.child_frame_id = child
        tr, ro = m.transform.translation, m.transform.rotation
        tr.x, tr.y, tr.z = t
        ro.x, ro.y, ro.z, ro.w = q
        return m

    def line_marker(ns, frame, stamp, points, width, color) -> Marker:
        m = Marker(ns=ns, id=0, type=Marker.LINE_STRIP, action=Marker.ADD)
        m.header.frame_id = frame
        m.header.stamp = stamp
        m.pose.orientation.w = 1.0
        m.scale.x = width
        m.color = ColorRGBA(r=color[0], g=color[1], b=color[2], a=color[3])
        m.points = [p if isinstance(p, Point) else Point(x=float(p[0]), y=float(p[1]),
                                                          z=float(p[2])) for p in points]
        m.frame_locked = False
        return m

    class StatePublisher(Node):
        def __init__(self, **kwargs):
            super().__init__('state_publisher', **kwargs)
            p = self.p = declare_params(self, SPEC.params)
            path = p['urdf_file'] or str(urdf_path())
            try:
                with open(path, encoding='utf-8') as f:
                    self.urdf = f.read()
                self.tree = TfTree(self.urdf)
                self.tree.pose([0.0] * len(self.tree.names), p['root_frame'], p['tcp_frame'])
            except (OSError, ValueError) as exc:
                raise SystemExit(f'state_publisher: {path}: {exc}') from None
            self.trace = Trace(p['trace_duration_s'], p['trace_sample_period_s'],
                               p['trace_rate_hz'])
            self.pub_tf = self.create_publisher(TFMessage, '/tf', QoSProfile(
                history=HistoryPolicy.KEEP_LAST, depth=TF_DEPTH,
                reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE))
            self.pub_static = self.create_publisher(TFMessage, '/tf_static', latched_qos())
            self.pub_urdf = self.create_publisher(String, 'robot_description', latched_qos())
            self.pub_path = self.pub_trace = None
            if p['markers']:
                self.pub_path = self.create_publisher(MarkerArray, 'visualization/planned_path',
                                                      latched_qos())
                self.pub_trace = self.create_publisher(MarkerArray, 'visualization/tcp_trace',
                                                       10)
                self.create_subscription(JointTrajectory, 'planned_trajectory', self.on_plan,
                                         latched_qos())
            # the 248 Hz path on serialized messages (robot_state.JointStateReader, TfEncoder)
            self._reader = JointStateReader()
            self._encoder = TfEncoder([(j.parent, j.child) for j in self.tree.movable])
            self.create_subscription(JointState, 'joint_states', self.on_state_raw,
                                     state_pub_qos(), raw=True)
            now = self.get_clock().now().to_msg()
            self.pub_static.publish(TFMessage(transforms=[
                transform_msg(now, *x) for x in self.tree.static_transforms()]))
            self.pub_urdf.publish(String(data=self.urdf))
            self._names = None
            self.published = 0
            self.skipped = 0
            self.get_logger().info(
                f'state_publisher: {len(self.tree.movable)} joints {self.tree.names}, '
                f'{len(self.tree.fixed)} fixed, URDF {path}')

        def on_state_raw(self, data: bytes) -> None:
            try:
                sec, nanosec, names, position = self._reader.read(data)
            except ValueError as exc:
                self._skip(str(exc))
                return
            self._state(sec, nanosec, names, position)

        def on_state(self, msg: JointState) -> None:
            """The same for a message object."""
            self._state(msg.header.stamp.sec, msg.header.stamp.nanosec, tuple(msg.name),
                        msg.position)

        def _skip(self, why: str) -> None:
            self.skipped += 1
            self.get_logger().warn(f'{why}: no /tf ({self.skipped} joint states skipped)',
                                   throttle_duration_sec=5.0)

        def _state(self, sec: int, nanosec: int, names: tuple, position) -> None:
            if names is not self._names:
                self._names = names
                self._index = self.tree.index(names)
            q, missing = self.tree.positions_at(self._index, position)
            if q is None:
                self._skip(f'joint_states without {", ".join(missing)}')
                return
            self.pub_tf.publish(self._encoder.encode(sec, nanosec, self.tree.transforms(q)))
            self.published += 1
            if self.pub_trace is None:
                return
            t = sec + nanosec * 1e-9
            tr = self.trace
            if tr.wants(t):
                x, y, z = self.tree.pose(q, self.p['root_frame'], self.p['tcp_frame'])[:3, 3]
                tr.add(t, Point(x=float(x), y=float(y), z=float(z)))
            if tr.due(t) and len(tr.points) >= 2:
                stamp = Time(sec=sec, nanosec=nanosec)
                self.pub_trace.publish(MarkerArray(markers=[line_marker(
                    'tcp_trace', self.p['root_frame'], stamp, tr.points,
                    self.p['trace_line_width_m'], TRACE_COLOR)]))

        def destroy_node(self):
            self.get_logger().info(f'state_publisher: {self.published} /tf published, '
                                   f'{self.skipped} joint states skipped')
            return super().destroy_node()

        def on_plan(self, msg: JointTrajectory) -> None:
            pts = []
            for point in msg.points:
                q, missing = self.tree.positions(msg.joint_names, point.positions)
                if q is None:
                    self.get_logger().warn(f'planned_trajectory without {", ".join(missing)}: '
                                           'no planned-path marker')
                    return
                pts.append(self.tree.pose(q, self.p['root_frame'],
                                          self.p['tcp_frame'])[:3, 3])
            stamp = msg.header.stamp
            self.pub_path.publish(MarkerArray(markers=[line_marker(
                'planned_path', self.p['root_frame'], stamp, pts,
                self.p['path_line_width_m'], PATH_COLOR)]))
            self.get_logger().info(f'planned path: {len(pts)} points')

    return StatePublisher


def make_node(**kwargs):
    """The node (rclpy must be initialised); kwargs go to rclpy's Node (context=...)."""
    return _make_node_class()(**kwargs)


def _spin(node) -> None:
    from rclpy.executors import SingleThreadedExecutor

    from .node_main import spin_until_signal
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spin_until_signal(executor)


def main(args=None):
    from .node_main import run_node
    run_node(make_node, _spin, args, spec=SPEC)


if __name__ == '__main__':
    main()
