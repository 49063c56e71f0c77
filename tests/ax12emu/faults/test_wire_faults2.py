"""The wire's faults on a Protocol 2.0 bus (Faults2): what unmodified dynamixel-sdk PacketHandler(2.0) sees.

A client sees COMM_RX_TIMEOUT for a dropped status or an unplugged servo, COMM_RX_CORRUPT for a
wrong CRC, and a late reply after its timeout (duplicate IDs and the faults of a servo's own are
test_faults2.py's).
"""

from __future__ import annotations

import pytest
import serial
from dynamixel_sdk import COMM_RX_CORRUPT, COMM_RX_TIMEOUT, COMM_SUCCESS, GroupSyncRead, PacketHandler
from emu_testkit import UrlPortHandler, ok

import ax12emu  # noqa: F401  (registers the URL handler)
from ax12emu import FaultConfig, VirtualBus
from ax12emu.faults import Faults2
from ax12emu.protocol.packets2 import Instruction2, encode_instruction2

BAUD = 57600
XL430 = 1060
LED, PRESENT_POSITION = 65, 132


def sdk2(url: str) -> tuple[UrlPortHandler, PacketHandler]:
    port = UrlPortHandler(url)
    assert port.openPort() and port.setBaudRate(BAUD)
    return port, PacketHandler(2.0)


@pytest.fixture
def xl430():
    with VirtualBus([1, 2, 3], servo="xl430-w250", transport="inprocess") as bus:
        port, ph = sdk2(bus.port)
        try:
            yield bus, port, ph
        finally:
            port.closePort()


def test_dropped_replies_time_out_but_the_write_is_done(xl430):
    bus, port, ph = xl430
    bus.faults.set_reply_faults(drop=1.0, ids=[2])
    assert isinstance(bus.call(lambda b: b.faults), Faults2)
    assert ph.write1ByteTxRx(port, 2, LED, 1)[0] == COMM_RX_TIMEOUT
    assert bus.read(2, "led") == 1
    assert ok(ph.ping(port, 1)) == XL430  # another ID untouched
    assert bus.faults.dropped == 1
    bus.faults.clear()
    assert ok(ph.ping(port, 2)) == XL430


def test_corrupt_replies_fail_the_crc(xl430):
    bus, port, ph = xl430
    bus.faults.set_reply_faults(corrupt=1.0)
    assert ph.ping(port, 3)[1] == COMM_RX_CORRUPT
    assert ph.read4ByteTxRx(port, 1, PRESENT_POSITION)[1] == COMM_RX_CORRUPT
    assert bus.faults.corrupted == 2


def test_a_vanished_servo_hears_nothing_and_breaks_a_sync_read_chain(xl430):
    bus, port, ph = xl430
    bus.faults.vanish(2)
    assert ph.ping(port, 2)[1] == COMM_RX_TIMEOUT
    assert ph.write1ByteTxRx(port, 2, LED, 1)[0] == COMM_RX_TIMEOUT
    assert bus.read(2, "led") == 0  # not heard, so not done
    found, comm = ph.broadcastPing(port)
    assert comm == COMM_SUCCESS and sorted(found) == [1, 3]
    read = GroupSyncRead(port, ph, PRESENT_POSITION, 4)
    for servo_id in (1, 2, 3):
        read.addParam(servo_id)
    assert read.txRxPacket() != COMM_SUCCESS
    assert bus.faults.active(2) == ["vanished"]
    bus.faults.reappear(2)
    assert read.txRxPacket() == COMM_SUCCESS


def test_a_delayed_reply_arrives_after_the_timeout():
    """delay_s past the port's timeout: the read comes back empty, the status arrives later, whole."""
    config = FaultConfig(delay=1.0, delay_s=0.3)
    with VirtualBus([1], servo="xl430-w250", transport="inprocess", faults=config) as bus:
        with serial.serial_for_url(bus.port, baudrate=BAUD, timeout=0.05) as link:
            link.write(encode_instruction2(1, Instruction2.PING))
            assert link.read(14) == b""
            link.timeout = 1.0
            assert len(link.read(14)) == 14
        assert bus.faults.delayed == 1


def test_the_same_seed_drops_the_same_replies():
    def run() -> list[int]:
        with VirtualBus([1], servo="xl430-w250", transport="inprocess", faults=FaultConfig(drop=0.5, seed=7)) as bus:
            with serial.serial_for_url(bus.port, baudrate=BAUD, timeout=0.02) as link:
                lengths = []
                for _ in range(12):
                    link.write(encode_instruction2(1, Instruction2.PING))
                    lengths.append(len(link.read(14)))
                return lengths

    first = run()
    assert first == run() and 0 in first and 14 in first


def test_unknown_slots_are_refused_by_name():
    with VirtualBus([1, 2], servo="xl430-w250", transport="inprocess") as bus:
        with pytest.raises(ValueError, match="no servo launched as ID 5"):
            bus.faults.vanish(5)


def test_url_fault_options_apply_to_a_2_0_bus():
    with serial.serial_for_url("ax12emu://?servo=1-2:xl430-w250&drop=1&fault_ids=2", baudrate=BAUD, timeout=0.05) as link:
        link.write(encode_instruction2(2, Instruction2.PING))
        assert link.read(14) == b""
        link.write(encode_instruction2(1, Instruction2.PING))
        assert len(link.read(14)) == 14


def test_a_fast_sync_read_is_lost_corrupted_or_delayed_whole():
    """Its answer is one status packet the servos build share by share: a fault took single shares, so the host got
    a headerless tail or a packet with a share cut out; a fault on one ID missed the packet it shares in."""
    with VirtualBus([1, 2, 3], servo="xl430-w250", transport="inprocess", virtual_time=True) as bus:
        port, ph = sdk2(bus.port)
        try:
            read = GroupSyncRead(port, ph, PRESENT_POSITION, 4)
            for servo_id in (1, 2, 3):
                read.addParam(servo_id)
            bus.faults.set_reply_faults(drop=1.0, ids=[2])
            assert read.fastSyncRead() == COMM_RX_TIMEOUT
            bus.faults.set_reply_faults(corrupt=1.0, ids=[3])
            assert read.fastSyncRead() == COMM_RX_CORRUPT
            bus.faults.set_reply_faults(drop=0.5)
            results = [read.fastSyncRead() for _ in range(40)]
            assert set(results) == {COMM_SUCCESS, COMM_RX_TIMEOUT}  # all or nothing, never a broken packet
            assert bus.faults.dropped == 1 + results.count(COMM_RX_TIMEOUT)  # one per packet, not per share
        finally:
            port.closePort()


def test_a_mixed_wires_two_protocols_lose_replies_independently():
    """Both protocols' reply faults drew from two generators of one seed: a 1.0 and a 2.0 reply were always lost
    together, never one of them (the case robot code most needs to survive)."""
    with VirtualBus(servo="1:ax-12a,2:xl430-w250", baud_bps=1_000_000, transport="inprocess",
                    faults=FaultConfig(drop=0.5, seed=3)) as bus:
        port = UrlPortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(1_000_000)
        try:
            p1, p2 = PacketHandler(1.0), PacketHandler(2.0)
            one_lost = 0
            for _ in range(40):
                lost1 = p1.read1ByteTxRx(port, 1, 3)[1] != COMM_SUCCESS
                lost2 = p2.read1ByteTxRx(port, 2, 7)[1] != COMM_SUCCESS
                one_lost += lost1 != lost2
            assert one_lost >= 5, one_lost  # independent draws: about half of 40
        finally:
            port.closePort()
