"""Motor, gearbox, friction and load: the drive in, the shaft's motion out.

Why it exists: it is where the supply voltage turns into torque, so top speed
and stall torque scale with voltage, and where the shaft sticks and slips.
Everything is referred to the output shaft (see :mod:`firmware_model.params`
for the constants and their derivation):

* Motor: the H-bridge applies ``drive * V`` (averaged PWM; the winding
  inductance is neglected, as in the report's figure 3.3, because its time
  constant is far below a step).  Current ``i = (drive V - k w) / R``, torque
  at the output ``eta k i``.  With torque off the bridge is open: ``i = 0``.
* Bridge decay (:func:`bridge_current_a`): the current flows only in the
  direction the bridge drives.  While the shaft turns faster than the duty
  would hold it (the back-EMF above ``drive V``, as when the compliance slope
  lowers the duty near the goal), the current that would brake it has to
  return through the switches that are off, and the freewheeling diodes block
  it: the motor coasts, and brakes only once the drive reverses.  A real
  AX-12A at full speed keeps its speed into the slope and overshoots by about
  4 % of a 500-unit step, more with more inertia (``tools/real_ax12a.py``);
  a bridge that shorted the winding (synchronous, "slow decay") would stop
  it within a few units.  ``ServoParams.bridge_braking_fraction`` blends the
  two: 0 coasts (the default), 1 brakes with the full back-EMF current.
  Only up to the rail: a shaft a load turns faster than the supply could
  drive it generates more than the supply, and the diodes then conduct
  whatever the duty (:func:`rail_current_a`), so an overhauling load (a
  wheel pushed downhill, an arm falling) brakes there instead of running away.
  The step kernels take this term only with such a load on (an external
  torque or an arm; without one the drive cannot turn a shaft past its rail,
  and the term cost the physics 6-14 % of its speed for zeros): a
  supply lowered under a fast shaft is the one case left unbraked.
* Friction: static ``t_s`` at rest; sliding ``sign(w) (t_c + (t_s - t_c)
  exp(-(w / v_s)**2)) + b w`` (Coulomb, Stribeck, viscous).
* Load: the reflected rotor inertia plus the load's, an external torque (set
  from Python or the CLI) and optionally an arm's gravity.

Stick-slip without chatter (dry friction taken implicitly, as a proximal
step): each step the shaft first gets the speed every torque but dry friction
would give it, ``z``; dry friction then removes up to its whole impulse for
the step, ``F dt / J``, but never more than ``|z|``: ``w' = z - sign(z)
min(|z|, F dt / J)``.  ``F`` is the static torque at rest and the Coulomb
plus Stribeck torque while sliding (taken at the step's starting speed).  So
a shaft at rest stays at exactly zero while the applied torque is within
static friction, a sliding shaft whose friction would carry it past zero
stops there, and friction never turns a motion round by itself: no speed
flips back and forth around zero, and "stuck" is simply ``w == 0``.  It
replaced Karnopp's method, which needs a direction test and a clamp (three
numpy calls more per step).  One difference: Karnopp stopped a shaft for a
step whenever its speed would change sign, where this lets a push stronger
than friction turn it round within the step, against the sliding friction of
the starting speed.

Arm gravity convention: the arm points horizontally at the centre position
(raw 512, 150 degrees) and turns in a vertical plane with CCW (increasing
position) lifting it, so gravity's torque is ``-m g L cos(angle - centre)``:
strongest (pulling CW) at the centre, zero with the arm straight up or down.
"""

from __future__ import annotations

from dataclasses import dataclass

from .units import POSITION_RANGE_RAD

__all__ = ["GRAVITY_M_S2", "ARM_HORIZONTAL_RAD", "motor_current_a", "rail_current_a", "bridge_current_a", "arm_gravity_torque_nm", "DryFriction", "shaft_speed_step"]

#: Standard gravity.
GRAVITY_M_S2 = 9.80665
#: Shaft angle at which the arm is horizontal: the centre of the range, raw 512.
ARM_HORIZONTAL_RAD = float(POSITION_RANGE_RAD * 512.0 / 1023.0)


def motor_current_a(drive, supply_v, speed_rad_s, torque_constant: float, resistance_ohm: float):
    """Winding current from the averaged PWM voltage and the back-EMF."""
    return (drive * supply_v - torque_constant * speed_rad_s) / resistance_ohm


def rail_current_a(xp, emf_a, supply_a):
    """What the freewheeling diodes carry back to the supply once the back-EMF exceeds it, as currents
    (``emf_a = k w / R``, ``supply_a = V / R``): ``-sign(e) max(|e| - V, 0) / R``, zero below the rail.

    A shaft that a load turns faster than the supply could drive it (an overhauling load) generates
    more than the supply's voltage, and the diodes across the switches conduct whatever the PWM does.
    """
    return -xp.copysign(xp.maximum(xp.abs(emf_a) - supply_a, 0.0), emf_a)


def bridge_current_a(current_a, drive, braking_fraction: float, rail_a=None):
    """The share of ``current_a`` the H-bridge passes at ``drive`` (see the module docstring).

    Current in the drive's direction flows; current against it (braking, or any
    current at zero drive) is scaled by ``braking_fraction``: 0 blocks it (the
    motor coasts), 1 passes it all.  Where it is blocked, ``rail_a``
    (:func:`rail_current_a`; None: none) flows instead, on the blocked share.
    Works on floats and on numpy arrays alike (``current * drive > 0`` is a
    bool, multiplied as 0 or 1).
    """
    passes = current_a * drive > 0
    if braking_fraction == 0.0:
        out = current_a * passes
        return out if rail_a is None else out + rail_a * (1.0 - passes)
    out = current_a * (braking_fraction + (1.0 - braking_fraction) * passes)
    return out if rail_a is None else out + rail_a * ((1.0 - braking_fraction) * (1.0 - passes))


def arm_gravity_torque_nm(xp, angle_rad, weight_moment_nm):
    """Gravity on an arm of weight moment ``m g L`` (see the module docstring for the convention)."""
    return -weight_moment_nm * xp.cos(angle_rad - ARM_HORIZONTAL_RAD)


@dataclass(frozen=True)
class DryFriction:
    """Dry friction as speed changes per step (torque times step over inertia), the form the step uses."""

    #: Static friction's impulse per step over inertia, rad/s.
    static_dv_rad_s: float
    #: Coulomb friction's, rad/s.
    coulomb_dv_rad_s: float
    #: ``-1 / v_s**2`` of the Stribeck term ``exp(-(w / v_s)**2)``, s**2/rad**2.
    stribeck_coef_s2_rad2: float

    @classmethod
    def per_step(cls, static_nm, coulomb_nm, stribeck_velocity_rad_s, step_over_inertia) -> "DryFriction":
        """From torques (N m) and ``step / inertia``; scalars, or arrays of K parameter sets."""
        return cls(static_nm * step_over_inertia, coulomb_nm * step_over_inertia,
                   -1.0 / (stribeck_velocity_rad_s * stribeck_velocity_rad_s))


def shaft_speed_step(xp, speed_rad_s, applied_dv_rad_s, friction: DryFriction, viscous_keep=None):
    """The shaft's speed after one step (see the module docstring).

    ``applied_dv_rad_s`` is the speed change all torques but friction give in
    the step (torque times step over inertia); ``viscous_keep`` is ``1 - b
    step / J``, the share of the speed viscous friction leaves (None: no
    viscous friction).
    """
    free = (speed_rad_s if viscous_keep is None else speed_rad_s * viscous_keep) + applied_dv_rad_s
    dry = friction.coulomb_dv_rad_s + (friction.static_dv_rad_s - friction.coulomb_dv_rad_s) * xp.exp(
        speed_rad_s * speed_rad_s * friction.stribeck_coef_s2_rad2)
    return free - xp.copysign(xp.minimum(xp.abs(free), dry), free)
