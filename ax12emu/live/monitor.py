"""``ax12emu serve --monitor``: the live picture in the terminal, redrawn in place.

Why rich: its ``Live`` display redraws a table in place on any terminal
(and degrades to plain lines where there is none), is widely used and well
kept, and needs no curses screen.  The monitor draws on stderr, so the
first stdout line (the port scripts read) is never disturbed, and it
renders from the :class:`~ax12emu.live.sampler.Sampler`'s frames at
``refresh_hz``, never touching the bus itself.
"""

from __future__ import annotations

import logging
import sys
from typing import IO, Any

from rich.cells import cell_len
from rich.console import Console, ConsoleOptions, RenderResult
from rich.file_proxy import FileProxy
from rich.live import Live
from rich.table import Table
from rich.text import Text

from .sampler import Frame, Sampler

__all__ = ["Monitor", "render"]

#: Columns of a picture printed where there is no terminal.
PLAIN_WIDTH = 220

def _reading(servo: dict[str, Any], *names: str) -> dict[str, Any] | None:
    """The first of the named readings the servo has (an X-series servo senses current, an AX-12 load)."""
    found = {reading["name"]: reading for reading in servo["readings"]}
    return next((found[name] for name in names if name in found), None)


def _show(reading: dict[str, Any] | None) -> str:
    """A reading in its unit (one decimal), or raw where its unit is unknown; '-' where the servo has no such register.

    The page shows the raw values beside; a terminal row has room for one of them.
    """
    if reading is None:
        return "-"
    if reading["value"] is None:
        return f"{reading['raw']:+d}"
    return f"{reading['value']:+.1f} {reading['unit']}"


def _position(servo: dict[str, Any], name: str) -> str:
    """Position or goal in the servo's own units and in degrees."""
    reading = _reading(servo, name)
    if reading is None:
        return "-"
    return str(reading["raw"]) if reading["value"] is None else f"{reading['raw']} ({reading['value']:.1f}°)"


#: Prefixes for a rate in bits per second, largest first.
RATE_PREFIXES = ((1e6, "M"), (1e3, "k"), (1.0, ""))


def _bps(servo: dict[str, Any]) -> str:
    """The rate the servo listens at, short (1M, 57.6k): after a Baud Rate write it is why a host hears nothing."""
    bps = servo.get("baud_bps")
    if bps is None:
        return "-"
    scale, suffix = next(((scale, suffix) for scale, suffix in RATE_PREFIXES if bps >= scale), RATE_PREFIXES[-1])
    return f"{bps / scale:.3g}{suffix}"


#: Columns of the servo table: heading, how to show one servo (AX-12 and X series alike, from its readings),
#: and its rank: where the terminal is too narrow for every column, the lowest ranks are kept and the others left
#: out whole (rich would squeeze every column to a few characters, the short ones to nothing: no ID at 80
#: columns).  A servo's errors and faults, free text of any length, are :data:`TROUBLE_COLUMNS`.
COLUMNS: tuple[tuple[str, Any, int], ...] = (
    ("ID", lambda s: str(s["id"]), 0),
    ("model", lambda s: f"{s['model']} (P{s['protocol']})", 11),
    ("mode", lambda s: s["mode"] + (f" {s['limits'][0]}..{s['limits'][1]}" if s["limits"] else ""), 3),
    ("position", lambda s: _position(s, "position"), 1),
    ("goal", lambda s: _position(s, "goal"), 2),
    ("velocity", lambda s: _show(_reading(s, "velocity")), 5),
    ("current/load", lambda s: _show(_reading(s, "current", "load")), 9),
    ("PWM", lambda s: _show(_reading(s, "pwm")), 12),
    ("V", lambda s: "-" if (r := _reading(s, "voltage")) is None or r["value"] is None else f"{r['value']:.1f}", 8),
    ("°C", lambda s: "-" if (r := _reading(s, "temperature")) is None else str(r["raw"]), 7),
    ("torque", lambda s: "on" if s["registers"].get("torque_enable") else "off", 4),
    ("moving", lambda s: "yes" if s["registers"].get("moving") else "no", 6),
    ("baud", _bps, 10),
)
#: Characters between two columns (rich's padding, one each side).
GAP = 2


def _errors(servo: dict[str, Any]) -> str:
    return ",".join(servo["alarm_names"]) or (f"{servo['alarms']:#04x}" if servo["alarms"] else "")


#: A servo's errors and faults: columns of the table where the terminal is wide enough for every column (each
#: servo's trouble in its row, however many servos the terminal's height leaves room for), else lines of their own
#: under the table.
TROUBLE_COLUMNS: tuple[tuple[str, Any, int], ...] = (
    ("errors", lambda s: _errors(s) or "-", len(COLUMNS)),
    ("faults", lambda s: "; ".join(s["faults"]) or "-", len(COLUMNS) + 1),
)


def _troubles(servo: dict[str, Any]) -> Text | None:
    """A servo's errors and faults as a line under the table (None: it has neither); the terminal wraps it."""
    errors, faults = _errors(servo), "; ".join(servo["faults"])
    if not (errors or faults):
        return None
    said = "  ".join(part for part in (errors and f"errors {errors}", faults and f"faults {faults}") if part)
    return Text(f"ID {servo['id']} (P{servo['protocol']}): {said}", style="red")


def _widths(cells: list[list[str]]) -> list[int]:
    """Each column's width: its widest cell."""
    return [max(map(cell_len, column)) for column in zip(*cells)]


def _fitting(cells: list[list[str]], width: int) -> list[int]:
    """The columns (by index, in table order) that fit ``width``, taken by rank, each as wide as its widest cell."""
    widths = _widths(cells)
    kept: list[int] = []
    used = -GAP
    for index in sorted(range(len(COLUMNS)), key=lambda i: COLUMNS[i][2]):
        if used + GAP + widths[index] <= width:
            kept.append(index)
            used += GAP + widths[index]
    return sorted(kept)


class _Picture:
    """One frame's picture, laid out at the width it is drawn at (a terminal may be resized between frames)."""

    def __init__(self, frame: Frame) -> None:
        self.frame = frame

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        frame = self.frame
        stats = frame["stats"]
        clock = "paused" if frame["paused"] else "running"
        yield Text(
            f"t={frame['sim_time_s']:.3f} s ({clock})  packets/s {stats['packets_per_s']:.0f}  packets {stats['packets']}  "
            f"status errors {stats['status_errors']}  checksum errors in the log {stats['checksum_errors']}  "
            f"timeouts injected {stats['timeouts_injected']}  corrupt injected {stats['corrupt_injected']}  "
            f"Protocol {' + '.join(frame.get('protocols', ['1.0']))}"
        )
        servos = frame["servos"]
        every = COLUMNS + TROUBLE_COLUMNS
        cells = [[heading for heading, _, _ in every], *([show(servo) for _, show, _ in every] for servo in servos)]
        if sum(_widths(cells)) + GAP * (len(every) - 1) <= options.max_width:
            yield _table(every, cells, range(len(every)), servos)
            return
        cells = [row[: len(COLUMNS)] for row in cells]
        kept = _fitting(cells, options.max_width)
        yield _table(COLUMNS, cells, kept, servos)
        left_out = [heading for index, (heading, _, _) in enumerate(COLUMNS) if index not in kept]
        if left_out:
            yield Text(f"(no room for: {', '.join(left_out)})", style="dim")
        yield from filter(None, map(_troubles, servos))


def _table(columns: tuple[tuple[str, Any, int], ...], cells: list[list[str]], kept: Any, servos: list) -> Table:
    """The servo table of the ``kept`` columns (by index) of ``cells`` (headings first, then a row a servo)."""
    table = Table(box=None, show_edge=False, pad_edge=False, padding=(0, GAP // 2))
    for index in kept:
        table.add_column(columns[index][0], no_wrap=True)
    for servo, row in zip(servos, cells[1:]):
        style = "red" if servo["alarm_names"] or servo["faults"] else None
        table.add_row(*(row[index] for index in kept), style=style)
    return table


def render(frame: Frame) -> _Picture:
    """One frame as a rich renderable: a status line and the servo table, errors and faults its last columns where
    every column fits the width it is drawn at; else the columns that fit, and a line for each servo with errors or
    faults under the table."""
    return _Picture(frame)


class Monitor:
    """Redraws ``sampler``'s newest frame on ``stream`` (stderr by default) ``refresh_hz`` times a second.

    On a terminal the picture is redrawn in place; where the stream is a file
    or a pipe (a CI log) it is printed every ``plain_every_s`` seconds and
    once more when the monitor closes, so a log is not flooded.
    """

    def __init__(
        self,
        sampler: Sampler,
        *,
        stream: IO[str] | None = None,
        refresh_hz: float = 5.0,
        plain_every_s: float = 10.0,
        force_terminal: bool | None = None,
        width: int | None = None,
    ) -> None:
        self.sampler = sampler
        self.console = Console(file=stream or sys.stderr, force_terminal=force_terminal, width=width)
        if not self.console.is_terminal and width is None:
            self.console.width = PLAIN_WIDTH  # no terminal to fit: wide enough for every column
        self._every = max(1, round((1.0 / refresh_hz if self.console.is_terminal else plain_every_s) / sampler.period_s))
        self._live = Live(console=self.console, auto_refresh=False, redirect_stdout=False, redirect_stderr=False) if self.console.is_terminal else None
        self.drawn = 0
        #: Log handlers that wrote to the monitor's stream, now printing through its console (see :meth:`start`).
        self._rerouted: list[logging.StreamHandler] = []

    def start(self) -> "Monitor":
        if self._live is not None:
            self._live.start()
            self._reroute_logging()
        self.sampler.subscribe(self._on_frame)
        return self

    def _reroute_logging(self) -> None:
        """While the table is redrawn in place, a log line written straight to its stream lands inside the table and
        is drawn over: the root logger's handlers on that stream print through the console instead, which puts each
        line above the table (rich's Live does this for ``sys.stderr`` itself, but a handler keeps the stream it was
        given)."""
        stream = self.console.file
        for handler in logging.getLogger().handlers:
            if isinstance(handler, logging.StreamHandler) and handler.stream is stream:
                handler.setStream(FileProxy(self.console, stream))  # type: ignore[arg-type]
                self._rerouted.append(handler)

    def _restore_logging(self) -> None:
        stream = self.console.file
        for handler in self._rerouted:
            handler.setStream(stream)
        self._rerouted.clear()

    def _on_frame(self, frame: Frame) -> None:
        if frame["seq"] % self._every == 0:
            self._draw(frame)

    def _draw(self, frame: Frame) -> None:
        if self._live is not None:
            self._live.update(render(frame), refresh=True)
        else:
            self.console.print(render(frame))
        self.drawn += 1

    def close(self) -> None:
        self.sampler.unsubscribe(self._on_frame)
        if self._live is not None:
            self._restore_logging()
            self._live.stop()
        elif self.sampler.latest is not None:
            self._draw(self.sampler.latest)  # the last picture, for the log
