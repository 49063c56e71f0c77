"""The seam between the bus and any servo model: commands in, sensed values out.

Why it exists: the protocol side (``ax12emu``) owns the control table and its
byte layout; a model owns firmware and physics.  Neither imports the other.
Every model of N servos takes the same :class:`Commands` (the registers that
steer motion, in raw control-table units, one array element per servo) and
returns the same :class:`Sensed` (the registers the firmware writes back).
Raw units are used on purpose: they are what the AX-12's own firmware works
with (10-bit position, 0.111 rpm speed units, 0.1 % load, 0.1 V), so a model
reproduces the firmware's integer quirks instead of an idealised SI version.

Alarm bits use the Protocol 1.0 status-byte layout (e-manual, "Status Packet"):
the model raises the physical ones (input voltage, overheating, overload);
instruction-level errors (range, checksum, instruction, angle limit on a
write) belong to the protocol side.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = [
    "ALARM_INPUT_VOLTAGE",
    "ALARM_ANGLE_LIMIT",
    "ALARM_OVERHEATING",
    "ALARM_OVERLOAD",
    "Commands",
    "POWER_UP",
    "Sensed",
    "ServoModel",
    "SteppableTo",
    "Blockable",
    "AngleSettable",
    "STEP_SLACK",
]

#: Fraction of a control step within which a model takes a step as due (a millionth: 1 ns at 1 kHz). A bus's clock
#: sums its own floats; a bus that finds a step due by this slack must get it from ``step_to``, or a client's write
#: is marked shown with no step run.
STEP_SLACK = 1e-6

#: Status-byte bits a model may raise (e-manual Protocol 1.0, error field).
ALARM_INPUT_VOLTAGE = 0x01
ALARM_ANGLE_LIMIT = 0x02
ALARM_OVERHEATING = 0x04
ALARM_OVERLOAD = 0x20


@dataclass
class Commands:
    """Registers that steer the servos, raw units, arrays of shape (N,)."""

    #: Torque Enable (24): 0 = motor free, 1 = driven.
    torque_enable: np.ndarray
    #: Goal Position (30): 0..1023 over 0..300 degrees.
    goal_position: np.ndarray
    #: Moving Speed (32): joint mode 0..1023 (0 = no limit), wheel mode bit 10 = CW.
    moving_speed: np.ndarray
    #: Torque Limit (34): 0..1023 of maximum torque.
    torque_limit: np.ndarray
    #: CW / CCW Angle Limit (6, 8): both 0 selects wheel mode.
    cw_angle_limit: np.ndarray
    ccw_angle_limit: np.ndarray
    #: Compliance Margin (26, 27) and Slope (28, 29), raw.
    cw_compliance_margin: np.ndarray
    ccw_compliance_margin: np.ndarray
    cw_compliance_slope: np.ndarray
    ccw_compliance_slope: np.ndarray
    #: Punch (48): minimum drive, 0..1023.
    punch: np.ndarray
    #: Temperature Limit (11), degrees C.
    temperature_limit: np.ndarray
    #: Min / Max Voltage Limit (12, 13), units of 0.1 V.
    min_voltage_limit: np.ndarray
    max_voltage_limit: np.ndarray
    #: Alarm Shutdown (18): the alarm bits (ALARM_* below) that cut the output at the control step they are found
    #: (e-manual, Alarm Shutdown: "the motor output becomes 0 % by resetting the value of Torque Limit(34) to 0");
    #: the model then reports the cut (:attr:`Sensed.output_cut`) for the bus to write into the table.
    shutdown: np.ndarray

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Names of all command registers, in declaration order."""
        return tuple(f.name for f in fields(cls))

    @classmethod
    def power_up(cls, n: int = 1, **overrides) -> Commands:
        """The registers as an AX-12A powers up, torque on, for ``n`` servos; each override is a scalar or a
        sequence of length ``n`` (e.g. ``goal_position=500``).

        Why here: a step at full speed with the e-manual's default compliance is what the data sheet, the 2008
        report and the real recordings describe, and the tools, the diagnosis's synthetic recordings and the tests
        step it alike.  The values are the e-manual's initial ones (``ax12emu/protocol/models/ax-12a.toml``, which
        this layer does not read), over the full joint range, with Torque Enable 1 and Goal Position 512, but for
        Alarm Shutdown 0 (the e-manual's is 36: Overload and Overheating): stepped alone, as the tools and the
        data-sheet tests step it, the model shows the physics of a stall or a hot motor rather than the firmware
        cutting it short; the bus hands over its tables' Alarm Shutdown.
        """
        values = {**POWER_UP, **overrides}
        return cls(**{k: np.broadcast_to(np.asarray(v, dtype=np.int64), (n,)).copy() for k, v in values.items()})


#: :meth:`Commands.power_up`'s values: the e-manual's initial ones, torque on, goal at the centre.
POWER_UP = dict(
    torque_enable=1, goal_position=512, moving_speed=0, torque_limit=1023, cw_angle_limit=0, ccw_angle_limit=1023,
    cw_compliance_margin=1, ccw_compliance_margin=1, cw_compliance_slope=32, ccw_compliance_slope=32, punch=32,
    temperature_limit=70, min_voltage_limit=60, max_voltage_limit=140, shutdown=0,
)


@dataclass
class Sensed:
    """Registers the firmware writes back, raw units, arrays of shape (N,)."""

    #: Present Position (36): 0..1023.
    present_position: np.ndarray
    #: Present Speed (38): magnitude 0..1023 in 0.111 rpm, bit 10 set when turning CW.
    present_speed: np.ndarray
    #: Present Load (40): magnitude 0..1023 in 0.1 % of maximum, bit 10 set when CW.
    present_load: np.ndarray
    #: Present Voltage (42): units of 0.1 V.
    present_voltage: np.ndarray
    #: Present Temperature (43): degrees C.
    present_temperature: np.ndarray
    #: Moving (46): 1 while the servo is moving toward its goal.
    moving: np.ndarray
    #: Present alarm bits (ALARM_* above), 0 when all is well.
    alarms: np.ndarray
    #: Not a register: 1 where the model cut the output for Alarm Shutdown (:attr:`Commands.shutdown`) at a control
    #: step and the commands do not show it yet (Torque Limit and Torque Enable as they were then), else 0; the bus
    #: writes 0 into the register its edition's Alarm Shutdown clears, even if the alarm has gone again since.
    #: None from a model that leaves Alarm Shutdown to the bus (which applies it to the alarms it is shown).
    output_cut: np.ndarray | None = None

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Names of all sensed registers, in declaration order."""
        return tuple(f.name for f in fields(cls))


class ServoModel(Protocol):
    """What the bus needs from a model of N servos."""

    #: Number of servos simulated.
    n: int
    #: Fixed integration step, seconds; ``advance`` moves in whole steps.
    step_s: float
    #: Simulated time reached so far, seconds.
    time_s: float

    def advance(self, to_time_s: float, commands: Commands) -> Sensed:
        """Integrate from ``time_s`` to ``to_time_s`` holding ``commands``; return the sensors."""
        ...

    def sense(self) -> Sensed:
        """The sensed registers at ``time_s`` without advancing.

        An array handed out is never changed afterwards; a model may hand out
        the same read-only array again while the value stays the same (the
        bus then skips copying it).  A model may also offer ``step_to(to_time_s,
        commands)``, :meth:`advance` without reading the sensors, which lets a
        serving loop split a step in pieces (both models here do).
        """
        ...

    def set_external_torque(self, torque_nm: np.ndarray) -> None:
        """Set a torque acting on each output shaft (N·m, positive = CCW)."""
        ...


# Optional capabilities.  A model declares one by having the method; callers test with
# ``isinstance(model, Capability)`` once (not per step: a protocol check costs microseconds),
# so nothing probes a model's attributes by name.


@runtime_checkable
class SteppableTo(Protocol):
    """A model that can step without reading its sensors, so a serving loop can split a step in pieces."""

    def step_to(self, to_time_s: float, commands: Commands) -> None:
        """:meth:`ServoModel.advance` without reading the sensors."""
        ...


@runtime_checkable
class Blockable(Protocol):
    """A model whose shafts can be held still, as by a hand or an obstacle, while the motor keeps driving."""

    def set_blocked(self, blocked: Sequence[bool] | np.ndarray) -> None:
        """Block (True) or free each output shaft."""
        ...


@runtime_checkable
class AngleSettable(Protocol):
    """A model whose shaft can be turned by hand to an angle."""

    def set_angle(self, index: int, angle_rad: float) -> None:
        """Put shaft ``index`` at ``angle_rad`` (radians from the CW end), at rest."""
        ...
