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

import math
from collections import deque

import numpy as np

from .units import DIRECTION_BIT, speed_rad_s_to_raw

__all__ = ["drive_to_load_raw", "held_speed_rad_s", "registers", "DelayLine", "LatchHistory"]


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
        # One byte: a reading past it saturates there (a thermistor's ADC does), never wraps.
        "present_temperature": np.clip(np.rint(np.asarray(temperature_c, dtype=float)), 0, 255).astype(np.int64),
    }


class DelayLine:
    """The shaft angle of the last few steps, read ``delay_steps`` (a fraction allowed) ago.

    Why it exists: a servo whose readings lag the shaft (ADC, firmware loop)
    reports the angle of a moment ago: between two steps it is interpolated
    linearly, before the first step it is the first angle.  The same rule as
    the diagnosis's sensing delay (:func:`firmware_model.diagnose.batch.sample`).
    """

    def __init__(self, delay_steps: float, first_angle_rad: np.ndarray) -> None:
        self.delay_steps = float(delay_steps)
        #: Enough rows for the oldest one read, ``ceil(delay) + 1`` steps back, and the newest.
        self.rows = int(math.ceil(self.delay_steps)) + 2
        first = np.asarray(first_angle_rad, dtype=float)
        self._buf = np.empty((self.rows, first.size))
        self._buf[:] = first
        #: Step of the newest row (0: the starting angle).
        self.step = 0

    def push(self, angle_rad) -> None:
        """The angle after one more step (a float for one servo, or an array (N,))."""
        self.step += 1
        self._buf[self.step % self.rows] = angle_rad

    def repeat(self, count: int) -> None:
        """``count`` steps in which the shaft did not move."""
        last = self._buf[self.step % self.rows].copy()
        for _ in range(min(count, self.rows)):
            self.push(last)
        self.step += max(count - self.rows, 0)  # every row already holds the same angle

    def shift(self, by_rad) -> None:
        """Subtract ``by_rad`` (N,) from every stored angle (a wheel's angle wrapped by whole turns)."""
        self._buf -= np.asarray(by_rad, dtype=float)

    def read(self) -> tuple[np.ndarray, int]:
        """The delayed angle (N,) and the whole step it lies in (for the latched registers)."""
        where = max(self.step - self.delay_steps, 0.0)
        lo = math.floor(where)
        hi = min(lo + 1, self.step)
        a_lo, a_hi = self._buf[lo % self.rows], self._buf[hi % self.rows]
        return a_lo + (a_hi - a_lo) * (where - lo), lo


class LatchHistory:
    """Present Speed / Load latches of the last ``keep`` sample periods, with the step each was taken at.

    Why it exists: with a sensing delay the held registers read are those
    latched at or before the delayed step, not the newest.
    """

    def __init__(self, keep: int, n: int) -> None:
        self._latches: deque[tuple[int, np.ndarray, np.ndarray]] = deque(maxlen=keep)
        self._zeros = np.zeros(n)

    def add(self, step: int, held_speed, held_drive) -> None:
        """A latch taken at ``step``."""
        self._latches.append((step, np.array(held_speed, dtype=float).reshape(-1),
                              np.array(held_drive, dtype=float).reshape(-1)))

    def at(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        """Held speed and drive as read at ``step``: the latest latch taken at or before it (zeros before any)."""
        for taken, speed, drive in reversed(self._latches):
            if taken <= step:
                return speed, drive
        return self._zeros, self._zeros
