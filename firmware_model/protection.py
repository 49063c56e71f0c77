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
  controller's drive was at its limit (its unclipped demand, above zero, at
  or above Torque Limit: the e-manual's "the current load cannot be
  controlled with the set maximum torque") and the load won: the shaft
  stalled (speed below ``ServoParams.stall_speed_rad_s``) or turned against
  the drive.  At or above, not above: a wheel at full output asks for
  exactly Torque Limit 1023 and no more, and a blocked one must still trip;
  against the drive: a load the servo cannot hold turns the shaft back at
  full drive.  It clears as soon as that stops.  The delay keeps every start
  of a move (full demand, zero speed for a few milliseconds) and every
  reversal (full drive while the shaft still turns the old way) from
  counting; the e-manual gives no figure.
* Alarm Shutdown acts at the control step an alarm it selects is found
  (:class:`~firmware_model.physical.PhysicalModel` cuts its own drive limit
  there and reports the cut, ``Sensed.output_cut``); the bus writes it into
  the table.
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


def overload_timer_step(xp, timer_s, demand, limit_when_on, drive, speed_rad_s, stall_speed_rad_s: float,
                        period_s: float):
    """Time the overload condition has held without a break, seconds.

    ``limit_when_on`` is Torque Limit as a drive fraction, infinite for a servo
    with torque off (it cannot overload); ``drive`` the signed output (its sign
    says which way the motor pushes).
    """
    saturated = (demand >= limit_when_on) & (demand > 0.0)
    # The load wins: the shaft stalls, or turns against the drive, or no drive is allowed at all (Torque Limit 0).
    beaten = (xp.abs(speed_rad_s) < stall_speed_rad_s) | (speed_rad_s * drive < 0.0) | (limit_when_on <= 0.0)
    return xp.where(saturated & beaten, timer_s + period_s, 0.0)


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
