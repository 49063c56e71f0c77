"""Bus traces: every byte in and out, timestamped, as JSON lines.

Why it exists: a trace answers "what was on the wire when my code failed",
like a logic analyser's capture, and ``ax12emu decode`` turns it into
packets.  The format is plain JSON lines so any tool can read it::

    {"format": "ax12emu-trace/1", "started": "2026-01-01T12:00:00+00:00", "profile": "ax12a"}
    {"t": 0.012345, "dir": "in", "data": "ff ff 01 02 01 fb"}
    {"t": 0.012861, "dir": "out", "data": "ff ff 01 02 00 fc"}

A trace of Protocol 2.0 servos adds ``"servos": "1:xl430-w250,2:xl430-w250"`` (the
``--servo`` text, launch ID by launch ID) to the header, so the decoder can name their registers.
A trace ``serve`` recorded says in its header whether the adapter echoed the host's bytes
(``"echo": false``: no ``out`` bytes are an echo); on a paced wire (``serve --pace``) each ``in``
line adds when its last byte left the wire and a byte's wire time (``"end"``, ``"byte_s"``), so
the decoder measures a reply's latency from the instruction's end rather than its arrival.

``t`` is seconds since the first line (monotonic clock); ``in`` is what
the host sent (before any collision garbling), ``out`` what the bus put on
the line (status packets, echoed bytes).  A raw capture from hardware (host
and servo bytes interleaved in one binary file, no timing) is read by
:func:`read_raw`.
"""

from __future__ import annotations

import contextlib
import datetime
import json
import logging
import math
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO, NamedTuple

__all__ = ["TraceWriter", "Chunk", "read_trace", "read_raw", "read_capture", "trace_header", "TRACE_FORMAT", "IN", "OUT"]

log = logging.getLogger(__name__)

TRACE_FORMAT = "ax12emu-trace/1"
#: Directions: host to servos, servos (or the adapter's echo) to host.
IN, OUT = "in", "out"


class Chunk(NamedTuple):
    """Bytes seen on the line at ``t`` (None: unknown) going ``direction`` (None: unknown)."""

    t: float | None
    direction: str | None
    data: bytes
    #: On a paced wire: when the chunk's last byte left the wire (same clock as ``t``), and a byte's wire time.
    end: float | None = None
    byte_s: float | None = None


class TraceWriter:
    """Appends chunks to a JSON-lines file; timestamps are monotonic seconds since creation."""

    def __init__(self, path: str | os.PathLike[str], *, profile: str = "ax12a", servos: str | None = None) -> None:
        self.path = Path(path)
        # Line-buffered: the file keeps up with the wire, so a trace read while the server runs, or left by one that
        # was killed (a CI timeout's SIGKILL), holds the traffic up to its last packet, the part a failure is in.
        self._file: IO[str] | None = open(self.path, "w", encoding="utf-8", buffering=1)
        self._start = time.monotonic()
        self._last_t = float("-inf")
        #: The wire the next "in" chunk takes (see :meth:`on_wire`).
        self._wire: tuple[float, float] | None = None
        self._header: dict = {
            "format": TRACE_FORMAT,
            "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "profile": profile,
        }
        if servos is not None:  # Protocol 2.0 servos as --servo writes them: the decoder names their registers
            self._header["servos"] = servos
        #: Whether the header line is out. It goes at the first :meth:`note`, chunk, flush or close, not at once: a
        #: recorder notes the wire first, and a trace may go to a pipe or FIFO, where nothing written can be redone.
        self._header_out = False

    def _write_header(self) -> None:
        if not self._header_out and self._file is not None:
            self._header_out = True
            self._write(json.dumps(self._header) + "\n")

    def note(self, *, echo: bool) -> None:
        """Add what the recorder knows of the wire to the header and write it: ``echo``, whether the adapter echoes
        the host's bytes (``serve --echo``; without it no ``out`` bytes are an echo).  Only before anything else."""
        if self._file is None:
            return
        if self._header_out:
            raise ValueError("a trace's header is noted before its first chunk")
        self._header["echo"] = bool(echo)
        self._write_header()

    def on_wire(self, end: float, byte_s: float) -> None:
        """The next ``"in"`` chunk recorded is on a paced wire until monotonic time ``end``, ``byte_s`` a byte: its
        line records both (``"end"``, ``"byte_s"``), so a reply's latency is measured from the instruction's end."""
        self._wire = (end, byte_s)

    def record(self, direction: str, data: bytes, now: float | None = None) -> None:
        """Append one chunk seen at monotonic time ``now`` (default: now); ValueError for a line :func:`read_trace`
        would refuse (a direction other than ``"in"``/``"out"``, a time not finite or earlier than the last)."""
        if self._file is None or not data:
            return
        t = (time.monotonic() if now is None else now) - self._start
        if direction not in (IN, OUT) or not math.isfinite(t) or t < self._last_t:
            raise ValueError(f"a trace chunk goes {IN!r} or {OUT!r} at a finite time not before the last chunk's, "
                             f"got {direction!r} at {t!r} s")
        self._last_t = t
        wire, self._wire = (self._wire, None) if direction == IN else (None, self._wire)
        if wire is not None and math.isfinite(wire[0] - self._start) and math.isfinite(wire[1]) and wire[1] > 0:
            paced = f', "end": {max(t, wire[0] - self._start):.6f}, "byte_s": {wire[1]:.9f}'
        else:
            paced = ""
        self._write_header()
        self._write(f'{{"t": {t:.6f}, "dir": "{direction}", "data": "{bytes(data).hex(" ")}"{paced}}}\n')

    def _write(self, line: str) -> None:
        if self._file is None:
            return
        try:
            self._file.write(line)
        except OSError as exc:
            self._give_up(exc)

    def _give_up(self, exc: OSError) -> None:
        """A trace that cannot be written (the disk full) stops, said once; the bus it records goes on serving, as
        a state folder that fails mid-session does: the trace is a record of the session, not the session."""
        log.error("trace %s: %s; tracing stopped (the lines before stay)", self.path, exc.strerror or exc)
        file, self._file = self._file, None
        with contextlib.suppress(OSError):
            file.close()

    def flush(self) -> None:
        """Push buffered lines to the file."""
        self._write_header()
        if self._file is not None:
            try:
                self._file.flush()
            except OSError as exc:
                self._give_up(exc)

    def close(self) -> None:
        """Flush and close; safe to call more than once."""
        self._write_header()
        if self._file is not None:
            try:
                self._file.close()
            except OSError as exc:
                self._file = None
                log.error("trace %s: %s; its last lines are lost", self.path, exc.strerror or exc)
            self._file = None

    def __enter__(self) -> "TraceWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


#: The largest file a decode reads (bytes): a trace of hours of a busy bus is well under it, and a device file
#: (``/dev/zero``) or a wrong file would otherwise be read until memory runs out.
MAX_TRACE_BYTES = 512 * 1024 * 1024


def _check_size(path: str | os.PathLike[str]) -> None:
    size = os.stat(path).st_size
    if size > MAX_TRACE_BYTES or not Path(path).is_file():
        raise ValueError(f"{path}: not a trace file of at most {MAX_TRACE_BYTES // 2**20} MB "
                         f"({'not a regular file' if not Path(path).is_file() else f'{size} bytes'})")


def _number(value: object) -> bool:
    """Whether a JSON value is a finite number (an integer too large for a float raises OverflowError)."""
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


def read_trace(path: str | os.PathLike[str]) -> Iterator[Chunk]:
    """Chunks of a JSON-lines trace; a bad line raises ValueError naming its number (a time before the last one's
    too: a trace's times are the recorder's monotonic clock)."""
    _check_size(path)
    last_t = -math.inf
    with open(path, "rb") as handle:
        for number, raw in enumerate(handle, 1):
            try:
                line = raw.decode("utf-8-sig" if number == 1 else "utf-8").strip()
                if not line:
                    continue
                record = json.loads(line)
                if not isinstance(record, dict):
                    raise ValueError(f"a JSON object per line, got {type(record).__name__}")
                if "format" in record:
                    if record["format"] != TRACE_FORMAT:
                        raise ValueError(f"unknown trace format {record['format']!r}")
                    continue
                direction = record["dir"]
                if direction not in (IN, OUT):
                    raise ValueError(f"dir must be {IN!r} or {OUT!r}")
                t = record["t"]
                if not _number(t):
                    raise ValueError(f"t must be a finite number of seconds, got {t!r}")
                if t < last_t:
                    raise ValueError(f"t {t} is before the line before's {last_t}")
                last_t = t
                end, byte_s = record.get("end"), record.get("byte_s")
                if (end is None) != (byte_s is None):
                    raise ValueError("end and byte_s come together")
                if end is not None:
                    if not (_number(end) and _number(byte_s) and end >= t and byte_s > 0):
                        raise ValueError(f"end must be a time not before t and byte_s a positive time, got {end!r}, {byte_s!r}")
                    end, byte_s = float(end), float(byte_s)
                yield Chunk(float(t), direction, bytes.fromhex(record["data"]), end, byte_s)
            # RecursionError: JSON nested too deep; OverflowError: a number too large for a float (a 400-digit "t")
            except (ValueError, KeyError, TypeError, RecursionError, OverflowError) as exc:
                reason = "nested too deep" if isinstance(exc, RecursionError) else exc
                raise ValueError(f"{path}:{number}: not a trace line ({reason})") from None


#: The longest header line read: a wire of every ID on both protocols names ~500 servos in it (6 kB).
MAX_HEADER_BYTES = 64 * 1024


def trace_header(path: str | os.PathLike[str]) -> dict:
    """The header line of a JSON-lines trace (``profile``, and ``servos`` for a Protocol 2.0 bus); {} for a raw capture."""
    with open(path, "rb") as handle:
        first = handle.readline(MAX_HEADER_BYTES).strip().removeprefix(b"\xef\xbb\xbf")  # a UTF-8 byte-order mark
    if not first.startswith(b"{"):
        return {}
    try:
        record = json.loads(first)
    except (ValueError, RecursionError):
        return {}
    return record if isinstance(record, dict) and record.get("format") == TRACE_FORMAT else {}


def read_raw(path: str | os.PathLike[str]) -> Iterator[Chunk]:
    """A binary capture of the line (host and servo bytes interleaved) as one chunk."""
    _check_size(path)
    yield Chunk(None, None, Path(path).read_bytes())


def read_capture(path: str | os.PathLike[str]) -> Iterator[Chunk]:
    """A JSON-lines trace if the file starts like one, else a raw binary capture."""
    with open(path, "rb") as handle:
        start = handle.read(64).removeprefix(b"\xef\xbb\xbf").lstrip()  # a byte-order mark: still a trace
    return read_trace(path) if start.startswith(b"{") else read_raw(path)
