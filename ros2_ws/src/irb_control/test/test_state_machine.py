"""The controller's state machine walked state x event (issue 14, defects 1 and 4).

Each state is reached by stepping a robot that follows its reference exactly; then each event
is applied and the outcome compared with TRANSITIONS. For every state the offered plan must
leave the running reference (the next command) unchanged, and a stop stays latched until
enable.
"""
import numpy as np
import pytest

from irb_control.pd_plus import (EV_ENABLE, EV_MOTION_DONE, EV_PLAN, EV_RAMP_DONE, EV_STOP,
                                 EVENTS, MODE_HOLD, MODE_IDLE, MODE_NAMES, MODE_PATH,
                                 MODE_RAMP, MODE_STOPPED, MODE_TIME, TRANSITIONS,
                                 ControllerConfig, PdPlusController)
from irb_control.profiles import default_circle_profile, sine_trajectory

T = 0.004032
STATES = (MODE_IDLE, MODE_RAMP, MODE_PATH, MODE_TIME, MODE_HOLD, MODE_STOPPED)


@pytest.fixture(scope='module')
def profiles(model, circle):
    path = default_circle_profile(model, circle, 2.0, grid=181)
    start = path.q[0]
    time_a = sine_trajectory(start, 0, 0.3, 0.1, 1.0)
    # a second plan that starts elsewhere: taking it would move the robot at once
    time_b = sine_trajectory(start + np.array([0.2, 0.1, -0.1]), 1, 0.3, 0.1, 1.0)
    return path, time_a, time_b


def follow(ctrl, t, q, steps):
    """Step ``steps`` times with the robot exactly at the last reference; (t, q, out)."""
    out = None
    for _ in range(steps):
        out = ctrl.step(t, q, np.zeros(3))
        if out.publish and np.all(np.isfinite(out.q_ref)):
            q = out.q_ref.copy()
        t += T
    return t, q, out


def controller_in(model, circle, profiles, state):
    """A controller in ``state`` (and the time and robot pose reached)."""
    path, time_a, _ = profiles
    ctrl = PdPlusController(model, circle, ControllerConfig())
    timed = state in (MODE_TIME, MODE_HOLD)
    ctrl.set_time_trajectory(time_a) if timed else ctrl.set_path_profile(path)
    q, t = (time_a if timed else path).q[0].copy(), 0.0
    if state == MODE_IDLE:
        return ctrl, t, q
    if state == MODE_STOPPED:
        ctrl.stop('operator')
        return ctrl, t, q
    ctrl.enable()
    t, q, out = follow(ctrl, t, q, 1)
    while out.mode != state:
        t, q, out = follow(ctrl, t, q, 1)
        assert t < 30.0, f'never reached {MODE_NAMES[state]}'
    return ctrl, t, q


@pytest.mark.parametrize('state', STATES, ids=lambda s: MODE_NAMES[s])
@pytest.mark.parametrize('event', (EV_ENABLE, EV_STOP, EV_PLAN))
def test_external_events_follow_the_table(model, circle, profiles, state, event):
    ctrl, t, q = controller_in(model, circle, profiles, state)
    assert ctrl.mode == state
    nxt, _ = TRANSITIONS[(state, event)]
    # the reference a twin without the event would command next
    twin, _, _ = controller_in(model, circle, profiles, state)
    if event == EV_ENABLE:
        ok, _ = ctrl.enable()
        assert ok == (nxt is not None)
        if ok:
            assert ctrl.stop_reason == ''
            out = ctrl.step(t, q, np.zeros(3))
            assert out.mode == MODE_RAMP and out.publish
        else:
            assert ctrl.mode == state
    elif event == EV_STOP:
        ctrl.stop('test')
        assert ctrl.mode == MODE_STOPPED == nxt
        out = ctrl.step(t, q, np.zeros(3))
        assert not out.publish and out.mode == MODE_STOPPED
        expected = 'operator' if state == MODE_STOPPED else 'test'   # the first reason kept
        assert ctrl.stop_reason == expected
    else:
        ctrl.set_time_trajectory(profiles[2])       # a plan starting elsewhere
        assert ctrl.mode == state == nxt
        a, b = ctrl.step(t, q, np.zeros(3)), twin.step(t, q, np.zeros(3))
        assert a.mode == b.mode and a.publish == b.publish
        if a.publish:       # the running reference is not touched by the plan
            np.testing.assert_array_equal(a.q_ref, b.q_ref)
            np.testing.assert_array_equal(a.tau, b.tau)
        assert ctrl.pending is profiles[2] and ctrl.active is not profiles[2]


def test_the_table_is_complete_and_internal_events_happen_only_where_it_says(
        model, circle, profiles):
    assert set(TRANSITIONS) == {(s, e) for s in STATES for e in EVENTS}
    allowed = {(s, e) for (s, e), (n, _) in TRANSITIONS.items() if n is not None}
    assert {s for s, e in allowed if e == EV_RAMP_DONE} == {MODE_RAMP}
    assert {s for s, e in allowed if e == EV_MOTION_DONE} == {MODE_PATH, MODE_TIME}
    # a theta-driven motion runs IDLE -> RAMP -> PATH -> HOLD and nothing else
    path = profiles[0]
    ctrl = PdPlusController(model, circle, ControllerConfig())
    ctrl.set_path_profile(path)
    ctrl.enable()
    t, q, seen = 0.0, path.q[0].copy(), [MODE_IDLE]
    while seen[-1] != MODE_HOLD and t < 10.0:
        t, q, out = follow(ctrl, t, q, 1)
        if out.mode != seen[-1]:
            seen.append(out.mode)
    assert seen == [MODE_IDLE, MODE_RAMP, MODE_PATH, MODE_HOLD]


def test_a_plan_while_holding_does_not_move_the_robot(model, circle, profiles):
    # defect 1: a time-driven plan was sampled on the old plan's clock while holding
    ctrl, t, q = controller_in(model, circle, profiles, MODE_HOLD)
    before = ctrl.step(t, q, np.zeros(3))
    ctrl.set_time_trajectory(profiles[2])
    for k in range(200):                  # 0.8 s of holding with the new plan stored
        out = ctrl.step(t + (k + 1) * T, q, np.zeros(3))
        assert out.mode == MODE_HOLD
        np.testing.assert_array_equal(out.q_ref, before.q_ref)
        assert np.all(out.qd_ref == 0)
    ok, _ = ctrl.enable()                 # only enable takes it, through the ramp
    assert ok
    out = ctrl.step(t + 201 * T, q, np.zeros(3))
    assert out.mode == MODE_RAMP
    # the ramp starts where the robot is: its reference 3 samples ahead (the delay
    # compensation) has moved by a few 1e-5 rad, not the 0.2 rad to the new plan's start
    np.testing.assert_allclose(out.q_ref, q, atol=1e-4)


def test_a_plan_never_clears_a_latched_stop(model, circle, profiles):
    # defect 4: a new plan cleared a latched stop (after ~/stop or a tracking-error trip)
    ctrl, t, q = controller_in(model, circle, profiles, MODE_PATH)
    out = ctrl.step(t, q + np.array([1.0, 0.0, 0.0]), np.zeros(3))    # 1 rad tracking error
    assert out.mode == MODE_STOPPED and 'tracking error' in ctrl.stop_reason
    reason = ctrl.stop_reason
    ctrl.set_time_trajectory(profiles[2])
    for k in range(50):
        out = ctrl.step(t + k * T, q, np.zeros(3))
        assert out.mode == MODE_STOPPED and not out.publish
    assert ctrl.stop_reason == reason
    ok, _ = ctrl.enable()
    assert ok and ctrl.last_stop_reason == reason and ctrl.active is profiles[2]
