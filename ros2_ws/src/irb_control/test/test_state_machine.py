"""The controller's state machine walked state x event (issue 14, defects 1 and 4).

Each state is reached by stepping a robot that follows its reference exactly; then each event
is applied and the outcome compared with TRANSITIONS. For every state the offered plan must
leave the running reference (the next command) unchanged, and a stop stays latched until
enable.
"""
import numpy as np
import pytest

from irb_control.pd_plus import (EV_ENABLE, EV_HOLD, EV_MOTION_DONE, EV_PLAN, EV_RAMP_DONE,
                                 EV_STOP, EVENTS, MODE_HOLD, MODE_IDLE, MODE_NAMES, MODE_PATH,
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


# --- hold: a controlled stop along the reference, then HOLD (issue 32) -----------------------
@pytest.mark.parametrize('state', STATES, ids=lambda s: MODE_NAMES[s])
def test_hold_follows_the_table(model, circle, profiles, state):
    """Refused in IDLE and STOPPED (the stop stays latched, no command), a no-op in HOLD,
    accepted while moving (the mode stays until the reference has come to rest)."""
    ctrl, t, q = controller_in(model, circle, profiles, state)
    nxt, why = TRANSITIONS[(state, EV_HOLD)]
    reason = ctrl.stop_reason
    ok, text = ctrl.hold()
    assert ok == (nxt is not None) and text.startswith(why)
    out = ctrl.step(t, q, np.zeros(3))
    if state == MODE_STOPPED:
        assert out.mode == MODE_STOPPED and not out.publish and ctrl.stop_reason == reason
    elif state == MODE_IDLE:
        assert out.mode == MODE_IDLE and not out.publish
    else:
        assert out.mode == state and out.publish and ctrl.stopping == (state != MODE_HOLD)


def _hold_midway(model, circle, profiles, state, after_s):
    """Follow the reference exactly, request hold ``after_s`` into ``state``, follow on until
    HOLD; the outputs of the whole run and the index of the request."""
    if state == MODE_RAMP:          # a ramp that moves: from 0.3 rad away from the start
        ctrl = PdPlusController(model, circle, ControllerConfig())
        ctrl.set_path_profile(profiles[0])
        ctrl.enable()
        t, q = 0.0, profiles[0].q[0] + np.array([0.3, -0.2, 0.2])
    else:
        ctrl, t, q = controller_in(model, circle, profiles, state)
    outs = []
    for _ in range(int(after_s / T)):
        t, q, out = follow(ctrl, t, q, 1)
        outs.append(out)
    assert out.mode == state
    ok, text = ctrl.hold()
    assert ok and 'decelerating in' in text
    k = len(outs)
    while out.mode != MODE_HOLD:
        t, q, out = follow(ctrl, t, q, 1)
        outs.append(out)
        assert out.mode in (state, MODE_HOLD) and out.publish, MODE_NAMES[out.mode]
        assert len(outs) < k + 2000, 'never came to rest'
    for _ in range(100):                      # 0.4 s of holding: the pose stays
        t, q, out = follow(ctrl, t, q, 1)
        outs.append(out)
        assert out.mode == MODE_HOLD and out.publish
    return ctrl, outs, k


@pytest.mark.parametrize('state, after_s', [(MODE_PATH, 0.6), (MODE_TIME, 0.3),
                                            (MODE_RAMP, 0.2)],
                         ids=['path', 'time', 'ramp'])
def test_hold_decelerates_along_the_reference_and_holds(model, circle, profiles, state,
                                                        after_s):
    ctrl, outs, k = _hold_midway(model, circle, profiles, state, after_s)
    qd = np.array([o.qd_ref for o in outs])
    qdd = np.array([o.qdd_ref for o in outs])
    q_ref = np.array([o.q_ref for o in outs])
    assert np.max(np.abs(qd[k - 1])) > 0.05            # it was moving when asked
    end = next(i for i, o in enumerate(outs) if o.mode == MODE_HOLD)
    # at rest from HOLD on, the pose unchanged
    assert np.all(qd[end:] == 0) and np.all(qdd[end:] == 0)
    np.testing.assert_array_equal(q_ref[end:], np.tile(q_ref[end], (len(outs) - end, 1)))
    # the acceleration while stopping stays within twice the motion's own peak (the stop adds
    # at most that peak: T_s = 1.5 |qd| / a)
    if state == MODE_RAMP:
        d = np.abs(ctrl._ramp_to - ctrl._ramp_from)
        peak = 10 / np.sqrt(3) * d / ctrl._ramp_T ** 2
    else:
        peak = np.max(np.abs(ctrl.active.qdd), axis=0)
    lim = 2 * np.maximum(peak, ctrl.config.hold_min_deceleration_rad_s2) + 1e-9
    assert np.all(np.abs(qdd[k:end]) <= lim), (np.abs(qdd[k:end]).max(axis=0), lim)
    # and the speed never steps: per period no more than that acceleration allows
    assert np.all(np.abs(np.diff(qd[k - 1:end + 1], axis=0)) <= lim * T)
    # the pose it rests at lies on the motion's own curve, ahead of where it was asked to stop
    if state == MODE_PATH:
        p_rest = model.fk(q_ref[end])
        assert np.linalg.norm(p_rest - circle.point(circle.theta_of(p_rest))) < 1e-5
        assert outs[end - 1].theta > outs[k - 1].theta
    elif state == MODE_TIME:
        traj = ctrl.active
        dist = np.min(np.linalg.norm(traj.q - q_ref[end], axis=1))
        assert dist < 2e-3
    else:
        u = (q_ref[end] - ctrl._ramp_from) / (ctrl._ramp_to - ctrl._ramp_from)
        assert np.allclose(u, u[0], atol=1e-9) and 0 < u[0] < 1    # on the ramp's line
    assert ctrl.stop_reason == '' and ctrl.last_stop_reason == ''   # nothing latched


def test_enable_after_hold_ramps_to_the_start_again(model, circle, profiles):
    ctrl, outs, _ = _hold_midway(model, circle, profiles, MODE_PATH, 0.6)
    ok, _ = ctrl.enable()
    assert ok
    out = ctrl.step(100.0, outs[-1].q_ref, np.zeros(3))
    assert out.mode == MODE_RAMP


def test_profiles_let_go_of_are_retired_not_dropped_and_freed_in_slices(model, circle, profiles):
    """Issue 32: a profile replaced (a plan over a pending one, the old motion at enable) goes
    to ``retire`` (pdplus frees it on another thread) instead of being freed where it is
    replaced; ``dispose_sliced`` empties its tables chunk by chunk with a pause between."""
    from irb_control.profiles import dispose_sliced
    _, time_a, time_b = profiles
    path = default_circle_profile(model, circle, 2.0, grid=181)   # its own: it is emptied
    ctrl = PdPlusController(model, circle, ControllerConfig())
    retired = []
    ctrl.retire = retired.append
    ctrl.set_path_profile(path)
    ctrl.set_time_trajectory(time_a)                   # replaces the pending path profile
    assert retired == [path]
    ctrl.enable()                                      # time_a active, nothing let go of
    ctrl.set_time_trajectory(time_b)
    ctrl.enable()                                      # time_b active: time_a let go of
    assert retired == [path, time_a] and ctrl.active is time_b
    pauses = []
    n = len(path._rows_l)
    dispose_sliced(path, chunk=16, pause=lambda: pauses.append(len(path._rows_l)))
    assert path._rows_l == [] and path._xl == [] and path._h_slope == []
    assert pauses[0] == n - 16 and len(pauses) >= 3 * (n // 16)


def test_build_sliced_freezes_its_objects_before_collection_resumes(profiles):
    """Issue 32: pdplus's sliced build hands its ~11 objects per point to the permanent
    generation before the garbage collector runs again (else the next allocation, on the
    control thread, walks them all: 3-9 ms measured)."""
    import gc
    from irb_control.profiles import PathProfile, build_sliced
    path = profiles[0]
    arrays = {k: getattr(path, k) for k in ('theta', 'theta_dot', 'theta_ddot', 'q', 'qd',
                                            'qdd')}
    before = gc.get_freeze_count()
    b = build_sliced(PathProfile, arrays, freeze=True)
    try:
        assert gc.isenabled() and gc.get_freeze_count() >= before + len(b._rows_l)
        assert b._rows_l == path._rows_l
    finally:
        gc.unfreeze()
