"""The wire built from a ``--servo`` text: the one place that decides which bus serves which servo.

Why it exists: ``serve --servo``, ``VirtualBus(servo=...)``, ``ax12emu://?servo=...`` and the pytest
plugin must read the same servo text (:func:`ax12emu.protocol.servo_spec.parse_servo_spec`) and build
the same servos from it: each ID's model file gives its table, and
:func:`ax12emu.servo.model_factory2.build_x_firmware` its firmware model, so no model is named here.
:func:`build_wire` decides the bus: the X series on a Protocol 2.0 bus, the MX series on a Protocol
1.0 :class:`~ax12emu.bus.bus1x.Bus1X`, AX-12As and AX-18As on the AX-12 bus (inside the MX servos'
when both are named), and both protocols on one wire (:class:`~ax12emu.bus.mixed.MixedBus`).  It
lives in the bus layer so the command line and the harness above both import it.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace

from ax12emu.protocol.control_table import AX12_MODEL, PROTOCOL1_MODELS
from ax12emu.protocol.servo_models import model, model_names
from ax12emu.protocol.servo_spec import parse_servo_spec
from ax12emu.servo.model_factory import ModelChoice, build_protocol1_model
from ax12emu.servo.model_factory2 import XModelChoice, build_x_firmware
from ax12emu.servo.plant1x import build_plant1x
from ax12emu.servo.servo1x import Servo1XOptions
from ax12emu.servo.servo2 import Servo2Options
from ax12emu.servo.virtual_servo import ServoOptions

from .bus import BAUD_TOLERANCE, Bus
from .bus1x import Bus1X
from .bus2 import Bus2
from .clock import VirtualClock, WallClock
from .mixed import MixedBus, model_name, model_of
from .state_store import StateStore

__all__ = ["build_bus2", "build_wire", "build_wire_of", "protocol1_keys", "servo_family", "servo_list", "servo_models",
           "attach_wire_stores", "save_wire_state", "start_at_baud"]

log = logging.getLogger(__name__)


def protocol1_keys() -> tuple[str, ...]:
    """Every model served on Protocol 1.0 only: the AX-shaped tables (the AX-12 bus) and the MX series' (bus1x)."""
    return tuple(key for key in model_names() if "1.0" in model(key).protocols and "2.0" not in model(key).protocols)


def servo_models(spec: str, ids: list[int] | None, *, mixed: bool = False) -> list[tuple[int, str]]:
    """(ID, model key) per servo; ``ids`` None with a bare MODEL means ID 1. ``ValueError`` names the mistake.

    ``mixed``: the Protocol 1.0 models (AX-12A, AX-18A, the MX series) are taken beside the X series, as on a mixed wire.
    """
    if ids is None and ":" not in spec:
        ids = [1]
    return parse_servo_spec(spec, ids, also=protocol1_keys() if mixed else ())


def servo_family(key: str) -> str:
    """Which bus of a wire serves a model: "AX" (the AX-12 bus: AX-12A, AX-18A), "MX" (Protocol 1.0 on its own
    firmware model) or "X" (Protocol 2.0)."""
    if key in PROTOCOL1_MODELS:
        return "AX"
    return "X" if "2.0" in model(key).protocols else "MX"


def build_wire(spec: str, ids: list[int] | None = None, *, clock: WallClock | VirtualClock,
               baud_bps: float | None = None, choice: XModelChoice = XModelChoice(),
               options: Servo2Options = Servo2Options(), choice1: ModelChoice | None = None,
               options1: ServoOptions | None = None) -> Bus | Bus1X | Bus2 | MixedBus:
    """The bus ``spec``'s servos need: each protocol's servos on its own bus, and both on one wire (a MixedBus)
    when the text names both (:func:`build_wire_of` builds it).  ``choice1`` and ``options1`` shape the AX
    bus's servos (the AX-12As and AX-18As) and are refused where ``spec`` names none."""
    models = servo_models(spec, ids, mixed=True)
    if (choice1 is not None or options1 is not None) and not any(servo_family(key) == "AX" for _, key in models):
        raise ValueError(f"the AX bus's model and options shape AX-12As and AX-18As; {spec!r} names none")
    if options1 is not None and options1.profile != ServoOptions().profile:
        raise ValueError("profile: the AX-12A bus alone takes another edition of the AX-12A's table (leave out servo=)")
    return build_wire_of(models, clock=clock, baud_bps=baud_bps, choice=choice, options=options, choice1=choice1,
                         options1=ServoOptions() if options1 is None else options1)


def build_wire_of(models: Sequence[tuple[int, str]], *, clock: WallClock | VirtualClock,
                  baud_bps: float | None = None, choice: XModelChoice = XModelChoice(),
                  choice1: ModelChoice | None = None,
                  options: Servo2Options = Servo2Options(), options1: ServoOptions = ServoOptions(),
                  options1x: Servo1XOptions = Servo1XOptions(), state_store1: StateStore | None = None,
                  state_store2: StateStore | None = None, load_state: bool = True) -> Bus | Bus1X | Bus2 | MixedBus:
    """The bus for these (ID, model key) servos.

    Protocol 1.0: AX-12As and AX-18As on the AX-12 bus (:class:`Bus`, ``options1``; their physics is ``choice1``,
    by default ``choice``'s supply and torque as the X series' takes them); MX servos on :class:`Bus1X` (``options1x``), which
    holds the AX bus inside when both are named.  Protocol 2.0: :class:`Bus2` (``options``).  Every servo
    starts at its model's factory rate (1,000,000 bps on the AX series, 57,600 on the MX (Baud Rate 34) and X series) unless
    ``baud_bps``, which each servo turns into its own Baud Rate value.  ``state_store1``/``state_store2``: where
    each protocol's servos keep their EEPROM area (IDs are per protocol, so apart); ``load_state`` False starts
    from factory defaults and still saves there (:func:`save_wire_state` writes them at once).
    """
    ax = [(servo_id, key) for servo_id, key in models if servo_family(key) == "AX"]
    mx = [(servo_id, model(key)) for servo_id, key in models if servo_family(key) == "MX"]
    x_models = [(servo_id, model(key)) for servo_id, key in models if servo_family(key) == "X"]
    bus1: Bus | Bus1X | None = None
    if ax:
        keys1 = [key for _, key in ax]
        physics = build_protocol1_model(keys1, replace(choice1, profile=options1.profile) if choice1 is not None else ModelChoice(
            voltage_v=choice.voltage_v, external_torque_nm=choice.external_torque_nm, profile=options1.profile))
        bus1 = Bus([servo_id for servo_id, _ in ax], clock=clock, model=physics, options=options1,
                   state_store=state_store1 if load_state else None,
                   table_layout=[None if key == AX12_MODEL else model(key).layout() for key in keys1])
        bus1.state_store = state_store1
    if mx:
        bus1 = Bus1X(mx, lambda servo_model, servo: build_plant1x(servo_model, servo.table, choice), ax_bus=bus1,
                     clock=clock, options=options1x, state_store=state_store1 if load_state else None)
        bus1.state_store = state_store1
    bus2 = None
    if x_models:
        bus2 = Bus2(x_models, lambda servo_model, index: build_x_firmware(servo_model, choice), clock=clock,
                    options=options, state_store=state_store2 if load_state else None)
        bus2.state_store = state_store2
    if baud_bps is not None:
        # A servo whose EEPROM the state directory kept starts at the Baud Rate it kept, as a real one does after a
        # client changed it (``baud_bps`` overwrote it at every start, and the file with it).
        def kept(store: StateStore | None, slot: int, servo) -> bool:
            if not (load_state and store is not None and store.path_for(slot).exists()):
                return False
            if abs(servo.baud_bps - baud_bps) > BAUD_TOLERANCE * baud_bps:
                log.info("ID %d starts at the %.0f bps its state file %s keeps, not at --baud's %.0f", slot,
                         servo.baud_bps, store.path_for(slot), baud_bps)
            return True

        for slot, servo in zip(bus1.slots, bus1.servos) if bus1 is not None else ():
            if not kept(state_store1, slot, servo):
                start_at_baud(servo, baud_bps)
        for slot, servo in zip(bus2.slots, bus2.servos) if bus2 is not None else ():
            if not kept(state_store2, slot, servo):
                servo.start_at_baud(baud_bps)
    if bus1 is not None and bus2 is not None:
        return MixedBus(bus1, bus2)
    return bus1 if bus1 is not None else bus2  # type: ignore[return-value]


def attach_wire_stores(wire: Bus | Bus1X | Bus2 | MixedBus, state_store1: StateStore | None,
                       state_store2: StateStore | None) -> None:
    """Give each protocol's servos on ``wire`` their state store (an MX bus's AX-12As the Protocol 1.0 one), as
    :func:`build_wire_of` does.

    Why: ``serve --factory-reset`` builds its wire without them and attaches them once the server has started. A
    run refused after the build (a live view whose port is taken) closes its bus, and a bus with a store saves as
    it closes: the factory image it never served replaced the saved state.
    """
    for part in (wire.bus1, wire.bus2) if isinstance(wire, MixedBus) else (wire,):
        part.state_store = state_store2 if isinstance(part, Bus2) else state_store1
        if isinstance(part, Bus1X) and part.ax_bus is not None:
            part.ax_bus.state_store = state_store1


def save_wire_state(wire: Bus | Bus1X | Bus2 | MixedBus) -> None:
    """Every servo's EEPROM on ``wire`` (each protocol's, an MX bus's AX-12As too) written to its state store now.

    Why: ``serve --factory-reset`` serves the factory image without loading the saved one; saved only at exit, a
    server killed before then left the old files for the next run to serve.  The server saves once it has started
    (after every check that can refuse the run, which then leaves the state alone).
    """
    for part in (wire.bus1, wire.bus2) if isinstance(wire, MixedBus) else (wire,):
        if isinstance(part, Bus1X) and part.ax_bus is not None:
            part.ax_bus.save_state()
        part.save_state()


def start_at_baud(servo, bps: float) -> None:
    """Set a Protocol 1.0 servo's Baud Rate to the value whose rate is nearest ``bps``, as the servo itself says each
    value's rate (an MX's 250..252 are 2.25..3 Mbps, an AX-12A's are not); ValueError if none is within a UART's 3 %."""
    rates = servo.baud_rates_bps
    value = min(rates, key=lambda v: abs(rates[v] - bps))
    if abs(rates[value] - bps) > BAUD_TOLERANCE * bps:
        raise ValueError(f"ID {servo.id} ({model_name(servo)}) cannot run at {bps:.0f} bps: its Baud Rate values give "
                         f"{min(rates.values()):.0f}..{max(rates.values()):.0f} bps, none within 3 %")
    servo.table.set("baud_rate", value)


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


def servo_list(bus: Bus | Bus1X | Bus2 | MixedBus) -> str:
    """Every servo of the wire in the per-ID ``--servo`` form (launch ID: model key), as a trace's header keeps them
    (``ax12emu decode`` names each ID's registers by its model's table)."""
    keys = []
    for slot, servo in zip(bus.slots, bus.servos):  # each bus lists its slots and servos in one order
        spec = model_of(servo)
        if spec is None:
            raise ValueError(f"ID {slot}: no model file has Model Number {servo.table.get('model_number')}")
        keys.append(f"{slot}:{spec.key}")
    return ",".join(keys)
