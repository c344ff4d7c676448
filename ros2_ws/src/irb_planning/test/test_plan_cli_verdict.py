"""`plan` waits for the controller's verdict (issue 32): a fake planner service and a fake
controller on a private Context answer; the client runs as users run it (``main``) and exits
0 when the controller accepted the plan, 3 with the reason when it refused it, 0 with no
controller listening. Every wait is bounded."""
import os
import threading
import uuid

import pytest

rclpy = pytest.importorskip('rclpy')
from irb_description.node_main import latched_qos  # noqa: E402
from irb_interfaces.msg import PlanStatus  # noqa: E402
from irb_interfaces.srv import PlanPath  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from trajectory_msgs.msg import JointTrajectoryPoint  # noqa: E402

from irb_planning import plan_cli  # noqa: E402

pytestmark = pytest.mark.ros


@pytest.fixture
def graph():
    """plan_path answers every request with a one-point plan stamped uniquely; a
    controller (``verdict``: None = no controller) publishes its latched PlanStatus on it."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '41')))
    ns = f'/verdict_{uuid.uuid4().hex[:8]}'
    node = rclpy.create_node('fake_planner', namespace=ns, context=ctx)
    status_pub = {}
    setup = {'verdict': None, 'stamp': 0}

    def plan(request, response):
        setup['stamp'] += 1
        response.success = True
        response.trajectory.joint_names = ['joint_1', 'joint_2', 'joint_3']
        response.trajectory.points = [JointTrajectoryPoint(positions=[0.0] * 3,
                                                           velocities=[0.0] * 3,
                                                           effort=[0.0] * 3)]
        response.trajectory.header.stamp.sec = 100 + setup['stamp']
        if setup['verdict'] is not None:
            if 'pub' not in status_pub:
                status_pub['pub'] = node.create_publisher(PlanStatus, 'pdplus/plan_status',
                                                          latched_qos())
            ok, reason = setup['verdict']
            m = PlanStatus(accepted=ok, reason=reason, points=1)
            m.plan_stamp = response.trajectory.header.stamp
            status_pub['pub'].publish(m)
        return response
    node.create_service(PlanPath, 'plan_path', plan)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    yield ns, setup, status_pub
    executor.shutdown()
    spinner.join(30)
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)


def run_plan(ns, capsys, status=True):
    args = ['plan', '--plot', '', '--service', f'{ns}/plan_path', '--timeout', '60',
            '--verdict-timeout', '30']
    if status:
        args += ['--plan-status', f'{ns}/pdplus/plan_status']
    code = plan_cli.main(args)
    out = capsys.readouterr()
    return code, out.out + out.err


def test_plan_exits_with_the_controllers_refusal(graph, capsys):
    ns, setup, _ = graph
    # a first plan with a controller that accepts it: the publisher exists from now on
    setup['verdict'] = (True, '')
    code, text = run_plan(ns, capsys)
    assert code == 0 and 'plan accepted' in text, text
    setup['verdict'] = (False, 'joint trajectory does not follow the path: 12.0 mm')
    code, text = run_plan(ns, capsys)
    assert code == 3, text
    assert 'plan refused: joint trajectory does not follow the path: 12.0 mm' in text


def test_plan_without_a_controller_behaves_as_before(graph, capsys):
    ns, setup, _ = graph
    code, text = run_plan(ns, capsys)
    assert code == 0 and 'no controller listens' in text, text
