"""Heating and the physical alarms: overheating, overload, input voltage.

Why it exists: the firmware protects the motor, and a client must see the
same alarms a real servo raises when stalled, overloaded or badly supplied.
The model only *raises* the bits (``Sensed.alarms``, layout in
:mod:`firmware_model.interface`); the bus applies the Alarm LED and Alarm
Shutdown masks and turns torque off, as the hardware does.

* Thermal: one lumped node (winding, case and board together, since the
  AX-12's thermometer sits on the board): ``C dT/dt = i**2 R - (T - T_amb) /
  R_th``, integrated exactly over each thermal period with the mean ``i**2``
  of its steps.  Overheating is raised while Present Temperature (whole
  degrees) is above Temperature Limit, as the e-manual words it.
* Overload (precise definition): raised once, for at least
  ``ServoParams.overload_delay_s`` without a break, torque was on, the
  controller *asked* for more drive than Torque Limit allows (its unclipped
  demand above the limit) and the shaft was stalled (speed below
  ``ServoParams.stall_speed_rad_s``).  It clears as soon as that stops.  The
  delay keeps every start of a move (full demand, zero speed for a few
  milliseconds) from counting; the e-manual gives no figure.
* Input voltage: raised while the supply is outside [Min, Max Voltage Limit].
"""

from __future__ import annotations

import numpy as np

from .interface import ALARM_INPUT_VOLTAGE, ALARM_OVERHEATING, ALARM_OVERLOAD

__all__ = ["thermal_step", "overload_timer_step", "alarm_bits"]


def thermal_step(xp, temperature_c, steady_rise_k, ambient_c: float, decay: float):
    """Exact update of the lumped node over one thermal period.

    ``steady_rise_k`` is the rise the period's mean ``i**2 R R_th`` would hold
    in the steady state; ``decay = exp(-period / (R_th C))``.
    """
    steady = ambient_c + steady_rise_k
    return steady + (temperature_c - steady) * decay


def overload_timer_step(xp, timer_s, demand, limit_when_on, speed_rad_s, stall_speed_rad_s: float, period_s: float):
    """Time the overload condition has held without a break, seconds.

    ``limit_when_on`` is Torque Limit as a drive fraction, infinite for a servo
    with torque off (it cannot overload).
    """
    overloaded = (demand > limit_when_on) & (xp.abs(speed_rad_s) < stall_speed_rad_s)
    return xp.where(overloaded, timer_s + period_s, 0.0)


def alarm_bits(present_temperature, temperature_limit, overload_timer_s, overload_delay_s: float,
               supply_v: float, min_voltage_limit, max_voltage_limit) -> np.ndarray:
    """Alarm bits from the present state, arrays of shape (N,)."""
    volts_tenths = int(round(supply_v * 10.0))
    voltage_bad = (volts_tenths < np.asarray(min_voltage_limit)) | (volts_tenths > np.asarray(max_voltage_limit))
    hot = np.asarray(present_temperature) > np.asarray(temperature_limit)
    overload = np.asarray(overload_timer_s) >= overload_delay_s - 1e-9
    return (
        np.where(voltage_bad, ALARM_INPUT_VOLTAGE, 0)
        | np.where(hot, ALARM_OVERHEATING, 0)
        | np.where(overload, ALARM_OVERLOAD, 0)
    ).astype(np.int64)
