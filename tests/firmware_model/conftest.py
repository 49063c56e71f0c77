"""Shared helpers for the firmware_model tests: command registers with e-manual defaults."""

import numpy as np
import pytest

from firmware_model.interface import Commands

#: e-manual power-up values (joint mode over the full range), overridden per test.
DEFAULTS = dict(
    torque_enable=1, goal_position=512, moving_speed=0, torque_limit=1023, cw_angle_limit=0, ccw_angle_limit=1023,
    cw_compliance_margin=1, ccw_compliance_margin=1, cw_compliance_slope=32, ccw_compliance_slope=32, punch=32,
    temperature_limit=70, min_voltage_limit=60, max_voltage_limit=140,
)


def make_commands(n: int = 1, **overrides) -> Commands:
    """Commands for ``n`` servos; each override is a scalar or a sequence of length ``n``."""
    values = {**DEFAULTS, **overrides}
    return Commands(**{k: np.broadcast_to(np.asarray(v, dtype=np.int64), (n,)).copy() for k, v in values.items()})


@pytest.fixture
def commands():
    """The :func:`make_commands` factory."""
    return make_commands


def run_samples(model, cmds, duration_s: float, every_s: float = 1e-3):
    """Advance ``model`` in ``every_s`` increments; return the list of Sensed and of true speeds."""
    sensed, speeds = [], []
    steps = int(round(duration_s / every_s))
    start = model.time_s
    for i in range(1, steps + 1):
        sensed.append(model.advance(start + i * every_s, cmds))
        speeds.append(model.speed_rad_s.copy())
    return sensed, np.array(speeds)


@pytest.fixture
def sampler():
    """The :func:`run_samples` helper."""
    return run_samples
