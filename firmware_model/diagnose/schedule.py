"""A trace's commands compiled into whole-step segments for the simulators.

Why it exists: both the reference replay (:mod:`.replay`, through
:class:`~firmware_model.physical.PhysicalModel`) and the batched simulator
(:mod:`.batch`) must see the same thing: row ``i``'s commands act on the
steps after the reading at ``t_i`` up to and including the step read at
``t_{i+1}``, exactly as ``PhysicalModel.advance`` rounds times down to whole
steps.  Consecutive rows with the same commands merge into one segment.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..units import RAD_PER_POSITION_UNIT, RAD_S_PER_SPEED_UNIT
from .trace import Trace

__all__ = ["Segment", "Schedule", "compile_schedule", "FULL_SCALE_SPEED_RAD_S"]

#: Moving Speed 0 in joint mode: the register's full scale (as in firmware_model.physical).
FULL_SCALE_SPEED_RAD_S = float(1023 * RAD_S_PER_SPEED_UNIT)


@dataclass(frozen=True)
class Segment:
    """Steps ``first + 1 .. last`` under constant commands."""

    first: int
    last: int
    goal_rad: float
    max_speed_rad_s: float
    #: Torque Limit as a fraction of full drive.
    limit: float
    external_torque_nm: float
    supply_v: float
    #: Whether anything changed at ``first`` (the model re-plans then: dead zone, see setpoint.apply_dead_zone).
    replan: bool


@dataclass(frozen=True)
class Schedule:
    """Segments plus the step after which each sample was read."""

    step_s: float
    segments: tuple[Segment, ...]
    #: Step index (0 = start) at which each row's sensed columns were read, shape (n,).
    sample_steps: np.ndarray
    initial_position_raw: int

    @property
    def n_steps(self) -> int:
        """Total steps simulated."""
        return int(self.sample_steps[-1])


def compile_schedule(trace: Trace, step_s: float = 1e-3, supply_v: float = 9.6) -> Schedule:
    """Segments for ``trace`` (time origin: its first row); ``supply_v`` unless the trace has ``voltage``."""
    t = trace.t
    steps = np.floor(t / step_s + 1e-9).astype(np.int64)
    goal = trace["goal_position"].astype(float) * float(RAD_PER_POSITION_UNIT)
    speed_raw = trace["moving_speed"].astype(np.int64) & 0x3FF
    max_speed = np.where(speed_raw == 0, FULL_SCALE_SPEED_RAD_S, speed_raw * float(RAD_S_PER_SPEED_UNIT))
    n = len(trace)
    limit = np.minimum(trace["torque_limit"], 1023) / 1023.0 if trace.has("torque_limit") else np.ones(n)
    ext = trace["external_torque_nm"] if trace.has("external_torque_nm") else np.zeros(n)
    volts = trace["voltage"] / 10.0 if trace.has("voltage") else np.full(n, float(supply_v))
    segments: list[Segment] = []
    key_prev = None
    for i in range(n - 1):
        key = (float(goal[i]), float(max_speed[i]), float(limit[i]), float(ext[i]), float(volts[i]))
        if segments and key == key_prev:
            last = segments[-1]
            segments[-1] = Segment(last.first, int(steps[i + 1]), *key, replan=last.replan)
        else:
            segments.append(Segment(int(steps[i]), int(steps[i + 1]), *key, replan=True))
        key_prev = key
    return Schedule(step_s, tuple(segments), steps, int(trace["present_position"][0]))
