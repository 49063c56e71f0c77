"""AX-18As on the Protocol 1.0 bus: the AX-12A's table with model number 18 and the AX-18A's data-sheet physics."""

from __future__ import annotations

import pytest

from ax12emu.bus.bus import Bus
from ax12emu.bus.clock import VirtualClock
from ax12emu.protocol.packets import Instruction, encode_instruction
from ax12emu.protocol.servo_models import model
from ax12emu.servo.model_factory import ModelChoice, build_model, build_protocol1_model, datasheet_params
from firmware_model.grouped import GroupedModel

RPM_PER_POSITION_UNIT_S = (300.0 / 1023.0) / 360.0 * 60.0


def ax18a_bus(ids, voltage_v: float | None = None) -> Bus:
    spec = model("ax-18a")
    physics = build_model(ModelChoice(params=datasheet_params(spec), voltage_v=voltage_v), len(ids))
    return Bus(ids, clock=VirtualClock(), model=physics, table_layout=spec.layout())


def write(bus: Bus, servo_id: int, address: int, *values: int) -> None:
    replies = bus.receive(encode_instruction(servo_id, Instruction.WRITE, bytes([address, *values])))
    assert [reply.data[4] for reply in replies] == ([] if servo_id == 254 else [0])  # a broadcast is not answered


def full_speed_moves(bus: Bus) -> list[list[tuple[float, int]]]:
    """Every servo from 50 to 970 at Moving Speed 0 (as fast as it goes): (time, Present Position) per ms, per servo."""
    for servo in bus.servos:
        servo.table.set("goal_position", 50)
    write(bus, 254, 24, 1)  # torque on, all
    bus.clock.advance(2.0)
    bus.advance()
    write(bus, 254, 30, 970 & 0xFF, 970 >> 8, 0, 0)  # goal 970, Moving Speed 0
    samples: list[list[tuple[float, int]]] = [[] for _ in bus.servos]
    for _ in range(4000):
        bus.clock.advance(1e-3)
        bus.advance()
        for servo, own in zip(bus.servos, samples):
            own.append((bus.clock.now_s(), servo.table.get("present_position")))
    return samples


def mid_stroke_rpm(samples: list[tuple[float, int]]) -> float:
    """Output speed over the middle of the move."""
    window = [(t, p) for t, p in samples if 300 <= p <= 700]
    (t0, p0), (t1, p1) = window[0], window[-1]
    return (p1 - p0) / (t1 - t0) * RPM_PER_POSITION_UNIT_S


def unloaded_speed_rpm(bus: Bus) -> float:
    return mid_stroke_rpm(full_speed_moves(bus)[0])


def test_pings_and_reads_model_number_18():
    bus = ax18a_bus([1, 2])
    assert [s.table.get("model_number") for s in bus.servos] == [18, 18]
    reply = bus.receive(encode_instruction(2, Instruction.READ, bytes([0, 2])))[0].data
    assert reply[2] == 2 and reply[5:7] == bytes([18, 0])


def test_no_load_speed_is_the_data_sheets_and_faster_than_the_ax12a():
    sheet = model("ax-18a").physical.ratings[0]
    ax18 = unloaded_speed_rpm(ax18a_bus([1], voltage_v=sheet.voltage_v))
    assert ax18 == pytest.approx(sheet.no_load_speed_rpm, rel=0.10)
    # The AX-12A's parameters are fitted to measured AX-12As, which run well above their sheet's 59 rpm
    # (87 rpm at 12 V in this model), so the margin is small; the AX-18A is still the faster.
    ax12 = Bus([1], clock=VirtualClock(), model=build_model(ModelChoice(voltage_v=sheet.voltage_v), 1))
    assert unloaded_speed_rpm(ax12) < ax18


def test_a_state_file_of_another_model_is_refused(tmp_path):
    """An AX-12A's saved EEPROM does not turn into an AX-18A's: the state store names the model."""
    from ax12emu.bus.state_store import StateStore

    store = StateStore(tmp_path)
    with Bus([1], clock=VirtualClock(), state_store=store):
        pass
    physics = build_model(ModelChoice(params=datasheet_params(model("ax-18a"))), 1)
    with pytest.raises(ValueError, match="model number 12"):
        Bus([1], clock=VirtualClock(), state_store=store, table_layout=model("ax-18a").layout(), model=physics)


def test_ax12as_and_ax18as_on_one_bus_each_run_their_own_physics():
    """A mixed bus moves each servo exactly as a bus of its model alone does (one model per group, joined)."""
    keys = ["ax-12a", "ax-18a", "ax-12a"]
    choice = ModelChoice(voltage_v=12.0)
    layouts = [None if key == "ax-12a" else model(key).layout() for key in keys]
    mixed = Bus([1, 2, 3], clock=VirtualClock(), model=build_protocol1_model(keys, choice), table_layout=layouts)
    assert isinstance(mixed.model, GroupedModel)
    assert [s.table.get("model_number") for s in mixed.servos] == [12, 18, 12]
    moves = full_speed_moves(mixed)
    alone12 = full_speed_moves(Bus([1], clock=VirtualClock(), model=build_protocol1_model(["ax-12a"], choice)))[0]
    alone18 = full_speed_moves(ax18a_bus([2], voltage_v=12.0))[0]
    assert moves[0] == alone12 and moves[2] == alone12
    assert moves[1] == alone18
    assert mid_stroke_rpm(moves[0]) < mid_stroke_rpm(moves[1])


def test_its_coreless_rotor_is_lighter_and_a_speed_limited_move_comes_in_without_overshoot():
    """The AX-18A's motor is coreless (e-manual), its rotor lighter than the AX-12A's cored one: at Moving Speed 490
    (about half its top speed) the shaft comes into the goal without passing it, as a real AX-18A step does
    (tools/real_ax12a.py), where with the AX-12A's rotor it passed it by about 10 units."""
    spec = model("ax-18a")
    ax12_rotor_kg_m2 = build_model(ModelChoice(), 1).params.rotor_inertia_reflected_kg_m2
    assert datasheet_params(spec).rotor_inertia_reflected_kg_m2 < 0.5 * ax12_rotor_kg_m2
    bus = ax18a_bus([1])
    bus.servos[0].table.set("goal_position", 0)
    write(bus, 1, 24, 1)
    bus.clock.advance(1.0)
    bus.advance()
    write(bus, 1, 30, 500 & 0xFF, 500 >> 8, 490 & 0xFF, 490 >> 8)  # goal 500 at Moving Speed 490
    positions = []
    for _ in range(1500):
        bus.clock.advance(1e-3)
        bus.advance()
        positions.append(bus.servos[0].table.get("present_position"))
    assert max(positions) - positions[-1] <= 1
    assert abs(positions[-1] - 500) <= 3  # the compliance margin and the punch leave it a few units off
