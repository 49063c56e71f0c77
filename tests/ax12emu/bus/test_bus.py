"""The bus in process: who hears a packet, duplicate IDs, baud matching, persistence, physics seam."""

from __future__ import annotations

import pytest

from ax12emu.bus import Bus
from ax12emu.bus.clock import VirtualClock
from ax12emu.bus.state_store import StateFileError, StateStore
from ax12emu.protocol.ids import parse_ids
from ax12emu.protocol.packets import BROADCAST_ID, StatusError, encode_instruction, encode_status
from ax12emu.servo.virtual_servo import ServoOptions
from firmware_model import KinematicModel

#: Long enough for a servo to write a few EEPROM bytes, during which it ignores packets.
EEPROM_WRITE_S = 0.05


def ping(servo_id):
    return encode_instruction(servo_id, 0x01)


def test_parse_ids():
    """ID lists accept commas and ranges and reject nonsense with a clear message."""
    assert parse_ids("1,2,5") == [1, 2, 5]
    assert parse_ids("1-4,9") == [1, 2, 3, 4, 9]
    for bad, message in (("1-x", "not an ID"), ("5-1", "backwards"), ("1,1", "twice"), ("254", "outside"), ("", "empty")):
        with pytest.raises(ValueError, match=message):
            parse_ids(bad)


def test_only_the_addressed_servo_answers():
    """A PING to ID 2 is answered by servo 2 alone; an absent ID gets silence."""
    bus = Bus([1, 2], clock=VirtualClock())
    replies = bus.receive(ping(2))
    assert [(r.servo_id, r.data) for r in replies] == [(2, encode_status(2, 0))]
    assert bus.receive(ping(3)) == []


def test_broadcast_ping_answered_by_all():
    """Broadcast PING: every servo answers (2006 manual), so their replies collide on the wire."""
    bus = Bus([1, 2, 3], clock=VirtualClock())
    assert sorted(r.servo_id for r in bus.receive(ping(BROADCAST_ID))) == [1, 2, 3]
    quiet = Bus([1, 2], clock=VirtualClock(), options=ServoOptions(reply_to_broadcast_ping=False))
    assert quiet.receive(ping(BROADCAST_ID)) == []


def test_duplicate_ids_both_answer_after_an_id_change():
    """Giving servo 2 the ID 1 makes both act on packets to ID 1, as two real servos would."""
    bus = Bus([1, 2], clock=VirtualClock())
    bus.receive(encode_instruction(2, 0x03, bytes([3, 1])))
    bus.clock.advance(EEPROM_WRITE_S)
    assert bus.ids == [1, 1]
    assert len(bus.receive(ping(1))) == 2
    with pytest.raises(ValueError, match="duplicate"):
        Bus([1, 1])


def test_servo_at_another_baud_is_deaf():
    """A servo at 57,142 bps ignores a host at 1 Mbps but hears 57,600 (0.8 % off)."""
    bus = Bus([1, 2], clock=VirtualClock())
    bus.servo(1).table.set("baud_rate", 34)
    assert [r.servo_id for r in bus.receive(ping(1), line_bps=1e6)] == []
    assert [r.servo_id for r in bus.receive(ping(1), line_bps=57600)] == [1]
    assert [r.servo_id for r in bus.receive(ping(2), line_bps=57600)] == []
    assert [r.servo_id for r in bus.receive(ping(2), line_bps=None)] == [2]


def test_physics_runs_in_virtual_time():
    """A commanded move progresses only as the virtual clock advances, and reaches the goal (kinematic model)."""
    clock = VirtualClock()
    bus = Bus([1], clock=clock, model=KinematicModel(1))
    bus.receive(encode_instruction(1, 0x03, bytes([24, 1])))
    bus.receive(encode_instruction(1, 0x03, bytes([30, 0x00, 0x03])))  # goal 768 from 512
    table = bus.servo(1).table
    assert table.get("present_position") == 512
    clock.advance(0.05)
    bus.advance()
    middle = table.get("present_position")
    assert 512 < middle < 768 and table.get("moving") == 1
    clock.advance(2.0)
    bus.advance()
    assert table.get("present_position") == 768 and table.get("moving") == 0


def write_word(bus, servo_id, address, value):
    """A WRITE of a 2-byte register; the status packet's error byte."""
    return bus.receive(encode_instruction(servo_id, 0x03, bytes([address, value & 0xFF, value >> 8])))[0].data[4]


def run_s(bus, seconds, every_s=0.001):
    for _ in range(int(round(seconds / every_s))):
        bus.clock.advance(every_s)
        bus.advance()


def test_alarm_shutdown_cuts_the_output_only_for_the_alarms_its_value_selects():
    """AX-12A, Alarm Shutdown(18): an alarm sets Torque Limit to 0 only if its bit is set there (the factory 36:
    Overheating and Overload).  Max Voltage Limit 9.0 V under the 9.6 V supply: Input Voltage Error in every
    status packet, the output left on and the goal reached; a blocked shaft then overloads, and that one
    Shutdown selects: Torque Limit 0."""
    bus = Bus([1], clock=VirtualClock())  # the physical model, 9.6 V
    table = bus.servo(1).table
    assert table.get("shutdown") == 36
    bus.receive(encode_instruction(1, 0x03, bytes([13, 90])))  # Max Voltage Limit 9.0 V
    bus.clock.advance(EEPROM_WRITE_S)
    run_s(bus, 0.05)
    assert bus.receive(ping(1))[0].data[4] == StatusError.INPUT_VOLTAGE
    assert bus.receive(encode_instruction(1, 0x03, bytes([24, 1])))[0].data[4] == StatusError.INPUT_VOLTAGE
    assert write_word(bus, 1, 30, 800) == StatusError.INPUT_VOLTAGE
    run_s(bus, 1.0)
    assert table.get("torque_limit") == 1023 and table.get("torque_enable") == 1
    assert abs(table.get("present_position") - 800) <= 4
    bus.model.set_blocked(True)
    assert write_word(bus, 1, 30, 300) == StatusError.INPUT_VOLTAGE
    run_s(bus, 1.5)
    assert bus.receive(ping(1))[0].data[4] == StatusError.INPUT_VOLTAGE | StatusError.OVERLOAD
    assert table.get("torque_limit") == 0


def test_state_store_survives_and_rejects_corruption(tmp_path):
    """EEPROM writes are persisted per slot; a corrupt file is a clear error naming the file."""
    store = StateStore(tmp_path)
    bus = Bus([3], clock=VirtualClock(), state_store=store)
    bus.receive(encode_instruction(3, 0x03, bytes([8, 0x20, 0x03])))
    bus.clock.advance(EEPROM_WRITE_S)
    bus.receive(encode_instruction(3, 0x03, bytes([3, 11])))
    again = Bus([3], clock=VirtualClock(), state_store=store)
    assert again.ids == [11] and again.servo(11).table.get("ccw_angle_limit") == 800
    store.path_for(3).write_text("{not json")
    with pytest.raises(StateFileError, match="servo-003.json"):
        Bus([3], state_store=store)
    store.path_for(3).write_text('{"format": "ax12emu-eeprom/1", "eeprom": {"status_return_level": 9}}')
    with pytest.raises(StateFileError, match="status_return_level"):
        Bus([3], state_store=store)
    store.path_for(3).write_text('{"eeprom": {"id": 3}}')  # another program's JSON with a key this one reads
    with pytest.raises(StateFileError, match="not an ax12emu-eeprom/1 file"):
        Bus([3], state_store=store)
    store.path_for(3).write_text('{"format": "ax12emu-eeprom/1", "model_number": "12", "eeprom": {}}')
    with pytest.raises(StateFileError, match="model_number must be an integer, got '12'"):
        Bus([3], state_store=store)
    store.path_for(3).write_text("[" * 100_000 + "]" * 100_000)  # nested too deep to parse: no traceback
    with pytest.raises(StateFileError, match="unusable state file"):
        Bus([3], state_store=store)
