"""Every servo model's data-sheet stall torque and no-load speed, reproduced by the physical model.

Each model's figures come from its data file (``ax12emu/protocol/models/*.toml``, quoted from the
ROBOTIS e-manual); :meth:`ServoParams.from_datasheet` turns them into motor constants and
:class:`PhysicalModel` is then measured as a dynamometer would measure a real servo, at full drive:

* stall torque: the smallest opposing torque under which a fully driven shaft makes no forward
  progress (its speed after 1 s is not above zero), found over 61 shafts at once loaded with
  0.85 .. 1.15 times the data-sheet figure (0.5 % steps; more would back-drive the shaft past static
  friction, which at the AX-12 share is 10 % of the stall torque);
* no-load speed: the settled speed in wheel mode at full Moving Speed, which is full output (the
  AX-12's wheel mode sets the output, not a speed).

Tolerance 5 %: the derivation inverts the same equations the model steps, so this checks that the
simulated servo (controller, bridge, friction, stepping) delivers what the closed form promises; what
is left is the step's discretisation, the Stribeck term near rest and the measuring grid (0.5 %); 5 %
is also the rounding of the sheets' own figures (two significant digits: 1.4 N m is 1.35..1.45, +-3.6 %).

The falsifiable part is the prediction: one parameter set, fitted at the recommended (or first)
rating alone, against the sheet's other rated voltages (7 %).  No-load speeds follow everywhere;
five stall torques do not, and are marked with their figures (``STALL_NOT_LINEAR``).
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


def measured_stall_torque_nm(params: ServoParams, volts: float, around_nm: float, make_commands) -> float:
    """Smallest opposing torque (of 0.85 .. 1.15 x ``around_nm``, 0.5 % steps) that holds a fully driven shaft."""
    loads = around_nm * np.linspace(0.85, 1.15, 61)
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


def measured_no_load_speed_rad_s(params: ServoParams, volts: float, make_commands) -> float:
    """Settled wheel-mode speed at full Moving Speed: full output."""
    speed, drive = _wheel(params, volts, 1023, make_commands)
    assert drive == 1.0, "Moving Speed 1023 in wheel mode is full output"
    return speed


CASES = [(key, rating.voltage_v) for key in model_names() for rating in model(key).physical.ratings]


@pytest.mark.parametrize(("key", "volts"), CASES, ids=[f"{k}@{v}V" for k, v in CASES])
def test_stall_torque_and_no_load_speed_match_the_data_sheet(key, volts, commands):
    """Stall torque and no-load speed at each rated voltage within 5 % of the model's data sheet."""
    params, rating = _params(key, volts)
    stall = measured_stall_torque_nm(params, volts, rating.stall_torque_nm, commands)
    speed = measured_no_load_speed_rad_s(params, volts, commands)
    assert stall == pytest.approx(rating.stall_torque_nm, rel=TOLERANCE), key
    assert speed == pytest.approx(rating.no_load_speed_rad_s, rel=TOLERANCE), key


#: Where one parameter set cannot follow the sheet's stall torque to another voltage (measured miss in
#: the reason).  The linear motor's stall torque is ``c V - t_s``; these sheets' figures are not on one
#: such line (XL430-W250: 1.0, 1.4, 1.5 N m at 9, 11.1, 12 V is 0.111, 0.126, 0.125 N m/V), as a stall
#: figure limited by the driver's current or measured warm would not be.
STALL_NOT_LINEAR = {
    ("xl330-m077", 3.7): "predicts 0.154 N m against 0.180 (-15 %): the sheet's stall torque grows slower than the supply",
    ("xl330-m077", 6.0): "predicts 0.262 N m against 0.228 (+15 %): the sheet's stall torque grows slower than the supply",
    ("xl330-m288", 3.7): "predicts 0.371 N m against 0.42 (-12 %)",
    ("xl430-w250", 9.0): "predicts 1.114 N m against 1.0 (+11 %)",
    ("xm430-w350", 14.8): "predicts 5.15 N m against 4.8 (+7.3 %)",
}
OTHER_VOLTAGES = [
    (key, rating.voltage_v)
    for key in model_names()
    for rating in model(key).physical.ratings
    if rating.voltage_v != model(key).physical.rating_at().voltage_v
]
OTHER_IDS = [f"{k}@{v}V" for k, v in OTHER_VOLTAGES]
#: A prediction carries the sheets' rounding at two voltages (two significant digits each, up to
#: +-3.6 % apiece) and the linear motor's own error.
PREDICTION_TOLERANCE = 0.07


@pytest.mark.parametrize(("key", "volts"), OTHER_VOLTAGES, ids=OTHER_IDS)
def test_one_parameter_set_predicts_the_no_load_speed_at_the_other_rated_voltages(key, volts, commands):
    """Fitted at the recommended (or first) rating only, the model's no-load speed at each other rated voltage
    is within 7 % of the sheet (measured: within 3.4 % for every model)."""
    params, _ = _params(key, None)
    speed = measured_no_load_speed_rad_s(params, volts, commands)
    assert speed == pytest.approx(model(key).physical.rating_at(volts).no_load_speed_rad_s, rel=PREDICTION_TOLERANCE), key


@pytest.mark.parametrize(
    ("key", "volts"),
    [pytest.param(k, v, marks=pytest.mark.xfail(reason=STALL_NOT_LINEAR[(k, v)], strict=True))
     if (k, v) in STALL_NOT_LINEAR else (k, v) for k, v in OTHER_VOLTAGES],
    ids=OTHER_IDS,
)
def test_one_parameter_set_predicts_the_stall_torque_at_the_other_rated_voltages(key, volts, commands):
    """Fitted at the recommended (or first) rating only, the stall torque at each other rated voltage is within
    7 % of the sheet; the misses are listed in STALL_NOT_LINEAR with their figures."""
    params, _ = _params(key, None)
    stall = measured_stall_torque_nm(params, volts, params.stall_torque_nm(volts) - params.static_friction_nm, commands)
    assert stall == pytest.approx(model(key).physical.rating_at(volts).stall_torque_nm, rel=PREDICTION_TOLERANCE)


def test_from_datasheet_refuses_what_the_model_cannot_be():
    """Exactly one of stall current and efficiency; a stall current that needs an efficiency above one is refused."""
    common = dict(gear_ratio=100.0, min_supply_voltage_v=4.0, max_supply_voltage_v=6.0)
    with pytest.raises(ValueError, match="exactly one"):
        ServoParams.from_datasheet(0.2, 40.0, 5.0, **common)
    with pytest.raises(ValueError, match="exactly one"):
        ServoParams.from_datasheet(0.2, 40.0, 5.0, stall_current_a=1.5, gearbox_efficiency=0.7, **common)
    with pytest.raises(ValueError, match="gearbox efficiency of 1.3"):
        ServoParams.from_datasheet(0.215, 383 * 2 * np.pi / 60, 5.0, stall_current_a=1.47, **common)
    params = ServoParams.from_datasheet(0.215, 383 * 2 * np.pi / 60, 5.0, gearbox_efficiency=0.7, **common)
    assert params.gearbox_efficiency == 0.7 and params.stall_torque_nm(5.0) - params.static_friction_nm == pytest.approx(0.215)
    assert params.top_speed_rad_s(5.0) == pytest.approx(383 * 2 * np.pi / 60)
