"""Six-joint control (issue 30): the plant and PD+ on n joints, the three-axis mode unchanged.

* The three-axis closed loop on the thesis circle reproduces main's code to the bit: a SHA-256
  of every logged array, generated once with main's irb_control at commit f012514 (before
  the n-joint change; ``_digest`` below, run against a ``git archive`` of that commit) and
  stored here. A change that moves the three-axis circle on purpose must regenerate them.
* The n-joint code paths (``PdPlusController._step_n``, ``Plant._substep_n``) run on three
  joints give the unrolled ones' results (the step to the bit, the substep to 1e-12): the
  two stay one algorithm.
* Six joints: plant and controller on the rectangle with the nozzle normal to its plane
  (joint path by the six-axis IK, ``joint_path6``), TCP pose measured by the DH-free
  ``SixAxisKinematics`` (its own rotation-matrix products, not pinocchio).
"""
import hashlib

import numpy as np
import pytest
from irb_description.orientation import joint_path6, orientation_from_spec
from irb_description.path import rectangle_path
from irb_description.six_axis import SixAxisKinematics, pose
from irb_description.six_axis_model import SixJointModel

from irb_control.closed_loop import (build_default, build_six_joint, simulate_closed_loop,
                                     six_axis_controller_config)
from irb_control.pd_plus import ControllerConfig, PdPlusController
from irb_control.plant import (Plant, PlantConfig, default_plant_yaml, load_plant_brakes,
                               load_plant_friction)
from irb_control.profiles import (polynomial_theta_of_time, profile_from_theta_samples,
                                  sine_trajectory)

FIELDS = ('t', 'q', 'qd', 'q_meas', 'qd_meas', 'tau_cmd', 'tau_applied', 'q_ref', 'qd_ref',
          'theta', 'mode', 'published', 'cam_t', 'cam_p')
#: main's irb_control at f012514, build_default(mode, duration_s=10.0), 12 s run, with the
#: thesis's constant gains (the inertia schedule of issue 29 is a deliberate change after it)
MAIN_DIGESTS = {
    'nominal': (2470, '5dd3b1c04578e48bdf82c42715f542b7db533e304ddcda74c1320aee448f0d84'),
    'file': (2464, 'ad688ebc97d38a58d8ac560be9aa46a1f01f6e14091cf9bbed5bf3c9bd92dc21')}
TCP = pose(np.eye(3), [0.0, 0.0, 0.10])        # the 0.10 m gluing nozzle


def _digest(r) -> str:
    h = hashlib.sha256()
    for k in FIELDS:
        h.update(np.ascontiguousarray(getattr(r, k)).tobytes())
    h.update(np.float64(r.energy).tobytes())
    h.update(r.stop_reason.encode())
    return h.hexdigest()


@pytest.mark.parametrize('mode', ['nominal', 'file'])
def test_three_axis_circle_is_main_to_the_bit(model, mode):
    plant, ctrl = build_default(mode, duration_s=10.0, model=model,
                                controller_config=ControllerConfig(
                                    gain_design_inertia_kg_m2=None))
    r = simulate_closed_loop(plant, ctrl, 12.0)
    assert (len(r.t), _digest(r)) == MAIN_DIGESTS[mode]


def _run(model, path, generic: bool, traj=None, hold_at=None):
    plant, ctrl = build_default('file', duration_s=4.0, model=model, path=path)
    if traj is not None:
        ctrl.set_time_trajectory(traj)
    plant.reset(ctrl.start_pose())
    if generic:
        ctrl.step = ctrl._step_n       # the n-joint step on three joints
    if hold_at is None:
        return simulate_closed_loop(plant, ctrl, 5.5)
    first = simulate_closed_loop(plant, ctrl, hold_at, stop_when_done=None)
    assert ctrl.hold()[0]
    rest = simulate_closed_loop(plant, ctrl, 1.5, enable=False)
    return first, rest


@pytest.mark.parametrize('case', ['circle', 'rectangle_hold', 'time_trajectory'])
def test_n_joint_step_equals_the_unrolled_step_on_three_joints(model, case):
    path = traj = hold_at = None
    if case == 'rectangle_hold':     # delay prediction 'commanded', PathTracker, a hold
        path, hold_at = rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025), 2.0
    if case == 'time_trajectory':
        traj = sine_trajectory(np.array([0.0, 0.9, 0.25]), 1, 0.5)
    a = _run(model, path, False, traj, hold_at)
    b = _run(model, path, True, traj, hold_at)
    for ra, rb in zip(*((a, b) if hold_at else ((a,), (b,)))):
        assert ra.stop_reason == rb.stop_reason == ''
        for k in FIELDS:
            assert np.array_equal(getattr(ra, k), getattr(rb, k), equal_nan=True), k


def test_n_joint_substep_equals_the_unrolled_one_on_three_joints(model):
    """Single substeps from the same states: sliding, sticking, mixed, on a brake."""
    _, pf = load_plant_friction(default_plant_yaml(), model.joint_names)
    rng = np.random.default_rng(3)
    for brakes in ({}, load_plant_brakes(default_plant_yaml())):
        a = Plant(model, pf, PlantConfig(**brakes))
        b = Plant(model, pf, PlantConfig(**brakes))
        b._substep = b._substep_n
        for k in range(300):
            q = np.array([0.0, 0.9, 0.25]) + rng.uniform(-0.3, 0.3, 3)
            v = rng.uniform(-0.5, 0.5, 3) * (rng.random(3) < 0.6)     # some joints at rest
            tau = a.model.gravity(q) + rng.normal(0.0, 25.0, 3)
            for p in (a, b):
                p.state.q, p.state.qd = q.copy(), v.copy()
                p.braked = bool(brakes) and k % 3 == 0
                p._substep(tau.tolist())
            np.testing.assert_allclose(b.state.qd, a.state.qd, rtol=0, atol=1e-12)
            np.testing.assert_allclose(b.state.q, a.state.q, rtol=0, atol=1e-12)
            np.testing.assert_allclose(b.friction_torque, a.friction_torque, rtol=0,
                                       atol=1e-9)


@pytest.fixture(scope='module')
def six():
    return SixJointModel(TCP)


@pytest.fixture(scope='module')
def task():
    path = rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025)
    law = orientation_from_spec({'law': 'path_normal', 'normal': [0.3, 0.1, 1.0],
                                 'x_mode': 'fixed'}, path)
    return path, law


def test_six_joint_model_is_the_arm(six, model):
    kin = SixAxisKinematics(tcp=TCP)
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = rng.uniform(six.limits.lower, six.limits.upper) * 0.5
        np.testing.assert_allclose(six.fk_pose(q), kin.fk(q), atol=1e-9)
        # the TCP Jacobian against finite differences of fk
        J = np.array([(six.fk(q + 1e-7 * e) - six.fk(q - 1e-7 * e)) / 2e-7
                      for e in np.eye(6)]).T
        np.testing.assert_allclose(six.jacobian(q), J, atol=1e-6)
    # joints 4-6 at 0 and no TCP: the three-axis model's TCP and, without the wrist's rotor
    # inertias, its arm dynamics
    bare = SixJointModel(wrist_armature=False)
    q3 = np.array([0.2, 0.8, 0.3])
    q6 = np.r_[q3, 0.0, 0.0, 0.0]
    np.testing.assert_allclose(bare.fk(q6), model.fk(q3), atol=1e-12)
    import pinocchio as pin
    M6 = pin.crba(bare.model, bare.data, q6)
    np.testing.assert_allclose(np.triu(M6)[:3, :3], np.triu(model.mass_matrix(q3)), atol=1e-9)
    # the wrist armature = gear^2 J_rotor of dynamics.yaml, on joints 4-6 only
    arm = np.asarray(six.model.armature)
    assert np.all(arm[:3] == 0) and np.all(arm[3:] > 0.02)
    assert six.friction.joint_names == tuple(f'joint_{i}' for i in range(1, 7))
    assert len(six.limits.torque) == 6


def test_six_joint_plant_basics(six, model):
    _, pf = load_plant_friction(default_plant_yaml(), six.joint_names)
    q0 = np.array([0.0, 0.6, 0.2, 0.3, -0.5, 0.4])
    p = Plant(six, pf, PlantConfig(initial_q=tuple(q0)))
    # substeps 0 (the default): 10 with six joints, 5 with three (the thesis plant)
    assert p.config.substeps == 10 and p._h == pytest.approx(PlantConfig().period_s / 10)
    _, pf3 = load_plant_friction(default_plant_yaml(), model.joint_names)
    assert Plant(model, pf3, PlantConfig()).config.substeps == 5
    assert Plant(six, pf, PlantConfig(initial_q=tuple(q0), substeps=5)).config.substeps == 5
    p.command(np.zeros(3))                      # three torques for six joints: refused
    assert 'rejected invalid command' in p.events[-1][1]
    g = p.model.model
    import pinocchio as pin
    hold = pin.computeGeneralizedGravity(g, g.createData(), q0)
    for _ in range(100):                         # gravity held: nothing moves (stiction)
        m = p.measure()
        assert m.q.shape == m.qd.shape == m.tau.shape == (6,)
        p.command(hold)
        p.step()
    assert np.max(np.abs(p.state.q - q0)) < 1e-9
    # a wrist torque below joint 6's breakaway (1.25 N m) leaves it stuck, above moves it
    for extra, moves in ((1.0, False), (2.5, True)):
        p.reset(q0)
        for _ in range(60):
            p.command(hold + np.r_[0, 0, 0, 0, 0, extra])
            p.step()
        assert bool(abs(p.state.q[5] - q0[5]) > 1e-3) == moves, extra
    with pytest.raises(ValueError, match='initial_q has 3 joints'):
        Plant(six, pf, PlantConfig())
    with pytest.raises(ValueError, match='6 joints, the model 3'):
        PdPlusController(model, rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025),
                         six_axis_controller_config())
    with pytest.raises(ValueError, match='3 joints, the model 6'):
        PdPlusController(six, rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2,
                                             0.025), ControllerConfig())


def test_six_joint_closed_loop_follows_path_and_orientation(six, task):
    """The rectangle with the nozzle normal to its plane, rest to rest in 6 s (mean TCP speed
    0.16 m/s, peak ~0.30 m/s), the plant's own friction as feed-forward: every joint moves,
    no stop, and the TCP stays on the path with the nozzle on its law (bounds with margin
    over the measured 0.36 mm / 0.30 deg; the goals are measured by
    irb_bringup/benchmarks/bench_six_joint.py)."""
    path, law = task
    kin = SixAxisKinematics(tcp=TCP)
    ref = np.linspace(0.0, 2 * np.pi, 721)
    cfg = joint_path6(kin, path, law, ref).configuration

    def joints(theta):
        return joint_path6(kin, path, law, theta, configuration=cfg, derivatives=True)
    t, th, thd, thdd = polynomial_theta_of_time(6.0)
    prof = profile_from_theta_samples(six, path, th, thd, thdd, t, grid=1441, joints=joints)
    assert prof.q.shape == (1441, 6)
    plant, ctrl = build_six_joint(prof, path, TCP, friction_mode='file', model=six)
    r = simulate_closed_loop(plant, ctrl, 7.5)
    assert r.stop_reason == '' and r.finished()
    sel = r.mode == 2
    assert np.all(np.ptp(r.q[sel], axis=0) > 0.05)          # all six joints move
    T = kin.fk(r.q[sel])
    pos = path.distance(T[:, :3, 3])
    th = np.array([path.theta_of(p) for p in T[:, :3, 3]])
    th[-20:] = np.where(th[-20:] < 1.0, th[-20:] + 2 * np.pi, th[-20:])   # the lap's end
    R = law.rotation(np.clip(th, 0, 2 * np.pi))
    ang = 2 * np.arcsin(np.clip(np.linalg.norm((R - T[:, :3, :3]).reshape(-1, 9), axis=1)
                                / np.sqrt(8), 0, 1))
    assert pos.max() < 1.0e-3, pos.max()
    assert np.degrees(ang.max()) < 1.0, np.degrees(ang.max())


def test_six_joint_model_terms_are_the_matrix_formulation(six):
    """``_model_terms_n`` on six joints (two RNEA passes, C(q, u) w by polarization) against
    M(q) a + C(q, u) w + g(q) and diag M built here from pinocchio's matrices (the upper
    triangle crba fills, the Coriolis matrix, gravity), with u != w, at random states."""
    import pinocchio as pin
    ctrl = PdPlusController(six, rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2,
                                                0.025), six_axis_controller_config())
    assert ctrl._fast
    pm = six.model
    pd = pm.createData()
    rng = np.random.default_rng(7)
    for _ in range(50):
        q = rng.uniform(six.limits.lower, six.limits.upper) * 0.8
        u, w = rng.normal(0.0, 1.5, 6), rng.normal(0.0, 1.5, 6)
        a = rng.normal(0.0, 5.0, 6)
        M = pin.crba(pm, pd, q).copy()
        M = np.triu(M) + np.triu(M, 1).T
        want = M @ a + pin.computeCoriolisMatrix(pm, pd, q, u) @ w \
            + pin.computeGeneralizedGravity(pm, pd, q)
        tm, mdg = ctrl._model_terms_n(q.tolist(), u.tolist(), w.tolist(), a.tolist())
        scale = np.abs(M @ np.abs(a)).max() + np.abs(want).max()
        np.testing.assert_allclose(tm, want, rtol=0, atol=1e-12 * scale)
        assert mdg == M.diagonal().tolist()


def test_six_joint_step_equals_the_matrix_formulation_in_closed_loop(six, task):
    """The six-joint step's cheap formulation (``_fast``: RNEA model terms, math.exp in the
    friction feed-forward) against the matrix formulation of the three-joint step
    (``_fast`` False: crba, Coriolis matrix, gravity, numpy's exp) in the closed loop with
    config/pdplus_six_axis.yaml (stiction prediction on the wrist, which moves): the same
    modes and commands sent, every array within 1e-9 of its largest value."""
    path, law = task
    kin = SixAxisKinematics(tcp=TCP)
    cfg = joint_path6(kin, path, law, np.linspace(0.0, 2 * np.pi, 721)).configuration
    t, th, thd, thdd = polynomial_theta_of_time(3.0)
    prof = profile_from_theta_samples(
        six, path, th, thd, thdd, t, grid=721,
        joints=lambda x: joint_path6(kin, path, law, x, configuration=cfg, derivatives=True))
    runs = []
    for fast in (True, False):
        plant, ctrl = build_six_joint(prof, path, TCP, friction_mode='file', model=six)
        assert ctrl._stick_pred and ctrl._fast
        ctrl._fast = fast
        runs.append(simulate_closed_loop(plant, ctrl, 4.0))
    a, b = runs
    assert a.stop_reason == b.stop_reason == '' and a.finished()
    assert np.array_equal(a.mode, b.mode) and np.array_equal(a.published, b.published)
    assert np.ptp(a.q[:, 3:], axis=0).min() > 0.05          # the wrist moves
    for k in FIELDS:
        x, y = np.asarray(getattr(a, k), float), np.asarray(getattr(b, k), float)
        assert x.shape == y.shape, k
        assert np.array_equal(np.isnan(x), np.isnan(y)), k
        ok = ~np.isnan(x)
        scale = max(np.abs(x[ok]).max(), 1e-300) if ok.any() else 1.0
        np.testing.assert_allclose(x[ok], y[ok], rtol=0, atol=1e-9 * scale, err_msg=k)


def test_simulator_node_with_six_joints():
    """The simulator node with joints:=6: all six joints measured in /joint_states, commands
    of six joints by name applied, a three-joint command refused (in-process, no DDS)."""
    rclpy = pytest.importorskip('rclpy')
    import os

    from rclpy.parameter import Parameter
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState

    from irb_control.simulator_node import SimulatorNode, _stamp
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    q0 = [0.0, 0.6, 0.2, 0.3, -0.5, 0.4]
    node = SimulatorNode(context=ctx, parameter_overrides=[
        Parameter('joints', value=6), Parameter('initial_positions', value=q0),
        Parameter('tcp_xyz', value=[0.0, 0.0, 0.1])])
    try:
        sent = []
        node.pub_state = type('C', (), {'publish': lambda self, m: sent.append(m)})()
        measured = []
        measure = node.plant.measure
        node.plant.measure = lambda: measured.append(measure()) or measured[-1]
        stamp = _stamp(1.0)
        node._publish_state(stamp)
        m = deserialize_message(sent[-1], JointState)
        assert list(m.name) == [f'joint_{i}' for i in range(1, 7)]
        assert m.position.tolist() == measured[-1].q.tolist()
        np.testing.assert_allclose(m.position, q0, atol=1e-4)
        applied = []
        node.plant.command = lambda tau: applied.append(np.asarray(tau).tolist())
        names = ['joint_6', 'joint_5', 'joint_4', 'joint_3', 'joint_2', 'joint_1']
        cmd = JointState(name=names, effort=[6.0, 5.0, 4.0, 3.0, 2.0, 1.0])
        cmd.header.stamp = stamp
        node.on_command_raw(serialize_message(cmd))
        assert applied[-1] == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
        stamp = _stamp(1.004032)
        node._publish_state(stamp)
        three = JointState(name=['joint_1', 'joint_2', 'joint_3'], effort=[1.0, 2.0, 3.0])
        three.header.stamp = stamp
        node.on_command_raw(serialize_message(three))
        assert len(applied) == 1                    # joints 4-6 missing: refused
        assert node.plant.n == 6 and node.plant.config.brake_torque_nm[3:] == (20.0, 20.0,
                                                                               10.0)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


@pytest.fixture(scope='module')
def line_task():
    """A line with the nozzle pointing down (no piece ends: a plan sampled anywhere keeps the
    gate's consistency rule)."""
    from irb_description.orientation import FixedOrientation
    from irb_description.path import LinePath
    return LinePath([0.55, -0.2, 0.3], [0.75, 0.15, 0.4]), FixedOrientation.from_axes(
        [0.0, 0.0, -1.0])


def _six_joint_plan(six, task, duration=3.0):
    """A six-joint plan along ``task`` (t, q, qd, qdd), as the gate receives it."""
    path, law = task
    kin = SixAxisKinematics(tcp=TCP)
    t, th, thd, thdd = polynomial_theta_of_time(duration, 301)
    jp = joint_path6(kin, path, law, th, derivatives=True)
    return (t, jp.q, jp.dq * thd[:, None],
            jp.ddq * thd[:, None] ** 2 + jp.dq * thdd[:, None])


def test_plan_gate_accepts_six_joint_plans(six, line_task):
    task = line_task
    from irb_control.plan_checks import PlanRejected
    from irb_control.plan_gate import GateConfig, check_message_arrays
    path, _ = task
    t, q, qd, qdd = _six_joint_plan(six, task)
    order = [5, 0, 3, 1, 4, 2]                       # by name, in any order
    names = [f'joint_{i + 1}' for i in order]
    cfg = GateConfig(joints=6, tcp_xyz=(0.0, 0.0, 0.1))
    res = check_message_arrays(names, t, q[:, order], qd[:, order], qdd[:, order], six, path,
                               cfg, six.friction)
    assert res['kind'] == 'path' and res['arrays']['q'].shape[1] == 6
    np.testing.assert_allclose(res['arrays']['q'][0], q[0], atol=1e-12)
    with pytest.raises(PlanRejected, match='must be'):      # joints 4-6 missing
        check_message_arrays(names[:3], t, q[:, :3], qd[:, :3], qdd[:, :3], six, path, cfg,
                             six.friction)
    with pytest.raises(PlanRejected, match='three-axis model only'):
        check_message_arrays(['theta'], t, t[:, None], np.ones((t.size, 1)),
                             np.zeros((t.size, 1)), six, path, cfg, six.friction)


def test_pdplus_node_with_six_joints(six, line_task):
    task = line_task
    """pdplus with joints:=6 (config/pdplus_six_axis.yaml's gains): a six-joint plan offered,
    enabled, and a six-joint joint state answered with six torques by name."""
    rclpy = pytest.importorskip('rclpy')
    import os
    import uuid

    from rclpy.parameter import Parameter
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    from irb_control.pdplus_node import PdPlusNode
    from irb_control.profiles import profile_from_joint_trajectory
    c = six_axis_controller_config()
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    try:
        over = [Parameter('joints', value=6), Parameter('tcp_xyz', value=[0.0, 0.0, 0.1]),
                Parameter('builtin_profile', value='none'),
                Parameter('require_axis_status', value=False)]
        over += [Parameter(k, value=list(getattr(c, k))) for k in (
            'kp', 'kd', 'torque_rate_limit_nm_s', 'max_tracking_error_rad',
            'gain_design_inertia_kg_m2')]
        node = PdPlusNode(context=ctx, namespace=f'/t{uuid.uuid4().hex[:8]}',
                          parameter_overrides=over)
        try:
            assert node.ctrl.n == 6 and node.ctrl.kp.tolist() == list(c.kp)
            sent = []
            node.pub_cmd = type('C', (), {'publish': lambda self, m: sent.append(m)})()
            node.pub_state = type('C', (), {'publish': lambda self, m: None})()
            path, _ = task
            t, q, qd, qdd = _six_joint_plan(six, task)
            node.ctrl.set_path_profile(profile_from_joint_trajectory(six, path, t, q, qd, qdd),
                                       path)
            assert node.ctrl.enable()[0]
            s = node.get_clock().now().nanoseconds * 1e-9
            msg = JointState(name=[f'joint_{i}' for i in range(6, 0, -1)],
                             position=q[0][::-1].tolist(), velocity=[0.0] * 6)
            msg.header.stamp.sec, msg.header.stamp.nanosec = int(s), int((s % 1) * 1e9)
            node.on_state(msg)
            cmd = deserialize_message(sent[-1], JointState) if isinstance(sent[-1], bytes) \
                else sent[-1]
            assert list(cmd.name) == [f'joint_{i}' for i in range(1, 7)]
            assert len(cmd.effort) == 6 and np.all(np.isfinite(cmd.effort))
        finally:
            node.destroy_node()
        with pytest.raises(Exception, match="builtin_profile 'none'"):
            PdPlusNode(context=ctx, parameter_overrides=[Parameter('joints', value=6)])
    finally:
        rclpy.try_shutdown(context=ctx)


def test_pdplus_runs_the_stiction_prediction_only_on_a_map_file():
    """pdplus_six_axis.yaml turns the wrist's stiction prediction on; with the nominal map it
    made the wrist worse (0.74 against 0.44 deg), so pdplus keeps it only with friction_mode
    'file' and says so otherwise."""
    import os
    import uuid
    rclpy = pytest.importorskip('rclpy')
    from rclpy.parameter import Parameter

    from irb_control.pdplus_node import PdPlusNode
    c = six_axis_controller_config()
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    try:
        for mode, kept in (('nominal', False), ('file', True)):
            over = [Parameter(k, value=list(getattr(c, k))) for k in (
                'kp', 'kd', 'torque_rate_limit_nm_s', 'max_tracking_error_rad',
                'gain_design_inertia_kg_m2')]
            over += [Parameter('joints', value=6), Parameter('builtin_profile', value='none'),
                    Parameter('stribeck_measured', value=[False] * 3 + [True] * 3),
                    Parameter('stiction_prediction', value=True),
                    Parameter('friction_mode', value=mode),
                    Parameter('friction_map_file', value=str(default_plant_yaml()))]
            node = PdPlusNode(context=ctx, namespace=f'/t{uuid.uuid4().hex[:8]}',
                              parameter_overrides=over)
            try:
                assert node.ctrl.config.stiction_prediction is kept, mode
                assert node.ctrl._stick_pred is kept, mode
            finally:
                node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
