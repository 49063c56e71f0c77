"""The closed-loop replay of a BAM log: goals written as registers at the recorder's times, Present Position read back."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from firmware_model.xseries.bam_log import PendulumLog
from firmware_model.xseries.bam_replay import MIDDLE_PULSES, recorder_commands, replay_positions
from firmware_model.xseries.firmware import XFirmware
from firmware_model.xseries.interface import OperatingMode
from firmware_model.xseries.physics import XPhysicsParams

XL330_M288 = XPhysicsParams.from_datasheet(gear_ratio=288.4, ratings=[(3.7, 0.42, 1.11, 76), (5.0, 0.52, 1.47, 103),
                                                                     (6.0, 0.60, 1.74, 123)])


def _firmware(physics):
    return XFirmware(physics, current_unit_a=0.001, position_output_scale=0.5)


def _log(goal_rad: np.ndarray, torque_enable: np.ndarray, *, start_rad: float = 0.0, kp: int = 400, mass_kg: float = 0.0,
         period_s: float = 0.005) -> PendulumLog:
    n = len(goal_rad)
    zeros = np.zeros(n)
    return PendulumLog(name="synthetic", motor="xl330", trajectory="test", kp=kp, supply_v=7.4, mass_kg=mass_kg,
                       length_m=0.1, arm_mass_kg=0.0, time_s=0.0035 + period_s * np.arange(n),
                       position_rad=np.full(n, start_rad), goal_position_rad=np.asarray(goal_rad, float), speed_rad_s=zeros,
                       present_pwm=zeros.astype(np.int64), input_voltage_v=zeros + 7.4, temperature_c=zeros + 29,
                       torque_enable=np.asarray(torque_enable, bool))


def test_recorder_commands_are_position_mode_with_the_logs_gain_and_no_profile():
    c = recorder_commands(400, -0.5, True)
    assert c.operating_mode == OperatingMode.POSITION and c.position_p_gain == 400
    assert c.position_d_gain == 0 and c.position_i_gain == 0 and c.profile_velocity == 0
    assert c.goal_position == MIDDLE_PULSES + round(-0.5 * 4096 / (2 * math.pi)) and c.torque_enable == 1


def test_a_goal_step_is_followed_in_the_logs_frame():
    """Unloaded, a 0.5 rad step: the replayed Present Position starts at the log's first reading and settles on the goal
    (within the P controller's friction band)."""
    n = 300
    goal = np.where(np.arange(n) < 20, 0.0, 0.5)
    positions = replay_positions(_log(goal, np.ones(n, bool), start_rad=0.0), XL330_M288, _firmware)
    assert positions[0] == pytest.approx(0.0, abs=2e-3)
    assert positions[15] == pytest.approx(0.0, abs=2e-3)  # nothing before the step is written
    assert positions[-1] == pytest.approx(0.5, abs=0.02)
    assert np.all(np.diff(positions[20:35]) > 0)  # moving toward it (it may overshoot after)


def test_torque_off_lets_the_pendulum_fall_to_its_hanging_angle():
    """Torque off from the start, lifted 0.6 rad: it swings down and settles near the given hanging angle, well within
    its Coulomb band."""
    n = 1500
    log = _log(np.zeros(n), np.zeros(n, bool), start_rad=0.6, mass_kg=0.49)
    positions = replay_positions(log, XL330_M288, _firmware, gravity_zero_rad=0.05)
    assert positions.min() < 0.05 < positions.max()
    band_rad = math.asin(XL330_M288.coulomb_friction_nm / log.gravity_moment_nm(9.80665))
    assert abs(positions[-1] - 0.05) <= band_rad + 2e-3


def test_a_stronger_gain_follows_closer():
    """The log's kp reaches the firmware: the same slow sine against the pendulum lags less at kp 400 than at 100."""
    n = 600
    goal = 0.4 * np.sin(np.arange(n) * 0.005 * 2 * math.pi / 1.5)
    errors = {}
    for kp in (100, 400):
        log = _log(goal, np.ones(n, bool), kp=kp, mass_kg=0.49)
        errors[kp] = float(np.mean(np.abs(replay_positions(log, XL330_M288, _firmware) - goal)))
    assert errors[400] < 0.6 * errors[100]


def test_the_pendulum_is_the_logs():
    """Mass and length come from the log: a heavier pendulum sags further below a held goal."""
    n = 400
    sags = []
    for mass in (0.2, 0.49):
        log = _log(np.full(n, 0.8), np.ones(n, bool), start_rad=0.8, kp=100, mass_kg=mass)
        sags.append(0.8 - replay_positions(log, replace(XL330_M288), _firmware)[-1])
    assert 0.0 < sags[0] < sags[1]
