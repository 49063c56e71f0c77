"""The position controller: compliance control (the AX-12's) and the report's PID.

Why two: the e-manual describes the AX-12's firmware as compliance control,
and that is the default because it reproduces the data sheet (holding torque,
move time) and the report's overshoot.  The report fitted a PID to its
position data (section 3.2); it stays selectable for comparison.  The report
does not print its gains, so the PID gains here are ours, chosen to give a
comparable overshoot.

Both take the position error in raw units (the firmware sees the quantised
potentiometer, so the Compliance Margin is a real dead band) and return a
*drive*: the PWM duty in [-1, 1], positive toward CCW (increasing position).

Compliance control (e-manual, "Compliance", figure with A..E): no drive
within the margin (B: CW, C: CCW); beyond it the drive starts at Punch (E)
and ramps linearly to full over the slope (A: CW, D: CCW); everything is
clipped to Torque Limit.  The firmware uses the slope register by steps
(e-manual table: 0-3 -> 2, 4-7 -> 4, ... 128-254 -> 128 units), reproduced by
:func:`slope_width_units`.  The *demand* before the clip is returned too: the
overload alarm compares it with the limit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CompliancePlan", "compliance_plan", "compliance_drive", "symmetric_compliance_drive", "slope_width_units", "PidGains", "pid_drive"]


def slope_width_units(slope_raw: np.ndarray) -> np.ndarray:
    """Compliance Slope register to the ramp width in position units: 2, 4, ..., 128."""
    slope = np.maximum(np.asarray(slope_raw, dtype=np.int64), 1)
    level = np.clip(np.floor(np.log2(slope)), 1, 7)
    return np.power(2.0, level)


@dataclass
class CompliancePlan:
    """Compliance registers turned into per-direction constants, once per ``advance``."""

    #: Dead band either side, position units.
    cw_margin: np.ndarray
    ccw_margin: np.ndarray
    #: Drive per unit of error beyond the margin, fraction of full per unit.
    cw_gain: np.ndarray
    ccw_gain: np.ndarray
    #: Punch as a fraction of full drive.
    punch: np.ndarray
    #: Torque Limit as a fraction of full drive.
    limit: np.ndarray


def compliance_plan(cw_margin, ccw_margin, cw_slope, ccw_slope, punch, torque_limit) -> CompliancePlan:
    """Precompute the compliance constants from raw registers (arrays of shape (N,))."""
    punch_frac = np.minimum(np.asarray(punch, dtype=float), 1023.0) / 1023.0
    return CompliancePlan(
        cw_margin=np.asarray(cw_margin, dtype=float),
        ccw_margin=np.asarray(ccw_margin, dtype=float),
        cw_gain=(1.0 - punch_frac) / slope_width_units(cw_slope),
        ccw_gain=(1.0 - punch_frac) / slope_width_units(ccw_slope),
        punch=punch_frac,
        limit=np.minimum(np.asarray(torque_limit, dtype=float), 1023.0) / 1023.0,
    )


def compliance_drive(xp, error_units, cw_margin, ccw_margin, cw_gain, ccw_gain, punch, limit):
    """Drive for a position error (goal minus present, units); returns ``(drive, demand)``.

    ``demand`` is the unclipped magnitude the compliance curve asks for (it
    exceeds 1 far from the goal); ``drive`` is signed and clipped to ``limit``.
    """
    ccw = error_units > 0
    beyond = xp.abs(error_units) - xp.where(ccw, ccw_margin, cw_margin)
    demand = (punch + beyond * xp.where(ccw, ccw_gain, cw_gain)) * (beyond > 0)
    return xp.minimum(demand, limit) * xp.sign(error_units), demand


def symmetric_compliance_drive(xp, error_units, margin, gain, punch, limit):
    """:func:`compliance_drive` when CW and CCW registers agree (the usual case): fewer operations."""
    beyond = xp.abs(error_units) - margin
    demand = (punch + beyond * gain) * (beyond > 0)
    return xp.minimum(demand, limit) * xp.sign(error_units), demand


@dataclass(frozen=True)
class PidGains:
    """Gains of the report's PID (section 3.2), on the error in radians, output in duty."""

    #: Proportional gain, duty per radian.
    kp_per_rad: float = 9.0
    #: Integral gain, duty per radian-second.
    ki_per_rad_s: float = 30.0
    #: Derivative gain, duty per radian per second.
    kd_s_per_rad: float = 0.12
    #: Anti-windup bound on the integral term, duty.
    integral_limit: float = 0.5


def pid_drive(xp, error_rad, integral, prev_error_rad, step_s: float, gains: PidGains, limit):
    """One PID step; returns ``(drive, demand, integral)`` with the integral clamped against windup."""
    integral = xp.minimum(
        xp.maximum(integral + gains.ki_per_rad_s * error_rad * step_s, -gains.integral_limit), gains.integral_limit
    )
    raw = gains.kp_per_rad * error_rad + integral + gains.kd_s_per_rad * (error_rad - prev_error_rad) / step_s
    demand = xp.abs(raw)
    drive = xp.minimum(xp.maximum(raw, -limit), limit)
    return drive, demand, integral
