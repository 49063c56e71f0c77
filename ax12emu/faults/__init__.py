"""Fault injection: the configuration users write, and the faults a bus runs.

Above :mod:`ax12emu.bus`: wire faults filter the bus's replies; servo faults
act through the bus's and the model's declared interfaces.
"""

from .config import FAULT_OPTIONS, FaultConfig
from .injection import Faults, Faults1X, Faults2, MixedFaults, faults_for, parse_alarm_bits

__all__ = ["FAULT_OPTIONS", "FaultConfig", "Faults", "Faults1X", "Faults2", "MixedFaults", "faults_for", "parse_alarm_bits"]
