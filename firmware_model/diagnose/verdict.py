"""Verdict: the statistical tests and the rules that turn fits into named, tentative or rejected effects.

Why it is apart from the selection (:mod:`.selection`): the rules that keep
the workflow from naming noise should be readable, and testable, on their
own, from the numbers a fit leaves (:class:`.selection.Fit`), without a
trace or a simulation.

**A candidate passes** (:func:`judge`) only if all hold:

* it removes at least :data:`MIN_SHARE` of the current model's training cost
  (practical, not only statistical, significance);
* the BIC improves by more than :data:`BIC_MARGIN` (:func:`delta_bic`, with
  the autocorrelation-corrected sample count);
* the cost on the held-out blocks falls;
* the 95 % confidence region of its ``tested`` parameters excludes their
  null values: a Wald test from the fit's Jacobian, inflated for
  autocorrelation (:func:`wald`), or a profile over the grid for grid-only
  effects (:func:`grid_profile`).

The search names the passing candidate with the largest BIC gain, one per
round.  **After the last round** the final model is compared with the
measurement (:func:`residual_verdict`): if a residual remains that is not
noise the verdict says so (an unexplained residual) and effects that
explained only a small share are marked tentative (:func:`confidence`).
"Not noise" is judged from the data alone, two ways:

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
  channel's noise measured at rest, above :data:`UNEXPLAINED_RMS`.  For
  position that noise is taken as at most :data:`POT_NOISE_MAX_RAD`, the most
  a pot reads at rest: the rows "at rest" are those the model has at rest,
  and where the servo moved in them (a trace logged a row in 20 with its
  commands' onsets a sample off) their spread is the model's miss, not noise.
  Whitened by it, a position residual of 35 units RMS read as 1 sd and the
  trace was called explained; measured at rest, real AX-12A steps spread
  0.4-0.9 units, live recordings 0.3 and synthetic traces 0.8-0.9, so the
  bound never binds on them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from .effects import Effect
from .metrics import F_SCALE, trimmed_rms
from .phases import PHASES
from .selection import Fit, Linearisation, Score

__all__ = ["Candidate", "ResidualVerdict", "judge", "rejections", "delta_bic", "wald", "grid_profile", "residual_structure",
           "residual_verdict", "confidence", "BIC_MARGIN", "MIN_SHARE", "UNEXPLAINED_RMS", "STRUCTURE_RATIO",
           "STRUCTURE_FLOOR_UNITS", "TENTATIVE_SHARE", "POT_NOISE_MAX_RAD"]

#: BIC must improve by more than this (the usual "strong evidence" threshold).
BIC_MARGIN = 10.0
#: A candidate must also remove this share of the current cost (practical, not only statistical, significance).
MIN_SHARE = 0.05
#: Whitened residual RMS (in channel sd) above which a channel counts as unexplained.
UNEXPLAINED_RMS = 2.5
#: Structured position residual above this many times the white-noise level (both from the residual) is unexplained.
STRUCTURE_RATIO = 1.5
#: ... and above this many position units RMS (one quantisation step).
STRUCTURE_FLOOR_UNITS = 1.0
#: The most a position sensor reads at rest, rad (two AX-12 position units, 0.59 deg): the position noise the size
#: test whitens by is at most this (module docstring).
POT_NOISE_MAX_RAD = 0.01
#: With an unexplained residual, an effect that removed less than this share of the cost is "tentative".
TENTATIVE_SHARE = 0.8
#: Confidence level of every interval and test here.
_LEVEL = 0.95


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
        """All acceptance tests hold."""
        return not self.reasons


def delta_bic(n_params: int, current_cost: float, cost: float, n_eff: float) -> float:
    """BIC gain of a fit with ``n_params`` more parameters whose training cost fell from ``current_cost``.

    The robust cost stands in for the residual sum of squares and ``n_eff``
    (autocorrelation-corrected) for the sample count: counting every row of a
    smooth residual as independent would make any wiggle "significant".
    """
    return n_eff * np.log(current_cost / cost) - n_params * np.log(n_eff) if cost > 0 else np.inf


def wald(effect: Effect, values: dict[str, float], linear: Linearisation, n_eff: float) -> tuple[dict[str, float], bool]:
    """95 % half-widths of every fitted parameter, and whether the tested ones' confidence region excludes the null.

    ``values``: every fitted parameter by name (the effect's and the base's).
    The covariance is the robust fit's (soft-L1) in its sandwich form (an
    M-estimator's, heteroscedasticity-consistent as White's: ``B^-1 M B^-1``,
    bread ``B = sum_i psi'(r_i) J_i J_i'``, meat ``M = sum_i psi(r_i)^2 J_i
    J_i'``), scaled by ``n / (n - p)``
    and by ``n / n_eff`` because neighbouring rows' residuals are not
    independent.  Why the sandwich: a residual's spread differs along a
    recording (a step's move misses by units where its rests miss by none), and
    the plain form, one spread for every row, credits the rows that decide a
    parameter with the rest rows' small one.  On Wizard-style steps made by the
    model with the supply off by up to 2 %, the plain form's inertia intervals
    held the bar in 3 of 9, the sandwich's in 8 of 9 (the ninth an exact fit of
    a noise-free recording, no spread at all).  With an even spread the two agree.
    """
    r0, jac, names = linear.residual, linear.jacobian, linear.names
    n, p = jac.shape
    w = 1.0 / np.sqrt(1.0 + (r0 / F_SCALE) ** 2)  # soft-L1: psi(r) = w r, psi'(r) = w**3
    psi = w * r0
    if not np.any(psi):  # an exact fit (a noise-free recording): no spread, the null is excluded if the fit left it
        d = np.array([values[t] - effect.param(t).null for t in effect.tested])
        return {name: 0.0 for name in names}, bool(np.any(d != 0.0))
    bread = np.linalg.pinv((jac * (w**3)[:, None]).T @ jac)
    meat = (jac * (psi**2)[:, None]).T @ jac
    cov = bread @ meat @ bread * (n / max(n - p, 1)) * (n / max(n_eff, 1.0))
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    unc = {name: float(1.96 * sd[i]) for i, name in enumerate(names)}
    idx = [names.index(t) for t in effect.tested]
    d = np.array([values[t] - effect.param(t).null for t in effect.tested])
    sub = cov[np.ix_(idx, idx)]
    stat = float(d @ np.linalg.pinv(sub) @ d) if np.all(np.isfinite(sub)) else 0.0
    return unc, bool(stat > chi2.ppf(_LEVEL, len(idx)))


def grid_profile(effect: Effect, values: dict[str, float], grid: list[tuple[dict[str, float], float]],
                 cost: float, n_eff: float, current_cost: float) -> tuple[dict[str, float], bool]:
    """Half-widths and the null test of a grid-only effect, from the cost profile over its grid.

    A cost difference times ``n_eff / cost`` is read as chi-squared (the
    best point's cost as the noise scale, corrected for autocorrelation).
    The null's cost is its grid point's, or ``current_cost`` (the model
    without the effect) when the null is not on the grid.
    """
    scale = n_eff / max(cost, 1e-12)
    null_cost = next((s for v, s in grid if all(abs(v[k] - effect.param(k).null) < 1e-9 for k in effect.tested)),
                     current_cost)
    excluded = (null_cost - cost) * scale > chi2.ppf(_LEVEL, len(effect.tested))
    unc = {}
    for pname in values:
        inside = [v[pname] for v, s in grid if (s - cost) * scale <= chi2.ppf(_LEVEL, 1)]
        unc[pname] = float((max(inside) - min(inside)) / 2.0) if inside else float("nan")
    return unc, bool(excluded)


def judge(effect: Effect, fit: Fit, current: Score) -> Candidate:
    """Test ``fit`` (of ``effect``) against the current model's ``current`` score; failed tests become reasons."""
    s0, h0 = current.cost_train, current.cost_held
    s1, h1, n_eff = fit.score.cost_train, fit.score.cost_held, fit.score.n_eff
    dbic = delta_bic(len(effect.params), s0, s1, n_eff)
    if fit.linear is not None:
        unc, excluded = wald(effect, {**fit.values, **fit.base}, fit.linear, n_eff)
    else:
        unc, excluded = grid_profile(effect, fit.values, fit.grid, s1, n_eff, s0)
    c = Candidate(fit.effect, {k: float(v) for k, v in fit.values.items()}, {k: float(v) for k, v in fit.base.items()},
                  unc, s1, h1, float(dbic), float(n_eff), bool(excluded), refitted=fit.refitted,
                  share=float(1.0 - s1 / s0) if s0 > 0 else 0.0)
    c.reasons = rejections(c, h0)
    return c


def rejections(c: Candidate, current_held: float) -> list[str]:
    """Why ``c`` fails the acceptance rule (empty: it passes); ``current_held`` is the current model's held-out cost."""
    out = []
    if c.cost_train == 0.0:  # through every reading (a few rows): no spread to judge it by, its dBIC infinite
        out.append("fits every reading exactly: too few readings to judge it by")
    if not c.share >= MIN_SHARE:
        out.append(f"removes only {100 * c.share:.1f} % of the cost (< {100 * MIN_SHARE:g} %)")
    if not c.delta_bic > BIC_MARGIN:
        out.append(f"BIC improves by {c.delta_bic:.1f} <= {BIC_MARGIN:g}")
    if not c.cost_held < current_held:
        out.append(f"held-out cost does not fall ({c.cost_held:.1f} vs {current_held:.1f})")
    if not c.null_excluded:
        out.append("confidence region includes the null")
    return out


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


@dataclass(frozen=True)
class ResidualVerdict:
    """Whether the final model leaves a residual that is not noise, and where."""

    unexplained: bool
    #: One sentence for the report ("" when explained).
    detail: str
    #: Trimmed RMS of each channel's whitened residual (channel sd).
    rms_sd: dict[str, float]


def residual_verdict(z: np.ndarray, channels: list[str], sd: np.ndarray, phases: np.ndarray,
                     pot_noise_max: float | None = None) -> ResidualVerdict:
    """Judge the final whitened residual ``z`` (n, C; position first) by structure and by size (module docstring).

    ``pot_noise_max``: the most the position sensor reads at rest, in position units (:data:`POT_NOISE_MAX_RAD`
    in the trace's units); the size test whitens position by no more than that.
    """
    rms = {ch: trimmed_rms(z[:, i]) for i, ch in enumerate(channels)}
    size = dict(rms)
    noisy_rest = pot_noise_max is not None and sd[0] > pot_noise_max
    if noisy_rest:
        size[channels[0]] = rms[channels[0]] * sd[0] / pot_noise_max
    worst = max(size, key=size.get)
    structured, white = residual_structure(z[:, 0] * sd[0])  # position, raw units
    by_structure = structured > max(STRUCTURE_RATIO * white, STRUCTURE_FLOOR_UNITS)
    by_size = size[worst] > UNEXPLAINED_RMS
    unexplained = bool(by_structure or by_size)
    detail = ""
    if unexplained:
        ch = "present_position" if by_structure else worst
        per_phase = {PHASES[p]: trimmed_rms(z[phases == p, channels.index(ch)]) for p in np.unique(phases)}
        where = max(per_phase, key=per_phase.get)
        # The size message's figures are whitened by the capped pot noise; the structure message's stay in sd.
        scale = sd[0] / pot_noise_max if noisy_rest and ch == channels[0] and not by_structure else 1.0
        if by_structure:
            detail = (f"present_position keeps a time-correlated residual of {structured:.2f} units RMS after the "
                      f"named effects, {structured / max(white, 1e-9):.1f} x the row-to-row noise "
                      f"({white:.2f} units, from the residual itself)")
        elif scale != 1.0:
            detail = (f"{ch} residual is {rms[ch] * sd[0]:.1f} units RMS after the named effects, {size[ch]:.1f} x the "
                      f"most a position sensor reads at rest ({pot_noise_max:.1f} units; the rows the model has at rest "
                      f"spread {sd[0]:.1f} units: the servo moved where the model rests)")
        else:
            detail = f"{ch} residual is {rms[ch]:.1f} sd after the named effects (noise level is about 1)"
        detail += (f"; largest while {where.replace('_', ' ')} ({per_phase[where] * scale:.1f} sd): "
                   "no library effect explains it")
    return ResidualVerdict(unexplained, detail, rms)


def confidence(share: float, unexplained: bool) -> str:
    """How sure a named effect is: tentative if a residual remains unexplained and it removed little of the cost.

    An effect that removed under :data:`TENTATIVE_SHARE` of the cost while
    something else stays unexplained may be standing in for what is missing.
    """
    return "tentative" if unexplained and share < TENTATIVE_SHARE else "confident"
