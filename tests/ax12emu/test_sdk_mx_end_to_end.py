"""Unmodified dynamixel-sdk with PacketHandler(1.0) drives served MX-series servos (Protocol 1.0 firmware) over a pty.

``ax12emu serve --servo ...`` runs as a real process (stopped by pid by the ``emulator`` fixture); the
client is the stock SDK (only the port waits longer for replies: ``emu_testkit.PatientPortHandler``).
None of these scenarios times anything, so they run in parallel with the other tests.
"""

from __future__ import annotations

import time

from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, GroupBulkRead, GroupSyncWrite, PacketHandler
from emu_testkit import ok, sdk_port

from ax12emu.protocol.packets import StatusError

#: The MX's factory Baud Rate(4) 34: 2,000,000 / 35 = 57,143 bps, which a 57,600 bps host hears.
BAUD = 57600
MODEL_NUMBERS = {"mx-28": 29, "mx-64": 310, "mx-106": 320}
#: Addresses of the MX tables (e-manual, MX-28 Protocol 1.0).
CW_LIMIT, CCW_LIMIT, TORQUE_ENABLE, LED, P_GAIN, GOAL_POSITION, MOVING_SPEED = 6, 8, 24, 25, 28, 30, 32
PRESENT_POSITION, REGISTERED, MOVING = 36, 44, 46


def test_ping_read_write_and_errors_on_four_mx28(emulator):
    port_path = emulator("--servo", "mx-28", "--ids", "1-4").port
    with sdk_port(port_path, BAUD) as (port, ph):
        assert [ok(ph.ping(port, servo_id)) for servo_id in (1, 2, 3, 4)] == [29] * 4
        assert ph.ping(port, 5)[1] == COMM_RX_TIMEOUT
        assert ok(ph.read2ByteTxRx(port, 1, PRESENT_POSITION)) == 2048  # the middle of the turn
        assert ok(ph.read1ByteTxRx(port, 1, P_GAIN)) == 32
        assert ph.write1ByteTxRx(port, 2, LED, 1) == (COMM_SUCCESS, 0)
        assert ok(ph.read1ByteTxRx(port, 2, LED)) == 1
        assert ok(ph.read1ByteTxRx(port, 1, LED)) == 0
        # Protocol 1.0 reports errors as bits: Range for a value out of range, Angle Limit for a goal outside CW..CCW.
        assert ph.write1ByteTxRx(port, 1, P_GAIN, 255) == (COMM_SUCCESS, StatusError.RANGE)
        assert ph.write2ByteTxRx(port, 1, CW_LIMIT, 1000) == (COMM_SUCCESS, 0)
        assert ph.write2ByteTxRx(port, 1, GOAL_POSITION, 500) == (COMM_SUCCESS, StatusError.ANGLE_LIMIT)
        assert ok(ph.read2ByteTxRx(port, 1, GOAL_POSITION)) == 2048  # nothing written
        assert ph.write1ByteTxRx(port, 1, 2, 7)[1] == StatusError.RANGE  # Firmware Version is read-only
        assert ph.readTxRx(port, 1, 70, 10)[2] == StatusError.RANGE  # past the 74-byte table


def test_sync_write_moves_two_and_bulk_read_reads_both(emulator):
    port_path = emulator("--servo", "1:mx-28,2:mx-64,3:mx-106").port
    with sdk_port(port_path, BAUD) as (port, ph):
        assert [ok(ph.ping(port, servo_id)) for servo_id in (1, 2, 3)] == [29, 310, 320]
        sync = GroupSyncWrite(port, ph, GOAL_POSITION, 4)
        for servo_id, goal in ((1, 2248), (2, 1848)):
            assert sync.addParam(servo_id, [goal & 0xFF, goal >> 8, 0, 0])  # goal, Moving Speed 0 (no limit)
        assert sync.txPacket() == COMM_SUCCESS
        bulk = GroupBulkRead(port, ph)
        assert bulk.addParam(1, PRESENT_POSITION, 2)
        assert bulk.addParam(2, GOAL_POSITION, 2)
        assert bulk.addParam(3, 0, 2)
        # dynamixel-sdk 4.1.0's GroupBulkRead.txPacket passes Protocol 2.0's "fast" flag to Protocol 1.0's
        # bulkReadTx(port, param, param_length), a TypeError: the packet goes out through the handler itself.
        bulk.makeParam()
        deadline = time.monotonic() + 10.0
        while True:
            assert ph.bulkReadTx(port, bulk.param, 3 * 3) == COMM_SUCCESS
            assert bulk.rxPacket() == COMM_SUCCESS
            if abs(bulk.getData(1, PRESENT_POSITION, 2) - 2248) <= 10 or time.monotonic() > deadline:
                break
        assert abs(bulk.getData(1, PRESENT_POSITION, 2) - 2248) <= 10
        assert bulk.getData(2, GOAL_POSITION, 2) == 1848
        assert bulk.getData(3, 0, 2) == 320  # Model Number
        assert ok(ph.read1ByteTxRx(port, 2, TORQUE_ENABLE)) == 1  # a Goal Position write turned the torque on


def test_reg_write_action_and_reset(emulator):
    port_path = emulator("--servo", "mx-64", "--ids", "2-3").port
    with sdk_port(port_path, BAUD) as (port, ph):
        assert ph.regWriteTxRx(port, 2, LED, 1, [1]) == (COMM_SUCCESS, 0)
        assert ok(ph.read1ByteTxRx(port, 2, REGISTERED)) == 1
        assert ok(ph.read1ByteTxRx(port, 2, LED)) == 0
        assert ph.action(port, 2) == COMM_SUCCESS
        assert ok(ph.read1ByteTxRx(port, 2, LED)) == 1
        assert ok(ph.read1ByteTxRx(port, 2, REGISTERED)) == 0
        assert ph.write1ByteTxRx(port, 3, P_GAIN, 50) == (COMM_SUCCESS, 0)
        assert ph.factoryReset(port, 3) == (COMM_SUCCESS, 0)  # answered from ID 3, then the factory table: ID 1
        assert ph.ping(port, 3)[1] == COMM_RX_TIMEOUT
        assert ok(ph.ping(port, 1)) == 310
        assert ok(ph.read1ByteTxRx(port, 1, P_GAIN)) == 32
        assert ok(ph.read1ByteTxRx(port, 2, LED)) == 1  # the other servo untouched


def test_a_wire_of_ax12a_mx64_and_xl430_on_both_protocols(emulator):
    port_path = emulator("--servo", "1-2:ax-12a,3:mx-64,4:xl430-w250", "--baud", "1000000").port
    with sdk_port(port_path, 1_000_000) as (port, ph1):
        ph2 = PacketHandler(2.0)
        assert [ok(ph1.ping(port, servo_id)) for servo_id in (1, 2, 3)] == [12, 12, 310]
        assert ph1.ping(port, 4)[1] == COMM_RX_TIMEOUT
        assert ok(ph2.ping(port, 4)) == 1060
        assert ok(ph1.read2ByteTxRx(port, 3, PRESENT_POSITION)) == 2048
        assert ok(ph1.read2ByteTxRx(port, 1, PRESENT_POSITION)) == 512
        assert ph1.write1ByteTxRx(port, 3, LED, 1) == (COMM_SUCCESS, 0)
        assert ok(ph1.read1ByteTxRx(port, 3, LED)) == 1
        assert ok(ph1.read1ByteTxRx(port, 1, LED)) == 0
