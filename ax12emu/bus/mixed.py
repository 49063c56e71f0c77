"""One wire shared by Protocol 1.0 servos (AX-12A) and Protocol 2.0 servos (the X series).

Why it exists: robots mix generations (an arm of X-series servos beside AX-12 grippers), and a
client that speaks both protocols on one port must find each servo answering its own protocol
only.  A real wire carries every byte to every servo, and each servo's firmware frames the
stream with its own protocol's rules; here the bytes go to both buses, each with its own framer,
so a packet of one protocol is noise to the other's servos exactly as ``framing2``'s docstring
works out case by case (a stuffed 2.0 packet can hold a 1.0 header that makes the 1.0 servos wait
for bytes until their silence timeout; a 1.0 packet is never a 2.0 header).

IDs are per protocol: a 1.0 packet to ID 1 reaches the 1.0 servo with ID 1 and no 2.0 servo, so
both may have ID 1; :meth:`MixedBus.servo` therefore takes the protocol, and refuses an ID both
protocols have without it.  Both buses keep one clock.  The 1.0 bus's reply cache is bypassed (a cached
answer would skip the 2.0 framer's view of the bytes).  The faults
(:class:`~ax12emu.faults.injection.MixedFaults`) and the live view (:mod:`ax12emu.live`) reach each
servo through the bus of its protocol (``bus1``, ``bus2``).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

from ax12emu.protocol.servo_models import ServoModel, model, model_names

from .bus import Bus
from .bus2 import Bus2
from .reply import Reply

__all__ = ["MixedBus", "PROTOCOLS", "model_name", "model_of"]

#: The protocols of a mixed wire, as ``protocol=`` names them.
PROTOCOLS = (1.0, 2.0)


def model_of(servo: Any) -> ServoModel | None:
    """A servo's model file, found by the Model Number its table holds (every model file's ``model_number``
    is its table's default, and the register is read-only), so no kind of servo is named here; None if none has it."""
    number = servo.table.get("model_number")
    return next((model(key) for key in model_names() if model(key).model_number == number), None)


def model_name(servo: Any) -> str:
    """A servo's model as its model file names it (e.g. "MX-28")."""
    spec = model_of(servo)
    return spec.name if spec is not None else f"model number {servo.table.get('model_number')}"


class _Framers:
    """What the serving loop asks of a framer, for both buses' framers at once."""

    def __init__(self, *framers) -> None:
        self._framers = framers

    @property
    def buffered(self) -> int:
        return sum(framer.buffered for framer in self._framers)

    def reset(self) -> None:
        for framer in self._framers:
            framer.reset()


class MixedBus:
    """A Protocol 1.0 bus and a Protocol 2.0 bus on one wire and one clock."""

    #: Protocol 1.0 replies to one packet may collide: they are merged on the wire.
    replies_in_sequence = False

    def __init__(self, bus1: Bus, bus2: Bus2) -> None:
        if bus1.clock is not bus2.clock:
            raise ValueError("both buses of one wire must keep one clock")
        self.bus1, self.bus2 = bus1, bus2
        self.clock = bus1.clock
        self.framer = _Framers(bus1.framer, bus2.framer)
        self.faults = None

    @property
    def servos(self) -> list:
        return [*self.bus1.servos, *self.bus2.servos]

    @property
    def slots(self) -> list[int]:
        """The IDs the servos were launched with, 1.0's then 2.0's (an ID may appear once per protocol)."""
        return [*self.bus1.slots, *self.bus2.slots]

    def bus_of(self, protocol: float) -> Bus | Bus2:
        """The bus of one protocol (1.0 or 2.0); ValueError for another."""
        if protocol not in PROTOCOLS:
            raise ValueError(f"protocol must be 1.0 or 2.0, got {protocol!r}")
        return self.bus1 if protocol == 1.0 else self.bus2

    def servo(self, servo_id: int, protocol: float | None = None) -> Any:
        """The servo answering to ``servo_id`` on ``protocol`` now; without it, the only one with that ID.

        KeyError if no servo has the ID (on that protocol), ValueError if both protocols have it and
        ``protocol`` is not given.
        """
        if protocol is not None:
            return self.bus_of(protocol).servo(servo_id)
        found = []
        for bus in (self.bus1, self.bus2):
            try:
                found.append(bus.servo(servo_id))
            except KeyError:
                pass
        if not found:
            raise KeyError(f"no servo with ID {servo_id} on this wire (Protocol 1.0 IDs now: {sorted(self.bus1.ids)}, "
                           f"Protocol 2.0: {sorted(self.bus2.ids)})")
        if len(found) > 1:
            raise ValueError(f"ID {servo_id} answers on both protocols of this wire ({model_name(found[0])} on 1.0, "
                             f"{model_name(found[1])} on 2.0): give protocol=1.0 or protocol=2.0")
        return found[0]

    def holder(self, servo: Any) -> Any:
        """The bus that holds ``servo`` (its faults, its model): within the protocol's bus, its own holder."""
        for bus in (self.bus1, self.bus2):
            if any(servo is s for s in bus.servos):
                return bus.holder(servo)
        raise KeyError(f"ID {servo.id}: not a servo of this wire")

    def reindex(self) -> None:
        """Look servos up by the IDs in their tables again, on both buses."""
        self.bus1.reindex()
        self.bus2.reindex()

    @property
    def ids(self) -> list[int]:
        return [*self.bus1.ids, *self.bus2.ids]

    @property
    def request_lag_s(self) -> float:
        return self.bus1.request_lag_s

    @request_lag_s.setter
    def request_lag_s(self, lag_s: float) -> None:
        self.bus1.request_lag_s = self.bus2.request_lag_s = lag_s

    @property
    def physics_step_s(self) -> float:
        return min(self.bus1.physics_step_s, self.bus2.physics_step_s)

    def advance(self) -> bool:
        moved1 = self.bus1.advance()
        return self.bus2.advance() or moved1

    def advance_in_pieces(self) -> Iterator[None]:
        yield from self.bus1.advance_in_pieces()
        yield from self.bus2.advance_in_pieces()

    def cached_replies(self, data: bytes, line_bps: float | None = None) -> Sequence[Reply] | None:
        """No reply cache on a mixed wire: always None."""
        return None

    def answer(self, data: bytes, now_s: float | None = None, *, line_bps: float | None = None,
               cache: bool = True, looked_up: bool = False) -> list[Sequence[Reply]]:
        """Both protocols' servos hear ``data``; the replies of each completed packet, 1.0's first."""
        return [*self.bus1.answer(data, now_s, line_bps=line_bps, cache=False),
                *self.bus2.answer(data, now_s, line_bps=line_bps)]

    def receive(self, data: bytes, now_s: float | None = None, *, line_bps: float | None = None) -> list[Reply]:
        return [reply for replies in self.answer(data, now_s, line_bps=line_bps) for reply in replies]

    def expire(self, now_s: float) -> None:
        self.bus1.expire(now_s)
        self.bus2.expire(now_s)

    def close(self) -> None:
        self.bus1.close()
        self.bus2.close()

    def __enter__(self) -> "MixedBus":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
