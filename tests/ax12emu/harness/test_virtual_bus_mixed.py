"""A wire mixing AX-12As (Protocol 1.0) and X-series servos (Protocol 2.0) from the harness: VirtualBus and the URL.

IDs are per protocol, so an ID both protocols have is named with ``protocol=`` in the state
methods and the faults, and is refused with the reason without it.
"""

from __future__ import annotations

import pytest
import serial
from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, PacketHandler
from emu_testkit import UrlPortHandler, ok

import ax12emu  # noqa: F401  (registers the URL handler)
from ax12emu import FaultConfig, VirtualBus
from ax12emu.bus.mixed import MixedBus
from ax12emu.protocol.packets import encode_instruction
from ax12emu.protocol.packets2 import Instruction2, encode_instruction2

XL430 = 1060
AX12 = 12
MIXED = "1-2:ax-12a,1-3:xl430-w250"


@pytest.fixture
def mixed():
    """AX-12As 1-2 and XL430s 1-3 on one wire at 1 Mbps, in virtual time; both packet handlers on one port."""
    with VirtualBus(servo=MIXED, transport="inprocess", virtual_time=True, baud_bps=1_000_000) as bus:
        port = UrlPortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(1_000_000)
        try:
            yield bus, port, PacketHandler(1.0), PacketHandler(2.0)
        finally:
            port.closePort()


def test_each_protocol_finds_its_own_servos(mixed):
    bus, port, ph1, ph2 = mixed
    assert isinstance(bus.bus, MixedBus)
    assert [ok(ph1.ping(port, i)) for i in (1, 2)] == [AX12, AX12]
    assert ph1.ping(port, 3)[1] == COMM_RX_TIMEOUT
    assert [ok(ph2.ping(port, i)) for i in (1, 2, 3)] == [XL430] * 3


def test_an_id_on_both_protocols_needs_the_protocol(mixed):
    bus, port, ph1, ph2 = mixed
    with pytest.raises(ValueError, match=r"ID 1 answers on both protocols .*give protocol=1.0 or protocol=2.0"):
        bus.read(1, "present_position")
    assert bus.read(1, "present_position", protocol=1.0) == 512
    assert bus.read(1, "present_position", protocol=2.0) == 2048
    assert bus.read(3, "present_position") == 2048  # only the XL430 has ID 3
    with pytest.raises(KeyError, match="no servo with ID 4 on this wire"):
        bus.read(4, "led")
    with pytest.raises(KeyError, match="no servo with ID 3"):
        bus.read(3, "led", protocol=1.0)
    with pytest.raises(ValueError, match="protocol must be 1.0 or 2.0"):
        bus.read(1, "led", protocol=3)
    assert "cw_angle_limit" in bus.table(2, protocol=1.0) and "operating_mode" in bus.table(2, protocol=2.0)


def test_writes_reach_the_servo_of_the_protocol_named(mixed):
    bus, port, ph1, ph2 = mixed
    bus.write(2, "led", 1, protocol=2.0)
    assert ok(ph2.read1ByteTxRx(port, 2, 65)) == 1
    assert ok(ph1.read1ByteTxRx(port, 2, 25)) == 0  # the AX-12A with ID 2 untouched
    bus.write(2, "id", 7, protocol=1.0)
    assert ok(ph1.ping(port, 7)) == AX12
    assert bus.read(7, "id") == 7


def test_both_kinds_move_and_heat_in_virtual_time(mixed):
    bus, port, ph1, ph2 = mixed
    assert ph1.write2ByteTxRx(port, 1, 30, 700)[0] == COMM_SUCCESS  # AX-12A Goal Position (turns torque on)
    assert ph2.write1ByteTxRx(port, 1, 64, 1)[0] == COMM_SUCCESS
    assert ph2.write4ByteTxRx(port, 1, 116, 3000)[0] == COMM_SUCCESS
    bus.step(1.5)
    assert abs(ok(ph1.read2ByteTxRx(port, 1, 36)) - 700) <= 3
    assert abs(ok(ph2.read4ByteTxRx(port, 1, 132)) - 3000) <= 20
    assert bus.angle_deg(1, protocol=2.0) == pytest.approx(3000 * 360 / 4096, abs=2)
    assert bus.angle_deg(1, protocol=1.0) == pytest.approx(700 * 300 / 1023, abs=2)
    bus.set_temperature(2, 80, protocol=1.0)  # above the AX-12A's limit: Overheating in its status
    assert ph1.ping(port, 2)[2] & 0x04
    bus.set_temperature(2, 90, protocol=2.0)  # the XL430's firmware latches it: the Alert bit
    assert ph2.ping(port, 2)[2] == 0x80 and ph2.ping(port, 3)[2] == 0


def test_faults_name_a_servo_by_slot_and_protocol(mixed):
    bus, port, ph1, ph2 = mixed
    with pytest.raises(ValueError, match="ID 1 was launched on both protocols of this wire: give protocol=1.0"):
        bus.faults.vanish(1)
    bus.faults.vanish(1, protocol=2.0)
    assert ph2.ping(port, 1)[1] == COMM_RX_TIMEOUT and ok(ph1.ping(port, 1)) == AX12
    bus.faults.stall(3)  # only an XL430 was launched as 3
    assert bus.faults.active(3) == ["stalled"] and bus.faults.active(1, protocol=2.0) == ["vanished"]
    bus.faults.force_alarm(2, "overload", protocol=1.0)  # the AX-12A: its alarm bit, no latch
    assert ph1.ping(port, 2)[2] == 0x20 and ph2.ping(port, 2)[2] == 0
    bus.faults.set_reply_faults(drop=1.0)  # the wire's: both protocols
    assert ph1.ping(port, 1)[1] == COMM_RX_TIMEOUT and ph2.ping(port, 2)[1] == COMM_RX_TIMEOUT
    assert bus.faults.dropped == 2
    bus.faults.clear()
    assert ok(ph2.ping(port, 1)) == XL430 and ph1.ping(port, 2)[2] == 0


def test_fault_options_on_a_mixed_wire():
    with VirtualBus(servo="1:ax-12a,2:xl430-w250", transport="inprocess", faults=FaultConfig(vanish=((2, None, None),))) as bus:
        assert bus.faults.active(2) == ["vanished"]
    with pytest.raises(ValueError, match="ID 1 was launched on both protocols") as caught:
        VirtualBus(servo=MIXED, transport="inprocess", faults=FaultConfig(stall=(1,)))
    assert "a fault option cannot say which" in str(caught.value)  # not "give protocol=", which an option cannot


def test_a_url_builds_a_mixed_wire():
    with serial.serial_for_url(f"ax12emu://?servo={MIXED}&baud=1000000", baudrate=1_000_000, timeout=0.5) as link:
        link.write(encode_instruction(2, 0x01))  # Protocol 1.0 PING
        assert len(link.read(6)) == 6
        link.write(encode_instruction2(3, Instruction2.PING))
        assert len(link.read(14)) == 14
    with serial.serial_for_url(f"ax12emu://?servo={MIXED}&baud=1000000&vanish=3", baudrate=1_000_000, timeout=0.05) as link:
        link.write(encode_instruction2(3, Instruction2.PING))
        assert link.read(14) == b""
    # AX-12As alone with servo=: how they start at another rate (they were refused, as "the default bus")
    with serial.serial_for_url("ax12emu://?servo=1:ax-12a&baud=57600", baudrate=57_600, timeout=0.05) as link:
        link.write(encode_instruction(1, 0x01))
        assert len(link.read(6)) == 6


@pytest.mark.ax12_servo("1:ax-12a,1:xl430-w250")
@pytest.mark.ax12_bus_options(transport="inprocess", baud_bps=1_000_000)
def test_the_pytest_marker_takes_a_mixed_wire(ax12_bus):
    assert ax12_bus.read(1, "model_number", protocol=1.0) == AX12
    assert ax12_bus.read(1, "model_number", protocol=2.0) == XL430
