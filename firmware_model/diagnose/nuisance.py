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
  within that window (:func:`fit_onsets`).  For a Wizard export, where the
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
           "first_movement_row", "PROFILERS",
           "ONSET_PASSES", "MOVEMENT_UNITS"]

#: Alternating passes over the command changes (even ones varied, then odd ones) in :func:`fit_onsets`.
ONSET_PASSES = 4
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
                parts.append(f"the command's onset fitted {lag_ms[0]:.0f} ms after its row's reading")
            else:
                parts.append(f"{len(lag_ms)} command onsets fitted {np.min(lag_ms):.0f}-{np.max(lag_ms):.0f} ms "
                             f"after their rows' readings (median {np.median(lag_ms):.0f})")
        return "; ".join(parts) or "none"


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


def _owner_rows(ev) -> list[np.ndarray]:
    """Rows each segment mostly decides: from its earliest possible onset to the next segment's."""
    b = ev.schedule.bounds()
    steps = ev.schedule.sample_steps
    starts = np.append(b[:, 0], np.iinfo(np.int64).max)
    return [np.flatnonzero((steps > starts[j]) & (steps <= starts[j + 1])) for j in range(len(b))]


def fit_onsets(ev, knobs: dict[str, float], onsets: np.ndarray | None = None) -> np.ndarray:
    """Each segment's onset step within its window (``ev.schedule.bounds()``) that best fits the trace.

    Alternating passes: the even-numbered changes are varied over their whole
    window (column ``c`` puts every one of them ``c`` steps into its window)
    while the odd ones stay at their current best, then the other way round;
    each change takes the column that fits the rows it mostly decides (from
    its window to the next change's) best.  A change's effect on the rows
    after the next change is small where the servo settles in between, and
    is caught by the next pass where it does not.
    """
    b = ev.schedule.bounds()
    width = b[:, 1] - b[:, 0]
    best = b[:, 0].copy() if onsets is None else np.clip(np.asarray(onsets, dtype=np.int64), b[:, 0], b[:, 1])
    if not np.any(width > 0):
        return best
    owners = _owner_rows(ev)
    for p in range(ONSET_PASSES):
        vary = (np.arange(len(b)) % 2 == p % 2) & (width > 0)
        if not vary.any():
            continue
        cols = int(width[vary].max()) + 1
        grid = np.repeat(best[:, None], cols, axis=1)
        grid[vary] = np.minimum(b[vary, 0][:, None] + np.arange(cols)[None, :], b[vary, 1][:, None])
        cost = _row_cost(ev, ev.run([knobs] * cols, onsets=grid))
        for j in np.flatnonzero(vary):
            rows = owners[j]
            if len(rows):
                best[j] = grid[j, int(np.argmin(cost[:, rows].sum(axis=1)))]
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
        raise ValueError("the model does not move under the assumed goal: check --goal")
    lag_s = reach[0] * step_s
    lo, hi = (t[m - 1] if m > 0 else t[0]) - lag_s, t[m] - lag_s
    return float(max((lo + hi) / 2.0, 0.0))


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
        best = min(int(fit_onsets(ev, dict(ev.null))[1]), max(latest, int(lo)))
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
