"""Numerical models of the AX-12's firmware and physics: pure numpy, no I/O, no packets.

The bus drives any model through :class:`firmware_model.interface.ServoModel`.
"""

from .interface import Commands, Sensed, ServoModel
from .kinematic import KinematicModel

__all__ = ["Commands", "Sensed", "ServoModel", "KinematicModel"]
