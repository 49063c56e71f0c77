"""A trace's commands compiled into whole-step segments for the simulators.

Why it exists: both the reference replay (:mod:`.replay`, through
:class:`~firmware_model.physical.PhysicalModel`) and the batched simulator
(:mod:`.batch`) must see the same thing: row ``i``'s commands act on the
steps after the reading at ``t_i`` (or after ``command_t``, when the trace
records when they were sent) up to and including the step read at
``t_{i+1}``, exactly as ``PhysicalModel.advance`` rounds times down to whole
steps.  Consecutive rows with the same commands merge into one segment.

Where the trace does not record when a command was sent, its onset is only
known to lie between its row's reading and the next; the schedule keeps that
window (:attr:`Schedule.onset_bounds`) for :mod:`.nuisance`, which fits the
onset as a property of the recording.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..units import RAD_PER_POSITION_UNIT, RAD_S_PER_SPEED_UNIT
from .trace import Trace

__all__ = ["Segment", "Schedule", "compile_schedule", "CONTROL_STEP_S", "FULL_SCALE_SPEED_RAD_S"]

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
    #: Per segment, the first and last step its commands may start after, shape (len(segments), 2): both equal
    #: ``first`` where the trace records when the command was sent (``command_t``) or for the first segment;
    #: otherwise the change's row reading and the next row's (the onset is known only within that sample).
    onset_bounds: np.ndarray | None = None

    @property
    def n_steps(self) -> int:
        """Total steps simulated."""
        return int(self.sample_steps[-1])

    @property
    def onsets_known(self) -> bool:
        """Whether every command change's onset is known to the step."""
        b = self.bounds()
        return bool(np.all(b[:, 0] == b[:, 1]))

    def bounds(self) -> np.ndarray:
        """:attr:`onset_bounds`, or each segment's ``first`` twice where none were given."""
        if self.onset_bounds is not None:
            return self.onset_bounds
        first = np.array([seg.first for seg in self.segments], dtype=np.int64)
        return np.stack([first, first], axis=1)

    def nominal_onsets(self) -> np.ndarray:
        """Each segment's ``first`` (where its row puts it), shape (len(segments),)."""
        return np.array([seg.first for seg in self.segments], dtype=np.int64)


#: The physics step of the fit: the AX-12's 1 ms control loop, as the served model steps.
CONTROL_STEP_S = 1e-3


def compile_schedule(trace: Trace, step_s: float = CONTROL_STEP_S, supply_v: float = 9.6) -> Schedule:
    """Segments for ``trace`` (time origin: its first row); ``supply_v`` unless the trace has ``voltage``.

    A segment starts at each command change: at ``command_t`` where the trace
    has it, else at the change's row (its reading).
    """
    t = trace.t
    steps = np.floor(t / step_s + 1e-9).astype(np.int64)
    goal = trace["goal_position"].astype(float) * float(RAD_PER_POSITION_UNIT)
    speed_raw = trace["moving_speed"].astype(np.int64) & 0x3FF
    max_speed = np.where(speed_raw == 0, FULL_SCALE_SPEED_RAD_S, speed_raw * float(RAD_S_PER_SPEED_UNIT))
    n = len(trace)
    limit = np.minimum(trace["torque_limit"], 1023) / 1023.0 if trace.has("torque_limit") else np.ones(n)
    ext = trace["external_torque_nm"] if trace.has("external_torque_nm") else np.zeros(n)
    volts = trace["voltage"] / 10.0 if trace.has("voltage") else np.full(n, float(supply_v))
    rows = trace.change_rows()
    rows = rows[rows < n - 1]  # a change on the last row acts on no step
    if trace.records_command_times:
        sent = trace["command_t"] - trace["t"][0]
        first = np.floor(np.clip(sent[rows], 0.0, t[-1]) / step_s + 1e-9).astype(np.int64)
        first[0] = 0
        first = np.minimum(np.maximum.accumulate(first), steps[-1])
        bounds = np.stack([first, first], axis=1)
    else:
        first = steps[rows]
        bounds = np.stack([first, steps[rows + 1]], axis=1)
        bounds[0] = first[0]
    segments = []
    for j, i in enumerate(rows):
        last = int(first[j + 1]) if j + 1 < len(rows) else int(steps[-1])
        segments.append(Segment(int(first[j]), last, float(goal[i]), float(max_speed[i]), float(limit[i]),
                                float(ext[i]), float(volts[i]), replan=True))
    return Schedule(step_s, tuple(segments), steps, int(trace["present_position"][0]), bounds)
