"""``report`` on bags written here from the offline closed loop (irb_control.closed_loop):
figures checked by code of this test that shares nothing with the report's (its own
trapezoid rule on the raw arrays, camera points at a known offset from the path), a gap named,
a damaged or empty bag refused with one line."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

LINE = ([0.55, -0.1, 0.3], [0.75, 0.1, 0.3])     # horizontal: +z is normal to it
OFFSET_M = 1e-3
START_NS = 1_700_000_000 * 10**9
STANDBY_W = 300.0


@pytest.fixture(scope='module')
def loop():
    """One short closed-loop run along a line (ramp, path, hold), ~2.5 s simulated."""
    from irb_control.closed_loop import build_default, simulate_closed_loop
    from irb_description.path import LinePath
    path = LinePath(np.array(LINE[0]), np.array(LINE[1]))
    plant, ctrl = build_default('nominal', duration_s=1.5, path=path)
    res = simulate_closed_loop(plant, ctrl, 3.0)
    assert res.finished(), res.stop_reason
    return res, path


def write_bag(bag: Path, res, path, drop: tuple[float, float] | None = None,
              six: bool = False) -> dict:
    """The run as the recorder would write it; /camera/tcp: the path points nearest the true
    TCP lifted by OFFSET_M along +z; /electrical_power: STANDBY_W constant on total_none.
    ``drop``: (t0, t1) [s] of /joint_states left out; ``six``: /joint_states carries all six
    joints (4-6 at rest, listed first). Returns the raw arrays written."""
    from irb_identification.bagio import BagWriter, TopicInfo, serialize, typestore
    from irb_identification.series import encode_joint_states
    names = ['joint_1', 'joint_2', 'joint_3']
    ts = typestore(['irb_interfaces/msg/ControllerState', 'irb_interfaces/msg/PathSpec'])
    T = ts.types
    Header, Time = T['std_msgs/msg/Header'], T['builtin_interfaces/msg/Time']

    def header(ns):
        return Header(stamp=Time(sec=int(ns // 10**9), nanosec=int(ns % 10**9)),
                      frame_id='base_link')
    t_ns = START_NS + np.round(res.t * 1e9).astype(np.int64)
    keep = np.ones(len(t_ns), bool) if drop is None else ~((res.t >= drop[0])
                                                           & (res.t < drop[1]))
    arrays = [a[keep] for a in (res.q_meas, res.qd_meas, res.tau_applied)]
    if six:
        arrays = [np.hstack([np.zeros((len(a), 3)), a]) for a in arrays]
    js = encode_joint_states(t_ns[keep], (['joint_4', 'joint_5', 'joint_6'] if six else [])
                             + names, *arrays)
    empty = np.zeros(0)
    nan3 = np.full(3, np.nan)
    cam_ns = START_NS + np.round(res.cam_t * 1e9).astype(np.int64)
    cam_p = path.point(path.theta_of(res.cam_p)) + np.array([0.0, 0.0, OFFSET_M])
    with BagWriter(bag, split_period_s=1e9, clock=lambda: 0.0) as w:
        for topic, typ in (('/joint_states', 'sensor_msgs/msg/JointState'),
                           ('/torque_command', 'sensor_msgs/msg/JointState'),
                           ('/controller_state', 'irb_interfaces/msg/ControllerState'),
                           ('/camera/tcp', 'geometry_msgs/msg/PointStamped'),
                           ('/electrical_power', 'sensor_msgs/msg/JointState'),
                           ('/planned_path', 'irb_interfaces/msg/PathSpec')):
            w.add_topic(TopicInfo.for_type(topic, typ))
        P = T['geometry_msgs/msg/Point']
        w.write('/planned_path', START_NS, serialize('irb_interfaces/msg/PathSpec', T[
            'irb_interfaces/msg/PathSpec'](
            type='line', center=P(x=0.0, y=0.0, z=0.0), radius=0.0, start_angle=0.0,
            direction=1, normal=T['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0),
            sweep=0.0, waypoints=[P(x=a[0], y=a[1], z=a[2]) for a in LINE],
            blend_radii=np.zeros(0),
            closed=False)))
        for k, ns in enumerate(t_ns):
            if keep[k]:
                w.write('/joint_states', int(ns), js[int(keep[:k].sum())])
            if res.published[k]:
                w.write('/torque_command', int(ns), serialize(
                    'sensor_msgs/msg/JointState', T['sensor_msgs/msg/JointState'](
                        header=header(ns), name=names, position=empty, velocity=empty,
                        effort=res.tau_cmd[k])))
            q_ref = res.q_ref[k]
            w.write('/controller_state', int(ns), serialize(
                'irb_interfaces/msg/ControllerState', T['irb_interfaces/msg/ControllerState'](
                    header=header(ns), mode=int(res.mode[k]), stop_reason='',
                    theta=float(res.theta[k]), theta_predicted=0.0, theta_dot_ref=0.0,
                    q_ref=q_ref, qd_ref=res.qd_ref[k], qdd_ref=nan3,
                    q_error=q_ref - res.q_meas[k], qd_error=res.qd_ref[k] - res.qd_meas[k],
                    tau_model=nan3, tau_friction=nan3, tau_feedback=nan3,
                    tau_command=res.tau_cmd[k], missed_deadlines=0, rejected_inputs=0,
                    step_duration=0.0)))
            w.write('/electrical_power', int(ns), serialize(
                'sensor_msgs/msg/JointState', T['sensor_msgs/msg/JointState'](
                    header=header(ns), name=names + ['total_none'], position=empty,
                    velocity=empty, effort=np.array([1.0, 2.0, 3.0, STANDBY_W]))))
        for ns, p in zip(cam_ns, cam_p):
            w.write('/camera/tcp', int(ns), serialize(
                'geometry_msgs/msg/PointStamped', T['geometry_msgs/msg/PointStamped'](
                    header=header(ns), point=P(x=p[0], y=p[1], z=p[2]))))
    return {'t': t_ns[keep] * 1e-9, 'tau': res.tau_applied[keep], 'qd': res.qd_meas[keep],
            'ctrl_t': t_ns * 1e-9, 'mode': res.mode}


def run_report(bag, out, capsys, *extra):
    from irb_bringup.report import main
    rc = main(['--bag', str(bag), '--out', str(out), *extra])
    return rc, capsys.readouterr()


def test_report_of_a_closed_loop_run_along_a_line(loop, tmp_path, capsys):
    res, path = loop
    raw = write_bag(tmp_path / 'bag', res, path)
    rc, cap = run_report(tmp_path / 'bag', tmp_path / 'out', capsys)
    assert rc == 0, cap.err
    assert '[report] /joint_states' in cap.out          # progress while working
    s = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    # the window: first to last controller state in path mode (2)
    tc = raw['ctrl_t'][raw['mode'] == 2]
    t0, t1 = tc.min(), tc.max()
    # to the double's resolution at 1.7e9 s (2.4e-7 s): the report reads the stamps as
    # sec + 1e-9 nanosec, this test has ns * 1e-9
    assert s['window_s'] == pytest.approx([t0, t1], abs=np.spacing(t1))
    # mechanical energy: this test's own trapezoid rule over the raw arrays it wrote
    t, p = raw['t'], np.abs(raw['tau'] * raw['qd']).sum(axis=1)
    sel = np.flatnonzero((t >= t0) & (t <= t1))
    own = sum(0.5 * (p[i] + p[j]) * (t[j] - t[i]) for i, j in zip(sel[:-1], sel[1:]))
    assert own > 1.0
    assert s['mechanical_energy_j'] == pytest.approx(own, rel=1e-9)
    # camera points 1 mm off the line: 1 mm mean path error; constant standby power
    assert s['camera_path_error_mean_mm'] == pytest.approx(1e3 * OFFSET_M, abs=1e-6)
    assert s['electrical_energy_j']['total_none'] == pytest.approx(STANDBY_W * (t1 - t0),
                                                                  rel=1e-6)
    assert s['gaps'] == []
    md = (tmp_path / 'out' / 'report.md').read_text()
    for png in ('tcp_path', 'path_error', 'tracking', 'torque', 'modes_speed', 'power'):
        assert f']({png}.png)' in md
        assert (tmp_path / 'out' / f'{png}.png').stat().st_size > 10_000
    assert 'noise floor' in md and 'No gap' in md
    # tracking errors: the controller's q_error as written, RMS over the window
    e = (res.q_ref - res.q_meas)[(raw['ctrl_t'] >= t0) & (raw['ctrl_t'] <= t1)]
    assert s['tracking_rms_mrad'] == pytest.approx(1e3 * np.sqrt((e ** 2).mean(axis=0)),
                                                   rel=1e-9)


def test_a_gap_in_a_series_is_said_six_joints_picked_by_name(loop, tmp_path, capsys):
    res, path = loop
    t_path = res.t[res.mode == 2]
    a = float(t_path[0] + 0.5)
    raw = write_bag(tmp_path / 'bag', res, path, drop=(a, a + 0.1), six=True)
    rc, cap = run_report(tmp_path / 'bag', tmp_path / 'out', capsys)
    assert rc == 0, cap.err
    s = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    assert [g['series'] for g in s['gaps']] == ['/joint_states']
    assert s['gaps'][0]['length_s'] == pytest.approx(0.1, abs=0.01)
    assert 'GAP: /joint_states misses' in cap.out
    assert 'Gaps in the recorded series' in (tmp_path / 'out' / 'report.md').read_text()
    # six joints in /joint_states: the model's three picked by name, energy over them
    t0, t1 = s['window_s']
    t, p = raw['t'], np.abs(raw['tau'] * raw['qd']).sum(axis=1)
    # the window's ends from the report are the controller's stamps read as sec + 1e-9 nsec:
    # the same instants as this test's ns * 1e-9 within a microsecond (samples are 4 ms apart)
    sel = np.flatnonzero((t >= t0 - 1e-6) & (t <= t1 + 1e-6))
    own = sum(0.5 * (p[i] + p[j]) * (t[j] - t[i]) for i, j in zip(sel[:-1], sel[1:]))
    assert s['mechanical_energy_j'] == pytest.approx(own, rel=1e-9)


def test_a_bag_with_joint_states_only_reports_what_it_can(loop, tmp_path, capsys):
    from irb_identification.offline_sim import SimRun, write_run_bag
    res, _ = loop
    run = SimRun(res.t, res.q_meas, res.qd_meas, res.tau_applied, res.q_ref, res.qd_ref, 0,
                 type('P', (), {'speed': 0.0, 'hold_s': 0.0})())
    write_run_bag(run, tmp_path / 'bag', ['joint_1', 'joint_2', 'joint_3'])
    rc, cap = run_report(tmp_path / 'bag', tmp_path / 'out', capsys)
    assert rc == 0, cap.err
    s = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    said = ' '.join(s['not_computed'])
    for what in ('no planned path', 'no /torque_command', 'no /electrical_power',
                 'no /controller_state'):
        assert what in said, what
    assert s['window_kind'] == 'whole recording'
    assert s['mechanical_energy_j'] == pytest.approx(s['mechanical_energy_all_j'])


@pytest.mark.parametrize('damage', ['empty_dir', 'truncated', 'missing'])
def test_a_damaged_or_empty_bag_ends_with_one_line(loop, tmp_path, capsys, damage):
    bag = tmp_path / 'bag'
    if damage == 'empty_dir':
        bag.mkdir()
    elif damage == 'truncated':
        res, path = loop
        write_bag(bag, res, path)
        for f in bag.glob('*.mcap'):
            f.write_bytes(f.read_bytes()[:len(f.read_bytes()) // 3])
    rc, cap = run_report(bag, tmp_path / 'out', capsys)
    assert rc == 1
    assert len(cap.err.strip().splitlines()) == 1, cap.err
    assert cap.err.startswith('report: ') and 'Traceback' not in cap.err
