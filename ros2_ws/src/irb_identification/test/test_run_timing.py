"""run_timing: the run monitor's state machine (pure, no graph)."""
import pytest

from irb_identification.run_timing import (DONE, FAILED, MARGIN, MODE_HOLD, MODE_IDLE,
                                           MODE_NAMES, MODE_RAMP, MODE_STOPPED, MODE_TIME,
                                           RUNNING, WAIT_START, RunMonitor,
                                           controller_state_head, header_stamp)

T = 0.004032


def feed(mon, t0, t1, mode, reason=''):
    """Controller states every period from t0 to t1 [s] (exclusive) in ``mode``; returns t1."""
    k = 0
    while t0 + k * T < t1 - 1e-12:
        mon.on_state(t0 + k * T, mode, reason)
        k += 1
    return t0 + k * T


def test_a_run_ends_after_hold_plus_the_recorded_margin():
    mon = RunMonitor(margin_s=1.5, start_timeout_s=5.0)
    t = feed(mon, 0.0, 2.0, MODE_HOLD)             # the previous run's hold
    assert not mon.is_moving
    mon.start(mon.t_state)
    # pdplus still reports HOLD right after publishing: that is not this run's end
    t = feed(mon, t, t + 0.2, MODE_HOLD)
    assert mon.phase == WAIT_START
    t = feed(mon, t, t + 0.008, MODE_IDLE)          # enable -> idle for a sample
    t_ramp = t
    t = feed(mon, t, t + 0.5, MODE_RAMP)
    assert mon.phase == RUNNING and mon.t_start == pytest.approx(t_ramp)
    t_time = t
    t = feed(mon, t, t + 3.0, MODE_TIME)
    assert mon.t_time == pytest.approx(t_time)
    t_hold = t
    feed(mon, t, t + 3.0, MODE_HOLD)                # the controller runs ahead ...
    assert mon.phase == MARGIN and mon.t_hold == pytest.approx(t_hold)
    # ... the recorder trails: done only once it holds t_hold + margin
    for stamp in (t_hold - 1.0, t_hold + 1.0, t_hold + 1.49):
        mon.on_recorded(stamp)
        assert mon.phase == MARGIN
    mon.on_recorded(t_hold + 1.0)                   # older stamps do not count
    assert mon.t_recorded == pytest.approx(t_hold + 1.49)
    mon.on_recorded(t_hold + 1.5 + T)
    assert mon.phase == DONE and mon.t_end == pytest.approx(t_hold + 1.5)
    assert not mon.error


def test_time_without_ramp_messages_still_starts_and_states_out_of_order_are_ignored():
    mon = RunMonitor(margin_s=0.5)
    feed(mon, 0.0, 1.0, MODE_HOLD)
    mon.start(mon.t_state)
    mon.on_state(1.2, MODE_TIME)
    mon.on_state(1.1, MODE_HOLD)                    # late, older message: ignored
    assert mon.phase == RUNNING and mon.mode == MODE_TIME
    mon.on_state(2.0, MODE_HOLD)
    mon.on_recorded(2.5)
    assert mon.phase == DONE


def test_stop_during_the_run_fails_with_the_reason():
    mon = RunMonitor()
    feed(mon, 0.0, 1.0, MODE_HOLD)
    mon.start(mon.t_state)
    t = feed(mon, 1.0, 1.6, MODE_RAMP)
    t = feed(mon, t, t + 1.0, MODE_TIME)
    mon.on_state(t, MODE_STOPPED, 'tracking error [0.06] rad > [0.05]')
    assert mon.phase == FAILED and 'tracking error' in mon.error
    mon.on_state(t + T, MODE_HOLD)                  # nothing revives a failed run
    mon.on_recorded(t + 10)
    assert mon.phase == FAILED and mon.finished


def test_no_start_is_an_error_after_the_start_timeout_of_simulated_time():
    mon = RunMonitor(start_timeout_s=2.0)
    feed(mon, 0.0, 1.0, MODE_STOPPED, 'stop service')   # latched stop from before
    mon.start(mon.t_state)
    # pdplus checks the plan (wall-clock work) while a lockstep simulator's time runs on:
    # no timeout before enable was accepted (thesis_run failed so on a loaded machine)
    feed(mon, 1.0, 30.0, MODE_STOPPED, 'stop service')
    assert mon.phase == WAIT_START
    mon.enabled(30.0)
    feed(mon, 30.0, 31.9, MODE_STOPPED, 'stop service')  # STOPPED while waiting: not yet
    assert mon.phase == WAIT_START
    feed(mon, 31.9, 32.5, MODE_STOPPED, 'stop service')
    assert mon.phase == FAILED
    assert 'did not start' in mon.error and 'stop service' in mon.error


def test_leaving_the_run_otherwise_fails_and_start_twice_is_refused():
    mon = RunMonitor()
    feed(mon, 0.0, 0.1, MODE_IDLE)
    mon.start(mon.t_state)
    mon.on_state(0.2, MODE_RAMP)
    mon.on_state(0.3, MODE_IDLE)
    assert mon.phase == FAILED and 'idle' in mon.error
    with pytest.raises(RuntimeError):
        mon.start(0.4)


def test_is_moving_before_any_state_and_while_a_motion_runs():
    mon = RunMonitor()
    assert mon.is_moving                             # nothing known yet
    mon.on_state(0.0, MODE_TIME)
    assert mon.is_moving
    mon.on_state(0.1, MODE_HOLD)
    assert not mon.is_moving


def test_modes_are_the_controller_state_contract():
    msg = pytest.importorskip('irb_interfaces.msg')
    for mode, name in MODE_NAMES.items():
        assert getattr(msg.ControllerState, f'MODE_{name.upper()}') == mode


def test_header_reads_match_rclpy_serialization():
    serialization = pytest.importorskip('rclpy.serialization')
    from irb_interfaces.msg import ControllerState
    from sensor_msgs.msg import JointState
    for frame, reason in (('', ''), ('base_link', 'tracking error 0.06 rad > 0.05'),
                          ('abc', 'x')):
        m = ControllerState()
        m.header.stamp.sec, m.header.stamp.nanosec = 123, 456_000_000
        m.header.frame_id = frame
        m.mode = MODE_STOPPED
        m.stop_reason = reason
        m.q_ref = [1.0, 2.0, 3.0]
        data = serialization.serialize_message(m)
        assert controller_state_head(data) == (pytest.approx(123.456), MODE_STOPPED, reason)
    js = JointState()
    js.header.stamp.sec, js.header.stamp.nanosec = 7, 4_032_000
    js.name = ['joint_1']
    assert header_stamp(serialization.serialize_message(js)) == pytest.approx(7.004032)
    with pytest.raises(ValueError):
        header_stamp(b'\x00\x01\x00\x00\x01')
    with pytest.raises(ValueError):
        controller_state_head(serialization.serialize_message(m)[:14])
