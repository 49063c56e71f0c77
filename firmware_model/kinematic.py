"""The first honest motion model: constant-speed moves, no dynamics.

Why it exists: it gives the bus a servo that moves and answers truthfully
(Moving, Present Position, Present Speed) before the physical model is in.
It is a fixed-step integrator like the physical one, so it runs the same in
virtual and wall-clock time.

What it models: with torque on, in joint mode (an angle limit non-zero) the
shaft moves toward Goal Position at Moving Speed x 0.111 rpm (0 means the
maximum, 114 rpm, per the e-manual); in wheel mode (both angle limits 0) it
turns endlessly, bit 10 the direction, at Moving Speed's share of the output
times 114 rpm: an ideal motor, whose speed is in proportion to the output
(so Present Speed reads the same number the physical model's does, the
output, though Present Load reads 0).  With torque off
it stays where it is.  What it does not model: acceleration, load, friction,
heating (Present Load reads 0 and the temperature stays at ambient).
"""

from __future__ import annotations

import numpy as np

from .interface import STEP_SLACK, Commands, Sensed
from .units import (
    DIRECTION_BIT,
    RAD_PER_POSITION_UNIT,
    RAD_S_PER_SPEED_UNIT,
    position_rad_to_raw,
    speed_rad_s_to_raw,
)

__all__ = ["KinematicModel"]

#: 114 rpm, what Moving Speed 0 means in joint mode (e-manual, Moving Speed).
MAX_SPEED_RAD_S = 114.0 * 2.0 * np.pi / 60.0


class KinematicModel:
    """N servos moving at commanded speed, integrated at a fixed step."""

    def __init__(
        self,
        n: int,
        *,
        step_s: float = 1e-3,
        initial_position_raw: int | np.ndarray = 512,
        supply_voltage_v: float = 9.6,
        ambient_temperature_c: float = 30.0,
    ) -> None:
        if n < 1:
            raise ValueError(f"need at least one servo, got n={n}")
        if not 0 < step_s < float("inf"):  # (NaN passed, to fail at the first step)
            raise ValueError(f"step_s must be positive, got {step_s}")
        self.n = n
        self.step_s = step_s
        self.time_s = 0.0
        self._steps = 0
        self.angle_rad = np.broadcast_to(
            np.asarray(initial_position_raw, dtype=float) * RAD_PER_POSITION_UNIT, (n,)
        ).copy()
        self.speed_rad_s = np.zeros(n)
        self.supply_voltage_v = supply_voltage_v
        self.ambient_temperature_c = ambient_temperature_c
        self.external_torque_nm = np.zeros(n)
        self._moving = np.zeros(n, dtype=np.int64)
        self._sensed: Sensed | None = None
        self._rest_commands: Commands | None = None
        self._constant = {
            "present_load": np.zeros(n, dtype=np.int64),
            "present_voltage": np.full(n, int(round(supply_voltage_v * 10)), dtype=np.int64),
            "present_temperature": np.full(n, int(round(ambient_temperature_c)), dtype=np.int64),
            "alarms": np.zeros(n, dtype=np.int64),
        }

    def set_external_torque(self, torque_nm: np.ndarray) -> None:
        """Accepted for interface parity; a kinematic servo is infinitely stiff."""
        self.external_torque_nm = np.broadcast_to(np.asarray(torque_nm, dtype=float), (self.n,)).copy()

    def set_angle(self, index: int, angle_rad: float) -> None:
        """Put shaft ``index`` at ``angle_rad`` (by hand), at rest; the readings follow at once."""
        self.angle_rad[index] = float(angle_rad)
        self.speed_rad_s[index] = 0.0
        self._rest_commands = None
        self._sensed = None

    def advance(self, to_time_s: float, commands: Commands) -> Sensed:
        """Step from ``time_s`` to ``to_time_s`` (whole steps only) with ``commands`` held."""
        self.step_to(to_time_s, commands)
        return self.sense()

    def step_to(self, to_time_s: float, commands: Commands) -> None:
        """:meth:`advance` without reading the sensors."""
        target_steps = int(np.floor(to_time_s / self.step_s + STEP_SLACK))  # as PhysicalModel.step_to
        count = target_steps - self._steps
        if count <= 0:
            self._take_commands(commands)
        elif commands is not self._rest_commands:
            self._integrate(count * self.step_s, commands)
            # At rest under unchanged commands, further steps change nothing: skip them.
            self._rest_commands = commands if not self.speed_rad_s.any() else None
            self._steps = target_steps
            self.time_s = target_steps * self.step_s

    def _take_commands(self, c: Commands) -> None:
        """New commands with no time passing (a packet between two control steps): Moving follows them at once.

        Moving as :meth:`_integrate` leaves it over a zero-length interval: short of the goal (wheel mode:
        a speed commanded), torque on; the shaft has not moved yet.
        """
        enabled = np.asarray(c.torque_enable) != 0
        wheel = (np.asarray(c.cw_angle_limit) == 0) & (np.asarray(c.ccw_angle_limit) == 0)
        turning = (np.asarray(c.moving_speed, dtype=np.int64) & 0x3FF) != 0
        short = np.abs(np.asarray(c.goal_position) * RAD_PER_POSITION_UNIT - self.angle_rad) > 1e-9
        moving = (enabled & np.where(wheel, turning, short)).astype(np.int64)
        if not np.array_equal(moving, self._moving):
            self._moving = moving
            self._sensed = None

    def _integrate(self, dt_s: float, c: Commands) -> None:
        # Constant speed makes the closed form exact, so many steps cost one.
        enabled = np.asarray(c.torque_enable) != 0
        wheel = (np.asarray(c.cw_angle_limit) == 0) & (np.asarray(c.ccw_angle_limit) == 0)
        speed_raw = np.asarray(c.moving_speed, dtype=np.int64)
        magnitude = speed_raw & 0x3FF
        speed = magnitude * RAD_S_PER_SPEED_UNIT
        joint_speed = np.where(magnitude == 0, MAX_SPEED_RAD_S, speed)
        error = np.asarray(c.goal_position) * RAD_PER_POSITION_UNIT - self.angle_rad
        reach = joint_speed * dt_s
        # Joint mode: the mean velocity over the interval (the last one may end early at the goal).
        step = np.clip(error, -reach, reach)
        wheel_velocity = np.where(speed_raw & DIRECTION_BIT, -speed, speed)
        self.speed_rad_s = np.where(wheel, wheel_velocity, step / dt_s) * enabled
        self.angle_rad = np.mod(self.angle_rad + self.speed_rad_s * dt_s, 2.0 * np.pi)
        # Moving: still short of the goal at the end of the interval (wheel mode: turning).
        still_going = np.where(wheel, speed != 0, np.abs(error - step) > 1e-9)
        self._moving = (enabled & still_going).astype(np.int64)
        self._sensed = None

    def sense(self) -> Sensed:
        """Registers as the firmware would report them now (cached until the state changes)."""
        if self._sensed is None:
            self._sensed = Sensed(
                present_position=position_rad_to_raw(self.angle_rad),
                present_speed=speed_rad_s_to_raw(self.speed_rad_s),
                moving=self._moving,
                **self._constant,
            )
        return self._sensed
