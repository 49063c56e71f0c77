"""In-Position (Moving Status bit 0) after a factory-default move, on every X-series model, in virtual time.

The e-manual: In-Position is "Whether or not the DYNAMIXEL has arrived to the desired Goal Position(116)", set "when
the positional deviation is smaller than a predefined value" (_includes/en/dxl/x/moving_status.md).  A real servo
at its factory settings on a free shaft arrives: a host that writes a goal and waits for the bit must not wait for
ever.  Every X model's factory Position I Gain is 0, so its proportional loop stops where its output no longer
beats the servo's own friction; the firmware's window (``IN_POSITION_PULSES``) must take that in, at every supply
the model runs on.
"""

from __future__ import annotations

import random

import pytest

from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock
from ax12emu.protocol.packets2 import Instruction2, decode_packet2, encode_instruction2
from ax12emu.protocol.servo_models import model, model_names
from ax12emu.servo.model_factory2 import XModelChoice, build_x_firmware
from firmware_model.xseries.firmware import IN_POSITION_PULSES

X_MODELS = [key for key in model_names() if "2.0" in model(key).protocols and model(key).classic is None]
IN_POSITION = 0x01


class _Servo:
    """One servo of ``key`` at ``supply_v`` on a Protocol 2.0 bus in virtual time, spoken to in packets."""

    def __init__(self, key: str, supply_v: float | None = None) -> None:
        choice = XModelChoice(voltage_v=supply_v)
        self.bus = Bus2([(1, model(key))], lambda spec, index: build_x_firmware(spec, choice), clock=VirtualClock())

    def _entry(self, name: str):
        return self.bus.servo(1).table.layout.by_name[name]

    def write(self, name: str, value: int) -> None:
        e = self._entry(name)
        data = e.address.to_bytes(2, "little") + (value & ((1 << 8 * e.size) - 1)).to_bytes(e.size, "little")
        reply = decode_packet2(self.bus.receive(encode_instruction2(1, Instruction2.WRITE, data))[0].data)
        assert reply.error == 0, (name, value, reply.error)

    def read(self, name: str) -> int:
        e = self._entry(name)
        data = e.address.to_bytes(2, "little") + e.size.to_bytes(2, "little")
        reply = decode_packet2(self.bus.receive(encode_instruction2(1, Instruction2.READ, data))[0].data)
        return int.from_bytes(reply.params, "little", signed=e.signed)

    def run_s(self, seconds: float) -> None:
        self.bus.clock.advance(seconds)


def _supplies(key: str) -> list[float]:
    physical = model(key).physical
    return [physical.operating_voltage_v[0], physical.recommended_voltage_v]


@pytest.mark.parametrize("profile", [(0, 0), (100, 20)], ids=["no-profile", "trapezoid"])
@pytest.mark.parametrize("key", X_MODELS)
def test_a_factory_default_move_ends_in_position(key, profile):
    """Twenty moves at the factory registers (Profile Velocity and Acceleration as given), at the lowest and the
    recommended supply: each has In-Position within 3 s of the goal write and, a second later, at rest, still."""
    velocity, acceleration = profile
    for supply_v in _supplies(key):
        servo = _Servo(key, supply_v)
        servo.write("torque_enable", 1)
        servo.write("profile_velocity", velocity)
        servo.write("profile_acceleration", acceleration)
        rng = random.Random(key)
        for _ in range(20):
            goal = rng.randint(500, 3500)
            servo.write("goal_position", goal)
            for _ in range(300):
                servo.run_s(0.01)
                if servo.read("moving_status") & IN_POSITION:
                    break
            servo.run_s(1.0)  # and it stays there, at rest
            status, present = servo.read("moving_status"), servo.read("present_position")
            assert status & IN_POSITION and servo.read("moving") == 0, (
                f"{key} at {supply_v} V: stopped {goal - present} pulses from goal {goal}, Moving Status {status:#x}")
            assert abs(goal - present) < IN_POSITION_PULSES


def test_in_position_needs_the_shaft_at_the_goal():
    """A blocked shaft short of its goal, the profile over: not In-Position."""
    servo = _Servo("xm430-w350")
    servo.write("torque_enable", 1)
    servo.run_s(0.1)
    servo.bus.servo(1).plant.firmware.set_blocked(True)
    servo.write("goal_position", servo.read("present_position") + 3 * IN_POSITION_PULSES)
    servo.run_s(0.5)
    assert not servo.read("moving_status") & IN_POSITION
