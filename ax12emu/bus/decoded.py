"""What a bus that decodes every packet does with the bytes it hears, and with its servos' saved state.

Why a module of its own: the MX series' Protocol 1.0 bus (:class:`~.bus1x.Bus1X`) and the Protocol 2.0
bus (:class:`~.bus2.Bus2`) keep no reply cache (the AX-12 bus's, :class:`~.bus.Bus`, is what its
polling hosts' speed rests on), so both frame the bytes, dispatch each whole packet, judge whether a
servo hears the line's rate, and persist a servo's EEPROM area after a write changed it, the same way.
A bus brings its own ``framer``, ``dispatch`` and ``reindex``, and the servos it persists if not all
its ``slots`` and ``servos``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, TypeVar

from .bus import BAUD_TOLERANCE
from .reply import Reply
from .state_store import StateStore

__all__ = ["DecodedBus"]

_B = TypeVar("_B", bound="DecodedBus")


class DecodedBus:
    """Bytes in, every packet decoded and dispatched; state saved per launch ID (a mixin)."""

    framer: Any
    slots: list[int]
    servos: list
    state_store: StateStore | None
    _closed: bool

    def _persisted(self) -> Iterable[tuple[int, Any]]:
        """(launch ID, servo) for each servo whose EEPROM area this bus keeps in its state store."""
        return zip(self.slots, self.servos)

    # -- bytes in, replies out ---------------------------------------------------------
    def receive(self, data: bytes, now_s: float | None = None, *, line_bps: float | None = None) -> list[Reply]:
        """Feed bytes that arrived at wall time ``now_s``; return the replies they cause."""
        return [reply for replies in self.answer(data, now_s, line_bps=line_bps) for reply in replies]

    def cached_replies(self, data: bytes, line_bps: float | None = None) -> Sequence[Reply] | None:
        """No reply cache on this bus: always None (every packet is decoded)."""
        return None

    def answer(self, data: bytes, now_s: float | None = None, *, line_bps: float | None = None,
               cache: bool = True, looked_up: bool = False) -> list[Sequence[Reply]]:
        """Feed bytes; return the replies to each packet they completed, one sequence per packet."""
        return [self.dispatch(packet, line_bps=line_bps) for packet in self.framer.feed(data, now_s)]

    def expire(self, now_s: float) -> None:
        """Let the framer drop a partial packet after silence."""
        self.framer.expire(now_s)

    @staticmethod
    def _hears(servo: Any, line_bps: float | None) -> bool:
        """Whether ``servo`` hears a host sending at ``line_bps`` (None: the transport knows no rate, all hear)."""
        baud = servo.baud_bps
        return line_bps is None or abs(line_bps - baud) <= BAUD_TOLERANCE * baud

    def _after_writes(self) -> None:
        """After a packet that may have written: look IDs up again, persist the EEPROM areas it changed."""
        self.reindex()
        for slot, servo in self._persisted():
            if servo.eeprom_dirty:
                servo.eeprom_dirty = False
                if self.state_store is not None:
                    self.state_store.save_or_say(slot, servo.table, servo.backup)

    # -- life cycle --------------------------------------------------------------------
    def save_state(self) -> None:
        """Write every servo's EEPROM area to the state store (if any); a failure is said once, as mid-session, and
        the bus closes anyway."""
        if self.state_store is not None:
            for slot, servo in self._persisted():
                self.state_store.save_or_say(slot, servo.table, servo.backup)

    def close(self) -> None:
        """Save state; safe to call more than once."""
        if not self._closed:
            self._closed = True
            self.save_state()

    def __enter__(self: _B) -> _B:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
