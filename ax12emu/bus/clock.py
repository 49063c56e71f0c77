"""Clocks: where simulated time comes from.

Why it exists: physics runs in simulated seconds, which follow the wall clock
(optionally K times faster or slower) when serving a real client, and follow
nothing but the test's own steps in virtual time, so physics tests are fast
and deterministic.  Timing of bytes on the wire always uses the real
monotonic clock; only the simulated world is scaled.
"""

from __future__ import annotations

import time

__all__ = ["WallClock", "VirtualClock"]


class WallClock:
    """Simulated seconds since creation, at ``time_scale`` simulated seconds per wall second."""

    def __init__(self, time_scale: float = 1.0) -> None:
        if not time_scale > 0:
            raise ValueError(f"time scale must be positive, got {time_scale}")
        self.time_scale = time_scale
        self._start = time.monotonic()

    def now_s(self) -> float:
        """Simulated time now."""
        return (time.monotonic() - self._start) * self.time_scale


class VirtualClock:
    """Simulated time that moves only when told to."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._now = start_s

    def now_s(self) -> float:
        """Simulated time now."""
        return self._now

    def advance(self, dt_s: float) -> float:
        """Move time forward by ``dt_s`` and return the new time."""
        if dt_s < 0:
            raise ValueError(f"virtual time cannot go backwards (dt={dt_s})")
        self._now += dt_s
        return self._now
