"""The command-line clients' service call when the server goes away mid-call (in-process: a
server on a private Context whose callback holds the request; no sleeps, every wait bounded).

Before, `plan` and `place --node` waited out their whole --timeout (up to an hour for a
search) when the planner node died after taking the request."""
import os
import threading
import time
import uuid

import pytest

rclpy = pytest.importorskip('rclpy')
from irb_interfaces.srv import PlanPath  # noqa: E402
from rclpy.exceptions import InvalidHandle  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from irb_planning import service_call  # noqa: E402

pytestmark = pytest.mark.ros
BOUND = 60.0           # generous bound of every wait [s]
CLIENT_TIMEOUT = 300.0  # the client's own --timeout: far beyond what the test may take


@pytest.fixture
def server():
    """A node on a private context serving plan_path with a callback that signals it has the
    request and then holds it until released."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '41')))
    ns = f'/call_test_{uuid.uuid4().hex[:8]}'
    node = rclpy.create_node('holding_server', namespace=ns, context=ctx)
    entered, release = threading.Event(), threading.Event()

    def hold(request, response):
        entered.set()
        release.wait(BOUND)
        return response
    srv = node.create_service(PlanPath, 'plan_path', hold)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)

    def spin():
        try:
            executor.spin()
        except InvalidHandle:
            # the held request's answer to a service the test destroyed (the server that
            # goes away): nothing left to serve; anything else still fails the thread
            pass
    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    yield node, srv, ns, entered, release
    release.set()
    executor.shutdown()
    spinner.join(BOUND)
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)


def _call_in_thread(ns: str, code: int):
    """The client's call in a thread (it blocks): the thread and where it leaves its exit
    code and the time it ended."""
    result = {}

    def call():
        result['code'] = service_call.call_service(
            PlanPath, f'{ns}/plan_path', PlanPath.Request(), CLIENT_TIMEOUT, 'call_test',
            lambda response: code)
        result['end'] = time.monotonic()
    caller = threading.Thread(target=call, daemon=True)
    caller.start()
    return caller, result


def test_a_server_that_goes_away_ends_the_wait_with_one_line_and_exit_2(server, capsys):
    node, srv, ns, entered, release = server
    caller, result = _call_in_thread(ns, 0)
    assert entered.wait(BOUND), 'the request never reached the server'
    assert caller.is_alive()                 # the client waits for the answer
    gone = time.monotonic()
    node.destroy_service(srv)                # the server goes away with the request
    caller.join(BOUND)
    release.set()
    assert not caller.is_alive(), f'the client still waits {BOUND:g} s after the server left'
    assert result['code'] == 2
    # noticed within a few watch periods, not at the client's timeout
    assert result['end'] - gone < 10 * (service_call.WATCH_PERIOD + service_call.GONE_GRACE)
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f'service {ns}/plan_path went away before answering']


def test_a_server_that_answers_is_not_taken_for_gone(server):
    """The watch must not end a call whose server is there and answers late: the answer
    comes after several watch periods and is the one returned."""
    node, srv, ns, entered, release = server
    caller, result = _call_in_thread(ns, 7)
    assert entered.wait(BOUND)
    # hold the answer over more than three watch periods and the grace (measured by the
    # client's own clock: the wait below is on the caller, bounded)
    caller.join(3 * service_call.WATCH_PERIOD + service_call.GONE_GRACE)
    assert caller.is_alive()
    release.set()
    caller.join(BOUND)
    assert not caller.is_alive() and result['code'] == 7
