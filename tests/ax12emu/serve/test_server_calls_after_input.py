"""A call made after a client wrote sees that write: the serving loop reads what is pending before running calls.

A packet with no reply (Sync Write, or any packet at Status Return Level 0) gives the client nothing to
wait for, so its next move, a ``VirtualBus`` call such as ``step()``, can come before the loop's next
read: the call must not overtake the bytes.  The client is unmodified dynamixel-sdk on the pty; a PING
before each Sync Write leaves the loop mid-conversation (spinning), the case where calls overtook writes.
"""

from __future__ import annotations

from dynamixel_sdk import COMM_SUCCESS, GroupSyncWrite, PacketHandler
from emu_testkit import PatientPortHandler

from ax12emu import VirtualBus

#: Rounds per test: about one in ten lost the race before the loop read pending input first (ours).
ROUNDS = 200


def _misses(bus: VirtualBus, protocol: float, baud: int, led_at: int) -> list[int]:
    """Each round: PING, a Sync Write of LED to IDs 1 and 2, a step at once, then the tables; the rounds that missed."""
    # Patient for the PING's reply (the SDK's own wait is a few ms, which a loaded machine can outlast): a late
    # reply is not what this counts.
    port = PatientPortHandler(bus.port)
    assert port.openPort() and port.setBaudRate(baud)
    handler = PacketHandler(protocol)
    misses = []
    try:
        for round_no in range(ROUNDS):
            value = (round_no + 1) % 2
            assert handler.ping(port, 1)[1] == COMM_SUCCESS
            write = GroupSyncWrite(port, handler, led_at, 1)
            for servo_id in (1, 2):
                write.addParam(servo_id, bytes([value]))
            assert write.txPacket() == COMM_SUCCESS
            bus.step(0.001)
            if [bus.read(servo_id, "led") for servo_id in (1, 2)] != [value, value]:
                misses.append(round_no)
    finally:
        port.closePort()
    return misses


def test_protocol2_sync_write_then_step_is_seen_every_time():
    with VirtualBus([1, 2], servo="xl430-w250", virtual_time=True, transport="pty") as bus:
        assert _misses(bus, 2.0, 57600, led_at=65) == []  # XL430-W250 LED(65)


def test_protocol1_sync_write_then_step_is_seen_every_time():
    with VirtualBus([1, 2], virtual_time=True, model="kinematic", transport="pty") as bus:
        assert _misses(bus, 1.0, 1_000_000, led_at=25) == []  # AX-12A LED(25)
