"""Faults on a Protocol 1.0 wire with MX servos (Faults1X), as dynamixel-sdk PacketHandler(1.0) sees them.

The wire's faults act on every status packet of the wire and on each servo as on the AX-12 bus.
An MX's own faults act inside its X-series firmware model and show as the Protocol 1.0 firmware
shows them: every status packet carries the alarm conditions present, those Shutdown(18) selects drop
Torque Limit to 0, and once they are gone a Torque Limit written non-zero lets the motor run (e-manual,
MX-28 "Torque Limit(34)").  An AX-12A on the same wire keeps the AX-12 bus's faults.  All in virtual time.
"""

from __future__ import annotations

import pytest
from dynamixel_sdk import COMM_RX_CORRUPT, COMM_RX_TIMEOUT, COMM_SUCCESS, PacketHandler
from emu_testkit import UrlPortHandler, ok

import ax12emu  # noqa: F401  (registers the URL handler)
from ax12emu import FaultConfig, VirtualBus
from ax12emu.bus.clock import VirtualClock
from ax12emu.faults.injection import Faults, Faults1X, MixedFaults, faults_for
from ax12emu.harness.servos2 import build_wire
from ax12emu.protocol.packets import Instruction, encode_instruction

BAUD = 1_000_000
MX28, AX12 = 29, 12
SHUTDOWN, TORQUE_ENABLE, GOAL_POSITION, TORQUE_LIMIT, PRESENT_POSITION, PRESENT_LOAD = 18, 24, 30, 34, 36, 40
OVERLOAD, OVERHEATING, INPUT_VOLTAGE = 0x20, 0x04, 0x01


@pytest.fixture
def wire():
    """MX-28s 1-2 and an AX-12A 3 on one Protocol 1.0 wire at 1 Mbps, in virtual time."""
    with VirtualBus(servo="1-2:mx-28,3:ax-12a", transport="inprocess", virtual_time=True, baud_bps=BAUD) as bus:
        port = UrlPortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(BAUD)
        try:
            yield bus, port, PacketHandler(1.0)
        finally:
            port.closePort()


def test_the_faults_of_an_mx_wire_are_faults1x():
    bus1x = build_wire("1:mx-64,2:ax-12a", clock=VirtualClock())
    faults = faults_for(bus1x, seed=3)
    assert isinstance(faults, Faults1X) and isinstance(bus1x.ax_bus.faults, Faults) and faults.ax is bus1x.ax_bus.faults
    mixed = build_wire("1:mx-64,1:xl430-w250", clock=VirtualClock())
    assert isinstance(faults_for(mixed), MixedFaults) and isinstance(mixed.bus1.faults, Faults1X)


@pytest.mark.parametrize(("ids", "warned"), [([1], False), ([2], False), ([3], False), ([9], True), ([3, 9], False)])
def test_reply_faults_on_a_mixed_wire_warn_only_when_no_servo_of_it_answers_as_the_ids(caplog, ids, warned):
    """Each half of a mixed wire checked the IDs against its own servos alone: ``--fault-ids 3`` warned "no servo
    answers" from the Protocol 1.0 half while the XL430 on the 2.0 half answered as ID 3."""
    bus = build_wire("1:ax-12a,2:mx-28,3:xl430-w250", clock=VirtualClock())
    faults = faults_for(bus)
    with caplog.at_level("WARNING", logger="ax12emu.faults.injection"):
        faults.set_reply_faults(drop=1.0, ids=ids)
    said = [record.getMessage() for record in caplog.records if "no servo answers" in record.getMessage()]
    assert said == ([f"reply faults on IDs {ids}, which no servo answers as now (IDs [1, 2, 3])"] if warned else [])
    bus.close()


def test_reply_faults_act_on_every_status_packet_of_the_wire(wire):
    bus, port, ph = wire
    bus.faults.set_reply_faults(drop=1.0)
    assert ph.ping(port, 1)[1] == COMM_RX_TIMEOUT and ph.ping(port, 3)[1] == COMM_RX_TIMEOUT
    assert bus.faults.dropped == 2  # the MX's and the AX-12A's, counted once for the wire
    bus.faults.set_reply_faults(corrupt=1.0, ids=[2])
    assert ph.ping(port, 2)[1] == COMM_RX_CORRUPT and ok(ph.ping(port, 1)) == MX28 and ok(ph.ping(port, 3)) == AX12
    bus.faults.clear()
    assert ok(ph.ping(port, 2)) == MX28


def test_a_delayed_reply_leaves_late_by_delay_s():
    bus = build_wire("1:mx-28,2:ax-12a", clock=VirtualClock())
    on_time = {reply.servo_id: reply.delay_s for reply in bus.receive(encode_instruction(0xFE, Instruction.PING))}
    faults = faults_for(bus)
    bus.faults = faults
    faults.set_reply_faults(delay=1.0, delay_s=0.1)
    late = {reply.servo_id: reply.delay_s for reply in bus.receive(encode_instruction(0xFE, Instruction.PING))}
    assert late == {servo_id: pytest.approx(delay_s + 0.1) for servo_id, delay_s in on_time.items()} and len(late) == 2
    assert faults.delayed == 2


def test_an_unplugged_mx_hears_nothing(wire):
    bus, port, ph = wire
    bus.faults.vanish(1)
    assert ph.ping(port, 1)[1] == COMM_RX_TIMEOUT and ok(ph.ping(port, 2)) == MX28
    assert ph.write2ByteTxRx(port, 1, GOAL_POSITION, 3000)[0] == COMM_RX_TIMEOUT
    bus.step(0.5)
    assert bus.read(1, "goal_position") == 2048  # it did not hear the write
    bus.faults.reappear(1)
    assert ok(ph.ping(port, 1)) == MX28 and bus.faults.active(1) == []


def test_an_unplugged_mx_breaks_a_bulk_read_chain():
    """Bulk Read (0x92): each listed MX answers after the one before it; the chain stops at an unplugged one."""
    bus = build_wire("1-3:mx-28", clock=VirtualClock())
    bus.faults = faults_for(bus)
    # params: 0x00, then LENGTH, ID, ADDRESS per servo (e-manual, Protocol 1.0 "Bulk Read")
    bulk = encode_instruction(0xFE, Instruction.BULK_READ, bytes([0, 2, 2, PRESENT_POSITION, 2, 1, PRESENT_POSITION,
                                                                 2, 3, PRESENT_POSITION]))
    assert [reply.servo_id for reply in bus.receive(bulk)] == [2, 1, 3]
    bus.faults.vanish(1)
    assert [reply.servo_id for reply in bus.receive(bulk)] == [2]  # ID 3 waits for ID 1's status packet
    bus.faults.reappear(1)
    assert [reply.servo_id for reply in bus.receive(bulk)] == [2, 1, 3]


def test_two_mx_servos_on_one_id_both_answer_and_collide(wire):
    bus, port, ph = wire
    assert ph.write2ByteTxRx(port, 2, GOAL_POSITION, 3000) == (COMM_SUCCESS, 0)
    bus.step(1.0)
    bus.faults.duplicate(2, 1)
    assert ph.read2ByteTxRx(port, 1, PRESENT_POSITION)[1] == COMM_RX_CORRUPT  # 2048 and 3000 AND-ed on the wire
    assert ok(ph.ping(port, 1)) == MX28  # equal answers look clean
    assert bus.faults.active(2) == ["answers as ID 1"]
    bus.faults.unduplicate(2)
    assert ok(ph.ping(port, 2)) == MX28
    with pytest.raises(ValueError, match="outside 0..253"):
        bus.faults.duplicate(2, 254)


def test_a_forced_alarm_is_a_shutdown_until_lifted_and_torque_limit_is_written(wire):
    bus, port, ph = wire
    assert ph.write2ByteTxRx(port, 1, GOAL_POSITION, 3000) == (COMM_SUCCESS, 0)
    bus.faults.force_alarm(1, "overload")
    assert ph.ping(port, 1)[2] == OVERLOAD and ph.ping(port, 2)[2] == 0  # every packet of that servo, no other
    assert bus.read(1, "torque_limit") == 0
    bus.step(1.0)
    assert abs(bus.read(1, "present_position") - 2048) < 50  # no output: it did not go to 3000
    assert bus.faults.active(1) == ["alarm 0x20"]
    assert ph.write2ByteTxRx(port, 1, TORQUE_LIMIT, 1023) == (COMM_SUCCESS, OVERLOAD)  # the alarm still holds
    bus.step(0.01)
    assert bus.read(1, "torque_limit") == 0
    bus.faults.clear_alarm(1)
    assert ph.ping(port, 1)[2] == 0 and bus.faults.active(1) == []
    assert bus.read(1, "torque_limit") == 0  # as on the AX-12 bus: the client restores it
    assert ph.write2ByteTxRx(port, 1, TORQUE_LIMIT, 1023) == (COMM_SUCCESS, 0)  # the client's way out
    bus.step(1.0)
    assert abs(bus.read(1, "present_position") - 3000) <= 3


def test_a_forced_alarm_is_reported_whatever_shutdown_selects_and_shuts_down_only_where_it_does(wire):
    """As on the AX-12A (e-manual, Alarm Shutdown: the bits are the status packet's conditions, Shutdown decides the output)."""
    bus, port, ph = wire
    bus.faults.force_alarm(1, "input_voltage")  # the factory Shutdown 0x24 does not select it
    assert ph.ping(port, 1)[2] == INPUT_VOLTAGE
    bus.step(0.1)
    assert bus.read(1, "torque_limit") == 1023
    assert ph.write1ByteTxRx(port, 1, SHUTDOWN, 0x25) == (COMM_SUCCESS, INPUT_VOLTAGE)
    bus.step(0.01)
    assert bus.read(1, "torque_limit") == 0
    with pytest.raises(ValueError, match="unknown alarm 'electrical_shock'"):
        bus.faults.force_alarm(2, "electrical_shock")  # an X-series error the Protocol 1.0 status has no bit for
    with pytest.raises(ValueError, match="MX-28's alarm bits are"):
        bus.faults.force_alarm(2, 0x10)  # the status packet's Checksum Error bit: no alarm
    bus.faults.clear_alarm(1)
    assert ph.ping(port, 1)[2] == 0 and bus.faults.active(1) == []
    assert bus.read(1, "torque_limit") == 0


def test_a_blocked_mx_trips_overload_after_the_firmware_overload_time(wire):
    bus, port, ph = wire
    bus.faults.stall(1)
    for servo_id in (1, 2):
        assert ph.write2ByteTxRx(port, servo_id, GOAL_POSITION, 3000) == (COMM_SUCCESS, 0)
    bus.step(0.5)
    assert ph.read2ByteTxRx(port, 1, PRESENT_POSITION) == (2048, COMM_SUCCESS, 0)
    assert bus.read(1, "present_speed") == 0 and bus.read(1, "present_load") & 0x3FF > 900  # driving into the block
    bus.step(0.4)
    assert ph.ping(port, 1)[2] == 0  # 0.9 s of the firmware's 1 s
    assert abs(bus.read(2, "present_position") - 3000) <= 3  # the free one got there
    bus.step(0.3)
    assert ph.ping(port, 1)[2] == OVERLOAD and bus.read(1, "torque_limit") == 0
    assert bus.faults.active(1) == ["stalled"]
    bus.faults.release(1)
    assert ph.write2ByteTxRx(port, 1, TORQUE_LIMIT, 1023) == (COMM_SUCCESS, 0)
    bus.step(1.0)
    assert abs(bus.read(1, "present_position") - 3000) <= 3
    with pytest.raises(ValueError, match="overload time"):
        bus.faults.stall(2, overload_after_s=0.5)


def test_hold_pins_the_readings_the_firmware_senses(wire):
    bus, port, ph = wire
    bus.faults.hold(1, "present_temperature", 70)
    bus.step(1.0)
    assert bus.read(1, "present_temperature") == 70 and ph.ping(port, 1)[2] == 0  # below the limit 80
    bus.faults.hold(1, "present_temperature", 85)
    assert ph.ping(port, 1)[2] == OVERHEATING
    assert bus.faults.active(1) == ["present_temperature held at 85"]
    bus.faults.hold(1, "present_temperature", None)
    bus.step(0.01)
    assert bus.read(1, "present_temperature") < 40 and bus.faults.active(1) == []
    assert ph.ping(port, 1)[2] == 0  # a condition, not a latched error (as on the AX-12A)
    assert bus.read(1, "torque_limit") == 0  # the Shutdown (factory 0x24 selects Overheating) holds ...
    assert ph.write2ByteTxRx(port, 1, TORQUE_LIMIT, 1023) == (COMM_SUCCESS, 0)  # ... until the client writes it
    bus.step(0.01)
    assert ph.ping(port, 1)[2] == 0 and bus.read(1, "torque_limit") == 1023
    with pytest.raises(ValueError, match="not a register the firmware senses"):
        bus.faults.hold(2, "goal_position", 5)
    with pytest.raises(KeyError, match="MX-28 has no register 'present_input_voltage'"):
        bus.faults.hold(2, "present_input_voltage", 50)


def test_an_ax_12a_beside_mx_servos_keeps_the_ax_12_faults(wire):
    bus, port, ph = wire
    bus.faults.force_alarm(3, "input_voltage")  # the AX-12A raises any alarm bit, Shutdown or not
    assert ph.ping(port, 3)[2] == INPUT_VOLTAGE and ph.ping(port, 1)[2] == 0
    bus.faults.stall(3)
    bus.faults.vanish(2)
    assert bus.faults.active(3) == ["stalled", "alarm 0x01"] and bus.faults.active(2) == ["vanished"]
    bus.faults.clear()
    assert ph.ping(port, 3)[2] == 0 and ok(ph.ping(port, 2)) == MX28
    assert bus.faults.active(3) == [] and bus.faults.active(2) == []
    with pytest.raises(ValueError, match="no servo launched as ID 9"):
        bus.faults.vanish(9)


def test_fault_config_installs_on_a_wire_with_mx_servos():
    faults = FaultConfig(drop=0.5, vanish=((2, None, None),), stall=(1,), alarm=((3, 0x20),), seed=7)
    bus = build_wire("1:mx-106,2:ax-12a,3:mx-64,1:xl430-w250", clock=VirtualClock(), baud_bps=BAUD)
    with pytest.raises(ValueError, match="ID 1 was launched on both protocols"):
        faults.install(bus)  # the options cannot name the protocol
    bus = build_wire("1:mx-106,2:ax-12a,3:mx-64,4:xl430-w250", clock=VirtualClock())
    installed = faults.install(bus)
    assert installed.active(2) == ["vanished", "replies: drop 0.5, corrupt 0, delay 0"]
    assert installed.active(1)[0] == "stalled" and installed.active(3)[0] == "alarm 0x20"
    assert bus.bus1.servos_mx[1].alarms == OVERLOAD
