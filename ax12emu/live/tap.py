"""A tap on the bytes a served bus sees, for the live packet log.

Why it exists: the serving loop already hands every chunk in and out to its
trace hook (``BusServer.trace``, ``InProcessLink.trace``: anything with
``record(direction, data, now)``).  :class:`ByteTap` takes that place, passes
each chunk on to the trace file if there is one, and keeps the newest chunks
in a bounded deque.  Appending to a deque is one atomic step, so the serving
thread never waits for the live view; when the view reads too slowly the
oldest chunks fall out, and :meth:`take` says how many were lost.
"""

from __future__ import annotations

import collections
import time
from typing import Any

from ax12emu.tracing.trace import Chunk

__all__ = ["ByteTap"]


class ByteTap:
    """Keeps the last ``capacity`` chunks seen on the line; forwards each to ``inner`` (a TraceWriter) too."""

    def __init__(self, inner: Any = None, *, capacity: int = 2048) -> None:
        self.inner = inner
        self._chunks: collections.deque[tuple[float, str, bytes]] = collections.deque(maxlen=capacity)
        #: Chunks recorded so far (only the serving thread writes it).
        self.recorded = 0
        self._taken = 0

    def record(self, direction: str, data: bytes, now: float | None = None) -> None:
        """The trace hook: called on the serving thread for every chunk in and out."""
        if self.inner is not None:
            self.inner.record(direction, data, now)
        if data:
            self._chunks.append((time.monotonic() if now is None else now, direction, bytes(data)))
            self.recorded += 1

    def take(self) -> tuple[list[Chunk], int]:
        """The chunks since the last call (monotonic times) and how many fell out unread before it."""
        recorded = self.recorded  # read first: chunks recorded meanwhile are popped now or next time
        out = []
        chunks = self._chunks
        while True:
            try:
                t, direction, data = chunks.popleft()
            except IndexError:
                break
            out.append(Chunk(t, direction, data))
        lost = max(0, recorded - self._taken - len(out))
        self._taken += len(out) + lost
        return out, lost

    # A TraceWriter's other methods, for code that flushes or closes the trace it was given.
    def flush(self) -> None:
        if self.inner is not None:
            self.inner.flush()

    def close(self) -> None:
        if self.inner is not None:
            self.inner.close()
