"""The X-series plant's reads and writes of its table: the firmware sees the table's registers, the table the firmware's."""

from __future__ import annotations

import random

import pytest

from ax12emu.protocol.servo_models import model, model_names
from ax12emu.servo.model_factory2 import build_x_firmware
from ax12emu.servo.plant2 import SENSED_REGISTERS, Plant2
from ax12emu.servo.table2 import Table2
from firmware_model.xseries.interface import XCommands

X_MODELS = [key for key in model_names() if "2.0" in model(key).protocols]


@pytest.mark.parametrize("key", X_MODELS)
def test_commands_are_the_registers_values_whatever_the_bytes(key):
    """Every command register, read all at once, equals its value read on its own (sign and size included)."""
    spec = model(key)
    table = Table2(spec.layout())
    plant = Plant2(build_x_firmware(spec), table)
    names = [name for name in XCommands.field_names() if table.has(name)]
    rng = random.Random(key)
    for _ in range(50):
        table.row[:] = bytes(rng.randrange(256) for _ in range(len(table.row)))
        commands = plant.commands()
        assert {name: getattr(commands, name) for name in names} == {name: table.get(name) for name in names}


@pytest.mark.parametrize("key", X_MODELS)
def test_write_back_puts_what_the_firmware_senses_in_the_table(key):
    spec = model(key)
    table = Table2(spec.layout())
    plant = Plant2(build_x_firmware(spec), table)
    table.set("torque_enable", 1)
    plant.command()
    plant.catch_up(0.05)
    sensed = plant.firmware.sense()
    for field, candidates in SENSED_REGISTERS.items():
        present = [name for name in candidates if table.has(name)]
        if present:
            assert table.get(present[0]) == getattr(sensed, field), field
