"""Register writes and reads at given times against one X-series firmware model: the closed loop of a recording.

Why it exists: replaying a recording means telling the firmware model what the client wrote, when it
wrote it, and reading the registers back when the client read them; the control loop in between is
the firmware's (:mod:`.firmware`).  Both replays of real and measured X-series data, a BAM pendulum
log (:mod:`.bam_replay`) and a diagnosis trace (``firmware_model.diagnose.xreplay``), go through this
one loop, so they cannot drift apart in how they order a write and a read or round times to steps.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from .interface import XCommands, XSensed, XServoModel

__all__ = ["Write", "run_closed_loop"]


@dataclass(frozen=True)
class Write:
    """Registers written at ``time_s`` (the model's clock); ``goal_written``: a goal register was among them."""

    time_s: float
    commands: XCommands
    goal_written: bool = True
    #: Anything else the client changed at that time (the supply, a load on the shaft), applied before the write.
    world: Callable[[XServoModel], None] | None = None


def run_closed_loop(model: XServoModel, writes: Sequence[Write], reads_s: Sequence[float]) -> list[XSensed]:
    """Apply each write at its time and sense at each read time, in time order (a write before a read at the same time).

    ``writes`` and ``reads_s`` must each be in increasing time; the model steps in whole steps
    (``XServoModel.step_to``), so a time between two steps acts at the earlier one.
    """
    out: list[XSensed] = []
    w = 0
    for read_s in reads_s:
        while w < len(writes) and writes[w].time_s <= read_s:
            write = writes[w]
            model.step_to(write.time_s)
            if write.world is not None:
                write.world(model)
            model.command(write.commands, goal_written=write.goal_written)
            w += 1
        model.step_to(read_s)
        out.append(model.sense())
    return out
