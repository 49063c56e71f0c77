"""Compliance control (e-manual figure) and the report's PID, as drive functions."""

import numpy as np
import pytest

from firmware_model.backend import NUMPY
from firmware_model.controller import PidGains, compliance_drive, compliance_plan, pid_drive, slope_width_units


def _drive(errors, margin=(1, 1), slope=(32, 32), punch=32, limit=1023):
    plan = compliance_plan(margin[0], margin[1], slope[0], slope[1], punch, limit)
    return compliance_drive(NUMPY, np.asarray(errors, dtype=float), plan.cw_margin, plan.ccw_margin,
                            plan.cw_gain, plan.ccw_gain, plan.punch, plan.limit)


def test_compliance_curve_shape():
    """Zero inside the margin, Punch just beyond it, full drive at margin + slope, sign by direction."""
    drive, _ = _drive([0, 1, -1, 2, 33, -33, 100])
    punch = 32 / 1023
    assert drive[:3].tolist() == [0, 0, 0]
    assert drive[3] == pytest.approx(punch + (1 - punch) / 32)
    assert drive[4] == pytest.approx(1.0) and drive[5] == pytest.approx(-1.0)
    assert drive[6] == 1.0


def test_torque_limit_clips_drive_not_demand():
    """Torque Limit 512 caps the drive at 50 %; the demand (used by the overload alarm) is not capped."""
    drive, demand = _drive([200.0, -200.0], limit=512)
    assert drive.tolist() == pytest.approx([512 / 1023, -512 / 1023])
    assert demand[0] > 1.0


def test_asymmetric_margins_and_slopes():
    """CW and CCW registers act on their own side (CW = negative error)."""
    drive, _ = _drive([3.0, -3.0], margin=(4, 1), slope=(128, 2))
    assert drive[1] == 0.0  # inside the 4-unit CW margin
    assert drive[0] == pytest.approx(1.0)  # 2 units beyond a 1-unit margin with a 2-unit slope


def test_slope_register_steps():
    """e-manual: the slope acts in steps 2, 4, ..., 128."""
    assert slope_width_units(np.array([0, 3, 4, 31, 32, 100, 254])).tolist() == [2, 2, 4, 16, 32, 64, 128]


def test_pid_drive_signs_and_limit():
    """The PID pushes toward the goal, integrates a constant error and respects the torque limit."""
    gains = PidGains()
    drive, demand, integral = pid_drive(NUMPY, np.array([0.01, -0.01]), np.zeros(2), np.array([0.01, -0.01]), 1e-3, gains, 1.0)
    assert drive[0] > 0 > drive[1] and integral[0] > 0
    drive, _, _ = pid_drive(NUMPY, np.array([1.0]), np.zeros(1), np.zeros(1), 1e-3, gains, 0.25)
    assert drive[0] == 0.25
