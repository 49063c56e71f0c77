"""One servo's answers to instructions, in process: reply policy, errors as values, options."""

from __future__ import annotations

import pytest

from ax12emu.protocol.packets import BROADCAST_ID, InstructionPacket, StatusError, encode_status
from ax12emu.servo.request_handler import handle
from ax12emu.servo.virtual_servo import ServoOptions, VirtualServo


def servo(**options) -> VirtualServo:
    s = VirtualServo.fresh(1, ServoOptions(**options), index=0)
    s.power_on()
    return s


def send(s, instruction, params=b"", packet_id=1, checksum_ok=True):
    return handle(s, InstructionPacket(packet_id, instruction, bytes(params), checksum_ok))


def test_emanual_examples():
    """PING and READ temperature answer as the e-manual's examples (temperature 32 C there)."""
    s = servo()
    assert send(s, 0x01).reply == bytes.fromhex("ffff010200fc")
    s.table.set("present_temperature", 32)
    assert send(s, 0x02, [0x2B, 1]).reply == bytes.fromhex("ffff01030020db")


def test_alarms_appear_in_every_status_byte():
    """The present alarm bits are OR'd into the error byte; bit 7 never appears."""
    s = servo()
    s.alarms = 0x24 | 0x80
    assert send(s, 0x01).reply == encode_status(1, 0x24)
    assert send(s, 0x03, [24, 5]).reply == encode_status(1, 0x24 | StatusError.RANGE)


def test_checksum_error_reply_or_silence():
    """A bad checksum is answered with bit 0x10 by default and ignored when configured silent."""
    bad_read = dict(instruction=0x02, params=[36, 2], checksum_ok=False)
    outcome = send(servo(), **bad_read)
    assert outcome.reply == encode_status(1, StatusError.CHECKSUM, b"\x00\x00")
    assert send(servo(reply_on_checksum_error=False), **bad_read).reply is None


def test_broadcast_is_silent_except_ping_by_option():
    """Broadcast WRITE is executed silently; broadcast PING answers unless configured silent."""
    s = servo()
    assert send(s, 0x03, [25, 1], packet_id=BROADCAST_ID).reply is None
    assert s.table.get("led") == 1
    assert send(s, 0x01, packet_id=BROADCAST_ID).reply == encode_status(1, 0)
    assert send(servo(reply_to_broadcast_ping=False), 0x01, packet_id=BROADCAST_ID).reply is None


def test_reset_reply_id_option():
    """RESET answers from the old ID by default, from the new ID 1 when configured."""
    for new_id, expected in ((False, 7), (True, 1)):
        s = servo(reset_reply_from_new_id=new_id)
        s.table.set("id", 7)
        outcome = send(s, 0x06, packet_id=7)
        assert outcome.reply == encode_status(expected, 0)
        assert s.id == 1 and s.table.get("baud_rate") == 1


def test_lock_cannot_be_released_by_a_write():
    """Once Lock is 1 only a power cycle releases it (e-manual): writing 0 is a Range Error."""
    s = servo()
    assert send(s, 0x03, [47, 1]).error == StatusError.NONE
    assert send(s, 0x03, [47, 0]).error == StatusError.RANGE
    assert s.table.get("lock") == 1
    assert send(s, 0x03, [3, 5]).error == StatusError.RANGE


def test_malformed_parameters_are_range_errors():
    """READ without its two parameters, WRITE without data: Range Error, nothing changes."""
    s = servo()
    assert send(s, 0x02, [36]).error == StatusError.RANGE
    assert send(s, 0x03, [25]).error == StatusError.RANGE
    assert send(s, 0x83, [30, 2, 1, 0]).error == StatusError.RANGE  # block of the wrong size


def test_wheel_mode_skips_angle_check():
    """With both angle limits 0 (wheel mode) any Goal Position is accepted."""
    s = servo()
    assert send(s, 0x03, [8, 0, 0]).error == StatusError.NONE
    assert send(s, 0x03, [30, 0xFF, 3]).error == StatusError.NONE


def test_reg_write_validated_at_registration():
    """An invalid REG_WRITE is refused at once and nothing is registered."""
    s = servo()
    assert send(s, 0x04, [24, 9]).error == StatusError.RANGE
    assert s.table.get("registered") == 0 and s.registered_write is None


def test_a_registered_goal_past_the_angle_limits_is_refused_when_registered():
    """A Reg Write is "similar to Write Instruction": a goal past CW/CCW Angle Limit gets Angle Limit Error at
    once (as on the MX), not Instruction-free acceptance and a silent failure at a broadcast Action."""
    s = servo()
    assert send(s, 0x03, [6, 100, 0, 200, 0]).error == StatusError.NONE  # limits 100..200
    assert send(s, 0x04, [30, 0xF4, 1]).error == StatusError.ANGLE_LIMIT  # goal 500
    assert s.table.get("registered") == 0 and s.registered_write is None
    assert send(s, 0x04, [30, 150, 0]).error == StatusError.NONE and s.table.get("registered") == 1


def test_a_goal_past_the_angle_limits_takes_the_output_to_zero_where_shutdown_selects_it():
    """"providing that Angle Limit Error Bit in the Alarm LED/Shutdown is set, ... the motor's output will be 0
    [%]" (e-manual, AX-12A, Goal Position): Torque Limit 0, as every Alarm Shutdown; not without the bit."""
    s = servo()
    send(s, 0x03, [6, 100, 0, 200, 0])
    assert send(s, 0x03, [30, 0xF4, 1]).error == StatusError.ANGLE_LIMIT
    assert s.table.get("torque_limit") == 1023  # the factory Shutdown (36) does not select Angle Limit
    assert send(s, 0x03, [18, 36 | StatusError.ANGLE_LIMIT]).error == StatusError.NONE
    assert send(s, 0x03, [30, 0xF4, 1]).error == StatusError.ANGLE_LIMIT
    assert s.table.get("torque_limit") == 0 and s.table.get("goal_position") != 500


def test_under_the_2006_profile_the_angle_limit_shutdown_turns_the_torque_off():
    """The 2006 manual's Alarm Shutdown turns the torque off (its recovery: Torque Enable 1); the Angle Limit
    Error zeroed Torque Limit there as under the e-manual, so that recovery left the servo limp."""
    s = servo(profile="ax12-2006")
    send(s, 0x03, [6, 100, 0, 200, 0])
    send(s, 0x03, [18, 36 | StatusError.ANGLE_LIMIT])
    send(s, 0x03, [24, 1])
    assert send(s, 0x03, [30, 0xF4, 1]).error == StatusError.ANGLE_LIMIT
    assert (s.table.get("torque_enable"), s.table.get("torque_limit")) == (0, 1023)


def test_a_reset_cannot_go_around_lock():
    """Lock: "EEPROM area cannot be modified", released only by a power cycle; RESET rewrote the EEPROM and Lock."""
    s = servo()
    send(s, 0x03, [5, 10])
    send(s, 0x03, [47, 1])
    assert send(s, 0x06).error == StatusError.RANGE
    assert (s.table.get("lock"), s.table.get("return_delay_time")) == (1, 10)


def test_on_the_ax_series_a_moving_speed_write_turns_the_torque_on():
    """Luos-io/Pyluos #59: setting the speed on AX motors "turn[s] the motor stiff"; a wheel set up with both
    angle limits 0 and Moving Speed alone (pyax12's example) stayed limp.  Not with --goal-torque unchanged."""
    s = servo()
    send(s, 0x03, [6, 0, 0, 0, 0])
    assert send(s, 0x03, [32, 0, 2]).error == StatusError.NONE
    assert s.table.get("torque_enable") == 1
    s = servo(goal_position_enables_torque=False)
    send(s, 0x03, [32, 0, 2])
    assert s.table.get("torque_enable") == 0


def write_word(s, address, value):
    return send(s, 0x03, [address, value & 0xFF, value >> 8])


@pytest.mark.parametrize("cw, ccw", [(0, 1023), (100, 900)], ids=["factory", "narrowed"])
def test_a_goal_exactly_at_an_angle_limit_is_accepted(cw, ccw):
    """The range CW..CCW Angle Limit includes both ends (e-manual, AX-12A: a Goal Position "out of the range"
    is the Angle Limit Error): a goal exactly at either limit is written with no error."""
    s = servo()
    assert send(s, 0x03, [6, cw & 0xFF, cw >> 8, ccw & 0xFF, ccw >> 8]).error == StatusError.NONE
    for goal in (ccw, cw):
        assert write_word(s, 30, goal).error == StatusError.NONE, goal
        assert s.table.get("goal_position") == goal


@pytest.mark.parametrize("cw, ccw", [(100, 900), (1, 1022)])
def test_a_goal_one_past_an_angle_limit_is_an_angle_limit_error(cw, ccw):
    """One unit outside CW..CCW Angle Limit: Angle Limit Error, the goal left as it was."""
    s = servo()
    assert send(s, 0x03, [6, cw & 0xFF, cw >> 8, ccw & 0xFF, ccw >> 8]).error == StatusError.NONE
    for goal in (ccw + 1, cw - 1):
        assert write_word(s, 30, goal).error == StatusError.ANGLE_LIMIT, goal
        assert s.table.get("goal_position") == 512


def test_a_goal_past_the_factory_ccw_limit_is_out_of_goal_positions_range():
    """At the factory limits 0..1023 no goal lies one past a limit within Goal Position's own range: 1024 is a
    Range Error, the goal left as it was."""
    s = servo()
    assert write_word(s, 30, 1024).error == StatusError.RANGE
    assert s.table.get("goal_position") == 512


@pytest.mark.parametrize(("bit", "instruction", "params", "checksum_ok"), [
    (StatusError.RANGE, 0x03, [36, 1], True),  # Present Position is read-only
    (StatusError.CHECKSUM, 0x03, [25, 1], False),
    (StatusError.INSTRUCTION, 0x07, [], True),
])
def test_range_checksum_and_instruction_errors_take_the_output_to_zero_where_shutdown_selects_them(
        bit, instruction, params, checksum_ok):
    """Alarm Shutdown(18) bits 3 (Range), 4 (CheckSum), 6 (Instruction): "in case of Alarm Shutdown, the motor output
    becomes 0 % by resetting the value of Torque Limit(34) to 0" (e-manual, control_table_alarm_shutdown.md)."""
    s = servo()
    outcome = send(s, instruction, params, checksum_ok=checksum_ok)
    assert outcome.error == bit and s.table.get("torque_limit") == 1023  # the factory Shutdown (36) selects neither
    assert send(s, 0x03, [18, 36 | bit]).error == StatusError.NONE
    assert send(s, instruction, params, checksum_ok=checksum_ok).error == bit
    assert s.table.get("torque_limit") == 0


def test_a_checksum_error_a_silent_servo_drops_does_not_shut_it_down_and_the_2006_profile_turns_the_torque_off():
    s = servo(reply_on_checksum_error=False)
    send(s, 0x03, [18, 0x7F])
    assert send(s, 0x03, [25, 1], checksum_ok=False).reply is None and s.table.get("torque_limit") == 1023
    old = servo(profile="ax12-2006")
    send(old, 0x03, [18, 36 | StatusError.INSTRUCTION])
    send(old, 0x03, [24, 1])
    assert send(old, 0x07).error == StatusError.INSTRUCTION
    assert (old.table.get("torque_enable"), old.table.get("torque_limit")) == (0, 1023)
