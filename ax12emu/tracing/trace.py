"""Bus traces: every byte in and out, timestamped, as JSON lines.

Why it exists: a trace answers "what was on the wire when my code failed",
like a logic analyser's capture, and ``ax12emu decode`` turns it into
packets.  The format is plain JSON lines so any tool can read it::

    {"format": "ax12emu-trace/1", "started": "2026-01-01T12:00:00+00:00", "profile": "ax12a"}
    {"t": 0.012345, "dir": "in", "data": "ff ff 01 02 01 fb"}
    {"t": 0.012861, "dir": "out", "data": "ff ff 01 02 00 fc"}

A trace of Protocol 2.0 servos adds ``"servos": "1:xl430-w250,2:xl430-w250"`` (the
``--servo`` text, launch ID by launch ID) to the header, so the decoder can name their registers.

``t`` is seconds since the first line (monotonic clock); ``in`` is what
the host sent (before any collision garbling), ``out`` what the bus put on
the line (status packets, echoed bytes).  A raw capture from hardware (host
and servo bytes interleaved in one binary file, no timing) is read by
:func:`read_raw`.
"""

from __future__ import annotations

import datetime
import json
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO, NamedTuple

__all__ = ["TraceWriter", "Chunk", "read_trace", "read_raw", "read_capture", "trace_header", "TRACE_FORMAT", "IN", "OUT"]

TRACE_FORMAT = "ax12emu-trace/1"
#: Directions: host to servos, servos (or the adapter's echo) to host.
IN, OUT = "in", "out"


class Chunk(NamedTuple):
    """Bytes seen on the line at ``t`` (None: unknown) going ``direction`` (None: unknown)."""

    t: float | None
    direction: str | None
    data: bytes


class TraceWriter:
    """Appends chunks to a JSON-lines file; timestamps are monotonic seconds since creation."""

    def __init__(self, path: str | os.PathLike[str], *, profile: str = "ax12a", servos: str | None = None) -> None:
        self.path = Path(path)
        self._file: IO[str] | None = open(self.path, "w", encoding="utf-8")
        self._start = time.monotonic()
        header = {
            "format": TRACE_FORMAT,
            "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "profile": profile,
        }
        if servos is not None:  # Protocol 2.0 servos as --servo writes them: the decoder names their registers
            header["servos"] = servos
        self._file.write(json.dumps(header) + "\n")

    def record(self, direction: str, data: bytes, now: float | None = None) -> None:
        """Append one chunk seen at monotonic time ``now`` (default: now)."""
        if self._file is None or not data:
            return
        t = (time.monotonic() if now is None else now) - self._start
        self._file.write(f'{{"t": {t:.6f}, "dir": "{direction}", "data": "{bytes(data).hex(" ")}"}}\n')

    def flush(self) -> None:
        """Push buffered lines to the file."""
        if self._file is not None:
            self._file.flush()

    def close(self) -> None:
        """Flush and close; safe to call more than once."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> "TraceWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_trace(path: str | os.PathLike[str]) -> Iterator[Chunk]:
    """Chunks of a JSON-lines trace; a bad line raises ValueError naming its number."""
    with open(path, encoding="utf-8") as handle:
        for number, line in enumerate(handle, 1):
            line = line.strip()
            if not line:
                continue
            try:
                record = json.loads(line)
                if "format" in record:
                    if record["format"] != TRACE_FORMAT:
                        raise ValueError(f"unknown trace format {record['format']!r}")
                    continue
                direction = record["dir"]
                if direction not in (IN, OUT):
                    raise ValueError(f"dir must be {IN!r} or {OUT!r}")
                yield Chunk(float(record["t"]), direction, bytes.fromhex(record["data"]))
            except (ValueError, KeyError, TypeError) as exc:
                raise ValueError(f"{path}:{number}: not a trace line ({exc})") from None


def trace_header(path: str | os.PathLike[str]) -> dict:
    """The header line of a JSON-lines trace (``profile``, and ``servos`` for a Protocol 2.0 bus); {} for a raw capture."""
    with open(path, "rb") as handle:
        first = handle.readline(4096).strip()
    if not first.startswith(b"{"):
        return {}
    try:
        record = json.loads(first)
    except ValueError:
        return {}
    return record if isinstance(record, dict) and record.get("format") == TRACE_FORMAT else {}


def read_raw(path: str | os.PathLike[str]) -> Iterator[Chunk]:
    """A binary capture of the line (host and servo bytes interleaved) as one chunk."""
    yield Chunk(None, None, Path(path).read_bytes())


def read_capture(path: str | os.PathLike[str]) -> Iterator[Chunk]:
    """A JSON-lines trace if the file starts like one, else a raw binary capture."""
    with open(path, "rb") as handle:
        start = handle.read(64).lstrip()
    return read_trace(path) if start.startswith(b"{") else read_raw(path)
