"""Simulate many candidate models of one trace at once and score them.

Why it exists: the search asks "what would these 50 parameter sets read?"
again and again.  :class:`Evaluator` answers a whole list in one batched
simulation (identical motion knobs are simulated once; sensing knobs are
applied afterwards), and :class:`Lockstep` lets several least-squares fits,
each in its own thread, pool their requests into that one simulation, so
fitting three candidates costs about what fitting one does.

**Rows that count less.**  Where a trace says its rests are arbitrary
(``meta["rests_arbitrary"]``: a Wizard graph export, where the flat stretch
before the goal's write and after the servo settles lasts as long as the
user happened to wait before and after), each of those two stretches counts
as :data:`REST_COUNTS_S` of readings however long it is (:func:`rest_weights`):
otherwise a recording stopped a minute later would weigh its settled reading
(one unit either way, decided by friction, play and the unrecorded goal as
much as by anything the step shows) a hundred times over the move, and the
model comparison would name whatever moves that unit.  The weights scale the
whitened residual (a down-weighted row is read as a noisier one) in every
cost, fit and count (:meth:`Evaluator.weigh`), and the held-out blocks are
cut to equal weight, so on a single step they hold rows of the move; the
residual a report shows is not weighted.  Traces of a designed excitation (synthetic, live, BAM) have
rests of designed lengths and no weights.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np

from ..params import ServoParams
from .batch import DYNAMIC_KNOBS, SENSING_KNOBS, null_knobs, sample, simulate
from .metrics import CHANNELS, QUANT_STEP, channel_scales, robust_cost
from .phases import classify
from .schedule import compile_schedule
from .trace import Trace, departures, rest_level

__all__ = ["Evaluator", "Lockstep", "HELD_OUT_BLOCKS", "REST_COUNTS_S", "rest_weights"]

#: The trace is cut into 8 equal blocks; these are held out of every fit and used only to check it.
HELD_OUT_BLOCKS = (1, 5)
#: An arbitrary rest (see the module docstring) counts as this many seconds of readings, however long it lasts:
#: about the time a step's own settling takes, so the settled reading counts once, like any other feature.
REST_COUNTS_S = 0.25
#: A reading within this many position units of the final one is settled (the compliance margin's default, 1).
SETTLED_UNITS = 1.0
#: A reading this many units from where the trace rests at first has moved (as :data:`.nuisance.MOVEMENT_UNITS`).
MOVED_UNITS = 2.0


def rest_weights(trace: Trace) -> np.ndarray:
    """Each row's weight: 1, except in a trace with arbitrary rests (module docstring), where the rows before the
    first movement and those after the last reading more than :data:`SETTLED_UNITS` from where it rests at the
    end (:func:`.trace.rest_level`) share :data:`REST_COUNTS_S` worth of readings each."""
    n = len(trace)
    w = np.ones(n)
    if not trace.meta.get("rests_arbitrary") or not trace.has("present_position") or n < 3:
        return w
    pos = trace["present_position"].astype(float)
    moved = departures(pos, MOVED_UNITS)
    if len(moved) == 0:
        return w
    away = np.flatnonzero(np.abs(pos - rest_level(pos, end=True)) > SETTLED_UNITS)
    spacing_s = float(np.median(np.diff(trace.t)))
    # the row before the first movement may have started moving: it stays a move row
    for rows in (np.arange(0, max(int(moved[0]) - 1, 0)), np.arange(int(away[-1]) + 1 if len(away) else n, n)):
        lasts_s = len(rows) * spacing_s
        if lasts_s > REST_COUNTS_S:
            w[rows] = REST_COUNTS_S / lasts_s
    return w


class Evaluator:
    """One measured trace, ready to score candidate knob sets against."""

    def __init__(self, trace: Trace, params: ServoParams = ServoParams(), step_s: float = 1e-3) -> None:
        self.trace, self.params = trace, params
        self.schedule = compile_schedule(trace, step_s, params.supply_voltage_v)
        self.phases = classify(self.schedule, params)
        self._measure(trace, [ch for ch in CHANNELS if trace.has(ch)])
        self.null = null_knobs(params)
        #: Each segment's onset step for every simulation (None: where its row puts it); set by the nuisance fit.
        self.onsets: np.ndarray | None = None
        self._records: dict = {}
        self.simulations = 0
        self.columns = 0


    def _measure(self, trace: Trace, channels: list[str]) -> None:
        """The measured ``channels``, their noise scales (from the rows at rest) and the held-out rows."""
        self.channels = channels
        self.scales = channel_scales(trace, self.phases == 0)
        self.measured = np.stack([trace[ch].astype(float) for ch in channels], axis=1)
        self.sd = np.array([self.scales[ch] for ch in channels])
        weight = rest_weights(trace)
        # blocks of equal weight (of equal row count where every row weighs one): with its rests weighed, the
        # held-out blocks of a single step fall on the move, not on rows at rest that test nothing
        before = np.cumsum(weight) - weight
        block = np.floor(before * 8 / weight.sum() + 1e-9).astype(np.int64)
        self.held = np.isin(block, HELD_OUT_BLOCKS)
        self.train = ~self.held
        #: sqrt of each row's weight (:func:`rest_weights`): what :meth:`weigh` scales the whitened residual by.
        self.row_scale = np.sqrt(weight)
        #: Each row's weight (:func:`rest_weights`).
        self.weight = weight
        # The model is read unrounded (a prediction: the reading's rounding is part of the noise the sd counts).  On
        # a moving shaft successive readings round independently; through an arbitrary rest the shaft is still and
        # every reading shares one rounding, so a model resting anywhere within the reading's unit fits them all
        # and is compared by its distance to that unit: counted row by row, one rounding decided the fit (a bar's
        # inertia and the gearbox efficiency traded to bring the settled level to a whole unit).
        self.resting = weight < 1.0
        self.half_step = np.array([QUANT_STEP[ch] / 2.0 for ch in channels])

    def weigh(self, z: np.ndarray) -> np.ndarray:
        """Whitened residuals (..., n, C) scaled by each row's weight, as every cost and count reads them."""
        return z * self.row_scale[:, None]

    def run(self, requests: list[dict[str, float]], onsets: np.ndarray | None = None) -> np.ndarray:
        """Simulated channels for each knob set, shape (M, n, C); missing knobs take their null value.

        ``onsets``: each segment's onset step (:func:`.batch.simulate`), shape
        (segments,) for all requests or (segments, M) one column per request;
        default :attr:`onsets` (the recording's fitted onsets, or the rows').
        """
        full = [{**self.null, **r} for r in requests]
        per_request = onsets is not None and np.ndim(onsets) == 2
        shared = None if per_request else (self.onsets if onsets is None else np.asarray(onsets))
        keys = [tuple(r[name] for name in DYNAMIC_KNOBS) + ((onsets[:, i].tobytes(),) if per_request else ())
                for i, r in enumerate(full)]
        unique = list(dict.fromkeys(keys))
        index = {key: i for i, key in enumerate(unique)}
        dyn = {name: np.array([key[j] for key in unique]) for j, name in enumerate(DYNAMIC_KNOBS)}
        first = [keys.index(key) for key in unique]
        cols = np.asarray(onsets)[:, first] if per_request else shared
        cache_key = (tuple(unique), None if cols is None else np.asarray(cols).tobytes())
        record = self._records.get(cache_key)
        if record is None:  # a profile over sensing knobs only (e.g. the hold phase) reuses the motion
            record = simulate(self.schedule, self.params, dyn, len(unique), onsets=cols)
            self._records = {cache_key: record}
            self.simulations += 1
            self.columns += len(unique)
        sensing = {name: np.array([r[name] for r in full]) for name in SENSING_KNOBS}
        out = sample(self.schedule, record, self.params, sensing, columns=np.array([index[k] for k in keys]), rounded=False)
        return np.stack([out[ch] for ch in self.channels], axis=2).astype(float).transpose(1, 0, 2)

    def whiten(self, simulated: np.ndarray) -> np.ndarray:
        """(sim - measured) / channel sd, same shape as ``simulated``; on the rows of an arbitrary rest, the distance
        to the reading's unit instead (see :meth:`_measure`)."""
        d = simulated - self.measured
        if self.resting.any():
            d = np.where(self.resting[:, None], np.sign(d) * np.maximum(np.abs(d) - self.half_step, 0.0), d)
        return d / self.sd

    def costs(self, z: np.ndarray) -> tuple[float, float]:
        """Robust cost of whitened residuals ``z`` (n, C) on the training rows and on the held-out rows."""
        c = robust_cost(self.weigh(z)).sum(axis=1)
        return float(c[self.train].sum()), float(c[self.held].sum())


class Lockstep:
    """Run callables in threads; their ``submit`` calls are merged into one :meth:`Evaluator.run`."""

    def __init__(self, run: Callable[[list[dict]], np.ndarray]) -> None:
        self._run = run
        self._cv = threading.Condition()
        self._pending: list[dict] = []
        self._active = 0

    def submit(self, requests: list[dict]) -> np.ndarray:
        """Simulate ``requests`` together with whatever the other threads are waiting for."""
        slot = {"requests": requests, "result": None, "error": None}
        with self._cv:
            self._pending.append(slot)
            self._maybe_run()
            while slot["result"] is None and slot["error"] is None:
                self._cv.wait()
        if slot["error"] is not None:
            raise RuntimeError("batched simulation failed") from slot["error"]
        return slot["result"]

    def _maybe_run(self) -> None:
        """With the lock held: once every live thread waits, run all their requests as one batch."""
        if not self._pending or len(self._pending) < self._active:
            return
        batch, self._pending = self._pending, []
        flat = [r for s in batch for r in s["requests"]]
        try:
            result = self._run(flat)
            i = 0
            for s in batch:
                s["result"] = result[i: i + len(s["requests"])]
                i += len(s["requests"])
        except Exception as exc:  # every waiter must wake, or the pool deadlocks
            for s in batch:
                s["error"] = exc
        self._cv.notify_all()

    def map(self, jobs: list[Callable[[], object]]) -> list[object]:
        """Run ``jobs`` concurrently (each may call :meth:`submit`); return their results in order."""
        results: list[object] = [None] * len(jobs)
        errors: list[BaseException] = []
        self._active = len(jobs)

        def wrap(i: int, job: Callable[[], object]) -> None:
            try:
                results[i] = job()
            except BaseException as exc:  # reported after join
                errors.append(exc)
            finally:
                with self._cv:
                    self._active -= 1
                    self._maybe_run()

        threads = [threading.Thread(target=wrap, args=(i, job), daemon=True) for i, job in enumerate(jobs)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        if errors:
            raise errors[0]
        return results
