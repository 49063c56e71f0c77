"""The buses a live view can show, walked the same way: AX-12 (Protocol 1.0), X series (2.0), both on one wire.

Why it exists: the snapshot, the controls and the packet log each need to know which protocol
a servo speaks and which bus of a mixed wire holds it, and a mixed wire names a servo by ID *and*
protocol (IDs are per protocol there: :class:`~ax12emu.bus.mixed.MixedBus`).  These helpers say it
once, from the bus objects themselves, so no part of the live view asks "which model is this".
"""

from __future__ import annotations

from typing import Any

from ax12emu.bus import Bus
from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.mixed import MixedBus
from ax12emu.bus.wire import servo_list

__all__ = ["AnyBus", "PROTOCOL_NAMES", "parts", "protocols", "locate", "decoder_options", "protocol_name"]

AnyBus = Bus | Bus2 | MixedBus
#: How frames name the protocols, by the number ``protocol=`` takes (as VirtualBus and MixedFaults do).
PROTOCOL_NAMES = {1.0: "1.0", 2.0: "2.0"}


def parts(bus: AnyBus) -> list[tuple[float, Bus | Bus2]]:
    """(protocol, bus of that protocol) for each protocol on the wire, 1.0 first (a mixed wire's order)."""
    if isinstance(bus, MixedBus):
        return [(1.0, bus.bus1), (2.0, bus.bus2)]
    return [(2.0 if isinstance(bus, Bus2) else 1.0, bus)]


def protocols(bus: AnyBus) -> tuple[float, ...]:
    return tuple(protocol for protocol, _ in parts(bus))


def protocol_name(protocol: float) -> str:
    return PROTOCOL_NAMES[protocol]


def locate(bus: AnyBus, servo_id: int, protocol: float | None = None) -> tuple[float, Bus | Bus2, Any]:
    """(protocol, its bus, the servo) answering to ``servo_id`` now.

    KeyError if no servo has the ID; ValueError if ``protocol`` is not on this wire, or if both
    protocols of a mixed wire have the ID and ``protocol`` is not given (the message says which to give).
    """
    on_wire = parts(bus)
    if protocol is not None and protocol not in [p for p, _ in on_wire]:
        have = " and ".join(protocol_name(p) for p, _ in on_wire)
        raise ValueError(f"protocol {protocol:g}: this bus's servos speak Protocol {have}")
    found = []
    for proto, sub in on_wire:
        if protocol is not None and proto != protocol:
            continue
        try:
            found.append((proto, sub, sub.servo(servo_id)))
        except KeyError:
            pass
    if not found:
        raise KeyError(f"no servo with ID {servo_id} on the bus (IDs now: "
                       + "; ".join(f"Protocol {protocol_name(p)}: {sorted(sub.ids)}" for p, sub in on_wire) + ")")
    if len(found) > 1:
        raise ValueError(f"ID {servo_id} answers on both protocols of this wire: give protocol 1.0 or 2.0")
    return found[0]


def decoder_options(bus: AnyBus) -> dict[str, Any]:
    """The ``ax12emu decode`` decoder's options for this bus's traffic: the protocol, the AX-12 table profile, and
    every servo of the wire in the ``--servo`` form, so each ID's registers are named by its own model's table
    (an MX's, an AX-18A's on Protocol 1.0 as much as an X series servo's on 2.0), as a trace's header keeps them."""
    on_wire = parts(bus)
    # A wire of one protocol is framed by that protocol alone, as ``ax12emu decode`` reads a trace whose servos are
    # all of one: a 1.0 frame that a 2.0 packet's bytes happen to hold is no packet there. A mixed wire takes
    # "both" (each byte to both protocols' framers).
    kinds = {p for p, _ in on_wire}
    options: dict[str, Any] = {"protocol": "1.0" if kinds == {1.0} else "2.0" if kinds == {2.0} else "both"}
    for protocol, sub in on_wire:
        if protocol == 1.0:
            ax = getattr(sub, "ax_bus", sub)  # an MX bus holds its AX-12As on an AX-12 bus of their own
            profile = getattr(getattr(ax, "options", None), "profile", None)  # the AX-12 bus's table profile
            if profile is not None:
                options["profile"] = profile
    options["servos"] = servo_list(bus)
    return options
