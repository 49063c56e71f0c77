"""build_model: a parameter file with effects (the fitted twin the diagnosis writes) loads as it is written."""

from __future__ import annotations

from dataclasses import replace

import pytest

from ax12emu.protocol.control_table import AX12_MODEL
from ax12emu.protocol.servo_models import model
from ax12emu.servo.model_factory import ModelChoice, build_model, build_protocol1_model, datasheet_params, parse_arm
from firmware_model.interface import ALARM_OVERLOAD, Commands
from firmware_model.params import ServoEffects, ServoParams

TWIN = ServoParams(static_friction_nm=0.2, effects=ServoEffects(backlash_rad=0.04, arm_weight_moment_nm=0.3,
                                                                  position_offset_units=5.0))


def test_params_file_with_effects_builds_the_twin(tmp_path):
    path = tmp_path / "params.toml"
    TWIN.to_toml(path)
    model = build_model(ModelChoice(params_path=path), 2)
    assert model.params == TWIN
    assert list(model._array("weight_nm")) == [0.3, 0.3]  # the effect's arm hangs on every shaft
    assert build_model(ModelChoice(params=TWIN), 1).params == TWIN  # the same as an object


@pytest.mark.parametrize(("choice", "message"), [
    (dict(params_path="/nonexistent/params.toml"), "cannot read the parameter file '/nonexistent/params.toml'"),
    (dict(params=TWIN, arm=(0.1, 0.2)), "two arms"),
    (dict(params=TWIN, params_path="x.toml"), "not both"),
    (dict(name="kinematic", params=TWIN), "--params need the physical model"),
    (dict(profile="ax12-2005"), "unknown profile 'ax12-2005'"),
])
def test_bad_choices_raise_one_line_errors(choice, message):
    with pytest.raises(ValueError, match=message):
        build_model(ModelChoice(**choice), 1)


def test_arm_option_alone_still_hangs_an_arm():
    model = build_model(ModelChoice(arm=(0.2, 0.1)), 1)
    assert model._array("weight_nm")[0] == pytest.approx(0.2 * 9.80665 * 0.1)


def test_a_wire_of_another_model_alone_runs_the_given_parameters_and_a_mixed_wire_refuses_them():
    """A twin fitted to an AX-18A's recording serves AX-18As; on a wire of AX-12As and AX-18As it would be one
    servo's parameters put on the other too."""
    twin = replace(datasheet_params(model("ax-18a")), static_friction_nm=0.21)
    assert build_protocol1_model(["ax-18a", "ax-18a"], ModelChoice(params=twin)).params == twin
    assert build_protocol1_model(["ax-18a"]).params == datasheet_params(model("ax-18a"))
    with pytest.raises(ValueError, match=r"several models \(ax-12a, ax-18a\)"):
        build_protocol1_model(["ax-12a", "ax-18a"], ModelChoice(params=twin))
    with pytest.raises(ValueError, match="kinematic applies to the AX-12A only"):
        build_protocol1_model(["ax-18a"], ModelChoice(name="kinematic"))


@pytest.mark.parametrize("text", ["1e308,1e308", "101,0.1", "0.1,11", "-1,0.1", "nan,0.1", "0.1,inf"])
def test_an_arm_beyond_any_servo_is_refused_in_one_line(text):
    """A mass or length so large the physics overflowed (1e308 gave infinite positions) is a flag error."""
    with pytest.raises(ValueError, match=r"arm mass must be 0..100 kg and length 0..10 m"):
        parse_arm(text)
    assert parse_arm("100,10") == (100.0, 10.0)


def _cut_and_alarms(model) -> tuple[list[int], list[int]]:
    """Every shaft blocked at full drive, Alarm Shutdown selecting Overload, 3 s at once: the cut and the alarms."""
    model.set_blocked([True] * model.n)
    sensed = model.advance(3.0, Commands.power_up(model.n, goal_position=900, shutdown=ALARM_OVERLOAD))
    return sensed.output_cut.tolist(), sensed.alarms.tolist()


@pytest.mark.parametrize("build", [build_model, lambda choice, n: build_protocol1_model([AX12_MODEL] * n, choice)],
                         ids=["build_model", "build_protocol1_model"])
def test_a_model_built_for_the_2006_profile_cuts_by_turning_torque_off(build):
    """The physical model's own Alarm Shutdown cut learned the 2006 edition's rule (torque off) only from the bus,
    which set it on the model after building it for the e-manual's (Torque Limit 0).  Built for the profile, the
    cut inside a long step is torque off from the start: a blocked servo overloads, is cut, and with torque off no
    Overload stays, where the e-manual's cut (Torque Limit 0, torque on) keeps it."""
    assert _cut_and_alarms(build(ModelChoice(profile="ax12-2006"), 1)) == ([1], [0])
    assert _cut_and_alarms(build(ModelChoice(), 1)) == ([1], [ALARM_OVERLOAD])


def test_an_ax18a_beside_2006_ax12as_keeps_its_own_tables_cut():
    """The profile names the AX-12A's edition; an AX-18A's model cuts as its own model file's table says (a bus
    refuses servos whose Alarm Shutdown clears different registers, so the two models only meet here)."""
    assert _cut_and_alarms(build_protocol1_model([AX12_MODEL, "ax-18a"], ModelChoice(profile="ax12-2006"))) == (
        [1, 1], [0, ALARM_OVERLOAD])
