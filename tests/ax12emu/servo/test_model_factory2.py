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


# ---------------------------------------------------------------------------- the rotor

#: Rhoban's BAM fits of real servos, "armature" (kg m^2 at the output), bam/params/<servo>/m1.json: the MX-64 and
#: MX-106 (Maxon coreless), the XL330 (cored, the reference of the cored scaling).
BAM_ARMATURE = {"mx-64": 0.011951238325312509, "mx-106": 0.026609234235148084, "xl330-m288": 0.0018141672784458866}


@pytest.mark.parametrize("key", sorted(BAM_ARMATURE))
def test_the_rotor_of_a_servo_bam_fitted_is_bams_fit(key):
    """The reflected rotor and gears the served servo accelerates are what BAM fitted on the real one (to 0.1 %):
    from the scaling of the XL330's cored rotor the MX-64 had 8.6 and the MX-106 6.8 times that."""
    inertia = build_x_firmware(model(key)).physics.params.inertia_kg_m2
    assert inertia == pytest.approx(BAM_ARMATURE[key], rel=1e-3)


@pytest.mark.parametrize("key", ["mx-28", "xm430-w350", "xc330-m288"])
def test_a_coreless_servo_no_source_gives_a_rotor_for_is_scaled_from_the_coreless_fits(key):
    """The model file says the motor is coreless (the e-manual's "Motor" row), so the rotor is scaled from BAM's
    MX-64/MX-106 fits, several times below what the cored XL330's scaling gives the same motor torque."""
    from firmware_model.xseries.physics import XPhysicsParams

    spec = model(key)
    assert spec.physical.motor == "coreless" and spec.physical.rotor_inertia_at_motor_kg_m2 is None
    ratings = [(r.voltage_v, r.stall_torque_nm, r.stall_current_a, r.no_load_speed_rpm) for r in spec.physical.ratings]
    cored = XPhysicsParams.from_datasheet(gear_ratio=spec.physical.gear_ratio, ratings=ratings, motor="cored")
    served = build_x_firmware(spec).physics.params
    assert served.inertia_kg_m2 == pytest.approx(cored.inertia_kg_m2 / 7.68, rel=0.01)


def test_the_coreless_scaling_reproduces_both_bam_mx_fits_within_13_percent():
    from firmware_model.xseries.physics import XPhysicsParams

    for key in ("mx-64", "mx-106"):
        physical = model(key).physical
        ratings = [(r.voltage_v, r.stall_torque_nm, r.stall_current_a, r.no_load_speed_rpm) for r in physical.ratings]
        scaled = XPhysicsParams.from_datasheet(gear_ratio=physical.gear_ratio, ratings=ratings, motor="coreless")
        assert scaled.inertia_kg_m2 == pytest.approx(BAM_ARMATURE[key], rel=0.13)


def test_an_mx_64_reaches_its_speed_as_fast_as_bams_fitted_rotor_lets_it():
    """Full duty from rest, free shaft: 63 % of the no-load speed in about 14 ms (BAM's fitted rotor), not 115 ms."""
    firmware = build_x_firmware(model("mx-64"))
    firmware.command(XCommands(torque_enable=1, operating_mode=16, goal_pwm=885, pwm_limit=885))
    speeds = []
    for k in range(1, 301):
        firmware.step_to(k * 0.001)
        speeds.append(firmware.physics.velocity_rad_s)
    rise_ms = next(i + 1 for i, speed in enumerate(speeds) if speed >= 0.632 * speeds[-1])
    assert 10 <= rise_ms <= 20

