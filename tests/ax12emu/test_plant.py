"""Plant: command registers out of the tables, sensed values back into them, alarms applied."""

import pytest

from ax12emu.bus import Bus
from ax12emu.clock import VirtualClock
from firmware_model.interface import Sensed

SENSED = [name for name in Sensed.field_names() if name != "alarms"]


def _step(bus: Bus, steps: int = 1) -> None:
    for _ in range(steps):
        bus.clock.advance(0.001)
        bus.advance()


def test_tables_hold_what_the_model_senses_after_every_step():
    """Every sensed register of every servo equals the model's reading after each step (also when a
    slow register keeps its value and the plant need not copy it again)."""
    bus = Bus([1, 2, 3], clock=VirtualClock())
    wheel, mover, _ = (servo.table for servo in bus.servos)
    for table in (wheel, mover):
        table.set("torque_enable", 1)
    wheel.set("cw_angle_limit", 0)
    wheel.set("ccw_angle_limit", 0)
    wheel.set("moving_speed", 500)
    mover.set("goal_position", 900)
    bus.plant.tables_changed()
    positions = set()
    for step in range(400):
        _step(bus)
        sensed = bus.model.sense()
        positions.add((wheel.get("present_position"), mover.get("present_position")))
        for index, servo in enumerate(bus.servos):
            for name in SENSED:
                assert servo.table.get(name) == getattr(sensed, name)[index], (step, servo.id, name)
            assert servo.alarms == sensed.alarms[index] & 0x7F
    assert len(positions) > 100  # they did move


@pytest.mark.parametrize("announce", ["tables_changed", "refresh"])
def test_a_sensed_register_overwritten_by_someone_else_is_rewritten_once_they_say_so(announce):
    """A writer other than the plant (a test, a fault) announces it; the next step then restores the
    model's value even if the model's reading itself did not change."""
    bus = Bus([1], clock=VirtualClock())
    _step(bus)
    table = bus.servos[0].table
    true_c = table.get("present_temperature")
    table.set("present_temperature", true_c + 20)
    getattr(bus.plant, announce)()
    _step(bus)
    assert table.get("present_temperature") == true_c
