"""X-series firmware models built from a servo model's data file.

Why it exists: the firmware and physics of an X-series servo (:mod:`firmware_model.xseries`) take
plain numbers, the data sheet's gear ratio and ratings, the current unit and any measured
departure of the control loop from the e-manual; the model files
(:mod:`ax12emu.protocol.servo_models`) hold them.  This reads one into the other, so the bus builds
one firmware model per servo from whichever model each ID is, with no code per model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ax12emu.protocol.servo_models import ServoModel
from firmware_model.xseries.firmware import build_x_servo
from firmware_model.xseries.interface import XServoModel

__all__ = ["XModelChoice", "build_x_firmware"]

#: Where the shaft starts: the middle of the position range (Present Position 2048), so a
#: client can move it both ways without touching the position limits.
START_ANGLE_RAD = math.pi


@dataclass(frozen=True)
class XModelChoice:
    """What the command line or a harness chooses for every X-series servo on a bus."""

    #: Supply voltage; None: the model's recommended supply.
    voltage_v: float | None = None
    #: A constant torque on every output shaft, N m (+ = counter-clockwise).
    external_torque_nm: float = 0.0


def build_x_firmware(spec: ServoModel, choice: XModelChoice = XModelChoice()) -> XServoModel:
    """One servo's firmware model from its data file; ``ValueError`` with the reason when the file cannot give one."""
    physical = spec.physical
    supply_v = choice.voltage_v if choice.voltage_v is not None else (
        physical.recommended_voltage_v or physical.ratings[0].voltage_v)
    low, high = physical.operating_voltage_v
    if not low <= supply_v <= high:
        raise ValueError(f"{spec.name} runs on {low:g}..{high:g} V, not {supply_v:g} V")
    ratings = []
    for rating in physical.ratings:
        if rating.stall_current_a is None:
            raise ValueError(f"{spec.path}: the X-series model needs stall_current_a in every rating")
        ratings.append((rating.voltage_v, rating.stall_torque_nm, rating.stall_current_a, rating.no_load_speed_rpm))
    unit_ma = physical.current_unit_ma
    firmware = build_x_servo(gear_ratio=physical.gear_ratio, ratings=ratings,
                             current_unit_a=None if unit_ma is None else unit_ma * 1e-3,
                             supply_v=supply_v, angle_rad=START_ANGLE_RAD,
                             position_output_scale=spec.controller.position_output_scale,
                             motor=physical.motor, rotor_inertia_at_motor_kg_m2=physical.rotor_inertia_at_motor_kg_m2)
    if choice.external_torque_nm:
        firmware.set_external_torque(choice.external_torque_nm)
    return firmware
