"""A Protocol 2.0 bus built from the ``--servo`` text, for the harness (VirtualBus, ``ax12emu://``).

Why it exists: ``VirtualBus(servo="xl430-w250")`` and ``ax12emu://?servo=...`` must read the same
servo text the command line does (:func:`ax12emu.protocol.servo_spec.parse_servo_spec`) and build
the same servos from it: each ID's model file gives its table, and
:func:`ax12emu.servo.model_factory2.build_x_firmware` its firmware model, so no model is named here.
AX-12As and AX-18As in the text (``1-2:ax-12a,3-6:xl430-w250``) share the wire on Protocol 1.0
(:class:`~ax12emu.bus.mixed.MixedBus`), as ``serve --servo`` puts them; AX-18As alone (or with
AX-12As) are a Protocol 1.0 bus.
"""

from __future__ import annotations

from ax12emu.bus.bus import Bus
from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock, WallClock
from ax12emu.bus.mixed import MixedBus
from ax12emu.protocol.control_table import AX12_MODEL, PROTOCOL1_MODELS
from ax12emu.protocol.servo_models import model
from ax12emu.protocol.servo_spec import parse_servo_spec
from ax12emu.servo.model_factory import build_protocol1_model
from ax12emu.servo.model_factory2 import XModelChoice, build_x_firmware
from ax12emu.servo.servo2 import Servo2Options
from ax12emu.servo.virtual_servo import baud_value

__all__ = ["build_bus2", "build_wire", "servo_list", "servo_models"]


def servo_models(spec: str, ids: list[int] | None, *, mixed: bool = False) -> list[tuple[int, str]]:
    """(ID, model key) per servo; ``ids`` None with a bare MODEL means ID 1. ``ValueError`` names the mistake.

    ``mixed``: AX-12As and AX-18As (Protocol 1.0) are taken beside the X series, as on a mixed wire.
    """
    if ids is None and ":" not in spec:
        ids = [1]
    return parse_servo_spec(spec, ids, also=PROTOCOL1_MODELS if mixed else ())


def build_wire(spec: str, ids: list[int] | None = None, *, clock: WallClock | VirtualClock,
               baud_bps: float | None = None, choice: XModelChoice = XModelChoice(),
               options: Servo2Options = Servo2Options()) -> Bus | Bus2 | MixedBus:
    """:func:`build_bus2`, or, if ``spec`` names AX-12As or AX-18As too, both protocols' servos on one wire
    (a MixedBus), or a Protocol 1.0 bus when it names no X-series servo (AX-18As among them).

    The AX servos start at their factory 1,000,000 bps, the X series at theirs (57,600), unless ``baud_bps``.
    """
    models = servo_models(spec, ids, mixed=True)
    ax = [(servo_id, key) for servo_id, key in models if "2.0" not in model(key).protocols]
    if not ax:
        return build_bus2(spec, ids, clock=clock, baud_bps=baud_bps, choice=choice, options=options)
    keys1 = [key for _, key in ax]
    if len(ax) == len(models) and set(keys1) == {AX12_MODEL}:
        raise ValueError(f"{spec!r} names no Protocol 2.0 servo; AX-12As alone are the default bus (leave out servo=)")
    x_models = [(servo_id, key) for servo_id, key in models if "2.0" in model(key).protocols]
    bus1 = Bus([servo_id for servo_id, _ in ax], clock=clock, model=build_protocol1_model(keys1),
               table_layout=[None if key == AX12_MODEL else model(key).layout() for key in keys1])
    bus2 = (Bus2([(servo_id, model(key)) for servo_id, key in x_models],
                 lambda servo_model, index: build_x_firmware(servo_model, choice), clock=clock, options=options)
            if x_models else None)
    if baud_bps is not None:
        value = baud_value(baud_bps)  # ValueError if an AX-12A cannot run at it
        for servo in bus1.servos:
            servo.table.set("baud_rate", value)
        for servo in bus2.servos if bus2 is not None else ():
            servo.start_at_baud(baud_bps)
    return MixedBus(bus1, bus2) if bus2 is not None else bus1


def build_bus2(spec: str, ids: list[int] | None = None, *, clock: WallClock | VirtualClock,
               baud_bps: float | None = None, choice: XModelChoice = XModelChoice(),
               options: Servo2Options = Servo2Options()) -> Bus2:
    """The servos ``spec`` names on one Protocol 2.0 bus; ``baud_bps``: all start at that rate (else each model's factory rate)."""
    bus = Bus2([(servo_id, model(key)) for servo_id, key in servo_models(spec, ids)],
               lambda servo_model, index: build_x_firmware(servo_model, choice), clock=clock, options=options)
    if baud_bps is not None:
        for servo in bus.servos:
            servo.start_at_baud(baud_bps)
    return bus


def servo_list(bus: Bus2 | MixedBus) -> str:
    """The bus's Protocol 2.0 servos in the per-ID ``--servo`` form (launch ID: model key), as a trace's header keeps them."""
    if isinstance(bus, MixedBus):
        bus = bus.bus2
    return ",".join(f"{slot}:{servo.spec.name.lower()}" for slot, servo in zip(bus.slots, bus.servos))
