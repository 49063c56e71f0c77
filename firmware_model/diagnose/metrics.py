"""Where measurement and simulation disagree: channel scales, robust cost, gaps, effective sample count.

Why it exists: the search compares models by one number, so the channels
must be put on one scale (each divided by its noise or effective
quantisation) and the samples counted honestly (a model error is smooth in
time, and the 10 Hz held registers repeat each value ten times at 100 Hz,
so 2000 rows are far fewer independent observations).

Effective quantisation, why these floors: position reads in whole units
(sd ``1/sqrt(12)``); Present Speed is a position difference over the hold
period, so one position unit is ``unit / 0.1 s`` = 4.4 speed units; Present
Load is the compliance drive, which moves by ``1023 (1 - punch) / 32`` = 31
load units per position unit of error.  Measured noise (from rows at rest)
adds in quadrature.
"""

from __future__ import annotations

import numpy as np

from .phases import PHASES
from .trace import Trace

__all__ = ["CHANNELS", "F_SCALE", "channel_scales", "robust_cost", "effective_count", "gaps", "QUANT_STEP", "trimmed_rms"]

CHANNELS = ("present_position", "present_speed", "present_load", "present_velocity", "present_current", "present_pwm")
#: Effective quantisation step of each channel, raw units (see the module docstring).  X-series servos read
#: every register fresh each time (no hold), so their channels' steps are one register unit each.
QUANT_STEP = {"present_position": 1.0, "present_speed": 4.4, "present_load": 31.0, "present_velocity": 1.0,
              "present_current": 1.0, "present_pwm": 1.0}
#: Robust loss scale, in channel sd: residuals beyond it count linearly (soft L1), so glitches do not dominate.
F_SCALE = 3.0


def channel_scales(trace: Trace, at_rest: np.ndarray) -> dict[str, float]:
    """sd per measured channel: quantisation plus the noise seen in rows at rest (robust first differences)."""
    out = {}
    for ch in CHANNELS:
        if not trace.has(ch):
            continue
        quant = QUANT_STEP[ch] / np.sqrt(12.0)
        x = trace[ch].astype(float)
        # deviation from each run at rest's own median (held channels repeat values, so no differences)
        runs = np.cumsum(np.diff(np.concatenate([[0], at_rest.astype(int)])) != 0)
        dev = [x[(runs == r) & at_rest] - np.median(x[(runs == r) & at_rest]) for r in np.unique(runs[at_rest])]
        dev = np.concatenate(dev) if dev else np.zeros(0)
        noise = float(np.sqrt(np.mean(dev**2))) if len(dev) > 10 else 0.0
        out[ch] = float(np.hypot(quant, noise))
    return out


def robust_cost(z: np.ndarray) -> np.ndarray:
    """Soft-L1 cost of whitened residuals, elementwise (``r**2`` for small ``r``), as scipy's least_squares uses it."""
    u = (z / F_SCALE) ** 2
    return F_SCALE**2 * 2.0 * (np.sqrt(1.0 + u) - 1.0)


def effective_count(z: np.ndarray, weights: np.ndarray | None = None) -> float:
    """Samples corrected for autocorrelation, summed over channels: ``n (1 - rho) / (1 + rho)`` (lag-1 rho).

    ``z`` is (n, C) whitened residuals of one model on contiguous rows; ``weights`` (n,), each row's weight
    in the cost (default 1): ``n`` is their sum, since a row of weight ``w`` counts as ``w`` readings (a long
    rest counted as a fixed stretch of readings, :func:`.evaluate.rest_weights`).  Counting such rows as one
    each would credit a single step's hundreds of rows at rest, which tell nothing of its motion, as samples.
    """
    n = float(len(z)) if weights is None else float(np.sum(weights))
    total = 0.0
    for c in range(z.shape[1]):
        r = z[:, c] - z[:, c].mean()
        denom = float(np.dot(r, r))
        rho = float(np.dot(r[1:], r[:-1]) / denom) if denom > 0 else 0.0
        rho = min(max(rho, 0.0), 0.98)
        total += n * (1.0 - rho) / (1.0 + rho)
    return max(total, 2.0)


def gaps(measured: Trace, simulated: dict[str, np.ndarray], phases: np.ndarray) -> dict[str, dict]:
    """Per channel: RMS and peak error (raw units) overall and RMS per motion phase."""
    out = {}
    for ch in CHANNELS:
        if not measured.has(ch):
            continue
        e = simulated[ch].astype(float) - measured[ch].astype(float)
        per_phase = {}
        for i, name in enumerate(PHASES):
            sel = phases == i
            if sel.any():
                per_phase[name] = float(np.sqrt(np.mean(e[sel] ** 2)))
        out[ch] = {"rms": float(np.sqrt(np.mean(e**2))), "peak": float(np.max(np.abs(e))), "per_phase": per_phase}
    return out


def trimmed_rms(x: np.ndarray, keep: float = 0.99) -> float:
    """RMS of the smallest ``keep`` share of ``|x|``: one timing glitch must not make a trace look unexplained."""
    a = np.sort(np.abs(np.asarray(x, dtype=float)))
    a = a[: max(1, int(np.ceil(keep * len(a))))]
    return float(np.sqrt(np.mean(a**2)))
