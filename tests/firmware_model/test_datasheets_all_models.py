"""Every servo model's data-sheet stall torque and no-load speed, reproduced by the physical model.

Each model's figures come from its data file (``ax12emu/protocol/models/*.toml``, quoted from the
ROBOTIS e-manual); :meth:`ServoParams.from_datasheet` turns them into motor constants and
:class:`PhysicalModel` is then measured as a dynamometer would measure a real servo, at full drive:

* stall torque: the smallest opposing torque under which a fully driven shaft makes no forward
  progress (its speed after 1 s is not above zero), found over 61 shafts at once loaded with
  0.85 .. 1.15 times the data-sheet figure (0.5 % steps; more would back-drive the shaft past static
  friction, which at the AX-12 share is 10 % of the stall torque);
* no-load speed: the settled speed in wheel mode at full Moving Speed.  The AX-12 firmware's wheel
  loop asks for at most 1023 x 0.111 rpm (114 rpm); a model whose no-load speed is above about 108
  rpm (XL-320, XL330-M077) cannot be driven flat out that way, so its speed at full drive is found from
  the drive the loop needs at two lower speeds (the motor line is straight: drive = (c k w + t_c) / c V),
  extrapolated to full drive.

Tolerance 5 %: the derivation inverts the same equations the model steps, so what is left is the
step's discretisation, the Stribeck term near rest and the measuring grid (0.5 %); 5 % is also the
rounding of the sheets' own figures (two significant digits: 1.4 N m is 1.35..1.45, +-3.6 %).
"""

from __future__ import annotations

import numpy as np
import pytest

from ax12emu.protocol.servo_models import model, model_names
from firmware_model.params import ServoParams
from firmware_model.physical import FULL_SCALE_SPEED_RAD_S, PhysicalModel

TOLERANCE = 0.05
#: Where the sheet's stall current would need a gearbox efficiency above one (the stall figure is
#: current-limited, not the winding's), the AX-12 derivation's efficiency is used instead.
AX12_EFFICIENCY = ServoParams().gearbox_efficiency


def _params(key: str, voltage_v: float | None = None) -> tuple[ServoParams, object]:
    physical = model(key).physical
    rating = physical.rating_at(voltage_v)
    low, high = physical.operating_voltage_v
    common = dict(gear_ratio=physical.gear_ratio, min_supply_voltage_v=low, max_supply_voltage_v=high)
    try:
        params = ServoParams.from_datasheet(rating.stall_torque_nm, rating.no_load_speed_rad_s, rating.voltage_v,
                                            stall_current_a=rating.stall_current_a, **common)
    except ValueError:
        params = ServoParams.from_datasheet(rating.stall_torque_nm, rating.no_load_speed_rad_s, rating.voltage_v,
                                            gearbox_efficiency=AX12_EFFICIENCY, **common)
    return params, rating


def measured_stall_torque_nm(params: ServoParams, volts: float, datasheet_nm: float, make_commands) -> float:
    """Smallest opposing torque (of 0.85 .. 1.15 x the sheet's, 0.5 % steps) that holds a fully driven shaft."""
    loads = datasheet_nm * np.linspace(0.85, 1.15, 61)
    servo = PhysicalModel(len(loads), params, initial_position_raw=100)
    servo.set_supply_voltage(volts)
    servo.set_external_torque(-loads)  # against the CCW move
    sensed = servo.advance(1.0, make_commands(len(loads), goal_position=1000))
    # Shafts slower than the reference (capped at the register's top speed) and short of the goal are
    # driven flat out; light loads on a fast model may have caught the reference or arrived.
    slow = (servo.speed_rad_s < 0.5 * FULL_SCALE_SPEED_RAD_S) & (sensed.present_position < 900)
    assert np.all(servo.drive[slow] > 0.999), "a shaft held back must be driven flat out"
    held = slow & (servo.speed_rad_s <= 0.0)  # no forward motion (a load well above it may push the shaft back)
    assert held[-1] and not held[0], "the grid must bracket the stall torque"
    return float(loads[np.argmax(held)])


def _wheel(params: ServoParams, volts: float, setting: int, make_commands) -> tuple[float, float]:
    servo = PhysicalModel(1, params)
    servo.set_supply_voltage(volts)
    servo.advance(2.0, make_commands(cw_angle_limit=0, ccw_angle_limit=0, moving_speed=setting))
    return float(servo.speed_rad_s[0]), float(servo.drive[0])


def measured_no_load_speed_rad_s(params: ServoParams, volts: float, make_commands) -> tuple[float, str]:
    """Settled wheel-mode speed at full drive; extrapolated from two lower speeds where the register cannot ask for it."""
    speed, drive = _wheel(params, volts, 1023, make_commands)
    if drive > 0.999:
        return speed, "full drive"
    assert speed == pytest.approx(FULL_SCALE_SPEED_RAD_S, rel=0.01)  # the loop holds the register's top speed
    (w1, d1), (w2, d2) = _wheel(params, volts, 400, make_commands), _wheel(params, volts, 900, make_commands)
    return w1 + (1.0 - d1) * (w2 - w1) / (d2 - d1), "extrapolated"


CASES = [(key, rating.voltage_v) for key in model_names() for rating in model(key).physical.ratings]


@pytest.mark.parametrize(("key", "volts"), CASES, ids=[f"{k}@{v}V" for k, v in CASES])
def test_stall_torque_and_no_load_speed_match_the_data_sheet(key, volts, commands):
    """Stall torque and no-load speed at each rated voltage within 5 % of the model's data sheet."""
    params, rating = _params(key, volts)
    stall = measured_stall_torque_nm(params, volts, rating.stall_torque_nm, commands)
    speed, how = measured_no_load_speed_rad_s(params, volts, commands)
    assert stall == pytest.approx(rating.stall_torque_nm, rel=TOLERANCE), key
    assert speed == pytest.approx(rating.no_load_speed_rad_s, rel=TOLERANCE), (key, how)
