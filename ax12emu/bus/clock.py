"""Clocks: where simulated time comes from.

Why it exists: physics runs in simulated seconds, which follow the wall clock
(optionally K times faster or slower) when serving a real client, and follow
nothing but the test's own steps in virtual time, so physics tests are fast
and deterministic.  Timing of bytes on the wire always uses the real
monotonic clock; only the simulated world is scaled.
"""

from __future__ import annotations

import logging
import time

__all__ = ["WallClock", "VirtualClock", "MAX_STRIDE_S"]

log = logging.getLogger(__name__)

#: The most simulated time a wall clock moves between two readings (s).  Each reading is where a bus brings its
#: physics to, so this bounds the stepping one reading can ask for: at a time scale the model cannot keep up with
#: (thousands, or many servos moving at hundreds), each catch-up took longer than the one before, the serving
#: loop never got back to a packet or a signal, and the server could not be stopped.  Past it the clock slips:
#: simulated time runs as fast as the model can step it.  At a time scale of 1 it takes a process stalled for a
#: second to slip.
MAX_STRIDE_S = 1.0


class WallClock:
    """Simulated seconds since creation, at ``time_scale`` simulated seconds per wall second.

    A tester watching the live view can pause it (simulated time stands
    still, so the physics does) and step it by hand while paused, as a
    :class:`VirtualClock` is stepped.
    """

    def __init__(self, time_scale: float = 1.0) -> None:
        if not 0 < time_scale < float("inf"):
            raise ValueError(f"time scale must be positive and finite, got {time_scale}")
        self.time_scale = time_scale
        self._start = time.monotonic()
        self._paused_at: float | None = None
        #: The last reading (simulated s): the next moves at most :data:`MAX_STRIDE_S` past it.
        self._last_s = 0.0
        #: Simulated time let go because the readings were further apart than :data:`MAX_STRIDE_S`.
        self.slipped_s = 0.0
        #: Whether the clock has been read (a slow start before the first reading is no news) and has said so.
        self._read = self._warned = False

    def now_s(self) -> float:
        """Simulated time now: at most :data:`MAX_STRIDE_S` past the last reading (the rest slips)."""
        wall_s = time.monotonic() if self._paused_at is None else self._paused_at
        now = (wall_s - self._start) * self.time_scale
        if now - self._last_s > MAX_STRIDE_S:
            slip = now - self._last_s - MAX_STRIDE_S
            self._start += slip / self.time_scale
            now -= slip
            if self._read and not self._warned:
                self._warned = True
                log.warning("simulated time slipped %.3g s: the model could not step as fast as --time-scale %g asks "
                            "(or the process was stopped); it now runs as fast as the model steps", slip, self.time_scale)
            self.slipped_s += slip
        self._last_s = now
        self._read = True
        return now

    @property
    def paused(self) -> bool:
        """Whether simulated time stands still."""
        return self._paused_at is not None

    def pause(self) -> None:
        """Stop simulated time (no effect if already paused)."""
        if self._paused_at is None:
            self._paused_at = time.monotonic()

    def resume(self) -> None:
        """Let simulated time follow the wall clock again, from where it stood."""
        if self._paused_at is not None:
            self._start += time.monotonic() - self._paused_at
            self._paused_at = None

    def advance(self, dt_s: float) -> float:
        """While paused, move simulated time forward by ``dt_s``; returns the new time."""
        if self._paused_at is None:
            raise RuntimeError("a wall clock can be stepped only while paused")
        if not 0 <= dt_s < float("inf"):
            raise ValueError(f"simulated time moves by a finite step, not backwards (dt={dt_s})")
        self._start -= dt_s / self.time_scale
        self._last_s += dt_s  # a step by hand is taken whole, whatever its length
        return self.now_s()


class VirtualClock:
    """Simulated time that moves only when told to."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._now = start_s

    def now_s(self) -> float:
        """Simulated time now."""
        return self._now

    def advance(self, dt_s: float) -> float:
        """Move time forward by ``dt_s`` and return the new time."""
        if not 0 <= dt_s < float("inf"):  # NaN or infinity would stick to the clock for good
            raise ValueError(f"virtual time moves by a finite step, not backwards (dt={dt_s})")
        self._now += dt_s
        return self._now
