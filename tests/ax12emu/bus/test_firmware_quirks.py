"""Two documented quirks of the AX-12 firmware, on by default and each with a switch (``ServoOptions``).

* a write into the EEPROM area leaves the servo deaf for about 6 ms per byte
  written (xevelabs' USB2AX protocol notes), timed by the bus clock;
* writing Goal Position turns the torque on (pypot's and Luos' maintainers, poppy users).
"""

from __future__ import annotations

import pytest

from ax12emu.bus import Bus
from ax12emu.bus.clock import VirtualClock
from ax12emu.protocol.control_table import layout
from ax12emu.protocol.packets import BROADCAST_ID, Instruction, StatusError, encode_instruction
from ax12emu.servo.virtual_servo import ServoOptions

LAY = layout("ax12a")
PER_BYTE_S = ServoOptions().eeprom_busy_s_per_byte


def _packet(name: str, value: int, *, instruction: Instruction = Instruction.WRITE, servo_id: int = 1) -> bytes:
    entry = LAY.by_name[name]
    return encode_instruction(servo_id, instruction, bytes([entry.address]) + value.to_bytes(entry.size, "little"))


def _ping(bus: Bus, servo_id: int = 1) -> bool:
    return bool(bus.receive(encode_instruction(servo_id, Instruction.PING)))


def _read(bus: Bus, name: str, servo_id: int = 1) -> int | None:
    entry = LAY.by_name[name]
    replies = bus.receive(encode_instruction(servo_id, Instruction.READ, bytes([entry.address, entry.size])))
    return int.from_bytes(replies[0].data[5:-1], "little") if replies else None


# -- EEPROM busy time ---------------------------------------------------------------------
def test_default_is_six_ms_per_byte():
    assert PER_BYTE_S == pytest.approx(0.006)


@pytest.mark.parametrize(("name", "value", "size"), [("return_delay_time", 10, 1), ("ccw_angle_limit", 1000, 2)])
def test_eeprom_write_is_answered_then_the_servo_ignores_packets_per_byte(name, value, size):
    bus = Bus([1, 2], clock=VirtualClock())
    (reply,) = bus.receive(_packet(name, value))
    assert reply.data[4] == 0  # answered as usual
    busy_s = size * PER_BYTE_S
    assert not _ping(bus)
    assert _ping(bus, 2)  # the other servo did not write anything
    bus.clock.advance(busy_s - 1e-4)
    assert not _ping(bus)
    # A packet meanwhile is not acted on either (not only unanswered).
    assert bus.receive(_packet("led", 1)) == []
    bus.clock.advance(2e-4)
    assert _ping(bus)
    assert _read(bus, name) == value and _read(bus, "led") == 0


def test_ram_writes_leave_the_servo_listening():
    bus = Bus([1], clock=VirtualClock())
    bus.receive(_packet("led", 1))
    bus.receive(_packet("goal_position", 600))
    assert _ping(bus) and _read(bus, "led") == 1


def test_a_refused_eeprom_write_writes_nothing_and_costs_nothing():
    bus = Bus([1], clock=VirtualClock())
    bad_checksum = bytearray(_packet("return_delay_time", 10))
    bad_checksum[-1] ^= 0xFF
    (reply,) = bus.receive(bytes(bad_checksum))
    assert reply.data[4] & StatusError.CHECKSUM
    model_number = LAY.by_name["model_number"]
    (reply,) = bus.receive(encode_instruction(1, Instruction.WRITE, bytes([model_number.address, 1, 2])))
    assert reply.data[4] & StatusError.RANGE  # read-only: refused
    assert _ping(bus)


def test_broadcast_eeprom_write_makes_every_servo_busy_and_sync_write_only_those_written():
    bus = Bus([1, 2, 3], clock=VirtualClock())
    assert bus.receive(_packet("return_delay_time", 0, servo_id=BROADCAST_ID)) == []
    assert not any(_ping(bus, i) for i in (1, 2, 3))
    bus.clock.advance(PER_BYTE_S)
    assert all(_ping(bus, i) for i in (1, 2, 3))
    address = LAY.by_name["return_delay_time"].address
    bus.receive(encode_instruction(BROADCAST_ID, Instruction.SYNC_WRITE, bytes([address, 1, 2, 7])))
    assert [_ping(bus, i) for i in (1, 2, 3)] == [True, False, True]


def test_the_reply_cache_never_answers_for_a_busy_servo():
    """A READ answered (and cached) before an EEPROM write gets silence while the servo is busy,
    even when the write left every byte as it was, then its answer again."""
    bus = Bus([1], clock=VirtualClock())
    assert _read(bus, "id") == 1 and _read(bus, "id") == 1
    assert bus.reply_cache.hits == 1
    bus.receive(_packet("id", 1))  # same value: the table is unchanged
    assert _read(bus, "id") is None
    bus.clock.advance(PER_BYTE_S)
    assert _read(bus, "id") == 1
    assert _read(bus, "id") == 1


def test_busy_time_off_answers_at_once():
    bus = Bus([1], clock=VirtualClock(), options=ServoOptions(eeprom_busy_s_per_byte=0.0))
    bus.receive(_packet("ccw_angle_limit", 1000))
    assert _ping(bus) and _read(bus, "ccw_angle_limit") == 1000


def test_busy_time_option_is_checked():
    for bad in (-0.001, float("nan"), 2.0):
        with pytest.raises(ValueError, match="eeprom_busy_s_per_byte"):
            ServoOptions(eeprom_busy_s_per_byte=bad)


# -- Goal Position turns torque on --------------------------------------------------------
def test_goal_position_write_turns_torque_on_by_default():
    bus = Bus([1], clock=VirtualClock())
    assert _read(bus, "torque_enable") == 0
    bus.receive(_packet("goal_position", 700))
    assert _read(bus, "torque_enable") == 1
    assert _read(bus, "moving") == 1  # and the servo moves


def test_every_way_of_writing_goal_position_turns_torque_on():
    bus = Bus([1, 2], clock=VirtualClock())
    goal = LAY.by_name["goal_position"]
    bus.receive(encode_instruction(1, Instruction.WRITE, bytes([goal.address + 1, 2])))  # high byte alone
    assert _read(bus, "torque_enable") == 1
    bus.receive(encode_instruction(BROADCAST_ID, Instruction.SYNC_WRITE, bytes([goal.address, 2, 2, 0x00, 0x02])))
    assert _read(bus, "torque_enable", 2) == 1
    bus.receive(_packet("torque_enable", 0))
    bus.receive(_packet("goal_position", 300, instruction=Instruction.REG_WRITE))
    assert _read(bus, "torque_enable") == 0  # registered, not yet written
    bus.receive(encode_instruction(1, Instruction.ACTION))
    assert _read(bus, "torque_enable") == 1


def test_other_writes_and_refused_goals_leave_torque_off():
    bus = Bus([1], clock=VirtualClock())
    bus.receive(_packet("punch", 100))  # (Moving Speed does turn an AX's torque on: test_request_handler)
    bus.receive(_packet("led", 1))
    assert _read(bus, "torque_enable") == 0
    bus.receive(_packet("cw_angle_limit", 400))
    bus.clock.advance(2 * PER_BYTE_S)
    (reply,) = bus.receive(_packet("goal_position", 100))  # below CW Angle Limit: refused, nothing written
    assert reply.data[4] & StatusError.ANGLE_LIMIT
    assert _read(bus, "torque_enable") == 0


def test_goal_position_leaves_torque_off_when_switched_off():
    bus = Bus([1], clock=VirtualClock(), options=ServoOptions(goal_position_enables_torque=False))
    bus.receive(_packet("goal_position", 700))
    bus.clock.advance(0.05)
    assert _read(bus, "torque_enable") == 0 and _read(bus, "moving") == 0
