"""The planner node in-process: private Context, explicit executor, futures (no sleeps)."""
import os
import uuid

import pytest

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import Point  # noqa: E402
from irb_interfaces.msg import PathSpec  # noqa: E402
from irb_interfaces.srv import PlanPath  # noqa: E402
from rcl_interfaces.srv import GetParameters  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from trajectory_msgs.msg import JointTrajectory  # noqa: E402

from irb_planning import messages  # noqa: E402
from irb_planning.planner_node import PlannerNode  # noqa: E402
from irb_planning.planner import limit_cost_from_message  # noqa: E402

pytestmark = pytest.mark.ros
TIMEOUT = 120.0


@pytest.fixture
def ros():
    yield from _ros([])


@pytest.fixture
def ros_quick():
    """Without the extra solve of the cost of the smoothness limits (limit_cost)."""
    yield from _ros([Parameter('limit_cost', value=False)])


def _ros(extra):
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '41')))
    ns = f'/planner_test_{uuid.uuid4().hex[:8]}'
    server = PlannerNode(context=ctx, namespace=ns,
                         parameter_overrides=[Parameter('grid_size', value=40),
                                              Parameter('evaluation_rate_hz', value=500.0)]
                         + extra)
    client = rclpy.create_node('planner_test_client', namespace=ns, context=ctx)
    executor = MultiThreadedExecutor(num_threads=3, context=ctx)
    executor.add_node(server)
    executor.add_node(client)
    yield server, client, executor, ns
    executor.shutdown()
    client.destroy_node()
    server.destroy_node()
    rclpy.try_shutdown(context=ctx)


def _request(**kw):
    req = PlanPath.Request()
    req.path = PathSpec(type='circle', center=Point(x=0.6, y=0.0, z=0.13), radius=0.15,
                        direction=1)
    req.objective = 'energy'
    for k, v in kw.items():
        if k == 'radius':
            req.path.radius = v
        else:
            setattr(req, k, v)
    return req


def _call(client, executor, cli, req):
    future = cli.call_async(req)
    executor.spin_until_future_complete(future, timeout_sec=TIMEOUT)
    assert future.done(), 'no answer in time'
    return future.result()


def test_plan_latch_and_keep_serving_after_bad_requests(ros, model):
    server, client, executor, ns = ros
    cli = client.create_client(PlanPath, 'plan_path')
    assert cli.wait_for_service(timeout_sec=30.0)

    resp = _call(client, executor, cli, _request(duration=4.0))
    assert resp.success, resp.message
    assert resp.error_code == PlanPath.Response.ERROR_NONE
    assert list(resp.trajectory.joint_names) == model.joint_names
    pts = resp.trajectory.points
    # at least the 40 nodes; more where quintic interpolation needs them to stay on the path
    assert len(pts) >= 40 and len(pts[0].effort) == 3 and len(pts[0].accelerations) == 3
    assert resp.theta_interpolation == PlanPath.Response.INTERPOLATION_QUADRATIC
    t_end = pts[-1].time_from_start.sec + 1e-9 * pts[-1].time_from_start.nanosec
    assert t_end == pytest.approx(4.0, rel=1e-6)
    assert resp.energy == pytest.approx(resp.optimizer_energy, rel=0.01)
    assert resp.energy <= resp.baseline_energy and resp.baseline_feasible
    # the cost of the smoothness limits, on by default (issue 28), in the answer's message
    cost = limit_cost_from_message(resp.message)
    assert cost is not None and cost['quantity'] == 'energy'
    assert cost['with'] == pytest.approx(resp.optimizer_energy, rel=1e-5)
    assert cost['without'] <= cost['with'] * (1 + 1e-5)

    # a late subscriber still gets the latched plan and theta profile
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         reliability=ReliabilityPolicy.RELIABLE)
    got_traj = rclpy.task.Future()
    got_theta = rclpy.task.Future()
    client.create_subscription(JointTrajectory, 'planned_trajectory',
                               lambda m: got_traj.done() or got_traj.set_result(m), latched)
    client.create_subscription(Float64MultiArray, 'planned_theta_profile',
                               lambda m: got_theta.done() or got_theta.set_result(m), latched)
    executor.spin_until_future_complete(got_traj, timeout_sec=TIMEOUT)
    executor.spin_until_future_complete(got_theta, timeout_sec=TIMEOUT)
    assert got_traj.done() and len(got_traj.result().points) == len(pts)
    # each plan carries its own stamp (pdplus's verdict names it), the same in the response
    assert resp.trajectory.header.stamp.sec > 0
    assert got_traj.result().header.stamp == resp.trajectory.header.stamp
    prof = messages.profile_from_msg(got_theta.result())
    assert prof['t'][-1] == pytest.approx(4.0, rel=1e-6)
    assert list(prof['theta_dot']) == pytest.approx(list(resp.theta_dot))

    # bad requests: specific codes, and the node keeps serving
    for req, code in [(_request(duration=4.0, radius=-0.1),
                       PlanPath.Response.ERROR_INVALID_REQUEST),
                      (_request(duration=4.0, objective='nope'),
                       PlanPath.Response.ERROR_INVALID_REQUEST),
                      (_request(duration=0.01), PlanPath.Response.ERROR_INFEASIBLE_DURATION),
                      (_request(duration=4.0, friction_map='/no/such/map.yaml'),
                       PlanPath.Response.ERROR_FRICTION_MAP),
                      (_request(duration=4.0, friction_map='/proc/self/status'),
                       PlanPath.Response.ERROR_FRICTION_MAP),
                      (_request(duration=1e6), PlanPath.Response.ERROR_INFEASIBLE_DURATION)]:
        bad = _call(client, executor, cli, req)
        assert not bad.success and bad.error_code == code and bad.message
        assert 'Name:' not in bad.message and 'Error' not in bad.message
    again = _call(client, executor, cli, _request(objective='trapezoid', duration=3.0))
    assert again.success, again.message
    assert again.trajectory.header.stamp != resp.trajectory.header.stamp
    # energy: the message as played (quintic between points); baseline: the exact profile.
    # For a trapezoid request they are the same motion, apart from the interpolation (~1e-5)
    assert again.energy == pytest.approx(again.baseline_energy, rel=1e-4)
    assert again.theta_interpolation == PlanPath.Response.INTERPOLATION_LINEAR


def test_solve_does_not_block_other_callbacks(ros_quick):
    server, client, executor, ns = ros_quick
    cli = client.create_client(PlanPath, 'plan_path')
    params = client.create_client(GetParameters, f'{ns}/planner/get_parameters')
    assert cli.wait_for_service(timeout_sec=30.0)
    assert params.wait_for_service(timeout_sec=30.0)
    # a big new grid: building and solving takes seconds
    plan_future = cli.call_async(_request(duration=3.0, grid_size=400))
    param_future = params.call_async(GetParameters.Request(names=['grid_size']))
    executor.spin_until_future_complete(param_future, timeout_sec=TIMEOUT)
    assert param_future.done()
    assert param_future.result().values[0].integer_value == 40
    assert not plan_future.done(), 'the parameter answer should come before the plan'
    executor.spin_until_future_complete(plan_future, timeout_sec=TIMEOUT)
    assert plan_future.done() and plan_future.result().success, plan_future.result().message
