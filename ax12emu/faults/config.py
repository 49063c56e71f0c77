"""Faults as data: the ``serve`` flags and ``ax12emu://`` URL options parsed into a :class:`FaultConfig`.

Why apart from :mod:`ax12emu.faults.injection`: that module bends what the servos do
while the bus runs; this one only turns text into a frozen description
(with a clear ``ValueError`` naming the option for bad text) and installs
it on a bus.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ax12emu.protocol.ids import parse_ids

from .injection import (
    DEFAULT_REPLY_DELAY_S,
    HW_ERROR_NAMES,
    MAX_REPLY_DELAY_S,
    Faults,
    MixedFaults,
    faults_for,
    parse_alarm_bits,
)

if TYPE_CHECKING:
    from ax12emu.bus.bus import Bus
    from ax12emu.bus.bus2 import Bus2
    from ax12emu.bus.mixed import MixedBus

__all__ = ["FaultConfig", "FAULT_OPTIONS"]


def _fraction(text: str) -> float:
    value = float(text)
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"expected a fraction 0..1, got {text}")
    return value


def _delay_s(text: str) -> float:
    value = float(text)
    if not 0.0 <= value <= MAX_REPLY_DELAY_S:
        raise ValueError(f"expected seconds 0..{MAX_REPLY_DELAY_S:g}, got {text}")
    return value


def _pair(text: str) -> tuple[int, int]:
    left, sep, right = text.partition(":")
    if not sep:
        raise ValueError(f"expected SLOT:ID, got {text!r}")
    return int(left), int(right)


def _vanish(text: str) -> tuple[int, float | None, float | None]:
    """"ID" (absent) or "ID:EVERY_S:FOR_S" (absent FOR_S of every EVERY_S)."""
    parts = text.split(":")
    if len(parts) == 1:
        return int(parts[0]), None, None
    if len(parts) == 3:
        every_s, for_s = float(parts[1]), float(parts[2])
        if not (math.isfinite(every_s) and math.isfinite(for_s)):  # an infinite period: gone FOR_S, then never again
            raise ValueError(f"expected finite seconds in ID:EVERY_S:FOR_S, got {text!r} (to unplug for good: ID alone)")
        return int(parts[0]), every_s, for_s
    raise ValueError(f"expected ID or ID:EVERY_S:FOR_S, got {text!r}")


def _alarm(text: str) -> tuple[int, int | str]:
    """"ID:NAMES": the bits when every name means the same on both protocols, else the names.

    Why not always bits: an X series name (electrical_shock, encoder) is a Hardware Error Status
    bit whose number is another error on the AX-12 (0x10 its Checksum Error), so it is kept as a
    name for the bus to refuse or take; a name neither knows is refused here.
    """
    slot, sep, names = text.partition(":")
    if not sep:
        raise ValueError(f"expected ID:ALARMS (e.g. 1:overload), got {text!r}")
    try:
        return int(slot), parse_alarm_bits(names)
    except ValueError:
        parse_alarm_bits(names, HW_ERROR_NAMES)  # ValueError naming the X series' names too
        return int(slot), names.strip().lower()


def _ids(text: str) -> tuple[int, ...]:
    """An ID list as ``--ids`` takes it ("1,2,5", "1-3")."""
    return tuple(parse_ids(text))


@dataclass(frozen=True)
class FaultConfig:
    """Faults as data, for ``ax12emu serve`` flags and ``ax12emu://`` URL options."""

    #: Fraction of status packets dropped (client: timeout).
    drop: float = 0.0
    #: Fraction of status packets sent with a wrong checksum (client: corrupt packet).
    corrupt: float = 0.0
    #: Fraction of status packets sent ``delay_s`` late (client: timeout, then stray bytes).
    delay: float = 0.0
    delay_s: float = 0.1
    #: Wire IDs the three above apply to; empty: all.
    fault_ids: tuple[int, ...] = ()
    #: Seed of the random choices.
    seed: int = 0
    #: (slot, every_s, for_s): unplugged servos, always or periodically.
    vanish: tuple[tuple[int, float | None, float | None], ...] = ()
    #: (slot, as_id): a servo answering to another's ID.
    duplicate: tuple[tuple[int, int], ...] = ()
    #: (slot, bits or names): forced alarms (an X-series name such as "electrical_shock" stays a name).
    alarm: tuple[tuple[int, int | str], ...] = ()
    #: Slots whose shaft is blocked.
    stall: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        # Built in Python, one fault given bare (duplicate=(2, 1)) failed deep in install with a TypeError naming nothing.
        for name, width in (("vanish", 3), ("duplicate", 2), ("alarm", 2)):
            value = getattr(self, name)
            if not isinstance(value, tuple) or not all(isinstance(item, tuple) and len(item) == width for item in value):
                raise ValueError(f"{name} takes a tuple of {width}-tuples, one per servo, got {value!r}")
        for name in ("stall", "fault_ids"):
            value = getattr(self, name)
            if not isinstance(value, tuple) or not all(isinstance(item, int) and not isinstance(item, bool) for item in value):
                raise ValueError(f"{name} takes a tuple of IDs, got {value!r}")
        for refusal in _DOES_NOTHING:  # each setting that did nothing (or not what it said), without a word
            says = refusal(self)
            if says:
                raise ValueError(says)

    @property
    def active(self) -> bool:
        """Whether any fault is configured."""
        return any((self.drop, self.corrupt, self.delay, self.vanish, self.duplicate, self.alarm, self.stall))

    def install(self, bus: "Bus | Bus2 | MixedBus") -> "Faults | MixedFaults":
        """Attach a :class:`Faults` with this configuration to ``bus`` and return it.

        On a Protocol 2.0 bus: :class:`~.injection.Faults2` (its firmware acts out ``alarm``,
        ``stall`` and ``hold``); on a Protocol 1.0 wire with MX servos: :class:`~.injection.Faults1X`.  On a wire mixing protocols: :class:`~.injection.MixedFaults`, where
        a slot launched on both protocols is a ValueError (the options cannot name the protocol).
        """
        if self.fault_ids:  # IDs no servo answers as: the reply faults did nothing, without a word
            on_wire = set(bus.slots) | set(getattr(bus, "ids", ())) | {as_id for _, as_id in self.duplicate}
            missing = sorted(set(self.fault_ids) - on_wire)
            if missing:
                raise ValueError(f"fault_ids: no servo on this wire answers as ID {', '.join(map(str, missing))} "
                                 f"(its IDs: {', '.join(map(str, sorted(on_wire)))})")
        named = [slot for slot, *_ in (*self.vanish, *self.duplicate, *self.alarm)] + list(self.stall)
        both = set(getattr(getattr(bus, "bus1", None), "slots", ())) & set(getattr(getattr(bus, "bus2", None), "slots", ()))
        for slot in named:
            if slot in both:  # the Python API's answer (protocol=) is no option here
                raise ValueError(f"ID {slot} was launched on both protocols of this wire, and a fault option cannot say "
                                 "which servo it means: launch them on different IDs, or inject the fault from Python "
                                 "(bus.faults.<fault>(..., protocol=1.0 or 2.0))")
        faults = faults_for(bus, seed=self.seed)
        faults.set_reply_faults(
            drop=self.drop, corrupt=self.corrupt, delay=self.delay, delay_s=self.delay_s, ids=self.fault_ids or None
        )
        for slot, every_s, for_s in self.vanish:
            faults.vanish(slot, every_s=every_s, for_s=for_s)
        for slot, as_id in self.duplicate:
            faults.duplicate(slot, as_id)
        for slot, bits in self.alarm:
            faults.force_alarm(slot, bits)
        for slot in self.stall:
            faults.stall(slot)
        bus.faults = faults
        return faults

    @classmethod
    def from_options(cls, options: Mapping[str, list[str]]) -> "FaultConfig":
        """Build from name -> values (URL query or flags); unknown names are the caller's business."""
        values: dict[str, object] = {}
        for name, texts in options.items():
            parse, repeated = FAULT_OPTIONS[name]
            try:
                parsed = [parse(text) for text in texts]
            except ValueError as exc:
                raise ValueError(f"{name}: {exc}") from None
            values[name] = tuple(parsed) if repeated else parsed[-1]
        return cls(**values)  # type: ignore[arg-type]


def _fault_ids_alone(config: FaultConfig) -> str | None:
    if config.fault_ids and not (config.drop or config.corrupt or config.delay):
        return "fault_ids: names the IDs drop, corrupt and delay act on, and none of them is given"
    return None


def _delay_s_alone(config: FaultConfig) -> str | None:
    if config.delay_s != DEFAULT_REPLY_DELAY_S and not config.delay:
        return f"delay_s: how late the delay option's replies leave ({config.delay_s:g} s), and delay is not given"
    return None


def _slot_named_twice(config: FaultConfig) -> str | None:
    """A second vanish or duplicate of one servo replaced the first: one period, one ID per servo."""
    for name in ("vanish", "duplicate"):
        slots = [slot for slot, *_ in getattr(config, name)]
        twice = sorted({slot for slot in slots if slots.count(slot) > 1})
        if twice:
            return f"{name}: ID {', '.join(map(str, twice))} named more than once; a servo takes one {name}"
    return None


def _duplicate_as_itself(config: FaultConfig) -> str | None:
    same = [slot for slot, as_id in config.duplicate if slot == as_id]
    if same:
        return (f"duplicate: {same[0]}:{same[0]} gives servo {same[0]} the ID it was launched as, which changes nothing "
                "(SLOT:ID gives it another servo's ID)")
    return None


#: The checks of a FaultConfig's settings that would do nothing, or not what they say: each the refusal's text or None.
_DOES_NOTHING: tuple[Callable[[FaultConfig], str | None], ...] = (
    _fault_ids_alone, _delay_s_alone, _slot_named_twice, _duplicate_as_itself,
)


#: Option name -> (parser of one value, may repeat).
FAULT_OPTIONS: Mapping[str, tuple[Callable[[str], object], bool]] = {
    "drop": (_fraction, False),
    "corrupt": (_fraction, False),
    "delay": (_fraction, False),
    "delay_s": (_delay_s, False),
    "fault_ids": (_ids, False),
    "seed": (int, False),
    "vanish": (_vanish, True),
    "duplicate": (_pair, True),
    "alarm": (_alarm, True),
    "stall": (int, True),
}
