"""dynamixel-sdk drives the bus as it drives hardware: a real ``ax12emu serve`` over a pty or TCP, and in process.

The scenarios that do not depend on the way in run over all three
(``served_bus`` in conftest); the rest say what they need.
"""

from __future__ import annotations

import os
import re
import time

import pytest
from dynamixel_sdk import (
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupSyncWrite,
)
from emu_testkit import ok, sdk_port, wait_eeprom

from ax12emu.protocol.control_table import layout
from ax12emu.protocol.packets import StatusError

IDS = [1, 2, 5]
#: Registers the firmware computes, compared by rule rather than against a default.
DYNAMIC = {"present_position", "present_speed", "present_load", "present_voltage", "present_temperature", "goal_position"}


#: The wall-clock tier (real time, margins meant for one test at a time; CI runs it on its own) takes the
#: scenarios whose outcome hangs on how soon something happens: a partial-packet timeout, the Return
#: Delay Time, motion against a deadline, Moving read within one round trip, the EEPROM's deaf time.
#: The rest start real processes but time nothing (an expected silence is silence however loaded the
#: machine), so they run in parallel with the other tests.
wallclock = pytest.mark.wallclock


@pytest.fixture
def bus(served_bus):
    """A three-servo bus behind each way in (pty, TCP, in process)."""
    return served_bus(IDS)


def test_ping_every_id_reports_model_12(bus):
    """Every configured ID answers PING and reads model number 12; an absent ID times out."""
    with sdk_port(bus.port) as (port, ph):
        for servo_id in IDS:
            assert ok(ph.ping(port, servo_id)) == 12
        _, comm, _ = ph.ping(port, 3)
        assert comm == COMM_RX_TIMEOUT


def test_read_every_address_matches_ax12_defaults(bus):
    """Reading 0..49 byte by byte and in one block gives the e-manual's defaults."""
    lay = layout("ax12a")
    with sdk_port(bus.port) as (port, ph):
        table = bytes(ok(ph.readTxRx(port, 1, 0, 50)))
        single = bytes(ok(ph.read1ByteTxRx(port, 1, address)) for address in range(50))
    assert len(table) == 50
    for entry in lay.entries:
        value = int.from_bytes(table[entry.address : entry.end], "little")
        if entry.name not in DYNAMIC:
            assert value == entry.default, entry.name
    present = int.from_bytes(table[36:38], "little")
    assert int.from_bytes(table[30:32], "little") == present, "Goal Position starts at Present Position"
    assert table[42] == 96 and table[43] > 0
    # Byte-by-byte reads agree with the block read wherever the firmware does not move values.
    for address in range(50):
        if lay.owner[address] < 0 or lay.entries[lay.owner[address]].name not in DYNAMIC:
            assert single[address] == table[address], address


def test_write_and_read_back_one_and_two_byte_values(bus):
    """1- and 2-byte writes read back; a 2-byte register can also be written byte by byte."""
    with sdk_port(bus.port) as (port, ph):
        assert ph.write1ByteTxRx(port, 2, 25, 1) == (COMM_SUCCESS, 0)
        assert ok(ph.read1ByteTxRx(port, 2, 25)) == 1
        comm, error = ph.write2ByteTxRx(port, 2, 32, 300)
        assert (comm, error) == (COMM_SUCCESS, 0)
        assert ok(ph.read2ByteTxRx(port, 2, 32)) == 300
        comm, error = ph.write1ByteTxRx(port, 2, 34, 0x34)  # low byte of Torque Limit
        comm2, error2 = ph.write1ByteTxRx(port, 2, 35, 0x01)  # high byte
        assert (comm, error, comm2, error2) == (COMM_SUCCESS, 0, COMM_SUCCESS, 0)
        assert ok(ph.read2ByteTxRx(port, 2, 34)) == 0x134


def test_group_sync_write_reaches_several_ids(bus):
    """GroupSyncWrite sets Moving Speed on three servos in one broadcast packet."""
    with sdk_port(bus.port) as (port, ph):
        group = GroupSyncWrite(port, ph, 32, 2)
        for servo_id in IDS:
            assert group.addParam(servo_id, [servo_id * 10, 1])
        assert group.txPacket() == COMM_SUCCESS
        for servo_id in IDS:
            assert ok(ph.read2ByteTxRx(port, servo_id, 32)) == 256 + servo_id * 10


def test_reg_write_waits_for_action(bus):
    """REG_WRITE sets Registered and changes nothing until ACTION; ACTION applies and clears it."""
    with sdk_port(bus.port) as (port, ph):
        comm, error = ph.regWriteTxRx(port, 1, 32, 2, [0x00, 0x02])
        assert (comm, error) == (COMM_SUCCESS, 0)
        assert ok(ph.read1ByteTxRx(port, 1, 44)) == 1
        assert ok(ph.read2ByteTxRx(port, 1, 32)) == 0
        assert ph.action(port, 1) == COMM_SUCCESS
        assert ok(ph.read2ByteTxRx(port, 1, 32)) == 0x200
        assert ok(ph.read1ByteTxRx(port, 1, 44)) == 0


def test_action_without_reg_write_is_an_instruction_error(bus):
    """ACTION with nothing registered answers with the Instruction Error bit (e-manual)."""
    with sdk_port(bus.port) as (port, ph):
        _, comm, error = ph.txRxPacket(port, [0, 0, 1, 2, 0x05, 0])
        assert comm == COMM_SUCCESS and error == StatusError.INSTRUCTION


@wallclock  # unanswered EEPROM writes: only the 10 ms pause keeps the next packet out of the deaf time
def test_status_return_levels(bus):
    """Level 0 answers only PING; level 1 answers PING and READ; level 2 everything."""
    with sdk_port(bus.port) as (port, ph):
        ph.write1ByteTxOnly(port, 1, 16, 0)
        time.sleep(0.01)
        _, comm, _ = ph.ping(port, 1)
        assert comm == COMM_RX_TIMEOUT  # sdk's ping also READs the model number: not answered at level 0
        _, comm, _ = ph.txRxPacket(port, [0, 0, 1, 2, 0x01, 0])
        assert comm == COMM_SUCCESS  # a bare PING is always answered
        _, comm, _ = ph.read1ByteTxRx(port, 1, 16)
        assert comm == COMM_RX_TIMEOUT
        ph.write1ByteTxOnly(port, 1, 16, 1)
        time.sleep(0.01)
        assert ok(ph.read1ByteTxRx(port, 1, 16)) == 1
        comm, _ = ph.write1ByteTxRx(port, 1, 25, 1)
        assert comm == COMM_RX_TIMEOUT
        assert ok(ph.read1ByteTxRx(port, 1, 25)) == 1, "the unanswered write was still executed"
        ph.write1ByteTxOnly(port, 1, 16, 2)
        time.sleep(0.01)
        assert ph.write1ByteTxRx(port, 1, 25, 0) == (COMM_SUCCESS, 0)


def test_broadcast_write_acts_on_all_and_answers_none(bus):
    """A WRITE to ID 0xFE changes every servo and produces no status packet."""
    with sdk_port(bus.port) as (port, ph):
        assert ph.write1ByteTxOnly(port, 0xFE, 25, 1) == COMM_SUCCESS
        time.sleep(0.01)
        assert port.getBytesAvailable() == 0
        for servo_id in IDS:
            assert ok(ph.read1ByteTxRx(port, servo_id, 25)) == 1


def test_reset_restores_factory_defaults_and_answers_from_old_id(bus):
    """RESET of ID 5 answers as ID 5 (e-manual example), then the servo is ID 1 at defaults."""
    with sdk_port(bus.port) as (port, ph):
        ph.write1ByteTxRx(port, 1, 3, 7)  # move servo 1 out of the way first
        assert ph.write1ByteTxRx(port, 5, 5, 10) == (COMM_SUCCESS, 0)
        wait_eeprom()
        assert ph.factoryReset(port, 5) == (COMM_SUCCESS, 0)
        _, comm, _ = ph.ping(port, 5)
        assert comm == COMM_RX_TIMEOUT
        assert ok(ph.read1ByteTxRx(port, 1, 5)) == 250
        assert ok(ph.ping(port, 7)) == 12


def test_id_change_moves_servo_at_once(bus):
    """Writing the ID is answered from the old ID, then only the new ID answers."""
    with sdk_port(bus.port) as (port, ph):
        assert ph.write1ByteTxRx(port, 2, 3, 9) == (COMM_SUCCESS, 0)
        _, comm, _ = ph.ping(port, 2)
        assert comm == COMM_RX_TIMEOUT
        assert ok(ph.ping(port, 9)) == 12
        assert ok(ph.read1ByteTxRx(port, 9, 3)) == 9


def test_error_bits_for_angle_limit_range_and_instruction(bus):
    """Goal outside the angle limits, an out-of-range value, a read-only write and BULK_READ set their bits."""
    with sdk_port(bus.port) as (port, ph):
        assert ph.write2ByteTxRx(port, 1, 8, 600) == (COMM_SUCCESS, 0)  # CCW limit 600
        wait_eeprom(2)
        comm, error = ph.write2ByteTxRx(port, 1, 30, 700)
        assert comm == COMM_SUCCESS and error == StatusError.ANGLE_LIMIT
        assert ok(ph.read2ByteTxRx(port, 1, 30)) != 700, "a rejected write changes nothing"
        assert ph.write1ByteTxRx(port, 1, 24, 2) == (COMM_SUCCESS, StatusError.RANGE)
        assert ph.write2ByteTxRx(port, 1, 36, 5) == (COMM_SUCCESS, StatusError.RANGE)
        _, comm, error = ph.txRxPacket(port, [0, 0, 1, 3, 0x92, 0x00, 0])
        assert comm == COMM_SUCCESS and error == StatusError.INSTRUCTION


def test_erroring_read_still_returns_its_bytes(bus):
    """A READ past the table sets RANGE but carries the requested bytes, so read2ByteTxRx does not crash."""
    with sdk_port(bus.port) as (port, ph):
        value, comm, error = ph.read2ByteTxRx(port, 1, 49)
        assert comm == COMM_SUCCESS and error == StatusError.RANGE
        assert value == 0  # byte 49 (Punch high) is 0, byte 50 is past the table


@wallclock
def test_garbage_and_truncated_packets_then_ping(bus):
    """After random garbage, repeated 0xFF and a truncated packet, a valid PING is answered."""
    with sdk_port(bus.port) as (port, ph):
        port.writePort(bytes(range(0, 0xFE, 7)) + b"\xff\xff\xff\xff\x01\x04\x02")  # ends mid-packet
        time.sleep(0.1)  # longer than the firmware's partial-packet timeout
        assert ok(ph.ping(port, 1)) == 12
        port.writePort(b"\xff\xff\x01\x00\x00")  # impossible LENGTH: resync at once
        assert ok(ph.ping(port, 2)) == 12
        port.writePort(b"\xff\xff\x01\x02\x01\x00")  # bad checksum: answered with the Checksum bit
        time.sleep(0.01)
        rx, comm = ph.rxPacket(port)
        assert comm == COMM_SUCCESS and rx[4] == StatusError.CHECKSUM
        assert ok(ph.ping(port, 5)) == 12


def test_client_closes_and_reopens_the_port(bus):
    """Closing the port (as setBaudRate does) and reopening it leaves the bus talking."""
    for _ in range(3):
        with sdk_port(bus.port) as (port, ph):
            assert ok(ph.ping(port, 1)) == 12
            assert port.setBaudRate(1_000_000)  # closes and reopens inside
            assert ok(ph.ping(port, 2)) == 12


def test_baud_change_makes_servo_deaf_until_host_follows(bus):
    """After Baud Rate 34 (57,142 bps) the servo ignores 1 Mbps traffic and answers at 57,600."""
    if not bus.kind.carries_baud:
        pytest.skip(f"{bus.kind.name} carries no line rate: a servo at another baud still hears the host")
    with sdk_port(bus.port) as (port, ph):
        assert ph.write1ByteTxRx(port, 1, 4, 34) == (COMM_SUCCESS, 0)
        _, comm, _ = ph.ping(port, 1)
        assert comm == COMM_RX_TIMEOUT
        assert ok(ph.ping(port, 2)) == 12
        assert port.setBaudRate(57600)
        assert ok(ph.ping(port, 1)) == 12
        _, comm, _ = ph.ping(port, 2)
        assert comm == COMM_RX_TIMEOUT


@wallclock
def test_return_delay_time_is_honoured(bus):
    """Return Delay Time 250 (500 us): no PING round trip is shorter than the delay, and 0 is much faster."""
    def fastest_ping_s(port, ph, count=20):
        """The fastest of ``count`` round trips: load on a shared machine only ever adds time."""
        times = []
        for _ in range(count):
            start = time.perf_counter()
            _, comm, _ = ph.txRxPacket(port, [0, 0, 1, 2, 0x01, 0])
            times.append(time.perf_counter() - start)
            assert comm == COMM_SUCCESS
        return min(times)

    fast = slow = 1.0
    with sdk_port(bus.port) as (port, ph):
        for _ in range(5):  # alternating blocks: a spell of load weighs on both settings alike
            ph.write1ByteTxRx(port, 1, 5, 0)
            wait_eeprom()
            fast = min(fast, fastest_ping_s(port, ph))
            ph.write1ByteTxRx(port, 1, 5, 250)
            wait_eeprom()
            slow = min(slow, fastest_ping_s(port, ph))
    # No round trip is shorter than the delay; and the fastest ones differ by the delay less what
    # hides inside it (it runs from the packet's arrival, so the emulator's own processing and
    # part of the transport overlap it): under load the fastest undelayed round trip took 0.22 ms
    # and the delayed one 0.51 ms, 0.29 ms apart.  Both bounds on the difference are wide: a
    # loaded machine can delay even the fastest of 100 round trips (a 0.8 ms upper bound failed
    # once that way); the precise figure is tools/bench_protocol.py's.
    assert slow >= 0.0005, (fast, slow)
    assert 0.0002 < slow - fast < 0.002, (fast, slow)


def test_sigterm_removes_link_and_exits_cleanly(emulator, tmp_path):
    """SIGTERM stops the server with exit status 0 and removes the --link symlink."""
    link = tmp_path / "ax12"
    served = emulator("--link", str(link))
    assert os.path.islink(link) and os.readlink(link) == served.port
    with sdk_port(str(link)) as (port, ph):
        assert ok(ph.ping(port, 1)) == 12
    assert served.stop() == 0
    assert not os.path.lexists(link)


def test_state_dir_persists_id_and_limits_over_restart(emulator, tmp_path):
    """An ID and an angle limit written by a client survive a restart with --state-dir."""
    state = tmp_path / "state"
    first = emulator("--ids", "1", "--state-dir", str(state))
    with sdk_port(first.port) as (port, ph):
        assert ph.write2ByteTxRx(port, 1, 8, 800) == (COMM_SUCCESS, 0)
        wait_eeprom(2)
        assert ph.write1ByteTxRx(port, 1, 3, 4) == (COMM_SUCCESS, 0)
    assert first.stop() == 0
    second = emulator("--ids", "1", "--state-dir", str(state))
    with sdk_port(second.port) as (port, ph):
        assert ok(ph.ping(port, 4)) == 12
        assert ok(ph.read2ByteTxRx(port, 4, 8)) == 800
    assert second.stop() == 0
    third = emulator("--ids", "1", "--state-dir", str(state), "--factory-reset")
    with sdk_port(third.port) as (port, ph):
        assert ok(ph.ping(port, 1)) == 12


@wallclock
def test_moving_servo_reaches_goal(bus):
    """With torque on, Present Position moves to Goal Position and Moving drops back to 0.

    The physical model stops within a few units of the goal, as a real AX-12 does with its
    default compliance (margin 1, slope 32) against static friction.
    """
    with sdk_port(bus.port) as (port, ph):
        ph.write1ByteTxRx(port, 1, 24, 1)
        start = ok(ph.read2ByteTxRx(port, 1, 36))
        ph.write2ByteTxRx(port, 1, 30, 800)
        time.sleep(0.02)
        assert ok(ph.read1ByteTxRx(port, 1, 46)) == 1
        deadline = time.monotonic() + 3.0
        while ok(ph.read1ByteTxRx(port, 1, 46)) and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.3)
        final = ok(ph.read2ByteTxRx(port, 1, 36))
        assert abs(final - 800) <= 4 and start < 700, (start, final)
        assert ok(ph.read1ByteTxRx(port, 1, 46)) == 0


@wallclock
def test_moving_reads_1_on_the_first_read_after_a_goal(bus):
    """Write a goal, then poll Moving at once: the first read already says 1, every time.

    A real servo's 1 ms control loop has run before a host's next packet can
    arrive over USB, so "write the goal, poll Moving until 0" must not end at
    once.  Alternating between two goals far apart (beyond the compliance
    margin), twenty times, with no pause between the write and the read.
    """
    with sdk_port(bus.port) as (port, ph):
        assert ph.write1ByteTxRx(port, 1, 24, 1) == (COMM_SUCCESS, 0)
        first_reads = []
        for k in range(20):
            assert ph.write2ByteTxRx(port, 1, 30, 300 if k % 2 else 700) == (COMM_SUCCESS, 0)
            first_reads.append(ok(ph.read1ByteTxRx(port, 1, 46)))
        assert first_reads == [1] * 20


@wallclock
@pytest.mark.parametrize("flags", [(), ("--goal-torque", "unchanged", "--eeprom-busy-ms", "0")], ids=["default", "off"])
def test_firmware_quirks_through_the_flags(emulator, flags):
    """By default a goal turns torque on and an EEPROM write leaves the servo deaf a while; the flags turn both off.

    The deaf time is set long here (300 ms per byte) so that the PING just
    after the write cannot miss it on a loaded machine; the default is 6 ms.
    """
    default = not flags
    served = emulator("--ids", "1", *(flags or ("--eeprom-busy-ms", "300")))
    with sdk_port(served.port) as (port, ph):
        assert ph.write2ByteTxRx(port, 1, 30, 600) == (COMM_SUCCESS, 0)
        assert ok(ph.read1ByteTxRx(port, 1, 24)) == (1 if default else 0)
        assert ph.write1ByteTxRx(port, 1, 5, 0) == (COMM_SUCCESS, 0)  # Return Delay Time: EEPROM
        _, comm, _ = ph.ping(port, 1)
        assert comm == (COMM_RX_TIMEOUT if default else COMM_SUCCESS)
        time.sleep(0.35)
        assert ok(ph.ping(port, 1)) == 12


def test_verbose_logs_every_packet_with_timestamps(emulator):
    """-v logs each decoded packet on one timestamped line, with register names."""
    served = emulator("-v", "--ids", "1")
    with sdk_port(served.port) as (port, ph):
        assert ph.write2ByteTxRx(port, 1, 30, 600) == (COMM_SUCCESS, 0)
        assert ok(ph.read1ByteTxRx(port, 1, 43)) > 0
    assert served.stop() == 0
    log = served.process.stderr.read()
    assert re.search(r"^\d\d:\d\d:\d\d\.\d{3} .*rx WRITE id=1 goal_position=600", log, re.M), log
    assert re.search(r"rx READ id=1 address=43 length=1 \(present_temperature\)", log), log
