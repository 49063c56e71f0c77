"""A Protocol 2.0 bus built from the ``--servo`` text, for the harness (VirtualBus, ``ax12emu://``).

Why it exists: ``VirtualBus(servo="xl430-w250")`` and ``ax12emu://?servo=...`` must read the same
servo text the command line does (:func:`ax12emu.protocol.servo_spec.parse_servo_spec`) and build
the same servos from it: each ID's model file gives its table, and
:func:`ax12emu.servo.model_factory2.build_x_firmware` its firmware model, so no model is named here.
"""

from __future__ import annotations

from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock, WallClock
from ax12emu.protocol.servo_models import model
from ax12emu.protocol.servo_spec import parse_servo_spec
from ax12emu.servo.model_factory2 import XModelChoice, build_x_firmware
from ax12emu.servo.servo2 import Servo2Options

__all__ = ["build_bus2", "servo_list", "servo_models"]


def servo_models(spec: str, ids: list[int] | None) -> list[tuple[int, str]]:
    """(ID, model key) per servo; ``ids`` None with a bare MODEL means ID 1. ``ValueError`` names the mistake."""
    if ids is None and ":" not in spec:
        ids = [1]
    return parse_servo_spec(spec, ids)


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


def servo_list(bus: Bus2) -> str:
    """The bus's servos in the per-ID ``--servo`` form (launch ID: model key), as a trace's header keeps them."""
    return ",".join(f"{slot}:{servo.spec.name.lower()}" for slot, servo in zip(bus.slots, bus.servos))
