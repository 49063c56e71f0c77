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
    """Simulated seconds since creation, at ``time_scale`` simulated seconds per wall second.

    A tester watching the live view can pause it (simulated time stands
    still, so the physics does) and step it by hand while paused, as a
    :class:`VirtualClock` is stepped.
    """

    def __init__(self, time_scale: float = 1.0) -> None:
        if not time_scale > 0:
            raise ValueError(f"time scale must be positive, got {time_scale}")
        self.time_scale = time_scale
        self._start = time.monotonic()
        self._paused_at: float | None = None

    def now_s(self) -> float:
        """Simulated time now."""
        wall_s = time.monotonic() if self._paused_at is None else self._paused_at
        return (wall_s - self._start) * self.time_scale

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
        if dt_s < 0:
            raise ValueError(f"simulated time cannot go backwards (dt={dt_s})")
        self._start -= dt_s / self.time_scale
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
        if dt_s < 0:
            raise ValueError(f"virtual time cannot go backwards (dt={dt_s})")
        self._now += dt_s
        return self._now
