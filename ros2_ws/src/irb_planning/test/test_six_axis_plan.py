"""Six-axis planning (issue 30): a plan along a path with an orientation law, played by a player
written here (scipy ``BPoly.from_derivatives`` per joint, 10 kHz) and measured against the
task's own poses at the profile's time law through irb_description's DH kinematics
(``orientation.pose_errors``), which shares nothing with the closed-form IK or the planner's
check; the three-axis planner unchanged by it; path files with an orientation block."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import BPoly

from irb_description.orientation import pose_errors, tool_poses
from irb_description.path import path_from_spec

from irb_planning.planner import Planner
from irb_planning.request import PlanRequest
from irb_planning.six_axis_check import play
from irb_planning.six_axis_plan import SixAxisPlanError, SixAxisPlanner, task_from_spec

ARC = dict(type='arc', center=[0.65, 0.1, 0.35], normal=[0.0, -0.3, 1.0], radius=0.1,
           start_angle=0.5, sweep=4.0)
GRID = 40
DURATION = 2.0          # [s] (time-optimal about 0.6 s)


def three_axis_plan():
    """The thesis circle planned by the three-axis planner (coarse grid)."""
    return Planner().plan(PlanRequest(objective='energy', duration=10.0, grid_size=30))


@pytest.fixture(scope='module')
def planned():
    before = three_axis_plan()
    planner = SixAxisPlanner()
    path, law = task_from_spec({**ARC, 'orientation': {'law': 'path_normal'}})
    prob = planner.problem(path, law, GRID)
    plan = planner.plan(prob, 'energy', DURATION)
    return planner, path, law, plan, before


def test_plan_played_within_goals(planned):
    planner, path, law, plan, _ = planned
    tr = plan.trajectory
    t, q, qd, qdd = (np.asarray(tr[k]) for k in ('t', 'q', 'qd', 'qdd'))
    assert q.shape[1] == 6 and abs(t[-1] - DURATION) < 1e-6
    assert plan.min_duration < DURATION
    # the player: per joint the quintic through (q, qd, qdd) at the points, 10 kHz clock
    ts = np.unique(np.concatenate([t[0] + np.arange(int((t[-1] - t[0]) * 1e4) + 1) / 1e4, t]))
    ts = ts[ts <= t[-1]]
    qs = np.stack([BPoly.from_derivatives(t, np.stack([q[:, i], qd[:, i], qdd[:, i]], 1),
                                          orders=5)(ts) for i in range(6)], axis=1)
    # the wanted pose at each played instant: theta(t) of the profile's time law, the path's
    # point and the law's rotation there
    theta = plan.profile.sample(ts)[0]
    pos, ori = pose_errors(planner.kin, qs, tool_poses(path, law, theta))
    assert pos.max() <= 1e-4, f'{pos.max() * 1e3:.4f} mm'
    assert np.degrees(ori.max()) <= 0.05, f'{np.degrees(ori.max()):.4f} deg'
    # the joints move (the wrist keeps the tool normal to the tilted plane) inside the limits
    assert np.ptp(qs[:, 3:], axis=0).max() > 0.05
    assert np.all(qs >= planner.limits.lower - 1e-9) and np.all(qs <= planner.limits.upper + 1e-9)
    assert np.all(plan.check.peak_torque <= planner.limits.torque)
    assert np.all(plan.check.peak_speed <= planner.limits.velocity)
    assert plan.energy > 0 and abs(plan.energy / plan.optimizer_energy - 1) < 0.05


def test_played_check_sees_a_wrong_point(planned):
    """The planner's own played check (six_axis_check) flags a wrist point 10 mrad off."""
    planner, path, law, plan, _ = planned
    tr = {k: np.array(v, float) for k, v in plan.trajectory.items()}
    prob = type('P', (), {'path': path, 'law': law})
    ok = planner.check(prob, tr['t'], tr['q'], tr['qd'], tr['qdd'])
    assert ok.ok and ok.orientation_error < np.radians(0.025)
    k = len(tr['t']) // 2
    tr['q'][k, 4] += 0.01
    bad = planner.check(prob, tr['t'], tr['q'], tr['qd'], tr['qdd'])
    assert not bad.ok and bad.orientation_error > np.radians(0.5)
    assert any('off its law' in p for p in bad.problems)


def test_player_is_the_quintic_hermite():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(1e-3, 0.05, 12))
    q, qd, qdd = (rng.normal(size=(12, 6)) for _ in range(3))
    ts, qs, qds, qdds = play(t, q, qd, qdd, 1e4)
    for i in range(6):
        ref = BPoly.from_derivatives(t, np.stack([q[:, i], qd[:, i], qdd[:, i]], 1), orders=5)
        np.testing.assert_allclose(qs[:, i], ref(ts), atol=1e-12)
        np.testing.assert_allclose(qds[:, i], ref.derivative()(ts), atol=1e-9)


def test_three_axis_plan_unchanged(planned):
    """A three-axis plan made after the six-axis one equals the one made before it, bit for
    bit: the six-axis module changes nothing the three-axis planner uses."""
    *_, before = planned
    after = three_axis_plan()
    np.testing.assert_array_equal(after.profile.theta_dot, before.profile.theta_dot)
    for key in ('t', 'q', 'qd', 'qdd', 'tau'):
        np.testing.assert_array_equal(after.trajectory[key], before.trajectory[key])
    assert after.evaluation.energy == before.evaluation.energy
    assert before.trajectory['q'].shape[1] == 3


def test_path_files_with_an_orientation_block():
    spec = {**ARC, 'orientation': {'law': 'fixed', 'rpy': [np.pi, 0.2, 0.0]}}
    # the three-axis reader keeps refusing the block, naming the six-axis chain
    with pytest.raises(ValueError, match="six-axis chain .*plan6"):
        path_from_spec(spec)
    path, law = task_from_spec(spec)
    assert path.length > 0 and law.rotation(np.array([1.0])).shape == (1, 3, 3)
    with pytest.raises(SixAxisPlanError, match="needs an 'orientation' block"):
        task_from_spec(ARC)
    task_from_spec({**spec, 'process': {'tcp_speed_max': 0.1}})     # a band: taken
    for bad in ({'tcp_speed_max': -0.1}, {'speed': 0.1}, [0.1]):
        with pytest.raises(SixAxisPlanError, match='process'):
            task_from_spec({**spec, 'process': bad})
    with pytest.raises(SixAxisPlanError, match='orientation law'):
        task_from_spec({**ARC, 'orientation': {'law': 'tangent'}})


def test_plan6_refuses_bad_files_in_one_line(tmp_path, capsys):
    from irb_planning.plan6_cli import main
    three_axis = tmp_path / 'three.yaml'
    three_axis.write_text('type: line\nwaypoints: [[0.55, -0.25, 0.25], [0.75, 0.2, 0.45]]\n')
    bad_law = tmp_path / 'bad.yaml'
    bad_law.write_text('type: line\nwaypoints: [[0.55, -0.25, 0.25], [0.75, 0.2, 0.45]]\n'
                       'orientation: {law: path_normal}\n')
    for f, words in ((tmp_path / 'missing.yaml', 'cannot read'),
                     (three_axis, "needs an 'orientation' block"),
                     (bad_law, 'a line has no plane')):
        assert main(['--path-file', str(f), '--duration', '2']) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err, err
    assert main(['--path-file', str(three_axis)]) == 2          # energy without a duration
    assert '--duration' in capsys.readouterr().err
    for bad in (['--grid', '5'], ['--tcp', '0', '0', 'nan'], ['--duration', 'inf'],
                ['--place-n', '0', '1', '1'], ['--place-n', '2', '2', '2', '--place-lo', '0',
                                               '0', '0', '--place-hi', '0', '-1', '0'],
                ['--place-refine', '0.01'], ['--place-n', '2', '2', '2', '--place-refine',
                                             '-0.01']):
        assert main(['--path-file', str(three_axis), '--duration', '2'] + bad) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_plan6_refuses_an_unreachable_path(tmp_path, capsys):
    from irb_planning.plan6_cli import main
    far = tmp_path / 'far.yaml'
    far.write_text('type: line\nwaypoints: [[2.5, 0.0, 0.3], [2.7, 0.1, 0.3]]\n'
                   'orientation: {law: fixed, rpy: [3.14159, 0.0, 0.0]}\n')
    assert main(['--path-file', str(far), '--duration', '2']) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and 'unreachable' in err and 'workspace' in err, err


def test_wrist_friction_one_source(planned):
    """The planner's friction of joints 4-6 is irb_description dynamics.yaml's
    ``wrist_friction`` (read here from the file itself), its own config holds no copy, and a
    plan with the map built here equals the planner's to the bit (plans unchanged)."""
    import dataclasses

    import yaml
    from irb_description.friction import FrictionMap, JointFriction
    from irb_description.params import config_path

    from irb_planning.six_axis_plan import load_config
    planner, path, law, plan, _ = planned
    assert 'wrist_friction' not in load_config()
    with open(config_path('dynamics.yaml'), encoding='utf-8') as f:
        raw = yaml.safe_load(f)
    w = raw['wrist_friction']
    fm = planner.limits.friction
    for i, j in enumerate(fm.joints[3:]):
        assert (j.coulomb, j.static, j.stribeck_velocity, j.viscous) == (
            w['coulomb_nm'][i], w['static_nm'][i], w['stribeck_velocity_rad_s'][i],
            w['viscous_nms_rad'][i])
    own = [JointFriction(coulomb=float(w['coulomb_nm'][i]), static=float(w['static_nm'][i]),
                         stribeck_velocity=float(w['stribeck_velocity_rad_s'][i]),
                         viscous=float(w['viscous_nms_rad'][i]),
                         valid_range=tuple(float(x) for x in w['valid_range_rad_s']))
           for i in range(3)]
    limits = dataclasses.replace(planner.limits, friction=FrictionMap(
        fm.joint_names, fm.joints[:3] + tuple(own), 'built by the test'))
    other = SixAxisPlanner(limits=limits)
    again = other.plan(other.problem(path, law, GRID), 'energy', DURATION)
    for k in ('t', 'q', 'qd', 'qdd'):
        assert np.array_equal(np.asarray(again.trajectory[k]), np.asarray(plan.trajectory[k]))


def test_smoothness_limits_hold_as_played(planned):
    """The plan keeps the smoothness limits (issue 28) on six joints, measured here apart
    from the planner's check: joint jerk from this test's quintic (BPoly's third derivative),
    the TCP jerk as third differences of irb_description's link-chain TCP (not the check's DH
    product) on a 10 kHz clock, the rigid-body torque rate from pinocchio's RNEA of the played
    samples. The arc has no blend, so nothing is exempt."""
    from irb_description.six_axis_dynamics import SixAxisDynamics
    planner, path, law, plan, _ = planned
    sm = planner.smooth_limits
    assert sm is not None and sm.jerk.size == 6 and np.all(sm.jerk[3:] > 0)
    tr = plan.trajectory
    t, q, qd, qdd = (np.asarray(tr[k]) for k in ('t', 'q', 'qd', 'qdd'))
    dt = 1e-4
    ts = t[0] + np.arange(int((t[-1] - t[0]) / dt) + 1) * dt
    polys = [BPoly.from_derivatives(t, np.stack([q[:, i], qd[:, i], qdd[:, i]], 1), orders=5)
             for i in range(6)]
    jerk = np.stack([p.derivative(3)(ts) for p in polys], axis=1)
    assert np.all(np.abs(jerk).max(axis=0) <= sm.jerk * (1 + 1e-6)), np.abs(jerk).max(axis=0)
    qs = np.stack([p(ts) for p in polys], axis=1)
    p_tcp = planner.kin.fk(qs)[:, :3, 3]
    j_tcp = np.linalg.norm(np.diff(p_tcp, 3, axis=0), axis=1) / dt ** 3
    # third differences average the jerk over 3 dt; round-off ~1e-16 m / dt^3 = 1e-4 m/s^3
    assert j_tcp.max() <= sm.tcp_jerk * (1 + 1e-3), j_tcp.max()
    dyn = SixAxisDynamics()
    k = slice(None, None, 10)                              # 1 kHz: the rate between samples
    qds = np.stack([p.derivative(1)(ts[k]) for p in polys], axis=1)
    qdds = np.stack([p.derivative(2)(ts[k]) for p in polys], axis=1)
    tau = np.array([dyn.inverse_dynamics(a, b, c) for a, b, c in zip(qs[k], qds, qdds)])
    rate = np.abs(np.diff(tau, axis=0)).max(axis=0) / (10 * dt)
    assert np.all(rate <= sm.torque_rate * (1 + 1e-3)), rate
    # the planner's own peaks are those measured here (its check plays the same points)
    assert plan.check.peak_jerk == pytest.approx(np.abs(jerk).max(axis=0), rel=1e-3, abs=1e-3)
    assert plan.check.tcp_jerk_peak == pytest.approx(j_tcp.max(), rel=0.02)


def test_electrical_energy_model(planned):
    """An energy plan on the six axes' electrical model: its played electrical energy (the
    model applied here to this test's own torques: pinocchio RNEA + the friction map's numbers
    of the played samples) is what the optimiser says, and at most the mechanical plan's
    electrical energy (the objective each minimises)."""
    from irb_description.electrical import load_electrical
    from irb_description.six_axis_dynamics import SixAxisDynamics
    planner, path, law, mech, _ = planned
    prob = planner.problem(path, law, GRID, energy_model='electrical')
    plan = planner.plan(prob, 'energy', DURATION)
    assert plan.energy_model == 'electrical' and not plan.check.problems
    model = load_electrical().axes(6)
    dyn = SixAxisDynamics()
    fm = planner.limits.friction
    tr = plan.trajectory
    t, q, qd, qdd = (np.asarray(tr[k]) for k in ('t', 'q', 'qd', 'qdd'))
    ts = np.linspace(t[0], t[-1], 4001)
    polys = [BPoly.from_derivatives(t, np.stack([q[:, i], qd[:, i], qdd[:, i]], 1), orders=5)
             for i in range(6)]
    qs, qds, qdds = (np.stack([p.derivative(d)(ts) if d else p(ts) for p in polys], axis=1)
                     for d in (0, 1, 2))
    tau = np.array([dyn.inverse_dynamics(a, b, c) for a, b, c in zip(qs, qds, qdds)])
    tau = tau + fm.torque(qds)
    e_own = model.energy(ts, tau, qds)
    assert e_own == pytest.approx(plan.electrical_energy, rel=2e-3)
    assert plan.optimizer_energy == pytest.approx(plan.electrical_energy, rel=1e-2)
    assert plan.electrical_energy <= mech.electrical_energy * (1 + 1e-4), (
        plan.electrical_energy, mech.electrical_energy)


def test_placement_moves_the_task_and_keeps_refusals(planned):
    """Six-axis placement: a task moved by an offset is the same path shifted with the same
    tool orientations; the search plans every offset, keeps an unreachable one with its
    reason, and the best is the planned one, with the energy of the same plan made directly
    (the fixture's, same grid and duration)."""
    from irb_planning.six_axis_plan import place, placement_offsets, translated_spec
    planner, path, law, plan, _ = planned
    spec = {**ARC, 'orientation': {'law': 'path_normal'}}
    d = np.array([0.02, -0.03, 0.01])
    moved, moved_law = task_from_spec(translated_spec(spec, d))
    th = np.linspace(0.0, 2 * np.pi, 9)
    np.testing.assert_allclose(moved.point(th), path.point(th) + d, atol=1e-12)
    np.testing.assert_allclose(moved_law.rotation(th), law.rotation(th), atol=1e-12)
    assert spec['center'] == ARC['center']                       # the caller's spec untouched
    grid = placement_offsets([0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2, 1, 1])
    np.testing.assert_array_equal(grid, [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    seen = []
    res = place(planner, spec, grid, DURATION, 'mechanical', GRID,
                progress=lambda k, m, pt: seen.append((k, m)))
    assert seen == [(1, 2), (2, 2)]
    far = res.points[1]
    assert not np.isfinite(far.energy) and 'unreachable' in far.reason
    assert res.best is res.points[0] and res.best.energy == plan.energy
    with pytest.raises(SixAxisPlanError):
        translated_spec(spec, [0.0, np.nan, 0.0])


def test_linear_slerp_keyframe_refused_with_its_reason():
    """Plain slerp steps the rotation rate at an inner keyframe: with the jerk limits on the
    planner says so (instead of an infeasible NLP); the default smooth easing plans."""
    planner = SixAxisPlanner()
    frames = [{'theta': 0.0, 'rpy': [np.pi, 0.0, 0.0]},
              {'theta': float(np.pi), 'rpy': [np.pi, 0.3, 0.0]},
              {'theta': float(2 * np.pi), 'rpy': [np.pi, 0.0, 0.3]}]
    line = dict(type='line', waypoints=[[0.55, -0.25, 0.25], [0.75, 0.2, 0.45]])
    path, law = task_from_spec({**line, 'orientation': {'law': 'slerp', 'easing': 'linear',
                                                        'keyframes': frames}})
    with pytest.raises(SixAxisPlanError, match=r'rotation rate steps .*theta = 3\.1416'):
        planner.problem(path, law, GRID)
    path, law = task_from_spec({**line, 'orientation': {'law': 'slerp', 'keyframes': frames}})
    assert law.easing == 'smooth'
    plan = planner.plan(planner.problem(path, law, GRID), 'energy', 2.2)
    assert plan.check.ok and plan.check.orientation_error < np.radians(0.05)


def test_compass_refinement_of_a_placement_finds_the_minimum_inside_the_box(monkeypatch):
    """refine_placement on a stand-in energy (a bowl about c, refused where x < -0.05): from
    the 3 x 3 x 3 grid's best it walks to c within the last step, never plans a point twice or
    outside the box, keeps every point; with c outside the box it stops on the box's face
    and says so."""
    from irb_planning import six_axis_plan as sap

    calls = []

    def fake_place(planner, spec, offsets, duration, energy_model='electrical',
                   grid_size=40, progress=None):
        pts = []
        for d in np.atleast_2d(offsets):
            calls.append(tuple(np.round(d, 9)))
            if d[0] < -0.05:
                pts.append(sap.PlacementPoint(d.copy(), float('nan'), 'unreachable'))
            else:
                pts.append(sap.PlacementPoint(d.copy(), float(100 + 1e3 * np.sum((d - c) ** 2))))
        return sap.SixAxisPlacement(pts, energy_model, duration, grid_size)
    monkeypatch.setattr(sap, 'place', fake_place)
    lo, hi = np.full(3, -0.1), np.full(3, 0.1)
    grid = sap.placement_offsets(lo, hi, [3, 3, 3])
    for c, inside in ((np.array([0.03, -0.02, 0.05]), True),
                      (np.array([0.25, 0.0, 0.04]), False)):
        calls.clear()
        res = fake_place(None, {}, grid, 8.0)
        assert res.best.offset.tolist() == pytest.approx(
            [0.1 if not inside else 0.0, 0.0, 0.0])
        out = sap.refine_placement(None, {}, res, lo, hi, [0.1, 0.1, 0.1], 0.01)
        best = out.best
        assert len(set(calls)) == len(calls)                       # no point planned twice
        assert len(out.points) == len(calls)
        assert all(np.all((p.offset >= lo) & (p.offset <= hi)) for p in out.points)
        target = np.clip(c, lo, hi)
        assert np.all(np.abs(best.offset - target) <= 0.0125 + 1e-12), (best.offset, target)
        assert best.energy <= res.best.energy
        assert sap.on_box_edge(best.offset, lo, hi) == ([] if inside else [0])
        assert any(not np.isfinite(p.energy) for p in out.points)   # refusals kept


def test_a_process_band_holds_on_six_axes_as_played(planned):
    """A path file's process block (TCP speed band beyond 30 mm ramps, |TCP acceleration|) on
    the six-axis planner: the plan keeps it as played by this test's own player (quintic per
    joint at 2 kHz) and irb_description's link-chain FK (``SixAxisKinematics.fk``, not the
    check's DH product), speeds and accelerations by central differences; a band the path
    cannot keep at that duration is refused in one line naming it."""
    from irb_planning.six_axis_plan import SixAxisPlanError, task_process
    planner = planned[0]
    band = dict(tcp_speed_min=0.15, tcp_speed_max=0.3, tcp_ramp_length=0.03,
                tcp_accel_max=2.0)
    spec = {**ARC, 'orientation': {'law': 'path_normal'}, 'process': band}
    path, law = task_from_spec(spec)
    assert task_process(spec) == band
    prob = planner.problem(path, law, GRID, process=task_process(spec))
    plan = planner.plan(prob, 'energy', DURATION)
    tr = plan.trajectory
    t, q, qd, qdd = (np.asarray(tr[k]) for k in ('t', 'q', 'qd', 'qdd'))
    dt = 5e-4
    ts = np.arange(int(round((t[-1] - t[0]) / dt)) + 1) * dt + t[0]
    qs = np.stack([BPoly.from_derivatives(t, np.stack([q[:, i], qd[:, i], qdd[:, i]], 1),
                                          orders=5)(ts) for i in range(6)], axis=1)
    p = np.array([planner.kin.fk(x)[:3, 3] for x in qs])
    v = np.linalg.norm(p[2:] - p[:-2], axis=1) / (2 * dt)
    a = np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=1) / dt ** 2
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])[1:-1]
    inside = (s >= band['tcp_ramp_length'] + 1e-3) & (s <= s[-1] - band['tcp_ramp_length']
                                                       - 1e-3)
    assert abs(s[-1] - path.length) < 1e-3
    assert v.max() <= band['tcp_speed_max'] * (1 + 2e-3), v.max()
    assert v[inside].min() >= band['tcp_speed_min'] * (1 - 2e-3), v[inside].min()
    assert a.max() <= band['tcp_accel_max'] * (1 + 2e-3), a.max()
    # the planner's own figures agree with this measurement
    assert plan.check.tcp_speed_peak == pytest.approx(v.max(), rel=2e-3)
    assert plan.check.tcp_accel_peak == pytest.approx(a.max(), rel=5e-3)
    # the band costs energy: the same energy plan without it is not dearer
    free = planned[3]
    assert free.energy <= plan.energy * (1 + 1e-6)
    # a floor the duration cannot keep: 0.3 m/s over a 0.4 m arc needs < 1.4 s, not 2 s
    tight = task_process({'process': dict(band, tcp_speed_min=0.29)})
    with pytest.raises(SixAxisPlanError, match='process constraints'):
        planner.plan(planner.problem(path, law, GRID, process=tight), 'energy', DURATION)
