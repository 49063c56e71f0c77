"""MX servos (Protocol 1.0 firmware) from the harness: VirtualBus(servo="mx-28"), per-ID mixes, the URL, the pytest plugin.

The harness builds the bus the servo text needs (one decision, ``build_wire``) and reaches every servo
through the buses' interface, so the state methods, faults and traces work on MX servos as on the
X series and the AX-12A, alone and with an AX-12A or an X-series servo sharing the wire.  In virtual time.
"""

from __future__ import annotations

import json

import pytest
import serial
from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, PacketHandler
from emu_testkit import UrlPortHandler, ok

import ax12emu  # noqa: F401  (registers the URL handler)
from ax12emu import FaultConfig, VirtualBus
from ax12emu.bus.bus import Bus
from ax12emu.bus.bus1x import Bus1X
from ax12emu.bus.mixed import MixedBus
from ax12emu.protocol.packets import encode_instruction, encode_status
from ax12emu.protocol.servo_models import model

pytest_plugins = ["pytester"]

MX28, MX64, AX12, XL430 = 29, 310, 12, 1060
#: The MX series' factory Baud Rate(4) 34: 2,000,000 / 35 = 57,143 bps (e-manual, MX-28 "Baud Rate(4)").
MX_FACTORY_BPS = 57_600
TORQUE_ENABLE, GOAL_POSITION, TORQUE_LIMIT, PRESENT_POSITION, GOAL_ACCELERATION = 24, 30, 34, 36, 73


@pytest.fixture
def mx28():
    """Two MX-28s at their factory rate, in virtual time, with a Protocol 1.0 packet handler."""
    with VirtualBus([1, 2], servo="mx-28", transport="inprocess", virtual_time=True) as bus:
        port = UrlPortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(MX_FACTORY_BPS)
        try:
            yield bus, port, PacketHandler(1.0)
        finally:
            port.closePort()


def test_mx_servos_alone_are_a_protocol_1_wire(mx28):
    bus, port, ph = mx28
    assert isinstance(bus.bus, Bus1X) and bus.bus.ids == [1, 2]
    assert [ok(ph.ping(port, i)) for i in (1, 2)] == [MX28, MX28]
    assert bus.read(1, "model_number") == MX28
    assert "goal_acceleration" in bus.table(1) and "cw_compliance_margin" not in bus.table(1)  # the MX table, not the AX-12's
    with pytest.raises(KeyError, match="MX-28 has no register 'cw_compliance_margin'"):
        bus.read(1, "cw_compliance_margin")
    with pytest.raises(ValueError, match="this bus's servos all speak Protocol 1.0"):
        bus.read(1, "led", protocol=2.0)


def test_an_mx_moves_in_virtual_time_and_the_state_methods_reach_it(mx28):
    bus, port, ph = mx28
    assert bus.angle_deg(1) == pytest.approx(180.0)  # Present Position 2048: the middle of the turn
    assert ph.write2ByteTxRx(port, 1, GOAL_POSITION, 3000) == (COMM_SUCCESS, 0)  # turns the torque on
    bus.step(1.0)
    assert abs(ok(ph.read2ByteTxRx(port, 1, PRESENT_POSITION)) - 3000) <= 3
    assert bus.angle_deg(1) == pytest.approx(3000 * 360 / 4096, abs=0.5)
    assert bus.read(2, "present_position") == 2048  # the other one stayed
    bus.write(2, "goal_position", 1000)  # as the firmware would: its firmware takes the new goal
    bus.write(2, "torque_enable", 1)
    bus.step(1.0)
    assert abs(bus.read(2, "present_position") - 1000) <= 3
    bus.write(2, "id", 7)
    assert ok(ph.ping(port, 7)) == MX28 and ph.ping(port, 2)[1] == COMM_RX_TIMEOUT
    with pytest.raises(NotImplementedError, match="firmware model of MX-28 does not let its angle be set"):
        bus.set_angle_deg(1, 10.0)


def test_a_push_and_a_pinned_reading_act_through_the_mx_firmware(mx28):
    bus, port, ph = mx28
    bus.set_external_torque(1, 1.0)  # torque off: the shaft turns under the push (N m, CCW: the angle grows)
    bus.step(0.5)
    assert bus.angle_deg(1) > 180.0 + 10.0 and bus.angle_deg(2) == pytest.approx(180.0)
    bus.set_temperature(2, 85)  # above Temperature Limit 80: Overheating, selected by the default Shutdown 0x24
    assert bus.temperature_c(2) == 85 and ph.ping(port, 2)[2] == 0x04 and ph.ping(port, 1)[2] == 0
    assert bus.read(2, "torque_limit") == 0  # the Alarm Shutdown of the Protocol 1.0 firmware
    bus.set_voltage(1, 17.0)  # outside 6..16 V: the status bit, whatever Shutdown selects (0x24 leaves it out) ...
    assert bus.read(1, "present_voltage") == 170 and ph.ping(port, 1)[2] == 0x01
    assert bus.read(1, "torque_limit") == 1023  # ... and no shutdown


def test_a_per_id_mix_puts_mx_and_ax_12a_on_protocol_1_beside_the_x_series():
    with VirtualBus(servo="1:mx-64,2:ax-12a,2-3:xl430-w250", transport="inprocess", virtual_time=True,
                    baud_bps=1_000_000) as bus:
        assert isinstance(bus.bus, MixedBus) and isinstance(bus.bus.bus1, Bus1X)
        port = UrlPortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(1_000_000)
        ph1, ph2 = PacketHandler(1.0), PacketHandler(2.0)
        try:
            assert [ok(ph1.ping(port, i)) for i in (1, 2)] == [MX64, AX12]
            assert [ok(ph2.ping(port, i)) for i in (2, 3)] == [XL430, XL430]
            assert bus.read(1, "model_number") == MX64  # only the MX-64 has ID 1
            assert bus.read(2, "model_number", protocol=1.0) == AX12
            # The AX-12A beside the MX servos: its bus's model (inside theirs) takes the angle and the push.
            bus.set_angle_deg(2, 100.0, protocol=1.0)
            assert bus.angle_deg(2, protocol=1.0) == pytest.approx(100.0)
            bus.set_temperature(2, 80, protocol=1.0)
            assert ph1.ping(port, 2)[2] & 0x04 and ph1.ping(port, 1)[2] == 0
            bus.set_external_torque(2, 0.2, protocol=1.0)  # both torque off: each turns CCW under its push
            bus.set_external_torque(1, 1.0)
            bus.step(0.2)  # short of a turn: the AX-12A's angle wraps at 360
            assert bus.angle_deg(2, protocol=1.0) > 100.0 + 5.0 and bus.angle_deg(1) > 180.0 + 5.0
            assert bus.angle_deg(2, protocol=2.0) == pytest.approx(180.0, abs=0.5)  # the XL430 with ID 2 unpushed
        finally:
            port.closePort()


def test_an_id_both_protocols_have_is_refused_naming_both_models():
    with VirtualBus(servo="1:mx-106,1:xm430-w350", transport="inprocess", virtual_time=True) as bus:
        with pytest.raises(ValueError, match=r"ID 1 answers on both protocols of this wire \(MX-106 on 1.0, XM430-W350 on 2.0\)"):
            bus.read(1, "led")
        assert bus.read(1, "model_number", protocol=1.0) == model("mx-106").model_number


def test_faults_given_to_virtual_bus_act_on_mx_servos():
    with VirtualBus([1, 2], servo="mx-28", transport="inprocess", virtual_time=True,
                    faults=FaultConfig(vanish=((2, None, None),), alarm=((1, "overload"),))) as bus:
        port = UrlPortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(MX_FACTORY_BPS)
        ph = PacketHandler(1.0)
        try:
            assert ph.ping(port, 1)[2] == 0x20 and ph.ping(port, 2)[1] == COMM_RX_TIMEOUT
            assert bus.faults.active(1) == ["alarm 0x20"] and bus.faults.active(2) == ["vanished"]
        finally:
            port.closePort()


def test_a_trace_records_every_servo_model(tmp_path):
    path = tmp_path / "mx.jsonl"
    with VirtualBus(servo="1:mx-28,2:ax-12a,3:xl430-w250", transport="inprocess", trace=str(path)):
        pass
    header = json.loads(path.read_text().splitlines()[0])
    assert header["servos"] == "1:mx-28,2:ax-12a,3:xl430-w250"


def test_a_url_builds_a_private_mx_bus():
    with serial.serial_for_url("ax12emu://?servo=mx-64&ids=1,2", baudrate=MX_FACTORY_BPS, timeout=0.5) as link:
        link.write(encode_instruction(2, 0x01))
        assert link.read(6) == encode_status(2, 0)
    with serial.serial_for_url("ax12emu://?servo=1:mx-28,2:ax-12a&baud=1000000&stall=1&vanish=2",
                               baudrate=1_000_000, timeout=0.05) as link:
        link.write(encode_instruction(1, 0x01))
        assert link.read(6) == encode_status(1, 0)
        link.write(encode_instruction(2, 0x01))
        assert link.read(6) == b""  # the AX-12A beside the MX is unplugged


def test_a_bus_of_ax_models_alone_stays_the_ax_12_bus():
    with VirtualBus(servo="1:ax-18a,2:ax-12a", transport="inprocess") as bus:
        assert type(bus.bus) is Bus


@pytest.mark.ax12_servo("mx-28")
@pytest.mark.ax12_ids(3, 4)
@pytest.mark.ax12_bus_options(transport="inprocess")
def test_plugin_marker_serves_mx_servos(ax12_bus):
    assert ax12_bus.bus.ids == [3, 4] and ax12_bus.read(4, "model_number") == MX28


@pytest.mark.ax12_servo("1:mx-64,2:ax-12a,1:xl430-w250")
@pytest.mark.ax12_bus_options(transport="inprocess")
def test_plugin_marker_serves_a_mix_with_mx(ax12_bus):
    assert ax12_bus.read(1, "model_number", protocol=1.0) == MX64
    assert ax12_bus.read(1, "model_number", protocol=2.0) == XL430


def test_plugin_option_serves_mx_servos(pytester):
    """pytest --ax12-servo with an MX model: a test without the marker gets it."""
    pytester.makepyfile(
        """
        def test_default(ax12_bus):
            assert ax12_bus.bus.ids == [1, 2]
            assert ax12_bus.read(2, "model_number") == 320
        """
    )
    result = pytester.runpytest_inprocess("--ax12-servo", "1-2:mx-106", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=1)


def test_baud_bps_sets_each_servo_by_what_its_own_baud_rate_values_mean():
    with VirtualBus([1], servo="mx-106", transport="inprocess", baud_bps=3_000_000) as bus:
        assert bus.read(1, "baud_rate") == 252  # the MX's "For BPS over 250 values": 3 Mbps
    with VirtualBus(servo="1:mx-28,2:ax-12a", transport="inprocess", baud_bps=1_000_000) as bus:
        assert [bus.read(i, "baud_rate") for i in (1, 2)] == [1, 1]
    with pytest.raises(ValueError, match=r"ID 2 \(AX-12A\) cannot run at 3000000 bps: its Baud Rate values give 7843..2000000 bps"):
        VirtualBus(servo="1:mx-28,2:ax-12a", transport="inprocess", baud_bps=3_000_000)


def test_a_joint_pushed_through_a_turn_goes_back_the_direct_way_within_one_turn(mx28):
    """Joint mode works within one turn (Goal Position 0..4,095; "Multi-turn mode allows joint mode control over
    multiple rotations"): a compliant joint pushed more than a turn round comes back to its goal the direct way,
    within the turn it reads; it used to drive back round every turn it was pushed through."""
    bus, port, ph = mx28
    assert ph.write1ByteTxRx(port, 1, 18, 0) == (COMM_SUCCESS, 0)  # Shutdown 0: no alarm cuts the push short
    assert ph.write2ByteTxRx(port, 1, GOAL_POSITION, 2048) == (COMM_SUCCESS, 0)
    bus.step(0.5)
    assert ph.write2ByteTxRx(port, 1, 34, 100) == (COMM_SUCCESS, 0)  # Torque Limit 10 %: a compliant joint
    bus.set_external_torque(1, 1.0)  # a hand turns the horn CCW, past what 10 % holds
    bus.step(4.0)
    bus.set_external_torque(1, 0.0)
    pushed_deg = bus.angle_deg(1)
    assert pushed_deg > 180.0 + 360.0  # more than a turn round
    bus.step(6.0)
    assert abs(bus.read(1, "present_position") - 2048) <= 3 and bus.read(1, "moving") == 0
    assert abs(bus.angle_deg(1) - (180.0 + 360.0)) < 1.0  # back to its goal in the turn it was in, not 1.5 turns back


@pytest.mark.parametrize(("drive_mode", "angle_deg"), [(0, 180.0 + 952 * 360 / 4096), (1, 180.0 - 952 * 360 / 4096)])
def test_the_mx_106_drive_mode_reverse_bit_turns_the_other_way(drive_mode, angle_deg):
    """Drive Mode(10) bit 0: "rotational direction is inverted. Thus, Goal Position, Present Position will have a
    inverted direction" (control_table_drivemode.md); the MX-106 stored it and turned the same way."""
    with VirtualBus([1], servo="mx-106", transport="inprocess", virtual_time=True) as bus:
        port = UrlPortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(MX_FACTORY_BPS)
        ph = PacketHandler(1.0)
        try:
            assert ph.write1ByteTxRx(port, 1, 10, drive_mode) == (COMM_SUCCESS, 0)
            assert ph.write2ByteTxRx(port, 1, GOAL_POSITION, 3000) == (COMM_SUCCESS, 0)
            bus.step(2.0)
            assert abs(bus.read(1, "present_position") - 3000) <= 5
            assert abs(bus.angle_deg(1) - angle_deg) < 1.0
        finally:
            port.closePort()


def test_present_load_is_the_output_so_a_shaft_pushed_round_with_no_output_reads_none(mx28):
    """"Present load is an inferred value based on the internal output value" (control_table_present_load.md): with
    Torque Limit 0 the output is 0 whatever the push (it read 18 %, the winding's braking current)."""
    bus, port, ph = mx28
    assert ph.write1ByteTxRx(port, 1, 18, 0) == (COMM_SUCCESS, 0)
    assert ph.write2ByteTxRx(port, 1, GOAL_POSITION, 2048) == (COMM_SUCCESS, 0)
    bus.step(0.2)
    assert ph.write2ByteTxRx(port, 1, 34, 0) == (COMM_SUCCESS, 0)
    bus.set_external_torque(1, 0.5)
    bus.step(1.0)
    assert bus.read(1, "present_speed") & 0x3FF > 20 and bus.read(1, "present_load") & 0x3FF == 0
    assert ph.write2ByteTxRx(port, 1, 34, 1023) == (COMM_SUCCESS, 0)
    bus.step(1.0)  # driving back against the push: a load, counter-clockwise of it
    assert bus.read(1, "present_load") & 0x3FF > 100
