"""The measured-trace CSV format: one reader and one writer, side by side.

Why it exists: a trace is the one thing a user with hardware (or anyone's
log) hands the diagnosis workflow, so its format is small, plain and checked
with errors that say where a file is wrong.

Format
------
A header line naming the columns, then one row per sample, comma-separated.
Values are raw control-table units as a client reads them::

    t,goal_position,moving_speed,present_position,present_speed,present_load
    0.000000,512,0,512,0,0
    0.010000,600,200,513,12,-80

* ``t`` (s, required): when the row's sensed columns were read; strictly
  increasing.  The replay's time origin is the first row's ``t``.
* ``goal_position`` (0..1023), ``moving_speed`` (0..1023; 0 = full speed)
  (required): the registers *in effect from* ``t`` on (written at ``t``, after
  the reading, or earlier).
* ``present_position`` (0..1023, required).
* ``present_speed``, ``present_load`` (optional): **signed** integers,
  positive when the position increases (not the register's bit-10 form:
  ``-80`` rather than ``1104``), -1023..1023.
* ``torque_limit`` (0..1023), ``voltage`` (0.1 V units), ``external_torque_nm``
  (N m, positive CCW) (optional): what was applied from ``t`` on.
* ``command_t`` (s, optional): when the row's commands were sent, on the
  clock of ``t``.  Read only on rows whose commands differ from the row
  before, where it must lie after the previous row's ``t`` and before the
  next row's.  With it the trace *records when commands were given*: the
  replay applies each change at that time, and a latency between the shaft
  and the reading (the ``delay`` effect) can be told apart from it.  Without
  it a change is only known to fall somewhere between its row's reading and
  the next one, and the workflow fits when as a property of the recording
  (:mod:`.nuisance`), never as an effect.

Blank lines and lines starting with ``#`` are ignored (comments), except
``#@ key = value`` lines: metadata (:attr:`Trace.meta`), the value in JSON.
Any other problem raises :class:`TraceFormatError` naming the line and the
column.

X-series traces (Protocol 2.0)
------------------------------
A trace whose metadata says ``#@ servo = "x"`` is an X-series servo's, in
its own control table's units (e-manual, X-series "Control Table"): the same
layout with the X registers' columns (:data:`X_COLUMNS`):

* ``goal_position``, ``present_position`` (required): pulses, 4096 per turn
  (signed 32-bit: extended position mode counts turns);
* ``present_velocity`` (0.229 rpm), ``present_current`` (the model's current
  unit: 1 mA on the XL330) or ``present_pwm`` (0.113 %, 885 = full duty): the
  load column is whichever of the two the recording read;
* ``profile_velocity``, ``profile_acceleration``, ``torque_enable``,
  ``voltage``, ``external_torque_nm``, ``command_t``: as above, commands in
  effect from ``t`` (or ``command_t``) on.

What does not change within a recording is metadata (:data:`X_META`): the
operating mode and the gains, the data sheet the physics is built from (gear
ratio, ratings, current unit) and what was on the horn.  Each value is checked
as it is read, like a cell: a key :data:`X_META` does not list (a misspelt
gain would leave the gain at its default), a value of the wrong JSON type or
one no servo has (a register outside its range, a supply in mV) is a
:class:`TraceFormatError` naming its line and key.  Example::

    #@ servo = "x"
    #@ model = "XL330-M288"
    #@ gear_ratio = 288.4
    #@ ratings = [[5.0, 0.52, 1.47, 103]]
    #@ current_unit_a = 0.001
    #@ operating_mode = 3
    #@ position_p_gain = 400
    t,goal_position,present_position,present_velocity,present_pwm,command_t
"""

from __future__ import annotations

import csv
import difflib
import io
import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..xseries.interface import POSITION_MODES

__all__ = ["Trace", "TraceFormatError", "read_trace", "write_trace", "check_span", "MAX_ROWS", "MAX_SPAN_S", "REQUIRED", "OPTIONAL", "COLUMNS",
           "COMMAND_COLUMNS", "command_time_errors", "TraceColumns", "FORMATS", "X_COLUMNS", "X_META", "REST_READINGS",
           "rest_level", "departures", "MetaKey", "x_meta_error", "SUPPLY_RATING_SHARE"]

#: Columns every trace has, in the order the writer uses.
REQUIRED = ("t", "goal_position", "moving_speed", "present_position")
#: Columns a trace may have.
OPTIONAL = ("present_speed", "present_load", "torque_limit", "voltage", "external_torque_nm", "command_t")
COLUMNS = REQUIRED + OPTIONAL
#: Inclusive ranges of the integer columns.
_INT_RANGES = {
    "goal_position": (0, 1023), "moving_speed": (0, 1023), "present_position": (0, 1023),
    "present_speed": (-1023, 1023), "present_load": (-1023, 1023), "torque_limit": (0, 1023), "voltage": (0, 255),
}
_FLOAT_COLUMNS = ("t", "external_torque_nm", "command_t")
#: Bounds of the float columns that are not times: a torque on the horn beyond 100 N m (some forty times the
#: largest stall torque served) is a unit slip, and a simulation of it only overflows.
_FLOAT_RANGES = {"external_torque_nm": (-100.0, 100.0)}
#: Columns that are commands (a change in any of them is a command change).
COMMAND_COLUMNS = ("goal_position", "moving_speed", "torque_limit", "voltage", "external_torque_nm")

_INT32 = (-(2**31), 2**31 - 1)

#: Readings at either end of a recording whose median is the level it rests at there.
REST_READINGS = 5


def rest_level(values: np.ndarray, end: bool = False) -> float:
    """Where a recording rests at its start (``end``: at its end): the median of its first (last) few readings.

    Why not the first (last) reading itself: a pot's noise puts a reading at rest a unit or two off, and a
    first reading two units off made every later reading at rest look like a movement.
    """
    v = np.asarray(values, dtype=float)
    k = max(1, min(REST_READINGS, len(v) // 4))  # a short trace's first readings may already be its move
    return float(np.median(v[-k:] if end else v[:k]))


def departures(values: np.ndarray, units: float) -> np.ndarray:
    """Indices of the readings ``units`` or more from where the recording rests at first (:func:`rest_level`) whose
    next reading is too (the last reading needs no next): a lone reading that far, back at rest the next time, is
    the pot's noise, not a movement."""
    v = np.asarray(values, dtype=float)
    away = np.abs(v - rest_level(v)) >= units
    return np.flatnonzero(away & np.append(away[1:], True))


@dataclass(frozen=True)
class TraceColumns:
    """One servo family's columns: required, optional, integer ranges, and which are commands."""

    required: tuple[str, ...]
    optional: tuple[str, ...]
    int_ranges: dict[str, tuple[int, int]]
    commands: tuple[str, ...]

    @property
    def columns(self) -> tuple[str, ...]:
        return self.required + self.optional


#: X-series columns (e-manual, X-series control table: Goal Position(116) within +-1,048,575 in extended
#: position mode, Present Position(132) a signed 4-byte count, Present PWM(124) within +-885, Profile
#: Velocity/Acceleration(112, 108) 0..32767).
X_COLUMNS = TraceColumns(
    required=("t", "goal_position", "present_position"),
    optional=("present_velocity", "present_current", "present_pwm", "profile_velocity", "profile_acceleration",
              "torque_enable", "voltage", "external_torque_nm", "command_t"),
    int_ranges={"goal_position": (-1_048_575, 1_048_575), "present_position": _INT32, "present_velocity": _INT32,
                "present_current": (-32768, 32767), "present_pwm": (-885, 885), "profile_velocity": (0, 32767),
                "profile_acceleration": (0, 32767), "torque_enable": (0, 1), "voltage": (0, 255)},
    commands=("goal_position", "profile_velocity", "profile_acceleration", "torque_enable", "voltage",
              "external_torque_nm"),
)
#: Column sets by the ``servo`` metadata value (absent: the AX-12's).
FORMATS = {"ax": TraceColumns(REQUIRED, OPTIONAL, _INT_RANGES, COMMAND_COLUMNS), "x": X_COLUMNS}
#: A supply is taken as the X-series servo's from this share of its data sheet's lowest rated voltage to this share
#: of its highest: the physics is built from the ratings and scales with the supply a little beyond them (the
#: real XL330 pendulum logs ran at 7.4 V, 1.23 times its highest rating), while a supply off by half or more is a
#: slip of unit (mV) or another servo's sheet.
SUPPLY_RATING_SHARE = (0.5, 1.5)
#: The position controller's registers' range (e-manual, X-series control table: Position P/I/D Gain(84, 82, 80),
#: Feedforward 1st/2nd Gain(90, 88)).
_GAIN_RANGE = (0, 16383)


def _is_number(value: object) -> bool:
    """A finite JSON number (not true/false, which JSON keeps apart and Python would count as 1 and 0)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _whole(low: int, high: int, what: str = "the register's range") -> Callable[[object, dict], str | None]:
    def check(value: object, meta: dict) -> str | None:
        if _is_number(value) and value == int(value) and low <= value <= high:
            return None
        return f"must be a whole number {low}..{high} ({what})"
    return check


def _one_of(values: tuple[int, ...], why: str) -> Callable[[object, dict], str | None]:
    def check(value: object, meta: dict) -> str | None:
        return None if _is_number(value) and value in values else f"must be one of {', '.join(map(str, values))}: {why}"
    return check


def _number(low: float, high: float = math.inf, low_open: bool = False, unit: str = "") -> Callable[[object, dict], str | None]:
    def check(value: object, meta: dict) -> str | None:
        if _is_number(value) and (low < value if low_open else low <= value) and value <= high:
            return None
        bound = (f"above {low:g}" if low_open else f"of at least {low:g}") if high == math.inf else f"in {low:g}..{high:g}"
        return f"must be a number {bound}{unit}"
    return check


def _text(value: object, meta: dict) -> str | None:
    return None if isinstance(value, str) else "must be a JSON string"


def _unit(value: object, meta: dict) -> str | None:
    ok = value is None or (_is_number(value) and value > 0)
    return None if ok else "must be a number of A above 0 (0.001: 1 mA), or null where the servo senses no current"


def _ratings(value: object, meta: dict) -> str | None:
    rows = value if isinstance(value, list) and value else [None]
    if all(isinstance(r, list) and len(r) == 4 and all(_is_number(x) and x > 0 for x in r) for r in rows):
        return None
    return "must be [[voltage_v, stall_torque_nm, stall_current_a, no_load_speed_rpm], ...], all above 0"


def _supply(value: object, meta: dict) -> str | None:
    if not _is_number(value) or value <= 0:
        return "must be a number of volts above 0"
    ratings = meta.get("ratings")
    if _ratings(ratings, meta) is not None:  # no sheet to compare with: the missing sheet is said when it is used
        return None
    volts = [r[0] for r in ratings]
    low, high = SUPPLY_RATING_SHARE[0] * min(volts), SUPPLY_RATING_SHARE[1] * max(volts)
    if low <= value <= high:
        return None
    return (f"{value:g} V is outside {low:g}..{high:g} V, where the data sheet's ratings ({', '.join(f'{v:g}' for v in volts)} V) "
            "hold (a supply in mV?)")


class MetaKey(NamedTuple):
    """One X-series metadata key: what it means, and its check (``check(value, meta)``: None, or why not)."""

    meaning: str
    check: Callable[[object, dict], str | None]


#: X-series metadata keys (the values are JSON): what each means and what it may be; any other key is an error.
X_META = {
    "servo": MetaKey('"x"', _text),
    "model": MetaKey("the model's name, for the report", _text),
    "gear_ratio": MetaKey("the data sheet's gear ratio", _number(0.0, low_open=True)),
    "ratings": MetaKey("the data sheet's [[voltage_v, stall_torque_nm, stall_current_a, no_load_speed_rpm], ...]",
                       _ratings),
    "current_unit_a": MetaKey("Present Current's unit, A (null: no current sensing, the XL430)", _unit),
    "position_output_scale": MetaKey("the position controller's output against the e-manual's (0.5 measured on the "
                                     "XL330)", _number(0.0, low_open=True)),
    "operating_mode": MetaKey("Operating Mode(11): 3 position, 4 extended position, 5 current-based position",
                              _one_of(POSITION_MODES, "the diagnosis replays the position modes, whose command is "
                                                      "Goal Position")),
    **{key: MetaKey(f"{name} as set", _whole(*_GAIN_RANGE)) for key, name in (
        ("position_p_gain", "Position P Gain(84)"), ("position_i_gain", "Position I Gain(82)"),
        ("position_d_gain", "Position D Gain(80)"), ("feedforward_1st_gain", "Feedforward 1st Gain(90)"),
        ("feedforward_2nd_gain", "Feedforward 2nd Gain(88)"))},
    "pwm_limit": MetaKey("PWM Limit(36) as set", _whole(0, 885)),
    # the largest Current Limit and Velocity Limit of the X series' tables are well under these register widths
    "current_limit": MetaKey("Current Limit(38) as set", _whole(0, 32767)),
    "velocity_limit": MetaKey("Velocity Limit(44) as set", _whole(0, 32767)),
    "drive_mode": MetaKey("Drive Mode(10) as set", _whole(0, 13, "bits 0, 2 and 3")),
    "supply_v": MetaKey("the supply, V, where the trace has no voltage column", _supply),
    "load_inertia_kg_m2": MetaKey("an inertia on the horn", _number(0.0, unit=" kg m^2")),
    "gravity_moment_nm": MetaKey("a pendulum on the horn (m g l), hanging down at gravity_zero_pulses",
                                 _number(0.0, unit=" N m")),
    "gravity_zero_pulses": MetaKey("where the pendulum hangs down, pulses (default 2048)",
                                   _number(-(2**31), 2**31 - 1, unit=" pulses")),
}


def x_meta_error(meta: dict) -> tuple[str, str] | None:
    """The first X-series metadata key that :data:`X_META` does not list or whose value it refuses, with why, as
    (key, message); None if every key is well.  The keys are checked in the file's order."""
    for key, value in meta.items():
        if key not in X_META:
            near = difflib.get_close_matches(key, X_META, n=1)
            hint = f"did you mean {near[0]}?" if near else f"the keys are {', '.join(X_META)}"
            return key, f"#@ {key}: not an X-series metadata key ({hint})"
        why = X_META[key].check(value, meta)
        if why is not None:
            if isinstance(value, str) and X_META[key].check is not _text:
                why += "; write it as a JSON number, without quotes or unit"
            shown = json.dumps(value)
            return key, f"#@ {key} = {shown if len(shown) <= 40 else shown[:37] + '...'}: {why}"
    return None


class TraceFormatError(ValueError):
    """A malformed trace; ``line`` (1-based) and ``column`` (name) say where, when known."""

    def __init__(self, message: str, line: int | None = None, column: str | None = None, source: str = "trace") -> None:
        where = source + (f":{line}" if line is not None else "") + (f": column {column!r}" if column is not None else "")
        super().__init__(f"{where}: {message}")
        self.line, self.column = line, column


@dataclass
class Trace:
    """A trace in memory: ``columns`` maps each present column name to an array of shape (n,)."""

    columns: dict[str, np.ndarray]
    #: Comment lines (without ``#``) kept from the file, e.g. the tool that made it.
    comments: list[str] = field(default_factory=list)
    #: Metadata (``#@ key = value`` lines): the servo family and what does not change within the recording.
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        servo = self.meta.get("servo", "ax")
        if not isinstance(servo, str) or servo not in FORMATS:
            raise TraceFormatError(f"unknown servo {servo!r} (known: {', '.join(FORMATS)})")
        missing = [c for c in self.format.required if c not in self.columns]
        if missing:
            raise TraceFormatError(f"missing required column(s) {', '.join(missing)}")
        lengths = {len(v) for v in self.columns.values()}
        if len(lengths) != 1:
            raise TraceFormatError(f"columns differ in length: {sorted(lengths)}")
        self.columns = {k: np.asarray(v, dtype=float if k in _FLOAT_COLUMNS else np.int64) for k, v in self.columns.items()}

    def __len__(self) -> int:
        return len(self.columns["t"])

    @property
    def servo(self) -> str:
        """The servo family (``"ax"``, ``"x"``), from the metadata."""
        return str(self.meta.get("servo", "ax"))

    @property
    def format(self) -> TraceColumns:
        """This trace's column set."""
        return FORMATS[self.servo]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def has(self, name: str) -> bool:
        """Whether the trace carries column ``name``."""
        return name in self.columns

    @property
    def t(self) -> np.ndarray:
        """Sample times relative to the first row, seconds."""
        return self.columns["t"] - self.columns["t"][0]

    @property
    def records_command_times(self) -> bool:
        """Whether the trace says when each command was sent (a ``command_t`` column)."""
        return "command_t" in self.columns

    def change_rows(self) -> np.ndarray:
        """Rows whose commands differ from the row before (row 0 included), shape (m,)."""
        changed = np.zeros(len(self), dtype=bool)
        changed[0] = True
        for name in self.format.commands:
            if name in self.columns:
                changed[1:] |= self.columns[name][1:] != self.columns[name][:-1]
        return np.flatnonzero(changed)

    def with_columns(self, **columns: np.ndarray) -> "Trace":
        """A copy with some columns replaced or added (e.g. simulated sensed values)."""
        return Trace({**self.columns, **columns}, list(self.comments), dict(self.meta))


def _parse(text: str, name: str, line: int, source: str, fmt: TraceColumns = FORMATS["ax"]) -> float | int:
    """One cell, checked against its column's type and range."""
    text = text.strip()
    if name in _FLOAT_COLUMNS:
        try:
            value = float(text)
        except ValueError:
            raise TraceFormatError(f"{text!r} is not a number", line, name, source) from None
        if not math.isfinite(value):
            raise TraceFormatError(f"{text!r} is not finite", line, name, source)
        low, high = _FLOAT_RANGES.get(name, (-math.inf, math.inf))
        if not low <= value <= high:
            raise TraceFormatError(f"{value:g} is outside {low:g}..{high:g}", line, name, source)
        return value
    try:
        value = int(text)
    except ValueError:
        raise TraceFormatError(f"{text!r} is not an integer", line, name, source) from None
    low, high = fmt.int_ranges[name]
    if not low <= value <= high:
        raise TraceFormatError(f"{value} is outside {low}..{high}", line, name, source)
    return value


def read_trace(path: str | Path) -> Trace:
    """Read and validate a trace file; raise :class:`TraceFormatError` with line and column on any problem."""
    path = Path(path)
    try:  # utf-8-sig: a spreadsheet's "CSV UTF-8" starts with a byte-order mark, which would join the first column's name
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise TraceFormatError(f"not UTF-8 text ({exc.reason})", source=str(path)) from None
    return parse_trace(text, source=str(path))


def parse_trace(text: str, source: str = "trace") -> Trace:
    """:func:`read_trace` on a string (``source`` names it in errors)."""
    comments: list[str] = []
    meta: dict = {}
    meta_lines: dict[str, int] = {}
    fmt = FORMATS["ax"]
    header: list[str] | None = None
    rows: list[list[float | int]] = []
    data_lines: list[int] = []
    for line_no, raw in enumerate(io.StringIO(text), start=1):
        stripped = raw.strip()
        if not stripped:
            continue
        if stripped.startswith("#@"):
            key, sep, value = stripped[2:].partition("=")
            try:
                if not sep or header is not None:
                    raise ValueError("metadata is '#@ key = JSON value', before the header")
                meta[key.strip()] = json.loads(value)
                meta_lines[key.strip()] = line_no
            except ValueError as exc:
                raise TraceFormatError(f"bad metadata: {exc}", line_no, None, source) from None
            servo = meta.get("servo", "ax")
            if not isinstance(servo, str) or servo not in FORMATS:
                raise TraceFormatError(f"unknown servo {servo!r} (known: {', '.join(FORMATS)})", line_no, None, source)
            fmt = FORMATS[meta.get("servo", "ax")]
            continue
        if stripped.startswith("#"):
            comments.append(stripped[1:].strip())
            continue
        cells = next(csv.reader([stripped]))
        if header is None:
            bad_meta = x_meta_error(meta) if fmt is X_COLUMNS else None
            if bad_meta:  # all of it read (the servo may be named last), before any row
                raise TraceFormatError(bad_meta[1], meta_lines[bad_meta[0]], None, source)
            header = [c.strip() for c in cells]
            for col in header:
                if not col:
                    raise TraceFormatError("an empty column name (a trailing comma?)", line_no, col, source)
                if col not in fmt.columns:
                    raise TraceFormatError(f"unknown column (known: {', '.join(fmt.columns)})", line_no, col, source)
            dup = {c for c in header if header.count(c) > 1}
            if dup:
                raise TraceFormatError("column appears twice", line_no, sorted(dup)[0], source)
            for col in fmt.required:
                if col not in header:
                    raise TraceFormatError("required column missing from the header", line_no, col, source)
            continue
        if len(cells) != len(header):
            raise TraceFormatError(f"expected {len(header)} values, got {len(cells)}", line_no, None, source)
        row = [_parse(cell, name, line_no, source, fmt) for cell, name in zip(cells, header)]
        t = row[header.index("t")]
        if rows and not t > rows[-1][header.index("t")]:
            raise TraceFormatError(f"time {t} does not increase", line_no, "t", source)
        rows.append(row)
        data_lines.append(line_no)
    if header is None:
        raise TraceFormatError("empty file: no header", source=source)
    if len(rows) < 2:
        raise TraceFormatError("need at least two rows", source=source)
    data = np.array(rows, dtype=float)
    trace = Trace({name: data[:, i] for i, name in enumerate(header)}, comments, meta)
    bad = command_time_errors(trace)
    if len(bad):
        row = int(bad[0])
        line = data_lines[row]
        raise TraceFormatError("a command change's time must lie after the previous row's t and before the next "
                               "row's", line, "command_t", source)
    return trace


def command_time_errors(trace: Trace) -> np.ndarray:
    """Rows (0-based) whose command change has a ``command_t`` outside (previous row's t, next row's t)."""
    if not trace.has("command_t"):
        return np.zeros(0, dtype=np.int64)
    t, ct = trace["t"], trace["command_t"]
    rows = trace.change_rows()
    rows = rows[rows > 0]
    nxt = np.append(t, np.inf)[rows + 1]
    return rows[~((ct[rows] > t[rows - 1]) & (ct[rows] < nxt))]


def write_trace(trace: Trace, path: str | Path) -> None:
    """Write ``trace`` in the format above (known columns in canonical order, comments first)."""
    names = [c for c in trace.format.columns if trace.has(c)]
    out = io.StringIO()
    for comment in trace.comments:
        out.write(f"# {comment}\n")
    for key, value in trace.meta.items():
        out.write(f"#@ {key} = {json.dumps(value)}\n")
    out.write(",".join(names) + "\n")
    cols = [trace[c] for c in names]
    for i in range(len(trace)):
        cells = []
        for name, col in zip(names, cols):
            if name == "t":
                cells.append(f"{col[i]:.6f}")
            elif name in _FLOAT_COLUMNS:
                cells.append(repr(float(col[i])))
            else:
                cells.append(str(int(col[i])))
        out.write(",".join(cells) + "\n")
    Path(path).write_text(out.getvalue(), encoding="utf-8")


#: The longest recording the workflow simulates (s): every fit steps the model through all of it at 1 kHz for
#: dozens of parameter sets at once, and the arrays grow with it (a 3,000 s trace took 4.6 GB).  Recordings the
#: workflow is meant for last seconds to a minute or two; a longer span is usually a time column in ms, not s.
MAX_SPAN_S = 300.0


#: The most rows the workflow reads: it holds every row for dozens of parameter sets at once, about 3 GB per
#: 100,000 rows (120 s logged at 1 kHz took 3.4 GB); the span's limit alone let a 300 s log at 1 kHz ask for 8.5.
MAX_ROWS = 100_000


def check_span(t_s: np.ndarray, source: str, unit_s: float = 1.0) -> None:
    """ValueError naming the widest gap when the rows span more than :data:`MAX_SPAN_S` (times in ``unit_s``), or
    when they are more than :data:`MAX_ROWS`."""
    if len(t_s) > MAX_ROWS:
        every = -(-len(t_s) // MAX_ROWS)
        raise ValueError(f"{source}: {len(t_s):,} rows, more than the {MAX_ROWS:,} the workflow holds in memory; keep "
                         f"one row in {every} (or cut the recording)")
    span_s = float(t_s[-1] - t_s[0]) * unit_s if len(t_s) else 0.0
    if span_s > MAX_SPAN_S:
        widest = int(np.argmax(np.diff(t_s))) + 1
        raise ValueError(f"{source}: the rows span {span_s:.6g} s, more than the {MAX_SPAN_S:g} s the workflow "
                         f"simulates (the widest gap: row {widest + 1} of the data, from {t_s[widest - 1]:.6g} to "
                         f"{t_s[widest]:.6g}); cut the recording, or check the time column's unit")
