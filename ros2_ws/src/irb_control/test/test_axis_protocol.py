"""Axis-computer protocol codec and bridge logic (pure, no sockets)."""
import struct
import zlib

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from irb_control.axis_bridge_core import BridgeCore
from irb_control.axis_protocol import (BRAKE_ENGAGE, COMMAND_SIZE, CYCLE_S, MODE_IDLE,
                                       POWER_CODES, POWER_NONE, STATE_SIZE, STATE_SIZE_V2,
                                       CommandPacket, ProtocolError, StatePacket, decode_command,
                                       SequenceTracker, decode_state, encode_command,
                                       encode_state, seq_newer)


def state(seq, q0=0.1, session=77):
    return StatePacket(seq, seq * 4_032_000, np.full(6, q0), np.arange(6) * 0.1,
                       np.arange(6) * -2.0, True, 1, 0, session)


def test_layout_sizes_are_fixed():
    assert STATE_SIZE == 24 + 18 * 8 + 4 + 4 + 4 == 180       # version 3
    assert STATE_SIZE_V2 == 24 + 18 * 8 + 4 + 4 == 176
    assert COMMAND_SIZE == 24 + 6 * 8 + 4 + 4 == 80
    assert len(encode_state(state(1))) == STATE_SIZE
    assert len(encode_command(CommandPacket(1, 0, np.ones(6)))) == COMMAND_SIZE


def test_state_round_trip_and_little_endian_header():
    p = state(0xFFFFFFF0)
    data = encode_state(p)
    assert data[:4] == b'IRBS'
    assert struct.unpack_from('<H', data, 4)[0] == 3            # version, little-endian
    assert struct.unpack_from('<I', data, 12)[0] == 77          # session
    assert struct.unpack_from('<I', data, 8)[0] == 0xFFFFFFF0   # sequence number
    back = decode_state(data)
    assert back.seq == p.seq and back.stamp_ns == p.stamp_ns and back.session == 77
    for a in ('q', 'qd', 'tau'):
        assert_array_equal(getattr(back, a), getattr(p, a))
    assert (back.motors_on, back.mode, back.error) == (True, 1, 0)


def test_command_round_trip():
    c = CommandPacket(42, 123, np.array([1.5, -2, 3, 0, 0, 0.25]), 1, True, 0xABCDEF01)
    back = decode_command(encode_command(c))
    assert back.seq == 42 and back.reset and back.mode_request == 1
    assert back.session == 0xABCDEF01
    assert_array_equal(back.tau_ref, c.tau_ref)


def corrupt(data, offset):
    b = bytearray(data)
    b[offset] ^= 0xFF
    return bytes(b)


def recrc(data):
    return data[:-4] + struct.pack('<I', zlib.crc32(data[:-4]))


@pytest.mark.parametrize('mutate, reason', [
    (lambda d: d[:-1], 'size'),
    (lambda d: d + b'\0', 'size'),
    (lambda d: recrc(b'XXXX' + d[4:]), 'magic'),
    (lambda d: recrc(d[:4] + struct.pack('<H', 1) + d[6:]), 'version'),
    (lambda d: corrupt(d, 40), 'crc'),
    (lambda d: recrc(d[:24] + struct.pack('<d', float('nan')) + d[32:]), 'nan'),
    (lambda d: recrc(d[:24] + struct.pack('<d', float('inf')) + d[32:]), 'nan'),
])
def test_malformed_states_are_rejected_with_a_reason(mutate, reason):
    with pytest.raises(ProtocolError) as exc:
        decode_state(mutate(encode_state(state(7))))
    assert exc.value.reason == reason


def test_command_is_not_a_state():
    with pytest.raises(ProtocolError):
        decode_state(encode_command(CommandPacket(1, 0, np.zeros(6))))


def test_sequence_comparison_wraps():
    assert seq_newer(1, 0) and not seq_newer(0, 1) and not seq_newer(5, 5)
    assert seq_newer(0, 0xFFFFFFFF) and seq_newer(3, 0xFFFFFFFE)


def test_bridge_replies_with_the_state_sequence_number():
    b = BridgeCore()
    s, event = b.on_datagram(encode_state(state(10)), now=0.0)
    assert s.seq == 10 and event == 'up'
    reply = b.on_command(np.ones(6), now=0.001)
    assert decode_command(reply).seq == 10 and decode_command(reply).session == 77
    assert b.on_command(np.ones(6), now=0.002) is None          # one reply per state
    assert b.stats.commands_sent == 1 and b.stats.late_commands == 1


def test_bridge_never_sends_a_command_older_than_one_cycle():
    b = BridgeCore()
    b.on_datagram(encode_state(state(1)), now=0.0)
    assert b.on_command(np.ones(6), now=CYCLE_S * 1.01) is None
    assert b.stats.late_commands == 1


def test_bridge_rejects_duplicates_stale_and_counts_them():
    b = BridgeCore()
    b.on_datagram(encode_state(state(5)), 0.0)
    assert b.on_datagram(encode_state(state(5)), 0.001) == (None, None)
    assert b.on_datagram(encode_state(state(3)), 0.002) == (None, None)
    assert b.on_datagram(corrupt(encode_state(state(6)), 30), 0.003) == (None, None)
    s, _ = b.on_datagram(encode_state(state(6)), 0.004)
    assert s.seq == 6
    assert b.stats.rejected == {'duplicate': 1, 'stale': 1, 'crc': 1}
    assert b.stats.unanswered == 1          # state 5 got no command before state 6


def test_bridge_never_forwards_non_finite_commands():
    b = BridgeCore()
    b.on_datagram(encode_state(state(1)), 0.0)
    assert b.on_command(np.array([0, 0, np.nan, 0, 0, 0]), 0.001) is None
    assert b.on_command(np.array([0, 0, 1, 0, 0]), 0.001) is None          # wrong length
    assert b.stats.rejected['command_nan'] == 2
    assert b.on_command(np.zeros(6), 0.002) is not None


def test_link_loss_and_recovery_are_reported_once():
    b = BridgeCore(link_timeout_s=0.05)
    assert b.check_link(0.0) is None                       # never up: nothing to lose
    b.on_datagram(encode_state(state(1)), 0.0)
    assert b.check_link(0.04) is None
    assert b.check_link(0.06) == 'lost'
    assert b.check_link(0.5) is None
    _, event = b.on_datagram(encode_state(state(2)), 0.6)
    assert event == 'recovered' and b.stats.link_losses == 1


def latched(seq):
    """A STATE datagram reporting a latched ERR_COMM_TIMEOUT."""
    s = state(seq)
    s.error = 1
    return encode_state(s)


def test_reset_is_repeated_until_the_axis_computer_reports_no_error():
    b = BridgeCore()
    b.on_datagram(latched(1), 0.0)
    assert not decode_command(b.on_command(np.zeros(6), 0.001)).reset   # not requested yet
    b.request_reset()
    for seq in (2, 3):                       # e.g. the first reset was lost: still latched
        b.on_datagram(latched(seq), 0.004 * seq)
        assert decode_command(b.on_command(np.zeros(6), 0.004 * seq + 0.001)).reset
    b.on_datagram(encode_state(state(4)), 0.016)                        # error cleared
    assert not decode_command(b.on_command(np.zeros(6), 0.017)).reset


def test_a_reset_reaches_the_axis_computer_while_the_controller_is_silent():
    # after a fault pdplus is stopped and sends nothing: the reset must not wait for its
    # commands (the soak on the axis path stayed latched for minutes, enable refused)
    b = BridgeCore()
    b.on_datagram(latched(1), 0.0)
    assert b.reset_command(0.001) is None                      # not requested
    b.request_reset()
    b.on_datagram(latched(2), 0.004)
    cmd = decode_command(b.reset_command(0.0041))
    assert cmd.reset and cmd.seq == 2 and cmd.mode_request == MODE_IDLE
    assert not cmd.tau_ref.any()
    assert b.reset_command(0.0042) is None                     # one answer per state
    assert b.on_command(np.zeros(6), 0.0043) is None           # the state is answered
    b.on_datagram(latched(3), 0.020)
    assert b.reset_command(0.020 + 2 * CYCLE_S) is None        # too old to answer
    b.on_datagram(encode_state(state(4)), 0.024)               # cleared: nothing more
    assert b.reset_command(0.0241) is None


def test_restart_of_the_axis_computer_is_followed_after_confirmation():
    # issue 14 defect 6: after a restart (seq back to 1) 250 of 250 states were rejected
    b = BridgeCore(resync_confirm=3)
    for k in range(1000, 1010):
        assert b.on_datagram(encode_state(state(k)), k * CYCLE_S)[0] is not None
    got = [b.on_datagram(encode_state(state(k, session=78)), 2.0 + k * CYCLE_S)
           for k in range(1, 6)]
    assert [g[0] is not None for g in got] == [False, False, True, True, True]
    assert got[2][1] == 'resync' and b.stats.resyncs == 1
    assert b.stats.rejected['session'] == 2
    reply = decode_command(b.on_command(np.zeros(6), 2.0 + 5 * CYCLE_S + 1e-4))
    assert reply.session == 78 and reply.seq == 5


def test_one_spoofed_packet_cannot_lock_the_link_out():
    # defect 6: one valid packet with seq + 2^31 locked the link (460 of 460 states rejected)
    b = BridgeCore()
    for k in range(1, 11):
        b.on_datagram(encode_state(state(k)), k * CYCLE_S)
    assert b.on_datagram(encode_state(state(10 + 2 ** 31)), 0.05)[0] is None
    assert b.on_datagram(encode_state(state(10 + 3000)), 0.05)[0] is None     # a jump
    for k in range(11, 471):
        assert b.on_datagram(encode_state(state(k)), k * CYCLE_S)[0] is not None
    assert b.stats.rejected == {'stale': 1, 'jump': 1}


def test_sequence_tracker_window_and_resync_after_a_real_gap():
    tr = SequenceTracker(window=250, confirm=3)
    assert tr.offer(5, 100) == 'resync'           # first contact
    assert tr.offer(5, 101) == 'accept' and tr.offer(5, 101) == 'duplicate'
    assert tr.offer(5, 351) == 'accept'           # 250 ahead: inside the window
    assert tr.offer(5, 2000) == 'jump'            # packets lost for long: three in a row
    assert tr.offer(5, 2001) == 'jump'
    assert tr.offer(5, 2002) == 'resync'
    assert tr.offer(5, 2003) == 'accept'
    assert tr.offer(5, 2003 + 2 ** 31) == 'stale'


# --- version 3: the power mode and the brakes (issue 29), version 2 still read --------------
def test_version_3_carries_power_mode_and_brakes_both_ways():
    p = state(5)
    p.brakes_engaged, p.power_mode, p.motors_on = True, POWER_CODES['bus_off'], False
    back = decode_state(encode_state(p))
    assert back.version == 3 and back.brakes_engaged and back.power_mode == 3   # bus_off
    c = CommandPacket(5, 0, np.zeros(6), MODE_IDLE, False, 77, BRAKE_ENGAGE,
                      POWER_CODES['hibernate'])
    data = encode_command(c)
    assert len(data) == COMMAND_SIZE == 80                     # the reserved bytes used
    assert struct.unpack_from('<BB', data, 74) == (BRAKE_ENGAGE, 4)
    back = decode_command(data)
    assert (back.brake_request, back.power_mode_request, back.version) == (1, 4, 3)


def test_version_2_packets_are_still_read():
    """A version-2 peer: its 176-byte state decodes (brakes = not motors_on, power mode
    unknown), its command (reserved bytes 0) decodes as no request; and a version-2 encoder
    writes exactly the version-2 layout."""
    p = state(9)
    p.version, p.motors_on = 2, False
    data = encode_state(p)
    assert len(data) == STATE_SIZE_V2 and struct.unpack_from('<H', data, 4)[0] == 2
    back = decode_state(data)
    assert back.version == 2 and back.brakes_engaged and back.power_mode == POWER_NONE
    c = CommandPacket(9, 0, np.ones(6), 1, False, 77, BRAKE_ENGAGE, 2, version=2)
    data = encode_command(c)
    assert struct.unpack_from('<HH', data, 4)[0] == 2 and data[74:76] == b'\0\0'
    back = decode_command(data)
    assert (back.brake_request, back.power_mode_request, back.version) == (0, 0, 2)
    assert_array_equal(back.tau_ref, np.ones(6))
