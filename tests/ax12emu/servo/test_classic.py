"""The classic-table translation (XL-320 numbers from its model file): registers to X commands, readings back."""

from __future__ import annotations

import pytest

from ax12emu.protocol.servo_models import model, parse_model
from ax12emu.servo.classic import ClassicMap
from firmware_model.xseries.interface import OperatingMode, XCommands, XSensed

JOINT = dict(torque_enable=1, goal_position=512, moving_speed=0, torque_limit=1023, cw_angle_limit=0, ccw_angle_limit=1023,
             p_gain=32, i_gain=0, d_gain=0, control_mode=2, shutdown=3, temperature_limit=65, min_voltage_limit=60,
             max_voltage_limit=90)


@pytest.fixture
def xl320() -> ClassicMap:
    return ClassicMap.from_model(model("xl-320"))


def test_positions_map_300_degrees_onto_pulses_centred_on_2048(xl320):
    """1024 units over 300 deg centred on 512: 512 -> 2048, one unit 300/1024 deg = 3.333 pulses; ends at +-150 deg."""
    assert xl320.position_to_pulses(512) == 2048
    assert xl320.position_to_pulses(0) == pytest.approx(2048 - 150 / 360 * 4096)
    assert xl320.position_to_pulses(1024) == pytest.approx(2048 + 150 / 360 * 4096)
    for value in (0, 1, 300, 511, 512, 900, 1023):
        assert xl320.pulses_to_position(xl320.position_to_pulses(value)) == value
    # a shaft in the dead zone (wheel mode turns through it) reads the nearer end; whole turns drop out
    assert xl320.pulses_to_position(4000) == 1023 and xl320.pulses_to_position(100) == 0
    assert xl320.pulses_to_position(2048 + 3 * 4096) == 512


def test_joint_mode_is_position_control_with_speed_torque_limit_gains_and_angle_limits(xl320):
    cmd = xl320.commands({**JOINT, "goal_position": 812, "moving_speed": 300, "torque_limit": 512, "cw_angle_limit": 100,
                          "ccw_angle_limit": 900, "p_gain": 64, "i_gain": 10, "d_gain": 5})
    assert cmd.operating_mode == OperatingMode.POSITION and cmd.torque_enable == 1
    assert cmd.goal_position == 3048  # 300 units = 87.9 deg = 1000 pulses
    assert cmd.profile_velocity == round(300 * 0.111 / 0.229)  # 33.3 rpm in 0.229 rpm units
    assert cmd.goal_pwm == round(512 * 885 / 1023)
    assert (cmd.min_position_limit, cmd.max_position_limit) == (round(2048 - 412 * 10 / 3), round(2048 + 388 * 10 / 3))
    # Kp = P/8 per unit in 1023ths of output -> KPP = P_x/128 per pulse in 885ths
    assert cmd.position_p_gain == round(64 / 8 * 128 * (885 / 1023) / (10 / 3))
    assert cmd.position_i_gain == round(10 * 1000 / 2048 * 0.001 * 65536 * (885 / 1023) / (10 / 3))
    assert cmd.position_d_gain == round(5 * 4 / 1000 / 0.001 * 16 * (885 / 1023) / (10 / 3))
    # Shutdown 3 (Overload | OverHeating on the XL-320) selects the firmware's Overload 0x20 and Overheating 0x04
    assert cmd.shutdown == 0x24


def test_moving_speed_zero_is_the_no_load_speed_and_one_is_the_slowest(xl320):
    # "the maximum rpm of the motor ... will not exceed the No Load Speed": the sheet's 114 rpm at 7.4 V, as a profile
    assert xl320.commands({**JOINT, "moving_speed": 0}).profile_velocity == round(114 / 0.229)
    assert xl320.commands({**JOINT, "moving_speed": 1}).profile_velocity == 1


def test_wheel_mode_is_pwm_control_with_the_direction_bit(xl320):
    ccw = xl320.commands({**JOINT, "control_mode": 1, "moving_speed": 512, "torque_limit": 1023})
    cw = xl320.commands({**JOINT, "control_mode": 1, "moving_speed": 1024 + 512, "torque_limit": 300})
    assert ccw.operating_mode == cw.operating_mode == OperatingMode.PWM
    assert ccw.goal_pwm == round(512 * 885 / 1023) and cw.goal_pwm == -round(512 * 885 / 1023)
    assert cw.pwm_limit == round(300 * 885 / 1023)  # Torque Limit bounds the output in wheel mode too
    assert xl320.commands({**JOINT, "control_mode": 1, "moving_speed": 1024}).goal_pwm == 0


def test_readings_come_back_in_classic_units_with_the_direction_bit(xl320):
    joint = xl320.commands(JOINT)
    sensed = XSensed(present_position=3048, present_velocity=-100, present_current=-400, present_pwm=300,
                     present_input_voltage=74, present_temperature=31, moving=1, hardware_error_status=0x20 | 0x01,
                     torque_enable=0)
    regs = xl320.sensed_to_registers(sensed, joint)
    assert regs["present_position"] == 812
    assert regs["present_speed"] == 1024 + round(100 * 0.229 / 0.111)  # clockwise
    assert regs["present_load"] == round(300 * 1023 / 885)  # the output's share, counter-clockwise (not the current)
    assert (regs["present_voltage"], regs["present_temperature"], regs["moving"], regs["torque_enable"]) == (74, 31, 1, 0)
    assert regs["hardware_error_status"] == 0x01 | 0x04  # Overload and Input Voltage in the XL-320's bits
    wheel = xl320.sensed_to_registers(sensed, xl320.commands({**JOINT, "control_mode": 1}))
    assert wheel["present_speed"] == round(300 * 1023 / 885)  # wheel mode: the output share, "about 0.1%"
    # a reading past the register's scale is held at its top
    assert xl320.sensed_to_registers(XSensed(present_velocity=600), joint)["present_speed"] == 1023


def test_angle_limits_both_zero_select_wheel_mode_without_a_mode_register():
    """The AX/MX rule, for a file without mode_register: both angle limits 0 is wheel mode."""
    text = open(model("xl-320").path, encoding="utf-8").read()
    text = text.replace('mode_register = "control_mode"\nwheel_modes = [1]\n', "")
    spec = parse_model(text, "classic-test", "classic-test.toml")
    classic = ClassicMap.from_model(spec)
    assert classic.commands({**JOINT, "cw_angle_limit": 0, "ccw_angle_limit": 0}).operating_mode == OperatingMode.PWM
    assert classic.commands(JOINT).operating_mode == OperatingMode.POSITION


def test_a_velocity_wheel_asks_for_the_speed():
    text = open(model("xl-320").path, encoding="utf-8").read().replace('wheel_output = "pwm"', 'wheel_output = "velocity"')
    classic = ClassicMap.from_model(parse_model(text, "classic-test", "classic-test.toml"))
    cmd = classic.commands({**JOINT, "control_mode": 1, "moving_speed": 1024 + 300})
    assert cmd.operating_mode == OperatingMode.VELOCITY and cmd.goal_velocity == -round(300 * 0.111 / 0.229)
    assert cmd.velocity_p_gain > 0 and cmd.velocity_i_gain > 0


@pytest.mark.parametrize(("old", "new", "message"), [
    ("position_centre = 512", "position_centre = 1024", "position_centre"),
    ("wheel_output = \"pwm\"", "wheel_output = \"torque\"", "wheel_output"),
    ("errors = { overload = 1,", "errors = { overload = 3,", "one bit"),
    ("errors = { overload = 1,", "errors = { stall = 1,", "errors"),
    ('mode_register = "control_mode"', 'mode_register = "operating_mode"', "mode_register"),
    ("p_gain_factor = 0.125\n", "", "p_gain needs"),
])
def test_a_broken_classic_section_is_refused_by_name(old, new, message):
    text = open(model("xl-320").path, encoding="utf-8").read()
    assert old in text
    with pytest.raises(ValueError, match=message):
        ClassicMap.from_model(parse_model(text.replace(old, new), "broken", "broken.toml"))


def test_a_model_without_a_classic_section_is_refused():
    with pytest.raises(ValueError, match=r"no \[classic\]"):
        ClassicMap.from_model(model("xl430-w250"))
    assert isinstance(ClassicMap.from_model(model("xl-320")).commands(JOINT), XCommands)
