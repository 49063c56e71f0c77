"""Conversions between AX-12 raw register units and SI, shared by every model.

Sources: ROBOTIS AX-12 e-manual (Goal Position: 0..1023 over 0..300 degrees,
0.29 degree per unit; Moving Speed / Present Speed: 0.111 rpm per unit, bit 10
is the direction; Present Load: 0.1 % per unit, bit 10 the direction).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "POSITION_RANGE_RAD",
    "POSITION_MAX_RAW",
    "RAD_PER_POSITION_UNIT",
    "RAD_S_PER_SPEED_UNIT",
    "DIRECTION_BIT",
    "position_raw_to_rad",
    "position_rad_to_raw",
    "speed_rad_s_to_raw",
    "signed_raw_to_value",
]

#: The potentiometer's linear range: 1023 units span 300 degrees (e-manual).
POSITION_RANGE_RAD = np.deg2rad(300.0)
POSITION_MAX_RAW = 1023
RAD_PER_POSITION_UNIT = POSITION_RANGE_RAD / POSITION_MAX_RAW
#: 0.111 rpm per speed unit (e-manual, Moving Speed).
RAD_S_PER_SPEED_UNIT = 0.111 * 2.0 * np.pi / 60.0
#: Bit 10 of Present Speed / Present Load / wheel-mode Moving Speed: set = CW (decreasing position).
DIRECTION_BIT = 1024


# Python floats: arithmetic with numpy scalars costs more per call (the same values).
_TWO_PI, _UNIT_RAD, _RANGE_RAD = 2.0 * np.pi, float(RAD_PER_POSITION_UNIT), float(POSITION_RANGE_RAD)


def position_raw_to_rad(raw: np.ndarray) -> np.ndarray:
    """Raw position units to radians from the CW end (0 rad = raw 0)."""
    return np.asarray(raw, dtype=float) * RAD_PER_POSITION_UNIT


def position_rad_to_raw(angle_rad: np.ndarray) -> np.ndarray:
    """Angle in [0, 2*pi) to the pot's reading: linear over 300 degrees, clamped in the dead zone.

    Beyond 300 degrees the wiper leaves the linear track (report, section 2.2);
    the reading is pinned to the nearer end, which is what the servo reports
    while the horn passes through the 60 degree gap.
    """
    angle = np.asarray(angle_rad, dtype=float)
    wrapped = np.mod(angle.reshape(-1), _TWO_PI)  # 1-d, so the gap can be zeroed in place
    # On the track and in the gap's upper half this is the reading (past the top it saturates);
    # a point nearer the CW end (0) than the top can only lie in the gap, where it reads 0.
    raw = np.minimum(np.rint(wrapped / _UNIT_RAD), float(POSITION_MAX_RAW))
    raw[(wrapped - _RANGE_RAD) >= (_TWO_PI - wrapped)] = 0.0
    return raw.astype(np.int64).reshape(angle.shape)


def speed_rad_s_to_raw(speed_rad_s: np.ndarray) -> np.ndarray:
    """Signed angular speed to Present Speed's magnitude-plus-direction-bit form."""
    speed = np.asarray(speed_rad_s, dtype=float)
    magnitude = np.minimum(np.rint(np.abs(speed) / RAD_S_PER_SPEED_UNIT), 1023).astype(np.int64)
    return np.where(speed < 0, magnitude | DIRECTION_BIT, magnitude)


def signed_raw_to_value(raw: np.ndarray) -> np.ndarray:
    """Magnitude-plus-direction-bit (bit 10 = CW = negative) to a signed integer."""
    raw = np.asarray(raw, dtype=np.int64)
    magnitude = raw & 0x3FF
    return np.where(raw & DIRECTION_BIT, -magnitude, magnitude)
