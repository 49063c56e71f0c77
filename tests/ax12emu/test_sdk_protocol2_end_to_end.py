"""Unmodified dynamixel-sdk with PacketHandler(2.0) drives a served bus of six XL430-W250s over a pty, as it drives hardware.

``ax12emu serve --servo xl430-w250 --ids 1-6`` runs as a real process; the client is the stock
SDK (only the port waits longer for replies: ``emu_testkit.PatientPortHandler``).
"""

from __future__ import annotations

import time
from contextlib import contextmanager

import pytest
from dynamixel_sdk import (
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupBulkRead,
    GroupBulkWrite,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
)
from emu_testkit import PatientPortHandler, UrlPortHandler, ok

from ax12emu.protocol.packets2 import ErrorNumber

IDS = list(range(1, 7))
#: The X series' factory baud: Baud Rate(8) = 1, 57,600 bps.
BAUD = 57600
XL430_MODEL_NUMBER = 1060
#: Addresses of the XL430-W250 table (e-manual).
TORQUE_ENABLE, LED, OPERATING_MODE, GOAL_POSITION, PRESENT_POSITION = 64, 65, 11, 116, 132

#: The wall-clock tier (real time, margins meant for one test at a time; CI runs it on its own) takes the
#: scenarios whose outcome hangs on how soon something happens: a broadcast Ping's replies within the
#: SDK's fixed window, motion against a deadline.  The rest start real processes but time nothing, so
#: they run in parallel with the other tests.
wallclock = pytest.mark.wallclock


@contextmanager
def sdk2(path: str):
    port = UrlPortHandler(path) if "://" in path else PatientPortHandler(path)
    port.baudrate = BAUD  # openPort opens at it: one open, not open-close-reopen (see emu_testkit.sdk_port)
    assert port.openPort(), f"could not open {path}"
    try:
        yield port, PacketHandler(2.0)
    finally:
        port.closePort()


@pytest.fixture
def xl430(emulator):
    """Six XL430-W250s on Protocol 2.0, served on a pty; the port path."""
    return emulator("--servo", "xl430-w250", "--ids", "1-6").port


def u32(value: int) -> list[int]:
    return list((value & 0xFFFFFFFF).to_bytes(4, "little"))


@wallclock
def test_ping_and_broadcast_ping_find_all_six(xl430):
    with sdk2(xl430) as (port, ph):
        for servo_id in IDS:
            assert ok(ph.ping(port, servo_id)) == XL430_MODEL_NUMBER
        assert ph.ping(port, 9)[1] == COMM_RX_TIMEOUT
        found, comm = ph.broadcastPing(port)
        assert comm == COMM_SUCCESS
        assert found == {servo_id: [XL430_MODEL_NUMBER, 45] for servo_id in IDS}  # model file: firmware_version 45


def test_one_two_and_four_byte_reads_and_writes(xl430):
    with sdk2(xl430) as (port, ph):
        assert ok(ph.read2ByteTxRx(port, 2, 0)) == XL430_MODEL_NUMBER
        assert ok(ph.read1ByteTxRx(port, 2, 7)) == 2
        assert ok(ph.read4ByteTxRx(port, 2, 44)) == 265  # Velocity Limit's default
        assert ph.write1ByteTxRx(port, 2, LED, 1) == (COMM_SUCCESS, 0)
        assert ok(ph.read1ByteTxRx(port, 2, LED)) == 1
        assert ph.write2ByteTxRx(port, 2, 84, 900) == (COMM_SUCCESS, 0)  # Position P Gain
        assert ok(ph.read2ByteTxRx(port, 2, 84)) == 900
        assert ph.write4ByteTxRx(port, 2, 112, 100) == (COMM_SUCCESS, 0)  # Profile Velocity
        assert ok(ph.read4ByteTxRx(port, 2, 112)) == 100
        assert ok(ph.read1ByteTxRx(port, 1, LED)) == 0  # the others untouched


def test_errors_reach_the_client_as_error_numbers(xl430):
    with sdk2(xl430) as (port, ph):
        assert ph.write4ByteTxRx(port, 3, GOAL_POSITION, 5000) == (COMM_SUCCESS, ErrorNumber.DATA_RANGE)
        assert ph.write2ByteTxRx(port, 3, GOAL_POSITION, 100) == (COMM_SUCCESS, ErrorNumber.DATA_LENGTH)
        assert ph.write1ByteTxRx(port, 3, 0, 1) == (COMM_SUCCESS, ErrorNumber.ACCESS)
        assert ph.write1ByteTxRx(port, 3, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 3, OPERATING_MODE, 1) == (COMM_SUCCESS, ErrorNumber.ACCESS)
        assert ph.write1ByteTxRx(port, 3, TORQUE_ENABLE, 0) == (COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 3, OPERATING_MODE, 1) == (COMM_SUCCESS, 0)


def test_group_sync_write_and_sync_read(xl430):
    with sdk2(xl430) as (port, ph):
        write = GroupSyncWrite(port, ph, 112, 4)  # Profile Velocity
        for servo_id in IDS:
            assert write.addParam(servo_id, u32(10 * servo_id))
        assert write.txPacket() == COMM_SUCCESS
        read = GroupSyncRead(port, ph, 112, 4)
        for servo_id in IDS:
            assert read.addParam(servo_id)
        assert read.txRxPacket() == COMM_SUCCESS
        assert [read.getData(servo_id, 112, 4) for servo_id in IDS] == [10 * servo_id for servo_id in IDS]
        assert read.fastSyncRead() == COMM_SUCCESS
        assert [read.getData(servo_id, 112, 4) for servo_id in IDS] == [10 * servo_id for servo_id in IDS]


def test_group_bulk_write_and_bulk_read(xl430):
    with sdk2(xl430) as (port, ph):
        write = GroupBulkWrite(port, ph)
        assert write.addParam(1, LED, 1, [1])
        assert write.addParam(4, 112, 4, u32(77))
        assert write.txPacket() == COMM_SUCCESS
        read = GroupBulkRead(port, ph)
        assert read.addParam(1, LED, 1)
        assert read.addParam(4, 112, 4)
        assert read.addParam(6, 0, 2)
        assert read.txRxPacket() == COMM_SUCCESS
        expected = [1, 77, XL430_MODEL_NUMBER]
        assert [read.getData(1, LED, 1), read.getData(4, 112, 4), read.getData(6, 0, 2)] == expected
        assert read.fastBulkRead() == COMM_SUCCESS
        assert [read.getData(1, LED, 1), read.getData(4, 112, 4), read.getData(6, 0, 2)] == expected


@wallclock
def test_a_goal_position_moves_present_position_toward_it(xl430):
    """Torque on and a goal 1000 pulses away: Present Position closes in within seconds of wall-clock time."""
    with sdk2(xl430) as (port, ph):
        start = ok(ph.read4ByteTxRx(port, 5, PRESENT_POSITION))
        goal = start + 1000
        assert ph.write1ByteTxRx(port, 5, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
        assert ph.write4ByteTxRx(port, 5, GOAL_POSITION, goal) == (COMM_SUCCESS, 0)
        positions = []
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:
            positions.append(ok(ph.read4ByteTxRx(port, 5, PRESENT_POSITION)))
            if abs(positions[-1] - goal) <= 20:
                break
            time.sleep(0.02)
        assert abs(positions[-1] - goal) <= 20, positions[-10:]
        assert any(start < p < goal - 20 for p in positions), "it passed through the positions between"
        assert ok(ph.read4ByteTxRx(port, 4, PRESENT_POSITION)) == start  # the others hold still


@wallclock
def test_a_mixed_bus_per_id(emulator):
    port_path = emulator("--servo", "1-2:xm430-w350,3:xl330-m077").port
    with sdk2(port_path) as (port, ph):
        found, comm = ph.broadcastPing(port)
        assert comm == COMM_SUCCESS
        assert {servo_id: info[0] for servo_id, info in found.items()} == {1: 1020, 2: 1020, 3: 1190}


def test_over_tcp_too(emulator):
    """The same bus behind TCP (socket:// through pyserial): ping, a sync read of all six."""
    url = emulator("--servo", "xl430-w250", "--ids", "1-6", "--tcp", "127.0.0.1:0").port
    assert url.startswith("socket://")
    with sdk2(url) as (port, ph):
        assert ok(ph.ping(port, 6)) == XL430_MODEL_NUMBER
        read = GroupSyncRead(port, ph, PRESENT_POSITION, 4)
        for servo_id in IDS:
            assert read.addParam(servo_id)
        assert read.txRxPacket() == COMM_SUCCESS
        assert [read.getData(servo_id, PRESENT_POSITION, 4) for servo_id in IDS] == [2048] * 6


def test_a_wire_mixing_ax12a_on_protocol_1_and_xl430_on_protocol_2(emulator):
    """One port, two packet handlers: each protocol finds its own servos, IDs 1 and 2 exist on both."""
    port_path = emulator("--servo", "1-2:ax-12a,1-3:xl430-w250", "--baud", "1000000").port
    with sdk2(port_path) as (port, ph2):
        assert port.setBaudRate(1_000_000)
        ph1 = PacketHandler(1.0)
        assert [ok(ph1.ping(port, servo_id)) for servo_id in (1, 2)] == [12, 12]
        assert ph1.ping(port, 3)[1] == COMM_RX_TIMEOUT
        assert [ok(ph2.ping(port, servo_id)) for servo_id in (1, 2, 3)] == [XL430_MODEL_NUMBER] * 3
        assert ok(ph1.read2ByteTxRx(port, 2, 36)) == 512  # the AX-12A's Present Position, mid-range
        assert ok(ph2.read4ByteTxRx(port, 2, PRESENT_POSITION)) == 2048
        assert ph1.write1ByteTxRx(port, 1, 25, 1) == (COMM_SUCCESS, 0)  # the AX-12A's LED
        assert ok(ph2.read1ByteTxRx(port, 1, LED)) == 0  # the XL430 with the same ID untouched


def test_state_dir_keeps_the_eeprom_between_runs(emulator, tmp_path):
    args = ("--servo", "xl430-w250", "--ids", "1-2", "--state-dir", str(tmp_path))
    first = emulator(*args)
    with sdk2(first.port) as (port, ph):
        assert ph.write1ByteTxRx(port, 2, 7, 12) == (COMM_SUCCESS, 0)  # ID 2 -> 12
        assert ph.write4ByteTxRx(port, 1, 20, 0xFFFFFF38) == (COMM_SUCCESS, 0)  # Homing Offset -200
    assert first.stop() == 0
    with sdk2(emulator(*args).port) as (port, ph):
        assert ok(ph.ping(port, 12)) == XL430_MODEL_NUMBER
        assert ok(ph.read4ByteTxRx(port, 1, 20)) == 0xFFFFFF38
    assert (tmp_path / "protocol2" / "servo-002.json").exists()
