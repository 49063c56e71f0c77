#!/usr/bin/env python3
"""The physical model against real AX-12A step responses (DYNAMIXEL Wizard 2 exports).

Why it exists: the model was built from a data sheet and a 2008 report; these
are the only recordings of real servos it can be held to.  Each file is one
full-speed step of Goal Position from about 0 to about 500, unloaded or with
a bar of known inertia on the horn (``../shared/reference/real-ax12a/``, see
its README).  The tool prints, per recording, the overshoot (peak minus the
final reading), the dip after the peak (final minus the lowest reading after
it) and the RMS position error, for the real servo, the model before the
bridge-decay change, the default model, and a *twin*: the default model with
the two things these files leave unknown fitted on the unloaded recording
(the supply voltage, which the files do not record, and the inertia of rotor
and gears).  The twin then *predicts* the loaded recordings with only the
bar's inertia added; that is the test of a mechanism (one that fits only the
file it was fitted on is wrong).  The same fit is run with a bridge that
brakes (shorts the winding) to show it cannot do the same.

What the files do not record, and what is assumed (override with flags):
Goal Position (``--goal``, default 500: every servo settles at 498-500),
Moving Speed 0 (full speed), the e-manual's default compliance (margin 1,
slope 32, punch 32) and when the goal was written.  The last is a nuisance,
not a knob: the command onset is scanned in 1 ms steps over the 250 ms before
the first movement and the best one is used (for every model alike).
The Wizard stamps rows on a ~16 ms clock tick while the servo is read about
every 19 ms, so a row's time is late by up to a tick; that puts a floor of
about 3 units under any RMS during the move.  ``tick RMS`` allows for it
(the distance to the model's range over the tick after the stamp) and is
what tells mechanisms apart.

Usage::

    python tools/real_ax12a.py [--data DIR] [--goal 500] [--fit-on AX12A_NOLOAD_1.csv] [--plot tools/figures/real_ax12a.png]

``--fit-on`` names the unloaded AX-12A step the twin is fitted on (a folder may hold repeats of it).

Exit status 2 with a message if the data folder is missing or a recording in it cannot be read or is cut short.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ax12emu.cli.arg_types import OneLineParser, int_range  # noqa: E402
from ax12emu.protocol.control_table import AX12_MODEL  # noqa: E402
from ax12emu.servo.model_factory import ax_bus_model, datasheet_params  # noqa: E402
from firmware_model.diagnose.synthetic import step_response  # noqa: E402
from firmware_model.diagnose.wizard import SPEED_LIMITED_SHARE, read_wizard  # noqa: E402
from firmware_model.diagnose.wizard import cruise_units_s as wizard_cruise_units_s  # noqa: E402
from firmware_model.params import ServoParams  # noqa: E402
from firmware_model.units import RAD_PER_POSITION_UNIT, speed_rad_s_to_raw  # noqa: E402

#: Where the recordings live, relative to the repository (never copied into it).
DEFAULT_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "reference" / "real-ax12a"


@dataclass(frozen=True)
class Recording:
    """One recording and what its README says about it."""

    file: str
    servo: str
    #: Bar inertia on the horn, kg m**2 (J = m (h**2 + b**2) / 12, pivoted at its centre).
    load_kg_m2: float
    #: Overshoot and dip as the README lists them (raw units), for reference; None where it does not list them.
    readme_overshoot: int | None
    readme_dip: int | None


#: The README's table columns this tool reads, by the start of their header cell: these three it needs ...
README_COLUMNS = {"file": "file", "servo": "servo", "load_kg_m2": "J ("}
#: ... and these it reads where the table has them (the load's name, the overshoot and dip as measured there).
README_OPTIONAL_COLUMNS = {"load": "load", "readme_overshoot": "overshoot", "readme_dip": "undershoot"}
#: A cell that says "nothing here" ("-", an en or em dash, "?", or empty).
README_BLANKS = {"", "-", "\u2013", "\u2014", "?", "n/a"}


def _readme_int(cell: str) -> int | None:
    """An overshoot or dip cell: the whole number it holds, or None where it holds none (blank, dash, a range)."""
    try:
        value = float(cell)
    except ValueError:
        return None
    return int(value) if value.is_integer() else None


def _readme_load(cell: str, load: str | None) -> float:
    """The J cell (kg m^2): its number, or 0 where it is blank and the load is none; ValueError otherwise."""
    if cell.lower() in README_BLANKS and (load or "none").lower() in README_BLANKS | {"none", "no load"}:
        return 0.0
    value = float(cell)
    if not 0.0 <= value < math.inf:
        raise ValueError(f"J must be a finite inertia of 0 or more, got {cell}")
    return value


def _columns(cells: list[str], starts: dict[str, str]) -> dict[str, int | None]:
    """Where each column is in a header row (the first cell starting so), None where it has none."""
    return {key: next((i for i, c in enumerate(cells) if c.lower().startswith(start.lower())), None)
            for key, start in starts.items()}


def read_recordings(data: Path) -> tuple[Recording, ...]:
    """The recordings the data folder's README lists, in its table's order; () where there is no README.

    Why from the README and not a list here: the loads are the README's (bar masses and sizes measured by
    whoever recorded them), and a folder holding more recordings of the same kinds (more bars, repeats)
    is read the same way without a change to this tool.  The table needs a file, a servo and a J column; the
    overshoot and dip it lists are kept for reference where given (None where a cell holds no whole number),
    and a J left blank or dashed counts as no load where the load column says none.  A row whose J cannot be
    read raises ValueError naming the line.
    """
    readme = data / "README.md"
    if not readme.exists():
        return ()
    header: dict[str, int | None] | None = None
    out = []
    for number, line in enumerate(readme.read_text(encoding="utf-8").splitlines(), 1):
        cells = [c.strip() for c in line.strip().strip("|").split("|")] if line.lstrip().startswith("|") else []
        if not cells:  # a table ends at the first line that is not a row of it
            header = None
            continue
        if header is None:
            found = _columns(cells, README_COLUMNS)
            header = {**found, **_columns(cells, README_OPTIONAL_COLUMNS)} if None not in found.values() else None
            continue
        if header["file"] >= len(cells) or not cells[header["file"]].lower().endswith(".csv"):
            continue  # the separator row
        try:
            row = {key: None if i is None else cells[i] for key, i in header.items()}
            out.append(Recording(row["file"], row["servo"], _readme_load(row["load_kg_m2"], row["load"]),
                                 _readme_int(row["readme_overshoot"] or ""), _readme_int(row["readme_dip"] or "")))
        except (IndexError, TypeError, ValueError) as exc:
            raise ValueError(f"{readme}:{number}: cannot read this recording's row ({exc}): {line.strip()}") from None
    return tuple(out)


#: The recordings and their loads, as the README of the default data folder lists them (see
#: :func:`read_recordings`).  Another servo's steps (the AX-18A's) are replayed with its served model (:func:`other_servo_rows`).
RECORDINGS = read_recordings(DEFAULT_DATA)
#: The recording the twin is fitted on.
FIT_ON = "AX12A_NOLOAD_1.csv"
#: The model before the bridge-decay change: a bridge that shorts the winding, rotor inertia 3.265e-3.
BEFORE = dataclasses.replace(ServoParams(), bridge_braking_fraction=1.0, rotor_inertia_reflected_kg_m2=3.265e-3)
#: The twin's knobs: supply (V; the files do not record it) and rotor + gear inertia (times the default).
SUPPLY_GRID_V = np.round(np.arange(8.0, 11.01, 0.25), 2)
INERTIA_SCALE_GRID = np.round(np.arange(0.8, 2.61, 0.1), 2)
#: Rows further than this before the first movement, or after it, are not compared (ms).
WINDOW_BEFORE_MS, WINDOW_AFTER_MS = 150.0, 1000.0
#: The command onset is searched this far before the first movement (ms), 1 ms apart.
ONSET_SEARCH_MS = 250
#: The Wizard's timestamp tick (ms): a row was read at its stamp or up to this much later.
TICK_MS = 16
#: A row counts as moved when it is this many units from the first reading.
MOVED_UNITS = 2
#: Settled value: the median of the readings from this long after the first movement on (ms).
SETTLED_AFTER_MS = 1000.0


@dataclass
class Measured:
    t_ms: np.ndarray
    pos: np.ndarray

    @property
    def first_move_ms(self) -> float:
        moved = np.abs(self.pos - self.pos[0]) >= MOVED_UNITS
        if not moved.any():
            raise ValueError("the recording never moves")
        return float(self.t_ms[np.argmax(moved)])


def load(path: Path) -> Measured:
    """One Wizard export; ValueError (or OSError) naming the file when it cannot be compared.

    A recording cut short before the servo settled has no final value to measure overshoot and dip from.
    """
    ex = read_wizard(path)
    if "present_position" not in ex.values:
        raise ValueError(f"{path}: no Present Position column")
    rec = Measured(ex.t_s * 1000.0, ex.values["present_position"].astype(float))
    try:
        settle_from_ms = rec.first_move_ms + SETTLED_AFTER_MS
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    if rec.t_ms[-1] < settle_from_ms:
        raise ValueError(f"{path}: the recording ends {rec.t_ms[-1] - rec.first_move_ms:.0f} ms after the first "
                         f"movement; the settled value is read from {SETTLED_AFTER_MS:.0f} ms after it on (cut short?)")
    return rec


def simulate(params: ServoParams, start: int, goal: int, duration_ms: int, moving_speed: int = 0) -> np.ndarray:
    """Present Position every ms from the command (index 0) on, at the params' supply (the served model)."""
    return step_response(params, start, goal, duration_ms, moving_speed)


def features(values: np.ndarray, times_ms: np.ndarray, settle_from_ms: float) -> tuple[float, float, float]:
    """(overshoot, dip, final): peak minus final, final minus the lowest reading after the peak, final."""
    final = float(np.median(values[times_ms >= settle_from_ms]))
    peak_at = int(np.argmax(values))
    return float(values[peak_at] - final), float(final - values[peak_at:].min()), final


def align(sim: np.ndarray, rec: Measured) -> dict:
    """Best command onset for ``sim`` against ``rec``: plain RMS and tick RMS there (rows near the move)."""
    first = rec.first_move_ms
    w = (rec.t_ms >= first - WINDOW_BEFORE_MS) & (rec.t_ms <= first + WINDOW_AFTER_MS)
    t, p = rec.t_ms[w], rec.pos[w]
    onsets = first - np.arange(ONSET_SEARCH_MS + 1, dtype=float)
    idx = np.clip(np.rint(t[None, :] - onsets[:, None]).astype(int), 0, len(sim) - 1)
    err = sim[idx] - p[None, :]
    rms = np.sqrt(np.mean(err * err, axis=1))
    # Tick RMS: the row was read somewhere in [stamp, stamp + tick): distance to the model's range there.
    padded = np.concatenate([sim, np.full(TICK_MS, sim[-1])])
    windows = np.lib.stride_tricks.sliding_window_view(padded, TICK_MS)
    lo, hi = windows.min(axis=1), windows.max(axis=1)
    gap = np.maximum(0.0, np.maximum(lo[idx] - p[None, :], p[None, :] - hi[idx]))
    tick_rms = np.sqrt(np.mean(gap * gap, axis=1))
    best = int(np.argmin(rms))
    return {"rms": float(rms[best]), "tick_rms": float(tick_rms[best]), "onset_ms": float(onsets[best])}


def evaluate(params: ServoParams, rec: Measured, goal: int, moving_speed: int = 0) -> dict:
    """Replay ``rec``'s step with ``params``: features of the model's own trajectory and the fit to the rows."""
    duration = int(min(rec.t_ms[-1] - rec.first_move_ms + ONSET_SEARCH_MS + 50, 4000))
    sim = simulate(params, int(rec.pos[0]), goal, duration, moving_speed)
    t_sim = np.arange(len(sim), dtype=float)
    moved = np.abs(sim - sim[0]) >= MOVED_UNITS
    model_first = float(np.argmax(moved)) if moved.any() else 0.0
    over, dip, final = features(sim, t_sim, model_first + SETTLED_AFTER_MS)
    return {"overshoot": over, "dip": dip, "final": final, "sim": sim, **align(sim, rec)}


def real_features(rec: Measured) -> dict:
    over, dip, final = features(rec.pos, rec.t_ms, rec.first_move_ms + SETTLED_AFTER_MS)
    return {"overshoot": over, "dip": dip, "final": final}


def cruise_units_s(rec: Measured) -> float:
    """The step's cruise speed (units/s; :func:`firmware_model.diagnose.wizard.cruise_units_s` to the settled value)."""
    return wizard_cruise_units_s(rec.t_ms / 1000.0, rec.pos, real_features(rec)["final"])


def datasheet_servo(name: str) -> ServoParams | None:
    """The served model's parameters for another servo of the AX bus named as the README names it (e.g. "AX-18A"):
    its model file's motor, as ``ax12emu serve --servo`` runs it; None for the AX-12A (its rows are the default and
    the twin) and where no such model has that name (the MX series runs another firmware model)."""
    spec = ax_bus_model(name)
    return None if spec is None or spec.key == AX12_MODEL else datasheet_params(spec)


def other_servo_rows(r: Recording, rec: Measured, goal: int) -> dict[str, tuple[ServoParams, int]] | None:
    """What another servo's step is replayed with: its served model with the recording's bar, at Moving Speed 0
    (the README's presumption) and, where the step cruised well below that model's top speed, at the Moving Speed
    of the cruise (a step taken speed-limited: the export does not record Moving Speed), that row last.  None
    where the servo has no model file."""
    params = datasheet_servo(r.servo)
    if params is None:
        return None
    params = dataclasses.replace(params, load_inertia_kg_m2=params.load_inertia_kg_m2 + r.load_kg_m2)  # the bar, if any
    rows = {"served, Moving Speed 0": (params, 0)}
    try:
        cruise = cruise_units_s(rec) * RAD_PER_POSITION_UNIT
    except ValueError:  # a step too short to cruise: nothing tells a Moving Speed
        return rows
    if cruise < SPEED_LIMITED_SHARE * params.top_speed_rad_s(params.supply_voltage_v):
        speed = int(speed_rad_s_to_raw(cruise))
        rows[f"served, Moving Speed {speed} (cruise)"] = (params, speed)
    return rows


def with_supply(params: ServoParams, volts: float, inertia_scale: float = 1.0, extra_kg_m2: float = 0.0) -> ServoParams:
    return dataclasses.replace(params, supply_voltage_v=float(volts),
                               rotor_inertia_reflected_kg_m2=params.rotor_inertia_reflected_kg_m2 * inertia_scale,
                               load_inertia_kg_m2=params.load_inertia_kg_m2 + extra_kg_m2)


def fit_twin(base: ServoParams, rec: Measured, goal: int) -> tuple[ServoParams, float, float, dict]:
    """Supply and inertia scale minimising the RMS at the best onset (grid); returns (params, volts, scale, result)."""
    best = None
    for volts in SUPPLY_GRID_V:
        for scale in INERTIA_SCALE_GRID:
            params = with_supply(base, volts, scale)
            result = evaluate(params, rec, goal)
            if best is None or result["rms"] < best[3]["rms"]:
                best = (params, float(volts), float(scale), result)
    return best


def close_twin(twin: ServoParams, path: Path, goal: int) -> tuple[ServoParams, object]:
    """The twin with what the diagnosis names on its own fit recording added: (that twin, the diagnosis).

    Why: what the workflow finds missing on the recording the twin was fitted on (no bar) is the servo's
    (on these steps, gear play), so the twin the loaded steps are diagnosed from should carry it, or the
    loaded steps name it again instead of the bar.  Named effects that are fields of the params
    (:func:`firmware_model.diagnose.output.fitted_params`) go in, the base re-fit with them; the recording's
    own traits (the goal write's time) do not.
    """
    from firmware_model.diagnose.cli import load_input, parse_args
    from firmware_model.diagnose.output import fitted_params
    from firmware_model.diagnose.search import diagnose

    args = parse_args([str(path), "--out", "unused", "--goal", str(goal), "--voltage", str(twin.supply_voltage_v)])
    d = diagnose(load_input(args, twin).trace, twin, progress=lambda msg: None)
    return (fitted_params(d, twin) if d.named else twin), d


def _or_dash(value: int | None) -> str:
    return "-" if value is None else str(value)


def _row(name: str, r: dict, real: dict | None = None) -> str:
    text = f"  {name:<34} overshoot {r['overshoot']:5.1f}  dip {r['dip']:4.1f}  final {r['final']:6.1f}"
    if "rms" in r:
        text += f"  RMS {r['rms']:5.2f}  tick RMS {r['tick_rms']:5.2f}"
    if real is not None:
        text += f"   (vs real: {r['overshoot'] - real['overshoot']:+.0f} / {r['dip'] - real['dip']:+.0f})"
    return text


def run(data: Path, goal: int, plot: Path | None, fit_on: str = FIT_ON) -> int:
    try:
        recordings = read_recordings(data)
        in_readme = {r.file for r in recordings}
        listed = next((r for r in recordings if r.file == fit_on), None)
        if listed is None:  # the unloaded step the twin is fitted on, listed or not
            recordings = (Recording(fit_on, "AX-12A", 0.0, None, None),) + recordings
        elif listed.servo != "AX-12A" or listed.load_kg_m2 != 0:
            print(f"real_ax12a: the twin is fitted on an unloaded AX-12A step; the README lists {fit_on} as an "
                  f"{listed.servo} with J {listed.load_kg_m2:g} kg m^2", file=sys.stderr)
            return 2
        recs = {r.file: load(data / r.file) for r in recordings if (data / r.file).exists()}
    except (ValueError, OSError) as exc:  # WizardFormatError is a ValueError
        print(f"real_ax12a: {exc}", file=sys.stderr)
        return 2
    if fit_on not in recs:
        print(f"real_ax12a: {data / fit_on} not found (the recordings live in ../shared/reference/real-ax12a)",
              file=sys.stderr)
        return 2
    default = ServoParams()
    print(f"Assumed: goal {goal}, Moving Speed 0, compliance margin 1 / slope 32 / punch 32; command onset scanned "
          f"over the {ONSET_SEARCH_MS} ms before the first movement.  Default supply {default.supply_voltage_v} V.")
    twins = {}
    for label, braking in (("twin", default.bridge_braking_fraction), ("braking-bridge twin", 1.0)):
        base = dataclasses.replace(default, bridge_braking_fraction=braking)
        params, volts, scale, _ = fit_twin(base, recs[fit_on], goal)
        twins[label] = params
        print(f"{label}: bridge braking fraction {braking:g}, fitted on {fit_on}: supply {volts:.2f} V, rotor and gear "
              f"inertia x{scale:.1f} ({params.rotor_inertia_reflected_kg_m2:.3g} kg m^2)")
    curves = {}
    for r in recordings:
        if r.file not in recs:
            print(f"{r.file}: not found, skipped")
            continue
        rec = recs[r.file]
        real = real_features(rec)
        listed = ("not in the README" if r.file not in in_readme
                  else f"README: overshoot {_or_dash(r.readme_overshoot)}, dip {_or_dash(r.readme_dip)}")
        print(f"\n{r.file} ({r.servo}, bar J {r.load_kg_m2:.3g} kg m^2; {listed})")
        print(_row("real", real))
        if r.servo != "AX-12A":
            others = other_servo_rows(r, rec, goal)
            if others is None:
                print(f"  (no servo of the AX bus is named {r.servo}: not replayed)")
                continue
            print(f"  (the served {r.servo}: its model file's motor, friction scaled from the AX-12A's)")
            curves[r.file] = (rec, {})
            for name, (params, speed) in others.items():
                result = evaluate(params, rec, goal, speed)
                curves[r.file][1][name] = result
                print(_row(name, result, real))
            continue
        rows = {"before (shorting bridge, old J)": with_supply(BEFORE, BEFORE.supply_voltage_v, 1.0, r.load_kg_m2),
                "default": with_supply(default, default.supply_voltage_v, 1.0, r.load_kg_m2)}
        rows.update({name + (" (fitted here)" if r.file == fit_on else " (predicted)"):
                     dataclasses.replace(p, load_inertia_kg_m2=p.load_inertia_kg_m2 + r.load_kg_m2)
                     for name, p in twins.items()})
        curves[r.file] = (rec, {})
        for name, params in rows.items():
            result = evaluate(params, rec, goal)
            curves[r.file][1][name] = result
            print(_row(name, result, real))
    if plot is not None:
        _plot(curves, plot)
        print(f"\nwrote {plot}")
    return 0


def _plot(curves: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(curves), 1, figsize=(8, 3.2 * len(curves)), squeeze=False)
    for ax, (name, (rec, results)) in zip(axes[:, 0], curves.items()):
        first = rec.first_move_ms
        shown = (rec.t_ms >= first - 60) & (rec.t_ms <= first + 700)
        ax.plot(rec.t_ms[shown] - first, rec.pos[shown], "ko", ms=3, label="real (Wizard rows)")
        for label, r in results.items():
            if label.startswith("braking"):
                continue
            t = np.arange(len(r["sim"])) + r["onset_ms"] - first
            keep = (t >= -60) & (t <= 700)
            ax.plot(t[keep], r["sim"][keep], lw=1.2, label=f"{label}: over {r['overshoot']:.0f}, dip {r['dip']:.0f}")
        ax.set_title(name)
        ax.set_xlabel("ms from the first movement")
        ax.set_ylabel("Present Position")
        ax.set_ylim(380, 535)  # the end of the move, where the mechanisms differ
        ax.set_xlim(250, 700)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)


def main(argv: list[str] | None = None) -> int:
    ap = OneLineParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder with the Wizard exports")
    ap.add_argument("--goal", type=int_range(0, 1023), default=500,
                    help="the Goal Position the step went to (not recorded)")
    ap.add_argument("--plot", type=Path, default=None, help="write a figure (needs matplotlib)")
    ap.add_argument("--fit-on", default=FIT_ON, metavar="FILE",
                    help=f"the unloaded AX-12A step in --data the twin is fitted on (default {FIT_ON})")
    args = ap.parse_args(argv)
    if Path(args.fit_on).name != args.fit_on:
        ap.error(f"--fit-on names a file in --data, not a path: {args.fit_on!r}")
    return run(args.data, args.goal, args.plot, args.fit_on)


if __name__ == "__main__":
    sys.exit(main())
