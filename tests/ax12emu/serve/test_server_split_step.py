"""The serving loop's control step split over a fast host's two pauses, on a clock the test moves.

While a robot cycles faster than 1 kHz with its Sync Writes held, the loop takes the held goals right
after the reply two host cycles before the step falls due (``Bus2.take_parked_early``) and the step right
after the next reply, leaving a write held in between for the next step.  A step the loop takes more than
a host cycle late (held up past it) takes every write held first.
"""

from __future__ import annotations

import os
import time

import pytest
from emu_testkit import Packets2, PipeTransport, u32

from ax12emu.bus.clock import WallClock
from ax12emu.bus.wire import build_bus2
from ax12emu.serve.server import EARLY_STEP_S, BusServer

IDS = (1, 2, 3, 4, 5, 6)
RETURN_DELAY_TIME, TORQUE_ENABLE, GOAL_POSITION, PRESENT_POSITION = 9, 64, 116, 132
PACKETS = Packets2(IDS)


class _Clock:
    """``time.monotonic`` for the serving loop and the bus's wall clock: moves only when the test moves it."""

    def __init__(self) -> None:
        self.now_s = 1000.0

    def __call__(self) -> float:
        return self.now_s


@pytest.fixture
def served(monkeypatch):
    clock = _Clock()
    monkeypatch.setattr(time, "monotonic", clock)
    bus = build_bus2("xl430-w250", list(IDS), clock=WallClock(), baud_bps=1_000_000)
    with PipeTransport() as transport:
        server = BusServer(bus, transport)

        def send(data: bytes, *, at_s: float) -> None:
            """The host's bytes at bus-clock time ``at_s`` (after the loop's passes until then)."""
            clock.now_s = server._next_physics + at_s  # relative to the step the loop waits for
            os.write(transport.write_fd, data)
            server.run_once()

        for servo_id in IDS:
            for data in (PACKETS.write(servo_id, RETURN_DELAY_TIME, b"\x00"),
                         PACKETS.write(servo_id, TORQUE_ENABLE, b"\x01")):
                send(data, at_s=-0.0009)
        yield bus, server, clock, send


def goals(bus) -> list[int]:
    return [servo.table.get("goal_position") for servo in bus.servos]


def cycle(goal: int) -> bytes:
    """A robot's Sync Write of new goals and its Sync Read, read by the loop at once (as over a pty)."""
    return PACKETS.sync_write(GOAL_POSITION, {servo_id: u32(goal + servo_id) for servo_id in IDS}) + \
        PACKETS.sync_read(PRESENT_POSITION, 4)


def test_goals_are_taken_two_host_cycles_before_their_step_and_a_later_write_waits_for_the_next(served):
    bus, server, clock, send = served
    send(cycle(1000), at_s=-0.0008)  # a step ahead of the clock now: the next writes are held
    send(cycle(1100), at_s=-0.0005)
    assert bus.parked
    send(cycle(1200), at_s=-1.8 * EARLY_STEP_S)  # the reply two host cycles before the step: goals taken
    assert not bus.parked and goals(bus) == [1200 + servo_id for servo_id in IDS]
    stepped_to_s = [servo.plant.firmware.time_s for servo in bus.servos]
    send(cycle(1300), at_s=-0.6 * EARLY_STEP_S)  # the reply before the step: the step, without 1300
    assert all(servo.plant.firmware.time_s > before for servo, before in zip(bus.servos, stepped_to_s))
    assert bus.parked and goals(bus) == [1200 + servo_id for servo_id in IDS]


def test_a_step_the_loop_takes_late_takes_every_write_held_first(served):
    bus, server, clock, send = served
    send(cycle(1000), at_s=-0.0008)
    send(cycle(1100), at_s=-0.0005)
    send(cycle(1200), at_s=-1.8 * EARLY_STEP_S)  # goals taken early
    send(PACKETS.sync_write(GOAL_POSITION, {servo_id: u32(1300 + servo_id) for servo_id in IDS}),
         at_s=-1.5 * EARLY_STEP_S)  # held, no reply: the step waits
    assert bus.parked
    clock.now_s = server._next_physics + 0.005  # the loop held up 5 ms past the step
    server.run_once()
    assert not bus.parked and goals(bus) == [1300 + servo_id for servo_id in IDS]
