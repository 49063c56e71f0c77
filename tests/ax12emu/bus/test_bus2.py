"""The Protocol 2.0 bus, byte for byte: the e-manual's example packets and answers, every error, who answers when.

Servos here stand on a recording firmware model (``x2_testkit``): what is checked is what the
protocol side answers and what it hands the model, not motion.
"""

from __future__ import annotations

import dataclasses
import random

import pytest
from protocol2_vectors import EMANUAL_PACKETS
from x2_testkit import RecordingFirmware, recording_bus

from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock
from ax12emu.bus.reply import BITS_PER_BYTE, merge_replies
from ax12emu.bus.state_store import StateFileError, StateStore
from ax12emu.protocol.packets2 import (
    ErrorNumber,
    Instruction2,
    decode_packet2,
    encode_instruction2,
    encode_status2,
)
from ax12emu.protocol.servo_models import model

EMPTY_OK = bytes.fromhex(EMANUAL_PACKETS["empty status"])


def h(name: str) -> bytes:
    return bytes.fromhex(EMANUAL_PACKETS[name])


def u32(value: int) -> bytes:
    return (value & 0xFFFFFFFF).to_bytes(4, "little")


def send(bus, packet_id, instruction, params=b""):
    return bus.receive(encode_instruction2(packet_id, instruction, params))


def status(bus, packet_id, instruction, params=b""):
    """The one status packet a request gets, decoded."""
    replies = send(bus, packet_id, instruction, params)
    assert len(replies) == 1, replies
    return decode_packet2(replies[0].data)


@pytest.fixture
def xm():
    """IDs 1..7 of XM430-W350s (the e-manual's examples use an XM430) and their recording models."""
    return recording_bus(ids=range(1, 8), key="xm430-w350")


def set_sensed(firmware, **values):
    firmware.sensed = dataclasses.replace(firmware.sensed, **values)


def refresh(bus):
    """Sensed values changed on the stand-in: the tables show them after the next step."""
    bus.clock.advance(0.002)
    bus.advance()


# -- the e-manual's examples ---------------------------------------------------------------
def test_read_example_byte_for_byte(xm):
    bus, firmware = xm
    set_sensed(firmware[0], present_position=166)
    refresh(bus)
    replies = bus.receive(h("Read (0x02)"))
    assert [r.data for r in replies] == [h("Read status")]
    assert replies[0].delay_s == pytest.approx(250 * 2e-6)  # Return Delay Time 250 (default) x 2 us


def test_write_reg_write_action_factory_reset_reboot_clear_examples(xm):
    bus, firmware = xm
    for name in ("Write (0x03)", "Reg Write (0x04)", "Action (0x05)", "Clear (0x10)", "Factory Reset (0x06)", "Reboot (0x08)"):
        assert [r.data for r in bus.receive(h(name))] == [EMPTY_OK], name
    assert firmware[0].reboots == 1 and firmware[0].clears == 1


def test_write_example_sets_goal_position_and_starts_a_profile(xm):
    bus, firmware = xm
    bus.receive(h("Write (0x03)"))
    assert bus.servo(1).table.get("goal_position") == 512
    commands, goal_written = firmware[0].commands[-1]
    assert commands.goal_position == 512 and goal_written


def test_reg_write_waits_for_action(xm):
    bus, firmware = xm
    table = bus.servo(1).table
    bus.receive(h("Reg Write (0x04)"))
    assert table.get("goal_velocity") == 0 and table.get("registered_instruction") == 1
    bus.receive(h("Action (0x05)"))
    assert table.get("goal_velocity") == 200 and table.get("registered_instruction") == 0
    assert firmware[0].last.goal_velocity == 200


def test_action_without_reg_write_is_instruction_error(xm):
    bus, _ = xm
    assert status(bus, 1, Instruction2.ACTION).error == ErrorNumber.INSTRUCTION


def test_ping_answers_model_number_and_firmware_version(xm):
    bus, _ = xm
    reply = status(bus, 1, Instruction2.PING)
    assert reply.params == (1020).to_bytes(2, "little") + bytes((45,))  # the model file's firmware_version
    assert bus.servo(1).table.get("firmware_version") == 45


def test_sync_read_example_and_the_order_of_answers(xm):
    bus, firmware = xm
    set_sensed(firmware[0], present_position=166)
    set_sensed(firmware[1], present_position=2079)
    refresh(bus)
    replies = bus.receive(h("Sync Read (0x82)"))
    assert [r.data for r in replies] == [h("Read status"), h("Sync Read status ID 2")]
    byte_s = BITS_PER_BYTE / 57600
    rdt_s = 500e-6
    assert replies[0].delay_s == pytest.approx(rdt_s)
    assert replies[1].delay_s == pytest.approx(rdt_s + len(replies[0].data) * byte_s + rdt_s)


def test_sync_write_example(xm):
    bus, _ = xm
    assert bus.receive(h("Sync Write (0x83)")) == []
    assert bus.servo(1).table.get("goal_position") == 150
    assert bus.servo(2).table.get("goal_position") == 170


def test_bulk_read_example(xm):
    bus, firmware = xm
    set_sensed(firmware[0], present_input_voltage=119)
    set_sensed(firmware[1], present_temperature=36)
    refresh(bus)
    assert [r.data for r in bus.receive(h("Bulk Read (0x92)"))] == [h("Bulk Read status ID 1"), h("Bulk Read status ID 2")]


def test_bulk_write_example(xm):
    bus, _ = xm
    assert bus.receive(h("Bulk Write (0x93)")) == []
    assert bus.servo(1).table.get("max_voltage_limit") == 160
    assert bus.servo(2).table.get("temperature_limit") == 80


def test_fast_sync_read_example_is_one_combined_status(xm):
    bus, firmware = xm
    for index, position in ((2, 166), (6, 2079), (3, 1023)):
        set_sensed(firmware[index], present_position=position)
    refresh(bus)
    replies = bus.receive(h("Fast Sync Read (0x8A)"))
    assert b"".join(r.data for r in replies) == h("Fast Sync Read status")
    # The first servo waits its Return Delay Time, the others follow back to back.
    byte_s = BITS_PER_BYTE / 57600
    assert replies[0].delay_s == pytest.approx(500e-6)
    for before, after in zip(replies, replies[1:]):
        assert after.delay_s == pytest.approx(before.delay_s + len(before.data) * byte_s)


def test_fast_bulk_read_example(xm):
    bus, firmware = xm
    set_sensed(firmware[2], present_position=166)
    set_sensed(firmware[6], present_pwm=421)
    set_sensed(firmware[3], present_temperature=31)
    refresh(bus)
    params = bytes.fromhex("03 84 00 04 00 07 7C 00 02 00 04 92 00 01 00")
    replies = send(bus, 0xFE, Instruction2.FAST_BULK_READ, params)
    assert b"".join(r.data for r in replies) == h("Fast Bulk Read status")


# -- broadcast ----------------------------------------------------------------------------
def test_broadcast_ping_every_servo_in_the_slot_of_its_id():
    bus, _ = recording_bus(ids=(5, 1, 3), key="xl430-w250")
    replies = bus.receive(h("Ping broadcast"))
    assert [r.servo_id for r in replies] == [1, 3, 5]
    slot_s = 14 * BITS_PER_BYTE / 57600 + 508e-6  # the answer and the longest Return Delay Time
    for reply in replies:
        assert reply.delay_s == pytest.approx(500e-6 + reply.servo_id * slot_s)
        assert decode_packet2(reply.data).params == (1060).to_bytes(2, "little") + bytes((45,))


def test_broadcast_ping_answers_never_overlap_whatever_each_servos_return_delay():
    """One servo left at the factory 500 us among servos set to 0 (as lerobot configures them): the slots of each
    servo's own delay overlapped, ID 2's answer started before ID 1's ended and the host decoded neither."""
    bus, _ = recording_bus(ids=(1, 2, 3), key="xl430-w250")
    for servo_id in (2, 3):
        send(bus, servo_id, Instruction2.WRITE, bytes((9, 0, 0)))  # Return Delay Time 0
    replies = bus.receive(h("Ping broadcast"))
    spans = [(r.delay_s, r.delay_s + len(r.data) * BITS_PER_BYTE / r.baud_bps) for r in replies]
    assert [r.servo_id for r in replies] == [1, 2, 3]
    assert all(end <= next_start for (_, end), (next_start, _) in zip(spans, spans[1:])), spans


def test_broadcast_write_is_executed_silently_and_broadcast_read_not_at_all(xm):
    bus, _ = xm
    assert send(bus, 0xFE, Instruction2.WRITE, bytes((65, 0, 1))) == []
    assert all(servo.table.get("led") == 1 for servo in bus.servos)
    assert send(bus, 0xFE, Instruction2.READ, bytes((65, 0, 1, 0))) == []


def test_factory_reset_all_is_not_executed_by_broadcast(xm):
    bus, _ = xm
    send(bus, 0xFE, Instruction2.WRITE, bytes((31, 0, 70)))
    send(bus, 0xFE, Instruction2.FACTORY_RESET, b"\xff")
    assert bus.servo(3).table.get("temperature_limit") == 70
    send(bus, 0xFE, Instruction2.FACTORY_RESET, b"\x02")
    assert bus.servo(3).table.get("temperature_limit") == 80 and bus.ids == list(range(1, 8))


def test_an_xl320_carries_a_broadcast_factory_reset_all_out():
    """The refusal is "MX(2.0) FW42, X-series FW42 or above"'s (e-manual, Factory Reset): the XL-320, outside those,
    resets (to ID 1) where it kept its ID and EEPROM."""
    bus, _ = recording_bus(ids=(7,), key="xl-320")
    send(bus, 7, Instruction2.WRITE, bytes((5, 0, 10)))  # Return Delay Time 10
    send(bus, 0xFE, Instruction2.FACTORY_RESET, b"\xff")
    assert bus.ids == [1] and bus.servo(1).table.get("return_delay_time") == 250


def test_factory_reset_options(xm):
    bus, _ = xm
    send(bus, 4, Instruction2.WRITE, bytes((8, 0, 3)))
    assert status(bus, 4, Instruction2.FACTORY_RESET, b"\x01").id == 4  # answered from the old ID, before the reset
    servo = bus.servos[3]
    assert (servo.id, servo.table.get("baud_rate")) == (4, 1)
    assert status(bus, 4, Instruction2.FACTORY_RESET, b"\xff").id == 4
    assert servo.id == 1 and bus.servo(1) is bus.servos[0]
    assert servo.table.get("firmware_version") == 45  # the firmware's own: no reset changes it


def test_a_sync_instruction_to_one_id_is_ignored(xm):
    bus, _ = xm
    assert send(bus, 1, Instruction2.SYNC_READ, bytes((132, 0, 4, 0, 1))) == []


def test_a_listed_servo_missing_breaks_the_chain(xm):
    bus, _ = xm
    replies = send(bus, 0xFE, Instruction2.SYNC_READ, bytes((132, 0, 4, 0, 1, 9, 2)))
    assert [r.servo_id for r in replies] == [1]
    fast = send(bus, 0xFE, Instruction2.FAST_SYNC_READ, bytes((132, 0, 4, 0, 1, 9, 2)))
    assert len(fast) == 1  # the header and ID 1's share; the packet's LENGTH announces three


# -- errors -------------------------------------------------------------------------------
def test_crc_error_is_answered_with_error_3(xm):
    bus, _ = xm
    packet = bytearray(encode_instruction2(1, Instruction2.READ, bytes((132, 0, 4, 0))))
    packet[-1] ^= 0xFF
    reply = decode_packet2(bus.receive(bytes(packet))[0].data)
    assert (reply.error, reply.params) == (ErrorNumber.CRC, bytes(4))
    packet = bytearray(encode_instruction2(0xFE, Instruction2.PING))
    packet[-1] ^= 0xFF
    assert bus.receive(bytes(packet)) == []


@pytest.mark.parametrize(
    ("instruction", "params", "error"),
    [
        (0x07, b"", ErrorNumber.INSTRUCTION),  # undefined
        (Instruction2.READ, b"\x84\x00\x04", ErrorNumber.RESULT_FAIL),  # 3 parameter bytes
        (Instruction2.CLEAR, b"\x01DXL!", ErrorNumber.RESULT_FAIL),  # wrong fixed bytes
        (Instruction2.WRITE, b"\x00\x00\x01\x00", ErrorNumber.ACCESS),
        (Instruction2.WRITE, b"\x74\x00\x00\x02", ErrorNumber.DATA_LENGTH),
        (Instruction2.WRITE, b"\x74\x00" + u32(5000), ErrorNumber.DATA_RANGE),
        (Instruction2.WRITE, b"\x68\x00" + u32(300), ErrorNumber.DATA_LIMIT),
        (Instruction2.READ, b"\x90\x02\x08\x00", ErrorNumber.ACCESS),  # 656..663 runs past 662
    ],
)
def test_error_numbers_byte_for_byte(xm, instruction, params, error):
    bus, _ = xm
    replies = send(bus, 1, instruction, params)
    # A Read past the table: Access Error "and return with no parameters" (e-manual, Read's note).
    assert [r.data for r in replies] == [encode_status2(1, error, b"")]


def test_eeprom_write_with_torque_on_is_access_error(xm):
    bus, _ = xm
    assert status(bus, 1, Instruction2.WRITE, bytes((64, 0, 1))).error == ErrorNumber.NONE
    assert status(bus, 1, Instruction2.WRITE, bytes((11, 0, 1))).error == ErrorNumber.ACCESS


def test_clear_while_moving_is_result_fail(xm):
    bus, firmware = xm
    set_sensed(firmware[0], moving=1)
    refresh(bus)
    assert status(bus, 1, Instruction2.CLEAR, b"\x01DXL\x22").error == ErrorNumber.RESULT_FAIL
    assert firmware[0].clears == 0


def test_alert_bit_while_a_hardware_error_is_latched(xm):
    bus, firmware = xm
    set_sensed(firmware[0], hardware_error_status=0x04)
    refresh(bus)
    reply = status(bus, 1, Instruction2.PING)
    assert reply.error == 0x80 and reply.alert
    assert status(bus, 1, Instruction2.ACTION).error == 0x80 | ErrorNumber.INSTRUCTION


# -- Status Return Level, ID change, Return Delay Time -----------------------------------
def test_status_return_level(xm):
    bus, _ = xm
    send(bus, 1, Instruction2.WRITE, bytes((68, 0, 1)))
    assert send(bus, 1, Instruction2.WRITE, bytes((65, 0, 1))) == []
    assert len(send(bus, 1, Instruction2.READ, bytes((65, 0, 1, 0)))) == 1
    assert len(send(bus, 0xFE, Instruction2.SYNC_READ, bytes((65, 0, 1, 0, 1)))) == 1
    send(bus, 1, Instruction2.WRITE, bytes((68, 0, 0)))
    assert send(bus, 1, Instruction2.READ, bytes((65, 0, 1, 0))) == []
    assert len(send(bus, 1, Instruction2.PING)) == 1


def test_an_id_change_answers_from_the_old_id_then_moves(xm):
    bus, _ = xm
    assert status(bus, 7, Instruction2.WRITE, bytes((7, 0, 20))).id == 7
    assert send(bus, 7, Instruction2.PING) == []
    assert status(bus, 20, Instruction2.PING).id == 20


def test_return_delay_time_in_2_us_units(xm):
    bus, _ = xm
    send(bus, 2, Instruction2.WRITE, bytes((9, 0, 10)))
    assert send(bus, 2, Instruction2.PING)[0].delay_s == pytest.approx(20e-6)


def test_a_servo_at_another_baud_does_not_hear(xm):
    bus, _ = xm
    assert send(bus, 1, Instruction2.PING) and not bus.receive(encode_instruction2(1, Instruction2.PING), line_bps=1e6)


def test_status_packets_on_the_wire_are_ignored(xm):
    bus, _ = xm
    assert bus.receive(h("Ping status")) == []


# -- firmware state: Realtime Tick, Bus Watchdog, reboot ----------------------------------
def test_realtime_tick_counts_milliseconds_and_wraps(xm):
    bus, _ = xm
    bus.clock.advance(40.0)
    tick = int.from_bytes(status(bus, 1, Instruction2.READ, bytes((120, 0, 2, 0))).params, "little")
    assert tick == 40000 % 32768


def test_bus_watchdog_stops_the_servo_and_refuses_goals_until_cleared(xm):
    bus, firmware = xm
    send(bus, 1, Instruction2.WRITE, bytes((11, 0, 1)))  # velocity mode
    send(bus, 1, Instruction2.WRITE, bytes((64, 0, 1)))
    send(bus, 1, Instruction2.WRITE, bytes((104, 0)) + u32(50))
    send(bus, 1, Instruction2.WRITE, bytes((108, 0)) + u32(20) + u32(100))  # Profile Acceleration and Velocity
    send(bus, 1, Instruction2.WRITE, bytes((98, 0, 5)))  # 100 ms
    bus.clock.advance(0.09)
    assert status(bus, 1, Instruction2.READ, bytes((98, 0, 1, 0))).params == b"\x05"  # in time: still armed
    bus.clock.advance(0.15)
    bus.advance()
    assert bus.servo(1).table.get("bus_watchdog") == 0xFF
    assert firmware[0].last.goal_velocity == 0 and firmware[0].commands[-1][1]
    # "When it stops, the Profile Acceleration(108) and Profile Velocity(112) are applied as '0'": a step, no ramp
    assert firmware[0].last.profile_acceleration == 0 and firmware[0].last.profile_velocity == 0
    assert status(bus, 1, Instruction2.WRITE, bytes((104, 0)) + u32(150)).error == ErrorNumber.DATA_RANGE
    # Only 0 clears the error ("If the value of Bus Watchdog(98) is changed to '0'"): re-armed at once, it stays
    assert status(bus, 1, Instruction2.WRITE, bytes((98, 0, 5))).error == ErrorNumber.DATA_RANGE
    assert bus.servo(1).table.get("bus_watchdog") == 0xFF
    assert status(bus, 1, Instruction2.WRITE, bytes((104, 0)) + u32(150)).error == ErrorNumber.DATA_RANGE
    assert status(bus, 1, Instruction2.WRITE, bytes((98, 0, 0))).error == ErrorNumber.NONE
    assert firmware[0].last.goal_velocity == 0  # still stopped: nothing new was asked
    assert status(bus, 1, Instruction2.WRITE, bytes((104, 0)) + u32(150)).error == ErrorNumber.NONE
    assert firmware[0].last.goal_velocity == 150


def test_bus_watchdog_in_position_mode_holds_the_shaft_with_its_drive_limits_kept(xm):
    # Goal PWM caps the drive in position mode: zeroed by the watchdog, the servo would go limp, not stop.
    bus, firmware = xm
    table = bus.servo(1).table
    send(bus, 1, Instruction2.WRITE, bytes((64, 0, 1)))
    send(bus, 1, Instruction2.WRITE, bytes((98, 0, 5)))  # 100 ms
    bus.clock.advance(0.25)
    bus.advance()
    assert table.get("bus_watchdog") == 0xFF
    held = firmware[0].last
    assert held.goal_position == table.get("present_position") and held.goal_velocity == 0
    assert held.goal_pwm == table.get("pwm_limit") and held.goal_current == table.get("current_limit")


def test_bus_watchdog_does_not_trip_with_the_torque_off(xm):
    """It "monitors the communication interval ... when Torque Enable(64) is '1'" (e-manual, Bus Watchdog(98)):
    with the torque off no silence trips it, whether the bus steps through it or a packet ends it; the interval
    is timed from the packet that turns the torque on."""
    bus, _ = xm
    table = bus.servo(1).table
    assert status(bus, 1, Instruction2.WRITE, bytes((98, 0, 5))).error == ErrorNumber.NONE  # 100 ms, torque off
    bus.clock.advance(10.0)
    bus.advance()
    assert table.get("bus_watchdog") == 5
    assert status(bus, 1, Instruction2.READ, bytes((98, 0, 1, 0))).params == b"\x05"
    bus.clock.advance(10.0)
    assert status(bus, 1, Instruction2.WRITE, bytes((64, 0, 1))).error == ErrorNumber.NONE
    assert table.get("bus_watchdog") == 5 and table.get("torque_enable") == 1
    bus.clock.advance(0.098)
    bus.advance()
    assert table.get("bus_watchdog") == 5
    bus.clock.advance(0.004)
    bus.advance()
    assert table.get("bus_watchdog") == 0xFF


@pytest.mark.parametrize("value", [1, 5, 50])
@pytest.mark.parametrize("ended_by", ["step", "packet"])
def test_bus_watchdog_trips_after_its_value_times_20_ms(xm, value, ended_by):
    """Unit 20 ms: silent for 2 ms less than value x 20 ms the watchdog is still armed, 2 ms more and it has
    tripped (-1, read 255), seen by a step of the bus in the silence or by the packet that ends it."""
    bus, _ = xm
    table = bus.servo(1).table
    send(bus, 1, Instruction2.WRITE, bytes((64, 0, 1)))
    send(bus, 1, Instruction2.WRITE, bytes((98, 0, value)))
    interval_s = value * 0.020

    def watchdog_after(silence_s):
        bus.clock.advance(silence_s)
        if ended_by == "step":
            bus.advance()
            return table.get("bus_watchdog")
        return status(bus, 1, Instruction2.READ, bytes((98, 0, 1, 0))).params[0]  # (it restarts the interval)

    assert watchdog_after(interval_s - 0.002) == value
    if ended_by == "step":
        bus.clock.advance(0.004)
        bus.advance()
        assert table.get("bus_watchdog") == 0xFF
    else:
        assert watchdog_after(interval_s + 0.002) == 0xFF


def test_reboot_restores_the_ram_area_and_keeps_the_eeprom(xm):
    bus, firmware = xm
    send(bus, 1, Instruction2.WRITE, bytes((31, 0, 70)))
    send(bus, 1, Instruction2.WRITE, bytes((65, 0, 1)))
    send(bus, 1, Instruction2.REBOOT)
    table = bus.servo(1).table
    assert (table.get("temperature_limit"), table.get("led")) == (70, 0)
    assert firmware[0].reboots == 1


def test_boot_sets_goal_pwm_and_current_to_their_limits_and_goal_position_to_present(xm):
    bus, firmware = xm
    table = bus.servo(1).table
    assert table.get("goal_pwm") == table.get("pwm_limit")
    assert table.get("goal_current") == table.get("current_limit")
    assert table.get("goal_position") == 2048
    assert firmware[0].last.goal_pwm == table.get("pwm_limit")


def test_models_mix_on_one_bus():
    bus = Bus2([(1, model("xm430-w350")), (6, model("xl330-m077"))], lambda spec, index: RecordingFirmware(),
               clock=VirtualClock())
    models = {r.servo_id: decode_packet2(r.data).params[:2] for r in bus.receive(h("Ping broadcast"))}
    assert models == {1: (1020).to_bytes(2, "little"), 6: (1190).to_bytes(2, "little")}


def test_a_protocol_1_model_is_refused():
    with pytest.raises(ValueError, match="not 2.0"):
        Bus2([(1, model("ax-12a"))], lambda spec, index: RecordingFirmware())


def test_replies_timed_in_sequence_keep_the_wire_paced_and_their_order_and_delays_unpaced():
    """A broadcast Ping's answers: paced, each byte leaves when its slot on the wire ends (ID n's answer its Return
    Delay Time and n slots of a status and the longest Return Delay Time in); unpaced, bytes take no time, so each
    answer leaves whole, in ID order (ID n: its Return Delay Time and n longest ones)."""
    bus, _ = recording_bus(ids=(1, 2), key="xl430-w250")
    replies = bus.receive(h("Ping broadcast"))
    rdt_s, slot_rdt_s, byte_s = 500e-6, 508e-6, BITS_PER_BYTE / 57600
    status_s = len(replies[0].data) * byte_s
    paced = merge_replies(replies, 10.0, per_byte=True, in_sequence=bus.replies_in_sequence)
    assert b"".join(data for _, data in paced) == b"".join(r.data for r in replies)
    for reply, first_byte_s in zip(replies, (rdt_s + status_s + slot_rdt_s, rdt_s + 2 * (status_s + slot_rdt_s))):
        k = sum(len(r.data) for r in replies if r.servo_id < reply.servo_id)
        assert paced[k][0] == pytest.approx(10.0 + first_byte_s + byte_s, abs=byte_s / 2)  # on the byte grid
    chunks = merge_replies(replies, 10.0, per_byte=False, in_sequence=bus.replies_in_sequence)
    assert [data for _, data in chunks] == [r.data for r in replies]
    assert [t for t, _ in chunks] == pytest.approx([10.0 + rdt_s + slot_rdt_s, 10.0 + rdt_s + 2 * slot_rdt_s])


def test_requests_too_big_to_answer_do_not_crash_the_bus(xm):
    bus, _ = xm
    # Fast Sync Read of 65535 bytes from three servos: no LENGTH can announce it, nobody starts.
    assert send(bus, 0xFE, Instruction2.FAST_SYNC_READ, bytes((0, 0, 0xFF, 0xFF, 1, 2, 3))) == []
    # The broadcast ID in a Fast list: the servos before it answer, the chain stops there.
    assert len(send(bus, 0xFE, Instruction2.FAST_SYNC_READ, bytes((0, 0, 2, 0, 1, 0xFE, 2)))) == 1
    # A READ of 65535 bytes: Access Error and no data (e-manual, Read), not a 64 KiB packet.
    reply = status(bus, 1, Instruction2.READ, bytes((0, 0, 0xFF, 0xFF)))
    assert (reply.error, len(reply.params)) == (ErrorNumber.ACCESS, 0)


def test_random_packets_and_noise_never_raise():
    """Seeded random instructions, parameters, flipped bits and noise: every one is answered or ignored."""
    bus, _ = recording_bus(ids=(1, 2, 3), key="xm430-w350")
    rng = random.Random(7)
    instructions = [int(i) for i in Instruction2 if i != Instruction2.STATUS] + [0x07, 0x99]
    for _ in range(3000):
        address = rng.choice((7, 8, 9, 11, 48, 64, 68, 98, 104, 116, 168, 224, 660, 65535))
        params = address.to_bytes(2, "little") + bytes(rng.randrange(256) for _ in range(rng.randrange(12)))
        data = bytearray(encode_instruction2(rng.choice((0, 1, 2, 3, 9, 0xFE)), rng.choice(instructions), params))
        if rng.random() < 0.1:
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        if rng.random() < 0.05:
            data = bytearray(rng.randrange(256) for _ in range(rng.randrange(1, 30)))
        for reply in bus.receive(bytes(data)):
            assert reply.data.startswith(b"\xff\xff\xfd\x00")
        if rng.random() < 0.1:
            bus.clock.advance(0.01)


def test_secondary_id_groups_servos_silently_and_on_the_ram_area_only(xm):
    """e-manual, Secondary ID(12): executed by the group, no status packet, EEPROM out of reach, ID first."""
    bus, _ = xm
    for servo_id in (1, 2, 3):
        send(bus, servo_id, Instruction2.WRITE, bytes((12, 0, 5)))  # Secondary ID 5
    replies = send(bus, 5, Instruction2.WRITE, bytes((65, 0, 1)))
    assert [r.servo_id for r in replies] == [5]  # only the servo whose ID it is answers
    assert [bus.servo(i).table.get("led") for i in range(1, 8)] == [1, 1, 1, 0, 1, 0, 0]  # ID 5 itself too
    send(bus, 5, Instruction2.WRITE, bytes((31, 0, 60)))  # Temperature Limit: EEPROM
    assert [bus.servo(i).table.get("temperature_limit") for i in (1, 2, 3, 5)] == [80, 80, 80, 60]
    # A Reg Write through it is judged when registered: an EEPROM one is refused then, so a broadcast Action
    # cannot carry an ID change to the whole group (they would all take ID 9 and collide).
    assert status(bus, 5, Instruction2.REG_WRITE, bytes((7, 0, 9))).error == ErrorNumber.NONE  # ID 5's own: registered
    assert [bus.servo(i).table.get("registered_instruction") for i in (1, 2, 3, 5)] == [0, 0, 0, 1]
    send(bus, 0xFE, Instruction2.ACTION, b"")  # broadcast
    assert sorted(bus.ids) == [1, 2, 3, 4, 6, 7, 9]
    send(bus, 3, Instruction2.WRITE, bytes((12, 0, 255)))  # off again
    send(bus, 5, Instruction2.WRITE, bytes((65, 0, 0)))
    assert [bus.servo(i).table.get("led") for i in (1, 2, 3, 9)] == [0, 0, 1, 1]


def test_eeprom_persists_by_launch_id_signed_values_too(tmp_path):
    store = StateStore(tmp_path)
    bus, _ = recording_bus(ids=(1, 2), key="xm430-w350", state_store=store)
    send(bus, 1, Instruction2.WRITE, bytes((20, 0)) + u32(-300))  # Homing Offset, signed
    send(bus, 2, Instruction2.WRITE, bytes((7, 0, 9)))  # ID 2 -> 9
    send(bus, 1, Instruction2.WRITE, bytes((65, 0, 1)))  # LED: RAM, not kept
    bus.close()
    again, _ = recording_bus(ids=(1, 2), key="xm430-w350", state_store=store)
    assert again.ids == [1, 9]
    assert again.servo(1).table.get("homing_offset") == -300 and again.servo(1).table.get("led") == 0


def test_the_backup_outlives_the_process_and_startup_restores_from_it(tmp_path):
    """A state store keeps the Control Table Backup with the EEPROM (the servo's own non-volatile memory): a servo
    launched again finds it (Backup Ready 1), and Startup Configuration's RAM Restore brings its gains back."""
    store = StateStore(tmp_path)
    bus, _ = recording_bus(ids=(1,), key="xl430-w250", state_store=store)
    send(bus, 1, Instruction2.WRITE, bytes((84, 0)) + (1234).to_bytes(2, "little"))  # Position P Gain
    assert status(bus, 1, Instruction2.CONTROL_TABLE_BACKUP, b"\x01CTRL").error == ErrorNumber.NONE
    send(bus, 1, Instruction2.WRITE, bytes((60, 0, 2)))  # RAM Restore at startup
    bus.close()
    again, _ = recording_bus(ids=(1,), key="xl430-w250", state_store=store)
    table = again.servo(1).table
    assert table.get("backup_ready") == 1 and table.get("position_p_gain") == 1234
    restore = encode_instruction2(1, Instruction2.CONTROL_TABLE_BACKUP, b"\x02CTRL")
    assert [r.data for r in again.receive(restore)] == [EMPTY_OK]  # the stored backup can be restored too
    again.close()
    path = store.path_for(1)
    path.write_text(path.read_text().replace('"backup": "', '"backup": "zz'))
    with pytest.raises(StateFileError, match="unusable state file"):
        recording_bus(ids=(1,), key="xl430-w250", state_store=store)


def test_control_table_backup_stores_with_torque_off_and_restores_the_eeprom():
    bus, firmware = recording_bus(ids=(1, 2), key="xl430-w250")  # its table has Backup Ready (147)
    table = bus.servo(1).table
    assert [r.data for r in bus.receive(h("Control Table Backup (0x20) store"))] == [EMPTY_OK]
    assert table.get("backup_ready") == 1
    send(bus, 1, Instruction2.WRITE, bytes((31, 0, 50)))  # Temperature Limit
    restore = encode_instruction2(1, Instruction2.CONTROL_TABLE_BACKUP, b"\x02CTRL")
    assert [r.data for r in bus.receive(restore)] == [EMPTY_OK]
    assert table.get("temperature_limit") == 72 and firmware[0].reboots == 1
    assert table.get("backup_ready") == 1  # the backup outlives the reboot of the restore
    send(bus, 1, Instruction2.REBOOT)
    assert table.get("backup_ready") == 1
    send(bus, 1, Instruction2.WRITE, bytes((64, 0, 1)))
    assert status(bus, 1, Instruction2.CONTROL_TABLE_BACKUP, b"\x01CTRL").error == ErrorNumber.RESULT_FAIL
    assert status(bus, 2, Instruction2.CONTROL_TABLE_BACKUP, b"\x02CTRL").error == ErrorNumber.RESULT_FAIL  # nothing stored


def test_control_table_backup_restore_with_torque_on_fails_and_keeps_the_table():
    """"If the Torque Enable is set as '1' (Torque On), Status Packet with Result Fail will be returned": the
    restore too, which then neither restores nor reboots."""
    bus, firmware = recording_bus(ids=(1,), key="xl430-w250")
    table = bus.servo(1).table
    assert status(bus, 1, Instruction2.CONTROL_TABLE_BACKUP, b"\x01CTRL").error == ErrorNumber.NONE
    send(bus, 1, Instruction2.WRITE, bytes((31, 0, 50)))  # Temperature Limit, after the backup
    send(bus, 1, Instruction2.WRITE, bytes((64, 0, 1)))
    assert status(bus, 1, Instruction2.CONTROL_TABLE_BACKUP, b"\x02CTRL").error == ErrorNumber.RESULT_FAIL
    assert table.get("temperature_limit") == 50 and table.get("torque_enable") == 1 and firmware[0].reboots == 0


@pytest.mark.parametrize("startup", [0, 1, 2, 3])
def test_startup_configuration_turns_the_torque_on_and_restores_the_backed_up_ram_at_boot(startup):
    """Startup Configuration(60): bit 0 Torque On at startup, bit 1 the backup's RAM registers (gains, profile,
    Indirect Addresses) restored at startup; neither without its bit, and nothing a backup does not carry."""
    bus, _ = recording_bus(ids=(1,), key="xl430-w250")
    table = bus.servo(1).table
    send(bus, 1, Instruction2.WRITE, bytes((84, 0)) + (1234).to_bytes(2, "little"))  # Position P Gain
    send(bus, 1, Instruction2.WRITE, bytes((112, 0)) + u32(77))  # Profile Velocity
    send(bus, 1, Instruction2.WRITE, bytes((168, 0)) + (132).to_bytes(2, "little"))  # Indirect Address 1
    send(bus, 1, Instruction2.WRITE, bytes((65, 0, 1)))  # LED: RAM, not in a backup
    assert status(bus, 1, Instruction2.CONTROL_TABLE_BACKUP, b"\x01CTRL").error == ErrorNumber.NONE
    send(bus, 1, Instruction2.WRITE, bytes((84, 0)) + (999).to_bytes(2, "little"))  # after the backup
    assert status(bus, 1, Instruction2.WRITE, bytes((60, 0, startup))).error == ErrorNumber.NONE
    send(bus, 1, Instruction2.REBOOT)
    restored = bool(startup & 2)
    assert table.get("position_p_gain") == (1234 if restored else 640)
    assert table.get("profile_velocity") == (77 if restored else 0)
    assert table.get("indirect_address_1") == (132 if restored else 224)
    assert table.get("led") == 0
    assert table.get("torque_enable") == startup & 1
    assert table.get("goal_position") == table.get("present_position")  # torque on at boot holds where it is


def test_startup_ram_restore_without_a_backup_boots_with_the_defaults():
    bus, _ = recording_bus(ids=(1,), key="xl430-w250")
    send(bus, 1, Instruction2.WRITE, bytes((84, 0)) + (1234).to_bytes(2, "little"))
    send(bus, 1, Instruction2.WRITE, bytes((60, 0, 2)))
    send(bus, 1, Instruction2.REBOOT)
    assert bus.servo(1).table.get("position_p_gain") == 640


def test_the_xl320_knows_no_clear_backup_or_fast_read():
    """The Protocol 2.0 page's "Supported DYNAMIXEL" lists leave the XL-320 out of Clear, Control Table Backup
    and the fast reads: Instruction Error to the first two, silence in a fast read's chain (which stops there),
    while the X series beside it answers all of them."""
    bus, _ = recording_bus(ids=(1,), key="xl-320")
    assert status(bus, 1, Instruction2.CLEAR, b"\x01DXL\x22").error == ErrorNumber.INSTRUCTION
    assert status(bus, 1, Instruction2.CONTROL_TABLE_BACKUP, b"\x01CTRL").error == ErrorNumber.INSTRUCTION
    assert bus.servo(1).backup is None
    for fast, plain in ((Instruction2.FAST_SYNC_READ, Instruction2.SYNC_READ),
                        (Instruction2.FAST_BULK_READ, Instruction2.BULK_READ)):
        params = bytes((37, 0, 2, 0, 1)) if plain == Instruction2.SYNC_READ else bytes((1, 37, 0, 2, 0))
        assert send(bus, 0xFE, fast, params) == []
        assert len(send(bus, 0xFE, plain, params)) == 1  # the plain forms it answers
    x_bus, _ = recording_bus(ids=(1,), key="xl430-w250")
    assert status(x_bus, 1, Instruction2.CLEAR, b"\x01DXL\x22").error == ErrorNumber.NONE
    assert len(send(x_bus, 0xFE, Instruction2.FAST_SYNC_READ, bytes((132, 0, 4, 0, 1)))) == 1


def test_reg_write_is_checked_when_registered_and_bulk_write_errors_are_silent(xm):
    bus, _ = xm
    assert status(bus, 1, Instruction2.REG_WRITE, b"\x74\x00" + u32(5000)).error == ErrorNumber.DATA_RANGE
    assert bus.servo(1).table.get("registered_instruction") == 0
    assert send(bus, 0xFE, Instruction2.BULK_WRITE, bytes((1, 0x74, 0, 4, 0)) + u32(5000) + bytes((2, 65, 0, 1, 0, 1))) == []
    assert bus.servo(1).table.get("goal_position") == 2048 and bus.servo(2).table.get("led") == 1
