"""Servos looked up by the IDs in their tables: what every bus needs to know who a packet is for.

Why a module of its own: the Protocol 1.0 and 2.0 buses look servos up alike (an ID is a
register, so it changes when a packet or a fault writes it, and two servos may share one), and
refuse the same launch IDs.
"""

from __future__ import annotations

from typing import Generic, Protocol, TypeVar

__all__ = ["ServosById", "check_ids"]


def check_ids(ids: list[int], max_id: int, protocol_note: str = "") -> None:
    """ValueError for the IDs a bus is launched with when there are none, one repeats, or one lies outside 0..max_id."""
    if not ids:
        raise ValueError("a bus needs at least one servo")
    if len(set(ids)) != len(ids):
        raise ValueError(f"duplicate IDs in {ids}")
    for servo_id in ids:
        if not 0 <= servo_id <= max_id:
            raise ValueError(f"ID {servo_id} is outside 0..{max_id}{protocol_note}")


class _HasId(Protocol):
    @property
    def id(self) -> int: ...


S = TypeVar("S", bound=_HasId)


class ServosById(Generic[S]):
    """A bus's servos (``self.servos``, in slot order) by their present IDs; call :meth:`reindex` once set."""

    servos: list[S]
    _by_id: dict[int, list[S]]
    #: The protocol the bus's servos speak, as ``protocol=`` names it (1.0 or 2.0).
    protocol: float

    def reindex(self) -> None:
        """Look servos up by the IDs in their tables again (after an ID changed outside a packet)."""
        by_id: dict[int, list[S]] = {}
        for servo in self.servos:
            by_id.setdefault(servo.id, []).append(servo)
        self._by_id = by_id

    def servo(self, servo_id: int, protocol: float | None = None) -> S:
        """The (first) servo answering to ``servo_id`` now; ``protocol``, if given, must be the bus's (ValueError)."""
        if protocol is not None and protocol != self.protocol:
            raise ValueError(f"protocol={protocol}: this bus's servos all speak Protocol {self.protocol}")
        try:
            return self._by_id[servo_id][0]
        except KeyError:
            raise KeyError(f"no servo with ID {servo_id} on the bus (IDs now: {sorted(self._by_id)})") from None

    def holder(self, servo: S) -> "ServosById[S]":
        """The bus that holds ``servo`` (its faults, its model): this one; a bus of buses names the inner one."""
        return self

    @property
    def ids(self) -> list[int]:
        """Present IDs, in slot order."""
        return [servo.id for servo in self.servos]
