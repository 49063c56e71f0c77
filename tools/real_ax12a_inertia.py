#!/usr/bin/env python3
"""What the real AX-12A steps say about the bars' inertia, through the twin: the figures behind the miss.

Why it exists: from the twin fitted on the unloaded step (``tools/real_ax12a.py``), the
diagnosis should name ``extra_inertia`` on each loaded step with the bar's J inside its
interval, and it does not (``tests/tools/test_real_ax12a.py``).  Two explanations compete:
the model's response to inertia is wrong (its overshoot grows too slowly with J), or these
recordings do not carry the bar's signature above their own noise.  This tool prints the
numbers that tell them apart, per AX-12A recording:

1. **Timing, model-free.**  When the step crosses :data:`LEVELS_UNITS` on the rows' rebuilt
   reading times (interpolated between rows), from its crossing of the first: a start slowed
   by the bar shows in the first intervals, the supply (not recorded, and free to differ from
   one recording to the next) in the cruise between 200 and 400 units; the twin with the
   bar's J added, at 1 ms, beside it.
2. **Peaks.**  The highest reading of the real step, against the twin's peak with the bar's J
   added, at 1 ms and as read every reading period (the Wizard reads the servo about every
   20 ms; the range over every phase of that clock is printed).  A reading that far apart can
   miss a peak by a few units, so overshoot differences of that size between recordings are
   not evidence about the model.
3. **Cost over extra inertia**, as the diagnosis scores it (its evaluator: the rows' rebuilt
   reading times, whitened soft-L1 cost on the training rows), from the twin plus each value:

   * *write fixed*: the goal write's time (not recorded in a Wizard export, a nuisance the
     base fit places) held where the twin put it, as the search once screened and fitted
     effects (it now re-fits the write with each, ``selection.WRITE_SHIFT``).  Inertia slows
     the start, so held there it is charged for a lag the write time would absorb;
   * *write re-fitted*: the write time re-fitted at each value (:func:`fit_onsets`);
   * *move rows*: only the rows from the first movement to :data:`AFTER_PEAK_S` after the
     peak, the write time re-fitted for them; the rows at rest, where the settled level (one
     unit either way, decided by friction and play as much as by inertia) weighs a hundred
     rows, are left out.  Its 95 % region (cost rise times ``n_eff / cost`` below the
     chi-squared quantile, as :func:`firmware_model.diagnose.verdict.grid_profile` reads a
     grid) says what the move itself pins down, and its BIC gain over no extra inertia
     (:func:`firmware_model.diagnose.verdict.delta_bic`, one parameter, the best point's sample
     count) whether the move alone carries enough to name it.

4. **The return from the peak, model-free.**  How long the step takes to fall through
   :data:`RETURN_LEVELS_UNITS` after its peak (interpolated between rows; both levels lie below
   every peak and above every dip), real and the twin with the bar's J at 1 ms.  The held-out
   rows of a single step are the peak and the return (:mod:`firmware_model.diagnose.evaluate`),
   and a bar that the model returns slower with than the real servo does makes them worse there.

5. With ``--joint``: a twin fitted on the unloaded step as the diagnosis scores it (the rebuilt
   reading times, the write time re-fitted), over supply, rotor and gear inertia *and* gear
   play together (every real gear train has some), and what the diagnosis names on each step
   from it.

6. With ``--synthetic``: whether the workflow could name the bars at all on recordings like these.
   Each loaded step's Present Position is replaced by what the closed twin
   (:func:`real_ax12a.close_twin`) with :data:`SYNTHETIC_SCALES` times the bar's J reads at the
   same rows (the diagnosis's own evaluator: the rebuilt reading times, the goal write fitted),
   plus Gaussian noise of :data:`SYNTHETIC_SIGMA_UNITS`, rounded, and the diagnosis runs on it from
   the closed twin.  A recording the model made itself holds the bar and nothing else: what the
   workflow finds there and misses on the real step is the model's to explain, not beyond the
   workflow's reach.

7. With ``--split``: where the diagnosis's own fit finds the bar, row by row.  From the closed twin, each
   loaded step's cost over :data:`SPLIT_GRID_KG_M2` of extra inertia, the shared base parameters (the
   gearbox efficiency, the goal write's time) re-fitted at each value by the search's least squares
   (:meth:`~firmware_model.diagnose.selection.Selection.fit`, the inertia held), on the training rows
   and on the held-out rows apart, and the training cost of the rows at rest (where a Wizard export's
   settled readings sit).  The workflow fits on the first and judges on the second: where the two
   have their minima far apart, one inertia does not fit the whole step.

Usage::

    python tools/real_ax12a_inertia.py [--data DIR] [--goal 500] [--joint] [--synthetic] [--split]

Exit status 2 with a message if the data folder is missing.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
from scipy.stats import chi2

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import real_ax12a  # noqa: E402

from ax12emu.cli.arg_types import OneLineParser, int_range  # noqa: E402
from firmware_model.diagnose.cli import load_input, parse_args  # noqa: E402
from firmware_model.diagnose.evaluate import Lockstep  # noqa: E402
from firmware_model.diagnose.metrics import effective_count, robust_cost  # noqa: E402
from firmware_model.diagnose.nuisance import fit_onsets  # noqa: E402
from firmware_model.diagnose.search import diagnose  # noqa: E402
from firmware_model.diagnose.selection import BASE_ONLY, Selection  # noqa: E402
from firmware_model.diagnose.verdict import BIC_MARGIN, delta_bic  # noqa: E402
from firmware_model.diagnose.wizard import read_wizard  # noqa: E402
from firmware_model.params import ServoEffects, ServoParams  # noqa: E402

#: Extra inertia profiled, kg m**2 (the bars are 0.73e-3 and 1.02e-3; the twin's own is about 6e-3).
EXTRA_GRID_KG_M2 = np.round(np.arange(-1.0e-3, 2.001e-3, 0.25e-3), 6)
#: The move rows run from the first movement to this long after the highest reading (s): the return from the peak.
AFTER_PEAK_S = 0.12
#: Position levels (units) whose crossing times are compared, the first the origin.
LEVELS_UNITS = (15, 100, 200, 400, 480)
#: Confidence level of the move rows' region.
LEVEL = 0.95
#: The joint fit's grid: supply (V), rotor and gear inertia added to the default's (kg m**2), gear play (rad).
JOINT_SUPPLY_V = (8.75, 9.0, 9.25)
JOINT_EXTRA_KG_M2 = np.round(np.arange(-1.0e-3, 3.001e-3, 0.25e-3), 6)
JOINT_PLAY_RAD = (0.0, 0.005, 0.01, 0.015)


#: The synthetic check: the bars' J times these, noise on the readings (units, SD), seeds per file and scale.
SYNTHETIC_SCALES = (1.0, 2.0)
SYNTHETIC_SIGMA_UNITS = 0.5
SYNTHETIC_SEEDS = 3


def _trace(params: ServoParams, path: Path, goal: int):
    args = parse_args([str(path), "--out", "unused", "--goal", str(goal), "--voltage", str(params.supply_voltage_v)])
    return load_input(args, params).trace


def fit_joint(path: Path, goal: int) -> tuple[ServoParams, float]:
    """Supply, rotor and gear inertia and gear play minimising the diagnosis's cost on ``path`` (write re-fitted)."""
    best = (np.inf, None)
    for volts in JOINT_SUPPLY_V:
        base = dataclasses.replace(ServoParams(), supply_voltage_v=volts)
        sel = Selection(_trace(base, path, goal), base, lambda msg: None)
        sel.fit_nuisance()
        ev, onsets = sel.ev, sel.nuisance.onsets
        lo, hi = ev.schedule.bounds()[1]
        grid = np.repeat(onsets[:, None], hi - lo + 1, axis=1)
        grid[1] = np.arange(lo, hi + 1)
        for play in JOINT_PLAY_RAD:
            for extra in JOINT_EXTRA_KG_M2:
                knobs = sel.knobs(sel.base, {"extra_inertia": {"extra_inertia_kg_m2": float(extra)},
                                             "backlash": {"backlash_rad": float(play)}})
                z = ev.whiten(ev.run([knobs] * grid.shape[1], onsets=grid))
                cost = min(sum(ev.costs(zi)) for zi in z)  # one change owns every row after its window
                if cost < best[0]:
                    twin = dataclasses.replace(
                        base, rotor_inertia_reflected_kg_m2=base.rotor_inertia_reflected_kg_m2 + float(extra),
                        effects=ServoEffects(backlash_rad=float(play)) if play else ServoEffects())
                    best = (cost, twin)
    return best[1], float(best[0])


def crossings_ms(times_ms: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """When ``pos`` first reaches each of :data:`LEVELS_UNITS` (interpolated between rows), ms after the first."""
    out = []
    for level in LEVELS_UNITS:
        i = int(np.argmax(pos >= level))
        if i == 0 or pos[i] < level:
            raise ValueError(f"the step never crosses {level} units from below")
        out.append(times_ms[i - 1] + (level - pos[i - 1]) * (times_ms[i] - times_ms[i - 1]) / (pos[i] - pos[i - 1]))
    return np.array(out[1:]) - out[0]


#: The return from the peak is timed between these readings on the way down (units; below every recorded peak,
#: 517-522, and above every dip, 495).
RETURN_LEVELS_UNITS = (512, 500)


def return_ms(times_ms: np.ndarray, pos: np.ndarray) -> float:
    """How long ``pos`` takes, after its peak, to fall from the first to the second of :data:`RETURN_LEVELS_UNITS`
    (interpolated between rows)."""
    top = int(np.argmax(pos))
    at = []
    for level in RETURN_LEVELS_UNITS:
        below = np.flatnonzero(pos[top:] <= level)
        if pos[top] <= level or not len(below):
            raise ValueError(f"the step does not fall through {level} units after its peak")
        j = top + int(below[0])
        at.append(times_ms[j - 1] + (level - pos[j - 1]) * (times_ms[j] - times_ms[j - 1]) / (pos[j] - pos[j - 1]))
    return float(at[1] - at[0])


def peaks(params: ServoParams, rec: real_ax12a.Measured, extra_kg_m2: float, period_ms: float, goal: int
          ) -> tuple[float, float, float]:
    """The twin's peak with ``extra_kg_m2`` added: at 1 ms, and the lowest and highest peak read every ``period_ms``."""
    loaded = dataclasses.replace(params, load_inertia_kg_m2=params.load_inertia_kg_m2 + extra_kg_m2)
    sim = real_ax12a.simulate(loaded, int(rec.pos[0]), goal, 900)
    top = int(np.argmax(sim))
    step = max(1, int(round(period_ms)))
    read = [sim[phase::step].max() for phase in range(step)]
    return float(sim[top]), float(min(read)), float(max(read))


def profile(params: ServoParams, path: Path, goal: int) -> dict:
    """The cost over :data:`EXTRA_GRID_KG_M2` three ways (see the module docstring), and the move rows' region."""
    trace = _trace(params, path, goal)
    sel = Selection(trace, params, lambda msg: None)
    sel.fit_nuisance()
    ev, onsets = sel.ev, sel.nuisance.onsets.copy()
    pos = trace["present_position"].astype(float)
    first = int(np.argmax(np.abs(pos - pos[0]) >= real_ax12a.MOVED_UNITS))
    top = int(np.argmax(pos))
    move = (np.arange(len(pos)) >= first - 1) & (trace.t <= trace.t[top] + AFTER_PEAK_S)
    lo, hi = ev.schedule.bounds()[1]
    windows = np.arange(lo, hi + 1)
    fixed, refit, moving = [], [], []
    for extra in EXTRA_GRID_KG_M2:
        knobs = sel.knobs(sel.base, {"extra_inertia": {"extra_inertia_kg_m2": float(extra)}})
        fixed.append(ev.costs(ev.whiten(ev.run([knobs], onsets=onsets[:, None]))[0])[0])
        best = fit_onsets(ev, knobs, onsets)
        refit.append(ev.costs(ev.whiten(ev.run([knobs], onsets=best[:, None]))[0])[0])
        grid = np.repeat(onsets[:, None], len(windows), axis=1)
        grid[1] = windows
        z = ev.whiten(ev.run([knobs] * len(windows), onsets=grid))[:, move, :]
        costs = robust_cost(z).sum(axis=(1, 2))
        at = int(np.argmin(costs))
        moving.append((float(costs[at]), effective_count(z[at])))
    move_cost = np.array([c for c, _ in moving])
    b = int(np.argmin(move_cost))
    scale = moving[b][1] / move_cost[b]
    inside = EXTRA_GRID_KG_M2[(move_cost - move_cost[b]) * scale <= chi2.ppf(LEVEL, 1)]
    none = int(np.argmin(np.abs(EXTRA_GRID_KG_M2)))
    return {"fixed": np.array(fixed), "refit": np.array(refit), "move": move_cost, "move_rows": int(move.sum()),
            "move_best": float(EXTRA_GRID_KG_M2[b]), "move_region": (float(inside.min()), float(inside.max())),
            "move_dbic": float(delta_bic(1, move_cost[none], move_cost[b], moving[b][1]))}


#: Extra inertia of the ``--split`` profile (kg m**2): the bars are 0.73e-3 and 1.02e-3, the fits 2.6-2.8e-3.
SPLIT_GRID_KG_M2 = (0.0, 0.25e-3, 0.5e-3, 0.75e-3, 1.0e-3, 1.25e-3, 1.5e-3, 2.0e-3, 2.5e-3, 3.0e-3)


def split_profile(params: ServoParams, path: Path, goal: int) -> list[dict]:
    """Per :data:`SPLIT_GRID_KG_M2` value: the training, held-out and resting-rows training cost with the base
    re-fitted (see the module docstring, 7), and the re-fitted base."""
    sel = Selection(_trace(params, path, goal), params, lambda msg: None)
    sel.fit_nuisance()
    ev = sel.ev
    resting_train = ev.train & ev.resting
    start = dict(sel.base)
    out = []
    for extra in SPLIT_GRID_KG_M2:
        sel.chosen, sel.base = {"extra_inertia": {"extra_inertia_kg_m2": float(extra)}}, dict(start)
        lock = Lockstep(ev.run)
        fit = lock.map([lambda lock=lock: sel.fit(BASE_ONLY, {}, lock, hold_chosen=True)])[0]
        rest = float(robust_cost(ev.weigh(fit.z))[resting_train].sum())
        out.append({"extra_kg_m2": float(extra), "train": fit.score.cost_train, "held": fit.score.cost_held,
                    "rest": rest, "base": fit.base})
    return out


def run_split(data: Path, goal: int) -> None:
    twin, _, _, _ = real_ax12a.fit_twin(ServoParams(), real_ax12a.load(data / real_ax12a.FIT_ON), goal)
    closed, _ = real_ax12a.close_twin(twin, data / real_ax12a.FIT_ON, goal)
    print("\ncost over extra inertia from the closed twin, the base re-fitted at each value (training / held-out rows):")
    for r in real_ax12a.read_recordings(data):
        path = data / r.file
        if r.servo != "AX-12A" or r.load_kg_m2 <= 0 or not path.exists():
            continue
        rows = split_profile(closed, path, goal)
        print(f"  {r.file} (bar {1e3 * r.load_kg_m2:.3f}e-3 kg m^2)")
        for row in rows:
            base = ", ".join(f"{k} {v:.4g}" for k, v in row["base"].items())
            print(f"    {1e3 * row['extra_kg_m2']:5.2f}e-3: training {row['train']:7.1f} (at rest {row['rest']:5.1f}), "
                  f"held out {row['held']:7.1f}; {base}")
        best = {k: 1e3 * min(rows, key=lambda row: row[k])["extra_kg_m2"] for k in ("train", "held")}
        print(f"    lowest: training at {best['train']:.2f}e-3, held out at {best['held']:.2f}e-3")


def synthetic_trace(params: ServoParams, path: Path, goal: int, extra_kg_m2: float, sigma_units: float, seed: int):
    """The recording at ``path`` with its Present Position replaced by what ``params`` with ``extra_kg_m2`` more
    inertia reads at the same rows (the diagnosis's evaluator, the goal write fitted), plus Gaussian noise of
    ``sigma_units``, rounded as the servo reports it."""
    trace = _trace(params, path, goal)
    loaded = dataclasses.replace(params, load_inertia_kg_m2=params.load_inertia_kg_m2 + extra_kg_m2)
    sel = Selection(trace, loaded, lambda msg: None)
    sel.fit_nuisance()
    ch = sel.ev.channels.index("present_position")
    sim = sel.ev.run([sel.knobs(sel.base, sel.chosen)])[0][:, ch]
    noisy = np.rint(sim + np.random.default_rng(seed).normal(0.0, sigma_units, len(sim)))
    columns = dict(trace.columns)
    columns["present_position"] = noisy.astype(trace.columns["present_position"].dtype)
    return dataclasses.replace(trace, columns=columns)


def run_synthetic(data: Path, goal: int) -> None:
    twin, _, _, _ = real_ax12a.fit_twin(ServoParams(), real_ax12a.load(data / real_ax12a.FIT_ON), goal)
    closed, closing = real_ax12a.close_twin(twin, data / real_ax12a.FIT_ON, goal)
    print(f"\nsynthetic steps from the closed twin (the unloaded step names {', '.join(closing.named) or 'nothing'}), "
          f"noise {SYNTHETIC_SIGMA_UNITS} units SD, {SYNTHETIC_SEEDS} seeds:")
    for r in real_ax12a.read_recordings(data):
        path = data / r.file
        if r.servo != "AX-12A" or r.load_kg_m2 <= 0 or not path.exists():
            continue
        for scale in SYNTHETIC_SCALES:
            extra = scale * r.load_kg_m2
            found = []
            for seed in range(SYNTHETIC_SEEDS):
                d = diagnose(synthetic_trace(closed, path, goal, extra, SYNTHETIC_SIGMA_UNITS, seed), closed)
                first = d.accepted[0] if d.accepted else None
                if first is not None and first.effect == "extra_inertia":
                    j, half = first.values["extra_inertia_kg_m2"], first.uncertainty["extra_inertia_kg_m2"]
                    found.append(f"{1e3 * j:.2f} +- {1e3 * half:.2f}{' (holds it)' if abs(j - extra) <= half else ''}")
                else:
                    found.append("names " + (", ".join(d.named) or "nothing"))
            print(f"  {r.file} with {scale:g} x the bar ({1e3 * extra:.2f}e-3 kg m^2): "
                  f"{sum(f[0].isdigit() for f in found)}/{len(found)} name extra_inertia first: " + "; ".join(found))


def run_joint(data: Path, goal: int) -> None:
    twin, cost = fit_joint(data / real_ax12a.FIT_ON, goal)
    play = twin.effects.value("backlash_rad", 0.0)
    print(f"\njoint twin ({real_ax12a.FIT_ON}, the diagnosis's cost {cost:.0f}): {twin.supply_voltage_v:.2f} V, rotor and "
          f"gear inertia {1e3 * twin.rotor_inertia_reflected_kg_m2:.2f}e-3 kg m^2, gear play {play:g} rad")
    for r in real_ax12a.read_recordings(data):
        path = data / r.file
        if r.servo != "AX-12A" or not path.exists():
            continue
        d = diagnose(_trace(twin, path, goal), twin)
        named = ", ".join(f"{c.effect} " + ", ".join(f"{v:.3g} +- {c.uncertainty.get(k, float('nan')):.2g}"
                                                   for k, v in c.values.items()) for c in d.accepted) or "nothing"
        loaded = dataclasses.replace(twin, load_inertia_kg_m2=twin.load_inertia_kg_m2 + r.load_kg_m2)
        sel = Selection(_trace(loaded, path, goal), loaded, lambda msg: None)
        sel.fit_nuisance()
        with_bar = float(np.sqrt(np.mean((sel.residual()[:, 0] * sel.ev.sd[0]) ** 2)))
        print(f"  {r.file}: names {named}; position gap {d.gaps_before['present_position']['rms']:.2f} -> "
              f"{d.gaps_after['present_position']['rms']:.2f} units RMS; twin + bar {with_bar:.2f}")


def run(data: Path, goal: int, joint: bool = False, synthetic: bool = False, split: bool = False) -> int:
    fit_on = data / real_ax12a.FIT_ON
    if not fit_on.exists():
        print(f"real_ax12a_inertia: {fit_on} not found (the recordings live in ../shared/reference/real-ax12a)",
              file=sys.stderr)
        return 2
    twin, volts, scale, _ = real_ax12a.fit_twin(ServoParams(), real_ax12a.load(fit_on), goal)
    print(f"twin ({real_ax12a.FIT_ON}, as tools/real_ax12a.py fits it): {volts:.2f} V, rotor and gear inertia x{scale:.1f} "
          f"(total {1e3 * (twin.rotor_inertia_reflected_kg_m2 + twin.load_inertia_kg_m2):.2f}e-3 kg m^2)")
    grid = "  ".join(f"{1e3 * j:+5.2f}" for j in EXTRA_GRID_KG_M2)
    for r in real_ax12a.read_recordings(data):
        path = data / r.file
        if r.servo != "AX-12A" or not path.exists():
            continue
        ex = read_wizard(path)
        period_ms = 1000.0 * (ex.read_period_s or real_ax12a.TICK_MS / 1000.0)
        rec = real_ax12a.load(path)
        final = real_ax12a.real_features(rec)["final"]
        at_1ms, read_lo, read_hi = peaks(twin, rec, r.load_kg_m2, period_ms, goal)
        print(f"\n{r.file} (bar {1e3 * r.load_kg_m2:.3f}e-3 kg m^2; read every {period_ms:.1f} ms)")
        sim = real_ax12a.simulate(dataclasses.replace(twin, load_inertia_kg_m2=twin.load_inertia_kg_m2 + r.load_kg_m2),
                                  int(rec.pos[0]), goal, 900)
        real_ms = crossings_ms(1000.0 * ex.times_s, ex.values["present_position"].astype(float))
        twin_ms = crossings_ms(np.arange(len(sim), dtype=float), sim)
        names = ", ".join(str(v) for v in LEVELS_UNITS[1:])
        print(f"  ms from {LEVELS_UNITS[0]} to {names} units: real " + " ".join(f"{x:5.1f}" for x in real_ms)
              + "; twin + bar " + " ".join(f"{x:5.1f}" for x in twin_ms)
              + f"; real cruise {LEVELS_UNITS[2]}-{LEVELS_UNITS[3]} in {real_ms[2] - real_ms[1]:.1f} ms")
        print(f"  peak: real {rec.pos.max():.0f} (settles at {final:.0f}); twin + bar {at_1ms:.1f} at 1 ms, "
              f"{read_lo:.0f}-{read_hi:.0f} read every {period_ms:.0f} ms")
        real_return = return_ms(1000.0 * ex.times_s, ex.values["present_position"].astype(float))
        print(f"  return from the peak, {RETURN_LEVELS_UNITS[0]} to {RETURN_LEVELS_UNITS[1]} units: real "
              f"{real_return:.1f} ms; twin + bar {return_ms(np.arange(len(sim), dtype=float), sim):.1f} ms")
        p = profile(twin, path, goal)
        print(f"  extra J (e-3 kg m^2)   {grid}")
        for label, key in (("write fixed", "fixed"), ("write re-fitted", "refit"), (f"move rows ({p['move_rows']})", "move")):
            print(f"  {label:<22} " + "  ".join(f"{c:5.0f}" for c in p[key]))
        lo, hi = p["move_region"]
        print(f"  move rows: best {1e3 * p['move_best']:+.2f}e-3, {100 * LEVEL:.0f} % region {1e3 * lo:+.2f}..{1e3 * hi:+.2f}e-3 "
              f"({'holds' if lo <= r.load_kg_m2 <= hi else 'excludes'} the bar, "
              f"{'holds' if lo <= 0.0 <= hi else 'excludes'} none); BIC gain over none {p['move_dbic']:.1f} "
              f"(the workflow names above {BIC_MARGIN:g})")
    if joint:
        run_joint(data, goal)
    if synthetic:
        run_synthetic(data, goal)
    if split:
        run_split(data, goal)
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = OneLineParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=real_ax12a.DEFAULT_DATA, help="folder with the Wizard exports")
    ap.add_argument("--goal", type=int_range(0, 1023), default=500,
                    help="the Goal Position the step went to (not recorded)")
    ap.add_argument("--joint", action="store_true", help="also fit supply, inertia and gear play together on the "
                                                         "unloaded step and diagnose every step from that twin")
    ap.add_argument("--synthetic", action="store_true", help="also diagnose each loaded step as the closed twin with "
                                                             "the bar would have recorded it (can the workflow see it?)")
    ap.add_argument("--split", action="store_true", help="also profile each loaded step's cost over extra inertia "
                                                         "on the training and the held-out rows apart, the base re-fitted")
    args = ap.parse_args(argv)
    return run(args.data, args.goal, args.joint, args.synthetic, args.split)


if __name__ == "__main__":
    sys.exit(main())
