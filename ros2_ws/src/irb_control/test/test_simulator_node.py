"""simulator node in-process: the serialized state and command paths (no DDS traffic)."""
import os

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from irb_control.simulator_node import SimulatorNode, _stamp  # noqa: E402

pytestmark = pytest.mark.ros


class _Capture:
    def __init__(self):
        self.sent = []

    def publish(self, msg):
        self.sent.append(msg)


@pytest.fixture
def sim():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    node = SimulatorNode(context=ctx)
    yield node
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)


def test_state_bytes_and_commands_by_name(sim):
    sim.pub_state = _Capture()
    measured = []
    measure = sim.plant.measure
    sim.plant.measure = lambda: measured.append(measure()) or measured[-1]
    stamp = _stamp(12.5)
    sim._publish_state(stamp)
    m = deserialize_message(sim.pub_state.sent[-1], JointState)
    y = measured[-1]
    assert m.header.stamp == stamp and list(m.name) == [f'joint_{i}' for i in range(1, 7)]
    # joints 1-3 as measured, the locked joints 4-6 at 0 with no speed and no torque
    assert m.position.tolist() == y.q.tolist() + [0.0] * 3
    assert m.velocity.tolist() == y.qd.tolist() + [0.0] * 3
    assert m.effort.tolist() == y.tau.tolist() + [0.0] * 3

    applied = []
    sim.plant.command = lambda tau: applied.append(np.asarray(tau).tolist())
    cmd = JointState(name=['joint_3', 'joint_1', 'joint_2'], effort=[3.0, 1.0, 2.0])
    cmd.header.stamp = stamp
    sim.on_command_raw(serialize_message(cmd))
    assert applied[-1] == [1.0, 2.0, 3.0] and len(sim.latencies) == 1
    stale = sim.stale_commands
    cmd.effort = [6.0, 4.0, 5.0]
    sim.on_command_raw(serialize_message(cmd))              # a second answer to one state
    assert applied[-1] == [1.0, 2.0, 3.0] and sim.stale_commands == stale + 1
    stamp = _stamp(12.504032)
    sim._publish_state(stamp)
    cmd.header.stamp = stamp
    sim.on_command(cmd)                                      # message-object path: the same
    assert applied[-1] == [4.0, 5.0, 6.0]
    unnamed = JointState(effort=[7.0, 8.0, 9.0, 10.0])
    sim.on_command_raw(serialize_message(unnamed))          # stamp 0: answers no state
    assert applied[-1] == [4.0, 5.0, 6.0] and sim.stale_commands == stale + 2
    stamp = _stamp(12.508064)
    sim._publish_state(stamp)
    unnamed.header.stamp = stamp
    sim.on_command_raw(serialize_message(unnamed))
    assert applied[-1] == [7.0, 8.0, 9.0]                   # no names: the first three
    n = len(applied)
    sim.on_command_raw(serialize_message(JointState(name=['joint_1'], effort=[1.0])))
    sim.on_command_raw(b'\x00\x01\x00')
    assert len(applied) == n                                  # refused, nothing applied


def test_camera_stamps_follow_sim_time_across_whole_seconds(sim):
    """Camera points are stamped at their sample time, also where the accumulated time sits a
    hair below a whole second (3.9999999999999587 s was once stamped 3.0 s)."""
    sim.pub_cam = _Capture()
    for _ in range(1200):                   # 4.84 s of simulated time: 484 camera points
        sim.plant.step()
        sim._after_step(_stamp)
    stamps = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
                       for m in sim.pub_cam.sent])
    assert stamps.size == 484               # 0, 0.01, ..., 4.83 s
    np.testing.assert_allclose(np.diff(stamps), 0.01, atol=2e-9)
    np.testing.assert_allclose(stamps, 0.01 * np.arange(stamps.size), atol=2e-9)


def test_electrical_power_from_the_plants_own_parameters(sim):
    """electrical_power: per-axis and total power of the applied torque at the true speed,
    from config/plant_electrical.yaml (not the planner's irb_description values), checked
    by hand-written formulas here."""
    import yaml
    from irb_control.plant import config_path
    sim.pub_state, sim.pub_power = _Capture(), _Capture()
    sim.plant.reset(np.array([0.0, 0.9, 0.25]), np.array([0.5, -0.4, 0.3]))
    assert sim.plant.request_power_mode('hold')[0]       # motors on, as in a motion
    tau = np.array([120.0, 80.0, -40.0])
    sim.plant.measure = lambda: type('Y', (), {'q': sim.plant.state.q, 'tau': tau,
                                               'qd': sim.plant.state.qd})()
    stamp = _stamp(3.0)
    sim._publish_state(stamp)
    m = sim.pub_power.sent[-1]
    assert m.header.stamp == stamp
    assert list(m.name) == ['joint_1', 'joint_2', 'joint_3', 'total_none', 'total_shared',
                            'total_regenerative']
    d = yaml.safe_load(open(config_path('plant_electrical.yaml')))
    ax = d['axes']
    ratio = np.array([120.0, 120.0, 100.0])        # irb_description dynamics.yaml
    qd = np.array([0.5, -0.4, 0.3])
    expect = []
    for i in range(3):
        pj = tau[i] * qd[i]
        eta = (ax['gear_efficiency_motoring'][i] if pj >= 0
               else ax['gear_efficiency_generating'][i])
        pg = pj / eta if pj >= 0 else pj * eta
        tm = tau[i] / ratio[i] / eta if pj >= 0 else tau[i] / ratio[i] * eta
        pe = pg + ax['resistance_ohm'][i] * (tm / ax['torque_constant_nm_a'][i]) ** 2
        ed = d['drive']['efficiency']
        expect.append((pe / ed if pe >= 0 else pe * ed) + ax['drive_idle_power_w'][i])
    np.testing.assert_allclose(m.effort[:3], expect, rtol=1e-12)
    sb = d['controller']['standby_power_w']
    assert m.effort[3] == pytest.approx(sb + sum(max(p, 0) for p in expect))
    assert m.effort[4] == pytest.approx(sb + max(sum(expect), 0))
    assert expect[1] < 0 < m.effort[4] < m.effort[3]   # axis 2 generates, shared recovers it


def test_power_modes_in_electrical_power_and_their_transition_times(sim):
    """Issue 29: each power mode's input power (irb_description power_modes on the plant's
    electrical model) in electrical_power; a change takes its transition time in simulated
    time, drawing the transition's energy meanwhile; modes changed by service, logged."""
    from std_srvs.srv import Trigger
    from irb_description.power_modes import load_power_modes
    # the YAML's transitions (up to 45 s) shortened 20x: the same rules, 3 s simulated
    pm = load_power_modes(electrical=sim.electrical).with_params(duration_factor=0.05)
    sim.power_modes = pm
    sim.pub_state, sim.pub_power = _Capture(), _Capture()
    pl = sim.plant
    pl.reset(np.array([0.0, 0.9, 0.25]))
    seen = []
    for mode in ('hold', 'brakes', 'bus_off', 'hibernate', 'hold'):
        r = sim.on_power_mode(mode, Trigger.Response())
        assert r.success, r.message
        tr = pm.transition(seen[-1] if seen else 'brakes', mode)
        t_end = pl.state.t + tr.duration_s
        energy = 0.0
        while pl.mode_target is not None:
            sim._publish_state(_stamp(pl.state.t))
            energy += sim.pub_power.sent[-1].effort[4] * pl.config.period_s
            pl.step()
        assert pl.power_mode == mode and pl.state.t == pytest.approx(t_end, abs=0.005)
        assert pl.braked                               # no command yet: on its brakes
        if mode != 'hold':
            assert energy == pytest.approx(tr.energy_j, rel=0.01, abs=1.0)
            sim._publish_state(_stamp(pl.state.t))
            m = sim.pub_power.sent[-1]
            assert list(m.effort[:3]) == [0.0, 0.0, 0.0]
            assert m.effort[3:] == pytest.approx([pm.power_w(mode)] * 3)
        seen.append(mode)
    assert seen[-1] == 'hold' and pm.power_w('hibernate') < pm.power_w('brakes')


def test_a_deeper_mode_ignores_commands_and_holds_the_arm_on_its_brakes(sim):
    """Brakes engaged with the torque off: the arm stays where it is (the brake torques of
    plant.yaml exceed gravity), commands are ignored (no error) until hold is asked for."""
    pl = sim.plant
    q0 = np.array([0.0, 0.9, 0.25])
    pl.reset(q0)
    assert pl.config.brake_torque_nm is not None      # plant.yaml's finite brakes
    assert pl.request_power_mode('brakes', 0.0)[0]
    for _ in range(250):                              # 1 s on the brakes, commands ignored
        pl.command(np.array([0.0, 300.0, 0.0]))
        pl.step()
    assert pl.rejected_mode == 250 and not pl.error and pl.braked
    np.testing.assert_array_equal(pl.state.q, q0)


def test_a_lockstep_simulator_in_a_deeper_mode_serves_its_services():
    """In lockstep, nobody answers while the drives are off on purpose, and the loop steps
    without waiting; it must still serve its services: ~/power_hold was never answered
    (irb_bringup cycle_run). Run loop in a thread, the request from another node, a bound."""
    import threading
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from std_srvs.srv import Trigger

    from irb_control.node_util import make_executor
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '17')))
    ns = f'/t_lockstep_{os.getpid()}'          # private names: no other simulator answers
    node = SimulatorNode(context=ctx, namespace=ns,
                         parameter_overrides=[Parameter('mode', value='lockstep')])
    client_node = rclpy.create_node('asker', context=ctx, namespace=ns)

    def spin():             # the executor made and run on one thread, as _spin does
        ex = make_executor(node.p['executor'], context=ctx)
        ex.add_node(node)
        try:
            node.run(ex)
        except Exception:  # noqa: BLE001 - the shutdown at the end of the test
            pass
    loop = threading.Thread(target=spin, daemon=True)
    try:
        assert node.plant.request_power_mode('brakes', 0.0)[0]
        assert node.plant.motors_off_requested
        loop.start()
        cex = SingleThreadedExecutor(context=ctx)
        cex.add_node(client_node)
        cli = client_node.create_client(Trigger, f'{ns}/simulator/power_hold')
        assert cli.wait_for_service(timeout_sec=20.0)
        fut = cli.call_async(Trigger.Request())
        cex.spin_until_future_complete(fut, timeout_sec=20.0)
        assert fut.done() and fut.result().success, 'the lockstep loop never served it'
        assert node.plant.mode_target == 'hold' or node.plant.power_mode == 'hold'
    finally:
        rclpy.try_shutdown(context=ctx)
        loop.join(timeout=10.0)
        client_node.destroy_node()
        node.destroy_node()
