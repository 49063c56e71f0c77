"""What the workflow hands back: the verdict as text and JSON, report.md with plots, and parameter files.

Why it exists: the search returns numbers; a user needs a verdict, the
evidence, and files that close the loop.

The parameter file: one ``params.toml`` holds the whole fitted twin, so
``ax12emu serve --params params.toml`` serves what was fitted.  The base
table has the :class:`~firmware_model.params.ServoParams` fields, with the
effects that are base parameters folded in: ``coulomb_friction``
(``coulomb_friction_nm`` and ``static_friction_nm``), ``stribeck_friction``
(``static_friction_nm``, ``stribeck_velocity_rad_s``), ``extra_inertia``
(``load_inertia_kg_m2``), ``sample_hold`` (``sample_hold_s``; the phase is a
property of the recording, not of the servo) and the base
``gearbox_efficiency``.  Its ``[effects]`` table
(:class:`~firmware_model.params.ServoEffects`) has every other named effect,
by :data:`EFFECT_FIELDS`; the physical model reproduces each as the batched
simulator the fit ran on defines it.  A fitted value outside what a servo can
be served with (a negative delay: the reading ahead of the shaft) is pinned to
the nearest valid one, and the file says so in a comment.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..params import EFFECT_NULLS, EFFECT_RANGES, ServoEffects, ServoParams
from .families import FAMILIES
from .phases import PHASES
from .search import Diagnosis
from .trace import Trace

__all__ = ["verdict_text", "verdict_json", "json_safe", "fitted_params", "fitted_effects", "fitted_inertia", "write_outputs", "EFFECT_FIELDS",
           "BASE_FIELD_EFFECTS", "SUPPLY_SOURCES", "supply_source"]

#: Library effects folded into base ServoParams fields by :func:`fitted_params`.
BASE_FIELD_EFFECTS = ("coulomb_friction", "stribeck_friction", "extra_inertia", "sample_hold")
#: Library effects that are ServoEffects fields: effect -> {ServoEffects field: batch knob}.
EFFECT_FIELDS = {
    "backlash": {"backlash_rad": "backlash_rad"},
    "delay": {"sensing_delay_s": "delay_s"},
    "torque_saturation": {"drive_ceiling_fraction": "drive_ceiling"},
    "gravity_load": {"arm_weight_moment_nm": "arm_weight_nm"},
    "compliance_deadband": {"extra_compliance_margin_units": "extra_margin_units"},
    "sensor_offset_gain": {"position_offset_units": "position_offset_units", "position_gain": "position_gain"},
}


def fitted_effects(named: list[str], knobs: dict[str, float],
                   kept: ServoEffects = ServoEffects()) -> tuple[ServoEffects, list[str]]:
    """The ServoEffects of the ``named`` effects from the final knobs, and a note per value pinned to its range.

    ``kept``: the effects the fit started from (a twin's ``[effects]``), written again unless a named effect
    re-fitted them (the knobs then hold the total: the start plus what was added).  A value at the effect's
    null stays absent.
    """
    values, notes = dict(kept.present()), []
    for effect in named:
        for field_name, knob in EFFECT_FIELDS.get(effect, {}).items():
            value = float(knobs[knob])
            low, high = EFFECT_RANGES[field_name]
            pinned = min(max(value, low), high)
            if pinned != value:
                notes.append(f"{effect}: fitted {field_name} = {value:.6g} is outside [{low:g}, {high:g}]; served as {pinned:g}")
            values[field_name] = pinned
    return ServoEffects(**{k: v for k, v in values.items() if v != EFFECT_NULLS[k]}), notes


def fitted_params(d: Diagnosis, params: ServoParams = ServoParams(), supply_v: float | None = None) -> ServoParams:
    """ServoParams with the base re-fit and every named effect: base fields folded in, the rest as ``effects``.

    ``supply_v``: the supply the fit simulated (the trace's voltage), which a served servo must run at to read
    and move as the fit did; None keeps ``params``'.
    """
    k = d.knobs
    changes = {"gearbox_efficiency": k["gearbox_efficiency"], "coulomb_friction_nm": max(k["coulomb_friction_nm"], 0.0),
               "static_friction_nm": max(k["static_friction_nm"], k["coulomb_friction_nm"], 0.0),
               "stribeck_velocity_rad_s": k["stribeck_velocity_rad_s"]}
    changes.update(fitted_inertia(k["extra_inertia_kg_m2"], params)[0])
    if "sample_hold" in d.named:
        changes["sample_hold_s"] = round(k["hold_s"], 2)
    changes["effects"] = fitted_effects(d.named, k, params.effects)[0]
    if supply_v is not None:
        changes["supply_voltage_v"] = supply_v
    return replace(params, **changes)


def fitted_inertia(extra: float, params: ServoParams) -> tuple[dict[str, float], list[str]]:
    """The inertia fields that serve ``params``' inertia plus a fitted ``extra`` (kg m^2), and a note where the
    load alone could not take it.

    The model has one inertia, the rotor's (reflected) and the load's together.  A servo lighter than the model
    (``extra`` below minus the load) once had its load pinned at 0 and was served heavier than fitted (7 units off
    the fit's own simulation); the rest comes off the rotor's instead, so the total is the fitted one.  Only a
    total at or below zero, no servo, is pinned (the load at 0, the rotor kept).
    """
    load = params.load_inertia_kg_m2 + extra
    if load >= 0.0:
        return {"load_inertia_kg_m2": load}, []
    rotor = params.rotor_inertia_reflected_kg_m2 + load
    if rotor > 0.0:
        return ({"load_inertia_kg_m2": 0.0, "rotor_inertia_reflected_kg_m2": rotor},
                [f"extra_inertia: fitted {extra:.6g} kg m^2 is more than the load's {params.load_inertia_kg_m2:g}; "
                 f"the rest is taken off the reflected rotor inertia, served as {rotor:.6g}"])
    return ({"load_inertia_kg_m2": 0.0},
            [f"extra_inertia: fitted {extra:.6g} kg m^2 leaves no inertia (rotor {params.rotor_inertia_reflected_kg_m2:g}"
             f" + load {params.load_inertia_kg_m2:g}); served with the load at 0"])


#: How the supply a twin was fitted at is known -> params.toml's words for it ({v}: the supply, V).  A supply the
#: recording does not hold is the fit's assumption, and a twin fitted at the wrong one names the difference as an
#: effect (friction, a drive ceiling): the file says which it was, so a reader knows whether to trust it.
SUPPLY_SOURCES = {
    "recorded": "the recording's supply, {v:g} V",
    "given": "the supply given (--voltage), {v:g} V",
    "assumed": "assumed {v:g} V: the recording does not hold its supply (give it with --voltage)",
}


def supply_source(trace: Trace, source: str | None = None) -> str:
    """How the supply of ``trace``'s fit is known (a :data:`SUPPLY_SOURCES` key): ``source`` where the caller knows
    (a voltage column it made from a flag or a default is not recorded), else the trace's voltage column says."""
    return source or ("recorded" if trace.has("voltage") else "assumed")


def fitted_supply_v(trace: Trace, params: ServoParams) -> tuple[float, list[str]]:
    """The supply a served twin of ``trace`` runs at, V, and a note when it is not the one the fit simulated.

    The fit simulated the trace's voltage column row by row (``params.supply_voltage_v`` without one); the
    served servo has one supply: the recording's median, within the model's valid range.
    """
    if not trace.has("voltage"):
        return params.supply_voltage_v, []
    volts = float(np.median(trace["voltage"])) / 10.0
    notes = []
    if float(np.ptp(trace["voltage"])) > 0:
        notes.append(f"the recording's supply varies ({trace['voltage'].min() / 10:.1f}-{trace['voltage'].max() / 10:.1f} V); "
                     f"served at its median, {volts:.1f} V")
    served = min(max(volts, params.min_supply_voltage_v), params.max_supply_voltage_v)
    if served != volts:
        notes.append(f"the recording's supply {volts:.1f} V is outside the model's "
                     f"{params.min_supply_voltage_v:g}-{params.max_supply_voltage_v:g} V; served at {served:g} V")
    return served, notes


def json_safe(value):
    """``value`` with every non-finite float as None: JSON has no NaN or Infinity (an exact fit's dBIC is infinite, a
    grid-only effect's half-width NaN), and ``json.dumps`` wrote them as tokens strict parsers refuse."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


def verdict_json(d: Diagnosis) -> dict:
    """One JSON-able object: named effects with identifiers and values, RMS gap per channel before and after
    (a number no JSON can hold, an infinite dBIC or an unknown half-width, as null)."""
    return json_safe({
        "named": [{"effect": c.effect, "confidence": c.confidence, "values": c.values,
                   "uncertainty_95": {k: v for k, v in c.uncertainty.items() if k in c.values},
                   "delta_bic": c.delta_bic} for c in d.accepted],
        "base": d.base,
        "gap_rms_before": {ch: d.gaps_before[ch]["rms"] for ch in d.channels},
        "gap_rms_after": {ch: d.gaps_after[ch]["rms"] for ch in d.channels},
        "unexplained": d.unexplained,
        "unexplained_detail": d.unexplained_detail,
        "seconds": d.seconds,
    })


def verdict_text(d: Diagnosis) -> str:
    """The verdict in a few lines."""
    lines = []
    if not d.accepted:
        lines.append("No library effect is needed: the base model explains the trace." if not d.unexplained
                     else "No library effect passes the tests.")
    for c in d.accepted:
        vals = ", ".join(f"{k} = {v:.4g} ± {c.uncertainty.get(k, float('nan')):.2g}" for k, v in c.values.items())
        lines.append(f"{c.effect} ({c.confidence}): {vals}  [dBIC {c.delta_bic:.0f}]")
    if d.unexplained:
        lines.append("Unexplained residual: " + d.unexplained_detail)
    for ch in d.channels:
        lines.append(f"  {ch}: RMS gap {d.gaps_before[ch]['rms']:.2f} -> {d.gaps_after[ch]['rms']:.2f}")
    return "\n".join(lines)


def _plots(trace: Trace, d: Diagnosis, out: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = trace.t
    files = []
    fig, axes = plt.subplots(len(d.channels), 1, figsize=(11, 2.6 * len(d.channels)), sharex=True)
    for ax, ch in zip(np.atleast_1d(axes), d.channels):
        ax.plot(t, trace[ch], "k.", ms=1.5, label="measured")
        ax.plot(t, d.sim_before[ch], "-", lw=0.8, color="tab:red", label="model before")
        ax.plot(t, d.sim_after[ch], "-", lw=0.8, color="tab:blue", label="model after")
        ax.set_ylabel(ch.replace("present_", ""))
    np.atleast_1d(axes)[0].legend(loc="upper right", fontsize=8)
    np.atleast_1d(axes)[-1].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(out / "measured_vs_model.png", dpi=90)
    plt.close(fig)
    files.append("measured_vs_model.png")
    fig, axes = plt.subplots(2, 1, figsize=(11, 5), sharex=True)
    colours = plt.get_cmap("tab10")
    for ax, sim, title in zip(axes, (d.sim_before, d.sim_after), ("before", "after")):
        e = sim["present_position"] - trace["present_position"]
        for i, name in enumerate(PHASES):
            sel = d.phases == i
            if sel.any():
                ax.plot(t[sel], e[sel], ".", ms=2, color=colours(i), label=name)
        ax.set_ylabel(f"position error {title}")
    axes[0].legend(loc="upper right", fontsize=7, ncol=4)
    axes[1].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(out / "residual_by_phase.png", dpi=90)
    plt.close(fig)
    files.append("residual_by_phase.png")
    return files


def _report(trace: Trace, d: Diagnosis, files: list[str], source: str) -> str:
    md = [f"# Model discrepancy report: {source}", "", "## Verdict", "", "```", verdict_text(d), "```", ""]
    md += ["## Named effects", ""]
    if not d.accepted:
        md += ["None.", ""]
    for c in d.accepted:
        e = FAMILIES[d.servo].library[c.effect]
        md += [f"### `{c.effect}` ({c.confidence})", "", f"*Physics:* {e.physics}", "", f"*Signature:* {e.signature}", "",
               "| parameter | fitted | ± 95 % | null |", "|---|---|---|---|"]
        md += [f"| {k} | {v:.5g} | {c.uncertainty.get(k, math.nan):.2g} | {e.param(k).null:g} |" for k, v in c.values.items()]
        md += ["", f"dBIC {c.delta_bic:.1f} (n_eff {c.n_eff:.0f}), share of cost removed {100 * c.share:.0f} %", ""]
    # each candidate's fit too, accepted or not: a rejected effect's value and interval say how far the trace got
    md += ["## Candidates per round", "", "| round | effect | fitted (± 95 %) | dBIC | held-out cost | null excluded | result |",
           "|---|---|---|---|---|---|---|"]
    for r, cands in enumerate(d.rounds, 1):
        for c in cands:
            fitted = ", ".join(f"{k} {v:.4g} ± {c.uncertainty.get(k, math.nan):.2g}" for k, v in c.values.items())
            md.append(f"| {r} | {c.effect} | {fitted} | {c.delta_bic:.1f} | {c.cost_held:.0f} | {c.null_excluded} | "
                      f"{'accepted' if c.accepted else ('passes' if c.passed() else '; '.join(c.reasons))} |")
    md += ["", "## Gap per channel and phase (RMS, raw units)", "", "| channel | phase | before | after |", "|---|---|---|---|"]
    for ch in d.channels:
        md.append(f"| {ch} | all (peak {d.gaps_before[ch]['peak']:.0f} -> {d.gaps_after[ch]['peak']:.0f}) | "
                  f"{d.gaps_before[ch]['rms']:.2f} | {d.gaps_after[ch]['rms']:.2f} |")
        for ph, v in d.gaps_before[ch]["per_phase"].items():
            md.append(f"| | {ph} | {v:.2f} | {d.gaps_after[ch]['per_phase'][ph]:.2f} |")
    md += ["", "## What remains", "",
           ("Unexplained residual: " + d.unexplained_detail) if d.unexplained else
           "Residual at noise level: " + ", ".join(f"{ch} {v:.2f} sd" for ch, v in d.residual_rms_sd.items()), ""]
    md += ["## Plots", ""] + [f"![{f}]({f})" for f in files]
    md += ["", "## Files", "", _PARAM_FILES[d.servo][0], "",
           f"{d.simulations} batched simulations, {d.seconds:.1f} s."]
    return "\n".join(md) + "\n"


def write_outputs(trace: Trace, d: Diagnosis, out: str | Path, source: str = "trace",
                  params: ServoParams = ServoParams(), supply: str | None = None) -> None:
    """Write report.md, the PNG plots, params.toml (base and effects) and verdict.json into ``out``.

    ``supply``: how the supply the fit ran at is known (:func:`supply_source`; None: from the trace's columns).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = _plots(trace, d, out)
    (out / "report.md").write_text(_report(trace, d, files, source), encoding="utf-8")
    _PARAM_FILES[d.servo][1](d, out, source, params, trace, supply_source(trace, supply))
    (out / "verdict.json").write_text(json.dumps(verdict_json(d), indent=2, allow_nan=False), encoding="utf-8")


def _write_servo_params(d: Diagnosis, out: Path, source: str, params: ServoParams, trace: Trace, supply: str) -> None:
    notes = fitted_effects(d.named, d.knobs, params.effects)[1] + fitted_inertia(d.knobs["extra_inertia_kg_m2"], params)[1]
    supply_v, supply_notes = fitted_supply_v(trace, params)
    header = (f"fitted by firmware_model.diagnose from {source}; named effects: {', '.join(d.named) or 'none'}",
              "supply_voltage_v: " + SUPPLY_SOURCES[supply].format(v=supply_v), *supply_notes, *notes)
    fitted_params(d, params, supply_v).to_toml(out / "params.toml", comments=header)


#: Knobs of the X-series replay that are its set-up, not physics parameters (written beside the physics).
_X_SETUP_KNOBS = ("arm_weight_nm", "drive_ceiling", "delay_s", "position_offset_units", "position_gain")


def _write_x_physics(d: Diagnosis, out: Path, source: str, params: object, trace: Trace, supply: str) -> None:
    from dataclasses import asdict

    from .xreplay import physics_with

    doc = {"source": source, "named": d.named, "physics": asdict(physics_with(d.start, d.knobs)),
           "set_up": {k: d.knobs[k] for k in _X_SETUP_KNOBS}}
    (out / "x_physics.json").write_text(json.dumps(doc, indent=2), encoding="utf-8")


#: Per servo family: the report's line about its parameter file, and the writer.
_PARAM_FILES = {
    "ax": ("* `params.toml`: the fitted twin, base parameters and named effects (`[effects]`); serve it with "
           "`ax12emu serve --params params.toml`.", _write_servo_params),
    "x": ("* `x_physics.json`: the fitted X-series physics (XPhysicsParams fields) and the set-up the named effects "
          "add (an arm's weight, a PWM ceiling, a reading latency, a sensor offset and gain).", _write_x_physics),
}
