"""A client writing faster than the servos' 1 ms control loop cannot run their physics ahead of the clock, in virtual time.

Each write earns one control step before the next request (a real servo's loop runs before a host's next
packet can arrive over USB), but a real servo's loop never runs ahead of its own clock: over a pty a client
can write many times within one millisecond, and each write taking a step of its own would move the servos
as many times faster than real.  So the model leads the clock by at most one step; a write in the same
control period is taken as the firmware takes a packet between two ticks (the new goal acted on, Moving
read at once) and the physics waits for the clock.  At one write per millisecond or slower nothing
changes: every write still earns its step.

Every served model, on the bus the served wire would use, with physics up to date at the write
(``request_lag_s`` 0) or a step behind it as under the serving loop.
"""

from __future__ import annotations

import pytest
from emu_testkit import RegisterLink

from ax12emu.bus.bus import Bus
from ax12emu.bus.bus1x import Bus1X
from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock
from ax12emu.bus.wire import build_wire_of
from ax12emu.protocol.packets import BROADCAST_ID, Instruction, encode_instruction
from ax12emu.protocol.packets2 import Instruction2, encode_instruction2
from ax12emu.protocol.servo_models import model_names
from ax12emu.servo.model_factory import ModelChoice, build_model

#: Goal writes in one burst, all at one instant of the clock.
BURST_WRITES = 50
#: Floating-point slack on model and clock times that add up millisecond steps.
SLACK_S = 1e-9
LAGS = pytest.mark.parametrize("lag_steps", [0, 1], ids=["up-to-date", "a-step-behind"])


class Link(RegisterLink):
    """One servo, ID 1, of ``key``'s model on its wire, spoken to in its protocol, in virtual time."""

    def __init__(self, key: str, lag_steps: int, bus: Bus | None = None) -> None:
        super().__init__(key, bus if bus is not None else build_wire_of([(1, key)], clock=VirtualClock()))
        self.clock = self.bus.clock
        self.step_s = self.bus.physics_step_s
        self.bus.request_lag_s = lag_steps * self.step_s
        profiled = "profile_velocity" in self.by_name
        self.write("profile_velocity" if profiled else "moving_speed", 100)
        self.write("torque_enable", 1)
        self.run_s(0.5)
        self.start = self.read("present_position")

    def model_times_s(self) -> list[float]:
        """Every model's time on the bus (one per servo, the AX-12 model once)."""
        bus = self.bus
        if isinstance(bus, Bus2):
            return [servo.plant.firmware.time_s for servo in bus.servos]
        if isinstance(bus, Bus1X):
            ax = [bus.ax_bus.plant.model.time_s] if bus.ax_bus is not None else []
            return [servo.plant.firmware.time_s for servo in bus.servos_mx] + ax
        return [bus.plant.model.time_s]

    def lead_s(self) -> float:
        """How far the furthest model is past the clock."""
        return max(self.model_times_s()) - self.clock.now_s()

    def sync_write(self, name: str, value: int) -> None:
        """A Sync Write of one register to ID 1: nobody answers."""
        entry = self.by_name[name]
        data = value.to_bytes(entry.size, "little", signed=entry.signed)
        if self.protocol2:
            params = entry.address.to_bytes(2, "little") + entry.size.to_bytes(2, "little") + bytes([1]) + data
            packet = encode_instruction2(BROADCAST_ID, Instruction2.SYNC_WRITE, params)
        else:
            packet = encode_instruction(BROADCAST_ID, Instruction.SYNC_WRITE, bytes([entry.address, entry.size, 1]) + data)
        assert self.bus.receive(packet) == []

    def goals(self, count: int) -> list[int]:
        """``count`` goals alternating 20 degrees either side of where the servo rests: each one a new move."""
        units = round(20.0 / self.spec.physical.resolution_deg)
        return [self.start + units if k % 2 == 0 else self.start - units for k in range(count)]


def _ax12_kinematic() -> Bus:
    return Bus([1], clock=VirtualClock(), model=build_model(ModelChoice(name="kinematic"), 1))


@LAGS
@pytest.mark.parametrize("key", [*model_names(), "ax-12a kinematic"])
def test_a_burst_of_goal_writes_in_one_millisecond_leads_the_clock_by_one_step_and_each_reads_moving(key, lag_steps):
    link = Link(key.split()[0], lag_steps, _ax12_kinematic() if key.endswith("kinematic") else None)
    assert link.lead_s() <= SLACK_S
    # First the goal it rests at (no move, its control step taken), so the burst's moves start in that
    # millisecond from rest: Moving can only come from the new goal.
    link.write("goal_position", link.start)
    link.read("moving")
    for goal in link.goals(BURST_WRITES):
        link.write("goal_position", goal)
        assert link.read("moving") == 1, "the first read after a goal write says the move started"
        assert link.lead_s() <= link.step_s + SLACK_S, f"model {link.model_times_s()} vs clock {link.clock.now_s()}"
    # The clock moving on lets the physics go on from where it stood: nothing was lost, nothing gained.
    link.run_s(link.step_s)
    link.write("goal_position", link.start)
    link.read("moving")
    assert abs(link.lead_s() - link.step_s) <= SLACK_S


@LAGS
@pytest.mark.parametrize("key", ["xl430-w250", "xl-320", "mx-28", "ax-12a"])
def test_a_burst_of_sync_writes_settled_after_each_packet_leads_by_one_step(key, lag_steps):
    """The serving loop's path for a packet nobody answers: the step it earned taken right after it (``settle_in_pieces``)."""
    link = Link(key, lag_steps)
    settle = getattr(link.bus, "settle_in_pieces", None)
    for goal in link.goals(BURST_WRITES):
        link.sync_write("goal_position", goal)
        if settle is not None:
            for _ in settle():
                pass
        assert link.lead_s() <= link.step_s + SLACK_S, f"model {link.model_times_s()} vs clock {link.clock.now_s()}"
        assert link.read("moving") == 1


@LAGS
@pytest.mark.parametrize("spacing_steps", [1, 3])
@pytest.mark.parametrize("key", ["xl430-w250", "xl-320", "mx-28", "ax-12a"])
def test_at_one_write_per_millisecond_or_slower_every_write_still_earns_its_step(key, spacing_steps, lag_steps):
    link = Link(key, lag_steps)
    for goal in link.goals(20):
        link.clock.advance(spacing_steps * link.step_s)
        if lag_steps:
            link.bus.advance()  # the serving loop's tick, between packets
        link.write("goal_position", goal)
        at_write_s = link.model_times_s()
        assert link.read("moving") == 1
        # The control step the write earned, run before this read could arrive.
        assert link.model_times_s() == pytest.approx([t + link.step_s for t in at_write_s], abs=SLACK_S)
        assert link.lead_s() <= link.step_s + SLACK_S
