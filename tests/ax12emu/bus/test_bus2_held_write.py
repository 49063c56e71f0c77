"""A bus served by a loop that settles after each packet (``Bus2.defer_settling``) answers every packet as the plain path does.

With it, a Sync/Bulk Read may leave a servo's catch-up for after its reply, and a broadcast Sync Write of
Goal registers is held for the next packet, which a read that cannot tell may overtake.  Both are shortcuts
for a robot's control cycle; neither may change a byte a client reads.  Here two identical buses take the
same packets in virtual time, one with the shortcuts and one without, settled at the same points as a
serving loop settles them (``settle_in_pieces``, the physics tick, time passing only once both have settled),
and every reply is compared byte for byte, then every table.  The packets are a robot's (Sync Write of Goal
Position, Sync Read of Present Position) mixed with what could catch a shortcut out: reads of Moving, Goal
Position and the trajectory right after a goal, a Bulk Read, writes the servo refuses (out of range), torque
off and on, Operating Mode, Homing Offset, the Bus Watchdog, a Hardware Error raised in the firmware, a
corrupt packet.
"""

from __future__ import annotations

import random

import pytest
from emu_testkit import Packets2, u16, u32

from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock
from ax12emu.protocol.packets2 import Instruction2, encode_instruction2
from ax12emu.protocol.servo_models import model
from ax12emu.servo.model_factory2 import build_x_firmware
from firmware_model.xseries.interface import HW_ERROR_OVERHEATING

IDS = (1, 2, 3, 4, 5, 6)
#: X-series addresses (e-manual, XL430-W250 / XM430-W350 control tables).
OPERATING_MODE, HOMING_OFFSET, SHUTDOWN, TORQUE_ENABLE = 11, 20, 63, 64
BUS_WATCHDOG, PROFILE_ACCELERATION, PROFILE_VELOCITY, GOAL_POSITION = 98, 108, 112, 116
MOVING, VELOCITY_TRAJECTORY, PRESENT_POSITION, RETURN_DELAY_TIME = 122, 136, 132, 9
#: The packets a host sends these servos.
_PACKETS = Packets2(IDS)
sync_write = _PACKETS.sync_write
sync_read = _PACKETS.sync_read
bulk_read = _PACKETS.bulk_read
write = _PACKETS.write


def new_bus(defer: bool) -> Bus2:
    specs = [model("xl430-w250"), model("xm430-w350")]
    bus = Bus2([(servo_id, specs[servo_id % 2]) for servo_id in IDS], lambda spec, index: build_x_firmware(spec),
               clock=VirtualClock(1.0))
    bus.request_lag_s = 0.001  # as the serving loop sets it
    bus.defer_settling = defer
    return bus


def packets(rng: random.Random):
    """An endless mix, weighted towards a robot's cycle."""
    goals = {servo_id: 2048 for servo_id in IDS}
    while True:
        roll = rng.random()
        if roll < 0.35:  # the cycle's write: new goals, near or far, sometimes the same again
            for servo_id in IDS:
                if rng.random() < 0.5:
                    goals[servo_id] = rng.choice((goals[servo_id] + rng.randint(-15, 15), rng.randint(0, 4095)))
            yield sync_write(GOAL_POSITION, {servo_id: u32(goal) for servo_id, goal in goals.items()})
        elif roll < 0.65:
            yield sync_read(PRESENT_POSITION, 4)
        elif roll < 0.70:
            yield sync_read(MOVING, 1)
        elif roll < 0.74:
            yield sync_read(GOAL_POSITION, 4)
        elif roll < 0.77:
            yield sync_read(VELOCITY_TRAJECTORY, 8)  # velocity and position trajectory
        elif roll < 0.80:
            yield sync_read(GOAL_POSITION, 20)  # goal, tick, moving, status, present PWM ... present position
        elif roll < 0.82:
            yield bulk_read([(2, PRESENT_POSITION, 4), (1, MOVING, 2), (5, 126, 10)])
        elif roll < 0.84:  # out of range on some: refused there, taken elsewhere
            yield sync_write(GOAL_POSITION, {servo_id: u32(rng.choice((5000, -3, goals[servo_id]))) for servo_id in IDS})
        elif roll < 0.86:
            yield sync_write(PROFILE_ACCELERATION, {servo_id: u32(rng.randint(0, 50)) + u32(rng.randint(0, 200))
                                                    for servo_id in IDS})
        elif roll < 0.88:
            yield write(rng.choice(IDS), TORQUE_ENABLE, bytes((rng.randint(0, 1),)))
        elif roll < 0.89:  # EEPROM: refused while the torque is on, taken when off
            yield write(rng.choice(IDS), OPERATING_MODE, bytes((rng.choice((3, 4)),)))
        elif roll < 0.90:
            yield write(rng.choice(IDS), HOMING_OFFSET, u32(rng.randint(-900, 900)))
        elif roll < 0.91:
            yield write(rng.choice(IDS), BUS_WATCHDOG, bytes((rng.choice((0, 0, 0, 3)),)))
        elif roll < 0.92:
            yield write(rng.choice(IDS), SHUTDOWN, bytes((rng.choice((0x34, 0x00)),)))  # Shutdown: EEPROM
        elif roll < 0.93:
            yield "raise"  # the firmware detects an overheating (a fault the world causes)
        elif roll < 0.94:
            yield encode_instruction2(rng.choice(IDS), Instruction2.REBOOT)
        elif roll < 0.95:
            corrupt = bytearray(sync_read(PRESENT_POSITION, 4))
            corrupt[-1] ^= 0xFF
            yield bytes(corrupt)
        else:
            yield encode_instruction2(rng.choice(IDS), Instruction2.READ, u16(PRESENT_POSITION) + u16(4))


def settle(bus: Bus2) -> None:
    for _ in bus.settle_in_pieces():
        pass


def settle_as_the_loop(bus: Bus2) -> None:
    """What the serving loop does after a packet: it settles, unless the bus holds a write for the next
    packet or the physics step (``Bus2.parked``)."""
    if not bus.parked:
        settle(bus)


def tick(bus: Bus2) -> None:
    for _ in bus.advance_in_pieces():
        pass


def robot_cycles(rng: random.Random):
    """Mostly a robot's cycle faster than the servos' 1 kHz loop (new goals, some out of range, then a Sync Read of
    Present Position), so held writes supersede each other; the mix above now and then."""
    others = packets(rng)
    goals = {servo_id: 2048 for servo_id in IDS}
    while True:
        if rng.random() < 0.8:
            for servo_id in IDS:
                if rng.random() < 0.7:
                    goals[servo_id] = min(max(goals[servo_id] + rng.randint(-40, 40), 0), 4095)
            yield sync_write(GOAL_POSITION, {servo_id: u32(5000 if rng.random() < 0.03 else goal)
                                             for servo_id, goal in goals.items()})
            yield sync_read(PRESENT_POSITION, 4)
        else:
            yield next(others)


def plain_and_quick(profile_velocity: int) -> tuple[Bus2, Bus2]:
    """A bus without the shortcuts and one with them, their servos alike: answering at once, torque on and,
    with ``profile_velocity``, goals starting profiles (a new goal then plans from the trajectory where it is)."""
    plain, quick = new_bus(defer=False), new_bus(defer=True)
    setup = [write(servo_id, RETURN_DELAY_TIME, b"\x00") for servo_id in IDS]
    if profile_velocity:
        setup += [write(servo_id, PROFILE_VELOCITY, u32(profile_velocity)) for servo_id in IDS]
    setup += [write(servo_id, TORQUE_ENABLE, b"\x01") for servo_id in IDS]
    for data in setup:
        assert plain.receive(data) == quick.receive(data)
    return plain, quick


def raise_on_both(rng: random.Random, plain: Bus2, quick: Bus2) -> None:
    """A fault on the same servo of both buses, acting between packets once the loop has settled (it runs as a
    call: what a held write and a reply left is taken first), told to the bus as the serving loop tells it."""
    servo_index = rng.randrange(len(IDS))
    for bus in (plain, quick):
        settle(bus)
        bus.take_deferred()
        bus.servos[servo_index].plant.firmware.raise_error(HW_ERROR_OVERHEATING)
        bus.changed_outside()


def compare_with_the_plain_path(stream, rng: random.Random, packets_sent: int,
                                profile_velocity: int = 0) -> tuple[int, int, int, int]:
    """Feed ``stream`` to a bus with the shortcuts and one without, settled and ticked at the same points as
    the serving loop does (time passing only once both have settled), compare every reply and, at the end,
    every table; return how often a held write was overtaken, superseded, a catch-up left for later and a read
    answered as the last time, nothing having changed since."""
    plain, quick = plain_and_quick(profile_velocity)
    overtaken = superseded = deferred = replayed = 0
    for step in range(packets_sent):
        data = next(stream)
        if data == "raise":
            raise_on_both(rng, plain, quick)
            continue
        waiting_before, superseded_before = quick.parked and quick._waiting, len(quick._superseded)
        changes_before = quick._changes
        replies_plain, replies_quick = plain.receive(data), quick.receive(data)
        assert [(r.data, r.delay_s) for r in replies_quick] == [(r.data, r.delay_s) for r in replies_plain], (step, data.hex())
        overtaken += waiting_before and quick.parked and not quick._waiting
        superseded += len(quick._superseded) > superseded_before
        replayed += bool(replies_quick) and quick._changes == changes_before  # answered as last time (nothing changed)
        deferred += any(servo.plant._deferred is not None for servo in quick.servos)
        roll = rng.random()
        if roll < 0.6:  # the loop settles right after the packet (or the next packet comes first)
            settle(plain)
            settle_as_the_loop(quick)
        if roll < 0.15:  # the physics tick, then time passes
            settle(plain)
            settle_as_the_loop(quick)
            tick(plain)
            tick(quick)
            dt_s = rng.choice((0.0001, 0.0003, 0.001, 0.0025))
            plain.clock.advance(dt_s)
            quick.clock.advance(dt_s)
        elif roll < 0.35:  # time passes between packets, before the next tick (a held write waits meanwhile)
            settle(plain)
            settle_as_the_loop(quick)
            dt_s = rng.choice((0.00005, 0.0002, 0.0006))
            plain.clock.advance(dt_s)
            quick.clock.advance(dt_s)
    settle(plain)
    settle(quick)
    quick.take_deferred()
    for a, b in zip(plain.servos, quick.servos):
        assert bytes(a.table.row) == bytes(b.table.row)
    return overtaken, superseded, deferred, replayed


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_the_shortcuts_answer_every_packet_byte_for_byte_as_the_plain_path(seed):
    rng = random.Random(seed)
    overtaken, superseded, deferred, _ = compare_with_the_plain_path(packets(rng), rng, 2500)
    # The shortcuts were taken (or this compared the plain path with itself).
    assert overtaken > 5 and superseded > 1 and deferred > 20, (overtaken, superseded, deferred)


@pytest.mark.parametrize("seed, profile_velocity", [(1, 0), (2, 200), (3, 30)])
def test_a_robot_cycle_faster_than_the_control_loop_answers_as_the_plain_path(seed, profile_velocity):
    rng = random.Random(seed)
    overtaken, superseded, deferred, replayed = compare_with_the_plain_path(robot_cycles(rng), rng, 3000,
                                                                            profile_velocity)
    assert overtaken > 200 and superseded > 100 and replayed > 50, (overtaken, superseded, deferred, replayed)


def test_a_held_goal_write_is_visible_to_a_read_of_what_it_changes():
    """Whatever a write changes is visible to the next request: Goal Position reads back, Moving is 1."""
    bus = new_bus(defer=True)
    for servo_id in IDS:
        bus.receive(write(servo_id, RETURN_DELAY_TIME, b"\x00"))
        bus.receive(write(servo_id, PROFILE_VELOCITY, u32(100)))
        bus.receive(write(servo_id, TORQUE_ENABLE, b"\x01"))
    assert bus.receive(sync_write(GOAL_POSITION, {servo_id: u32(3000) for servo_id in IDS})) == []
    assert bus.parked  # held for the next packet
    replies = bus.receive(sync_read(GOAL_POSITION, 4))
    assert [int.from_bytes(reply.data[9:13], "little") for reply in replies] == [3000] * len(IDS)
    bus.receive(sync_write(GOAL_POSITION, {servo_id: u32(1000) for servo_id in IDS}))
    replies = bus.receive(sync_read(MOVING, 1))
    assert [reply.data[9] for reply in replies] == [1] * len(IDS)


def test_a_step_falling_due_within_the_lead_is_taken_now_with_the_held_write():
    """The serving loop takes a step falling due just after a reply at once (``advance_in_pieces(lead_s)``): the
    held write is taken and the step it earned shows; with a lead short of the step's time, nothing steps."""
    bus = new_bus(defer=True)
    for servo_id in IDS:
        bus.receive(write(servo_id, PROFILE_VELOCITY, u32(100)))
        bus.receive(write(servo_id, TORQUE_ENABLE, b"\x01"))
    bus.receive(sync_write(GOAL_POSITION, {servo_id: u32(2048) for servo_id in IDS}))  # earns a step now
    settle(bus)
    bus.receive(sync_write(GOAL_POSITION, {servo_id: u32(3000) for servo_id in IDS}))
    assert bus.parked  # the models are a step ahead of the clock: the write waits for it
    firmware = [servo.plant.firmware for servo in bus.servos]
    model_s = firmware[0].time_s
    bus.clock.advance(model_s - bus.clock.now_s() - 0.0003)  # the step falls due in 0.3 ms
    for _ in bus.advance_in_pieces(0.0002):
        pass
    assert [model.time_s for model in firmware] == [model_s] * len(IDS)  # not yet: only the write taken
    assert not bus.parked
    for _ in bus.advance_in_pieces(0.0004):
        pass
    assert all(model.time_s > model_s for model in firmware)
    replies = bus.receive(sync_read(MOVING, 1))
    assert [reply.data[9] for reply in replies] == [1] * len(IDS)  # the move the write started shows
    assert bus.clock.now_s() < model_s  # before the step's own time


def compare_early_takes_with_the_plain_path(rng: random.Random, packets_sent: int,
                                            profile_velocity: int) -> tuple[int, int]:
    """A robot's cycle served as the loop serves it when the step is two host cycles off: the held goals
    taken early (``Bus2.take_parked_early``), the step then taken without what was held since (``take=False``),
    which is left for the next step.  The plain bus gets each packet as it comes, except the writes held at
    such a step, which it gets right after its own step: so both act on the same goals at every step, and
    every reply and, at the end, every table must match.  No time passes between an early take and its step
    (in the loop it is one host cycle).  Returns (early takes, reads answered as the last time between an early
    take and its step)."""
    plain, quick = plain_and_quick(profile_velocity)
    taken_during = []
    take_parked = quick.take_parked

    def spy(**kwargs):
        taken_during.append(quick._parked is not None)
        take_parked(**kwargs)
    quick.take_parked = spy
    stream = robot_cycles(rng)
    early_takes = replayed = 0
    waiting_is_on = False  # between an early take and its step
    waiting_for_step: list[bytes] = []  # writes quick holds since its early take, the plain bus's after its step
    for step in range(packets_sent):
        data = next(stream)
        if data == "raise":  # as in compare_with_the_plain_path: settling takes what quick holds first
            for held in waiting_for_step:
                assert plain.receive(held) == []
            waiting_for_step.clear()
            raise_on_both(rng, plain, quick)
            continue
        parked_before, changes_before = quick._parked, quick._changes
        taken_during.clear()
        replies_quick = quick.receive(data)
        if any(taken_during):  # the packet needed the held writes taken first (as they came)
            for held in waiting_for_step:
                assert plain.receive(held) == []
            waiting_for_step.clear()
        if waiting_is_on and quick._parked is not None and quick._parked is not parked_before:
            waiting_for_step.append(data)  # held for the next step
        else:
            replies_plain = plain.receive(data)
            assert [(r.data, r.delay_s) for r in replies_quick] == [(r.data, r.delay_s) for r in replies_plain], (
                step, data.hex())
        replayed += bool(replies_quick) and quick._changes == changes_before and waiting_is_on
        settle(plain)
        settle_as_the_loop(quick)
        roll = rng.random()
        if roll < 0.3 and quick.parked and not waiting_for_step and not waiting_is_on:
            quick.take_parked_early()
            early_takes += 1
            waiting_is_on = True
        elif roll < 0.45:  # the step (with the lead the loop gives it), then time passes
            lead_s = max(0.0, min(servo.plant.firmware.time_s for servo in quick.servos) - quick.clock.now_s())
            for _ in quick.advance_in_pieces(lead_s, take=not waiting_is_on):
                pass
            for _ in plain.advance_in_pieces(lead_s):
                pass
            for held in waiting_for_step:
                assert plain.receive(held) == []
            waiting_for_step.clear()
            waiting_is_on = False
            dt_s = rng.choice((0.0001, 0.0003, 0.001))
            plain.clock.advance(dt_s)
            quick.clock.advance(dt_s)
    for held in waiting_for_step:
        plain.receive(held)
    settle(plain)
    quick.take_parked()
    settle(quick)
    quick.take_deferred()
    for a, b in zip(plain.servos, quick.servos):
        assert bytes(a.table.row) == bytes(b.table.row)
    return early_takes, replayed


@pytest.mark.parametrize("seed, profile_velocity", [(1, 0), (2, 200), (3, 30)])
def test_goals_taken_a_host_cycle_before_their_step_act_on_it_as_if_they_came_last(seed, profile_velocity):
    early_takes, replayed = compare_early_takes_with_the_plain_path(random.Random(seed), 3000, profile_velocity)
    assert early_takes > 100 and replayed > 100, (early_takes, replayed)
