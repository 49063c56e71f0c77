"""What the firmware reports: quantised position, held speed and load, voltage, temperature.

Why it exists: a client sees the servo only through these registers, and
their quirks are part of the behaviour to reproduce.

* Present Position: the potentiometer through the 10-bit ADC, 1023 units over
  300 degrees, pinned to an end while the shaft is in the 60-degree dead zone
  (:func:`firmware_model.units.position_rad_to_raw`).  Fresh every step.
* Present Speed and Present Load: updated only once per sample period (the
  report, figure 2.5: 9-10 equal samples at 100 Hz, so about 0.1 s; another
  study reports about 130 ms; it is ``ServoParams.sample_hold_s``) and held
  in between.  The speed is the position difference over the last period
  divided by the period, as firmware without a tachometer has to do it, so it
  is the mean speed of the previous period and lags the position, as the
  report saw (section 5).
* Present Load: the servo has no current sensor (report, section 2.2: no
  shunt found), and the e-manual defines Present Load as the drive: so it is
  the controller's output at the sample instant, in 0.1 % of full (1023 =
  100 %), bit 10 set for a CW (negative) drive.
* Present Voltage in 0.1 V, Present Temperature in whole degrees C.
"""

from __future__ import annotations

import numpy as np

from .units import DIRECTION_BIT, speed_rad_s_to_raw

__all__ = ["drive_to_load_raw", "held_speed_rad_s", "registers"]


def held_speed_rad_s(angle_rad, angle_at_last_sample_rad, period_s: float):
    """Mean speed over the sample period that just ended (what the next period will report)."""
    return (angle_rad - angle_at_last_sample_rad) / period_s


def drive_to_load_raw(drive: np.ndarray) -> np.ndarray:
    """Signed drive in [-1, 1] to Present Load: magnitude in 0.1 %, bit 10 for CW."""
    drive = np.asarray(drive, dtype=float)
    magnitude = np.minimum(np.rint(np.abs(drive) * 1023.0), 1023).astype(np.int64)
    return np.where(drive < 0, magnitude | DIRECTION_BIT, magnitude)


def registers(held_speed, held_drive, supply_v: float, temperature_c) -> dict[str, np.ndarray]:
    """Raw Present Speed / Load / Voltage / Temperature for arrays of shape (N,) (position: units.position_rad_to_raw)."""
    n = np.shape(held_speed)[0]
    return {
        "present_speed": speed_rad_s_to_raw(held_speed),
        "present_load": drive_to_load_raw(held_drive),
        "present_voltage": np.full(n, int(round(supply_v * 10.0)), dtype=np.int64),
        "present_temperature": np.rint(np.asarray(temperature_c, dtype=float)).astype(np.int64),
    }
