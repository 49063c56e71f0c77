"""The setpoint generator: Goal Position and Moving Speed merged into one reference.

Why it exists: the firmware's controller takes one input, a position, while
the bus gives two (where to go, how fast).  The report (section 3.1, figure
3.1) merges them with a state machine that integrates a bounded acceleration
twice: rest (1), accelerate + (2), cruise + (3), accelerate - (4), cruise -
(5), switching on the braking distance ``x_b = v**2 / (2 a)``.

How it is done here: every step each servo picks the velocity it should have,
``v* = sign(e) * min(v_max, v_b(|e|))`` with ``e`` the distance to the goal
and ``v_b`` the discrete braking curve (the highest speed from which whole
steps at ``a`` stop exactly at the goal), and moves its velocity toward
``v*`` by at most ``a * dt``.  That one rule is the report's state machine
written without branches, so it vectorises over N servos, and it covers the
mid-move cases the report lists: a reversed goal (``v*`` has the other sign,
so the servo brakes at ``a`` and comes back), a lower speed (it brakes at
``a`` down to the new cruise), a goal inside the braking distance (it brakes
at ``a``, overshoots, and returns).  :func:`state_code` names the state the
report would be in.

The report needed the dead zone ``eps`` (0.001 rad, below the 0.0051 rad
resolution) because its machine switched on a threshold and chattered around
it.  The rule above has no threshold: the last step lands on the goal with
the speed ``d / dt`` and the next one stops, never exceeding ``a``.  ``eps``
keeps its other meaning, applied by :func:`apply_dead_zone` when commands
change: a goal within ``eps`` of a resting reference counts as reached.

Limits, exactly: ``|dv| <= a dt`` every step; ``|v| <= max(v_max, |v_prev|)``
(after Moving Speed is lowered the reference brakes at ``a`` to the new one).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "REST",
    "ACCEL_POS",
    "CRUISE_POS",
    "ACCEL_NEG",
    "CRUISE_NEG",
    "apply_dead_zone",
    "braking_speed",
    "setpoint_step",
    "setpoint_velocity",
    "state_code",
]

#: The report's state numbers (figure 3.1).
REST, ACCEL_POS, CRUISE_POS, ACCEL_NEG, CRUISE_NEG = 1, 2, 3, 4, 5


def braking_speed(xp, distance_rad, accel_rad_s2: float, step_s: float):
    """Highest speed from which steps of ``accel * step`` stop exactly after ``distance_rad``.

    Whole steps at ``a`` from speed ``n a dt`` cover ``a dt**2 n (n + 1) / 2``;
    solving for ``n`` gives ``a dt (sqrt(1/4 + 2 d / (a dt**2)) - 1/2)``, which
    tends to ``sqrt(2 a d)`` for large distances.  Below one step's worth the
    speed ``d / dt`` that lands exactly is used instead.
    """
    adt = accel_rad_s2 * step_s
    curve = xp.sqrt(0.25 * adt * adt + (2.0 * accel_rad_s2) * distance_rad) - 0.5 * adt
    return xp.minimum(curve, distance_rad * (1.0 / step_s))


def setpoint_velocity(xp, ref_rad, ref_vel_rad_s, goal_rad, max_speed_rad_s, accel_rad_s2: float, step_s: float):
    """The reference's velocity for the next step (the step loop moves the reference and the shaft together)."""
    error = goal_rad - ref_rad
    adt = accel_rad_s2 * step_s
    wanted = xp.copysign(xp.minimum(max_speed_rad_s, braking_speed(xp, xp.abs(error), accel_rad_s2, step_s)), error)
    return ref_vel_rad_s + xp.minimum(xp.maximum(wanted - ref_vel_rad_s, -adt), adt)


def setpoint_step(xp, ref_rad, ref_vel_rad_s, goal_rad, max_speed_rad_s, accel_rad_s2: float, step_s: float):
    """One step of the generator; returns the new ``(ref_rad, ref_vel_rad_s)``."""
    vel = setpoint_velocity(xp, ref_rad, ref_vel_rad_s, goal_rad, max_speed_rad_s, accel_rad_s2, step_s)
    return ref_rad + vel * step_s, vel


def apply_dead_zone(ref_rad, ref_vel_rad_s, goal_rad, eps_rad: float):
    """Take a goal within ``eps`` of a resting reference as reached (once per command change, not per step)."""
    ref_rad = np.asarray(ref_rad, dtype=float)
    close = (np.abs(np.asarray(goal_rad) - ref_rad) <= eps_rad) & (np.asarray(ref_vel_rad_s) == 0)
    return np.where(close, goal_rad, ref_rad)


def state_code(ref_vel_rad_s, prev_vel_rad_s, max_speed_rad_s) -> np.ndarray:
    """The report's state number for each servo, from two successive reference velocities."""
    vel = np.asarray(ref_vel_rad_s, dtype=float)
    accel = vel - np.asarray(prev_vel_rad_s, dtype=float)
    cruising = np.isclose(np.abs(vel), max_speed_rad_s) & np.isclose(accel, 0.0)
    code = np.where(accel > 0, ACCEL_POS, np.where(accel < 0, ACCEL_NEG, REST))
    code = np.where(cruising & (vel > 0), CRUISE_POS, code)
    code = np.where(cruising & (vel < 0), CRUISE_NEG, code)
    return np.where((vel == 0) & (accel == 0), REST, code)

