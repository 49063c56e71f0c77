"""Register conversions of the sensors module."""

import numpy as np

from firmware_model.sensors import drive_to_load_raw, held_speed_rad_s, registers
from firmware_model.units import position_rad_to_raw


def test_load_is_drive_in_tenths_of_percent_with_cw_bit():
    """e-manual Present Load: 0.1 % units, bit 10 set for CW (negative) drive."""
    assert drive_to_load_raw(np.array([0.0, 0.5, -0.5, 1.0, -1.0])).tolist() == [0, 512, 1024 | 512, 1023, 1024 | 1023]


def test_held_speed_is_mean_over_the_period():
    """The firmware differentiates the pot over its sample period."""
    assert held_speed_rad_s(np.array([1.5]), np.array([1.0]), 0.1)[0] == 5.0


def test_registers_quantise_and_pin_dead_zone():
    """Position 0..1023 over 300 degrees, pinned to an end in the 60-degree gap; voltage in 0.1 V; temperature rounded."""
    angles = np.deg2rad([0.0, 512 * 300 / 1023, 300.0, 310.0, 355.0])
    assert position_rad_to_raw(angles).tolist() == [0, 512, 1023, 1023, 0]
    regs = registers(np.zeros(5), np.zeros(5), 9.6, np.full(5, 30.4))
    assert regs["present_voltage"].tolist() == [96] * 5
    assert regs["present_temperature"].tolist() == [30] * 5
