"""The robot code's own tests, against virtual servos from ax12emu's pytest plugin."""

from __future__ import annotations

import pytest
from robot_arm import POSITION_TOLERANCE, Arm, CommError

from ax12emu import FaultConfig


@pytest.fixture
def arm(ax12_bus):
    """The arm on whatever bus the test asked for."""
    robot = Arm(ax12_bus.port, ax12_bus.bus.ids)
    yield robot
    robot.close()


@pytest.mark.ax12_ids(1, 2)
def test_joints_reach_their_goals(arm):
    """Both joints move to a commanded position and stop there."""
    arm.enable()
    assert arm.move_to(1, 600)
    assert arm.move_to(2, 400)
    assert abs(arm.read_position(1) - 600) <= POSITION_TOLERANCE  # a real servo also stops a few units off


@pytest.mark.ax12_ids(1)
@pytest.mark.ax12_bus_options(faults=FaultConfig(drop=0.2, seed=7))
def test_retries_ride_out_lost_replies(arm, ax12_bus):
    """With 20 % of replies lost the retries still get every read through."""
    for _ in range(20):
        assert arm.read_position(1) == 512
    assert ax12_bus.faults.dropped > 0


@pytest.mark.ax12_ids(1)
def test_dead_servo_raises(arm, ax12_bus):
    """A servo that vanished makes the code raise instead of hanging; it works again when back."""
    ax12_bus.faults.vanish(1)
    with pytest.raises(CommError):
        arm.read_position(1)
    ax12_bus.faults.reappear(1)
    assert arm.read_position(1) == 512


@pytest.mark.ax12_ids(1, 2)
def test_health_reports_overheating(arm, ax12_bus):
    """A joint above its temperature limit shows up in the health report."""
    ax12_bus.set_temperature(2, 85)
    assert arm.health() == {1: [], 2: ["overheating"]}
    ax12_bus.set_temperature(2, None)
    assert arm.health() == {1: [], 2: []}


@pytest.mark.ax12_ids(1)
def test_blocked_joint_times_out(arm, ax12_bus):
    """A blocked joint never arrives: move_to gives up instead of waiting forever."""
    arm.enable()
    ax12_bus.faults.stall(1)
    assert not arm.move_to(1, 700, timeout_s=0.3)
    ax12_bus.faults.release(1)
    assert arm.move_to(1, 700)
