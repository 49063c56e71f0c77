"""What one MX on Protocol 1.0 answers: who answers, the status bits, the reply before the write takes effect."""

from __future__ import annotations

import pytest

from ax12emu.protocol.packets import BROADCAST_ID, Instruction, InstructionPacket, StatusError, parse_bulk_read
from ax12emu.protocol.servo_models import model
from ax12emu.servo.plant1x import build_plant1x
from ax12emu.servo.request_handler1x import handle1x
from ax12emu.servo.servo1x import Servo1X, Servo1XOptions, baud_bps_1x


def mx(key: str = "mx-28", servo_id: int = 1, **options) -> Servo1X:
    return Servo1X(model(key), lambda servo: build_plant1x(model(key), servo.table), servo_id=servo_id, index=0,
                   options=Servo1XOptions(**options))


def packet(servo_id: int, instruction: int, *params: int, checksum_ok: bool = True) -> InstructionPacket:
    return InstructionPacket(servo_id, instruction, bytes(params), checksum_ok)


def test_status_return_level_and_broadcast_decide_who_answers():
    servo = mx()
    assert handle1x(servo, packet(1, Instruction.WRITE, 16, 1)).reply is not None  # level 2: answered, now 1
    assert handle1x(servo, packet(1, Instruction.WRITE, 25, 1)).reply is None
    assert handle1x(servo, packet(1, Instruction.READ, 25, 1)).reply[5] == 1
    assert handle1x(servo, packet(1, Instruction.PING)).reply is not None
    assert handle1x(servo, packet(BROADCAST_ID, Instruction.WRITE, 25, 0)).reply is None
    assert servo.table.get("led") == 0  # executed all the same
    assert handle1x(servo, packet(BROADCAST_ID, Instruction.PING)).reply is not None
    assert handle1x(mx(reply_to_broadcast_ping=False), packet(BROADCAST_ID, Instruction.PING)).reply is None


def test_a_bad_checksum_is_answered_with_its_bit_unless_told_not_to():
    outcome = handle1x(mx(), packet(1, Instruction.READ, 36, 2, checksum_ok=False))
    assert outcome.reply[4] == StatusError.CHECKSUM and len(outcome.reply) == 8  # the two bytes asked for, zero
    assert handle1x(mx(reply_on_checksum_error=False), packet(1, Instruction.PING, checksum_ok=False)).reply is None


def test_an_id_change_is_answered_from_the_old_id_and_reset_from_the_id_reached():
    servo = mx(servo_id=4)
    outcome = handle1x(servo, packet(4, Instruction.WRITE, 3, 9))
    assert outcome.reply_id == 4 and outcome.reply[2] == 4 and servo.id == 9
    servo.table.set("p_gain", 60)
    outcome = handle1x(servo, packet(9, Instruction.RESET))
    assert outcome.reply[2] == 9 and servo.id == 1 and servo.table.get("p_gain") == 32
    assert servo.eeprom_dirty


def test_eeprom_is_writable_with_the_torque_on_and_frozen_by_lock():
    servo = mx()
    assert handle1x(servo, packet(1, Instruction.WRITE, 24, 1)).error == 0  # torque on
    assert handle1x(servo, packet(1, Instruction.WRITE, 11, 70)).error == 0  # Temperature Limit (EEPROM)
    assert handle1x(servo, packet(1, Instruction.WRITE, 47, 1)).error == 0
    assert handle1x(servo, packet(1, Instruction.WRITE, 11, 75)).error == StatusError.RANGE
    assert servo.table.get("temperature_limit") == 70
    assert handle1x(servo, packet(1, Instruction.WRITE, 25, 1)).error == 0  # the RAM area stays writable


def test_reg_write_checks_now_and_writes_at_action():
    servo = mx()
    assert handle1x(servo, packet(1, Instruction.REG_WRITE, 28, 255)).error == StatusError.RANGE
    assert handle1x(servo, packet(1, Instruction.REG_WRITE, 28, 40)).error == 0
    assert servo.table.get("registered") == 1 and servo.table.get("p_gain") == 32
    assert handle1x(servo, packet(BROADCAST_ID, Instruction.ACTION)).reply is None
    assert servo.table.get("p_gain") == 40 and servo.table.get("registered") == 0


def test_sync_write_reaches_the_listed_servo_and_malformed_parameters_are_range_errors():
    servo = mx(servo_id=2)
    handle1x(servo, packet(BROADCAST_ID, Instruction.SYNC_WRITE, 25, 1, 1, 0, 2, 1))
    assert servo.table.get("led") == 1
    assert handle1x(servo, packet(2, Instruction.READ, 36)).error == StatusError.RANGE
    assert handle1x(servo, packet(2, Instruction.WRITE, 25)).error == StatusError.RANGE


def test_bulk_read_parameters():
    assert parse_bulk_read(bytes([0, 2, 1, 36, 2, 2, 36])) == [(1, 36, 2), (2, 36, 2)]
    assert parse_bulk_read(bytes([0, 2, 1, 36, 4, 1, 30])) == [(1, 36, 2)]  # the first of a repeated ID
    assert parse_bulk_read(bytes([1, 2, 1, 36])) is None
    assert parse_bulk_read(bytes([0, 2, 1])) is None
    assert handle1x(mx(), packet(1, Instruction.BULK_READ, 0, 2, 1, 36)).error == StatusError.INSTRUCTION  # to one ID: not Bulk Read


def test_baud_rates_over_250_are_the_mx_pages():
    assert baud_bps_1x(1) == 1_000_000 and baud_bps_1x(34) == 2_000_000 / 35
    assert (baud_bps_1x(250), baud_bps_1x(251), baud_bps_1x(252)) == (2_250_000, 2_500_000, 3_000_000)


def test_a_locked_mx_refuses_factory_reset_as_the_ax12a_does():
    """It answered OK, rewrote its EEPROM and cleared Lock without a power cycle, where the AX-12A answers Range Error."""
    servo = mx()
    handle1x(servo, packet(1, Instruction.WRITE, 5, 10))  # Return Delay Time 10
    handle1x(servo, packet(1, Instruction.WRITE, 47, 1))  # Lock
    assert handle1x(servo, packet(1, Instruction.RESET)).error == StatusError.RANGE
    assert (servo.table.get("lock"), servo.table.get("return_delay_time")) == (1, 10)


def write_word(servo: Servo1X, address: int, value: int):
    return handle1x(servo, packet(1, Instruction.WRITE, address, value & 0xFF, value >> 8))


@pytest.mark.parametrize("cw, ccw", [(0, 4095), (1000, 3000)], ids=["factory", "narrowed"])
def test_a_goal_exactly_at_an_angle_limit_is_accepted(cw, ccw):
    """The range CW..CCW Angle Limit includes both ends (e-manual, MX-28: a Goal Position out of it is the Angle
    Limit Error): a goal exactly at either limit is written with no error."""
    servo = mx()
    assert write_word(servo, 6, cw).error == 0 and write_word(servo, 8, ccw).error == 0
    for goal in (ccw, cw):
        assert write_word(servo, 30, goal).error == 0, goal
        assert servo.table.get("goal_position") == goal


@pytest.mark.parametrize("cw, ccw", [(1000, 3000), (1, 4094)])
def test_a_goal_one_past_an_angle_limit_is_an_angle_limit_error(cw, ccw):
    """One unit outside CW..CCW Angle Limit: Angle Limit Error, the goal left as it was."""
    servo = mx()
    assert write_word(servo, 6, cw).error == 0 and write_word(servo, 8, ccw).error == 0
    before = servo.table.get("goal_position")
    for goal in (ccw + 1, cw - 1):
        assert write_word(servo, 30, goal).error == StatusError.ANGLE_LIMIT, goal
        assert servo.table.get("goal_position") == before


@pytest.mark.parametrize(("bit", "sent"), [
    (StatusError.RANGE, packet(1, Instruction.WRITE, 28, 255)),  # P Gain 0..254
    (StatusError.RANGE, packet(1, Instruction.READ, 70, 10)),  # past the table
    (StatusError.CHECKSUM, packet(1, Instruction.WRITE, 25, 1, checksum_ok=False)),
    (StatusError.INSTRUCTION, packet(1, 0x07)),
])
def test_range_checksum_and_instruction_errors_cut_the_output_where_shutdown_selects_them(bit, sent):
    """Alarm Shutdown(18) bits 3, 4, 6 as the e-manual lists them (control_table_alarm_shutdown.md, the MX pages'):
    Torque Limit 0 and the firmware without output; not with the factory Shutdown (36), which selects none of them."""
    servo = mx()
    handle1x(servo, packet(1, Instruction.WRITE, 24, 1))
    assert handle1x(servo, sent).error == bit and servo.table.get("torque_limit") == 1023
    handle1x(servo, packet(1, Instruction.WRITE, 18, 36 | bit))
    assert handle1x(servo, sent).error == bit
    assert servo.table.get("torque_limit") == 0
    assert servo.plant.classic.commands(servo.plant.values()).goal_pwm == 0  # the firmware was told
    handle1x(servo, packet(1, Instruction.WRITE, 34, 0xFF, 0x03))  # Torque Limit non-zero: the motor runs again
    assert servo.table.get("torque_limit") == 1023


def test_a_checksum_error_a_silent_mx_drops_leaves_its_output():
    servo = mx(reply_on_checksum_error=False)
    handle1x(servo, packet(1, Instruction.WRITE, 18, 0x7F))
    assert handle1x(servo, packet(1, Instruction.WRITE, 25, 1, checksum_ok=False)).reply is None
    assert servo.table.get("torque_limit") == 1023
