"""Heating and alarms, through the physical model."""

import numpy as np
import pytest

from firmware_model.interface import ALARM_INPUT_VOLTAGE, ALARM_OVERHEATING, ALARM_OVERLOAD
from firmware_model.physical import PhysicalModel


def test_stall_heats_to_the_overheating_alarm_and_cools(commands):
    """Stalled at full drive (9.6 V: 1.5 A, 14.6 W) the temperature passes 70 C within 30-90 s; torque off, it cools."""
    model = PhysicalModel(1)
    model.set_external_torque(-1.55)  # just below holding torque: the shaft stands still, full drive
    cmds = commands(goal_position=1000)
    times = []
    for second in range(1, 91):
        sensed = model.advance(float(second), cmds)
        assert model.speed_rad_s[0] == 0.0 or second < 2
        if sensed.alarms[0] & ALARM_OVERHEATING:
            times.append(second)
    assert 30 <= times[0] <= 90
    assert sensed.present_temperature[0] > 70
    hot = model.temperature_c[0]
    model.set_external_torque(0.0)
    sensed = model.advance(model.time_s + 300.0, commands(torque_enable=0))
    assert model.temperature_c[0] < hot - 20 and not sensed.alarms[0] & ALARM_OVERHEATING


def test_overload_needs_a_stalled_demand_above_the_limit(commands):
    """Torque Limit 30 % against an obstacle: overload after 0.5 s; a free move at full demand never raises it."""
    model = PhysicalModel(1)
    model.set_external_torque(-0.5)  # 30 % drive (0.42 N m) plus static friction hold it: a stall
    cmds = commands(goal_position=900, torque_limit=300)
    assert not model.advance(0.4, cmds).alarms[0] & ALARM_OVERLOAD
    assert model.advance(1.0, cmds).alarms[0] & ALARM_OVERLOAD
    free = PhysicalModel(1)
    for i in range(1, 101):
        assert not free.advance(i * 0.01, commands(goal_position=1000 if i < 50 else 20)).alarms[0] & ALARM_OVERLOAD


@pytest.mark.parametrize(("volts", "low", "high", "alarm"), [(9.6, 60, 140, False), (9.6, 100, 140, True), (12.0, 60, 110, True)])
def test_input_voltage_alarm(volts, low, high, alarm, commands):
    """Input-voltage bit while the supply is outside [Min, Max Voltage Limit] (0.1 V units)."""
    model = PhysicalModel(2)
    model.set_supply_voltage(volts)
    sensed = model.advance(0.01, commands(2, min_voltage_limit=low, max_voltage_limit=high))
    assert bool(sensed.alarms[0] & ALARM_INPUT_VOLTAGE) == alarm
    assert np.all(sensed.present_voltage == round(volts * 10))
