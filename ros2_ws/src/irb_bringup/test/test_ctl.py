"""ctl: the pure status text and rates (ctl_core), then the commands against a fake pdplus and
simulator in this process (their services and topics as the real nodes name them, in a
namespace of their own). ctl runs in-process: its own rclpy context is the default one, the
fake graph's a private one."""
from __future__ import annotations

import math
import os
import re
import threading
import time

import pytest
from irb_bringup import ctl_core as core
from irb_bringup.ctl import main
from irb_control.pd_plus import MODE_HOLD, MODE_IDLE, MODE_PATH, MODE_RAMP, MODE_STOPPED

# nodes or processes on the ROS graph: run with the ROS tests, one at a time (scripts/test.sh)
pytestmark = pytest.mark.ros

BOUND_S = 60.0
PERIOD_S = 0.01


# --- pure -----------------------------------------------------------------------------------
def test_topic_rate_from_arrivals():
    r = core.topic_rate('/t', [1.0, 1.01, 1.02, 1.05])
    assert (r.count, r.rate_hz, r.max_gap_s) == (4, pytest.approx(3 / 0.05),
                                                 pytest.approx(0.03))
    assert math.isnan(core.topic_rate('/t', [1.0]).rate_hz)
    assert core.topic_rate('/t', []).count == 0


def test_wait_outcome_follows_a_motion_to_its_end():
    # enable --wait, started while pdplus still holds from before: not done until it moved
    seq = [(MODE_HOLD, False), (MODE_RAMP, True), (MODE_PATH, True), (MODE_HOLD, True)]
    verdicts = [core.wait_outcome('hold', m, '', moved, after_motion=True) for m, moved in seq]
    assert verdicts == [None, None, None, core.OK]
    # ctl wait hold when pdplus already holds (the motion ended before the wait): done at once
    assert core.wait_outcome('hold', MODE_HOLD, '', False) == core.OK
    # a latched stop ends any wait but one for 'stopped', with REFUSED
    assert core.wait_outcome('hold', MODE_STOPPED, 'watchdog', True) == core.REFUSED
    assert core.wait_outcome('stopped', MODE_STOPPED, 'watchdog', False) == core.OK
    # a moving mode is reached without a motion before it
    assert core.wait_outcome('path', MODE_PATH, '', False) == core.OK
    # idle is where pdplus starts: ctl wait idle ends once it is up; enable --wait asks for
    # a resting mode after the motion only
    assert core.wait_outcome('idle', MODE_IDLE, '', False) == core.OK
    assert core.wait_outcome('idle', MODE_IDLE, '', False, after_motion=True) is None
    assert core.wait_outcome('idle', MODE_IDLE, '', True, after_motion=True) == core.OK


def test_wait_arguments_are_checked(capsys):
    assert main(['wait']) == 2
    assert main(['wait', 'sideways']) == 2
    assert main(['status', 'hold']) == 2
    err = capsys.readouterr().err
    assert 'unknown mode' in err and 'goes with wait' in err


def test_names():
    assert core.split_node('/pdplus') == ('/', 'pdplus')
    assert core.split_node('robot1/pdplus') == ('/robot1', 'pdplus')
    assert core.join_name('/', 'joint_states') == '/joint_states'
    assert core.join_name('/robot1/pdplus', 'plan_status') == '/robot1/pdplus/plan_status'


def _snapshot(**kw):
    base = dict(pdplus='/pdplus', pdplus_seen=True, services=['enable', 'stop'],
                controller={'mode': MODE_STOPPED, 'stop_reason': 'stop service',
                            'missed_deadlines': 2, 'rejected_inputs': 0},
                plan={'accepted': False, 'reason': 'path mismatch > 5 mm', 'points': 10,
                      'duration': 0.0, 'accepted_count': 1, 'refused_count': 2},
                axis={'motors_on': False, 'brakes_engaged': True, 'error': 1,
                      'error_text': 'no command for 0.0161 s', 'source': 'simulator'},
                drive_resets=['/simulator/reset'], window_s=1.0,
                rates=[core.TopicRate('/joint_states', 249, 248.0, 0.0051),
                       core.TopicRate('/torque_command', 0, math.nan, math.nan)])
    base.update(kw)
    return core.Snapshot(**base)


def test_status_text_says_what_is_latched_and_how_out():
    text = core.format_status(_snapshot())
    assert text.splitlines()[0] == ('pdplus /pdplus: mode stopped  (missed deadlines 2, '
                                    'rejected inputs 0)')
    assert '  latched stop: stop service' in text
    assert 'ctl enable` ramps back to the start (after `ctl reset`' in text
    assert ('plan: last refused: path mismatch > 5 mm; accepted 1, refused 2 since pdplus '
            'started') in text
    assert ('drive (simulator): motors off, brakes engaged, latched error 0x1: no command '
            'for 0.0161 s') in text
    assert 'ctl reset` clears it (/simulator/reset)' in text
    assert '  /joint_states      248.0 Hz  (249 msgs, largest gap 5.1 ms)' in text
    assert re.search(r'/torque_command +no messages', text)
    assert core.status_code(_snapshot()) == core.OK


def test_status_text_running_and_absent():
    running = _snapshot(controller={'mode': MODE_PATH, 'stop_reason': '',
                                    'missed_deadlines': 0, 'rejected_inputs': 0},
                        plan=None, axis={'motors_on': True, 'brakes_engaged': False,
                                         'error': 0, 'error_text': '', 'source': 'simulator'})
    text = core.format_status(running)
    assert 'mode path' in text and 'latched' not in text and '->' not in text
    assert 'plan: no verdict on plan_status' in text
    assert 'drive (simulator): motors on, brakes released, no error' in text
    absent = _snapshot(pdplus_seen=False, controller=None, axis=None, plan=None)
    assert core.status_code(absent) == core.UNAVAILABLE
    assert 'not found on the graph' in core.format_status(absent)


def test_trigger_outcomes_and_reset_targets():
    assert core.trigger_outcome('enable', '/pdplus/enable', True, 'ok') == (
        0, 'enable (/pdplus/enable): done: ok')
    assert core.trigger_outcome('enable', '/pdplus/enable', False, 'no')[0] == core.REFUSED
    assert core.reset_services(['enable', 'stop'], '/pdplus', ['/simulator/reset']) == [
        '/simulator/reset']
    assert core.reset_services(['reset'], '/pdplus', ['/simulator/reset']) == [
        '/pdplus/reset', '/simulator/reset']
    assert core.missing_service_text('hold', '/pdplus', ['stop', 'enable']) == (
        'hold: /pdplus offers no ~/hold service (it offers: enable, stop)')


# --- against a fake pdplus and simulator ---------------------------------------------------
NS = f'/ctltest{os.getpid()}'
STOP_REASON = 'watchdog: no valid joint_states for 0.0151 s'


@pytest.fixture(scope='module')
def fake_graph():
    """pdplus (~/enable refuses once then accepts, ~/stop; controller_state and joint_states
    every PERIOD_S; a refused plan on ~/plan_status) and simulator (~/reset; an error on
    axis_status), both in NS. Yields the list of service calls received."""
    rclpy = pytest.importorskip('rclpy')
    from irb_description.node_main import latched_qos
    from irb_interfaces.msg import AxisStatus, ControllerState, PlanStatus
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    pd = rclpy.create_node('pdplus', namespace=NS, context=ctx)
    sim = rclpy.create_node('simulator', namespace=NS, context=ctx)
    calls = []
    pub_state = pd.create_publisher(ControllerState, 'controller_state', 10)
    pub_js = sim.create_publisher(JointState, 'joint_states', 10)

    def tick():
        pub_state.publish(ControllerState(mode=MODE_STOPPED, stop_reason=STOP_REASON,
                                          missed_deadlines=3, rejected_inputs=1))
        pub_js.publish(JointState(name=['joint_1'], position=[0.0]))
    pd.create_timer(PERIOD_S, tick)

    def service(node, name, answers):
        def cb(_req, resp):
            calls.append(name)
            resp.success, resp.message = answers[min(calls.count(name), len(answers)) - 1]
            return resp
        node.create_service(Trigger, f'~/{name}', cb)
    service(pd, 'enable', [(False, 'the start is 12.0 s of ramp away'), (True, 'enabled')])
    service(pd, 'stop', [(True, 'stopped (latched until enable)')])
    service(sim, 'reset', [(True, 'error cleared: no command for 0.0161 s')])
    pd.create_publisher(PlanStatus, '~/plan_status', latched_qos()).publish(
        PlanStatus(accepted=False, reason='path mismatch > 5 mm', points=7440,
                   refused_count=1))
    sim.create_publisher(AxisStatus, 'axis_status', latched_qos()).publish(
        AxisStatus(motors_on=False, brakes_engaged=True, error=1,
                   error_text='no command for 0.0161 s', source='simulator'))
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(pd)
    executor.add_node(sim)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    yield calls
    executor.shutdown()
    pd.destroy_node()
    sim.destroy_node()
    rclpy.try_shutdown(context=ctx)
    thread.join(timeout=BOUND_S)


def ctl(*args):
    return main([*args, '--pdplus', f'{NS}/pdplus', '--timeout', '30'])


def test_status_of_a_stopped_controller(fake_graph, capsys):
    assert ctl('status', '--window', '0.5') == 0
    out = capsys.readouterr().out
    assert f'pdplus {NS}/pdplus: mode stopped  (missed deadlines 3, rejected inputs 1)' in out
    assert f'latched stop: {STOP_REASON}' in out
    assert 'services: enable, stop' in out
    assert 'plan: last refused: path mismatch > 5 mm; accepted 0, refused 1' in out
    assert ('drive (simulator): motors off, brakes engaged, latched error 0x1: no command '
            'for 0.0161 s') in out
    assert f'({NS}/simulator/reset)' in out
    assert re.search(rf'{NS}/torque_command +no messages', out)
    for topic in ('joint_states', 'controller_state'):
        m = re.search(rf'{NS}/{topic} +([0-9.]+) Hz +\((\d+) msgs', out)
        assert m, out
        assert 0 < float(m.group(1)) <= 1.2 / PERIOD_S   # never faster than published
        assert int(m.group(2)) >= 2


def test_commands_and_exit_codes(fake_graph, capsys):
    assert ctl('enable') == 1                  # refused: the node's message, exit 1
    assert 'enable (' in capsys.readouterr().err
    assert fake_graph[-1] == 'enable'
    assert ctl('enable') == 0
    assert f'enable ({NS}/pdplus/enable): done: enabled' in capsys.readouterr().out
    assert ctl('stop') == 0 and fake_graph[-1] == 'stop'
    capsys.readouterr()
    assert ctl('hold') == 2                    # this pdplus has no ~/hold
    assert capsys.readouterr().err == (f'hold: {NS}/pdplus offers no ~/hold service (it '
                                       'offers: enable, stop)\n')
    assert ctl('reset') == 0 and fake_graph[-1] == 'reset'
    assert f'reset ({NS}/simulator/reset): done: error cleared' in capsys.readouterr().out


def test_absent_node_is_exit_2_in_one_line(capsys):
    assert main(['enable', '--pdplus', f'{NS}/absent', '--timeout', '1']) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and 'not found within 1 s' in err


# --- against the real simulator and pdplus -----------------------------------------------------
def test_status_of_the_real_simulator_and_pdplus(tmp_path, capsys):
    """The message shapes and names ctl reads are those the real nodes publish: an idle
    pdplus (auto_enable off) beside a realtime simulator, in a namespace of their own."""
    import subprocess
    from irb_control.process_group import stop_sessions
    ns = f'/ctlreal{os.getpid()}'
    procs = [subprocess.Popen(['ros2', 'run', 'irb_control', exe, '--ros-args',
                               '-r', f'__ns:={ns}', *extra],
                              cwd=tmp_path, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, start_new_session=True)
             for exe, extra in (('simulator', ['-p', 'mode:=realtime']),
                                ('pdplus', ['-p', 'auto_enable:=false']))]
    try:
        # both nodes on the graph first: status reports the graph as it is, and on a loaded
        # host the simulator (pinocchio, model) can come up seconds after pdplus (a fresh-clone
        # CI saw a status without the drive)
        from irb_bringup.ctl import _discover, _Session
        session = _Session([])
        try:
            seen, _, drives = _discover(session, f'{ns}/pdplus', BOUND_S,
                                        lambda found, settled: found[0] and bool(found[2]))
        finally:
            session.close()
        assert seen and drives == [f'{ns}/simulator/reset'], (seen, drives)
        t0 = time.monotonic()
        assert main(['status', '--pdplus', f'{ns}/pdplus', '--timeout', '60',
                     '--window', '0.5']) == 0
        # nothing to wait for once the graph is there: a pdplus that has no plan yet has
        # published nothing on its latched plan_status (status waited for its timeout)
        assert time.monotonic() - t0 < 45.0
        out = capsys.readouterr().out
        assert out.startswith(f'pdplus {ns}/pdplus: mode idle  (missed deadlines ')
        assert re.search(r'services: enable, (.+, )?stop', out), out   # others may come
        assert 'plan: no verdict on plan_status' in out
        assert 'drive (simulator): motors off, brakes engaged, no error' in out
        assert re.search(rf'{ns}/joint_states +[0-9.]+ Hz', out), out
        assert re.search(rf'{ns}/torque_command +(no messages|[0-9.]+ Hz)', out), out
        # ctl hold reaches the real ~/hold: an idle pdplus refuses it with its reason
        assert main(['hold', '--pdplus', f'{ns}/pdplus', '--timeout', '60']) == 1
        assert f'hold ({ns}/pdplus/hold): refused: idle' in capsys.readouterr().err
    finally:
        stop_sessions(procs)
