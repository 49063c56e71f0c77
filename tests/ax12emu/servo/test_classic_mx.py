"""The MX series' part of the classic map: multi-turn mode, Goal Acceleration, Torque Control Mode, Current(68)."""

from __future__ import annotations

from importlib import resources

import pytest

from ax12emu.protocol.servo_models import model, parse_model
from ax12emu.servo.classic import CURRENT_ZERO, X_ACCELERATION_UNIT_DEG_S2, ClassicMap
from firmware_model.xseries.interface import OperatingMode, XSensed

JOINT = {"torque_enable": 1, "goal_position": 3000, "moving_speed": 0, "torque_limit": 1023, "cw_angle_limit": 0,
         "ccw_angle_limit": 4095, "p_gain": 32, "i_gain": 0, "d_gain": 0, "shutdown": 36, "multi_turn_offset": 0,
         "resolution_divider": 1, "goal_acceleration": 0}


@pytest.fixture
def mx64() -> ClassicMap:
    return ClassicMap.from_model(model("mx-64"))


def test_joint_mode_positions_are_the_x_series_pulses(mx64):
    cmd = mx64.commands(JOINT)
    assert cmd.operating_mode == OperatingMode.POSITION
    assert (cmd.goal_position, cmd.min_position_limit, cmd.max_position_limit) == (3000, 0, 4095)
    # Moving Speed 0: a profile at the sheet's no-load speed (63 rpm at 12 V), no acceleration
    assert (cmd.profile_velocity, cmd.profile_acceleration) == (round(63 / 0.229), 0)
    # Shutdown 36 (Overheating 0x04, Overload 0x20) is the X series' bits of the same names.
    assert cmd.shutdown == 0x24


def test_goal_acceleration_is_profile_acceleration_and_needs_a_speed(mx64):
    cmd = mx64.commands({**JOINT, "goal_acceleration": 10, "moving_speed": 300})
    assert cmd.profile_acceleration == round(10 * 8.583 / X_ACCELERATION_UNIT_DEG_S2)  # 85.8 deg/s^2 in 21.46 deg/s^2 units
    assert cmd.profile_velocity == round(300 * 0.114 / 0.229)
    # Moving Speed 0 ("the maximum rpm of the motor") with an acceleration: the sheet's no-load speed, 63 rpm at 12 V.
    cmd = mx64.commands({**JOINT, "goal_acceleration": 1})
    assert cmd.profile_acceleration == 1 and cmd.profile_velocity == round(63 / 0.229)


def test_multi_turn_mode_reads_signed_goals_in_the_divided_frame_with_the_offset(mx64):
    values = {**JOINT, "cw_angle_limit": 4095, "ccw_angle_limit": 4095, "goal_position": -5000 & 0xFFFF,
              "resolution_divider": 2, "multi_turn_offset": 300}
    cmd = mx64.commands(values)
    assert cmd.operating_mode == OperatingMode.EXTENDED_POSITION
    assert cmd.goal_position == -10000 and cmd.homing_offset == 600
    # Present Position = Real / Divider + Offset: the firmware's count already holds the offset (times the divider).
    registers = mx64.sensed_to_registers(XSensed(present_position=-9400), cmd, values)
    assert registers["present_position"] == (-4700) & 0xFFFF
    # Outside multi-turn mode the divider and offset are ignored (e-manual: "applied in Multi-turn Mode only").
    assert mx64.divider({**JOINT, "resolution_divider": 4}) == 1
    assert mx64.commands({**JOINT, "multi_turn_offset": 300}).homing_offset == 0


def test_torque_control_mode_is_current_control_within_torque_limit(mx64):
    cmd = mx64.commands({**JOINT, "torque_ctrl_mode_enable": 1, "goal_torque": 1024 + 150, "torque_limit": 512})
    assert cmd.operating_mode == OperatingMode.CURRENT
    assert cmd.goal_current == -150  # bit 10: CW
    # Torque Limit 50 % of the sheet's 4.1 A stall current at 12 V, in 4.5 mA units.
    assert cmd.current_limit == round(512 / 1023 * 4.1 / 0.0045)
    registers = mx64.sensed_to_registers(XSensed(present_current=-150), cmd, {})
    assert registers["current"] == CURRENT_ZERO - 150


def test_wheel_mode_is_a_speed_and_the_mx28_has_no_current_register():
    mx28 = ClassicMap.from_model(model("mx-28"))
    cmd = mx28.commands({**JOINT, "cw_angle_limit": 0, "ccw_angle_limit": 0, "moving_speed": 1024 + 200, "goal_acceleration": 5})
    assert cmd.operating_mode == OperatingMode.VELOCITY
    assert cmd.goal_velocity == round(-200 * 0.114 / 0.229)
    assert cmd.profile_acceleration == round(5 * 8.583 / X_ACCELERATION_UNIT_DEG_S2)
    assert "current" not in mx28.sensed_registers
    # The firmware's error bits as Protocol 1.0's: Input Voltage 0x01, Overheating 0x04, Overload 0x20.
    assert mx28.errors_to_classic(0x01 | 0x04 | 0x20) == 0x25


@pytest.mark.parametrize(
    ("addition", "message"),
    [
        ("acceleration_unit_deg_s2 = 8.583", "no goal_acceleration register"),
        ("multi_turn_limit = 4095", "come together"),
        ("multi_turn_limit = 4095\nmulti_turn_goal_limit = 40000", "must lie in 1..32767"),
    ],
)
def test_the_mx_keys_are_checked(addition, message):
    """Appended to the XL-320 file, whose [classic] section is its last (the XL-320 has no Goal Acceleration)."""
    text = resources.files("ax12emu.protocol").joinpath("models/xl-320.toml").read_text(encoding="utf-8")
    assert text.rstrip().splitlines()[-1].startswith("errors")
    with pytest.raises(ValueError, match=message):
        parse_model(text + addition + "\n", "broken", "broken.toml")


@pytest.mark.parametrize("key", ["mx-64", "mx-106"])
def test_the_mx_position_loop_puts_out_what_bam_measured_on_real_mx_servos(key):
    """Rhoban's BAM measured on real MX-64s and MX-106s with an oscilloscope: duty = 0.158 x P Gain x error (rad), at the
    factory P Gain 32 7.9 / 1023 of full output per pulse, not the 4 / 1023 of Kp = P/8 read per position unit."""
    import math

    from ax12emu.servo.model_factory2 import build_x_firmware

    spec = model(key)
    cmd = ClassicMap.from_model(spec).commands({**JOINT, "goal_position": 2048})
    firmware = build_x_firmware(spec)
    firmware.command(cmd)
    firmware.step_to(0.01)
    firmware.set_blocked(True)  # the error stays what it is written as
    cmd = ClassicMap.from_model(spec).commands({**JOINT, "goal_position": 2048 + 40, "moving_speed": 0})
    cmd.profile_velocity = 0  # no profile: the whole error at once
    firmware.command(cmd, goal_written=True)
    firmware.step_to(0.02)
    duty = firmware.sense().present_pwm / 885
    assert duty == pytest.approx(0.158 * 32 * 40 * 2 * math.pi / 4096, rel=0.03)


def test_a_change_of_mode_by_the_angle_limits_is_a_goal_write(mx64):
    """The classic firmware runs the new mode on the goals it holds (wheel: Moving Speed, joint: Goal Position); the X
    firmware's mode change holds where it is unless told a goal came."""
    wheel = {**JOINT, "cw_angle_limit": 0, "ccw_angle_limit": 0}
    multi = {**JOINT, "cw_angle_limit": 4095, "ccw_angle_limit": 4095}
    assert mx64.goal_changed(JOINT, wheel) and mx64.goal_changed(wheel, JOINT)
    assert mx64.goal_changed(JOINT, multi) and mx64.goal_changed(multi, wheel)
    assert not mx64.goal_changed(JOINT, {**JOINT, "cw_angle_limit": 100})  # joint mode still: the goal stays
    assert not mx64.goal_changed(None, wheel)
