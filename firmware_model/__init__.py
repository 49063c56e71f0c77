"""Numerical models of the AX-12's firmware and physics: pure numpy, no I/O, no packets.

The bus drives any model through :class:`firmware_model.interface.ServoModel`:
:class:`KinematicModel` (constant-speed moves, the first model) or
:class:`PhysicalModel` (setpoint generator, compliance control, PWM motor,
friction, sensors, heating and alarms; parameters in :class:`ServoParams`).
"""

from .interface import Commands, Sensed, ServoModel
from .kinematic import KinematicModel
from .params import ServoParams
from .physical import PhysicalModel

__all__ = ["Commands", "Sensed", "ServoModel", "KinematicModel", "PhysicalModel", "ServoParams"]
