"""The X-series trajectory profile: what Position Trajectory (140) and Velocity Trajectory (136) follow after a goal write.

Why a separate module: the profile is pure kinematics, planned once per goal write and then read at
every control step, so it is planned analytically (a few constant-acceleration segments) rather than
integrated step by step: the step costs one segment lookup, and the timing matches the e-manual's
formulas exactly instead of drifting by a sample per phase.

Source: ROBOTIS e-manual, X-series "Profile Velocity(112)", "Profile Acceleration(108)" and "What is
the Profile" (https://emanual.robotis.com/docs/en/dxl/x/xm430-w350/#profile-velocity112 and
#what-is-the-profile, text in github.com/ROBOTIS-GIT/emanual _includes/en/dxl/profile_description.md
and _includes/dxl/control_table_profile_velocity.md):

* Velocity-based profile (Drive Mode bit 2 = 0): Profile Velocity V (0.229 rpm) caps the speed,
  Profile Acceleration A (214.577 rev/min^2) the acceleration.  V = 0: no profile (step: the
  trajectory jumps to the goal).  A = 0 with V != 0: rectangular profile (speed jumps to V).
  Otherwise the acceleration time is t1 = 64 * V / A ms and the travel time t3 = t1 + t2 with
  t2 = 64 * dPos / V ms; when the distance is too short to reach V (V_PRFL_TRI <= V) the profile is
  triangular.  In these units 1/64 pulse/ms is one velocity unit and 1/4096 pulse/ms^2 one
  acceleration unit (0.229 * 4096 / 60000 = 0.01563 ~ 1/64; 214.577 * 4096 / 60000^2 = 2.44e-4 ~
  1/4096), so V_PRFL_TRI = sqrt(A * dPos) in velocity units: the trapezoid needs t2 >= t1.
* Time-based profile (Drive Mode bit 2 = 1): Profile Velocity is the whole travel time t3 in ms and
  Profile Acceleration the acceleration time t1 in ms, t1 at most half of t3 (the e-manual: "will not
  exceed 50% of the configured Profile Velocity").  t3 = 0 means no profile (step).
* Velocity override: a goal written while moving plans from the present trajectory velocity, so
  the velocity stays continuous.

The e-manual notes the real firmware also limits jerk, so its travel can end a little after t3; this
profile has no jerk limit (a known difference: it ends at t3 exactly).

Units here: position in pulses (4096 per turn), velocity pulses/s, acceleration pulses/s^2, time s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "PROFILE_STEP",
    "PROFILE_RECTANGULAR",
    "PROFILE_TRIANGULAR",
    "PROFILE_TRAPEZOIDAL",
    "VELOCITY_UNIT_PULSES_S",
    "ACCEL_UNIT_PULSES_S2",
    "Profile",
    "plan_velocity_based",
    "plan_time_based",
]

#: Moving Status (123) profile-type bits (e-manual, "Moving Status(123)": 0x30 trapezoidal,
#: 0x20 triangular, 0x10 rectangular, 0x00 no profile).
PROFILE_STEP = 0x00
PROFILE_RECTANGULAR = 0x10
PROFILE_TRIANGULAR = 0x20
PROFILE_TRAPEZOIDAL = 0x30

#: One velocity unit (0.229 rpm) in pulses per second.
VELOCITY_UNIT_PULSES_S = 0.229 * 4096.0 / 60.0
#: One velocity-based Profile Acceleration unit (214.577 rev/min^2) in pulses per second squared.
ACCEL_UNIT_PULSES_S2 = 214.577 * 4096.0 / 3600.0


@dataclass
class Profile:
    """A planned trajectory: constant-acceleration segments from ``start_pulses`` at time 0.

    ``segments`` holds ``(end_s, accel_pulses_s2)`` in order; between ``segments[i-1].end_s`` and
    ``segments[i].end_s`` the acceleration is constant.  After the last segment the trajectory rests
    at ``goal_pulses``.
    """

    start_pulses: float
    start_velocity_pulses_s: float
    goal_pulses: float
    segments: tuple[tuple[float, float], ...]
    #: Moving Status (123) profile-type bits for this plan.
    kind: int

    def __post_init__(self) -> None:
        # Precompute the state at each segment start so ``at`` is one lookup and a few multiplies.
        starts = []
        t0, p, v = 0.0, self.start_pulses, self.start_velocity_pulses_s
        for end_s, a in self.segments:
            starts.append((t0, p, v))
            dt = end_s - t0
            p += v * dt + 0.5 * a * dt * dt
            v += a * dt
            t0 = end_s
        self._starts = starts
        self.end_s = t0

    def at(self, t_s: float) -> tuple[float, float, float]:
        """Trajectory ``(position_pulses, velocity_pulses_s, accel_pulses_s2)`` at ``t_s`` after the plan's start."""
        if t_s >= self.end_s:
            return self.goal_pulses, 0.0, 0.0
        for (t0, p, v), (end_s, a) in zip(self._starts, self.segments):
            if t_s < end_s:
                dt = t_s - t0
                return p + v * dt + 0.5 * a * dt * dt, v + a * dt, a
        return self.goal_pulses, 0.0, 0.0  # not reached: t_s < end_s means some segment holds it


def _step(start_pulses: float, goal_pulses: float) -> Profile:
    return Profile(start_pulses, 0.0, goal_pulses, (), PROFILE_STEP)


def plan_velocity_based(
    start_pulses: float, start_velocity_pulses_s: float, goal_pulses: float, profile_velocity: int, profile_acceleration: int
) -> Profile:
    """Plan a velocity-based profile from raw Profile Velocity (0.229 rpm) and Profile Acceleration (214.577 rev/min^2)."""
    if profile_velocity <= 0:
        return _step(start_pulses, goal_pulses)
    v_max = profile_velocity * VELOCITY_UNIT_PULSES_S
    distance = goal_pulses - start_pulses
    if profile_acceleration <= 0:
        # Rectangular: the speed jumps to V and drops to 0 at the goal; an override's old speed is dropped too.
        if distance == 0.0:
            return _step(start_pulses, goal_pulses)
        t2 = abs(distance) / v_max
        v = math.copysign(v_max, distance)
        return Profile(start_pulses, v, goal_pulses, ((t2, 0.0),), PROFILE_RECTANGULAR)
    a_max = profile_acceleration * ACCEL_UNIT_PULSES_S2
    segments: list[tuple[float, float]] = []
    t = 0.0
    p, v = start_pulses, start_velocity_pulses_s
    # An override moving away from the goal, or too fast to stop before it: brake to rest first
    # (the trajectory then comes back), keeping the velocity continuous.
    if v != 0.0 and (distance * v < 0.0 or v * v / (2.0 * a_max) > abs(distance)):
        t_stop = abs(v) / a_max
        a = -math.copysign(a_max, v)
        p += v * t_stop / 2.0
        t += t_stop
        segments.append((t, a))
        v = 0.0
        distance = goal_pulses - p
    if distance == 0.0:
        if not segments:
            return _step(start_pulses, goal_pulses)
        return Profile(start_pulses, start_velocity_pulses_s, goal_pulses, tuple(segments), PROFILE_TRAPEZOIDAL)
    sign = 1.0 if distance > 0 else -1.0
    d = abs(distance)
    u0 = abs(v)
    # Peak of a triangle from u0 up and down to rest over d: d = (vp^2 - u0^2)/2a + vp^2/2a.
    v_tri = math.sqrt(a_max * d + u0 * u0 / 2.0)
    if v_tri <= v_max:
        v_peak, kind = v_tri, PROFILE_TRIANGULAR
    else:
        v_peak, kind = v_max, PROFILE_TRAPEZOIDAL
    t_first = abs(v_peak - u0) / a_max
    d_first = abs(v_peak * v_peak - u0 * u0) / (2.0 * a_max)
    t_last = v_peak / a_max
    d_last = v_peak * v_peak / (2.0 * a_max)
    t_cruise = max(d - d_first - d_last, 0.0) / v_peak
    if t_first > 0.0:
        t += t_first
        segments.append((t, sign * a_max if v_peak >= u0 else -sign * a_max))
    if t_cruise > 0.0:
        t += t_cruise
        segments.append((t, 0.0))
    t += t_last
    segments.append((t, -sign * a_max))
    return Profile(start_pulses, start_velocity_pulses_s, goal_pulses, tuple(segments), kind)


def plan_time_based(
    start_pulses: float, start_velocity_pulses_s: float, goal_pulses: float, profile_velocity: int, profile_acceleration: int
) -> Profile:
    """Plan a time-based profile: raw Profile Velocity is the travel time t3 (ms), Profile Acceleration the acceleration time t1 (ms).

    The acceleration time is capped at half the travel time (e-manual).  From an initial velocity
    v0 the plan ramps from v0 to the cruise speed in t1, cruises, and ramps down to rest in t1,
    arriving at t3: ``d = (v0 + vp) t1 / 2 + vp (t3 - 2 t1) + vp t1 / 2`` gives ``vp``.
    """
    if profile_velocity <= 0:
        return _step(start_pulses, goal_pulses)
    t3 = profile_velocity / 1000.0
    t1 = min(max(profile_acceleration, 0), profile_velocity // 2) / 1000.0
    distance = goal_pulses - start_pulses
    v0 = start_velocity_pulses_s
    if t1 <= 0.0:
        if distance == 0.0:
            return _step(start_pulses, goal_pulses)
        return Profile(start_pulses, distance / t3, goal_pulses, ((t3, 0.0),), PROFILE_RECTANGULAR)
    v_peak = (distance - v0 * t1 / 2.0) / (t3 - t1)
    segments = [(t1, (v_peak - v0) / t1)]
    if t3 - 2.0 * t1 > 0.0:
        segments.append((t3 - t1, 0.0))
    segments.append((t3, -v_peak / t1))
    return Profile(start_pulses, v0, goal_pulses, tuple(segments), PROFILE_TRAPEZOIDAL)
