"""``python -m firmware_model.diagnose MEASURED.csv --out DIR [--json]``: the workflow's command line.

Why it exists: one command from a measured trace to a verdict, a report and
a parameter file ``ax12emu serve --params`` loads.  Progress goes to stderr;
the verdict (or, with ``--json``, one JSON object) to stdout.

Two input formats, told apart by the file's first line: the project's trace
CSV (:mod:`.trace`) and DYNAMIXEL Wizard 2 graph exports (:mod:`.wizard`).
A Wizard export records only what was plotted (usually Present Position),
so the commands come from options, each with a documented default, and
every assumption is printed with the verdict and in the report:

* ``--goal`` (default :data:`DEFAULT_GOAL`): the Goal Position written once;
* ``--initial-goal`` (default: the first Present Position, the servo holding
  where it stood);
* ``--onset`` (default: estimated from the first movement and fitted with the
  base model, :mod:`.nuisance`): when the goal was written, s after the
  first row read; giving it makes it known (the trace then records it);
* ``--moving-speed`` (default 0, full speed) and ``--voltage`` (default: the
  ``--params`` file's supply, which a twin's params.toml carries, else
  :data:`DEFAULT_VOLTAGE_V`).

``--voltage`` also gives the supply of a trace CSV without a ``voltage``
column (default: the ``--params`` file's, else the model's own), which is
then printed as assumed: a fit at the wrong supply names the difference as
an effect.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..interface import POWER_UP
from ..params import ServoParams
from ..stepping import check_step
from ..units import RAD_PER_POSITION_UNIT, speed_rad_s_to_raw
from .batch import null_knobs
from .effects import LIBRARY, X_LIBRARY
from .families import family_of
from .nuisance import first_movement_onset, first_movement_row, locate_onset
from .output import json_safe, verdict_json, verdict_text, write_outputs
from .schedule import CONTROL_STEP_S
from .search import Diagnosis, diagnose
from .trace import Trace, TraceFormatError, check_span, read_trace, rest_level
from .wizard import (
    ITEM_COLUMNS,
    SPEED_LIMITED_SHARE,
    WizardExport,
    cruise_units_s,
    is_wizard_export,
    read_wizard,
    to_trace,
)

__all__ = ["parse_args", "main", "load_input", "Input", "DEFAULT_GOAL", "DEFAULT_VOLTAGE_V"]

#: Goal Position assumed for a Wizard export that did not plot it (the shared real exports step 0 -> about 500).
DEFAULT_GOAL = 500
#: The AX-12A's model number: the workflow's model is its (other AX-series exports get a note).
AX12A_MODEL_NUMBER = 12
#: Supply assumed for a Wizard export: the AX-12A's recommended 12 V (its 3-cell LiPo / bench supply).
DEFAULT_VOLTAGE_V = 12.0
#: A located goal write this close before the first moved reading is reported as pinned there.
PINNED_S = 0.002
#: The options that supply what a Wizard export does not record (dest names).
_WIZARD_OPTIONS = ("goal", "initial_goal", "onset", "moving_speed", "voltage")
#: Of those, the ones a trace CSV may need too: what it may leave out (``voltage``), not its commands.
_TRACE_OPTIONS = ("voltage",)
#: How far from its goal a servo comes to rest, raw units: within the compliance margin the drive is off and
#: across the slope it grows from nothing, so friction stops the shaft within about margin + slope of the goal
#: (the e-manual's defaults, 1 + 32; the shared real steps rest 1-2 units short of 500).  A recording resting
#: farther from the default goal was stepped to another one.
SETTLES_WITHIN_UNITS = POWER_UP["cw_compliance_margin"] + POWER_UP["cw_compliance_slope"]
#: An export ends moving when its last MOVING_READINGS readings go one way only and cover MOVING_UNITS or more: a
#: still shaft's readings wander a unit or two either way (:func:`.trace.rest_level`) and creep by one, eight of
#: them in one direction by chance hardly ever; a move covers that in a row or a few, even at a low Moving Speed.
MOVING_READINGS = 8
MOVING_UNITS = 3


@dataclass
class Input:
    """The trace the workflow runs on, and what was assumed or counted to make it."""

    trace: Trace
    kind: str
    #: Lines for the report: rows read and skipped, each assumption and how to override it.
    notes: list[str] = field(default_factory=list)
    #: JSON-able facts about the input (format, rows, skipped rows, assumptions).
    facts: dict = field(default_factory=dict)
    #: How the supply the fit runs at is known (:data:`.output.SUPPLY_SOURCES`); None: the trace's columns say.
    supply: str | None = None


class _OneLineParser(argparse.ArgumentParser):
    """argparse, its errors one line on stderr (the bad option, not the usage block; ``--help`` shows that)."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


#: What the workflow does, in a line: its ``--help``'s first words.
DESCRIPTION = ("Find where a measured servo trace and the model disagree, name the missing physical effect and "
               "write a twin that ax12emu serve --params runs.")


def parse_args(argv: list[str] | None = None, prog: str = "python -m firmware_model.diagnose") -> argparse.Namespace:
    """The command line (pure: no I/O); ``prog``: the command the user typed (``ax12emu diagnose`` from the CLI)."""
    p = _OneLineParser(prog=prog, description=DESCRIPTION)
    p.add_argument("trace", metavar="MEASURED.csv",
                   help="measured trace: the project's CSV (firmware_model.diagnose.trace) or a Wizard 2 graph export")
    p.add_argument("--out", required=True, metavar="DIR", help="where report.md, plots and params.toml go")
    p.add_argument("--json", action="store_true", help="print the verdict as one JSON object")
    p.add_argument("--params", metavar="FILE", help="start from these ServoParams (TOML; its [effects] are simulated too) instead of the defaults")
    p.add_argument("--effects", metavar="LIST", help=f"comma-separated subset of: {', '.join(LIBRARY)} "
                                                      f"(X-series traces: {', '.join(X_LIBRARY)})")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.add_argument("--voltage", type=float, metavar="V",
                   help="supply voltage to fit at, in place of a recorded one (a trace CSV's voltage column, a Wizard 2 "
                        "export's Present Voltage: say so where the servo ran past the model's range); default: the "
                        "recording's, else --params' supply_voltage_v, else "
                        f"{DEFAULT_VOLTAGE_V} for a Wizard export and the model's {ServoParams().supply_voltage_v} for a "
                        "trace CSV; ax12emu diagnose gives another AX model's Wizard export (an AX-18A's) that model's "
                        "served parameters as --params, so its served supply")
    w = p.add_argument_group("what a Wizard 2 export does not record (only for such files)")
    w.add_argument("--goal", type=int, metavar="UNITS",
                   help=f"Goal Position written once (default {DEFAULT_GOAL})")
    w.add_argument("--initial-goal", type=int, metavar="UNITS",
                   help="Goal Position before it (default: the first Present Position read)")
    w.add_argument("--onset", type=float, metavar="S",
                   help="when the goal was written, s after the first row read (default: estimated from the first "
                        "movement and fitted)")
    w.add_argument("--moving-speed", type=int, metavar="N", help="Moving Speed register (default 0: full speed)")
    args = p.parse_args(argv)
    if args.effects:
        unknown = [e for e in args.effects.split(",") if e not in LIBRARY and e not in X_LIBRARY]  # the trace's, in main
        if "" in unknown:
            p.error(f"--effects {args.effects!r} has an empty entry (a stray comma?)")
        if unknown:
            p.error(f"unknown effect(s): {', '.join(unknown)}")
    for name in ("goal", "initial_goal", "moving_speed"):
        value = getattr(args, name)
        if value is not None and not 0 <= value <= 1023:
            p.error(f"--{name.replace('_', '-')} must be 0..1023 raw units, got {value}")
    if args.onset is not None and not args.onset == args.onset:
        p.error("--onset must be a number of seconds")
    return args




def load_input(args: argparse.Namespace, params: ServoParams, say=lambda msg: None) -> Input:
    """The trace named on the command line, in either format; raises ValueError / OSError on bad input."""
    given = [f"--{n.replace('_', '-')}" for n in _WIZARD_OPTIONS
             if n not in _TRACE_OPTIONS and getattr(args, n, None) is not None]
    # opened first: a file that cannot be read is neither format, and saying which it is would mislead
    with open(args.trace, "rb"):
        pass
    if not is_wizard_export(args.trace):
        if given:
            raise ValueError(f"{', '.join(given)} {'applies' if len(given) == 1 else 'apply'} only to Wizard 2 graph "
                             f"exports; {args.trace} is a trace CSV, which records its own commands")
        trace = read_trace(args.trace)
        check_span(trace.t, args.trace)
        notes = [f"{args.trace}: trace CSV, {len(trace)} rows"]
        if not trace.records_command_times:
            notes.append("the trace does not say when commands were sent (no command_t): each change's onset is "
                         "fitted within its sample as part of the base model")
        facts = {"format": "trace", "rows": len(trace), "records_command_times": trace.records_command_times}
        trace, supply = _trace_supply(trace, args, params, notes, facts)
        return Input(trace, "trace", notes, facts, supply)
    export = read_wizard(args.trace)  # checked against the workflow's limits as it is read (check_span)
    return _wizard_input(export, args, params, say)


def _trace_supply(trace: Trace, args: argparse.Namespace, params: ServoParams, notes: list[str],
                  facts: dict) -> tuple[Trace, str | None]:
    """The trace with the supply its fit runs at, and how that is known: its voltage column, ``--voltage`` (made
    a column, as a Wizard export's is), else ``params``' supply, said as assumed in ``notes`` and ``facts``."""
    if trace.servo != "ax":
        if args.voltage is not None:  # its model is built from the metadata, which says the supply
            raise ValueError(f"--voltage: {args.trace} is an X-series trace, whose supply is its voltage column or "
                             "#@ supply_v metadata")
        return trace, None
    if args.voltage is not None:
        params.check_supply(args.voltage, "--voltage")
        facts["voltage_v"] = args.voltage
        if trace.has("voltage"):  # the user's word over the recording's: a supply past the model's range, say
            recorded = trace["voltage"] / 10.0
            notes.append(f"--voltage {args.voltage:g} V in place of the recorded {recorded.min():.1f}-{recorded.max():.1f} V")
        return trace.with_columns(voltage=np.full(len(trace), int(round(args.voltage * 10)))), "given"
    if trace.has("voltage"):  # the model is valid over its supply range, as --voltage
        for volts in (float(trace["voltage"].min()) / 10.0, float(trace["voltage"].max()) / 10.0):
            try:
                params.check_supply(volts, f"{args.trace}: the voltage column's")
            except ValueError as exc:  # a servo runs past the model's range (an AX-12A to its 14 V alarm)
                raise ValueError(f"{exc}: give the supply to fit at with --voltage") from None
        return trace, "recorded"
    whose = "--params' supply_voltage_v" if args.params else "the model's default"
    notes.append(f"assumed: {params.supply_voltage_v:.1f} V ({whose}; the trace has no voltage column) — override "
                 "with --voltage")
    facts["voltage_v"], facts["assumed"] = params.supply_voltage_v, [f"{params.supply_voltage_v:.1f} V"]
    return trace, "assumed"


def _check_default_goal(ex: WizardExport) -> None:
    """Refuse to fit an export against :data:`DEFAULT_GOAL` when it comes to rest farther from it than a servo
    settles from its goal: the fit would read the distance as physics (a weak motor, friction) and write a twin
    of it.  Only the user knows the goal written."""
    readings = np.asarray(ex.values["present_position"], dtype=float)
    end = rest_level(readings, end=True)
    off = end - DEFAULT_GOAL
    if abs(off) <= SETTLES_WITHIN_UNITS:
        return
    # An export cut off mid-move, still heading for the default goal from short of it, says nothing against it;
    # one that rests or has passed the goal and goes on does.  Moving: its last readings go one way, never back,
    # and far enough that a pot's noise (a unit or two either way, and a still shaft's creep of one) cannot.
    last = readings[-MOVING_READINGS:]
    steps = np.diff(last)
    heading = float(last[-1] - last[0])
    monotone = bool(np.all(steps >= 0) or np.all(steps <= 0))
    moving = monotone and abs(heading) >= MOVING_UNITS
    if moving and heading * off < 0:
        return
    if moving:
        where = f"ends moving away from the default goal {DEFAULT_GOAL}, at {last[-1]:g}"
    else:
        where = f"comes to rest at {end:g}, {abs(off):g} units from the default goal {DEFAULT_GOAL}"
    raise ValueError(f"{ex.source}: the export {where} (a servo rests within {SETTLES_WITHIN_UNITS} of its goal): give "
                     "the Goal Position written with --goal")


#: The Wizard flags that stand in for a plotted item, and the trace column each replaces.
#: (``--voltage`` is not among them: it takes a recorded supply's place, as for a trace CSV, since a servo runs past
#: the model's supply range.)
_FLAG_COLUMNS = {"goal": "goal_position", "initial_goal": "goal_position", "onset": "goal_position",
                 "moving_speed": "moving_speed"}


def _wizard_input(ex: WizardExport, args: argparse.Namespace, params: ServoParams, say) -> Input:
    for flag, column in _FLAG_COLUMNS.items():
        if getattr(args, flag) is not None and column in ex.values:  # it was used silently, the recording won
            item = next(item for item, col in ITEM_COLUMNS.items() if col == column)
            raise ValueError(f"--{flag.replace('_', '-')}: the export records {item}; the flag stands in for it only "
                             "where it does not")
    goal = DEFAULT_GOAL if args.goal is None else args.goal
    speed = 0 if args.moving_speed is None else args.moving_speed
    # Unsaid, the supply is the parameter file's (a twin's params.toml carries the supply it was fitted at), else 12 V.
    volts = args.voltage if args.voltage is not None else params.supply_voltage_v if args.params else DEFAULT_VOLTAGE_V
    params.check_supply(volts, "--voltage")
    in_place_of = None  # the recorded supply --voltage replaces
    if "voltage" in ex.values:  # what the servo ran at: within the model's range, as --voltage is
        recorded_v = float(np.median(ex.values["voltage"])) / 10.0
        if args.voltage is not None:
            in_place_of = recorded_v
        else:
            try:
                params.check_supply(recorded_v, f"{ex.source}: the recorded Present Voltage (median)")
            except ValueError as exc:  # a servo runs past the model's range (an AX-12A to its 14 V alarm)
                raise ValueError(f"{exc}: give the supply to fit at with --voltage") from None
            volts = recorded_v
    if "present_position" not in ex.values:
        raise ValueError(f"{ex.source}: the export has no Present Position column: nothing to compare the model with")
    if args.goal is None and "goal_position" not in ex.values:
        _check_default_goal(ex)
    initial = int(ex.values["present_position"][0]) if args.initial_goal is None else args.initial_goal

    def build(onset_s: float, known: bool = False) -> Trace:
        trace = to_trace(ex, goal, onset_s, speed, volts, initial, onset_known=known)
        if in_place_of is None:
            return trace
        return trace.with_columns(voltage=np.full(len(trace), int(round(volts * 10)), dtype=np.int64))

    recorded = [c for c in ("goal_position", "moving_speed", "voltage") if c in ex.values]
    facts = {"format": "wizard", "model": ex.model_name, "rows_seen": ex.rows_seen, "rows_read": ex.rows_read,
             "skipped": dict(ex.skipped), "items_ignored": list(ex.ignored_items), "recorded": recorded,
             "reading_period_s": ex.read_period_s, "rows_on_reading_clock": ex.read_share if ex.read_s is not None else None}
    notes = [ex.summary()]
    if in_place_of is not None:
        notes.append(f"--voltage {volts:g} V in place of the recorded {in_place_of:.1f} V (median)")
    if ex.model_number != AX12A_MODEL_NUMBER and args.params is None:
        notes.append(f"the export is from an {ex.model_name}; the model is an AX-12A's (its parameters are not "
                     "that servo's unless --params says otherwise)")
    assumed = []
    if "goal_position" not in ex.values:
        assumed.append(f"goal {goal} written once (from {initial}"
                       + (")" if args.initial_goal is not None else ", the first reading)"))
        facts["goal"], facts["initial_goal"] = goal, initial
        if args.onset is not None:
            if not 0.0 <= args.onset < float(ex.t_s[-1]):  # a write outside the recording leaves nothing to fit
                raise ValueError(f"--onset {args.onset:g}: the goal must be written within the recording, "
                                 f"0..{float(ex.t_s[-1]):.3f} s from its first row")
            trace = build(args.onset, known=True)
            assumed.append(f"written at {args.onset:.3f} s (given, so known)")
            facts["onset_s"], facts["onset_source"] = args.onset, "given"
        else:
            guess = first_movement_onset(build(0.0), params)
            onset, trace = locate_onset(build, params, guess)
            say(f"goal write estimated at {onset:.3f} s (first movement suggests {guess:.3f} s)")
            assumed.append(f"written at an unrecorded time, estimated {onset:.3f} s from the first movement and "
                           "re-fitted with the model (not an effect)")
            facts["onset_s"], facts["onset_source"] = onset, "estimated"
            probe = build(0.0)
            moved_s = float(probe.t[first_movement_row(probe)])
            facts["first_movement_s"] = moved_s
            if onset >= moved_s - PINNED_S:
                notes.append(f"the goal write is pinned just before the first reading that shows movement "
                             f"({moved_s:.3f} s): the model would fit it later, i.e. it starts moving later after a "
                             "write than this servo did")
    else:
        trace = build(0.0)
    if "moving_speed" not in ex.values:
        assumed.append(f"Moving Speed {speed}" + (" (full speed)" if speed == 0 else ""))
        facts["moving_speed"] = speed
        if args.moving_speed is None:
            notes += _cruise_notes(ex, params, volts, facts)
    if "voltage" not in ex.values:
        assumed.append(f"{volts:.1f} V")
        facts["voltage_v"] = volts
    if assumed:
        notes.append("assumed: " + ", ".join(assumed)
                     + " — override with --goal, --initial-goal, --onset, --moving-speed, --voltage")
    facts["assumed"] = assumed
    supply = "given" if args.voltage is not None else "recorded" if "voltage" in ex.values else "assumed"
    return Input(trace, "wizard", notes, facts, supply)


def _cruise_notes(ex: WizardExport, params: ServoParams, volts: float, facts: dict) -> list[str]:
    """Where a step assumed at full speed cruised well below the model's top speed at the assumed supply: the
    supply or the Moving Speed that would make the model cruise so (the supply only where the servo runs at it).

    Why a note and not a fitted nuisance: both are settings of the user's, which the export does not record, so
    the user is asked for them (``--voltage``, ``--moving-speed``), as for the goal."""
    try:
        cruise = cruise_units_s(ex.times_s, ex.values["present_position"])
    except ValueError:
        return []
    facts["cruise_units_s"] = cruise
    top = params.top_speed_rad_s(volts) / float(RAD_PER_POSITION_UNIT)
    if cruise >= SPEED_LIMITED_SHARE * top:
        return []
    cruise_rad_s = cruise * float(RAD_PER_POSITION_UNIT)
    suggested = int(speed_rad_s_to_raw(cruise_rad_s))
    supply_v = params.supply_for_top_speed_v(cruise_rad_s)
    why = f"a Moving Speed of about {suggested} (--moving-speed)"
    if supply_v >= params.min_supply_voltage_v:
        why = f"a lower supply, about {supply_v:.1f} V (--voltage), or " + why
    return [f"the step cruises at {cruise:.0f} units/s, {100 * cruise / top:.0f} % of the model's top speed at "
            f"{volts:.1f} V: {why} would explain it"]


def _recording_notes(d: Diagnosis, trace: Trace) -> list[str]:
    out = [f"recording traits fitted with the base model (not effects): {d.recording}"]
    out += [f"not offered: {name} ({why})" for name, why in d.not_offered.items()]
    return out


def _insert_input_section(report: Path, notes: list[str]) -> None:
    """Put an "Input and assumptions" section after the report's verdict."""
    text = report.read_text(encoding="utf-8")
    section = "## Input and assumptions\n\n" + "\n".join(f"* {n}" for n in notes) + "\n\n"
    at = text.find("## Named effects")
    report.write_text(text[:at] + section + text[at:] if at >= 0 else text + "\n" + section, encoding="utf-8")


def _cannot_write(out: str, exc: OSError, what: str | None = None) -> str:
    """The one line for an ``--out`` that could not be written: ``what`` (default: the file the error names)."""
    if what is None:
        what = Path(exc.filename).name if isinstance(exc.filename, str) else "its files"
    return f"--out {out}: cannot write {what} ({exc.strerror or exc})"


def _check_out(out: str) -> None:
    """Refuse an ``--out`` that is not a folder this process can write, before the fit rather than after it: the
    folder is made and a file created and removed in it."""
    if Path(out).exists() and not Path(out).is_dir():
        raise ValueError(f"--out {out}: exists and is not a folder")
    try:
        Path(out).mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".diagnose-probe-"):
            pass
    except OSError as exc:
        raise ValueError(_cannot_write(out, exc, "a file in it")) from None


def _write_results(args: argparse.Namespace, data: Input, d: Diagnosis, params: ServoParams, notes: list[str]) -> dict:
    """Write the report, plots, params.toml and verdict.json into ``--out``; return the verdict (JSON-able)."""
    write_outputs(data.trace, d, args.out, source=args.trace, params=params, supply=data.supply)
    _insert_input_section(Path(args.out) / "report.md", notes)
    verdict = verdict_json(d)
    verdict["input"] = data.facts
    verdict["recording"] = {"hold_phase_s": d.nuisance.hold_phase_s, "onsets_fitted": d.nuisance.onsets_fitted,
                            "not_offered": d.not_offered}
    verdict = json_safe(verdict)
    (Path(args.out) / "verdict.json").write_text(json.dumps(verdict, indent=2, allow_nan=False), encoding="utf-8")
    return verdict


def main(argv: list[str] | None = None, prog: str = "python -m firmware_model.diagnose") -> int:
    """Run the workflow; exit 2 on a malformed trace or a bad option for it."""
    args = parse_args(argv, prog)
    progress = None if args.quiet else (lambda msg: print(msg, file=sys.stderr, flush=True))
    say = progress or (lambda msg: None)
    try:
        params = ServoParams.from_toml(args.params) if args.params else ServoParams()
        check_step(params, CONTROL_STEP_S)  # the fit steps the physics as the served servo does: too stiff, refused now
        null_knobs(params)  # the fit simulates the file's [effects] too: refuse one it cannot, before any work
        data = load_input(args, params, say)
        _check_out(args.out)
    except (TraceFormatError, ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for note in data.notes:
        say(note)
    family = family_of(data.trace)
    wanted = args.effects.split(",") if args.effects else None
    missing = [e for e in wanted or () if e not in family.library]
    if missing:
        print(f"error: {', '.join(missing)} not in the {family.name} servos' library ({', '.join(family.library)})",
              file=sys.stderr)
        return 2
    if family.name != "ax" and args.params:
        print("error: --params holds an AX-12's ServoParams; an X-series trace's model comes from its metadata",
              file=sys.stderr)
        return 2
    try:  # an X-series trace's data sheet (#@ gear_ratio, ratings) is read when its model is built
        d = diagnose(data.trace, params if family.name == "ax" else None, progress=say, effects=wanted)
    except TraceFormatError as exc:
        print(f"error: {args.trace}: {exc}", file=sys.stderr)
        return 2
    notes = data.notes + _recording_notes(d, data.trace)
    try:  # checked writable before the fit; a disk filling up or a folder changed since is still one line
        verdict = _write_results(args, data, d, params, notes)
    except OSError as exc:
        print(f"error: {_cannot_write(args.out, exc)}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(verdict, allow_nan=False))
    else:
        print("\n".join(notes[1:] if data.kind == "trace" else notes))
        print(verdict_text(d))
    return 0
