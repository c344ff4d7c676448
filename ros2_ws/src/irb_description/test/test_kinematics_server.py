"""SolveIk across two processes: the server started with `ros2 run`, this test the client."""
import os
import signal
import subprocess
import uuid

import numpy as np
import pytest
from numpy.testing import assert_allclose

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import Point  # noqa: E402
from irb_interfaces.srv import SolveIk  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from irb_description.output_lines import popen_lines  # noqa: E402

pytestmark = pytest.mark.ros


@pytest.fixture
def server():
    name = f'/test_solve_ik_{uuid.uuid4().hex[:8]}'
    proc = popen_lines(
        ['ros2', 'run', 'irb_description', 'kinematics_server', '--ros-args',
         '-r', f'solve_ik:={name}', '-r', f'__node:=kin_{uuid.uuid4().hex[:6]}'],
        start_new_session=True)
    yield name, proc
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)      # Ctrl-C: the whole group, once
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


@pytest.fixture
def client_node():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '0')))
    node = rclpy.create_node(f'ik_client_{uuid.uuid4().hex[:6]}', context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    yield node, executor
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)


def call(node, executor, name, points):
    client = node.create_client(SolveIk, name)
    assert client.wait_for_service(timeout_sec=60.0), 'kinematics_server did not come up'
    future = client.call_async(SolveIk.Request(points=points))
    executor.spin_until_future_complete(future, timeout_sec=60.0)
    assert future.done(), 'no response within 60 s'
    return future.result()


def test_solve_ik_across_processes(server, client_node, model):
    name, proc = server
    node, executor = client_node
    targets = [np.array([0.75, 0.0, 0.13]), np.array([0.6, 0.15, 0.13]),
               np.array([0.5, -0.2, 0.6])]
    res = call(node, executor, name, [Point(x=p[0], y=p[1], z=p[2]) for p in targets])
    assert res.success, res.message
    assert list(res.joint_names) == model.joint_names
    assert list(res.reachable) == [True] * 3
    for p, sol in zip(targets, res.solutions):
        assert_allclose(sol.positions, model.ik(p), atol=1e-12)
        assert_allclose(model.fk(np.array(sol.positions)), p, atol=1e-9)

    # an unreachable point is reported, the server keeps serving
    res = call(node, executor, name, [Point(x=3.0, y=0.0, z=0.0), Point(x=0.7, y=0.0, z=0.3)])
    assert not res.success and 'point 0' in res.message
    assert list(res.reachable) == [False, True]
    assert np.all(np.isnan(res.solutions[0].positions))

    os.killpg(proc.pid, signal.SIGINT)      # Ctrl-C: the whole group, once
    assert proc.wait(timeout=30) == 0, proc.out.rest()
