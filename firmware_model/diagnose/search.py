"""Forward selection over the effect library: screen, fit, test, accept, repeat.

Why it exists: it turns "the model is off" into "this effect, with these
values, explains it", with tests that keep it from naming noise.

Before the first round and after each accepted effect, the recording's
traits (:mod:`.nuisance`: the phase of the speed/load hold, and when each
command took effect where the trace does not record it) are re-fitted to the
current model.  They are part of the base model, never candidates; effects
that only a recorded command time can tell from them (``delay``) are not
offered on traces without one (:attr:`Diagnosis.not_offered`).

Each round:

1. **Screen** every remaining effect on its coarse grid (all of them in one
   batched simulation) with the current model's other parameters fixed.
2. **Fit** the three most promising (lowest screened cost, and below the
   current model's) by :func:`scipy.optimize.least_squares` (soft-L1 loss on
   residuals whitened by channel noise, the shared base parameters re-fitted
   with the effect, started at the best grid point: a multi-start for the
   non-smooth parameters); the fits run in lockstep threads sharing each
   simulation.  Grid-only effects (``smooth=False``) keep their grid optimum.
3. **Test** each fit; accept the best (by BIC) only if all hold: BIC improves
   by more than :data:`BIC_MARGIN` with the autocorrelation-corrected sample
   count; the cost on the held-out blocks falls; the 95 % confidence region
   of its ``tested`` parameters excludes the null (Wald test from the fit's
   Jacobian, inflated for autocorrelation; a profile over the grid for
   grid-only effects).

It stops when no candidate passes, then compares the final model with the
measurement: if a residual remains that is not noise the verdict says so (an
unexplained residual) and effects that explained only a small share are
marked tentative.  "Not noise" is judged from the data alone, two ways:

* **structure** (position, the one channel read fresh every row): the pot's
  noise and the quantisation are independent from row to row, a model error
  is smooth in time.  The white-noise level is estimated from the residual's
  own first differences, ``s_w = sqrt(mean(diff(r)**2) / 2)``; what is left of
  the residual's variance, ``s_struct = sqrt(rms**2 - s_w**2)``, is its
  structured (time-correlated) part.  It is unexplained when ``s_struct``
  exceeds both :data:`STRUCTURE_RATIO` times ``s_w`` and
  :data:`STRUCTURE_FLOOR_UNITS` (one position unit: a smaller systematic
  error is below the sensor's resolution and nobody's concern).  On
  synthetic traces a correct model leaves ``s_struct`` 0.2-0.45 units
  (0.5-1 x ``s_w``: rest offsets of one unit, timing jitter); an
  out-of-library cogging ripple of 0.15-0.25 N m leaves 2-2.7 units
  (3-4 x ``s_w``).
* **size** (every channel): the trimmed RMS of the residual, whitened by the
  channel's noise measured at rest, above :data:`UNEXPLAINED_RMS`.
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2

from ..params import ServoParams
from .effects import BASE_PARAMS, LIBRARY, Effect, Param, apply_effects
from .evaluate import Evaluator, Lockstep
from .metrics import F_SCALE, effective_count, gaps, trimmed_rms
from .nuisance import PROFILERS, Nuisance, fit_onsets, profile_hold_phase
from .phases import PHASES
from .trace import Trace

__all__ = ["Candidate", "Diagnosis", "diagnose", "BIC_MARGIN", "UNEXPLAINED_RMS", "TENTATIVE_SHARE",
           "STRUCTURE_RATIO", "STRUCTURE_FLOOR_UNITS", "residual_structure"]

log = logging.getLogger(__name__)

#: BIC must improve by more than this (the usual "strong evidence" threshold).
BIC_MARGIN = 10.0
#: Whitened residual RMS (in channel sd) above which a channel counts as unexplained.
UNEXPLAINED_RMS = 2.5
#: Structured position residual above this many times the white-noise level (both from the residual) is unexplained.
STRUCTURE_RATIO = 1.5
#: ... and above this many position units RMS (one quantisation step).
STRUCTURE_FLOOR_UNITS = 1.0
#: With an unexplained residual, an effect that removed less than this share of the cost is "tentative".
TENTATIVE_SHARE = 0.8
#: A candidate must also remove this share of the current cost (practical, not only statistical, significance).
MIN_SHARE = 0.05
#: Candidates fitted per round.
FIT_TOP = 3
#: Function evaluations per fit (each one batched simulation).
MAX_NFEV = 10
#: At most this many effects are named.
MAX_ROUNDS = 4


@dataclass
class Candidate:
    """One effect fitted in one round, with its test results."""

    effect: str
    values: dict[str, float]
    base: dict[str, float]
    #: 95 % half-width of each fitted parameter (NaN where not estimable).
    uncertainty: dict[str, float]
    cost_train: float
    cost_held: float
    delta_bic: float
    n_eff: float
    null_excluded: bool
    accepted: bool = False
    #: Every effect's values after this fit (earlier ones re-fitted with it).
    refitted: dict[str, dict[str, float]] = field(default_factory=dict)
    reasons: list[str] = field(default_factory=list)
    confidence: str = ""
    #: Share of the then-current cost this effect removed.
    share: float = 0.0

    def passed(self) -> bool:
        """All three acceptance tests hold."""
        return not self.reasons


@dataclass
class Diagnosis:
    """What the workflow found."""

    accepted: list[Candidate]
    rounds: list[list[Candidate]]
    base: dict[str, float]
    knobs: dict[str, float]
    channels: list[str]
    scales: dict[str, float]
    phases: np.ndarray
    sim_before: dict[str, np.ndarray]
    sim_after: dict[str, np.ndarray]
    gaps_before: dict
    gaps_after: dict
    unexplained: bool
    unexplained_detail: str
    residual_rms_sd: dict[str, float]
    seconds: float
    simulations: int
    #: The recording's traits fitted with the base model (hold phase, command onsets), never named as effects.
    nuisance: Nuisance = field(default_factory=Nuisance)
    #: Effects not offered on this trace, with the reason.
    not_offered: dict[str, str] = field(default_factory=dict)

    @property
    def named(self) -> list[str]:
        """Identifiers of the accepted effects, in order."""
        return [c.effect for c in self.accepted]

    @property
    def confident(self) -> list[str]:
        """Identifiers of the accepted effects not marked tentative."""
        return [c.effect for c in self.accepted if c.confidence == "confident"]


#: A pseudo-effect with no parameters: fitting it re-fits only the shared base parameters.
_BASE_ONLY = Effect("base", "", "", (), lambda v, k: {}, ())


class _Search:
    """State of one diagnosis (the current model and how to score changes to it)."""

    def __init__(self, trace: Trace, params: ServoParams, progress: Callable[[str], None]) -> None:
        self.ev = Evaluator(trace, params)
        self.params = params
        self.progress = progress
        self.base_params = tuple(Param(p.name, getattr(params, p.name), p.low, p.high, (getattr(params, p.name),),
                                       p.fd_step, p.hidden) for p in BASE_PARAMS)
        self.base = {p.name: p.null for p in self.base_params}
        self.chosen: dict[str, dict[str, float]] = {}
        self.nuisance = Nuisance(onsets_fitted=not self.ev.schedule.onsets_known)

    def knobs(self, base: dict[str, float], chosen: dict[str, dict[str, float]],
              nuisance: dict[str, float] | None = None) -> dict[str, float]:
        """Simulator knobs for base values, the recording's nuisance (``nuisance`` overrides it) and chosen effects."""
        k = dict(self.ev.null)
        k.update(base)
        k.update(self.nuisance.knobs())
        k.update(nuisance or {})
        return apply_effects(k, chosen)

    def fit_nuisance(self) -> None:
        """Re-fit the recording's traits to the current model (see :mod:`.nuisance`): onsets, then the hold phase."""
        if self.nuisance.onsets_fitted:
            self.nuisance.onsets = fit_onsets(self.ev, self.knobs(self.base, self.chosen), self.nuisance.onsets)
            self.ev.onsets = self.nuisance.onsets
        self.nuisance.hold_phase_s = profile_hold_phase(self.ev, self.knobs(self.base, self.chosen))

    # ------------------------------------------------------------------ scoring
    def score(self, z: np.ndarray) -> tuple[float, float, float]:
        """(train cost, held-out cost, effective training count) of whitened residuals (n, C)."""
        s, h = self.ev.costs(z)
        return s, h, effective_count(z[self.ev.train])

    # ------------------------------------------------------------------ one least-squares fit
    def fit(self, effect: Effect, start: dict[str, float], lock: Lockstep, nuisance: dict[str, float] | None = None):
        """Fit ``effect`` plus the base and the smooth accepted effects, from ``start``.

        ``nuisance``: the recording's traits as re-fitted at ``start`` (for an
        effect with ``nuisances``), held through the fit.

        The accepted effects are re-fitted too (their columns cost little in a
        batched simulation), so a new effect is not accepted merely to patch an
        earlier fit.  Returns (values, base, z, r0, jac, names, refitted chosen).
        """
        owners = [(effect.name, p) for p in effect.params]
        owners += [(name, p) for name in self.chosen if LIBRARY[name].smooth for p in LIBRARY[name].params]
        owners += [("base", p) for p in self.base_params]
        names = [p.name for _, p in owners]
        lo = np.array([p.low for _, p in owners])
        hi = np.array([p.high for _, p in owners])
        step = np.array([p.fd_step for _, p in owners])
        x0 = np.array([start.get(p.name, p.null) if o == effect.name else
                       (self.base[p.name] if o == "base" else self.chosen[o][p.name]) for o, p in owners], dtype=float)
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
                r0 = z[0][train].ravel()
                jac = np.stack([(z[j + 1][train].ravel() - r0) / hs[j] for j in range(len(x))], axis=1)
                cache[key] = (r0, jac, z[0])
            return cache[key]

        res = least_squares(lambda x: evaluate(x)[0], x0, jac=lambda x: evaluate(x)[1], bounds=(lo, hi),
                            loss="soft_l1", f_scale=F_SCALE, x_scale=step, max_nfev=MAX_NFEV * effect.effort,
                            method="trf", ftol=1e-4, xtol=1e-3)
        r0, jac, z = evaluate(res.x)
        values, base, chosen = split(res.x)
        return values, base, z, r0, jac, names, chosen

    # ------------------------------------------------------------------ tests
    def wald(self, effect: Effect, values, names, r0, jac, n_eff) -> tuple[dict[str, float], bool]:
        """95 % half-widths, and whether the tested parameters' confidence region excludes the null."""
        n, p = jac.shape
        w = 1.0 / np.sqrt(1.0 + (r0 / F_SCALE) ** 2)  # soft-L1 IRLS weights: the robust fit's curvature
        jw = jac * w[:, None] ** 0.5
        s2 = float(np.sum((r0 * w**0.5) ** 2)) / max(n - p, 1)
        cov = np.linalg.pinv(jw.T @ jw) * s2 * (n / max(n_eff, 1.0))
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        unc = {name: float(1.96 * sd[i]) for i, name in enumerate(names)}
        idx = [names.index(t) for t in effect.tested]
        d = np.array([values[t] - effect.param(t).null for t in effect.tested])
        sub = cov[np.ix_(idx, idx)]
        stat = float(d @ np.linalg.pinv(sub) @ d) if np.all(np.isfinite(sub)) else 0.0
        return unc, stat > chi2.ppf(0.95, len(idx))

    # ------------------------------------------------------------------ a round
    def round(self, current_z: np.ndarray, remaining: list[str], round_no: int) -> tuple[list[Candidate], np.ndarray]:
        """Screen, fit and test every remaining effect against the current model (base re-fitted first in round 1).

        Returns the candidates and the current model's residual (changed if the base re-fit helped).
        """
        ev = self.ev
        s0, h0, _ = self.score(current_z)
        grid_reqs, owners = [], []
        profiled: dict[tuple, dict[str, float]] = {}  # (effect, grid point) -> its re-fitted recording traits
        for name in remaining:
            e = LIBRARY[name]
            for combo in itertools.product(*(p.grid for p in e.params)):
                vals = dict(zip([p.name for p in e.params], combo))
                req = self.knobs(self.base, {**self.chosen, name: vals})
                prof: dict[str, float] = {}
                for nuisance in e.nuisances:  # re-fitted for this grid point (sensing only: no new simulation)
                    prof.update(PROFILERS[nuisance](ev, req))
                req.update(prof)
                profiled[(name, combo)] = prof
                grid_reqs.append(req)
                owners.append((name, vals))
        self.progress(f"round {round_no}: screening {len(remaining)} effects on {len(grid_reqs)} grid points")
        zs = ev.whiten(ev.run(grid_reqs))
        best: dict[str, tuple[float, dict, np.ndarray, list]] = {}
        for (name, vals), z in zip(owners, zs):
            s, _ = ev.costs(z)
            entry = best.setdefault(name, (np.inf, {}, None, []))
            entry[3].append((vals, s))
            if s < entry[0]:
                best[name] = (s, vals, z, entry[3])
        ranked = sorted((b[0], n) for n, b in best.items() if b[0] < s0)
        smooth = [n for _, n in ranked if LIBRARY[n].smooth][:FIT_TOP]
        rough = [n for _, n in ranked if not LIBRARY[n].smooth][:1]
        if smooth:
            self.progress(f"round {round_no}: fitting {', '.join(smooth)} by least squares")
        lock = Lockstep(ev.run)
        # each effect from its best grid point; effects with starts > 1 also from their next-best ones
        # (all fits share each batched simulation, so extra starts cost columns, not passes)
        starts = [(n, vals) for n in smooth
                  for vals, _ in sorted(best[n][3], key=lambda e: e[1])[:LIBRARY[n].starts]]
        jobs = [lambda n=n, v=v: self.fit(LIBRARY[n], v, lock, profiled[(n, tuple(v.values()))]) for n, v in starts]
        if round_no == 1:  # the shared base parameters alone, in the same batches
            jobs.append(lambda: self.fit(_BASE_ONLY, {}, lock))
        all_fits = lock.map(jobs)
        if round_no == 1:
            _, base, zb, _, _, _, _ = all_fits.pop()
            sb, hb, _ = self.score(zb)
            if sb < s0:
                self.base, current_z, s0, h0 = base, zb, sb, hb
                self.progress("round 1: base re-fit " + ", ".join(f"{k}={v:.4g}" for k, v in base.items()))
        fits = []
        for name in smooth:  # the best start of each effect (lowest training cost)
            mine = [f for (n, _), f in zip(starts, all_fits) if n == name]
            fits.append(min(mine, key=lambda f: self.score(f[2])[0]))
        out: list[Candidate] = []
        for name, (values, base, z, r0, jac, names, chosen) in zip(smooth, fits):
            e = LIBRARY[name]
            s1, h1, n_eff = self.score(z)
            dbic = n_eff * np.log(s0 / s1) - len(e.params) * np.log(n_eff) if s1 > 0 else np.inf
            unc, excluded = self.wald(e, {**values, **base}, names, r0, jac, n_eff)
            c = self._judge(name, values, base, unc, s1, h1, dbic, n_eff, excluded, h0, s0)
            c.refitted = chosen
            out.append(c)
        for name in rough:
            e = LIBRARY[name]
            s1, vals, z, table = best[name]
            _, h1, n_eff = self.score(z)
            dbic = n_eff * np.log(s0 / s1) - len(e.params) * np.log(n_eff)
            # profile over the grid: chi2-like scale from the best point, corrected for autocorrelation
            scale = n_eff / max(s1, 1e-12)
            null_cost = next((s for v, s in table if all(abs(v[k] - e.param(k).null) < 1e-9 for k in e.tested)), s0)
            excluded = (null_cost - s1) * scale > chi2.ppf(0.95, len(e.tested))
            unc = {}
            for pname in vals:
                inside = [v[pname] for v, s in table if (s - s1) * scale <= chi2.ppf(0.95, 1)]
                unc[pname] = float((max(inside) - min(inside)) / 2.0) if inside else float("nan")
            out.append(self._judge(name, vals, dict(self.base), unc, s1, h1, dbic, n_eff, excluded, h0, s0))
        return out, current_z

    def _judge(self, name, values, base, unc, s1, h1, dbic, n_eff, excluded, h0, s0) -> Candidate:
        c = Candidate(name, {k: float(v) for k, v in values.items()}, {k: float(v) for k, v in base.items()}, unc,
                      s1, h1, float(dbic), float(n_eff), bool(excluded), share=float(1.0 - s1 / s0) if s0 > 0 else 0.0)
        c.refitted = {**{k: dict(v) for k, v in self.chosen.items()}, name: c.values}
        if not c.share >= MIN_SHARE:
            c.reasons.append(f"removes only {100 * c.share:.1f} % of the cost (< {100 * MIN_SHARE:g} %)")
        if not dbic > BIC_MARGIN:
            c.reasons.append(f"BIC improves by {dbic:.1f} <= {BIC_MARGIN:g}")
        if not h1 < h0:
            c.reasons.append(f"held-out cost does not fall ({h1:.1f} vs {h0:.1f})")
        if not excluded:
            c.reasons.append("confidence region includes the null")
        return c


def residual_structure(residual: np.ndarray) -> tuple[float, float]:
    """(structured RMS, white-noise RMS) of one channel's residual (raw units), both estimated from it alone.

    The white part is estimated from first differences (for independent
    noise ``var(diff) = 2 var``), robustly: the largest 1 % of differences
    (timing glitches) are dropped.  The structured part is the rest of the
    residual's variance.
    """
    r = np.asarray(residual, dtype=float)
    if len(r) < 3:
        return 0.0, 0.0
    white = trimmed_rms(np.diff(r)) / np.sqrt(2.0)
    total = trimmed_rms(r)
    return float(np.sqrt(max(total**2 - white**2, 0.0))), float(white)


def diagnose(trace: Trace, params: ServoParams = ServoParams(), progress: Callable[[str], None] | None = None,
             effects: list[str] | None = None) -> Diagnosis:
    """Run the whole workflow on a measured trace (``effects``: restrict the library, default all)."""
    t0 = time.perf_counter()
    say = progress or (lambda msg: log.info(msg))
    srch = _Search(trace, params, say)
    ev = srch.ev
    say(f"{len(trace)} rows, {ev.schedule.n_steps} model steps; channel sd "
        + ", ".join(f"{ch.replace('present_', '')} {ev.scales[ch]:.2f}" for ch in ev.channels))
    srch.fit_nuisance()
    say("recording: " + srch.nuisance.describe(ev.schedule.step_s, ev.schedule.nominal_onsets()))
    z_before = ev.whiten(ev.run([srch.knobs(srch.base, {})]))[0]
    sim_before = ev.measured + z_before * ev.sd
    z = z_before
    remaining = list(effects or LIBRARY)
    not_offered = {}
    if not ev.schedule.onsets_known:
        not_offered = {n: "the trace does not record when commands were sent (no command_t), so this effect cannot "
                          "be told from when they took effect, which the base fit estimates"
                       for n in remaining if LIBRARY[n].needs_command_times}
        remaining = [n for n in remaining if n not in not_offered]
        if not_offered:
            say(f"not offered: {', '.join(not_offered)} (the trace does not record when commands were sent)")
    rounds: list[list[Candidate]] = []
    accepted: list[Candidate] = []
    for round_no in range(1, MAX_ROUNDS + 1):
        if not remaining:
            break
        cands, z = srch.round(z, remaining, round_no)
        rounds.append(cands)
        passing = [c for c in cands if c.passed()]
        for c in sorted(cands, key=lambda c: -c.delta_bic):
            say(f"  {c.effect}: dBIC {c.delta_bic:.1f}, "
                + ("passes" if c.passed() else "; ".join(c.reasons)))
        if not passing:
            break
        win = max(passing, key=lambda c: c.delta_bic)
        win.accepted = True
        accepted.append(win)
        srch.chosen = {k: dict(v) for k, v in win.refitted.items()}
        srch.base = win.base
        for c in accepted[:-1]:
            c.values = dict(srch.chosen[c.effect])
        remaining.remove(win.effect)
        srch.fit_nuisance()
        z = ev.whiten(ev.run([srch.knobs(srch.base, srch.chosen)]))[0]
        say(f"round {round_no}: accepted {win.effect} " + ", ".join(f"{k}={v:.4g}" for k, v in win.values.items()))
    sim_after = ev.measured + z * ev.sd
    as_dict = lambda arr: {ch: np.rint(arr[:, i]).astype(np.int64) for i, ch in enumerate(ev.channels)}  # noqa: E731
    rms = {ch: trimmed_rms(z[:, i]) for i, ch in enumerate(ev.channels)}
    worst = max(rms, key=rms.get)
    structured, white = residual_structure(z[:, 0] * ev.sd[0])  # position, raw units
    by_structure = structured > max(STRUCTURE_RATIO * white, STRUCTURE_FLOOR_UNITS)
    by_size = rms[worst] > UNEXPLAINED_RMS
    unexplained = bool(by_structure or by_size)
    detail = ""
    if unexplained:
        ch = "present_position" if by_structure else worst
        per_phase = {PHASES[p]: trimmed_rms(z[ev.phases == p, ev.channels.index(ch)]) for p in np.unique(ev.phases)}
        where = max(per_phase, key=per_phase.get)
        if by_structure:
            detail = (f"present_position keeps a time-correlated residual of {structured:.2f} units RMS after the "
                      f"named effects, {structured / max(white, 1e-9):.1f} x the row-to-row noise "
                      f"({white:.2f} units, from the residual itself)")
        else:
            detail = f"{ch} residual is {rms[ch]:.1f} sd after the named effects (noise level is about 1)"
        detail += (f"; largest while {where.replace('_', ' ')} ({per_phase[where]:.1f} sd): "
                   "no library effect explains it")
    for c in accepted:
        c.confidence = "tentative" if unexplained and c.share < TENTATIVE_SHARE else "confident"
    measured_trace = trace
    return Diagnosis(
        accepted=accepted, rounds=rounds, base=srch.base, knobs=srch.knobs(srch.base, srch.chosen),
        channels=ev.channels, scales=ev.scales, phases=ev.phases,
        sim_before=as_dict(sim_before), sim_after=as_dict(sim_after),
        gaps_before=gaps(measured_trace, as_dict(sim_before), ev.phases),
        gaps_after=gaps(measured_trace, as_dict(sim_after), ev.phases),
        unexplained=unexplained, unexplained_detail=detail, residual_rms_sd=rms,
        seconds=time.perf_counter() - t0, simulations=ev.simulations, nuisance=srch.nuisance, not_offered=not_offered,
    )

