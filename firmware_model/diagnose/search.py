"""Forward selection over the effect library: screen, fit, test, accept, repeat.

Why it exists: it turns "the model is off" into "this effect, with these
values, explains it", with tests that keep it from naming noise.

Before the first round and after each accepted effect, the recording's
traits (:mod:`.nuisance`: the phase of the speed/load hold, and when each
command took effect where the trace does not record it) are re-fitted to the
current model.  They are part of the base model, never candidates; effects
that only a recorded command time can tell from them (``delay``) are not
offered on traces without one (:attr:`Diagnosis.not_offered`).

Each round (:func:`_round`) has two halves, each in its own module:

1. **Selection** (:mod:`.selection`): screen every remaining effect on its
   coarse grid, fit the most promising by least squares (in round 1 the
   shared base parameters alone too, kept if they lower the cost), keep the
   grid optimum of grid-only effects.
2. **Verdict** (:mod:`.verdict`): test each fit against the current model
   (cost share, BIC, held-out cost, confidence region excluding the null);
   the passing candidate with the largest BIC gain is accepted, the gains
   compared on one sample count, the current model's (:func:`_ranking_bic`).

It stops when no candidate passes (or after :data:`MAX_ROUNDS`), then the
verdict compares the final model with the measurement: if a residual
remains that is not noise it says so (an unexplained residual) and effects
that explained only a small share are marked tentative.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..params import ServoParams
from ..xseries.physics import XPhysicsParams
from .metrics import gaps
from .nuisance import Nuisance
from .selection import Score, Selection, shortlist
from .trace import Trace
from .verdict import (
    BIC_MARGIN,
    POT_NOISE_MAX_RAD,
    STRUCTURE_FLOOR_UNITS,
    STRUCTURE_RATIO,
    TENTATIVE_SHARE,
    UNEXPLAINED_RMS,
    Candidate,
    confidence,
    delta_bic,
    judge,
    residual_structure,
    residual_verdict,
)

__all__ = ["Candidate", "Diagnosis", "diagnose", "BIC_MARGIN", "UNEXPLAINED_RMS", "TENTATIVE_SHARE",
           "STRUCTURE_RATIO", "STRUCTURE_FLOOR_UNITS", "residual_structure", "MAX_ROUNDS"]

log = logging.getLogger(__name__)

#: At most this many effects are named.
MAX_ROUNDS = 4


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
    #: The servo family the trace is from (:mod:`.families`), whose library named the effects.
    servo: str = "ax"
    #: The starting parameters of the model (ServoParams, or XPhysicsParams for an X-series servo).
    start: object = None
    #: The recording's fitted traits in one line.
    recording: str = ""

    @property
    def named(self) -> list[str]:
        """Identifiers of the accepted effects, in order."""
        return [c.effect for c in self.accepted]

    @property
    def confident(self) -> list[str]:
        """Identifiers of the accepted effects not marked tentative."""
        return [c.effect for c in self.accepted if c.confidence == "confident"]


def _ranking_bic(sel: Selection, c: Candidate, current_cost: float, n_eff: float) -> float:
    """The BIC gain ``c`` is ranked by among the passing candidates: on the current model's sample count ``n_eff``.

    Each candidate's own test counts its own residual's independent samples
    (:func:`.verdict.delta_bic`), and a better fit leaves a smaller, smoother
    residual with fewer of them: ranked by their own counts, a fit that
    removed 82 % of the cost lost to one that removed 65 % (an inertia twice
    the model's, read like a Wizard export, named as gear play).  Compared with
    each other, they are compared on one sample.
    """
    return float(delta_bic(len(sel.library[c.effect].params), current_cost, c.cost_train, n_eff))


def _round(sel: Selection, current_z: np.ndarray, remaining: list[str], round_no: int
           ) -> tuple[list[Candidate], np.ndarray, Score]:
    """Screen, fit and judge every remaining effect against the current model (base re-fitted too in round 1).

    Returns the candidates, the current model's residual (changed if the base re-fit helped) and its score.
    """
    current = sel.score(current_z)
    screened = sel.screen(remaining, round_no)
    smooth, rough = shortlist(screened, current.cost_train, sel.library)
    if smooth:
        sel.progress(f"round {round_no}: fitting {', '.join(smooth)} by least squares")
    fits, base_fit = sel.fit_shortlist(screened, smooth, with_base=round_no == 1)
    if base_fit is not None and base_fit.score.cost_train < current.cost_train:
        # the candidates are judged against the better base, and grid-only ones evaluated with it
        sel.base, current_z, current = base_fit.base, base_fit.z, base_fit.score
        sel.progress("round 1: base re-fit " + ", ".join(f"{k}={v:.4g}" for k, v in sel.base.items()))
    fits += [sel.grid_fit(screened[name]) for name in rough]
    return [judge(sel.library[f.effect], f, current) for f in fits], current_z, current


def diagnose(trace: Trace, params: ServoParams | XPhysicsParams | None = None,
             progress: Callable[[str], None] | None = None, effects: list[str] | None = None) -> Diagnosis:
    """Run the whole workflow on a measured trace (``effects``: restrict the library, default all).

    ``params``: the model to start from (default: the AX-12's defaults; for an X-series trace, the physics
    its metadata's data sheet gives).  The simulator and the effect library are the trace's servo
    family's (:mod:`.families`).
    """
    t0 = time.perf_counter()
    say = progress or (lambda msg: log.info(msg))
    sel = Selection(trace, params, say)
    ev = sel.ev
    say(f"{len(trace)} rows, {ev.schedule.n_steps} model steps; channel sd "
        + ", ".join(f"{ch.replace('present_', '')} {ev.scales[ch]:.2f}" for ch in ev.channels))
    sel.fit_nuisance()
    say("recording: " + sel.nuisance.describe(ev.schedule.step_s, ev.schedule.nominal_onsets()))
    z_before = sel.residual()
    sim_before = ev.measured + z_before * ev.sd
    z = z_before
    library = sel.library
    unknown = [n for n in effects or () if n not in library]
    if unknown:
        raise ValueError(f"effect(s) {', '.join(unknown)} not in this servo's library ({', '.join(library)})")
    remaining = list(effects or library)
    not_offered = {}
    if not ev.schedule.onsets_known:
        not_offered = {n: "the trace does not record when commands were sent (no command_t), so this effect cannot "
                          "be told from when they took effect, which the base fit estimates"
                       for n in remaining if library[n].needs_command_times}
        remaining = [n for n in remaining if n not in not_offered]
        if not_offered:
            say(f"not offered: {', '.join(not_offered)} (the trace does not record when commands were sent)")
    rounds: list[list[Candidate]] = []
    accepted: list[Candidate] = []
    for round_no in range(1, MAX_ROUNDS + 1):
        if not remaining:
            break
        cands, z, current = _round(sel, z, remaining, round_no)
        rounds.append(cands)
        passing = [c for c in cands if c.passed()]
        for c in sorted(cands, key=lambda c: -c.delta_bic):
            say(f"  {c.effect}: dBIC {c.delta_bic:.1f}, "
                + ("passes" if c.passed() else "; ".join(c.reasons)))
        if not passing:
            break
        win = max(passing, key=lambda c: _ranking_bic(sel, c, current.cost_train, current.n_eff))
        win.accepted = True
        accepted.append(win)
        sel.chosen = {k: dict(v) for k, v in win.refitted.items()}
        sel.base = win.base
        for c in accepted[:-1]:
            _refitted(c, sel.chosen[c.effect], win, sel.library[c.effect])
        remaining.remove(win.effect)
        sel.fit_nuisance()
        z = sel.residual()
        say(f"round {round_no}: accepted {win.effect} " + ", ".join(f"{k}={v:.4g}" for k, v in win.values.items()))
    sim_after = ev.measured + z * ev.sd
    as_dict = lambda arr: {ch: np.rint(arr[:, i]).astype(np.int64) for i, ch in enumerate(ev.channels)}  # noqa: E731
    residual = residual_verdict(z, ev.channels, ev.sd, ev.phases,
                                pot_noise_max=POT_NOISE_MAX_RAD / sel.family.position_unit_rad)
    for c in accepted:
        c.confidence = confidence(c.share, residual.unexplained)
    return Diagnosis(
        accepted=accepted, rounds=rounds, base=sel.base, knobs=sel.knobs(sel.base, sel.chosen),
        channels=ev.channels, scales=ev.scales, phases=ev.phases,
        sim_before=as_dict(sim_before), sim_after=as_dict(sim_after),
        gaps_before=gaps(trace, as_dict(sim_before), ev.phases),
        gaps_after=gaps(trace, as_dict(sim_after), ev.phases),
        unexplained=residual.unexplained, unexplained_detail=residual.detail, residual_rms_sd=residual.rms_sd,
        seconds=time.perf_counter() - t0, simulations=ev.simulations, nuisance=sel.nuisance, not_offered=not_offered,
        servo=trace.servo, start=sel.params,
        recording=sel.nuisance.describe(ev.schedule.step_s, ev.schedule.nominal_onsets()),
    )


def _refitted(c: Candidate, values: dict[str, float], win: Candidate, effect) -> None:
    """An effect accepted earlier, re-fitted with a later one: its values, half-widths and null test from that joint
    fit (the first round's interval beside the later value described another fit: an interval that held the null
    was shown "null excluded"); NaN where the joint fit gives no half-width (a grid-only winner)."""
    c.values = dict(values)
    c.uncertainty = {k: float(win.uncertainty.get(k, float("nan"))) for k in c.values}
    widths = [c.uncertainty.get(t, float("nan")) for t in effect.tested]
    if all(np.isfinite(widths)):
        c.null_excluded = any(abs(c.values[t] - effect.param(t).null) > w for t, w in zip(effect.tested, widths))
