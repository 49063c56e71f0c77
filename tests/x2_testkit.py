"""Helpers for the Protocol 2.0 bus tests: a recording stand-in for an X-series firmware model, and a bus of them.

Why a stand-in: the table, instruction and timing tests check what the protocol side does with
registers; they need a model that keeps time and reports what it was told, not physics.  The
tests that check motion use the real firmware model (``firmware_model.xseries``).
"""

from __future__ import annotations

import dataclasses

from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock
from ax12emu.protocol.servo_models import model
from firmware_model.xseries.interface import XCommands, XSensed


class RecordingFirmware:
    """An XServoModel that steps time, records every command and senses what a test sets in ``sensed``."""

    def __init__(self, step_s: float = 0.001) -> None:
        self.step_s = step_s
        self.time_s = 0.0
        self.sensed = XSensed(present_position=2048, present_input_voltage=120, present_temperature=30)
        self.commands: list[tuple[XCommands, bool]] = []
        self.reboots = 0
        self.clears = 0

    def command(self, commands: XCommands, *, goal_written: bool = False) -> None:
        self.commands.append((commands, goal_written))
        if "torque_enable" in XSensed.field_names():  # the firmware reports the torque it holds
            self.sensed = dataclasses.replace(self.sensed, torque_enable=commands.torque_enable)

    def step_to(self, to_time_s: float) -> None:
        steps = int((to_time_s - self.time_s) / self.step_s + 1e-9)
        self.time_s += max(steps, 1 if to_time_s > self.time_s else 0) * self.step_s

    def sense(self) -> XSensed:
        return self.sensed

    def reboot(self) -> None:
        self.reboots += 1

    def clear_multi_turn(self) -> None:
        self.clears += 1

    def set_external_torque(self, torque_nm: float) -> None:
        pass

    @property
    def last(self) -> XCommands:
        return self.commands[-1][0]


def recording_bus(ids=(1, 2, 3), key: str = "xl430-w250", **kwargs) -> tuple[Bus2, list[RecordingFirmware]]:
    """A Protocol 2.0 bus of ``key`` servos in virtual time, and their recording firmware models."""
    firmware: list[RecordingFirmware] = []

    def factory(spec, index):
        firmware.append(RecordingFirmware())
        return firmware[-1]

    spec = model(key)
    bus = Bus2([(i, spec) for i in ids], factory, clock=VirtualClock(), **kwargs)
    return bus, firmware
