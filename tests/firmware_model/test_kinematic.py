"""KinematicModel: the first, dynamics-free model stays usable."""

import numpy as np
import pytest

from firmware_model.kinematic import KinematicModel


def test_moves_at_commanded_speed_and_stops_at_goal(commands):
    """Moving Speed 300 (3.49 rad/s) covers 100 units (0.512 rad) in about 0.147 s, then stops on the goal."""
    model = KinematicModel(1)
    cmds = commands(goal_position=612, moving_speed=300)
    assert model.advance(0.1, cmds).present_position[0] == pytest.approx(512 + 0.1 * 3.487 / (np.deg2rad(300) / 1023), abs=1)
    sensed = model.advance(0.3, cmds)
    assert sensed.present_position[0] == 612 and sensed.moving[0] == 0


def test_wheel_mode_and_torque_off(commands):
    """Wheel mode turns CW with bit 10; torque off does not move."""
    model = KinematicModel(2)
    sensed = model.advance(0.1, commands(2, torque_enable=[1, 0], cw_angle_limit=0, ccw_angle_limit=0, moving_speed=1024 | 200))
    assert sensed.present_position[0] < 512 and sensed.present_position[1] == 512
