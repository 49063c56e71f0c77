"""How the data was taken: what the base fit estimates about a recording and never names as an effect.

Why it exists: a measured trace carries traits of its recording that are
not physics of the servo, yet move the model's residual as much as an effect
does.  Fitted as effects they get *named* (a clean live recording came out
"sample_hold" because its 10 Hz hold had another phase than the model's;
Wizard exports would come out "delay" because nobody knows when the goal was
written).  So they are fitted here, as part of the base model, before and
between the search's rounds:

* **The phase of the held Present Speed / Load** (``hold_phase_s``): the
  firmware latches them every ``sample_hold_s`` from its own power-up, which
  no recording sees.  Profiled over every step of one hold period (a sensing
  knob: one simulation, then one cheap re-sampling per phase).
* **When each command took effect**, where the trace does not record it (no
  ``command_t``): a client writes a command after a reading, a few ms later
  each time, and stamps its readings after the read returns; either way a
  change is only known to fall between its row's reading and the next.  Two
  live recordings of the same servo and excitation differ by 1-2.5 position
  units RMS for that reason alone and agree to about 0.6 once aligned on
  when each command was sent.  Each change's onset is fitted to the step
  within that window, and before it, back to the previous row's reading
  (the format's registers are in effect from a row's ``t``, written then or
  earlier), where the rows clearly say so: a trace logged slower than it
  was commanded (:func:`fit_onsets`).  For a Wizard export, where the
  goal's write is not recorded at all, :func:`first_movement_onset` places
  it from the first movement before that refinement.

A latency between shaft and reading (the ``delay`` effect) is the same
thing as a later onset, as far as a trace without command times can tell, so
effects that need command times (``Effect.needs_command_times``) are not
offered on such traces.  Timing jitter of the readings themselves is in
their recorded ``t``; what is left is the small spread of the after-read
stamps, which the robust cost treats as noise.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..params import ServoParams
from ..units import RAD_PER_POSITION_UNIT
from .batch import null_knobs, simulate
from .metrics import robust_cost
from .schedule import compile_schedule
from .trace import Trace, departures, rest_level

__all__ = ["Nuisance", "profile_hold_phase", "fit_onsets", "first_movement_onset", "locate_onset",
           "first_movement_row", "earliest_onsets", "PROFILERS",
           "ONSET_PASSES", "EARLY_SHARE", "EARLY_STRIDE", "EARLY_CHANGES", "MOVEMENT_UNITS"]

#: Alternating passes over the command changes (even ones varied, then odd ones) in :func:`fit_onsets`.
ONSET_PASSES = 4
#: An onset before its row's reading (:func:`fit_onsets`) must remove at least this share of the cost of the rows
#: that change decides.  A trace logged slower than it was commanded leaves those rows far off where the change is
#: put a sample late (an earlier onset removed 86-100 % of their cost on a 100 Hz trace kept 1 row in 10 or 20),
#: where a model a little slow to start pulls a row-by-row trace's onsets a few ms before their readings for
#: 7-25 % (a live-like synthetic trace with the base parameters spread).
EARLY_SHARE = 0.5
#: ... searched for every this many-th change at once (the rest held where they are).
EARLY_STRIDE = 4
#: ... and taken only where at least this share of the changes are so (each clearing :data:`EARLY_SHARE`): a trace
#: is logged slower than it was commanded or it is not.  On a row-by-row live-like trace with Stribeck friction one
#: change in 19 cleared the share (the last, 5 ms earlier, 3 ms before when it was sent: a model slow to break
#: away), on the 100 Hz trace kept a row in 10 or 20, 17 and 18 of 19 did.
EARLY_CHANGES = 0.5
#: A reading this many units from the first one counts as the first movement.
MOVEMENT_UNITS = 2


@dataclass
class Nuisance:
    """The recording's fitted traits (see the module docstring)."""

    #: Phase of the speed/load hold, s after the first row (None: the trace has neither channel).
    hold_phase_s: float | None = None
    #: Step after which each schedule segment's commands start (as :func:`.batch.simulate` takes them).
    onsets: np.ndarray | None = None
    #: Whether the onsets were fitted (the trace does not record when commands were sent).
    onsets_fitted: bool = False
    notes: list[str] = field(default_factory=list)

    def knobs(self) -> dict[str, float]:
        """The sensing knobs this nuisance sets."""
        return {} if self.hold_phase_s is None else {"hold_phase_s": float(self.hold_phase_s)}

    def describe(self, step_s: float, nominal: np.ndarray) -> str:
        """One line for the report."""
        parts = []
        if self.hold_phase_s is not None:
            parts.append(f"speed/load hold phase {1000 * self.hold_phase_s:.0f} ms")
        if self.onsets_fitted and self.onsets is not None and len(self.onsets) > 1:
            lag_ms = (self.onsets[1:] - nominal[1:]) * step_s * 1000
            if len(lag_ms) == 1:
                parts.append(f"the command's onset fitted {_lag(lag_ms[0])} its row's reading")
            elif np.min(lag_ms) >= 0:
                parts.append(f"{len(lag_ms)} command onsets fitted {np.min(lag_ms):.0f}-{np.max(lag_ms):.0f} ms "
                             f"after their rows' readings (median {np.median(lag_ms):.0f})")
            else:  # some written before their row's reading (a trace logged slower than it was commanded)
                parts.append(f"{len(lag_ms)} command onsets fitted from {_lag(np.min(lag_ms))} to "
                             f"{_lag(np.max(lag_ms))} their rows' readings (median {_lag(np.median(lag_ms))}; "
                             f"{int(np.sum(lag_ms < 0))} before)")
        return "; ".join(parts) or "none"


def _lag(ms: float) -> str:
    """``12 ms after`` / ``40 ms before``."""
    return f"{ms:.0f} ms after" if ms >= 0 else f"{-ms:.0f} ms before"


def _row_cost(ev, simulated: np.ndarray) -> np.ndarray:
    """Robust cost per row, summed over channels, of simulated channels (M, n, C): shape (M, n)."""
    return robust_cost(ev.weigh(ev.whiten(simulated))).sum(axis=2)


def profile_hold_phase(ev, knobs: dict[str, float]) -> float | None:
    """The hold phase (s) that best fits speed and load for ``knobs`` (None if the trace has neither channel)."""
    held = [i for i, ch in enumerate(ev.channels) if ch in ("present_speed", "present_load")]
    if not held:
        return None
    dt = ev.schedule.step_s
    hold = max(1, int(round(knobs["hold_s"] / dt)))
    reqs = [{**knobs, "hold_phase_s": j * dt} for j in range(hold)]
    z = ev.weigh(ev.whiten(ev.run(reqs)))[:, :, held]
    cost = robust_cost(z).sum(axis=(1, 2))
    return float(int(np.argmin(cost)) * dt)


def _owner_rows(ev, starts: np.ndarray) -> list[np.ndarray]:
    """Rows each segment mostly decides: from its earliest possible onset (``starts``) to the next segment's."""
    steps = ev.schedule.sample_steps
    ends = np.append(starts[1:], np.iinfo(np.int64).max)
    return [np.flatnonzero((steps > starts[j]) & (steps <= max(ends[j], starts[j]))) for j in range(len(starts))]


def earliest_onsets(ev) -> np.ndarray:
    """Per segment, the earliest step its commands may start after as the trace format allows: the previous
    row's reading where the onset is not known (registers are "in effect from ``t`` on": written after the
    reading, or earlier, after the row before), else the known onset (``ev.schedule.bounds()[:, 0]``)."""
    b = ev.schedule.bounds()
    steps = ev.schedule.sample_steps
    before = steps[np.maximum(np.searchsorted(steps, b[:, 0], side="left") - 1, 0)]
    return np.where(b[:, 1] > b[:, 0], np.minimum(before, b[:, 0]), b[:, 0])


def _onset_passes(ev, knobs: dict[str, float], best: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                  which: np.ndarray, before: np.ndarray | None = None) -> np.ndarray:
    """:data:`ONSET_PASSES` alternating passes over the segments ``which`` may vary, each within ``lo..hi`` and
    never past its neighbours' current onsets (the commands keep their order).

    ``before`` (each row window's first step): a segment moves only to an onset before it, and only where that
    removes at least :data:`EARLY_SHARE` of the cost of the rows it decides; every :data:`EARLY_STRIDE`-th
    segment is varied at once (a change read a row or two after the one before it is still moving from it), and
    the passes go on until none moves over a whole cycle (at most ``ONSET_PASSES * EARLY_STRIDE`` passes).
    """
    best = best.copy()
    owners = _owner_rows(ev, lo)
    n = len(best)
    stride = 2 if before is None else EARLY_STRIDE
    still = 0
    for p in range(ONSET_PASSES if before is None else ONSET_PASSES * EARLY_STRIDE):
        if before is not None and still >= stride:
            break  # a whole cycle moved nothing: nothing is left to move
        still += 1
        vary = (np.arange(n) % stride == p % stride) & which
        if not vary.any():
            continue
        # the neighbours stay put in this pass (they are not varied in it)
        prev = np.concatenate([[np.iinfo(np.int64).min], best[:-1]])
        nxt = np.concatenate([best[1:], [np.iinfo(np.int64).max]])
        first = np.maximum(lo, prev)
        last = np.maximum(np.minimum(hi, nxt), first)
        if before is not None:  # only the onsets before the row's reading; the last column keeps every one put
            last = np.minimum(last, before - 1)
        vary &= last >= first if before is not None else last > first
        if not vary.any():
            continue
        cols = int((last - first)[vary].max()) + 1
        grid = np.repeat(best[:, None], cols + (before is not None), axis=1)
        grid[vary, :cols] = np.minimum(first[vary][:, None] + np.arange(cols)[None, :], last[vary][:, None])
        cost = _row_cost(ev, ev.run([knobs] * grid.shape[1], onsets=grid))
        for j in np.flatnonzero(vary):
            rows = owners[j]
            if not len(rows):
                continue
            own = cost[:, rows].sum(axis=1)
            if before is None:
                best[j] = grid[j, int(np.argmin(own))]
                continue
            c = int(np.argmin(own[:-1]))
            if own[c] <= (1.0 - EARLY_SHARE) * own[-1] and grid[j, c] != best[j]:
                best[j], still = grid[j, c], 0
    return best


def fit_onsets(ev, knobs: dict[str, float], onsets: np.ndarray | None = None, extend: bool = True) -> np.ndarray:
    """Each segment's onset step that best fits the trace, within its row's window (``ev.schedule.bounds()``)
    and, where the rows say so clearly, back to the previous row's reading (``extend``).

    Alternating passes: the even-numbered changes are varied over their whole
    window (column ``c`` puts every one of them ``c`` steps into its window)
    while the odd ones stay at their current best, then the other way round;
    each change takes the column that fits the rows it mostly decides (from
    its window to the next change's) best.  A change's effect on the rows
    after the next change is small where the servo settles in between, and
    is caught by the next pass where it does not.

    Why the second window (``extend``): the trace format has a row's
    registers in effect from its ``t`` on, written after the reading *or
    earlier* (after the row before).  A client that logs every command's row
    writes after the reading, and its onsets fit inside the row's window.
    One that logs slower than it commands (a row in 20 of a 100 Hz loop) has
    most changes written before the row that shows them.  So, after the
    passes above, each change is searched again from the previous row's
    reading (:func:`earliest_onsets`) to its own, never past a neighbouring
    change, and moved there only where that removes at least
    :data:`EARLY_SHARE` of the cost of the rows it decides, and only if
    :data:`EARLY_CHANGES` of the changes are so moved: how the trace was
    logged is one trait of the recording, and a change or two of a
    row-by-row trace that fit better earlier are the model's miss (a slow
    start), not the recording's.  A row-by-row trace keeps its onsets, a
    sparse one gets them where they were sent.
    Searched only in the row's window, a 100 Hz trace kept a row in 20 was
    left 35 units RMS off and called explained.  :func:`locate_onset` moves
    its one change row by row itself and passes ``extend=False``.
    """
    b = ev.schedule.bounds()
    lo, hi = b[:, 0].copy(), b[:, 1].copy()
    earliest = earliest_onsets(ev) if extend else lo
    best = lo.copy() if onsets is None else np.clip(np.asarray(onsets, dtype=np.int64), earliest, hi)
    best = np.maximum.accumulate(best)
    if not np.any(hi > lo):
        return best
    best = _onset_passes(ev, knobs, best, lo, hi, hi > lo)
    if np.any(earliest < lo):
        early = _onset_passes(ev, knobs, best, earliest, hi, earliest < lo, before=lo)
        if np.sum(early < lo) >= EARLY_CHANGES * np.sum(earliest < lo):  # a trait of the recording, not of a change
            best = early
    return best


def first_movement_row(trace: Trace) -> int:
    """The first row read :data:`MOVEMENT_UNITS` or more from where it rests at first, the next row too
    (:func:`.trace.departures`; ValueError if none)."""
    pos = trace["present_position"].astype(float)
    moved = departures(pos, MOVEMENT_UNITS)
    if len(moved) == 0:
        raise ValueError("the servo never moves in this trace: the time the goal was written cannot be estimated")
    return int(moved[0])


def first_movement_onset(trace: Trace, params: ServoParams = ServoParams(), step_s: float = 1e-3) -> float:
    """When the trace's one goal change was most likely written, from its first movement (s after the first row).

    The measured first movement (the first reading :data:`MOVEMENT_UNITS`
    from the resting one) lies between that row's time and the previous
    row's; the model says how long after a goal is written the shaft first
    gets that far, so the write lies that much earlier.  Returns the middle
    of that interval; :func:`fit_onsets` refines it within a sample.
    """
    m = first_movement_row(trace)
    pos = trace["present_position"].astype(float)
    t = trace.t
    # the model's own response to the goal written at t = 0
    probe = trace.with_columns(goal_position=np.full(len(trace), int(trace["goal_position"][-1])))
    probe.columns.pop("command_t", None)
    schedule = compile_schedule(probe, step_s, params.supply_voltage_v)
    record = simulate(schedule, params, {k: np.array([v]) for k, v in null_knobs(params).items()}, 1)
    model = record.angle[:, 0] / float(RAD_PER_POSITION_UNIT)
    reach = np.flatnonzero(np.abs(model - rest_level(pos)) >= MOVEMENT_UNITS - 0.5)
    if len(reach) == 0:
        raise ValueError(_still_model(probe, params, float(t[-1])))
    lag_s = reach[0] * step_s
    lo, hi = (t[m - 1] if m > 0 else t[0]) - lag_s, t[m] - lag_s
    return float(max((lo + hi) / 2.0, 0.0))


def _still_model(probe: Trace, params: ServoParams, span_s: float) -> str:
    """Why no write time can be estimated when the model never moves: what was simulated, and what holds it still.

    Why it names the span: a time column in the wrong unit (seconds in a column of ms) leaves the model a
    thousandth of the recording to move in, and the goal is the least likely culprit of the three.
    """
    volts = float(np.median(probe["voltage"])) / 10.0 if probe.has("voltage") else params.supply_voltage_v
    return (f"the model does not move {MOVEMENT_UNITS} units from {rest_level(probe['present_position']):g} toward the "
            f"goal {int(probe['goal_position'][-1])} in the {span_s:.4g} s simulated ({len(probe)} rows) at {volts:.1f} V: "
            "the goal, the supply or the model's parameters may hold it still (--goal, --voltage, --params), or the "
            "time column is not in the unit it says")


def locate_onset(build: Callable[[float], Trace], params: ServoParams = ServoParams(),
                 guess_s: float | None = None, max_moves: int = 8) -> tuple[float, Trace]:
    """When a single goal change (not recorded) took effect, to the model's step: (onset s, the trace built for it).

    ``build(onset_s)`` makes the trace with the change on the last row read
    before ``onset_s`` (as :func:`.wizard.to_trace` does).  Starts from
    ``guess_s`` (default :func:`first_movement_onset`), fits the onset within
    that row's sample with the base model (:func:`fit_onsets`), and moves a
    row earlier or later while the best lies on the window's edge.  The
    write is never put at or after the first reading that shows movement
    (a model slower to start than the servo would otherwise pull it there).
    """
    from .evaluate import Evaluator  # evaluate imports batch, as this module does; kept local to stay acyclic

    if guess_s is None:
        guess_s = first_movement_onset(build(0.0), params)
    probe = build(0.0)
    moved_s = float(probe.t[first_movement_row(probe)])
    onset_s, visited = float(guess_s), set()
    for _ in range(max_moves):
        trace = build(onset_s)
        ev = Evaluator(trace, params)
        if len(ev.schedule.segments) < 2:  # written before the first reading: nothing to place
            return onset_s, trace
        lo, hi = ev.schedule.bounds()[1]
        latest = int(np.ceil(moved_s / ev.schedule.step_s - 1e-9)) - 1  # the last step before the movement is seen
        best = min(int(fit_onsets(ev, dict(ev.null), extend=False)[1]), max(latest, int(lo)))
        found = float(best * ev.schedule.step_s)
        t, row = trace.t, int(trace.change_rows()[1])
        visited.add(row)
        if best == lo and row > 1 and row - 1 not in visited:
            onset_s = float((t[row - 1] + t[row]) / 2.0)
        elif best == hi and row + 2 < len(t) and row + 1 not in visited:
            onset_s = float((t[row + 1] + t[row + 2]) / 2.0)
        else:
            return found, trace
    return found, trace


#: Nuisances an effect may name in ``Effect.nuisances``: name -> profiler(evaluator, knobs) -> knob updates.
PROFILERS = {
    "hold_phase": lambda ev, knobs: ({} if (ph := profile_hold_phase(ev, knobs)) is None else {"hold_phase_s": ph}),
}
