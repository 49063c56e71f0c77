"""GroupedModel: groups of servos behind their own models, seen as one model of N."""

from __future__ import annotations

import numpy as np
import pytest

from firmware_model import PhysicalModel, ServoParams
from firmware_model.grouped import GroupedModel


def test_the_groups_must_cover_every_index_once():
    with pytest.raises(ValueError, match="each servo index"):
        GroupedModel([(PhysicalModel(1), [0]), (PhysicalModel(1), [2])])
    with pytest.raises(ValueError, match="a model of 2 servos given 1"):
        GroupedModel([(PhysicalModel(2), [0]), (PhysicalModel(1), [1])])
    with pytest.raises(ValueError, match="one step"):
        GroupedModel([(PhysicalModel(1), [0]), (PhysicalModel(1, step_s=2e-3), [1])])


def test_per_servo_inputs_reach_the_servo_they_name():
    slow, fast = PhysicalModel(2, ServoParams()), PhysicalModel(1, ServoParams())
    grouped = GroupedModel([(slow, [0, 2]), (fast, [1])])
    grouped.set_angle(2, 1.0)
    grouped.set_angle(1, 2.0)
    assert slow.angle_rad[1] == pytest.approx(1.0) and fast.angle_rad[0] == pytest.approx(2.0)
    np.testing.assert_allclose(grouped.angle_rad[1:], [2.0, 1.0])
    grouped.set_blocked([False, True, False])
    grouped.set_external_torque([0.1, 0.2, 0.3])
    np.testing.assert_allclose(slow.external_torque_nm, [0.1, 0.3])
    np.testing.assert_allclose(grouped.external_torque_nm, [0.1, 0.2, 0.3])  # read back in the wire's order
    assert grouped.sense().present_position.shape == (3,)
