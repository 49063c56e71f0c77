"""The excitation program: one rich sequence of commands, shared by the dataset maker and the recorder.

Why it exists: an effect can only be named if the trace exercises it, so the
program has steps of several sizes at full and limited speed, a reversal
and a speed change mid-move, small steps (dead band, play, breakaway), slow
cruising (Stribeck), moves across the range (an arm's weight changes with
angle) and holds with an external load on and off.  ``tools/make_dataset.py``
and ``tools/record.py`` run the same program, so synthetic and recorded
traces are comparable.  A real bench cannot apply ``external_torque_nm``
through the bus; there those segments are plain holds (or a load applied by
hand).

The 20 s program is the reference; :func:`program` scales its durations to
other lengths (the tests use shorter ones).  It can be followed by
:data:`BREAKAWAY`, small steps from rest and short moves at a moderate
speed around the centre: breakaway (static, Stribeck) friction shows where
the shaft starts from rest and in how far short of the goal it stops, and
the reference program has few such starts.  (Crawling at 1-3 % of full
speed, tried first, shows it even more but makes the motion stick-slip,
whose timing is so sensitive to the friction values that no fit can match
it sample by sample.)  ``program(duration_s, breakaway_s=...)``;
``--breakaway SECONDS`` in ``tools/make_dataset.py`` and ``tools/record.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Step", "PROGRAM_20S", "BREAKAWAY", "program", "commands_at"]


@dataclass(frozen=True)
class Step:
    """Hold these commands for ``duration_s``."""

    duration_s: float
    goal_position: int
    moving_speed: int
    external_torque_nm: float = 0.0


#: The reference program, 20 s.
PROGRAM_20S = (
    Step(0.5, 512, 0),
    Step(1.0, 560, 0),             # small step, full speed
    Step(1.2, 412, 0),             # medium step down
    Step(1.5, 712, 300),           # large step, limited speed
    Step(0.25, 300, 0),            # start a move ...
    Step(1.2, 800, 0),             # ... and reverse it mid-way
    Step(0.3, 200, 500),           # a speed change mid-move
    Step(1.5, 200, 150),
    Step(0.4, 210, 0),             # small steps: dead band, play, breakaway
    Step(0.4, 200, 0),
    Step(0.4, 215, 0),
    Step(1.0, 215, 0, 0.4),        # hold under an external load, both ways
    Step(1.0, 215, 0, -0.4),
    Step(0.5, 215, 0),
    Step(1.5, 600, 200, -0.3),     # a move against a load
    Step(0.5, 600, 0),
    Step(2.0, 450, 60),            # slow cruise
    Step(1.0, 850, 0),             # across the range
    Step(1.5, 150, 0),
    Step(1.35, 512, 400),
)


#: Small steps (6-8 units) out and back from rest, then moves at Moving Speed 80 (0.93 rad/s) that pass through
#: the Stribeck range (0.1-0.5 rad/s) at every start and stop: about 6.7 s at this scale.
BREAKAWAY = (
    Step(0.5, 512, 0),
    *(Step(0.4, g, 0) for g in (506, 512, 518, 512, 504, 512, 520, 512)),
    *(Step(0.8, g, 80) for g in (560, 470, 560, 512)),
)


def _scaled(steps: tuple[Step, ...], duration_s: float) -> tuple[Step, ...]:
    scale = duration_s / sum(s.duration_s for s in steps)
    return tuple(Step(s.duration_s * scale, s.goal_position, s.moving_speed, s.external_torque_nm) for s in steps)


def program(duration_s: float = 20.0, breakaway_s: float = 0.0) -> tuple[Step, ...]:
    """:data:`PROGRAM_20S` scaled to ``duration_s - breakaway_s``, then :data:`BREAKAWAY` scaled to ``breakaway_s``."""
    if not 0.0 <= breakaway_s < duration_s:
        raise ValueError(f"breakaway_s must be in [0, {duration_s}), got {breakaway_s}")
    head = _scaled(PROGRAM_20S, duration_s - breakaway_s)
    return head + (_scaled(BREAKAWAY, breakaway_s) if breakaway_s > 0 else ())


def commands_at(times_s: np.ndarray, steps: tuple[Step, ...]) -> dict[str, np.ndarray]:
    """The commands in effect at each time (arrays ``goal_position``, ``moving_speed``, ``external_torque_nm``)."""
    ends = np.cumsum([s.duration_s for s in steps])
    idx = np.minimum(np.searchsorted(ends, np.asarray(times_s), side="right"), len(steps) - 1)
    return {
        "goal_position": np.array([steps[i].goal_position for i in idx], dtype=np.int64),
        "moving_speed": np.array([steps[i].moving_speed for i in idx], dtype=np.int64),
        "external_torque_nm": np.array([steps[i].external_torque_nm for i in idx], dtype=float),
    }
