"""A Sync/Bulk Read's answers remembered by ``Bus2._listed`` are never stale.

The bus hands out the answers it made for the same read while the bytes they came from (those read, and the
registers that decide whether and how each servo answers) are the same.  Here a step, a write, a torque
change, a changed ID, Status Return Level or Return Delay Time, a hardware error and a fault between two
identical reads must each change the answer exactly as a bus that remembers nothing would, and a long mixed
stream must answer byte for byte as such a bus does.
"""

from __future__ import annotations

import random

import pytest
from emu_testkit import Packets2, u32

from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock
from ax12emu.faults.injection import Faults2
from ax12emu.protocol.servo_models import model
from ax12emu.servo.model_factory2 import build_x_firmware
from firmware_model.xseries.interface import HW_ERROR_OVERHEATING

IDS = (1, 2, 3, 4, 5, 6)
#: X-series addresses (e-manual, XL430-W250 control table).
ID, RETURN_DELAY_TIME, STATUS_RETURN_LEVEL, TORQUE_ENABLE = 7, 9, 68, 64
PROFILE_VELOCITY, GOAL_POSITION, PRESENT_POSITION = 112, 116, 132
#: The packets a host sends these servos.
_PACKETS = Packets2(IDS)
sync_write = _PACKETS.sync_write
sync_read = _PACKETS.sync_read
fast_sync_read = _PACKETS.fast_sync_read
bulk_read = _PACKETS.bulk_read
write = _PACKETS.write


def new_bus(defer: bool = False) -> Bus2:
    bus = Bus2([(servo_id, model("xl430-w250")) for servo_id in IDS], lambda spec, index: build_x_firmware(spec),
               clock=VirtualClock(1.0))
    bus.request_lag_s = 0.001  # as the serving loop sets it
    bus.defer_settling = defer
    for servo_id in IDS:
        bus.receive(write(servo_id, RETURN_DELAY_TIME, b"\x00"))
        bus.receive(write(servo_id, PROFILE_VELOCITY, u32(50)))
        bus.receive(write(servo_id, TORQUE_ENABLE, b"\x01"))
    return bus


def wire(replies) -> list[tuple[int, bytes, float]]:
    return [(reply.servo_id, reply.data, reply.delay_s) for reply in replies]


def fresh(bus: Bus2, data: bytes) -> list[tuple[int, bytes, float]]:
    """What ``bus`` answers ``data`` with nothing remembered (``data`` must be a read with no effect but answers)."""
    bus._listed_answers.clear()
    return wire(bus.receive(data))


def positions(replies) -> list[int]:
    return [int.from_bytes(reply.data[9:13], "little", signed=True) for reply in replies]


def test_a_step_between_two_identical_sync_reads_shows_in_the_second():
    bus = new_bus()
    bus.receive(sync_write(GOAL_POSITION, {servo_id: u32(3000) for servo_id in IDS}))
    first = bus.receive(sync_read(PRESENT_POSITION, 4))
    assert wire(bus.receive(sync_read(PRESENT_POSITION, 4))) == wire(first)  # nothing changed: the same answer
    bus.clock.advance(0.02)
    second = bus.receive(sync_read(PRESENT_POSITION, 4))
    assert positions(second) != positions(first)  # the servos moved
    assert positions(second) == [servo.table.get("present_position") for servo in bus.servos]
    assert wire(second) == fresh(bus, sync_read(PRESENT_POSITION, 4))


@pytest.mark.parametrize("read", [sync_read(GOAL_POSITION, 4), fast_sync_read(GOAL_POSITION, 4),
                                  bulk_read([(3, GOAL_POSITION, 4), (1, GOAL_POSITION, 4)])])
def test_a_write_between_two_identical_reads_shows_in_the_second(read):
    bus = new_bus(defer=True)
    first = wire(bus.receive(read))
    bus.receive(write(3, GOAL_POSITION, u32(1234)))
    second = wire(bus.receive(read))
    assert second != first
    assert any(u32(1234) in data for _, data, _ in second)
    assert second == fresh(bus, read)


@pytest.mark.parametrize("change", [
    write(2, TORQUE_ENABLE, b"\x01"),  # Torque Enable itself is not read: the answer may stay, but must match
    write(2, RETURN_DELAY_TIME, b"\x05"),  # the second servo answers later (EEPROM: written with the torque off)
    write(2, STATUS_RETURN_LEVEL, b"\x00"),  # the chain breaks at the second servo
    write(2, ID, b"\x09"),  # ID 2 is gone: the chain breaks there
])
def test_what_the_bus_reads_per_servo_changed_between_two_identical_reads(change):
    bus = new_bus()
    bus.receive(write(2, TORQUE_ENABLE, b"\x00"))
    first = wire(bus.receive(sync_read(PRESENT_POSITION, 4)))
    bus.receive(change)
    second = wire(bus.receive(sync_read(PRESENT_POSITION, 4)))
    assert second == fresh(bus, sync_read(PRESENT_POSITION, 4))
    if change[8] != TORQUE_ENABLE:  # (the address: header 4, ID, LENGTH 2, instruction)
        assert second != first


def test_a_hardware_error_between_two_identical_reads_sets_the_alert_bit_in_the_second():
    bus = new_bus()
    first = bus.receive(sync_read(PRESENT_POSITION, 4))
    bus.servos[3].plant.firmware.raise_error(HW_ERROR_OVERHEATING)
    bus.clock.advance(0.005)  # the firmware's next step copies Hardware Error Status into the table
    second = bus.receive(sync_read(PRESENT_POSITION, 4))
    assert [reply.data[8] & 0x80 for reply in first] == [0] * len(IDS)
    assert [reply.data[8] & 0x80 for reply in second] == [0, 0, 0, 0x80, 0, 0]
    assert wire(second) == fresh(bus, sync_read(PRESENT_POSITION, 4))


def test_a_new_goal_between_two_reads_of_present_position_leaves_the_answer_as_made_anew():
    """A goal is not among the bytes a read of Present Position depends on: whether remembered or not, the
    answer is the one a bus that remembers nothing gives."""
    bus = new_bus(defer=True)
    for goal in (1000, 1001, 3000, 3001):
        bus.receive(sync_write(GOAL_POSITION, {servo_id: u32(goal) for servo_id in IDS}))
        answer = wire(bus.receive(sync_read(PRESENT_POSITION, 4)))
        assert answer == fresh(bus, sync_read(PRESENT_POSITION, 4))


def test_a_fault_set_between_two_identical_reads_acts_on_the_second():
    bus = new_bus()
    first = bus.receive(sync_read(PRESENT_POSITION, 4))
    assert len(first) == len(IDS)
    faults = Faults2(bus)
    bus.faults = faults
    faults.vanish(3)  # unplugged: the chain breaks at it
    assert len(bus.receive(sync_read(PRESENT_POSITION, 4))) == 2
    bus.faults = None
    assert wire(bus.receive(sync_read(PRESENT_POSITION, 4))) == wire(first)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_mixed_stream_is_answered_as_by_a_bus_that_remembers_nothing(seed):
    rng = random.Random(seed)
    remembering, forgetting = new_bus(defer=True), new_bus(defer=True)
    reads = [sync_read(PRESENT_POSITION, 4), sync_read(GOAL_POSITION, 20), fast_sync_read(PRESENT_POSITION, 4),
             bulk_read([(2, PRESENT_POSITION, 4), (5, GOAL_POSITION, 4)])]
    made = 0
    anew = remembering._listed_anew

    def counted(*args):
        nonlocal made
        made += 1
        return anew(*args)

    remembering._listed_anew = counted
    listed = 0
    for _ in range(3000):
        roll = rng.random()
        if roll < 0.55:
            data = rng.choice(reads)
            listed += 1
        elif roll < 0.75:
            data = sync_write(GOAL_POSITION, {servo_id: u32(rng.choice((1000, 3000))) for servo_id in IDS})
        elif roll < 0.8:
            data = write(rng.choice(IDS), rng.choice((TORQUE_ENABLE, RETURN_DELAY_TIME)), bytes((rng.randint(0, 1),)))
        else:
            data = None
            dt_s = rng.choice((0.0002, 0.001, 0.003))
            for bus in (remembering, forgetting):
                for _ in bus.settle_in_pieces():
                    pass
                bus.clock.advance(dt_s)
        if data is not None:
            forgetting._listed_answers.clear()
            assert wire(remembering.receive(data)) == wire(forgetting.receive(data)), data.hex()
    # Remembered answers were handed out (or this compared the made answers with themselves).
    assert listed - made > 300, (listed, made)
