"""Clocks: where simulated time comes from.

Why it exists: physics runs in simulated seconds, which follow the wall clock
(optionally K times faster or slower) when serving a real client, and follow
nothing but the test's own steps in virtual time, so physics tests are fast
and deterministic.  Timing of bytes on the wire always uses the real
monotonic clock; only the simulated world is scaled.
"""

from __future__ import annotations

import logging
import threading
import time

__all__ = ["WallClock", "VirtualClock", "MAX_STRIDE_S"]

log = logging.getLogger(__name__)

#: The most simulated time a serving loop's wall clock moves between two readings (s; :meth:`WallClock.bound_strides`).
#: Each reading is where the bus brings its physics to, so this bounds the stepping one reading can ask for: at a
#: time scale the model cannot keep up with (thousands, or many servos moving at hundreds), each catch-up took
#: longer than the one before, the serving loop never got back to a packet or a signal, and the server could not be
#: stopped.  Past it the clock slips: simulated time runs as fast as the model can step it.  A serving loop reads
#: its clock at every tick (1 ms), so at a time scale of 1 it takes a process stalled for a second to slip.
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
        #: The most simulated time between two readings, or infinity (unbounded, the default: :meth:`bound_strides`).
        self._stride_s = float("inf")
        #: The last reading (simulated s): the next moves at most ``_stride_s`` past it.
        self._last_s = 0.0
        #: Simulated time let go because the readings were further apart than the bound.
        self.slipped_s = 0.0
        #: Whether the clock has been read (a slow start before the first reading is no news) and has said so.
        self._read = self._warned = False
        #: Readings come from the serving thread and from callers' (VirtualBus.now_s): a slip is taken once.
        self._slipping = threading.Lock()

    def bound_strides(self, stride_s: float = MAX_STRIDE_S) -> None:
        """Move at most ``stride_s`` of simulated time between two readings from now on, letting the rest slip.

        For a clock a serving loop reads at every tick (:class:`~ax12emu.serve.server.BusServer`), so only a
        catch-up the model cannot finish in time, or a stalled process, makes it slip.  Left unbounded for a bus
        read only when a request comes (in process, ``ax12emu://``): there a second between requests is a second
        of the servo's time, not a slip.
        """
        if not stride_s > 0:
            raise ValueError(f"a stride must be positive, got {stride_s}")
        self._stride_s = stride_s

    @property
    def stride_s(self) -> float:
        """The most simulated time between two readings (infinity: unbounded)."""
        return self._stride_s

    def now_s(self) -> float:
        """Simulated time now (with :meth:`bound_strides`, at most the bound past the last reading)."""
        wall_s = time.monotonic() if self._paused_at is None else self._paused_at
        now = (wall_s - self._start) * self.time_scale
        if now - self._last_s > self._stride_s:
            with self._slipping:
                now = ((time.monotonic() if self._paused_at is None else self._paused_at) - self._start) * self.time_scale
                slip = now - self._last_s - self._stride_s
                if slip > 0:  # (not taken already by another thread's reading meanwhile)
                    self._start += slip / self.time_scale
                    now -= slip
                    if self._read and not self._warned:
                        self._warned = True
                        log.warning("simulated time slipped %.3g s: the model could not step as fast as --time-scale %g "
                                    "asks (or the process was stopped); it now runs as fast as the model steps", slip,
                                    self.time_scale)
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
