"""Selection: which effects are worth fitting this round, and their fits against the current model.

Why it is apart from the verdict (:mod:`.verdict`): screening and fitting
need the trace, the simulator and the current model (base values, chosen
effects, the recording's traits); judging a fit needs none of them, only the
numbers a fit leaves.  This module turns the current model into those
numbers, typed (:class:`Score`, :class:`Screened`, :class:`Fit`), and decides
nothing about names.

* **Screen** (:meth:`Selection.screen`): every remaining effect on its coarse
  grid, all in one batched simulation, with the current model's other
  parameters fixed; effects with ``nuisances`` have those recording traits
  re-fitted at each grid point.
* **Shortlist** (:func:`shortlist`): the :data:`FIT_TOP` most promising smooth
  effects (lowest screened cost, and below the current model's) and the best
  grid-only one.
* **Fit** (:meth:`Selection.fit_shortlist`): the smooth ones by
  :func:`scipy.optimize.least_squares` (soft-L1 loss on residuals whitened
  by channel noise, the shared base parameters and the smooth accepted
  effects re-fitted with the effect, started at the best grid points: a
  multi-start for the non-smooth parameters), all fits in lockstep threads
  sharing each simulation; grid-only effects (``smooth=False``) keep their
  grid optimum (:meth:`Selection.grid_fit`).  A one-parameter effect whose
  best value moves a recording trait (``delay``: the hold's phase) is then
  profiled with the trait re-fitted at each point and fitted again from the
  best (:meth:`Selection.refine_with_nuisances`).

**The write time of a single unrecorded step** (a Wizard export: one goal
written at a time nobody recorded).  The base fit places it to the model's
step (:mod:`.nuisance`), but a step's start lag is what inertia, friction and
the drive's strength all move: held where the base model put it, an inertia
is charged for a lag the write time would absorb (the real AX-12A steps: the
cost of the bars' J halves once the write is re-fitted).  So on such a trace
the write time is also a continuous shared base parameter, :data:`WRITE_SHIFT`
(the readings of a servo at rest until the write, shifted in time: the
sampler's reading latency, which is the same thing on such a trace and is why
the ``delay`` effect is not offered on it), re-fitted with every candidate:
profiled over :data:`WRITE_SHIFT_GRID_S` at each screened grid point (a
re-sampling, no new simulation) and fitted by least squares with the rest, so
an effect's interval allows for it.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from ..params import ServoParams
from .effects import LIBRARY, Effect, Param, apply_effects
from .evaluate import Lockstep
from .families import Family, family_of
from .metrics import F_SCALE, effective_count
from .nuisance import PROFILERS, Nuisance, fit_onsets, profile_hold_phase
from .trace import Trace

__all__ = ["Selection", "Score", "Screened", "Fit", "Linearisation", "shortlist", "BASE_ONLY", "FIT_TOP", "MAX_NFEV", "NUISANCE_PROFILE_STEPS", "WRITE_SHIFT",
           "WRITE_SHIFT_KNOB", "WRITE_SHIFT_GRID_S"]

#: Candidates fitted per round.
FIT_TOP = 3
#: Function evaluations per fit (each one batched simulation).
MAX_NFEV = 10
#: Where a one-parameter effect with recording nuisances is profiled after its fit, in its finite-difference steps
#: either way of the fitted value (:meth:`Selection.refine_with_nuisances`): a quarter step apart, two steps out.
NUISANCE_PROFILE_STEPS = tuple(k / 4 for k in range(-8, 9))

#: The write time of a single unrecorded step, as a shift of the readings (s; see the module docstring).  Bounds: a
#: reading period (20 ms on a Wizard export) either way of where the base fit placed it; the step is 1 ms.
WRITE_SHIFT = Param("write_shift_s", 0.0, -0.025, 0.025, (0.0,), 0.001, (0.0, 0.0))
#: The simulator's knob that shifts the readings in time (the ``delay`` effect's, not offered on such a trace).
WRITE_SHIFT_KNOB = "delay_s"
#: Shifts profiled at each screened grid point (s).
WRITE_SHIFT_GRID_S = tuple(round(0.002 * i, 3) for i in range(-10, 11))

#: A pseudo-effect with no parameters: fitting it re-fits only the shared base parameters (and the smooth chosen
#: effects, unless held: :meth:`Selection.fit`).
BASE_ONLY = Effect("base", "", "", (), lambda v, k: {}, ())


@dataclass(frozen=True)
class Score:
    """How well one model reproduces the trace: what every test of a fit is computed from."""

    #: Robust cost on the training rows.
    cost_train: float
    #: Robust cost on the held-out rows (never fitted to).
    cost_held: float
    #: Training rows' count corrected for autocorrelation (the sample size the BIC and the intervals use).
    n_eff: float


@dataclass
class Screened:
    """One effect's coarse grid, screened against the current model."""

    effect: str
    #: Every grid point (parameter values) and its training cost, in grid order.
    table: list[tuple[dict[str, float], float]]
    #: The grid point with the lowest training cost, that cost and its whitened residual (n, C).
    best_values: dict[str, float]
    best_cost: float
    best_z: np.ndarray
    #: Each grid point's re-fitted recording traits (knob -> value), keyed by the point's values in order.
    nuisance: dict[tuple[float, ...], dict[str, float]]
    #: Each grid point's profiled write shift (:data:`WRITE_SHIFT`), keyed like ``nuisance``; empty where not fitted.
    shift: dict[tuple[float, ...], float] = field(default_factory=dict)

    def starts(self, count: int) -> list[dict[str, float]]:
        """The ``count`` best grid points, best first: where the least-squares fits start."""
        return [vals for vals, _ in sorted(self.table, key=lambda e: e[1])[:count]]


@dataclass(frozen=True)
class Linearisation:
    """A least-squares fit's model at its optimum: what the Wald test needs."""

    #: Parameter of each Jacobian column (the effect's, the re-fitted accepted effects', the base's).
    names: list[str]
    #: Whitened training residuals, flattened (rows x channels).
    residual: np.ndarray
    #: d residual / d parameter, one column per name.
    jacobian: np.ndarray


@dataclass
class Fit:
    """One effect fitted against the current model: values and how well the result reproduces the trace."""

    effect: str
    values: dict[str, float]
    #: The shared base parameters as re-fitted with the effect.
    base: dict[str, float]
    #: Every effect's values with this one added (accepted smooth effects re-fitted with it).
    refitted: dict[str, dict[str, float]]
    score: Score
    #: Whitened residual of the fitted model, all rows (n, C).
    z: np.ndarray
    #: Least-squares fits: the linearisation at the optimum (for the Wald test); None for grid-only fits.
    linear: Linearisation | None = None
    #: Grid-only fits: the screened grid with each point's training cost (for the profile test).
    grid: list[tuple[dict[str, float], float]] = field(default_factory=list)


class Selection:
    """The current model of one trace (base, chosen effects, recording traits) and how to fit changes to it."""

    def __init__(self, trace: Trace, params: ServoParams | None, progress: Callable[[str], None],
                 family: Family | None = None) -> None:
        family = family or family_of(trace)
        #: The effects this trace's servo family can be diagnosed with (:mod:`.families`).
        self.library = family.library
        #: The trace's servo family (:mod:`.families`).
        self.family = family
        self.ev = family.evaluator(trace, family.default_params() if params is None else params)
        self.params = self.ev.params
        self.progress = progress
        start = self.ev.params
        self.base_params = tuple(Param(p.name, getattr(start, p.name), p.low, p.high, (getattr(start, p.name),),
                                       p.fd_step, p.hidden) for p in family.base_params)
        #: Whether the trace is one step written at an unrecorded time (module docstring): the write shift is fitted.
        self.shifts_write = (not self.ev.schedule.onsets_known and len(self.ev.schedule.segments) == 2
                             and WRITE_SHIFT_KNOB in self.ev.null and not self.ev.null[WRITE_SHIFT_KNOB])
        if self.shifts_write:
            self.base_params += (WRITE_SHIFT,)
        self.base = {p.name: p.null for p in self.base_params}
        self.chosen: dict[str, dict[str, float]] = {}
        self.nuisance = Nuisance(onsets_fitted=not self.ev.schedule.onsets_known)

    def knobs(self, base: dict[str, float], chosen: dict[str, dict[str, float]],
              nuisance: dict[str, float] | None = None) -> dict[str, float]:
        """Simulator knobs for base values, the recording's nuisance (``nuisance`` overrides it) and chosen effects."""
        k = dict(self.ev.null)
        k.update(base)
        if WRITE_SHIFT.name in k:
            k[WRITE_SHIFT_KNOB] = k.pop(WRITE_SHIFT.name)
        k.update(self.nuisance.knobs())
        k.update(nuisance or {})
        return apply_effects(k, chosen, self.library)

    def fit_nuisance(self) -> None:
        """Re-fit the recording's traits to the current model (see :mod:`.nuisance`): onsets, then the hold phase."""
        if self.nuisance.onsets_fitted:
            self.nuisance.onsets = fit_onsets(self.ev, self.knobs(self.base, self.chosen), self.nuisance.onsets)
            self.ev.onsets = self.nuisance.onsets
        self.nuisance.hold_phase_s = profile_hold_phase(self.ev, self.knobs(self.base, self.chosen))

    def residual(self) -> np.ndarray:
        """Whitened residual (n, C) of the current model."""
        return self.ev.whiten(self.ev.run([self.knobs(self.base, self.chosen)]))[0]

    def score(self, z: np.ndarray) -> Score:
        """Costs and effective training count of whitened residuals ``z`` (n, C)."""
        s, h = self.ev.costs(z)
        return Score(s, h, effective_count(self.ev.weigh(z)[self.ev.train], self.ev.weight[self.ev.train]))

    def _traits(self, effect: Effect, knobs: dict[str, float]) -> dict[str, float]:
        """The recording's traits ``effect`` moves (its ``nuisances``), re-fitted for ``knobs``: knob -> value."""
        traits: dict[str, float] = {}
        for nuisance in effect.nuisances:
            traits.update(PROFILERS[nuisance](self.ev, knobs))
        return traits

    # ------------------------------------------------------------------ screen
    def screen(self, remaining: list[str], round_no: int) -> dict[str, Screened]:
        """Every remaining effect on its coarse grid, in one batched simulation (see the module docstring)."""
        ev = self.ev
        grid_reqs, owners = [], []
        profiled: dict[tuple[str, tuple], dict[str, float]] = {}  # (effect, grid point) -> its re-fitted traits
        for name in remaining:
            e = self.library[name]
            for combo in itertools.product(*(p.grid for p in e.params)):
                vals = dict(zip([p.name for p in e.params], combo))
                req = self.knobs(self.base, {**self.chosen, name: vals})
                prof = self._traits(e, req)  # re-fitted for this grid point (sensing only: no new simulation)
                req.update(prof)
                profiled[(name, combo)] = prof
                grid_reqs.append(req)
                owners.append((name, vals))
        self.progress(f"round {round_no}: screening {len(remaining)} effects on {len(grid_reqs)} grid points")
        shifts = np.zeros(len(grid_reqs))
        if self.shifts_write:  # the write shift profiled at every grid point: one simulation, re-sampled per shift
            grid_s = np.array(WRITE_SHIFT_GRID_S) + self.base[WRITE_SHIFT.name]
            grid_s = grid_s[(grid_s >= WRITE_SHIFT.low) & (grid_s <= WRITE_SHIFT.high)]
            reqs = [{**r, WRITE_SHIFT_KNOB: float(d)} for r in grid_reqs for d in grid_s]
            zs_all = ev.whiten(ev.run(reqs)).reshape(len(grid_reqs), len(grid_s), *ev.measured.shape)
            at = np.array([int(np.argmin([ev.costs(z)[0] for z in row])) for row in zs_all])
            shifts = grid_s[at]
            zs = zs_all[np.arange(len(grid_reqs)), at]
        else:
            zs = ev.whiten(ev.run(grid_reqs))
        out: dict[str, Screened] = {}
        for (name, vals), z, shift in zip(owners, zs, shifts):
            s, _ = ev.costs(z)
            entry = out.get(name)
            if entry is None:
                entry = out[name] = Screened(name, [], {}, np.inf, None,
                                             {c: p for (n, c), p in profiled.items() if n == name})
            if self.shifts_write:
                entry.shift[tuple(vals.values())] = float(shift)
            entry.table.append((vals, s))
            if s < entry.best_cost:
                entry.best_values, entry.best_cost, entry.best_z = vals, s, z
        return out

    # ------------------------------------------------------------------ fits
    def fit_shortlist(self, screened: dict[str, Screened], smooth: list[str], with_base: bool
                      ) -> tuple[list[Fit], Fit | None]:
        """Least-squares fits of the ``smooth`` shortlist (each its best start), and of the base alone if asked.

        Each effect starts from its best grid point; effects with ``starts`` >
        1 also from their next-best ones (all fits share each batched
        simulation, so extra starts cost columns, not passes).
        """
        lock = Lockstep(self.ev.run)
        starts = [(n, vals) for n in smooth for vals in screened[n].starts(self.library[n].starts)]
        jobs = [lambda n=n, v=v: self.fit(self.library[n], v, lock, screened[n].nuisance[tuple(v.values())],
                                          screened[n].shift.get(tuple(v.values())))
                for n, v in starts]
        if with_base:  # the shared base parameters alone, in the same batches
            jobs.append(lambda: self.fit(BASE_ONLY, {}, lock))
        all_fits: list[Fit] = lock.map(jobs)
        base_fit = all_fits.pop() if with_base else None
        fits = []
        for name in smooth:  # the best start of each effect (lowest training cost)
            mine = [f for (n, _), f in zip(starts, all_fits) if n == name]
            fits.append(self.refine_with_nuisances(min(mine, key=lambda f: f.score.cost_train)))
        return fits, base_fit

    def refine_with_nuisances(self, fit: Fit) -> Fit:
        """``fit`` of a one-parameter effect with ``nuisances`` (``delay``), moved to the best point of a fine profile
        over its parameter (:data:`NUISANCE_PROFILE_STEPS`) with the recording's traits re-fitted at each point, and
        fitted again by least squares from there; ``fit`` itself where that costs no less.

        Why: the least squares holds the traits where the effect's grid start put them, and the traits move with
        the parameter (the hold's phase with a reading latency): held, the fit stayed at its start.  On synthetic
        traces a hidden delay of 10.8 ms was fitted at the grid's 10.0 ms, where with the phase re-fitted at each
        value the cost is smooth and least at 10.5-10.75 ms.  The profile re-samples one motion (the effect and the
        traits are sensing knobs), so it costs no simulation of the shaft.
        """
        effect = self.library[fit.effect]
        if not effect.nuisances or len(effect.params) != 1 or not effect.smooth:
            return fit
        p = effect.params[0]
        x0 = fit.values[p.name]
        xs = sorted({float(np.clip(x0 + k * p.fd_step, p.low, p.high)) for k in NUISANCE_PROFILE_STEPS})
        reqs, profiled = [], []
        for x in xs:
            req = self.knobs(fit.base, {**fit.refitted, effect.name: {p.name: x}})
            traits = self._traits(effect, req)
            reqs.append({**req, **traits})
            profiled.append(traits)
        costs = [self.ev.costs(z)[0] for z in self.ev.whiten(self.ev.run(reqs))]
        best = int(np.argmin(costs))
        if costs[best] >= fit.score.cost_train:
            return fit
        lock = Lockstep(self.ev.run)
        shift = fit.base.get(WRITE_SHIFT.name) if self.shifts_write else None
        again = lock.map([lambda: self.fit(effect, {p.name: xs[best]}, lock, profiled[best], shift)])[0]
        return again if again.score.cost_train < fit.score.cost_train else fit

    def grid_fit(self, screened: Screened) -> Fit:
        """A grid-only effect at its grid optimum, against the current base and chosen effects."""
        values = {k: float(v) for k, v in screened.best_values.items()}
        refitted = {**{k: dict(v) for k, v in self.chosen.items()}, screened.effect: values}
        _, held = self.ev.costs(screened.best_z)
        score = Score(screened.best_cost, held, effective_count(self.ev.weigh(screened.best_z)[self.ev.train],
                                                                self.ev.weight[self.ev.train]))
        base = dict(self.base)
        if self.shifts_write:
            base[WRITE_SHIFT.name] = screened.shift.get(tuple(screened.best_values.values()), base[WRITE_SHIFT.name])
        return Fit(screened.effect, values, base, refitted, score, screened.best_z, grid=screened.table)

    def fit(self, effect: Effect, start: dict[str, float], lock: Lockstep,
            nuisance: dict[str, float] | None = None, shift_s: float | None = None, hold_chosen: bool = False) -> Fit:
        """Fit ``effect`` plus the base and the smooth accepted effects, from ``start``.

        ``nuisance``: the recording's traits as re-fitted at ``start`` (for an
        effect with ``nuisances``), held through the fit.  ``shift_s``: the
        write shift profiled at ``start`` (where it is fitted), where its fit starts.

        The accepted effects are re-fitted too (their columns cost little in a
        batched simulation), so a new effect is not accepted merely to patch an
        earlier fit; ``hold_chosen`` holds them where :attr:`chosen` puts them (a
        profile over an effect's value, the base re-fitted at each: ``tools/real_ax12a_inertia.py --split``).
        """
        owners = [(effect.name, p) for p in effect.params]
        owners += [(name, p) for name in self.chosen if self.library[name].smooth and not hold_chosen
                   for p in self.library[name].params]
        owners += [("base", p) for p in self.base_params]
        names = [p.name for _, p in owners]
        lo = np.array([p.low for _, p in owners])
        hi = np.array([p.high for _, p in owners])
        step = np.array([p.fd_step for _, p in owners])
        base0 = dict(self.base)
        if shift_s is not None:
            base0[WRITE_SHIFT.name] = shift_s
        x0 = np.array([start.get(p.name, p.null) if o == effect.name else
                       (base0[p.name] if o == "base" else self.chosen[o][p.name]) for o, p in owners], dtype=float)
        x0 = np.clip(x0, lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
        cache: dict[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        train = self.ev.train

        def split(x):
            chosen = {k: dict(v) for k, v in self.chosen.items()}
            base: dict[str, float] = {}
            values: dict[str, float] = {}
            for (o, p), v in zip(owners, x):
                if o == "base":
                    base[p.name] = float(v)
                elif o == effect.name:
                    values[p.name] = float(v)
                else:
                    chosen[o][p.name] = float(v)
            if effect.params:
                chosen[effect.name] = values
            return values, base, chosen

        def evaluate(x):
            key = x.tobytes()
            if key not in cache:
                pts, hs = [x.copy()], []
                for j in range(len(x)):
                    h = step[j] if x[j] + step[j] <= hi[j] else -step[j]
                    xp = x.copy()
                    xp[j] += h
                    pts.append(xp)
                    hs.append(h)
                reqs = []
                for pt in pts:
                    _, b, chosen = split(pt)
                    reqs.append(self.knobs(b, chosen, nuisance))
                z = self.ev.whiten(lock.submit(reqs))
                zw = self.ev.weigh(z)  # the rows' weights, as every cost reads them
                r0 = zw[0][train].ravel()
                jac = np.stack([(zw[j + 1][train].ravel() - r0) / hs[j] for j in range(len(x))], axis=1)
                cache[key] = (r0, jac, z[0])
            return cache[key]

        res = least_squares(lambda x: evaluate(x)[0], x0, jac=lambda x: evaluate(x)[1], bounds=(lo, hi),
                            loss="soft_l1", f_scale=F_SCALE, x_scale=step, max_nfev=MAX_NFEV * effect.effort,
                            method="trf", ftol=1e-4, xtol=1e-3)
        r0, jac, z = evaluate(res.x)
        values, base, chosen = split(res.x)
        return Fit(effect.name, values, base, chosen, self.score(z), z, linear=Linearisation(names, r0, jac))


def shortlist(screened: dict[str, Screened], current_cost: float,
              library: dict[str, Effect] | None = None) -> tuple[list[str], list[str]]:
    """(smooth effects to fit by least squares, grid-only effects to judge at their optimum), best first.

    Only effects whose best grid point already beats the current model
    (training cost ``current_cost``) are worth a fit.
    """
    library = library or LIBRARY
    ranked = sorted((s.best_cost, n) for n, s in screened.items() if s.best_cost < current_cost)
    smooth = [n for _, n in ranked if library[n].smooth][:FIT_TOP]
    rough = [n for _, n in ranked if not library[n].smooth][:1]
    return smooth, rough
