"""X-series firmware models built from the model files: the data sheet's numbers reach the firmware."""

from __future__ import annotations

import pytest

from ax12emu.protocol.servo_models import model
from ax12emu.servo.model_factory2 import XModelChoice, build_x_firmware
from firmware_model.xseries.interface import XCommands


@pytest.mark.parametrize("key", ["xl430-w250", "xm430-w350", "xl330-m077", "xl330-m288", "xc330-m288"])
def test_every_x_model_builds_and_starts_mid_range_at_its_supply(key):
    spec = model(key)
    firmware = build_x_firmware(spec)
    sensed = firmware.sense()
    assert sensed.present_position == 2048
    assert sensed.present_input_voltage == round(spec.physical.recommended_voltage_v * 10)


def test_supply_outside_the_operating_range_is_refused():
    with pytest.raises(ValueError, match="runs on 6.5..12 V, not 13 V"):
        build_x_firmware(model("xl430-w250"), XModelChoice(voltage_v=13.0))


def test_an_external_torque_turns_a_limp_shaft():
    firmware = build_x_firmware(model("xl430-w250"), XModelChoice(external_torque_nm=0.3))
    firmware.command(XCommands(torque_enable=0))
    firmware.step_to(0.5)
    assert firmware.sense().present_position > 2048 + 10


def test_the_xl330_position_loop_drives_half_the_emanual_reading_as_measured():
    # Same error, same gain: the XL330's measured controller puts out half the PWM the XL430's e-manual reading does.
    def pwm_after_goal_step(key: str) -> int:
        firmware = build_x_firmware(model(key))
        firmware.command(XCommands(torque_enable=1, operating_mode=3, goal_position=2048, position_p_gain=100,
                                   pwm_limit=885, goal_pwm=885, current_limit=5000, goal_current=5000))
        firmware.step_to(0.01)
        firmware.command(XCommands(torque_enable=1, operating_mode=3, goal_position=2048 + 200, position_p_gain=100,
                                   pwm_limit=885, goal_pwm=885, current_limit=5000, goal_current=5000), goal_written=True)
        firmware.step_to(0.012)
        return firmware.sense().present_pwm

    assert model("xl330-m288").controller.position_output_scale == 0.5
    ratio = pwm_after_goal_step("xl330-m288") / pwm_after_goal_step("xl430-w250")
    assert ratio == pytest.approx(0.5, abs=0.08)
