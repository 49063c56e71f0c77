"""VirtualBus, ``ax12emu://`` and the pytest plugin serving Protocol 2.0 servos (``servo=``).

The client is unmodified dynamixel-sdk with PacketHandler(2.0) (through ``emu_testkit.UrlPortHandler``,
the port subclass the docs show for URLs); register helpers take the model's own names.
"""

from __future__ import annotations

import math

import pytest
import serial
from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, GroupSyncRead, PacketHandler
from emu_testkit import UrlPortHandler, ok

import ax12emu  # noqa: F401  (registers the URL handler)
from ax12emu import VirtualBus
from ax12emu.harness.urlhandler.protocol_ax12emu import UrlError
from ax12emu.protocol.packets2 import ErrorNumber, Instruction2, encode_instruction2, encode_status2
from ax12emu.protocol.servo_models import model
from ax12emu.servo.servo2 import Servo2Options
from ax12emu.servo.virtual_servo import ServoOptions

BAUD = 57600
XL430, XM430, XL330 = 1060, 1020, 1190
TORQUE_ENABLE, LED, GOAL_POSITION, PRESENT_POSITION = 64, 65, 116, 132

pytest_plugins = ["pytester"]


def sdk2(url: str, baud: int = BAUD) -> tuple[UrlPortHandler, PacketHandler]:
    port = UrlPortHandler(url)
    assert port.openPort() and port.setBaudRate(baud)
    return port, PacketHandler(2.0)


def test_in_process_bus_answers_dynamixel_sdk_by_model():
    """A per-ID servo text: each ID answers with its model's number; a Sync Read of all; an error number."""
    with VirtualBus(servo="1-2:xm430-w350,3:xl330-m077", transport="inprocess") as bus:
        assert bus.bus.ids == [1, 2, 3]
        port, ph = sdk2(bus.port)
        try:
            assert [ok(ph.ping(port, i)) for i in (1, 2, 3)] == [XM430, XM430, XL330]
            assert ph.ping(port, 4)[1] == COMM_RX_TIMEOUT
            found, comm = ph.broadcastPing(port)
            assert comm == COMM_SUCCESS and {i: v[0] for i, v in found.items()} == {1: XM430, 2: XM430, 3: XL330}
            read = GroupSyncRead(port, ph, PRESENT_POSITION, 4)
            for servo_id in (1, 2, 3):
                assert read.addParam(servo_id)
            assert read.txRxPacket() == COMM_SUCCESS
            assert [read.getData(i, PRESENT_POSITION, 4) for i in (1, 2, 3)] == [bus.read(i, "present_position") for i in (1, 2, 3)]
            assert ph.write4ByteTxRx(port, 3, GOAL_POSITION, 5000) == (COMM_SUCCESS, ErrorNumber.DATA_RANGE)
        finally:
            port.closePort()


def test_register_helpers_use_the_model_table_names():
    """read/write/table by the X-series names; a write reaches the firmware (a goal moves the shaft, in virtual time)."""
    with VirtualBus([1, 2], servo="xl430-w250", transport="inprocess", virtual_time=True) as bus:
        table = bus.table(1)
        assert table["model_number"] == XL430 and "profile_velocity" in table and "cw_angle_limit" not in table
        start = bus.read(1, "present_position")
        assert abs(bus.angle_deg(1) - start * 360.0 / 4096) < 0.1
        bus.write(1, "torque_enable", 1)
        bus.write(1, "goal_position", start + 1024)
        bus.step(2.0)
        assert abs(bus.read(1, "present_position") - (start + 1024)) <= 20
        assert abs(bus.angle_deg(1) - (start + 1024) * 360.0 / 4096) < 2.0
        assert bus.read(2, "present_position") == start  # the other servo held still
        assert math.isclose(bus.now_s, 2.0)
        with pytest.raises(KeyError, match="XL430-W250 has no register 'cw_angle_limit'"):
            bus.read(1, "cw_angle_limit")


def test_id_write_moves_the_servo_on_the_bus():
    with VirtualBus([1], servo="xl430-w250", transport="inprocess") as bus:
        bus.write(1, "id", 9)
        assert bus.bus.ids == [9] and bus.read(9, "id") == 9
        port, ph = sdk2(bus.port)
        try:
            assert ok(ph.ping(port, 9)) == XL430
        finally:
            port.closePort()


def test_external_torque_reaches_the_firmware():
    """A torque on a limp shaft turns it (virtual time)."""
    with VirtualBus([1], servo="xl430-w250", transport="inprocess", virtual_time=True) as bus:
        start = bus.angle_deg(1)
        bus.set_external_torque(1, 0.3)
        bus.step(0.5)
        assert bus.angle_deg(1) > start + 5.0


@pytest.mark.parametrize(("servo", "mode", "goal", "stop"), [
    # an XM430-W350 in Current Control Mode (0): Goal Current(102), signed
    ("xm430-w350", {"operating_mode": 0}, ("goal_current", 50, -50), ("goal_current", 0)),
    # an MX-64 (Protocol 1.0) in Torque Control Mode: Goal Torque(71) CCW 0..1023, CW 1024 + magnitude; Torque Limit 0
    ("mx-64", {"torque_ctrl_mode_enable": 1}, ("goal_torque", 100, 1124), ("torque_limit", 0)),
])
def test_a_current_loop_driven_backwards_hard_still_obeys_its_goal(servo, mode, goal, stop):
    """Back-driven at twice its stall torque, the current loop's correction wound up and froze with the duty at its
    limit: released, the motor ran at its no-load speed whatever Goal Current / Goal Torque / Torque Limit said;
    only Torque Enable 0 stopped it."""
    name, first, then = goal
    with VirtualBus([1], servo=servo, transport="inprocess", virtual_time=True) as bus:
        for register, value in mode.items():
            bus.write(1, register, value)
        bus.write(1, "torque_enable", 1)
        bus.write(1, name, first)
        bus.step(0.5)
        bus.set_external_torque(1, -16.0)
        bus.step(0.5)
        bus.set_external_torque(1, 0.0)
        bus.write(1, name, then)
        bus.step(0.5)
        bus.write(1, *stop)
        start = bus.angle_deg(1)
        bus.step(1.0)
        stopped_at = bus.angle_deg(1)
        bus.step(0.5)
        assert abs(bus.angle_deg(1) - stopped_at) < 1.0, (start, stopped_at, bus.angle_deg(1))  # it ran ~190 deg/s


def test_read_and_table_show_a_writes_consequence_as_a_clients_next_read_would():
    """Straight from the table, they lagged a write until the next packet or step: Torque Enable 0 beside the old
    Present PWM and Current, Present Position without the Homing Offset just written."""
    with VirtualBus([1], servo="xm430-w350", transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "operating_mode", 1)  # velocity
        bus.write(1, "torque_enable", 1)
        bus.write(1, "goal_velocity", 100)
        bus.step(0.5)
        assert bus.read(1, "present_pwm") != 0
        bus.write(1, "torque_enable", 0)
        assert (bus.read(1, "present_pwm"), bus.read(1, "present_current")) == (0, 0)
        bus.step(0.5)
        at = bus.read(1, "present_position")
        bus.write(1, "homing_offset", 500)
        assert bus.table(1)["present_position"] == at + 500


def test_served_on_a_pty_too():
    """The same servos behind a pty, at another start baud (baud_bps)."""
    with VirtualBus([3], servo="xl330-m077", baud_bps=1_000_000) as bus:
        assert bus.read(3, "baud_rate") == 3
        port, ph = sdk2(bus.port, 1_000_000)
        try:
            assert ok(ph.ping(port, 3)) == XL330
            assert ph.write1ByteTxRx(port, 3, LED, 1) == (COMM_SUCCESS, 0)
            assert bus.read(3, "led") == 1
        finally:
            port.closePort()


def test_served_over_tcp_with_options_of_the_2_0_servos():
    """TCP; Servo2Options(reply_on_crc_error=False): a packet with a wrong CRC goes unanswered."""
    with VirtualBus([1], servo="xl430-w250", transport="tcp", options=Servo2Options(reply_on_crc_error=False)) as bus:
        assert bus.port.startswith("socket://")
        with serial.serial_for_url(bus.port, timeout=0.3) as link:
            bad = bytearray(encode_instruction2(1, Instruction2.PING))
            bad[-1] ^= 0xFF
            link.write(bytes(bad))
            assert link.read(14) == b""
            link.write(encode_instruction2(1, Instruction2.PING))
            assert len(link.read(14)) == 14


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"servo": "xl999"}, "unknown servo model 'xl999'"),
        ({"servo": "1:xl430-w250", "ids": [1]}, "give one of them"),
        ({"servo": "xl430-w250", "baud_bps": 12345}, "not 12345"),
        ({"servo": "xl430-w250", "model": "kinematic"}, "shape AX-12As and AX-18As; 'xl430-w250' names none"),
        ({"servo": "ax-18a", "model": object()}, "a model object cannot serve a servo= wire"),
        ({"baud_bps": 3_000_000}, r"ID 1 \(AX-12A\) cannot run at 3000000 bps"),
        ({"servo": "mx-28", "baud_bps": float("nan")}, "baud_bps must be a finite bit rate"),  # not Baud Rate 0
        ({"options": Servo2Options()}, "Servo2Options apply with servo="),
        ({"servo": "xl430-w250", "options": ServoOptions(goal_position_enables_torque=False)}, "'xl430-w250' names none"),
        ({"servo": "ax-18a", "options": ServoOptions(profile="ax12-2006")}, "profile: the AX-12A bus alone"),
        ({"trace": ""}, "trace= names no file"),  # an unset variable's "": it traced nothing without a word
        ({"trace": " "}, "trace= names no file"),
    ],
)
def test_bad_servo_arguments_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        VirtualBus(**kwargs)


def test_what_the_2_0_bus_lacks_is_refused_by_name():
    with VirtualBus(servo="xl430-w250", transport="inprocess") as bus:
        with pytest.raises(NotImplementedError, match="Protocol 2.0 bus"):
            bus.set_angle_deg(1, 10.0)


def test_url_servo_option_builds_a_private_2_0_bus():
    """ax12emu://?servo=...: the port's baud is the line's; the servos answer at their factory 57,600."""
    with serial.serial_for_url("ax12emu://?servo=xl430-w250&ids=1,2", baudrate=BAUD, timeout=0.5) as link:
        link.write(encode_instruction2(2, Instruction2.PING))
        firmware = model("xl430-w250").firmware_version or 0  # the model file's, when it gives one
        assert link.read(14) == encode_status2(2, 0, bytes([XL430 & 0xFF, XL430 >> 8, firmware]))
    with serial.serial_for_url("ax12emu://?servo=1:xl430-w250", baudrate=1_000_000, timeout=0.05) as link:
        link.write(encode_instruction2(1, Instruction2.PING))
        assert link.read(14) == b""  # deaf at another baud, as on the wire
    with serial.serial_for_url("ax12emu://?servo=1:xl430-w250&baud=1000000", baudrate=1_000_000, timeout=0.5) as link:
        link.write(encode_instruction2(1, Instruction2.PING))
        assert len(link.read(14)) == 14


def test_url_through_dynamixel_sdk():
    port, ph = sdk2("ax12emu://?servo=1-3:xm430-w350&virtual_time=1")
    try:
        assert ok(ph.read2ByteTxRx(port, 3, 0)) == XM430
        assert ph.write1ByteTxRx(port, 2, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
        assert ok(ph.read1ByteTxRx(port, 2, TORQUE_ENABLE)) == 1
    finally:
        port.closePort()


@pytest.mark.parametrize(
    "url, message",
    [
        ("ax12emu://?servo=nope", "unknown servo model 'nope'"),
        ("ax12emu://?servo=", "servo= given no value"),
        ("ax12emu://?servo=1-2:xl430-w250&ids=3", "give one of them"),
        ("ax12emu://?servo=xl430-w250&baud=fast", "baud must be a bit rate"),
        ("ax12emu://?servo=xl430-w250&baud=1234", "not 1234"),
        ("ax12emu://?servo=xl430-w250&duplicate=1:253", "outside 0..252"),
        ("ax12emu://?servo=xl430-w250&alarm=1:input_voltage", "does not select input_voltage"),
        ("ax12emu://?servo=xl430-w250&alarm=1:hot", "unknown alarm 'hot'"),
        ("ax12emu://?servo=xl430-w250&vanish=9", "no servo launched as ID 9"),
        ("ax12emu://?servo=xl430-w250&profile=ax12a", "profile not available with servo="),
        ("ax12emu://?servo=xl430-w250&goal_torque=unchanged", "'xl430-w250' names none"),
        ("ax12emu://?servo=ax-18a&goal_torque=maybe", "goal_torque must be on or unchanged"),
        ("ax12emu://?servo=1:ax-12a,2:ax-18a&params=twin.toml", r"several models \(ax-12a, ax-18a\)"),
        ("ax12emu://?ids=1&baud=57600", "baud= applies with servo="),
    ],
)
def test_bad_servo_urls_are_named(url, message):
    with pytest.raises(UrlError, match=message):
        serial.serial_for_url(url, baudrate=BAUD)


@pytest.mark.ax12_servo("xl430-w250")
@pytest.mark.ax12_ids(2, 3)
@pytest.mark.ax12_bus_options(transport="inprocess")
def test_plugin_marker_serves_2_0_servos(ax12_bus):
    assert ax12_bus.bus.ids == [2, 3] and ax12_bus.read(3, "model_number") == XL430


def test_plugin_option_serves_every_bus(pytester):
    """pytest --ax12-servo SPEC: a test without the marker gets those servos; the marker still wins."""
    pytester.makepyfile(
        """
        import pytest

        def test_default(ax12_bus):
            assert ax12_bus.bus.ids == [1, 4]
            assert ax12_bus.read(4, "model_number") == 1190

        @pytest.mark.ax12_servo("xm430-w350")
        def test_marker(ax12_bus):
            assert ax12_bus.read(1, "model_number") == 1020
        """
    )
    result = pytester.runpytest_inprocess("--ax12-servo", "1,4:xl330-m077", "--strict-markers", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=2)


def test_startup_torque_on_holds_the_rebooted_servo_and_a_goal_moves_it_through_dynamixel_sdk():
    """Startup Configuration(60) bit 0 set and the servo rebooted: Torque Enable reads 1 without a write, the
    shaft holds against a load that turns a limp one, and the next Goal Position moves it (virtual time)."""
    with VirtualBus([1], servo="xl430-w250", transport="inprocess", virtual_time=True) as bus:
        port, ph = sdk2(bus.port)
        try:
            assert ph.write1ByteTxRx(port, 1, 60, 1) == (COMM_SUCCESS, 0)
            assert ph.reboot(port, 1) == (COMM_SUCCESS, 0)
            assert ok(ph.read1ByteTxRx(port, 1, TORQUE_ENABLE)) == 1
            start = bus.read(1, "present_position")
            bus.set_external_torque(1, 0.3)  # a limp shaft turns on (measured: 168, 355, 541 pulses after 0.5, 1, 1.5 s)
            bus.step(0.5)
            held = bus.read(1, "present_position") - start
            bus.step(1.0)
            assert held < 60 and bus.read(1, "present_position") - start == held  # the position loop's offset, held
            bus.set_external_torque(1, 0.0)
            assert ph.write4ByteTxRx(port, 1, GOAL_POSITION, start + 1024) == (COMM_SUCCESS, 0)
            bus.step(2.0)
            assert abs(bus.read(1, "present_position") - (start + 1024)) <= 20
        finally:
            port.closePort()


def test_torque_turned_on_by_a_goal_update_is_turned_off_by_torque_enable_0_through_dynamixel_sdk():
    """Drive Mode bit 3 ("Torque Enable(64) will be updated to '1'" by a goal): the torque it turned on answers a
    later Torque Enable 0 as one written would (it was lost: the servo ran on and refused EEPROM writes)."""
    with VirtualBus([1], servo="xl430-w250", transport="inprocess", virtual_time=True) as bus:
        port, ph = sdk2(bus.port)
        try:
            assert ph.write1ByteTxRx(port, 1, 10, 0x08) == (COMM_SUCCESS, 0)  # Drive Mode: torque on by goal update
            start = bus.read(1, "present_position")
            assert ph.write4ByteTxRx(port, 1, GOAL_POSITION, start + 2000) == (COMM_SUCCESS, 0)
            assert ok(ph.read1ByteTxRx(port, 1, TORQUE_ENABLE)) == 1
            bus.step(0.05)
            assert ph.write1ByteTxRx(port, 1, TORQUE_ENABLE, 0) == (COMM_SUCCESS, 0)
            bus.step(3.0)
            assert ok(ph.read1ByteTxRx(port, 1, TORQUE_ENABLE)) == 0
            assert bus.read(1, "present_velocity") == 0 and bus.read(1, "present_pwm") == 0
            assert bus.read(1, "present_position") - start < 1500  # it coasted to rest short of the goal
            assert ph.write1ByteTxRx(port, 1, 9, 100) == (COMM_SUCCESS, 0)  # Return Delay Time: the EEPROM is open
        finally:
            port.closePort()


def test_the_bus_watchdog_stops_the_servo_when_the_silence_runs_out_in_one_virtual_stretch():
    """Bus Watchdog(98) 5 (100 ms) on a wheel turning at Goal Velocity 200: however long the silence, the servo
    is stopped about 100 ms after the last packet, its velocity goal a step to 0 ("When it stops, the Profile Acceleration(108) and
    Profile Velocity(112) are applied as '0'", e-manual); it ran on for the whole stretch before."""
    with VirtualBus([1, 2], servo="xl430-w250", transport="inprocess", virtual_time=True) as bus:
        port, ph = sdk2(bus.port)
        try:
            for servo_id in (1, 2):
                assert ph.write1ByteTxRx(port, servo_id, 11, 1) == (COMM_SUCCESS, 0)  # Velocity Control Mode
                assert ph.write4ByteTxRx(port, servo_id, 108, 50) == (COMM_SUCCESS, 0)  # Profile Acceleration
                assert ph.write1ByteTxRx(port, servo_id, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
                assert ph.write4ByteTxRx(port, servo_id, 104, 200) == (COMM_SUCCESS, 0)
            bus.step(1.0)  # both at speed (200 x 0.229 rpm: 3,126 pulses/s)
            start = [bus.read(i, "present_position") for i in (1, 2)]
            assert ph.write1ByteTxRx(port, 1, 98, 5) == (COMM_SUCCESS, 0)  # ID 1 only: 100 ms
            bus.step(2.0)
            moved = [bus.read(i, "present_position") - s for i, s in zip((1, 2), start)]
            assert bus.read(1, "bus_watchdog") == 0xFF and bus.read(1, "present_velocity") == 0
            # ~100 ms at speed (313 pulses), then the velocity loop brings it to rest; the other ran on for 2 s
            assert 300 < moved[0] < 1500 and moved[1] > 6000
            assert bus.read(1, "velocity_trajectory") == 0
            assert bus.read(1, "profile_acceleration") == 50  # the register keeps its value for the next goal
        finally:
            port.closePort()


@pytest.mark.parametrize("servo", ["xl430-w250", "xm430-w350", "xl330-m288", "xl330-m077", "xc330-m288"])
def test_every_x_model_takes_the_drive_mode_bits_its_firmware_has(servo):
    """Time-based profile (firmware V42 on) and torque on by goal update (X430 V45, X330 V46 on: control_table_drivemode.md)
    on the firmware each model file gives; the XL330's and XM430's files refused them."""
    with VirtualBus([1], servo=servo, transport="inprocess", virtual_time=True) as bus:
        port, ph = sdk2(bus.port)
        try:
            assert ph.write1ByteTxRx(port, 1, 10, 0x04 | 0x08) == (COMM_SUCCESS, 0)
            start = bus.read(1, "present_position")
            assert ph.write4ByteTxRx(port, 1, 112, 1000) == (COMM_SUCCESS, 0)  # time-based: reach the goal in 1 s
            assert ph.write4ByteTxRx(port, 1, GOAL_POSITION, start + 400) == (COMM_SUCCESS, 0)
            assert ok(ph.read1ByteTxRx(port, 1, TORQUE_ENABLE)) == 1
            bus.step(0.5)
            assert 100 < bus.read(1, "position_trajectory") - start < 300  # halfway through a 1 s profile
            bus.step(1.0)
            assert abs(bus.read(1, "present_position") - (start + 400)) <= 20  # there, within the loop's offset
        finally:
            port.closePort()
