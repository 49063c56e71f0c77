"""The faults of an X-series servo's own on a Protocol 2.0 bus (Faults2), as dynamixel-sdk PacketHandler(2.0) sees them.

Each acts inside the firmware model, so the e-manual's rules follow: an error is detected only if
Shutdown(63) selects it, latches in Hardware Error Status with the Alert bit (0x80) in every status
packet and the torque off, and only REBOOT clears it; a blocked shaft trips Overload after the
firmware's overload time.  All in virtual time.
"""

from __future__ import annotations

import pytest
import serial
from dynamixel_sdk import COMM_RX_CORRUPT, COMM_SUCCESS, GroupSyncRead, PacketHandler
from emu_testkit import UrlPortHandler, ok

import ax12emu  # noqa: F401  (registers the URL handler)
from ax12emu import FaultConfig, VirtualBus
from ax12emu.faults.config import _alarm
from ax12emu.protocol.packets2 import Instruction2, encode_instruction2

BAUD = 57600
ALERT = 0x80
TORQUE_ENABLE, HARDWARE_ERROR, GOAL_POSITION, PRESENT_POSITION = 64, 70, 116, 132
SHUTDOWN = 63


@pytest.fixture
def xl430():
    with VirtualBus([1, 2], servo="xl430-w250", transport="inprocess", virtual_time=True) as bus:
        port = UrlPortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(BAUD)
        try:
            yield bus, port, PacketHandler(2.0)
        finally:
            port.closePort()


def test_a_forced_error_latches_with_the_alert_bit_until_reboot(xl430):
    bus, port, ph = xl430
    assert ph.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
    bus.faults.force_alarm(1, "overheating,electrical_shock")
    value, comm, error = ph.read1ByteTxRx(port, 1, HARDWARE_ERROR)
    assert (value, comm, error) == (0x14, COMM_SUCCESS, ALERT)
    assert ph.ping(port, 1)[2] == ALERT and ph.ping(port, 2)[2] == 0  # every packet of that servo, no other
    assert bus.read(1, "torque_enable") == 0  # Shutdown turned it off
    ph.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1)
    bus.step(0.01)
    assert bus.read(1, "torque_enable") == 0  # only REBOOT lets it on again
    assert bus.faults.active(1) == ["alarm 0x14"]
    ph.reboot(port, 1)
    assert ph.read1ByteTxRx(port, 1, HARDWARE_ERROR) == (0, COMM_SUCCESS, 0)
    assert bus.faults.active(1) == []  # the client's REBOOT cleared it
    assert ph.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
    bus.step(0.01)
    assert bus.read(1, "torque_enable") == 1


def test_an_error_shutdown_does_not_select_is_refused_until_selected(xl430):
    bus, port, ph = xl430
    with pytest.raises(ValueError, match=r"Shutdown\(63\) is 0x34, which does not select input_voltage"):
        bus.faults.force_alarm(1, "input_voltage")
    assert ph.read1ByteTxRx(port, 1, HARDWARE_ERROR) == (0, COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, SHUTDOWN, 0x35) == (COMM_SUCCESS, 0)
    bus.faults.force_alarm(1, 0x01)
    assert ph.read1ByteTxRx(port, 1, HARDWARE_ERROR) == (0x01, COMM_SUCCESS, ALERT)
    with pytest.raises(ValueError, match="Hardware Error Status bits"):
        bus.faults.force_alarm(1, 0x02)  # no such bit on the X series


def test_clear_alarm_reboots_the_servo(xl430):
    bus, port, ph = xl430
    bus.faults.force_alarm(2, "overload")
    assert ph.ping(port, 2)[2] == ALERT
    bus.faults.clear_alarm(2)
    assert ph.ping(port, 2)[2] == 0 and bus.faults.active(2) == []


def test_a_blocked_shaft_trips_overload_after_the_firmware_overload_time(xl430):
    bus, port, ph = xl430
    start = ph.read4ByteTxRx(port, 1, PRESENT_POSITION)[0]
    for servo_id in (1, 2):
        ph.write1ByteTxRx(port, servo_id, TORQUE_ENABLE, 1)
    bus.faults.stall(1)
    for servo_id in (1, 2):
        ph.write4ByteTxRx(port, servo_id, GOAL_POSITION, start + 1000)
    bus.step(0.5)
    assert ph.read4ByteTxRx(port, 1, PRESENT_POSITION)[0] == start
    assert bus.read(1, "present_velocity") == 0
    assert bus.read(1, "present_load") > 900  # 0.1 % of the stall current: the motor drives into the block
    assert bus.read(1, "moving_status") & 0x08  # following error: the trajectory went on without the shaft
    assert bus.read(1, "hardware_error_status") == 0
    assert abs(ph.read4ByteTxRx(port, 2, PRESENT_POSITION)[0] - (start + 1000)) < 20  # the free one got there
    bus.step(0.4)
    assert bus.read(1, "hardware_error_status") == 0  # not yet: 0.9 s of the firmware's 1 s
    bus.step(0.3)
    assert ph.read1ByteTxRx(port, 1, HARDWARE_ERROR) == (0x20, COMM_SUCCESS, ALERT)
    assert bus.read(1, "torque_enable") == 0 and bus.read(1, "present_load") == 0
    assert bus.faults.active(1) == ["stalled"]
    bus.faults.release(1)
    assert ph.read1ByteTxRx(port, 1, HARDWARE_ERROR)[0] == 0x20  # freed, but latched until REBOOT
    ph.reboot(port, 1)
    ph.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1)
    ph.write4ByteTxRx(port, 1, GOAL_POSITION, start + 1000)
    bus.step(1.0)
    assert abs(ph.read4ByteTxRx(port, 1, PRESENT_POSITION)[0] - (start + 1000)) < 20


def test_stall_takes_no_overload_time_of_its_own(xl430):
    bus, _, _ = xl430
    with pytest.raises(ValueError, match="overload time"):
        bus.faults.stall(1, overload_after_s=0.5)


def test_a_pinned_temperature_is_judged_by_the_firmware(xl430):
    bus, port, ph = xl430
    bus.set_temperature(1, 70)  # below Temperature Limit (72 on the XL430)
    assert ph.read1ByteTxRx(port, 1, 146) == (70, COMM_SUCCESS, 0)
    bus.step(1.0)
    assert bus.read(1, "present_temperature") == 70  # held against the thermal model
    bus.set_temperature(1, 90)
    assert ph.read1ByteTxRx(port, 1, 146) == (90, COMM_SUCCESS, ALERT)
    assert bus.read(1, "hardware_error_status") == 0x04
    bus.set_temperature(1, None)
    bus.step(0.01)
    assert bus.read(1, "present_temperature") < 40 and bus.read(1, "hardware_error_status") == 0x04
    assert bus.faults.active(1) == []


def test_a_pinned_voltage_raises_input_voltage_only_where_shutdown_selects_it(xl430):
    bus, port, ph = xl430
    bus.set_voltage(1, 5.0)
    assert ph.read2ByteTxRx(port, 1, 144) == (50, COMM_SUCCESS, 0)  # Shutdown 0x34: not detected
    ph.write1ByteTxRx(port, 1, SHUTDOWN, 0x35)
    bus.step(0.01)
    assert ph.read2ByteTxRx(port, 1, 144) == (50, COMM_SUCCESS, ALERT)
    assert bus.read(1, "hardware_error_status") == 0x01


def test_hold_pins_sensed_registers_only(xl430):
    bus, _, _ = xl430
    bus.faults.hold(2, "present_position", 100)
    bus.step(0.1)
    assert bus.read(2, "present_position") == 100
    bus.faults.hold(2, "present_position", None)
    assert bus.read(2, "present_position") != 100
    with pytest.raises(ValueError, match="not a register the firmware senses"):
        bus.faults.hold(2, "goal_position", 5)
    with pytest.raises(KeyError, match="no register 'present_voltage'"):
        bus.faults.hold(2, "present_voltage", 5)


def test_two_servos_on_one_id_both_act_and_their_answers_collide(xl430):
    bus, port, ph = xl430
    bus.faults.duplicate(2, 1)
    assert ok(ph.ping(port, 1)) == 1060  # equal answers AND to themselves: clean
    assert ph.ping(port, 2)[1] != COMM_SUCCESS
    assert ph.write1ByteTxRx(port, 1, 65, 1) == (COMM_SUCCESS, 0)
    assert bus.call(lambda b: [servo.table.get("led") for servo in b.servos]) == [1, 1]  # both acted
    assert ok(ph.read4ByteTxRx(port, 1, PRESENT_POSITION)) == 2048  # same readings: clean
    bus.faults.hold(2, "present_position", 100)  # now they differ
    assert ph.read4ByteTxRx(port, 1, PRESENT_POSITION)[1] == COMM_RX_CORRUPT
    read = GroupSyncRead(port, ph, PRESENT_POSITION, 4)
    read.addParam(1)
    assert read.txRxPacket() == COMM_RX_CORRUPT  # both answer in ID 1's turn
    assert bus.faults.active(2) == ["answers as ID 1", "present_position held at 100"]
    bus.faults.unduplicate(2)
    assert ok(ph.read4ByteTxRx(port, 1, PRESENT_POSITION)) == 2048
    assert ok(ph.read4ByteTxRx(port, 2, PRESENT_POSITION)) == 100


@pytest.mark.parametrize("instruction", [Instruction2.FAST_SYNC_READ, Instruction2.FAST_BULK_READ])
def test_two_servos_on_one_id_both_send_their_share_of_a_fast_read(instruction):
    """Fast Sync/Bulk Read of IDs 1 and 2 with a third servo also on ID 1: ID 1's share is both servos' bytes
    AND-ed; ID 2, after it, runs its CRC on over what it heard, so the packet's own CRC holds."""
    from ax12emu.protocol.crc16 import crc16
    from ax12emu.protocol.packets2 import FastStatusPart, encode_fast_status

    if instruction == Instruction2.FAST_SYNC_READ:
        params = bytes((PRESENT_POSITION, 0, 4, 0, 1, 2))
    else:
        params = bytes((1, PRESENT_POSITION, 0, 4, 0, 2, PRESENT_POSITION, 0, 4, 0))
    request = encode_instruction2(0xFE, instruction, params)
    with VirtualBus([1, 2, 3], servo="xl430-w250", transport="inprocess", virtual_time=True) as bus:
        bus.faults.hold(3, "present_position", 100)
        bus.faults.hold(2, "present_position", 2000)
        clean = encode_fast_status([FastStatusPart(1, 0, (2048).to_bytes(4, "little")),
                                    FastStatusPart(2, 0, (2000).to_bytes(4, "little"))])
        assert b"".join(r.data for r in bus.call(lambda b: b.receive(request))) == clean
        bus.faults.duplicate(3, 1)
        wire = b"".join(r.data for r in bus.call(lambda b: b.receive(request)))
    header = 8  # FF FF FD 00 FE LEN_L LEN_H 55
    assert len(wire) == len(clean)
    assert wire[header:header + 2] == bytes((0, 1))  # error 0, ID 1 from both
    assert wire[header + 2:header + 6] == (2048 & 100).to_bytes(4, "little")  # the two readings AND-ed
    share_2 = header + 8
    assert wire[share_2:share_2 + 6] == clean[share_2:share_2 + 6]  # ID 2's own share
    assert int.from_bytes(wire[-2:], "little") == crc16(wire[:-2])  # its CRC covers the collided bytes


def test_duplicate_from_a_config_and_its_id_range():
    with VirtualBus([1, 2], servo="xl430-w250", transport="inprocess", faults=FaultConfig(duplicate=((2, 1),))) as bus:
        assert bus.call(lambda b: b.ids) == [1, 1]
        with pytest.raises(ValueError, match="outside 0..252"):
            bus.faults.duplicate(1, 253)


def test_the_same_faults_from_a_config_and_a_url():
    config = FaultConfig.from_options({"alarm": ["1:electrical_shock"], "stall": ["2"]})
    assert config.alarm == ((1, "electrical_shock"),)
    with VirtualBus([1, 2], servo="xl430-w250", transport="inprocess", virtual_time=True, faults=config) as bus:
        assert bus.read(1, "hardware_error_status") == 0x10
        assert bus.faults.active(2) == ["stalled"]
    with serial.serial_for_url("ax12emu://?servo=xl430-w250&alarm=1:overload&virtual_time=1", baudrate=BAUD, timeout=0.5) as link:
        link.write(encode_instruction2(1, Instruction2.PING))
        status = link.read(14)
        assert len(status) == 14 and status[8] == ALERT  # the ERROR field of the status packet


def test_an_x_series_alarm_name_is_refused_on_the_ax12_bus():
    assert _alarm("1:overload") == (1, 0x20)  # one meaning on both protocols: bits
    with pytest.raises(ValueError, match="unknown alarm 'electrical_shock'"):
        VirtualBus([1], transport="inprocess", faults=FaultConfig(alarm=((1, "electrical_shock"),)))
    with pytest.raises(ValueError, match="unknown alarm 'hot'"):
        _alarm("1:hot")


def test_an_xl320s_alarm_is_judged_and_shown_in_its_own_shutdown_bits():
    """The XL-320's Shutdown(18) and Hardware Error Status(50) put Overload at bit 0, OverHeating at 1, Input Voltage
    at 2 (its e-manual page); its initial Shutdown 3 selects Overload and OverHeating, not Input Voltage."""
    with VirtualBus([1], servo="xl-320", transport="inprocess", virtual_time=True) as bus:
        with pytest.raises(ValueError, match=r"Shutdown\(18\) is 0x03, which does not select input_voltage"):
            bus.faults.force_alarm(1, "input_voltage")
        bus.faults.force_alarm(1, "overheating")
        assert bus.read(1, "hardware_error_status") == 0x02
        assert bus.faults.active(1) == ["alarm 0x04"]  # named in the firmware's bits, as on the X series
        bus.faults.clear_alarm(1)
        assert bus.read(1, "hardware_error_status") == 0 and bus.faults.active(1) == []


def test_an_xl320_holds_only_the_readings_its_table_shows_in_the_firmwares_units():
    """Present Voltage and Temperature read as the firmware senses them (0.1 V, deg C); Present Position is in the
    XL-320's own units, so pinning it is refused.  A pinned voltage below Min Voltage Limit raises Input Voltage
    (bit 2 in Hardware Error Status(50)) once Shutdown selects it."""
    with VirtualBus([1], servo="xl-320", transport="inprocess", virtual_time=True) as bus:
        with pytest.raises(ValueError, match="present_temperature, present_voltage"):
            bus.faults.hold(1, "present_position", 300)
        bus.write(1, "shutdown", 0x07)  # Overload, OverHeating and Input Voltage
        bus.faults.hold(1, "present_voltage", 50)
        bus.step(0.01)
        assert bus.read(1, "present_voltage") == 50 and bus.read(1, "hardware_error_status") == 0x04
        bus.faults.hold(1, "present_voltage", None)
        bus.step(0.01)
        assert bus.read(1, "present_voltage") == 74


def test_clearing_faults_after_the_client_rebooted_does_not_reboot_again(xl430):
    """The client cleared the forced error itself (REBOOT) and turned the torque on: lifting the faults changed
    nothing then, where it rebooted the servo again and its torque went off."""
    bus, port, ph = xl430
    bus.faults.force_alarm(1, "overheating")
    ph.reboot(port, 1)
    assert ph.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
    bus.faults.clear()
    assert bus.read(1, "torque_enable") == 1


def test_a_held_reading_the_register_cannot_show_is_refused_on_the_x_series(xl430):
    """The register showed 44 while the firmware judged 300 (Alert with the register under the limit)."""
    bus, port, ph = xl430
    with pytest.raises(ValueError, match=r"present_temperature holds 0..255, got 300"):
        bus.faults.hold(1, "present_temperature", 300)
    assert ph.read1ByteTxRx(port, 1, HARDWARE_ERROR) == (0, COMM_SUCCESS, 0)
