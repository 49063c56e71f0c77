"""The reply cache: a repeated READ / PING is replayed, and never once anything it depends on changed."""

from __future__ import annotations

import logging

import pytest

from ax12emu.bus.bus import Bus
from ax12emu.bus.clock import VirtualClock
from ax12emu.bus.reply_cache import MAX_ENTRIES
from ax12emu.faults.injection import Faults
from ax12emu.protocol.packets import encode_instruction, encode_status
from firmware_model import KinematicModel

READ_POSITION = encode_instruction(1, 0x02, bytes([36, 2]))
READ_ID_1 = encode_instruction(1, 0x02, bytes([3, 1]))
#: Long enough for a servo to write an EEPROM byte, during which it ignores packets.
EEPROM_WRITE_S = 0.05


def _bus(ids=(1,)) -> Bus:
    return Bus(list(ids), clock=VirtualClock(), model=KinematicModel(len(ids)))


def _data(replies) -> list[bytes]:
    return [r.data for r in replies]


def test_repeated_read_is_replayed_with_the_same_bytes():
    bus = _bus()
    first = bus.receive(READ_POSITION)
    assert bus.reply_cache.hits == 0
    for _ in range(5):
        assert _data(bus.receive(READ_POSITION)) == _data(first)
    assert bus.reply_cache.hits == 5
    assert _data(first) == [encode_status(1, 0, bytes([0x00, 0x02]))]  # 512, little-endian


def test_a_write_by_packet_is_seen_by_the_next_read():
    bus = _bus()
    bus.receive(encode_instruction(1, 0x02, bytes([25, 1])))  # LED
    bus.receive(encode_instruction(1, 0x03, bytes([25, 1])))
    assert _data(bus.receive(encode_instruction(1, 0x02, bytes([25, 1])))) == [encode_status(1, 0, b"\x01")]


def test_a_change_made_in_process_is_seen_by_the_next_read():
    """No writer has to announce itself: the cache compares the table's bytes."""
    bus = _bus()
    bus.receive(READ_POSITION)
    bus.servos[0].table.set("present_position", 700)
    assert _data(bus.receive(READ_POSITION)) == [encode_status(1, 0, (700).to_bytes(2, "little"))]


def test_physics_moving_the_servo_is_seen_by_the_next_read():
    bus = _bus()
    bus.receive(encode_instruction(1, 0x03, bytes([24, 1])))  # Torque Enable
    bus.receive(encode_instruction(1, 0x03, bytes([30]) + (800).to_bytes(2, "little")))  # Goal Position
    before = bus.receive(READ_POSITION)
    bus.clock.advance(0.05)
    after = bus.receive(READ_POSITION)
    assert _data(after) != _data(before) and bus.reply_cache.hits == 0


def test_status_return_level_and_alarms_change_the_replayed_reply():
    bus = _bus()
    bus.receive(READ_POSITION)
    bus.servos[0].alarms = 0x04  # overheating
    (reply,) = bus.receive(READ_POSITION)
    assert reply.data[4] == 0x04
    bus.receive(encode_instruction(1, 0x03, bytes([16, 0])))  # Status Return Level 0: only PING answered
    assert bus.receive(READ_POSITION) == []


def test_an_id_change_moves_the_answers():
    bus = _bus((1, 2))
    assert bus.receive(READ_ID_1)
    bus.receive(encode_instruction(1, 0x03, bytes([3, 7])))  # ID 1 -> 7
    bus.clock.advance(EEPROM_WRITE_S)
    assert bus.receive(READ_ID_1) == []
    bus.receive(encode_instruction(2, 0x03, bytes([3, 1])))  # ID 2 -> 1: another servo answers as 1
    bus.clock.advance(EEPROM_WRITE_S)
    assert _data(bus.receive(READ_ID_1)) == [encode_status(1, 0, b"\x01")]


def test_line_speed_is_part_of_the_key():
    bus = _bus()
    assert bus.receive(READ_POSITION, line_bps=1_000_000)
    assert bus.receive(READ_POSITION, line_bps=57_600) == []  # the servo listens at 1 Mbps: garbage to it


def test_faults_and_debug_logging_bypass_the_cache(caplog):
    bus = _bus()
    bus.receive(READ_POSITION)
    bus.faults = Faults(bus)
    bus.faults.set_reply_faults(drop=1.0)
    assert bus.receive(READ_POSITION) == []
    bus.faults = None
    with caplog.at_level(logging.DEBUG, logger="ax12emu.bus.bus"):
        bus.receive(READ_POSITION)
    assert bus.reply_cache.hits == 0
    assert any("rx" in record.getMessage() for record in caplog.records)


@pytest.mark.parametrize("chunks", [
    [READ_POSITION[:3], READ_POSITION[3:]],  # the second chunk finishes a packet: too short to be one
    [b"\x00" + READ_POSITION],  # garbage first
    [READ_POSITION + READ_POSITION],  # two packets in one read
])
def test_chunks_that_are_not_exactly_one_packet_are_served_and_not_stored(chunks):
    bus = _bus()
    for _ in range(3):
        replies = [r for chunk in chunks for r in bus.receive(chunk)]
        assert replies and all(r.data == encode_status(1, 0, bytes([0x00, 0x02])) for r in replies)
    assert bus.reply_cache.hits == 0


def test_a_packet_shaped_chunk_that_finished_a_held_partial_is_not_stored():
    """The chunk completes a stray partial (whose checksum happens to fit) instead of being the READ it looks like.

    The servo answers that combined packet (a READ with 6 parameters: Range error); the same bytes
    sent again cleanly are a plain READ and must get its own reply, not the one stored for the mix-up.
    """
    params = next(bytes([p]) + READ_POSITION[:5] for p in range(256)
                  if ~(1 + 8 + 2 + p + sum(READ_POSITION[:5])) & 0xFF == READ_POSITION[5])
    stray = bytes([0xFF, 0xFF, 1, len(params) + 2, 0x02, params[0]])
    bus = _bus()
    assert bus.receive(stray, now_s=0.0) == [] and bus.framer.buffered
    (mixed,) = bus.receive(READ_POSITION, now_s=0.001)
    assert mixed.data[4] & 0x08 and not bus.framer.buffered  # Range error: the combined packet was answered
    for later_s in (1.0, 2.0):
        assert _data(bus.receive(READ_POSITION, now_s=later_s)) == [encode_status(1, 0, bytes([0x00, 0x02]))]


def test_the_cache_stays_bounded():
    bus = _bus()
    for address in range(50):
        for length in range(1, 7):
            bus.receive(encode_instruction(1, 0x02, bytes([address, length])))
    assert len(bus.reply_cache._entries) <= MAX_ENTRIES


def test_a_second_servo_taking_the_id_answers_too():
    """Servo 1's table is unchanged, but servo 2 now also answers to ID 1 (duplicate IDs, both reply)."""
    bus = _bus((1, 2))
    assert len(bus.receive(READ_ID_1)) == 1
    bus.receive(encode_instruction(2, 0x03, bytes([3, 1])))
    bus.clock.advance(EEPROM_WRITE_S)
    assert len(bus.receive(READ_ID_1)) == 2
