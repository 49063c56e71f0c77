"""DYNAMIXEL Wizard 2 graph exports ("DYNAMIXEL Graph" CSV), read as they are.

Why it exists: most people who own an AX-12 have Wizard 2, not a logging
script, and its graph view exports exactly what the diagnosis workflow
needs (a measured trajectory) in its own format, with its own flaws.  This
module reads that format and nothing else; turning an export into a
:class:`~firmware_model.diagnose.trace.Trace` needs what the file does not
record (the goal, when it was written, Moving Speed, the supply), which
:func:`to_trace` takes as arguments and the command line asks for.

Format (Wizard 2's graph export)::

    DYNAMIXEL Graph,2                    <- magic and format version
    AX-12A,12                            <- model name, model number
    ItemCount,1                          <- how many items were plotted
    Present Position,#ffff00,0,1,0       <- one line per item: name, colour, display settings
    Time[ms],Present Position            <- column header: time, then the items in the same order
    0,1                                  <- one row per sample, about 16 ms apart
    96,1
    ...

Samples are whatever the Wizard's polling loop got: about 16 ms apart, with
gaps, and with a few rows garbled (a lost field or digit: ``499`` alone,
``5,499`` between ``2496`` and ``2512``) or repeating an earlier time.  Such
rows are skipped and counted (:attr:`WizardExport.skipped`, with the line
numbers in :attr:`WizardExport.skipped_lines`), never guessed at: a row is
kept only if every field parses and its time is later than the last kept
row's.  Anything wrong with the header is an error
(:class:`WizardFormatError`, a ``ValueError`` naming the file and line), and
so is a file with under two readable rows (naming the first skipped row and
why it was skipped).

**Re-saved by a spreadsheet.**  Empty fields at the end of a line are
ignored (a spreadsheet pads ragged CSV to a rectangle with commas), and the
separator is the one the first line uses after ``DYNAMIXEL Graph``
(:data:`SEPARATORS`: a spreadsheet in a comma-decimal locale saves with
``;``).

**The workflow's limits.**  :func:`read_wizard` refuses an export over the
workflow's row count or time span (:func:`.trace.check_span`) from its stamps,
before the reading clock is rebuilt: that costs about 1.5 ms a row, minutes
on an export the workflow would refuse anyway.  :func:`read_wizard_model`
reads only the two lines that name the servo.

**When a row was read.**  The Wizard stamps each row on its graph timer's
16 ms tick (:data:`TICK_S`) with the newest reading since the last tick,
while it reads the servo on its own, steadier clock (about 20 ms on the
shared AX-12A exports: at full speed each row is 23-30 units past the last
whether its stamp is 16 or 32 ms later; a tick with no new reading gets no
row).  So a stamp can be up to a tick after its reading, which at full speed
is +-10 units of apparent error.  :func:`reading_times` rebuilds the reading
clock from the stamps alone (no model): the period and phase whose readings,
each stamped on the first tick after it, reproduce which ticks have a row,
fitted in blocks of :data:`CLOCK_BLOCK_ROWS` rows between stalls; a row the
clock does not explain keeps the middle of its tick.  :func:`to_trace` uses
those times; ``t_s`` keeps the stamps.  An export not stamped on a 16 ms tick
is left as stamped.

Items map to trace columns by name (:data:`ITEM_COLUMNS`); items that map to
none (e.g. Present Temperature) are listed in
:attr:`WizardExport.ignored_items` and not read.  Present Speed and Present
Load arrive as the register's raw value (bit 10 = CW) and are converted to
the trace's signed form (positive when the position increases).

API::

    from firmware_model.diagnose.wizard import is_wizard_export, read_wizard, read_wizard_model, to_trace

    if is_wizard_export("AX12A_NOLOAD_1.csv"):
        ex = read_wizard("AX12A_NOLOAD_1.csv")   # WizardExport
        ex.model_name, ex.model_number            # "AX-12A", 12
        ex.t_s                                    # sample times, s from the first kept row, shape (n,)
        ex.values["present_position"]             # int64 array (n,); also goal_position, present_speed, ...
        ex.rows_read, ex.skipped                  # 206, {"garbled": 1, "repeated_time": 0, "time_back": 2}
        trace = to_trace(ex, goal_position=500, onset_s=1.87, moving_speed=0, voltage_v=12.0)
        read_wizard_model("AX12A_NOLOAD_1.csv")   # ("AX-12A", 12), from the first two lines alone
"""

from __future__ import annotations

import io
import itertools
import math
from array import array
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..units import DIRECTION_BIT
from .trace import Trace, TraceFormatError, check_span

__all__ = ["WizardExport", "WizardFormatError", "ITEM_COLUMNS", "SIGNED_ITEMS", "MAGIC", "is_wizard_export", "cruise_units_s",
           "CRUISE_SHARE", "SPEED_LIMITED_SHARE",
           "read_wizard", "read_wizard_model", "parse_wizard", "to_trace", "reading_times", "TICK_S", "SEPARATORS"]

#: The Wizard graph timer's tick (s): every stamp is a whole number of ticks (+-1 ms) from the first.
TICK_S = 0.016
#: A stamp within this much of a whole tick counts as on the tick (s); the shared exports stray by 1 ms.
TICK_TOLERANCE_S = 0.0015
#: The export is taken as tick-stamped when at least this share of its stamps is on the tick.
TICK_SHARE = 0.9
#: Reading periods tried (s): slower than the tick (a faster clock leaves a new reading at every tick, and
#: nothing to rebuild), up to three ticks.
CLOCK_PERIODS_S = (0.0165, 0.048)
#: Rows per block of one fitted clock (long enough to pin the period, short enough that its drift stays
#: well under a ms), and a gap longer than this many ticks (a stall of the Wizard) starts a new block.
CLOCK_BLOCK_ROWS, STALL_TICKS = 40, 4
#: Fewer rows than this between stalls pin no clock.
MIN_CLOCK_ROWS = 8

#: First field of the first line of every Wizard 2 graph export.
MAGIC = "DYNAMIXEL Graph"
#: Field separators an export is read with: the Wizard's own ',' and what a spreadsheet re-saves it with (';' in a
#: comma-decimal locale, a tab as "text"); the character after :data:`MAGIC` on the first line says which.
SEPARATORS = (",", ";", "\t")
#: Wizard item name -> trace column (see :mod:`.trace`).  Other items are listed as ignored.
ITEM_COLUMNS = {
    "Present Position": "present_position",
    "Goal Position": "goal_position",
    "Moving Speed": "moving_speed",
    "Present Speed": "present_speed",
    "Present Load": "present_load",
    "Torque Limit": "torque_limit",
    "Present Voltage": "voltage",
}
#: Columns whose raw register value carries the direction in bit 10 (converted to a signed value).
SIGNED_ITEMS = ("present_speed", "present_load")
#: Each mapped item's raw register range (AX series control table, e-manual: positions 0..1023 over 300 degrees,
#: speeds and loads 0..2047 with bit 10 the direction, Present Voltage one byte of 0.1 V).
ITEM_RANGES = {
    "present_position": (0, 1023), "goal_position": (0, 1023), "moving_speed": (0, 2047), "present_speed": (0, 2047),
    "present_load": (0, 2047), "torque_limit": (0, 1023), "voltage": (0, 255),
}
#: Model numbers of the servos whose exports the workflow reads: the AX series' 10-bit, 300-degree table
#: (AX-12/AX-12A 12, AX-18A 18, AX-12W 300); other servos count positions in other units.
AX_MODEL_NUMBERS = {12: "AX-12A", 18: "AX-18A", 300: "AX-12W"}
#: The time column's header.
TIME_HEADER = "Time[ms]"
#: Kinds of skipped rows, in report order.
SKIP_KINDS = ("garbled", "repeated_time", "time_back")


class WizardFormatError(TraceFormatError):
    """A malformed Wizard export; the message names the file and line (a ``ValueError``)."""


@dataclass
class WizardExport:
    """One Wizard graph export in memory (only the rows that parsed cleanly)."""

    source: str
    model_name: str
    model_number: int
    #: Plotted items, in column order, as the file names them.
    items: tuple[str, ...]
    #: Sample times, s, relative to the first kept row.
    t_s: np.ndarray
    #: Trace column name -> int64 values (signed for speed and load), one per kept row.
    values: dict[str, np.ndarray]
    #: Items that map to no trace column (not read).
    ignored_items: tuple[str, ...] = ()
    #: Data rows seen (kept + skipped), blank lines not counted.
    rows_seen: int = 0
    #: Skipped rows by kind: ``garbled`` (a field missing or not a number), ``repeated_time`` (same time as the
    #: last kept row), ``time_back`` (earlier than the last kept row).
    skipped: dict[str, int] = field(default_factory=lambda: dict.fromkeys(SKIP_KINDS, 0))
    #: 1-based line numbers of the skipped rows.
    skipped_lines: list[int] = field(default_factory=list)
    #: Time of the first kept row in the file's own clock, ms.
    t0_ms: float = 0.0
    #: When each kept row was read (s from the first reading; :func:`reading_times`); None: as stamped.
    read_s: np.ndarray | None = None
    #: The rebuilt reading clock's median period (s) and the share of rows it explains; None if not rebuilt.
    read_period_s: float | None = None
    read_share: float = 0.0

    @property
    def times_s(self) -> np.ndarray:
        """The rows' times a trace uses: when they were read where the clock was rebuilt, else the stamps."""
        return self.t_s if self.read_s is None else self.read_s

    @property
    def rows_read(self) -> int:
        """Rows kept."""
        return len(self.t_s)

    @property
    def rows_skipped(self) -> int:
        """Rows skipped, all kinds."""
        return sum(self.skipped.values())

    def summary(self) -> str:
        """One line: model, rows read and skipped by kind, items read and ignored."""
        kinds = ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in self.skipped.items() if v) or "none"
        out = (f"{self.source}: Wizard 2 graph export of an {self.model_name} (model {self.model_number}); "
               f"{self.rows_read} rows read, {self.rows_skipped} skipped ({kinds}); "
               f"items read: {', '.join(i for i in self.items if i in ITEM_COLUMNS)}")
        if self.ignored_items:
            out += f"; ignored: {', '.join(self.ignored_items)}"
        if self.read_period_s is not None:
            out += (f"; rows stamped on the {1000 * TICK_S:.0f} ms tick, read every {1000 * self.read_period_s:.1f} ms: "
                    f"reading times rebuilt ({100 * self.read_share:.0f} % of rows on the clock)")
        return out


def _separator(first_line: str) -> str | None:
    """The separator the first line uses after :data:`MAGIC` (``,`` where nothing follows it); None if the line
    does not start with :data:`MAGIC`, i.e. the file is no Wizard export."""
    line = first_line.strip()
    if not line.startswith(MAGIC):
        return None
    rest = line[len(MAGIC):].lstrip(" ")
    if not rest:
        return ","
    return rest[0] if rest[0] in SEPARATORS else None


def is_wizard_export(path: str | Path) -> bool:
    """Whether the file starts like a Wizard graph export (``DYNAMIXEL Graph``, then one of :data:`SEPARATORS`)."""
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as f:
            first = f.readline()
    except OSError:
        return False
    return _separator(first) is not None


def read_wizard(path: str | Path, limits: Callable[[np.ndarray, str], None] | None = check_span) -> WizardExport:
    """Read a Wizard graph export; raise :class:`WizardFormatError` (file and line) if it is malformed.

    ``limits(t_s, source)`` runs on the kept rows' stamps (s) before the reading clock is rebuilt, and raises
    ``ValueError`` for an export too large to go on with (default: the diagnosis workflow's; None: no limit).
    """
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise WizardFormatError(f"not UTF-8 text ({exc.reason})", source=str(path)) from None
    return parse_wizard(text, source=str(path), limits=limits)


def read_wizard_model(path: str | Path) -> tuple[str, int]:
    """The servo an export is from, (model name, model number), read from its first two lines alone.

    Why: knowing which servo's model to start from needs only those, and parsing a large export's rows twice
    doubles what the workflow takes to read it.  :class:`WizardFormatError` if the two lines are not an export's
    first; ``OSError`` if the file cannot be read.
    """
    source = str(path)
    try:
        with open(path, encoding="utf-8-sig") as f:
            head = list(itertools.islice(_lines(f), 2))
    except UnicodeDecodeError as exc:
        raise WizardFormatError(f"not UTF-8 text ({exc.reason})", source=source) from None
    sep = _magic(head, source)
    if len(head) < 2:
        raise WizardFormatError("header ends early: expected the model line", head[0][0], None, source)
    return _model(head[1], sep, source)


def _lines(raw: Iterable[str]) -> Iterator[tuple[int, str]]:
    """(1-based line number, text stripped) of each line that is not blank."""
    for n, line in enumerate(raw, start=1):
        stripped = line.strip()
        if stripped:
            yield n, stripped


def _fields(line: str, sep: str) -> list[str]:
    """A line's fields, stripped, without the empty ones at its end (a spreadsheet pads ragged rows with them)."""
    cells = [c.strip() for c in line.split(sep)]
    while len(cells) > 1 and not cells[-1]:
        cells.pop()
    return cells


def _magic(head: list[tuple[int, str]], source: str) -> str:
    """The separator of an export whose first non-blank lines are ``head``; WizardFormatError if it is none."""
    if not head:
        raise WizardFormatError(f"empty file: no {MAGIC!r} header", None, None, source)
    n, s = head[0]
    sep = _separator(s)
    if sep is None:
        raise WizardFormatError(f"not a Wizard graph export: the first line is {s[:40]!r}, expected {MAGIC!r},<version>",
                                n, None, source)
    return sep


def _model(line: tuple[int, str], sep: str, source: str) -> tuple[str, int]:
    """(model name, model number) from the model line ``<name>,<model number>``."""
    n, s = line
    model = _fields(s, sep)
    if len(model) != 2 or _int(model[1]) is None:
        raise WizardFormatError(f"expected the model line '<name>,<model number>', got {s[:40]!r}", n, None, source)
    return model[0], _int(model[1])


def _int(text: str) -> int | None:
    """An integer cell (``12`` or ``12.0``), or None if it is not one."""
    try:
        value = float(text)
    except ValueError:
        return None
    if not math.isfinite(value) or value != int(value):
        return None
    return int(value)


def parse_wizard(text: str, source: str = "wizard export",
                 limits: Callable[[np.ndarray, str], None] | None = check_span) -> WizardExport:
    """:func:`read_wizard` on a string (``source`` names it in errors)."""
    lines = _lines(io.StringIO(text))
    sep, (name, number), items, header_line = _header(lines, source)
    ex = WizardExport(source, name, number, items, np.zeros(0), {},
                      ignored_items=tuple(i for i in items if i not in ITEM_COLUMNS))
    data, kept_lines, first_skip = _rows(lines, sep, items, ex)
    if len(data) < 2:
        why = f"; the first, {first_skip[1]}" if first_skip else ""
        raise WizardFormatError(f"need at least two readable data rows, found {len(data)} ({ex.rows_skipped} skipped{why})",
                                first_skip[0] if first_skip else (list(kept_lines) or [header_line])[-1],
                                None, source)
    ex.t0_ms = float(data[0, 0])
    ex.t_s = (data[:, 0] - data[0, 0]) / 1000.0
    if limits is not None:  # before the clock: an export too large to go on with is refused in a second, not minutes
        limits(ex.t_s, source)
    for j, item in enumerate(items, start=1):
        col = ITEM_COLUMNS.get(item)
        if col is None:
            continue
        low, high = ITEM_RANGES[col]
        outside = np.flatnonzero((data[:, j] < low) | (data[:, j] > high))  # before the cast: 1e300 is no int64
        if outside.size:
            raise WizardFormatError(f"{item} {data[outside[0], j]:g} is outside the register's {low}..{high}"
                                    + (f" (and {outside.size - 1} more rows)" if outside.size > 1 else ""),
                                    kept_lines[outside[0]], None, source)
        v = data[:, j].astype(np.int64)
        if col in SIGNED_ITEMS:
            v = np.where(v >= DIRECTION_BIT, -(v & (DIRECTION_BIT - 1)), v)
        ex.values[col] = v
    read = reading_times(ex.t_s)
    if read is not None:
        ex.read_s, ex.read_period_s, ex.read_share = read
    return ex


def _header(lines: Iterator[tuple[int, str]], source: str) -> tuple[str, tuple[str, int], tuple[str, ...], int]:
    """(separator, (model name, model number), items, the column header's line) from an export's header lines,
    taken from ``lines`` (its non-blank lines, :func:`_lines`), which then holds the data rows."""

    def fail(message: str, line: int | None) -> WizardFormatError:
        return WizardFormatError(message, line, None, source)

    header = list(itertools.islice(lines, 3))
    sep = _magic(header, source)
    if len(header) < 3:
        raise fail("header ends early: expected the model line and 'ItemCount,<n>'", header[-1][0])
    model = _model(header[1], sep, source)
    n, s = header[2]
    count = _fields(s, sep)
    if len(count) != 2 or count[0] != "ItemCount" or _int(count[1]) is None or _int(count[1]) < 1:
        raise fail(f"expected 'ItemCount,<n>' with n >= 1, got {s[:40]!r}", n)
    n_items = _int(count[1])
    rest = list(itertools.islice(lines, n_items + 1))
    if len(rest) < n_items + 1:
        raise fail(f"header ends early: ItemCount is {n_items} but only {max(len(rest) - 1, 0)} item line(s) "
                   "and no column header follow", rest[-1][0] if rest else n)
    items = tuple(_fields(s, sep)[0] for _, s in rest[:n_items])
    for (n, s), item in zip(rest[:n_items], items):
        if not item or item == TIME_HEADER:
            raise fail(f"expected an item line '<name>,<colour>,...', got {s[:40]!r}", n)
    n, s = rest[n_items]
    cols = _fields(s, sep)
    if cols[0] != TIME_HEADER:
        raise fail(f"expected the column header '{TIME_HEADER},{','.join(items)}', got {s[:60]!r}", n)
    if tuple(cols[1:]) != items:
        raise fail(f"column header names {cols[1:]} but the item lines name {list(items)}", n)
    twice = sorted({i for i in items if i in ITEM_COLUMNS and items.count(i) > 1})
    if twice:  # which column counts would be a guess
        raise fail(f"{', '.join(twice)} plotted more than once", n)
    if model[1] not in AX_MODEL_NUMBERS:
        raise fail(f"the export is from a {model[0] or 'servo with no name'} (model number {model[1]}): the workflow reads "
                   f"the AX series' exports ({', '.join(f'{v} {k}' for k, v in AX_MODEL_NUMBERS.items())}), whose "
                   "positions are 0..1023 over 300 degrees", header[1][0])
    return sep, model, items, n


def _rows(lines: Iterator[tuple[int, str]], sep: str, items: tuple[str, ...], ex: WizardExport):
    """The data rows kept, shape (rows, 1 + items): time ms, then the items' values; their line numbers; and the
    first skipped row as (line, why) or None.  Skipped rows are counted in ``ex`` by kind (see the module doc).

    Kept in flat arrays of numbers as they are read: a list per row took 1.4 GB on a 4.6-million-row export."""
    kept = array("d")
    kept_lines = array("q")
    last_ms: float | None = None
    first_skip: tuple[int, str] | None = None
    for n, s in lines:
        ex.rows_seen += 1
        cells = _fields(s, sep)
        t = _number(cells[0]) if len(cells) == len(items) + 1 else None
        vals = [_int(c) for c in cells[1:]] if t is not None else [None]
        kind = None
        if t is None or any(v is None for v in vals):
            kind = "garbled"
        elif last_ms is not None and t == last_ms:
            kind = "repeated_time"
        elif last_ms is not None and t < last_ms:
            kind = "time_back"
        if kind:
            ex.skipped[kind] += 1
            ex.skipped_lines.append(n)
            if first_skip is None:
                first_skip = (n, f"{s[:40]!r}: {_skip_reason(kind, cells, items, last_ms)}")
            continue
        kept.append(t)
        kept.extend(vals)
        kept_lines.append(n)
        last_ms = t
    return np.frombuffer(kept, dtype=float).reshape(-1, len(items) + 1), kept_lines, first_skip


def _skip_reason(kind: str, cells: list[str], items: tuple[str, ...], last_ms: float | None) -> str:
    """Why a row was skipped, in words (for the error when no two rows are readable)."""
    if kind == "repeated_time":
        return f"its time repeats the last kept row's, {last_ms:g} ms"
    if kind == "time_back":
        return f"its time {cells[0]} ms is before the last kept row's, {last_ms:g} ms"
    if len(cells) != len(items) + 1:
        return f"{len(cells)} fields where the column header has {len(items) + 1}"
    if _number(cells[0]) is None:
        return f"the time {cells[0]!r} is not a number"
    item, cell = next((i, c) for i, c in zip(items, cells[1:]) if _int(c) is None)
    return f"{item} {cell!r} is not a whole number"


def _clock_scores(rows: np.ndarray, periods: np.ndarray, phase_step_s: float):
    """For each (period, phase): readings at ``phase + k * period`` from the tick before the block's first row,
    each stamped on the first tick at or after it.  Score: ticks with a row that a reading explains, minus
    ticks a reading predicts that have none (a lost row costs one; a wrong period costs many).
    Returns (score, period, phase) arrays over all pairs."""
    span = (len(rows) + 1) * TICK_S
    out = []
    for period in periods:
        phase = np.arange(0.0, period, phase_step_s)
        k = np.arange(int(span / period) + 2)
        tick = np.ceil((phase[:, None] + k[None, :] * period) / TICK_S - 1e-9).astype(np.int64) - 1
        inside = (tick >= 0) & (tick < len(rows))
        hit = rows[np.clip(tick, 0, len(rows) - 1)] & inside
        out.append((hit.sum(axis=1) - (inside & ~hit).sum(axis=1), np.full(len(phase), period), phase))
    return tuple(np.concatenate(x) for x in zip(*out))


def _block_readings(ticks: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(reading time s, on the clock?, period s) of each row of one block, from its stamps' tick numbers.

    A coarse then a fine search over period and phase; every clock with the best score explains the stamps
    equally well, so each row's reading is the mean over all of them of the reading inside its tick.
    """
    rows = np.zeros(int(ticks[-1] - ticks[0]) + 1, dtype=bool)
    rows[ticks - ticks[0]] = True
    score, period, _ = _clock_scores(rows, np.arange(*CLOCK_PERIODS_S, 5e-5), 2.5e-4)
    near = period[np.argmax(score)]
    score, period, phase = _clock_scores(rows, np.arange(near - 2e-4, near + 2e-4, 1e-5), 1e-4)
    best = score == score.max()
    period, phase = period[best], phase[best]
    origin = (ticks[0] - 1) * TICK_S + phase  # (candidates,)
    lo = (ticks - 1) * TICK_S  # each row's tick starts here; its reading is the first one after
    at = origin[:, None] + np.ceil((lo[None, :] - origin[:, None]) / period[:, None] - 1e-9) * period[:, None]
    ok = at <= (ticks * TICK_S)[None, :] + 1e-9
    count = ok.sum(axis=0)
    mean = np.where(count > 0, (at * ok).sum(axis=0) / np.maximum(count, 1), (ticks - 0.5) * TICK_S)
    return mean, count > 0, float(np.mean(period))


def reading_times(t_s: np.ndarray) -> tuple[np.ndarray, float, float] | None:
    """When each row of a tick-stamped export was read (s from the first reading), the clock's period, the
    share of rows it explains; None if the export is not stamped on the Wizard's tick (see the module doc).

    Each row's reading is placed where the rebuilt clock puts it inside the tick before its stamp; a row the
    clock does not explain keeps the middle of that tick.
    """
    t = np.asarray(t_s, dtype=float)
    ticks_f = t / TICK_S
    ticks = np.rint(ticks_f).astype(np.int64)
    if len(t) < MIN_CLOCK_ROWS or np.mean(np.abs(ticks_f - ticks) * TICK_S <= TICK_TOLERANCE_S) < TICK_SHARE:
        return None
    read = (ticks - 0.5) * TICK_S
    on_clock = np.zeros(len(t), dtype=bool)
    periods = []
    cuts = np.r_[0, np.flatnonzero(np.diff(ticks) > STALL_TICKS) + 1, len(t)]
    for a, b in zip(cuts[:-1], cuts[1:]):
        starts = list(range(a, b, CLOCK_BLOCK_ROWS))
        if len(starts) > 1 and b - starts[-1] < MIN_CLOCK_ROWS:  # a short tail joins the block before it
            starts.pop()
        for s, e in zip(starts, starts[1:] + [b]):
            if e - s < MIN_CLOCK_ROWS:  # too few rows to pin a clock: they keep the middle of their tick
                continue
            read[s:e], on_clock[s:e], period = _block_readings(ticks[s:e])
            periods.append(period)
    if not periods:
        return None
    read = np.maximum.accumulate(read)
    return read - read[0], float(np.median(periods)), float(on_clock.mean())


#: A step's cruise is read while it crosses this share of its way (from its first reading to its last).
CRUISE_SHARE = (0.2, 0.8)
#: A cruise slower than this share of the model's top speed was not run at Moving Speed 0 (full speed).
SPEED_LIMITED_SHARE = 0.9


def cruise_units_s(t_s: np.ndarray, positions: np.ndarray, final: float | None = None) -> float:
    """A step's cruise speed (units/s, magnitude): the slope of a line through the readings that cross the middle
    of its way (:data:`CRUISE_SHARE`, from the first reading to ``final``, default the last reading).

    Why: an export does not record Moving Speed, and a step that cruised well below the servo's top speed was
    taken with one, which its cruise tells.  ValueError where fewer than three readings cross the middle.
    """
    t, pos = np.asarray(t_s, dtype=float), np.asarray(positions, dtype=float)
    start, end = pos[0], pos[-1] if final is None else float(final)
    lo, hi = sorted(start + share * (end - start) for share in CRUISE_SHARE)
    inside = (pos >= lo) & (pos <= hi)
    if hi - lo < 1.0 or inside.sum() < 3:
        raise ValueError(f"only {int(inside.sum())} readings cross the middle of the step: no cruise to read")
    return float(abs(np.polyfit(t[inside], pos[inside], 1)[0]))


def _number(text: str) -> float | None:
    """A finite time cell, or None."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def to_trace(ex: WizardExport, goal_position: int, onset_s: float, moving_speed: int = 0,
             voltage_v: float | None = None, initial_goal: int | None = None, onset_known: bool = False) -> Trace:
    """The export as a trace, with the commands it does not record supplied by the caller.

    The goal is ``initial_goal`` (default: the first Present Position, i.e.
    the servo was holding where it stood) until ``onset_s`` (s from the first
    kept row's reading: the trace's times are :attr:`WizardExport.times_s`), then ``goal_position``; recorded Goal Position / Moving Speed
    columns, where plotted, are used instead.  The change goes on the last
    row read before ``onset_s``; only with ``onset_known`` (the user knows
    when the goal was written) does the trace also record the time itself
    (``command_t``), otherwise the workflow fits it within that sample as a
    trait of the recording (:mod:`.nuisance`).  ``voltage_v``: supply,
    unless the export plotted Present Voltage (None: the model's default).
    """
    t = ex.times_s
    n = len(t)
    if "present_position" not in ex.values:
        raise WizardFormatError("the export has no Present Position column: nothing to compare the model with",
                                source=ex.source)
    pos = ex.values["present_position"]
    cols: dict[str, np.ndarray] = {"t": t, "present_position": pos}
    cols.update({k: v for k, v in ex.values.items() if k != "present_position"})
    if "goal_position" not in cols:
        goal = np.full(n, int(pos[0]) if initial_goal is None else int(initial_goal), dtype=np.int64)
        command_t = t.copy()
        if onset_s <= t[0]:  # written before the recording started
            goal[:] = int(goal_position)
        else:
            row = min(int(np.searchsorted(t, onset_s, side="right")) - 1, n - 2)  # last reading before the onset
            goal[row:] = int(goal_position)
            command_t[row] = min(float(onset_s), float(np.nextafter(t[row + 1], t[row])))
        cols["goal_position"] = goal
        if onset_known:
            cols["command_t"] = command_t
    if "moving_speed" not in cols:
        cols["moving_speed"] = np.full(n, int(moving_speed), dtype=np.int64)
    if "voltage" not in cols and voltage_v is not None:
        cols["voltage"] = np.full(n, int(round(voltage_v * 10)), dtype=np.int64)
    comments = [f"from {ex.source}: {ex.model_name} Wizard 2 graph export, {ex.rows_read} rows read, "
                f"{ex.rows_skipped} skipped"]
    # the user started and stopped the graph whenever: its rests' lengths are not the servo's (see .evaluate)
    return Trace(cols, comments, {"rests_arbitrary": True})
