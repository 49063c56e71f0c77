"""``ax12emu serve --monitor``: the live picture in the terminal, redrawn in place.

Why rich: its ``Live`` display redraws a table in place on any terminal
(and degrades to plain lines where there is none), is widely used and well
kept, and needs no curses screen.  The monitor draws on stderr, so the
first stdout line (the port scripts read) is never disturbed, and it
renders from the :class:`~ax12emu.live.sampler.Sampler`'s frames at
``refresh_hz``, never touching the bus itself.
"""

from __future__ import annotations

import sys
from typing import IO, Any

from rich.console import Console, Group
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


#: Columns of the servo table: heading, how to show one servo (AX-12 and X series alike, from its readings),
#: whether the column may wrap (the free-text ones, so a narrow terminal keeps the numbers whole).
COLUMNS: tuple[tuple[str, Any, bool], ...] = (
    ("ID", lambda s: str(s["id"]), False),
    ("model", lambda s: f"{s['model']} (P{s['protocol']})", False),
    ("mode", lambda s: s["mode"] + (f" {s['limits'][0]}..{s['limits'][1]}" if s["limits"] else ""), True),
    ("position", lambda s: _position(s, "position"), False),
    ("goal", lambda s: _position(s, "goal"), False),
    ("velocity", lambda s: _show(_reading(s, "velocity")), False),
    ("current/load", lambda s: _show(_reading(s, "current", "load")), False),
    ("PWM", lambda s: _show(_reading(s, "pwm")), False),
    ("V", lambda s: "-" if (r := _reading(s, "voltage")) is None or r["value"] is None else f"{r['value']:.1f}", False),
    ("°C", lambda s: "-" if (r := _reading(s, "temperature")) is None else str(r["raw"]), False),
    ("torque", lambda s: "on" if s["registers"].get("torque_enable") else "off", False),
    ("moving", lambda s: "yes" if s["registers"].get("moving") else "no", False),
    ("errors", lambda s: ",".join(s["alarm_names"]) or (f"{s['alarms']:#04x}" if s["alarms"] else "-"), True),
    ("faults", lambda s: "; ".join(s["faults"]) or "-", True),
)


def render(frame: Frame) -> Group:
    """One frame as a rich renderable: a status line, the servo table, the newest log lines."""
    stats = frame["stats"]
    clock = "paused" if frame["paused"] else "running"
    head = Text(
        f"t={frame['sim_time_s']:.3f} s ({clock})  packets/s {stats['packets_per_s']:.0f}  packets {stats['packets']}  "
        f"status errors {stats['status_errors']}  checksum errors {stats['checksum_errors']}  "
        f"timeouts injected {stats['timeouts_injected']}  corrupt injected {stats['corrupt_injected']}  "
        f"Protocol {' + '.join(frame.get('protocols', ['1.0']))}"
    )
    table = Table(expand=False, show_edge=False, pad_edge=False)
    for heading, _, wraps in COLUMNS:
        table.add_column(heading, no_wrap=not wraps)
    for servo in frame["servos"]:
        style = "red" if servo["alarm_names"] or servo["faults"] else None
        table.add_row(*(show(servo) for _, show, _ in COLUMNS), style=style)
    return Group(head, table)


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

    def start(self) -> "Monitor":
        if self._live is not None:
            self._live.start()
        self.sampler.subscribe(self._on_frame)
        return self

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
            self._live.stop()
        elif self.sampler.latest is not None:
            self._draw(self.sampler.latest)  # the last picture, for the log
