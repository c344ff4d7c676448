"""Fake axis computer core: faults, command acceptance, miss -> brakes -> latched error."""
import numpy as np
import pytest

from irb_control.axis_bridge_core import BridgeCore
from irb_control.axis_protocol import (ERR_BAD_COMMAND, ERR_COMM_TIMEOUT, ERR_NONE,
                                       ERR_POSITION_LIMIT, ERR_SPEED_LIMIT, ERR_TORQUE_LIMIT,
                                       MODE_IDLE, MODE_TORQUE, CommandPacket, decode_state,
                                       encode_command)
from irb_control.fake_axis_core import FakeAxisCore, FaultConfig
from irb_control.plant import Plant, PlantConfig, PlantFriction


@pytest.fixture
def plant(model):
    return Plant(model, PlantFriction.from_map(model.friction), PlantConfig(seed=3))


SESSION = 0x5E5510

CONTROLLER = ('127.0.0.1', 6510)


def command(seq, tau=(0.0, 0.0, 0.0), reset=False, session=SESSION, mode=MODE_TORQUE,
            wrist=(0.0, 0.0, 0.0)):
    t = np.zeros(6)
    t[:3], t[3:] = tau, wrist
    return encode_command(CommandPacket(seq, 0, t, mode, reset, session))


def engaged(plant, **kw):
    """A core in external control for 5 cycles, holding the robot."""
    core = FakeAxisCore(plant, session=SESSION, controller=CONTROLLER, **kw)
    for _ in range(5):
        core.begin_cycle()
        assert core.on_datagram(command(core.seq, hold_torque(plant)), CONTROLLER)
        core.end_cycle()
    return core


def timed_out(plant):
    """An engaged core after 3 cycles without a command: ERR_COMM_TIMEOUT latched."""
    core = engaged(plant, miss_limit=3)
    for _ in range(3):
        core.begin_cycle()
        core.end_cycle()
    assert core.error == ERR_COMM_TIMEOUT
    return core


def hold_torque(plant):
    return plant.model.gravity(plant.state.q)


def test_round_trip_holds_the_robot_against_gravity(plant):
    core = FakeAxisCore(plant, session=SESSION)
    q0 = plant.state.q.copy()
    for _ in range(100):
        (offset, data), = core.begin_cycle()
        state = decode_state(data)
        assert offset == 0.0 and state.seq == core.seq
        assert core.on_datagram(command(state.seq, hold_torque(plant)))
        core.end_cycle()
    assert core.error == ERR_NONE and core.missed_total == 0
    assert not plant.braked
    assert np.abs(plant.state.q - q0).max() < 1e-3
    last = decode_state(core.begin_cycle()[0][1])
    assert last.motors_on and last.mode == MODE_TORQUE


def test_misses_engage_brakes_and_latch_until_reset(plant):
    core = FakeAxisCore(plant, miss_limit=3, session=SESSION)
    for _ in range(5):
        core.begin_cycle()
        core.on_datagram(command(core.seq, hold_torque(plant)))
        core.end_cycle()
    for _ in range(3):                         # three cycles without an answer
        core.begin_cycle()
        core.end_cycle()
    assert core.error == ERR_COMM_TIMEOUT and plant.braked
    q_held = plant.state.q.copy()
    state = decode_state(core.begin_cycle()[0][1])
    assert state.error == ERR_COMM_TIMEOUT and state.mode == MODE_IDLE
    assert not core.on_datagram(command(core.seq, hold_torque(plant)))   # ignored while latched
    core.end_cycle()
    np.testing.assert_allclose(plant.state.q, q_held)     # held on brakes, no sagging
    core.begin_cycle()
    assert core.on_datagram(command(core.seq, hold_torque(plant), reset=True))
    assert core.error == ERR_NONE
    assert any('reset' in e for e in core.events)


def test_a_reset_only_command_clears_the_error_and_stays_on_the_brakes(plant):
    # what the bridge sends for ~/reset while the controller is stopped: idle, zero, reset
    core = timed_out(plant)
    core.begin_cycle()
    core.on_datagram(command(core.seq, reset=True, mode=MODE_IDLE), CONTROLLER)
    core.end_cycle()
    state = decode_state(core.begin_cycle()[0][1])
    assert core.error == ERR_NONE and state.error == ERR_NONE     # no ERR_BAD_COMMAND either
    assert state.mode == MODE_IDLE and plant.braked
    assert core.on_datagram(command(core.seq, hold_torque(plant)), CONTROLLER)  # engages again


def test_no_timeout_before_external_control_is_engaged(plant):
    core = FakeAxisCore(plant, miss_limit=3)
    for _ in range(20):                        # controller not started yet
        core.begin_cycle()
        core.end_cycle()
    assert core.error == ERR_NONE and core.missed_total == 0 and plant.braked


def test_wrong_sequence_and_garbage_are_rejected(plant):
    core = FakeAxisCore(plant, session=SESSION)
    core.begin_cycle()
    assert not core.on_datagram(command(core.seq - 1))
    assert not core.on_datagram(b'garbage')
    assert core.rejected == {'wrong_seq': 1, 'size': 1}


def test_excessive_torque_latches_an_error(plant):
    core = FakeAxisCore(plant, session=SESSION)
    core.begin_cycle()
    assert not core.on_datagram(command(core.seq, (1e4, 0.0, 0.0)))
    assert core.error & ERR_TORQUE_LIMIT and plant.braked


@pytest.mark.parametrize('kind', ['drop', 'delay', 'duplicate', 'reorder', 'corrupt', 'nan'])
def test_each_fault_kind_is_injected_and_handled_by_the_bridge(plant, kind):
    core = FakeAxisCore(plant, FaultConfig(**{kind: 0.2, 'seed': 5}), miss_limit=1000)
    bridge = BridgeCore()
    now = 0.0
    pending = []
    for _ in range(300):
        pending += [(now + off, d) for off, d in core.begin_cycle()]
        pending.sort(key=lambda x: x[0])
        due = [d for t, d in pending if t <= now + 1e-9]
        pending = [(t, d) for t, d in pending if t > now + 1e-9]
        for d in due:
            state, _ = bridge.on_datagram(d, now)
            if state is not None:
                reply = bridge.on_command(np.concatenate([hold_torque(plant), np.zeros(3)]),
                                          now + 5e-4)
                if reply is not None:
                    core.on_datagram(reply)
        core.end_cycle()
        now += plant.config.period_s
    assert core.injected[kind] > 30
    assert core.error == ERR_NONE
    rejected = bridge.stats.rejected
    expected = {'drop': None, 'delay': None, 'duplicate': 'duplicate', 'reorder': 'stale',
                'corrupt': 'crc', 'nan': 'nan'}[kind]
    if expected:
        assert rejected[expected] > 0.5 * core.injected[kind], rejected
    if kind in ('drop', 'delay', 'reorder', 'corrupt', 'nan'):
        assert core.missed_total > 0           # those cycles got no valid answer in time


def test_zero_torque_fall_latches_a_position_limit(plant):
    # issue 14 defect 7: zero torque let joint 2 fall to 3.23 rad (limit 1.92) with no error
    core = engaged(plant, miss_limit=10 ** 6)
    for _ in range(2000):
        core.begin_cycle()
        core.on_datagram(command(core.seq), CONTROLLER)
        core.end_cycle()
        if core.latched:
            break
    assert core.error & (ERR_POSITION_LIMIT | ERR_SPEED_LIMIT) and plant.braked
    lim = plant.model.limits
    assert np.all(plant.state.q <= lim.upper + 0.05) and np.all(plant.state.q >= lim.lower - 0.05)


@pytest.mark.parametrize('what, kwargs', [
    ('nan', None), ('bad mode', dict(mode=7)), ('wrist torque', dict(wrist=(1e300, 0, 0)))])
def test_bad_commands_latch_an_error(plant, what, kwargs):
    # defect 7: ERR_BAD_COMMAND was never set; joints 4-6 accepted +-1e300
    core = engaged(plant)
    core.begin_cycle()
    if kwargs is None:
        data = bytearray(command(core.seq, hold_torque(plant)))
        import struct
        import zlib
        struct.pack_into('<d', data, 24, float('nan'))
        struct.pack_into('<I', data, len(data) - 4, zlib.crc32(bytes(data[:-4])))
        data = bytes(data)
    else:
        data = command(core.seq, hold_torque(plant), **kwargs)
    assert not core.on_datagram(data, CONTROLLER)
    assert core.error & ERR_BAD_COMMAND and plant.braked


def test_idle_request_leaves_external_control_without_an_error(plant):
    # defect 7: mode_request = 0 was ignored
    core = engaged(plant)
    core.begin_cycle()
    assert not core.on_datagram(command(core.seq, mode=MODE_IDLE), CONTROLLER)
    assert not core.engaged and core.error == ERR_NONE and plant.braked
    core.end_cycle()
    assert decode_state(core.begin_cycle()[0][1]).mode == MODE_IDLE


def test_only_the_bound_controller_is_heard_and_may_reset(plant):
    # defect 7: any sender could reset a latched error
    core = timed_out(plant)
    core.begin_cycle()
    assert not core.on_datagram(command(core.seq, reset=True), ('127.0.0.1', 9999))
    assert not core.on_datagram(command(core.seq, reset=True, session=1), CONTROLLER)
    assert core.error == ERR_COMM_TIMEOUT
    assert core.rejected['foreign_peer'] == 1 and core.rejected['wrong_session'] == 1
    assert core.on_datagram(command(core.seq, hold_torque(plant), reset=True), CONTROLLER)
    assert core.error == ERR_NONE


def test_speed_limit_latches(plant):
    core = engaged(plant, miss_limit=10 ** 6)
    big = np.array([600.0, 0.0, 0.0])            # accelerate joint 1 until over its limit
    for _ in range(2000):
        core.begin_cycle()
        core.on_datagram(command(core.seq, hold_torque(plant) + big), CONTROLLER)
        core.end_cycle()
        if core.latched:
            break
    assert core.error & ERR_SPEED_LIMIT


def test_fault_config_validation():
    with pytest.raises(ValueError):
        FaultConfig(drop=1.5)
    with pytest.raises(ValueError):
        FaultConfig(delay_s=-1.0)


# --- issue 29: power modes and brakes through the protocol (version 3) ----------------------
def _power(core, code, tau=None, brake=0):
    from irb_control.axis_protocol import CommandPacket, encode_command
    t = np.zeros(6)
    if tau is not None:
        t[:3] = tau
    return core.on_datagram(encode_command(CommandPacket(core.seq, 0, t, MODE_TORQUE, False,
                                                         SESSION, brake, code)), CONTROLLER)


def test_power_modes_travel_in_the_command_and_come_back_in_the_state(model):
    """brakes requested in a command: brakes engaged at once, torque off, later commands
    ignored without a miss or an error; the states report brakes and mode; hold requested
    again: after the transition the commanded torque acts on the closed brake for the
    opening time, then the brakes open and the arm stays put (gravity torque commanded)."""
    from irb_control.axis_protocol import POWER_CODES
    from irb_control.plant import default_plant_yaml, load_plant_brakes
    plant = Plant(model, PlantFriction.from_map(model.friction),
                  PlantConfig(seed=3, **load_plant_brakes(default_plant_yaml())))
    core = engaged(plant)
    q0 = plant.state.q.copy()
    core.begin_cycle()
    assert not _power(core, POWER_CODES['brakes'], hold_torque(plant))
    core.end_cycle()
    for _ in range(50):                         # 0.2 s: torque commands, all ignored
        (_, data), = core.begin_cycle()
        s = decode_state(data)
        assert not core.on_datagram(command(core.seq, hold_torque(plant)), CONTROLLER)
        core.end_cycle()
    assert s.brakes_engaged and not s.motors_on and s.power_mode == POWER_CODES['brakes']
    assert core.error == ERR_NONE and core.missed_total == 0 and plant.braked
    assert core.rejected['motors_off'] == 51            # the request's own torque + 50
    core.transition_s = lambda a, b: 0.1        # hold takes 0.1 s here
    core.begin_cycle()
    _power(core, POWER_CODES['hold'], hold_torque(plant))
    core.end_cycle()
    opened = None
    for k in range(100):
        (_, data), = core.begin_cycle()
        s = decode_state(data)
        core.on_datagram(command(core.seq, hold_torque(plant)), CONTROLLER)
        core.end_cycle()
        if opened is None and not plant.braked:
            opened = k
    assert s.power_mode == POWER_CODES['hold'] and not s.brakes_engaged and s.motors_on
    # opened after the transition (0.1 s) plus the opening time on the closed brake
    assert opened * plant.config.period_s >= 0.1 + plant.config.brake_release_s - 0.01
    assert core.error == ERR_NONE
    assert np.max(np.abs(plant.state.q - q0)) < 1e-4          # nothing sagged


def test_a_version_2_controller_still_drives_the_version_3_computer(plant):
    from irb_control.axis_protocol import CommandPacket, encode_command
    core = FakeAxisCore(plant, session=SESSION, controller=CONTROLLER)
    for _ in range(10):
        core.begin_cycle()
        t = np.zeros(6)
        t[:3] = hold_torque(plant)
        v2 = encode_command(CommandPacket(core.seq, 0, t, MODE_TORQUE, False, SESSION,
                                          version=2))
        assert core.on_datagram(v2, CONTROLLER)
        core.end_cycle()
    assert core.engaged and core.error == ERR_NONE and not plant.braked
