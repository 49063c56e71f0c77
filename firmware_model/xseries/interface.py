"""The seam between an X-series servo's control table and its firmware and physics model.

Why it exists: as with the AX-12 (:mod:`firmware_model.interface`), the protocol side owns the
control table and its bytes, a model owns the firmware's control loop and the physics, and neither
imports the other.  X-series servos differ enough to need their own seam: one model per servo
(a Protocol 2.0 bus mixes models with different tables, units and motors), signed 32-bit positions
(extended position mode counts turns), operating modes, and a trajectory profile that restarts
when a goal is written, so the model is told *when* the goal was written, not only what it is.

Units are the control table's own (e-manual, X-series "Control Table"): position in pulses
(0.088 deg, 4096 per turn), velocity in 0.229 rpm, PWM in 0.113 % (885 = 100 %), current in the
model's own unit (1 mA on the XL330/XC330, 2.69 mA on the XM430), Profile Velocity in 0.229 rpm and
Profile Acceleration in 214.577 rev/min^2 (velocity-based profile) or ms (time-based profile),
voltage in 0.1 V, temperature in degrees C.  The servo side hands over register values as they are
and reads back what the firmware writes; the model applies Homing Offset, Drive Mode and limits the
way the firmware does.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Protocol, runtime_checkable

__all__ = [
    "TRAJECTORY_SENSED",
    "HW_ERROR_INPUT_VOLTAGE",
    "HW_ERROR_OVERHEATING",
    "HW_ERROR_MOTOR_ENCODER",
    "HW_ERROR_ELECTRICAL_SHOCK",
    "HW_ERROR_OVERLOAD",
    "OperatingMode",
    "POSITION_MODES",
    "XCommands",
    "XSensed",
    "XServoModel",
    "XFaultable",
]

#: Hardware Error Status (70) bits (e-manual, X-series "Hardware Error Status").
HW_ERROR_INPUT_VOLTAGE = 0x01
HW_ERROR_OVERHEATING = 0x04
HW_ERROR_MOTOR_ENCODER = 0x08
HW_ERROR_ELECTRICAL_SHOCK = 0x10
HW_ERROR_OVERLOAD = 0x20


class OperatingMode:
    """Operating Mode (11) values (e-manual, X-series "Operating Mode")."""

    CURRENT = 0
    VELOCITY = 1
    POSITION = 3
    EXTENDED_POSITION = 4
    CURRENT_BASED_POSITION = 5
    PWM = 16


#: The modes whose command is Goal Position (the position controller runs in them).
POSITION_MODES = (OperatingMode.POSITION, OperatingMode.EXTENDED_POSITION, OperatingMode.CURRENT_BASED_POSITION)


@dataclass
class XCommands:
    """Registers that steer one X-series servo, raw register values (0 where the model has no such register)."""

    torque_enable: int = 0
    operating_mode: int = OperatingMode.POSITION
    drive_mode: int = 0
    homing_offset: int = 0
    moving_threshold: int = 10
    #: Limits the PWM in every mode but PWM mode (e-manual "Goal PWM(100)"): a real servo sets it to
    #: PWM Limit at power-on and REBOOT, so 0 here means a servo that cannot move.
    goal_pwm: int = 0
    #: Limits the current in Current-based Position mode; a real servo sets it to Current Limit at power-on.
    goal_current: int = 0
    goal_velocity: int = 0
    goal_position: int = 0
    profile_acceleration: int = 0
    profile_velocity: int = 0
    position_p_gain: int = 0
    position_i_gain: int = 0
    position_d_gain: int = 0
    velocity_p_gain: int = 0
    velocity_i_gain: int = 0
    feedforward_1st_gain: int = 0
    feedforward_2nd_gain: int = 0
    pwm_limit: int = 885
    current_limit: int = 0
    velocity_limit: int = 0
    max_position_limit: int = 4095
    min_position_limit: int = 0
    temperature_limit: int = 80
    max_voltage_limit: int = 140
    min_voltage_limit: int = 60
    shutdown: int = 0

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Names of all command registers, in declaration order."""
        return tuple(f.name for f in fields(cls))


@dataclass
class XSensed:
    """Registers one X-series servo's firmware writes back, raw register values."""

    present_position: int = 0
    present_velocity: int = 0
    #: Present Current (126) on current-sensing models, Present Load (126, 0.1 %) on the XL430.
    present_current: int = 0
    present_pwm: int = 0
    velocity_trajectory: int = 0
    position_trajectory: int = 0
    moving: int = 0
    moving_status: int = 0
    present_input_voltage: int = 0
    present_temperature: int = 0
    hardware_error_status: int = 0
    #: Torque Enable (64) as the firmware holds it: cleared by a Shutdown error (only REBOOT lets it
    #: back on), set by a goal write with Drive Mode bit 3 (torque on by goal update).
    torque_enable: int = 0

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Names of all sensed registers, in declaration order."""
        return tuple(f.name for f in fields(cls))


#: The sensed fields a command can change before the next step without moving a firmware's ``sensing_epoch``
#: (where it keeps one: :class:`.firmware.XFirmware`): a goal restarts the profile (the trajectory, Moving,
#: Moving Status), and Moving Threshold and the position limits are read by Moving and Moving Status.
TRAJECTORY_SENSED = frozenset({"velocity_trajectory", "position_trajectory", "moving", "moving_status"})


class XServoModel(Protocol):
    """What an X-series servo's control table needs from its firmware and physics model."""

    #: Fixed control step of the firmware, seconds; ``step_to`` moves in whole steps.
    step_s: float
    #: Simulated time reached so far, seconds.
    time_s: float

    def command(self, commands: XCommands, *, goal_written: bool = False) -> None:
        """Take new register values at ``time_s``; ``goal_written``: a goal register was just written, so a new profile starts."""
        ...

    def step_to(self, to_time_s: float) -> None:
        """Run the firmware's control loop and the physics from ``time_s`` to ``to_time_s``."""
        ...

    def sense(self) -> XSensed:
        """The registers the firmware writes back, at ``time_s``."""
        ...

    def reboot(self) -> None:
        """REBOOT: the firmware restarts (hardware errors cleared, torque off), the shaft keeps its angle."""
        ...

    def clear_multi_turn(self) -> None:
        """CLEAR option 0x01: Present Position's turn count reset, keeping the angle within one turn."""
        ...

    def set_external_torque(self, torque_nm: float) -> None:
        """A torque acting on the output shaft (N·m, positive = counter-clockwise)."""
        ...

    @property
    def present_errors(self) -> int:
        """The Hardware Error Status bits whose condition holds now, whether or not Shutdown(63) selects them."""
        ...

    @property
    def cut_errors(self) -> int:
        """The errors that cut the output, on a firmware whose Shutdown cuts it rather than latching (Protocol 1.0 MX)."""
        ...

    def restore_output(self) -> None:
        """The host lets the motor run again after a cut; an error still present cuts it again at the next step."""
        ...


@runtime_checkable
class XFaultable(Protocol):
    """A model whose servo can be made to fail as a real one does, for fault injection (``ax12emu.faults``).

    Each acts inside the firmware, so what follows is the firmware's own doing: an error it detects
    latches in Hardware Error Status and turns the torque off only as Shutdown(63) selects, and
    REBOOT clears it; a blocked shaft draws stall current until the overload protection trips.
    """

    def hold_errors(self, bits: int) -> None:
        """Hold the Hardware Error Status ``bits``' conditions present until called with 0, detected at every step."""
        ...

    def raise_error(self, bits: int) -> int:
        """The firmware detects the Hardware Error Status ``bits`` now; returns those it latched (Shutdown's)."""
        ...

    def set_blocked(self, blocked: bool) -> None:
        """Hold the output shaft still (an obstacle, a hand) while the motor keeps driving, or free it."""
        ...

    def hold_reading(self, name: str, value: int | None) -> None:
        """Pin a sensed register (an :class:`XSensed` field, register units) as a stuck sensor would; None frees it.

        The firmware's protections judge the pinned temperature and input voltage as they judge real ones.
        """
        ...
