"""Motor, gearbox, friction and load: the drive in, the shaft's motion out.

Why it exists: it is where the supply voltage turns into torque, so top speed
and stall torque scale with voltage, and where the shaft sticks and slips.
Everything is referred to the output shaft (see :mod:`firmware_model.params`
for the constants and their derivation):

* Motor: the H-bridge applies ``drive * V`` (averaged PWM; the winding
  inductance is neglected, as in the report's figure 3.3, because its time
  constant is far below a step).  Current ``i = (drive V - k w) / R``, torque
  at the output ``eta k i``.  With torque off the bridge is open: ``i = 0``.
* Friction: static ``t_s`` at rest; sliding ``sign(w) (t_c + (t_s - t_c)
  exp(-(w / v_s)**2)) + b w`` (Coulomb, Stribeck, viscous).
* Load: the reflected rotor inertia plus the load's, an external torque (set
  from Python or the CLI) and optionally an arm's gravity.

Stick-slip without chatter (Karnopp's method): a shaft at exactly zero speed
stays there while the applied torque is within static friction, because the
friction it would need is available; a sliding shaft whose speed would change
sign within a step stops at zero instead and sticks.  So "stuck" is simply
``w == 0``, and no speed ever flips back and forth around zero.

Arm gravity convention: the arm points horizontally at the centre position
(raw 512, 150 degrees) and turns in a vertical plane with CCW (increasing
position) lifting it, so gravity's torque is ``-m g L cos(angle - centre)``:
strongest (pulling CW) at the centre, zero with the arm straight up or down.
"""

from __future__ import annotations

from .units import POSITION_RANGE_RAD

__all__ = ["GRAVITY_M_S2", "ARM_HORIZONTAL_RAD", "motor_current_a", "arm_gravity_torque_nm", "mechanics_step"]

#: Standard gravity.
GRAVITY_M_S2 = 9.80665
#: Shaft angle at which the arm is horizontal: the centre of the range, raw 512.
ARM_HORIZONTAL_RAD = float(POSITION_RANGE_RAD * 512.0 / 1023.0)


def motor_current_a(drive, supply_v, speed_rad_s, torque_constant: float, resistance_ohm: float):
    """Winding current from the averaged PWM voltage and the back-EMF."""
    return (drive * supply_v - torque_constant * speed_rad_s) / resistance_ohm


def arm_gravity_torque_nm(xp, angle_rad, weight_moment_nm):
    """Gravity on an arm of weight moment ``m g L`` (see the module docstring for the convention)."""
    return -weight_moment_nm * xp.cos(angle_rad - ARM_HORIZONTAL_RAD)


def mechanics_step(
    xp, angle_rad, speed_rad_s, applied_nm, static_nm: float, coulomb_nm: float, viscous_nm_s_rad: float,
    stribeck_velocity_rad_s: float, step_over_inertia: float, step_s: float,
):
    """Advance the shaft one step under ``applied_nm`` (all torque but friction); returns ``(angle, speed)``.

    The friction's direction is the speed's, or at rest the applied torque's
    (the huge factor makes any non-zero speed win).  A speed that would cross
    or reach zero is set to zero: the shaft sticks.
    """
    direction = xp.sign(speed_rad_s * 1e12 + applied_nm)
    stribeck = xp.exp(speed_rad_s * speed_rad_s * (-1.0 / (stribeck_velocity_rad_s * stribeck_velocity_rad_s)))
    friction = direction * (coulomb_nm + (static_nm - coulomb_nm) * stribeck)
    if viscous_nm_s_rad:
        friction = friction + viscous_nm_s_rad * speed_rad_s
    speed = speed_rad_s + (applied_nm - friction) * step_over_inertia
    speed = speed * (speed * direction > 0.0)
    return angle_rad + speed * step_s, speed
