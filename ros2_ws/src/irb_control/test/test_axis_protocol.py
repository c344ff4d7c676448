"""Axis-computer protocol codec and bridge logic (pure, no sockets)."""
import struct
import zlib

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from irb_control.axis_bridge_core import BridgeCore
from irb_control.axis_protocol import (COMMAND_SIZE, CYCLE_S, STATE_SIZE, CommandPacket,
                                       ProtocolError, StatePacket, decode_command,
                                       decode_state, encode_command, encode_state, seq_newer)


def state(seq, q0=0.1):
    return StatePacket(seq, seq * 4_032_000, np.full(6, q0), np.arange(6) * 0.1,
                       np.arange(6) * -2.0, True, 1, 0)


def test_layout_sizes_are_fixed():
    assert STATE_SIZE == 24 + 18 * 8 + 4 + 4 == 176
    assert COMMAND_SIZE == 24 + 6 * 8 + 4 + 4 == 80
    assert len(encode_state(state(1))) == STATE_SIZE
    assert len(encode_command(CommandPacket(1, 0, np.ones(6)))) == COMMAND_SIZE


def test_state_round_trip_and_little_endian_header():
    p = state(0xFFFFFFF0)
    data = encode_state(p)
    assert data[:4] == b'IRBS'
    assert struct.unpack_from('<H', data, 4)[0] == 1            # version, little-endian
    assert struct.unpack_from('<I', data, 8)[0] == 0xFFFFFFF0   # sequence number
    back = decode_state(data)
    assert back.seq == p.seq and back.stamp_ns == p.stamp_ns
    for a in ('q', 'qd', 'tau'):
        assert_array_equal(getattr(back, a), getattr(p, a))
    assert (back.motors_on, back.mode, back.error) == (True, 1, 0)


def test_command_round_trip():
    c = CommandPacket(42, 123, np.array([1.5, -2, 3, 0, 0, 0.25]), 1, True)
    back = decode_command(encode_command(c))
    assert back.seq == 42 and back.reset and back.mode_request == 1
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
    (lambda d: recrc(d[:4] + struct.pack('<H', 2) + d[6:]), 'version'),
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
    assert decode_command(reply).seq == 10
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


def test_reset_is_repeated_until_the_axis_computer_reports_no_error():
    def latched(seq):
        s = state(seq)
        s.error = 1
        return encode_state(s)
    b = BridgeCore()
    b.on_datagram(latched(1), 0.0)
    assert not decode_command(b.on_command(np.zeros(6), 0.001)).reset   # not requested yet
    b.request_reset()
    for seq in (2, 3):                       # e.g. the first reset was lost: still latched
        b.on_datagram(latched(seq), 0.004 * seq)
        assert decode_command(b.on_command(np.zeros(6), 0.004 * seq + 0.001)).reset
    b.on_datagram(encode_state(state(4)), 0.016)                        # error cleared
    assert not decode_command(b.on_command(np.zeros(6), 0.017)).reset
