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


@pytest.mark.parametrize("key", [key for key in model_names() if "2.0" in model(key).protocols])
def test_sensed_registers_are_stored_as_table_set_stores_them(key):
    """Plant2's one-struct-call-per-run copy of the sensed registers writes what Table2.set would, values out
    of range masked as Entry.to_bytes masks them, bytes between the registers untouched; overlapping
    registers (no model has them) are written one by one, the later winning."""
    from ax12emu.protocol.registers import Access, Area, Entry
    from ax12emu.servo.plant2 import _writer

    rng = random.Random(3)
    by_name = model(key).layout().by_name
    entries = [by_name[name] for candidates in SENSED_REGISTERS.values() for name in candidates[:1] if name in by_name]
    for _ in range(50):
        values = tuple(rng.choice((rng.randrange(-(1 << 33), 1 << 33), rng.randrange(-3, 3))) for _ in entries)
        fast = bytearray(rng.randbytes(max(entry.end for entry in entries) + 8))
        slow = bytearray(fast)
        _writer(entries)(fast, values)
        for entry, value in zip(entries, values):
            slow[entry.address : entry.end] = entry.to_bytes(value)
        assert fast == slow
    overlapping = [Entry(10, 4, "a", Access.R, 0, 0, 0, Area.RAM), Entry(12, 2, "b", Access.R, 0, 0, 0, Area.RAM)]
    row = bytearray(16)
    _writer(overlapping)(row, (0x11223344, -1))
    assert row[10:14] == bytes((0x44, 0x33, 0xFF, 0xFF))


def test_a_write_while_the_model_is_ahead_is_shown_at_once_and_stepped_when_the_clock_reaches_it():
    """A second goal within one control period: its commands read back at once (Goal, the trajectory), and the
    servo's next tick, taken at the first catch-up once the clock has reached the model's time (not a period
    later), runs with it, as the servo's own 1 ms loop would."""
    spec = model("xl430-w250")
    table = Table2(spec.layout())
    plant = Plant2(build_x_firmware(spec), table)
    table.set("goal_pwm", table.get("pwm_limit"))  # as the servo sets it at power-on (Servo2.power_on)
    table.set("torque_enable", 1)
    plant.command()
    plant.catch_up(0.010, 0.010)
    start = table.get("present_position")
    table.set("goal_position", start + 400)
    plant.command(goal_written=True)
    plant.catch_up(0.0101, 0.0101)  # the write earns a step: the model runs one step past the clock
    assert plant.firmware.time_s == pytest.approx(0.011)
    table.set("goal_position", start - 400)  # a second goal before the clock reaches the model's time
    plant.command(goal_written=True)
    plant.catch_up(0.0102, 0.0102)
    assert plant.firmware.time_s == pytest.approx(0.011)  # shown, not stepped: the loop waits for the clock
    assert table.get("position_trajectory") == start - 400
    assert not plant.due(0.0105, 0.0105)
    assert plant.due(0.0110, 0.0110)  # the clock reached the model's time: the step the write earned is due
    plant.catch_up(0.0110, 0.0110)
    assert plant.firmware.time_s == pytest.approx(0.012)
    assert table.get("present_pwm") < 0  # that step drove towards the second goal
    assert not plant.due(0.0111, 0.0111)


def _goal_then_read(servo: str, write_between_pieces: bool) -> tuple[int, int]:
    """Torque on, a tick of the serving loop in its two pieces (step, copy), a Goal Position write (between the
    pieces, or after the whole tick), then the client's very next read: (Moving, Present PWM or Load)."""
    import struct

    from ax12emu.harness.virtual_bus import VirtualBus
    from ax12emu.protocol.packets2 import encode_instruction2

    x_series = servo != "xl-320"
    torque_at, goal, read = (64, struct.pack("<i", 2548), (122, 4)) if x_series else (24, struct.pack("<H", 700), (37, 13))
    with VirtualBus(servo=servo, ids=[1], transport="inprocess", virtual_time=True, baud_bps=1_000_000) as vb:
        bus = vb.bus
        bus.answer(encode_instruction2(1, 3, struct.pack("<HB", torque_at, 1)))
        bus.clock.advance(0.2)
        bus.advance()
        bus.clock.advance(0.0015)  # the next tick falls due
        pieces = bus.advance_in_pieces()
        next(pieces)  # the step
        goal_packet = encode_instruction2(1, 3, struct.pack("<H", 116 if x_series else 30) + goal)
        if write_between_pieces:
            bus.answer(goal_packet)
        for _ in pieces:  # the copy
            pass
        if not write_between_pieces:
            bus.answer(goal_packet)
        (reply,) = bus.answer(encode_instruction2(1, 2, struct.pack("<HH", *read)))[0]
    params = reply.data[9:-2]
    if x_series:  # Moving(122), Moving Status(123), Present PWM(124)
        return params[0], int.from_bytes(params[2:4], "little", signed=True)
    return params[49 - 37], int.from_bytes(params[41 - 37:43 - 37], "little")  # Moving(49), Present Load(41)


@pytest.mark.parametrize("servo", ["xm430-w350", "xl-320"])
def test_a_write_between_a_ticks_pieces_still_earns_its_step(servo):
    """A serving loop steps the physics in two pieces, answering packets between them. A goal written there was
    marked seen by the copy that followed, so the next read showed the old goal held (Moving 0, no drive), one
    write in five over a pty."""
    after = _goal_then_read(servo, write_between_pieces=False)
    between = _goal_then_read(servo, write_between_pieces=True)
    assert after[0] == 1 and after[1] != 0
    assert between == after


@pytest.mark.parametrize("servo", ["xl430-w250", "xm430-w350", "xl-320", "mx-28"])
def test_each_millisecond_step_of_virtual_time_steps_the_firmware(servo):
    """The clock sums its own floats and the firmware adds a step each step: after step(0.1) the sums differ by
    1e-16, and the test for a whole step due skipped every other 1 ms step (reads repeated in pairs)."""
    from ax12emu.harness.virtual_bus import VirtualBus

    with VirtualBus(servo=servo, ids=[1], transport="inprocess", virtual_time=True, baud_bps=1_000_000) as vb:
        firmware = vb.bus.servos[0].plant.firmware
        vb.write(1, "torque_enable", 1)
        vb.step(0.1)
        behind = []
        for _ in range(20):
            vb.step(0.001)
            behind.append(firmware.time_s < vb.bus.clock.now_s() - 1e-9)
    assert not any(behind)
