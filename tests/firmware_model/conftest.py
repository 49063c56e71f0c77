"""Shared helpers for the firmware_model tests: command registers with e-manual defaults."""

import numpy as np
import pytest

from firmware_model.interface import Commands


def make_commands(n: int = 1, **overrides) -> Commands:
    """Commands for ``n`` servos; each override is a scalar or a sequence of length ``n``."""
    return Commands.power_up(n, **overrides)


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
