"""The X-series firmware model against the e-manual's behaviour, in virtual time.

Data-sheet inputs are the e-manual's figures (https://emanual.robotis.com/docs/en/dxl/x/xm430-w350/,
.../xl430-w250/, .../xl330-m288/: gear ratio, stall torque and current, no-load speed per voltage) and
the control tables' initial gains; everything checked is measured from the model's registers.
"""

from __future__ import annotations

import dataclasses
import json
import math
import random
import statistics
from pathlib import Path

import pytest

from firmware_model.xseries.firmware import PULSE_RAD, PULSES_PER_REV, ThermalParams, XFirmware, build_x_servo
from firmware_model.xseries.interface import (
    HW_ERROR_INPUT_VOLTAGE,
    HW_ERROR_OVERHEATING,
    HW_ERROR_OVERLOAD,
    TRAJECTORY_SENSED,
    OperatingMode,
    XCommands,
)
from firmware_model.xseries.profile import VELOCITY_UNIT_PULSES_S

# (gear ratio, ratings (V, stall N m, stall A, no-load rpm), current unit A or None, rated V, control-table initial values)
MODELS = {
    "XM430-W350": (
        353.5,
        [(11.1, 3.8, 2.1, 43), (12.0, 4.1, 2.3, 46), (14.8, 4.8, 2.7, 57)],
        0.00269,
        12.0,
        dict(position_p_gain=800, position_d_gain=0, velocity_p_gain=100, velocity_i_gain=1920, current_limit=1193,
             velocity_limit=200, max_voltage_limit=160, min_voltage_limit=95, shutdown=52),
    ),
    "XL430-W250": (
        258.5,
        [(9.0, 1.0, 1.0, 47), (11.1, 1.4, 1.3, 57), (12.0, 1.5, 1.4, 61)],
        None,
        11.1,
        dict(position_p_gain=640, position_d_gain=4000, velocity_p_gain=100, velocity_i_gain=1000, current_limit=0,
             velocity_limit=265, max_voltage_limit=140, min_voltage_limit=60, shutdown=52),
    ),
    "XL330-M288": (
        288.4,
        [(3.7, 0.42, 1.11, 76), (5.0, 0.52, 1.47, 103), (6.0, 0.60, 1.74, 123)],
        0.001,
        5.0,
        dict(position_p_gain=400, position_d_gain=0, velocity_p_gain=180, velocity_i_gain=1600, current_limit=1750,
             velocity_limit=445, max_voltage_limit=70, min_voltage_limit=35, shutdown=53),
    ),
}


#: The position controller's output scale measured on a real XL330 (see XFirmware); the others keep the e-manual's.
OUTPUT_SCALE = {"XL330-M288": 0.5}


def make(model: str = "XM430-W350", *, supply_v: float | None = None, **registers) -> tuple[XFirmware, XCommands]:
    """A servo of ``model`` at its rated voltage with its initial control table, torque on, holding where it is."""
    gear, ratings, unit, rated_v, table = MODELS[model]
    kwargs = {k: registers.pop(k) for k in ("thermal", "overload_time_s", "position_output_scale") if k in registers}
    kwargs.setdefault("position_output_scale", OUTPUT_SCALE.get(model, 1.0))
    servo = build_x_servo(gear_ratio=gear, ratings=ratings, current_unit_a=unit, supply_v=supply_v or rated_v, **kwargs)
    commands = XCommands(**{"goal_pwm": 885, "goal_current": table["current_limit"], **table, **registers})
    servo.command(commands)
    if commands.torque_enable:
        servo.command(commands)
    return servo, commands


def write(servo: XFirmware, commands: XCommands, **registers) -> None:
    for name, value in registers.items():
        setattr(commands, name, value)
    goal = any(name.startswith("goal_") for name in registers)
    servo.command(XCommands(**vars(commands)), goal_written=goal)


def run(servo: XFirmware, duration_s: float):
    """Step ``duration_s`` millisecond by millisecond; the registers after each step."""
    out = []
    t0 = servo.time_s
    for k in range(1, int(round(duration_s / servo.step_s)) + 1):
        servo.step_to(t0 + k * servo.step_s)
        out.append(servo.sense())
    return out


# ---------------------------------------------------------------------------- profiles


def test_trapezoid_profile_timing_matches_the_emanual_formulas():
    servo, cmd = make(torque_enable=1, profile_velocity=100, profile_acceleration=20)
    start = servo.sense().present_position
    write(servo, cmd, goal_position=start + 2048)
    t1_ms = 64 * 100 / 20  # e-manual: t1 = 64 * Profile Velocity / Profile Acceleration
    t3_ms = t1_ms + 64 * 2048 / 100  # t2 = 64 * dPos / Profile Velocity, t3 = t1 + t2
    trace = run(servo, 2.0)
    velocity = [s.velocity_trajectory for s in trace]
    reached_v = next(i + 1 for i, v in enumerate(velocity) if v >= 100)
    assert abs(reached_v - t1_ms) <= 3
    done = next(i + 1 for i, s in enumerate(trace) if not s.moving_status & 0x02)  # profile over
    assert abs(done - t3_ms) <= 3
    assert trace[done].position_trajectory == start + 2048
    assert all(s.moving_status & 0x30 == 0x30 for s in trace)  # trapezoidal
    assert all(s.moving_status & 0x02 for s in trace[: int(t3_ms) - 3])  # profile ongoing
    assert all(s.moving for s in trace[: int(t3_ms) - 3])
    assert not trace[-1].moving_status & 0x02


def test_short_move_is_triangular_and_zero_acceleration_rectangular():
    servo, cmd = make(torque_enable=1, profile_velocity=100, profile_acceleration=20)
    start = servo.sense().present_position
    # V_PRFL_TRI = sqrt(A * dPos) = sqrt(20 * 200) = 63 < 100: triangular, peak 63 units at t3 / 2.
    write(servo, cmd, goal_position=start + 200)
    trace = run(servo, 1.0)
    assert trace[0].moving_status & 0x30 == 0x20
    peak = max(s.velocity_trajectory for s in trace)
    assert abs(peak - math.sqrt(20 * 200)) <= 1.5
    done = next(i + 1 for i, s in enumerate(trace) if not s.moving_status & 0x02)
    assert abs(done - 2 * 64 * math.sqrt(200 / 20)) <= 3  # t3 = 2 * t1 with t1 = 64 * V_TRI / A
    write(servo, cmd, profile_acceleration=0, goal_position=start)
    trace = run(servo, 0.5)
    assert trace[0].moving_status & 0x30 == 0x10
    assert trace[0].velocity_trajectory == -100  # rectangular: the speed jumps to Profile Velocity


def test_time_based_profile_reaches_the_goal_at_the_given_time():
    servo, cmd = make(torque_enable=1, drive_mode=0x04, profile_velocity=1500, profile_acceleration=300)
    start = servo.sense().present_position
    write(servo, cmd, goal_position=start + 1500)
    trace = run(servo, 1.8)
    done = next(i + 1 for i, s in enumerate(trace) if not s.moving_status & 0x02)
    assert abs(done - 1500) <= 2
    assert trace[done].position_trajectory == start + 1500
    assert trace[1400].position_trajectory < start + 1500 - 10
    assert abs(trace[-1].present_position - (start + 1500)) <= 5


def test_velocity_override_keeps_the_trajectory_velocity_continuous():
    servo, cmd = make(torque_enable=1, profile_velocity=150, profile_acceleration=30)
    start = servo.sense().present_position
    write(servo, cmd, goal_position=start + 4000)
    before = run(servo, 0.6)[-1].velocity_trajectory
    write(servo, cmd, goal_position=start + 500)  # a new goal behind: brake, turn, come back
    after = run(servo, 0.002)[0].velocity_trajectory
    assert before > 100 and abs(after - before) <= 2
    trace = run(servo, 5.0)
    assert abs(trace[-1].present_position - (start + 500)) <= 5


def test_a_goal_at_the_read_position_starts_no_profile_so_the_next_starts_from_rest():
    """The firmware knows the shaft by its encoder's whole count: Goal Position written as the Present Position just
    read, then torque on, leaves the trajectory standing there (no profile), and a goal written a few milliseconds
    later starts its trapezoid from rest.  (Planned from the exact angle, 0.44 of a pulse off the count, the first
    goal ran a profile of that fraction, still accelerating 4 ms later, and the next trapezoid started with its
    speed, about 4 ms ahead of the e-manual's from rest.)"""
    servo, cmd = make("XL330-M288", torque_enable=0, profile_velocity=85, profile_acceleration=36)
    servo.physics.angle_rad = (2048 + 0.44) * PULSE_RAD  # torque off, the shaft still between two counts
    run(servo, 0.005)
    present = servo.sense().present_position
    write(servo, cmd, goal_position=present)
    write(servo, cmd, torque_enable=1)
    held = run(servo, 0.004)[-1]
    assert not held.moving_status & 0x02 and held.velocity_trajectory == 0 and held.position_trajectory == present
    write(servo, cmd, goal_position=present + 400)
    trace = run(servo, 0.12)
    accel = 85 * VELOCITY_UNIT_PULSES_S / (64 * 85 / 36 / 1000.0)  # pulses/s^2: Profile Velocity reached in t1
    for ms in (40, 80, 120):
        assert abs(trace[ms - 1].position_trajectory - present - 0.5 * accel * (ms / 1000.0) ** 2) <= 1, ms


def test_goals_written_again_before_a_step_leave_no_trace_of_the_earlier_ones():
    """Two writes between two control ticks: the loop plans once, from its tick's state, so the servo moves as if
    only the last had come.  The earlier one here is a step profile (Profile Velocity 0), which has no length and
    so is never running: planning the last from it would start from the present position at rest instead of
    the running trapezoid's point and speed."""
    moves = []
    for earlier in (None, dict(profile_velocity=0, goal_position=0)):
        servo, cmd = make(torque_enable=1, profile_velocity=100, profile_acceleration=20)
        start = servo.sense().present_position
        write(servo, cmd, goal_position=start + 3000)
        run(servo, 0.3)  # the trapezoid is running at speed
        if earlier is not None:
            write(servo, cmd, **earlier)
        write(servo, cmd, profile_velocity=100, goal_position=start + 1000)
        moves.append([(s.position_trajectory, s.velocity_trajectory, s.present_position) for s in run(servo, 0.8)])
    assert moves[0][0][1] > 50  # (it was running at speed, so the start matters)
    assert moves[1] == moves[0]


# ---------------------------------------------------------------------------- control loops


@pytest.mark.parametrize("model", MODELS)
def test_position_mode_settles_within_a_few_pulses_at_default_gains(model):
    servo, cmd = make(model, torque_enable=1)
    start = servo.sense().present_position
    write(servo, cmd, goal_position=start + 1024)
    trace = run(servo, 2.0)
    # A P controller stops where its drive no longer beats the gears' dry friction: that band, in pulses.
    p = servo.physics.params
    nm_per_pulse = p.torque_constant_nm_a * servo.physics.supply_v / p.resistance_ohm * (
        servo.position_output_scale * cmd.position_p_gain / 128 / 885)
    band = p.coulomb_friction_nm / nm_per_pulse
    tolerance = max(4, math.ceil(band) + 1)
    assert all(abs(s.present_position - (start + 1024)) <= tolerance for s in trace[-200:])
    assert trace[-1].moving == 0
    if band < 4:
        assert trace[-1].moving_status & 0x01  # in position


@pytest.mark.parametrize("model", MODELS)
def test_velocity_mode_reaches_goal_velocity(model):
    servo, cmd = make(model, torque_enable=1, operating_mode=OperatingMode.VELOCITY, profile_acceleration=50)
    write(servo, cmd, goal_velocity=-120)
    trace = run(servo, 1.5)
    # e-manual: t1 = 64 * Goal Velocity / Profile Acceleration = 154 ms to reach the goal on the trajectory.
    assert abs(next(i + 1 for i, s in enumerate(trace) if s.velocity_trajectory == -120) - 64 * 120 / 50) <= 3
    assert all(abs(s.present_velocity + 120) <= 3 for s in trace[-300:])
    assert trace[-1].moving == 1


@pytest.mark.parametrize(("model", "voltage_v", "rpm"), [("XL430-W250", 11.1, 57), ("XL330-M288", 5.0, 103)])
def test_no_load_speed_of_the_data_sheet_in_velocity_mode(model, voltage_v, rpm):
    servo, cmd = make(model, supply_v=voltage_v, torque_enable=1, operating_mode=OperatingMode.VELOCITY, velocity_limit=1023)
    write(servo, cmd, goal_velocity=1023)
    trace = run(servo, 1.5)
    speed_rpm = trace[-1].present_velocity * 0.229
    assert trace[-1].present_pwm == 885
    assert speed_rpm == pytest.approx(rpm, rel=0.10)


def _hold_shaft(servo: XFirmware, duration_s: float, stiffness_nm_rad: float = 200.0, damping_nm_s_rad: float = 2.0):
    """A stiff hand on the horn: a spring to the starting angle; returns its torque at the end (N m)."""
    anchor = servo.physics.angle_rad
    torque = 0.0
    for _ in range(int(round(duration_s / servo.step_s))):
        p = servo.physics
        torque = -stiffness_nm_rad * (p.angle_rad - anchor) - damping_nm_s_rad * p.velocity_rad_s
        servo.set_external_torque(torque)
        servo.step_to(servo.time_s + servo.step_s)
    return torque


def test_current_mode_on_a_held_shaft_gives_torque_proportional_to_current():
    torques = []
    for goal_ma in (300, 600):
        servo, cmd = make("XL330-M288", torque_enable=1, operating_mode=OperatingMode.CURRENT)
        write(servo, cmd, goal_current=goal_ma)
        held_nm = -_hold_shaft(servo, 0.5)
        assert servo.sense().present_current == pytest.approx(goal_ma, abs=5)
        torques.append(held_nm)
        kt = servo.physics.params.torque_constant_nm_a
        # The hand holds the motor's torque, less what the gears' dry friction takes (at most Coulomb).
        assert held_nm == pytest.approx(kt * goal_ma / 1000.0, abs=servo.physics.params.coulomb_friction_nm * 1.01)
    assert torques[1] / torques[0] == pytest.approx(2.0, rel=0.1)


def test_current_based_position_limits_the_current_to_goal_current():
    servo, cmd = make("XL330-M288", torque_enable=1, operating_mode=OperatingMode.CURRENT_BASED_POSITION, goal_current=200)
    write(servo, cmd, goal_position=servo.sense().present_position + 2000)
    held_nm = _hold_shaft(servo, 0.5)  # far from its goal, the PID asks for far more than 200 mA
    assert servo.sense().present_current == pytest.approx(200, abs=5)
    kt = servo.physics.params.torque_constant_nm_a
    assert -held_nm == pytest.approx(kt * 0.2, abs=servo.physics.params.coulomb_friction_nm * 1.01)


def test_pwm_limit_caps_the_duty_in_pwm_and_position_modes():
    servo, cmd = make(torque_enable=1, operating_mode=OperatingMode.PWM, pwm_limit=300)
    write(servo, cmd, goal_pwm=885)
    trace = run(servo, 1.0)
    assert max(abs(s.present_pwm) for s in trace) == 300
    full, fcmd = make(torque_enable=1, operating_mode=OperatingMode.PWM)
    write(full, fcmd, goal_pwm=885)
    full_speed = run(full, 1.0)[-1].present_velocity
    assert trace[-1].present_velocity < 0.4 * full_speed
    servo, cmd = make(torque_enable=1, pwm_limit=200)
    write(servo, cmd, goal_position=servo.sense().present_position + 2000)
    assert max(abs(s.present_pwm) for s in run(servo, 1.0)) == 200


# ---------------------------------------------------------------------------- position registers


def test_homing_offset_shifts_present_position():
    servo, cmd = make(operating_mode=OperatingMode.EXTENDED_POSITION)
    plain = servo.sense().present_position
    write(servo, cmd, homing_offset=5000)
    assert servo.sense().present_position == plain + 5000
    write(servo, cmd, operating_mode=OperatingMode.POSITION, homing_offset=700)
    assert servo.sense().present_position == plain + 700
    write(servo, cmd, homing_offset=2000)  # outside -1024..1024: ignored in Position Control Mode
    assert servo.sense().present_position == plain


def test_extended_position_mode_counts_turns_and_clear_drops_them():
    servo, cmd = make(torque_enable=1, operating_mode=OperatingMode.EXTENDED_POSITION, profile_velocity=200, profile_acceleration=100)
    goal = 3 * PULSES_PER_REV + 100
    write(servo, cmd, goal_position=goal)
    trace = run(servo, 6.0)
    assert abs(trace[-1].present_position - goal) <= 4
    assert servo.physics.angle_rad == pytest.approx(goal * 2 * math.pi / 4096, abs=0.01)
    servo.clear_multi_turn()
    after = run(servo, 0.5)[-1].present_position
    assert abs(after - 100) <= 4  # the angle within one turn, and the shaft held where it was
    assert servo.physics.angle_rad == pytest.approx(goal * 2 * math.pi / 4096, abs=0.01)


def test_position_mode_resets_to_one_turn_at_torque_on_and_clamps_goal_to_limits():
    servo, cmd = make(operating_mode=OperatingMode.EXTENDED_POSITION, torque_enable=1)
    write(servo, cmd, goal_position=2 * PULSES_PER_REV + 1000)
    run(servo, 5.0)
    write(servo, cmd, torque_enable=0)
    write(servo, cmd, operating_mode=OperatingMode.POSITION, max_position_limit=3000, min_position_limit=500)
    assert abs(servo.sense().present_position - 1000) <= 4
    write(servo, cmd, torque_enable=1)
    write(servo, cmd, goal_position=4000)  # beyond Max Position Limit: held at it
    trace = run(servo, 2.0)
    assert abs(trace[-1].present_position - 3000) <= 4


def test_reverse_drive_mode_mirrors_the_shaft():
    servo, cmd = make(torque_enable=1, drive_mode=0x01)
    start = servo.sense().present_position
    angle0 = servo.physics.angle_rad
    write(servo, cmd, goal_position=start + 1000)
    trace = run(servo, 2.0)
    assert abs(trace[-1].present_position - (start + 1000)) <= 4
    assert servo.physics.angle_rad - angle0 == pytest.approx(-1000 * 2 * math.pi / 4096, abs=0.01)


def test_torque_on_by_goal_update():
    servo, cmd = make(drive_mode=0x08)
    assert servo.sense().torque_enable == 0
    write(servo, cmd, goal_position=servo.sense().present_position + 500)
    assert servo.sense().torque_enable == 1
    # The table now reads Torque Enable 1: handed back with another write, it is no new torque-on (the
    # profile runs on), and a 0 written after it turns the torque off.
    run(servo, 0.1)
    moving = servo.sense()
    write(servo, cmd, torque_enable=1)
    assert servo.sense().position_trajectory == moving.position_trajectory  # a torque-on would hold where it is
    write(servo, cmd, torque_enable=0)
    assert servo.sense().torque_enable == 0 and run(servo, 0.01)[-1].present_pwm == 0
    plain, pcmd = make()
    write(plain, pcmd, goal_position=plain.sense().present_position + 500)
    assert plain.sense().torque_enable == 0
    assert run(plain, 0.5)[-1].present_position == plain.sense().present_position


# ---------------------------------------------------------------------------- protection


def test_overload_shuts_down_and_reboot_clears_it():
    servo, cmd = make(torque_enable=1, overload_time_s=1.0)
    start = servo.sense().present_position
    write(servo, cmd, goal_position=start + 1000)
    servo.set_external_torque(-6.0)  # beyond the XM430-W350's 4.1 N m stall torque at 12 V
    trace = run(servo, 2.0)
    first = next(i for i, s in enumerate(trace) if s.hardware_error_status)
    assert 0.9 <= (first + 1) / 1000 <= 1.3
    assert trace[-1].hardware_error_status == HW_ERROR_OVERLOAD
    assert trace[-1].torque_enable == 0 and trace[-1].present_pwm == 0
    write(servo, cmd, torque_enable=0)
    write(servo, cmd, torque_enable=1)  # refused until REBOOT
    assert servo.sense().torque_enable == 0
    servo.set_external_torque(0.0)
    servo.reboot()
    assert servo.sense().hardware_error_status == 0 and servo.sense().torque_enable == 0
    write(servo, cmd, torque_enable=0)
    write(servo, cmd, torque_enable=1)
    assert servo.sense().torque_enable == 1


def test_a_servo_rebooted_hotter_than_its_limit_reports_overheating_again_at_rest():
    """Rebooted while still past Temperature Limit, with the torque off and the shaft still, the servo took the
    closed-form path of a servo at rest, which only looked for a temperature climbing across the limit: Hardware
    Error Status read 0 for the minute it took to cool, and a torque-on was taken."""
    servo, cmd = make(torque_enable=0)
    servo.temperature_c = cmd.temperature_limit + 15.0
    run(servo, 0.01)
    assert servo.sense().hardware_error_status == HW_ERROR_OVERHEATING
    servo.reboot()
    run(servo, 1.0)
    hot = servo.sense()
    assert hot.present_temperature > cmd.temperature_limit and hot.hardware_error_status == HW_ERROR_OVERHEATING


@pytest.mark.parametrize(("mode", "limit"), [(OperatingMode.POSITION, {"goal_pwm": 150}),
                                              (OperatingMode.CURRENT_BASED_POSITION, {"goal_current": 100}),
                                              (OperatingMode.CURRENT_BASED_POSITION, {"goal_pwm": 150})])
def test_the_position_integral_stops_at_a_lowered_goal_pwm_or_goal_current(mode, limit):
    """The integral stopped only at full scale (885, or Current Limit): held back by a load the lowered Goal PWM or
    Goal Current could not beat, it wound up, and once let go the shaft overshot its goal by 79 and 316 pulses,
    where without integral action it overshoots by 9 and 200 (the drive's own swing at that limit); in current-based
    position the current loop's Goal PWM bound too (111 against 22)."""

    def overshoot(i_gain: int) -> int:
        servo, cmd = make(torque_enable=1, operating_mode=mode, position_i_gain=i_gain, **limit)
        goal = servo.sense().present_position
        servo.set_external_torque(-0.6 if "goal_current" in limit else -1.0)
        run(servo, 3.0)
        assert goal - servo.sense().present_position > 300  # held well back: the drive at its lowered limit
        servo.set_external_torque(0.0)
        return max(s.present_position for s in run(servo, 2.0)) - goal

    assert overshoot(2000) <= overshoot(0) + 10


def test_overload_not_selected_by_shutdown_is_not_reported():
    servo, cmd = make(torque_enable=1, shutdown=0x04, overload_time_s=0.5)
    write(servo, cmd, goal_position=servo.sense().present_position + 1000)
    servo.set_external_torque(-6.0)
    trace = run(servo, 1.5)
    assert trace[-1].hardware_error_status == 0 and trace[-1].torque_enable == 1


def _overload_after_s(servo: XFirmware, limit_s: float) -> float | None:
    """Seconds until Hardware Error Status reads Overload, None if not within ``limit_s`` (10 ms resolution)."""
    for k in range(1, int(round(limit_s * 100)) + 1):
        servo.step_to(servo.time_s + 0.01)
        if servo.sense().hardware_error_status & HW_ERROR_OVERLOAD:
            return k / 100
    return None


@pytest.mark.parametrize(
    ("case", "low_s", "high_s"),
    [
        ("full drive, blocked, Position mode", 0.9, 1.2),  # a full stall: the overload time
        ("Goal PWM 885, blocked, PWM mode", 0.9, 1.2),  # the same current in another mode: the same time
        ("Goal Current 400 (1.08 A), blocked, Current-based Position", 2.0, 6.0),  # below the PWM limit all the while
        ("0.94 A holding a load, Position mode", 3.0, 8.0),  # ROBOTIS: "a high current ... for a few seconds"
        ("Goal PWM 200 (0.51 A), blocked, Position mode", None, None),  # at its PWM limit, but little current
        ("0.45 A holding a load, Position mode", None, None),  # 1/5 of the stall current: the e-manual's design load
    ],
)
def test_overload_is_current_held_over_time_whatever_limits_it(case, low_s, high_s):
    """XM430-W350 at 12 V (stall current 2.25 A in the model): Overload comes from the winding's current over time,
    the same in every mode, not from the output sitting at its limit (``OVERLOAD_CURRENT_SHARE``)."""
    servo, cmd = make(torque_enable=1, overload_time_s=1.0)
    k_t = servo.physics.params.torque_constant_nm_a
    if "PWM mode" in case:
        write(servo, cmd, operating_mode=OperatingMode.PWM)
        write(servo, cmd, torque_enable=1, goal_pwm=885)
        servo.set_blocked(True)
    elif "Current-based" in case:
        write(servo, cmd, operating_mode=OperatingMode.CURRENT_BASED_POSITION)
        write(servo, cmd, torque_enable=1, goal_current=400)
        write(servo, cmd, goal_position=servo.sense().present_position + 1000)
        servo.set_blocked(True)
    elif "holding" in case:
        amps = float(case.split(" A")[0])
        servo.set_external_torque(-amps * k_t)
    else:
        pwm = 200 if "Goal PWM 200" in case else 885
        write(servo, cmd, goal_pwm=pwm)
        write(servo, cmd, goal_position=servo.sense().present_position + 1000)
        servo.set_blocked(True)
    tripped = _overload_after_s(servo, 30.0)
    if low_s is None:
        assert tripped is None and servo.sense().torque_enable == 1
    else:
        assert tripped is not None and low_s <= tripped <= high_s, tripped


def test_the_overload_account_drains_when_the_current_falls():
    """0.9 s of full stall, then 3 s free: the account has drained, and the next stall takes the whole overload
    time again; with a shorter rest it trips sooner."""
    for rest_s, low_s, high_s in ((3.0, 0.9, 1.2), (0.3, 0.05, 0.5)):
        servo, cmd = make(torque_enable=1, operating_mode=OperatingMode.PWM, overload_time_s=1.0)
        write(servo, cmd, torque_enable=1, goal_pwm=885)
        servo.set_blocked(True)
        assert _overload_after_s(servo, 0.9) is None
        write(servo, cmd, goal_pwm=0)
        servo.step_to(servo.time_s + rest_s)
        write(servo, cmd, goal_pwm=885)
        tripped = _overload_after_s(servo, 2.0)
        assert tripped is not None and low_s <= tripped <= high_s, (rest_s, tripped)


def test_overheating_from_winding_loss_shuts_down():
    # Shutdown selects Overheating alone: 1.2 A is 0.82 of the stall current, which Overload would stop first.
    servo, cmd = make("XL330-M288", torque_enable=1, operating_mode=OperatingMode.CURRENT,
                      thermal=ThermalParams(time_constant_s=20.0), temperature_limit=70, shutdown=HW_ERROR_OVERHEATING)
    write(servo, cmd, goal_current=1200)
    hot = None
    for k in range(60):
        _hold_shaft(servo, 0.5)
        s = servo.sense()
        if s.hardware_error_status:
            hot = (k + 1) * 0.5
            break
    assert hot is not None and s.hardware_error_status == HW_ERROR_OVERHEATING
    assert s.present_temperature >= 70 and s.torque_enable == 0
    cooled = servo.temperature_c
    servo.step_to(servo.time_s + 60.0)  # torque off and at rest: cools in one skipped stretch
    assert servo.temperature_c < cooled - 20


def test_input_voltage_outside_limits():
    servo, cmd = make(torque_enable=1, shutdown=52 | HW_ERROR_INPUT_VOLTAGE)
    assert servo.sense().present_input_voltage == 120
    servo.set_supply_v(16.5)
    run(servo, 0.01)
    s = servo.sense()
    assert s.hardware_error_status == HW_ERROR_INPUT_VOLTAGE and s.torque_enable == 0
    quiet, qcmd = make(torque_enable=1)  # the default Shutdown (52) does not select it
    quiet.set_supply_v(16.5)
    run(quiet, 0.01)
    assert quiet.sense().hardware_error_status == 0


def test_a_shutdown_that_cuts_the_output_latches_nothing_and_reports_the_conditions_present():
    """The Protocol 1.0 MX firmware's Alarm Shutdown (``shutdown_cuts_output``): the output goes to 0 % at the step
    the overload is found, torque stays on, nothing is latched, and the overload is reported until the host
    restores the output; a condition Shutdown does not select is reported and cuts nothing."""
    servo, cmd = make(torque_enable=1, overload_time_s=1.0)
    servo.shutdown_cuts_output = True
    write(servo, cmd, goal_position=servo.sense().present_position + 1000)
    servo.set_external_torque(-6.0)  # beyond the XM430-W350's 4.1 N m stall torque at 12 V
    servo.step_to(servo.time_s + 0.9)
    assert servo.cut_errors == 0 and servo.present_errors == 0
    servo.step_to(servo.time_s + 2.0)  # one stretch, as a bus brings a servo nobody asked about to its time: cut within it
    s = servo.sense()
    assert servo.cut_errors == HW_ERROR_OVERLOAD and servo.present_errors == HW_ERROR_OVERLOAD
    assert s.present_pwm == 0 and s.torque_enable == 1 and s.hardware_error_status == 0
    driving, dcmd = make(torque_enable=1, overload_time_s=1.0, shutdown=0)  # the same stall, nothing selected
    driving.shutdown_cuts_output = True
    write(driving, dcmd, goal_position=driving.sense().present_position + 1000)
    driving.set_external_torque(-6.0)
    driving.step_to(servo.time_s)
    assert driving.sense().present_pwm != 0 and driving.present_errors == HW_ERROR_OVERLOAD  # reported, still driving
    servo.set_external_torque(0.0)
    servo.restore_output()
    assert servo.present_errors == 0
    trace = run(servo, 1.5)
    assert trace[-1].present_pwm != 0 or abs(trace[-1].present_position - cmd.goal_position) <= 2  # it drives again
    servo.set_supply_v(16.5)  # outside 9.5..16.0 V; the default Shutdown (52) does not select it
    run(servo, 0.01)
    assert servo.present_errors == HW_ERROR_INPUT_VOLTAGE and servo.cut_errors == 0


def test_held_errors_are_detected_at_every_step_until_lifted():
    servo, cmd = make(torque_enable=1)
    servo.shutdown_cuts_output = True
    servo.hold_errors(HW_ERROR_OVERHEATING)  # selected by the default Shutdown (52)
    assert servo.cut_errors == HW_ERROR_OVERHEATING and servo.present_errors == HW_ERROR_OVERHEATING
    servo.restore_output()
    servo.step_to(servo.time_s + 5.0)  # at rest: the skipped stretch detects it too
    assert servo.cut_errors == HW_ERROR_OVERHEATING
    servo.hold_errors(0)
    servo.restore_output()
    run(servo, 0.01)
    assert servo.cut_errors == 0 and servo.present_errors == 0
    latching, _ = make(torque_enable=1)  # the X series' Shutdown: latched, torque off
    latching.hold_errors(HW_ERROR_OVERHEATING)
    assert latching.sense().hardware_error_status == HW_ERROR_OVERHEATING and latching.sense().torque_enable == 0


# ---------------------------------------------------------------------------- cost


def test_a_servo_at_rest_with_torque_off_skips_its_steps_and_one_pushed_moves():
    servo, cmd = make()
    angle = servo.physics.angle_rad
    servo.step_to(100.0)
    assert servo.time_s == pytest.approx(100.0) and servo.physics.angle_rad == angle
    servo.set_external_torque(0.5)
    servo.step_to(100.5)
    assert servo.physics.angle_rad > angle + 0.1
    assert servo.sense().present_velocity > 0
    assert VELOCITY_UNIT_PULSES_S == pytest.approx(0.229 * 4096 / 60)


@pytest.mark.parametrize("model", MODELS)
def test_a_held_servo_skips_repeated_steps_without_changing_the_outcome(model):
    stepped, cmd_a = make(model, torque_enable=1, position_i_gain=0)
    skipped, cmd_b = make(model, torque_enable=1, position_i_gain=0)
    for servo, cmd in ((stepped, cmd_a), (skipped, cmd_b)):
        write(servo, cmd, goal_position=servo.sense().present_position + 700)
        run(servo, 4.0)
    assert skipped._fixed  # settled: its steps repeat exactly
    run(stepped, 20.0)
    skipped.step_to(skipped.time_s + 20.0)
    a, b = stepped.sense(), skipped.sense()
    assert a == b
    assert stepped.temperature_c == pytest.approx(skipped.temperature_c, abs=1e-6)
    assert stepped.physics.angle_rad == skipped.physics.angle_rad


def test_xl430_reports_present_load_in_tenths_of_a_percent():
    servo, cmd = make("XL430-W250", torque_enable=1, operating_mode=OperatingMode.PWM)
    write(servo, cmd, goal_pwm=885)
    _hold_shaft(servo, 0.3)  # full duty on a held shaft: the stall current, the load's full scale
    assert servo.sense().present_current == pytest.approx(1000, abs=150)
    write(servo, cmd, goal_pwm=-300)
    _hold_shaft(servo, 0.3)
    assert servo.sense().present_current == pytest.approx(-1000 * 300 / 885, abs=60)


def test_following_error_and_goal_velocity_clipped_to_velocity_limit():
    servo, cmd = make(torque_enable=1, profile_velocity=200, profile_acceleration=100)
    write(servo, cmd, goal_position=servo.sense().present_position + 3000)
    servo.set_external_torque(-6.0)  # the shaft cannot follow its trajectory
    trace = run(servo, 0.5)
    assert trace[-1].moving_status & 0x08
    assert not run(make(torque_enable=1, profile_velocity=200, profile_acceleration=100)[0], 0.1)[-1].moving_status & 0x08
    servo, cmd = make(torque_enable=1, operating_mode=OperatingMode.VELOCITY, velocity_limit=80)
    write(servo, cmd, goal_velocity=150)
    trace = run(servo, 1.0)
    assert trace[-1].velocity_trajectory == 80 and abs(trace[-1].present_velocity - 80) <= 3


def test_reverse_drive_mode_in_velocity_mode_turns_the_shaft_clockwise():
    servo, cmd = make(torque_enable=1, drive_mode=0x01, operating_mode=OperatingMode.VELOCITY)
    write(servo, cmd, goal_velocity=100)
    trace = run(servo, 1.0)
    assert abs(trace[-1].present_velocity - 100) <= 3
    assert servo.physics.velocity_rad_s == pytest.approx(-100 * 0.229 * 2 * math.pi / 60, rel=0.05)


REAL_XL330 = Path(__file__).resolve().parents[3] / ".." / "shared" / "reference" / "real-xl330"


@pytest.mark.parametrize("log_name", ["xl330_kp100_sin_sin", "xl330_kp400_up_and_down"])
def test_xl330_position_output_scale_matches_the_real_servos_present_pwm(log_name):
    path = REAL_XL330 / f"{log_name}.json"
    if not path.exists():
        pytest.skip(f"real XL330 logs not found in {REAL_XL330} (kept outside the repository)")
    log = json.loads(path.read_text())
    kp = log["kp"]
    ratios = []
    for entry in log["entries"]:
        pwm = entry["load"] - 65536 if entry["load"] > 32767 else entry["load"]  # Present PWM read unsigned
        predicted = kp / 128 * (entry["goal_position"] - entry["position"]) * 4096 / (2 * math.pi)
        if entry["torque_enable"] and 100 < abs(predicted) < 1600:
            ratios.append(pwm / predicted)
    real = statistics.median(ratios)
    # The logs ran at 7.4 V, above the XL330's default Max Voltage Limit (7.0 V): the recorder's servo had it raised.
    servo, cmd = make("XL330-M288", supply_v=7.4, torque_enable=1, position_p_gain=kp, max_voltage_limit=100)
    write(servo, cmd, goal_position=servo.sense().present_position + 200)
    _hold_shaft(servo, 0.2)
    s = servo.sense()
    model = s.present_pwm / (kp / 128 * (servo._goal_pulses() - s.present_position))
    assert model == pytest.approx(real, abs=0.02)


@pytest.mark.parametrize("model", ["XM430-W350", "XL430-W250"])
def test_torque_off_lets_go_of_the_output_at_once(model):
    """Torque Enable 0 written mid-move and read before the next control step (a host faster than 1 kHz): Present
    PWM and Present Current (the XL430's Present Load) read 0 beside it, not the drive of the step before."""
    servo, cmd = make(model, torque_enable=1)
    write(servo, cmd, goal_position=servo.sense().present_position + 1000)
    run(servo, 0.03)
    moving = servo.sense()
    assert abs(moving.present_pwm) > 100 and moving.present_current != 0
    write(servo, cmd, torque_enable=0)
    now = servo.sense()
    assert (now.torque_enable, now.present_pwm, now.present_current) == (0, 0, 0)
    assert now.present_velocity == moving.present_velocity  # the shaft has not yet slowed: no time passed


@pytest.mark.parametrize(("register", "mode"), [("goal_pwm", OperatingMode.POSITION), ("pwm_limit", OperatingMode.POSITION),
                                                ("pwm_limit", OperatingMode.VELOCITY), ("pwm_limit", OperatingMode.PWM)])
def test_a_lowered_pwm_bound_bounds_the_output_at_once(register, mode):
    """Goal PWM (outside PWM Control Mode) and PWM Limit bound the duty; lowered between two control steps, Present PWM
    already reads within them (how the MX's Torque Limit 0 shows as Present Load 0 at once)."""
    servo, cmd = make("XM430-W350", torque_enable=1, operating_mode=mode)
    goals = {OperatingMode.POSITION: {"goal_position": servo.sense().present_position + 1000},
             OperatingMode.VELOCITY: {"goal_velocity": 200}, OperatingMode.PWM: {"goal_pwm": 800}}[mode]
    write(servo, cmd, **goals)
    run(servo, 0.02)
    assert servo.sense().present_pwm > 200
    write(servo, cmd, **{register: 150})
    assert servo.sense().present_pwm == 150
    write(servo, cmd, **{register: 0})
    assert servo.sense().present_pwm == 0


# ---------------------------------------------------------------------------- sensing_epoch

#: Commands a client's writes give, drawn at random: goals, profile, gains, and now and then the frame or the torque.
_COMMAND_DRAWS = {
    "goal_position": lambda rng: rng.randint(0, 4095),
    "goal_velocity": lambda rng: rng.randint(-200, 200),
    "profile_velocity": lambda rng: rng.choice((0, 50, 200)),
    "profile_acceleration": lambda rng: rng.choice((0, 10, 50)),
    "position_p_gain": lambda rng: rng.choice((400, 800)),
    "moving_threshold": lambda rng: rng.choice((5, 10, 40)),
    "max_position_limit": lambda rng: rng.choice((4095, 3000)),
    "goal_pwm": lambda rng: rng.choice((885, 885, 300, 0)),
    "pwm_limit": lambda rng: rng.choice((885, 885, 400)),
    "torque_enable": lambda rng: rng.choice((0, 1, 1, 1)),
    "operating_mode": lambda rng: rng.choice((OperatingMode.POSITION, OperatingMode.POSITION, OperatingMode.VELOCITY,
                                              OperatingMode.EXTENDED_POSITION)),
    "homing_offset": lambda rng: rng.choice((0, 0, 0, 300)),
    "drive_mode": lambda rng: rng.choice((0, 0, 0, 1, 4, 8)),
}


@pytest.mark.parametrize("seed", range(3))
def test_a_command_that_keeps_sensing_changes_no_sensed_value_but_the_trajectory_ones(seed):
    """``keeps_sensing`` (and the unmoved ``sensing_epoch``) is what lets a serving bus leave a copy of the sensed
    registers for later: it must never be wrong, whatever the state and the command."""
    rng = random.Random(seed)
    servo, commands = make("XM430-W350", profile_velocity=100, profile_acceleration=20, torque_enable=1)
    kept = changed = 0
    for _ in range(600):
        name = rng.choice(list(_COMMAND_DRAWS))
        new = dataclasses.replace(commands, **{name: _COMMAND_DRAWS[name](rng)})
        goal_written = name.startswith("goal_") or rng.random() < 0.3
        before, epoch = servo.sense(), servo.sensing_epoch
        keeps = servo.keeps_sensing(new, goal_written=goal_written)
        servo.command(new, goal_written=goal_written)
        commands = new
        after = servo.sense()
        assert (servo.sensing_epoch == epoch) == keeps
        if keeps:
            kept += 1
            for field in dataclasses.fields(after):
                if field.name not in TRAJECTORY_SENSED:
                    assert getattr(after, field.name) == getattr(before, field.name), (name, field.name)
        else:
            changed += 1
        if rng.random() < 0.3:
            servo.step_to(servo.time_s + servo.step_s * rng.randint(1, 20))
    assert kept > 100 and changed > 20  # both kinds were drawn
