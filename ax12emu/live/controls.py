"""What a tester can do to the bus from the live view, as a table of actions.

Why it exists: the page's buttons and any script posting to
``/api/control`` must change the bus exactly as a test does with
:class:`~ax12emu.VirtualBus`, so each action calls the same methods
(``faults.set_reply_faults``, ``faults.vanish``, ``set_external_torque``,
``set_temperature``, ``set_voltage``, a step of the clock and the physics)
on a :class:`Controls` object: the ``VirtualBus`` itself, or, for
``ax12emu serve``, a :class:`ServedControls` around the server's ``call``.
Each action's parameters are checked here first (a clear message for a bad
one, never a half-done change), and :func:`apply` returns the line the
packet log shows.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ax12emu.bus import Bus
from ax12emu.faults.injection import Faults, faults_for, parse_alarm_bits

__all__ = ["Controls", "ServedControls", "ACTIONS", "ControlError", "apply"]


class ControlError(ValueError):
    """A control message that cannot be carried out (its text says why)."""


class Controls(Protocol):
    """The part of VirtualBus's API the live view drives."""

    @property
    def faults(self) -> Any: ...

    def call(self, fn: Callable[[Bus], Any]) -> Any: ...

    def set_external_torque(self, servo_id: int, torque_nm: float) -> None: ...

    def set_temperature(self, servo_id: int, celsius: float | None) -> None: ...

    def set_voltage(self, servo_id: int, volts: float | None) -> None: ...


class _FaultsThroughCall:
    """``faults.*``: each Faults method run where the bus is served (as VirtualBus.faults does)."""

    def __init__(self, owner: "ServedControls") -> None:
        self._owner = owner

    def __getattr__(self, name: str) -> Callable[..., Any]:
        def method(*args: Any, **kwargs: Any) -> Any:
            return self._owner.call(lambda bus: getattr(self._owner.faults_of(bus), name)(*args, **kwargs))

        return method


class ServedControls:
    """VirtualBus's control methods for a bus served by a BusServer (``ax12emu serve``)."""

    def __init__(self, call: Callable[[Callable[[Bus], Any]], Any], *, servos: int, seed: int = 0) -> None:
        self.call = call
        self.seed = seed
        self._torque_nm = np.zeros(servos)

    def faults_of(self, bus: Bus) -> Faults:
        if bus.faults is None:
            bus.faults = faults_for(bus, seed=self.seed)  # a Protocol 2.0 bus takes the wire's faults only
        return bus.faults

    @property
    def faults(self) -> Any:
        return _FaultsThroughCall(self)

    def set_temperature(self, servo_id: int, celsius: float | None) -> None:
        self.call(lambda bus: self.faults_of(bus).hold(bus.slots[bus.servo(servo_id).index], "present_temperature", None if celsius is None else round(celsius)))

    def set_voltage(self, servo_id: int, volts: float | None) -> None:
        self.call(lambda bus: self.faults_of(bus).hold(bus.slots[bus.servo(servo_id).index], "present_voltage", None if volts is None else round(volts * 10)))

    def set_external_torque(self, servo_id: int, torque_nm: float) -> None:
        def _set(bus: Bus) -> None:
            self._torque_nm[bus.servo(servo_id).index] = torque_nm
            bus.model.set_external_torque(self._torque_nm.copy())
            bus.plant.tables_changed()

        self.call(_set)


# -- parameters ---------------------------------------------------------------------------
def _int(name: str, low: int, high: int) -> Callable[[Any], int]:
    def check(value: Any) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise ControlError(f"{name} must be an integer {low}..{high}, got {value!r}")
        return value

    return check


def _number(name: str, low: float, high: float, *, optional: bool = False) -> Callable[[Any], float | None]:
    def check(value: Any) -> float | None:
        if value is None and optional:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or not low <= value <= high:
            raise ControlError(f"{name} must be a number {low:g}..{high:g}{' or null' if optional else ''}, got {value!r}")
        return float(value)

    return check


def _alarm(value: Any) -> int:
    try:
        return parse_alarm_bits(value) if isinstance(value, str) else _int("bits", 1, 127)(value)
    except ValueError as exc:
        raise ControlError(str(exc)) from None


_ID = _int("id", 0, 253)
_SLOT = _int("slot", 0, 253)
_FRACTION = {name: _number(name, 0.0, 1.0) for name in ("drop", "corrupt", "delay")}


def _step(seconds: float) -> Callable[[Bus], float]:
    def run(bus: Bus) -> float:
        clock = bus.clock
        if not getattr(clock, "paused", True):  # a virtual clock is always "paused": it moves only when stepped
            raise ControlError("pause first: simulated time can be stepped only while it stands still")
        now = clock.advance(seconds)  # type: ignore[union-attr]
        bus.advance()
        return now

    return run


def _pause(bus: Bus) -> None:
    if not hasattr(bus.clock, "pause"):
        raise ControlError("this bus runs in virtual time: it is always paused; use step")
    bus.clock.pause()  # type: ignore[union-attr]


def _resume(bus: Bus) -> None:
    if not hasattr(bus.clock, "resume"):
        raise ControlError("this bus runs in virtual time: it moves only when stepped")
    bus.clock.resume()  # type: ignore[union-attr]


@dataclass(frozen=True)
class Action:
    """One control: its parameters (name -> checker; a default makes one optional), what it does, how the log says it."""

    params: Mapping[str, Callable[[Any], Any]]
    run: Callable[[Controls, dict[str, Any]], Any]
    says: str
    defaults: Mapping[str, Any] = None  # type: ignore[assignment]


#: Every control by name.  Servos are named by ID in the state actions and by slot (the ID
#: they were launched with) in the fault actions, as in VirtualBus.
ACTIONS: Mapping[str, Action] = {
    "reply_faults": Action(
        {**_FRACTION, "ids": lambda v: None if v is None else [_int("ids", 0, 253)(i) for i in v] if isinstance(v, list) else _int("ids", 0, 253)(v)},
        lambda c, p: c.faults.set_reply_faults(drop=p["drop"], corrupt=p["corrupt"], delay=p["delay"], ids=p["ids"] if p["ids"] is None or isinstance(p["ids"], list) else [p["ids"]]),
        "reply faults: drop {drop:g}, corrupt {corrupt:g}, delay {delay:g} (IDs: {ids})",
        {"drop": 0.0, "corrupt": 0.0, "delay": 0.0, "ids": None},
    ),
    "vanish": Action({"slot": _SLOT}, lambda c, p: c.faults.vanish(p["slot"]), "servo {slot} vanished"),
    "reappear": Action({"slot": _SLOT}, lambda c, p: c.faults.reappear(p["slot"]), "servo {slot} back"),
    "stall": Action({"slot": _SLOT}, lambda c, p: c.faults.stall(p["slot"]), "servo {slot} stalled"),
    "release": Action({"slot": _SLOT}, lambda c, p: c.faults.release(p["slot"]), "servo {slot} released"),
    "alarm": Action({"slot": _SLOT, "bits": _alarm}, lambda c, p: c.faults.force_alarm(p["slot"], p["bits"]), "servo {slot}: alarm bits {bits:#04x} forced"),
    "clear_alarm": Action({"slot": _SLOT}, lambda c, p: c.faults.clear_alarm(p["slot"]), "servo {slot}: forced alarms lifted"),
    "clear_faults": Action({}, lambda c, p: c.faults.clear(), "every fault lifted"),
    "external_torque": Action(
        {"id": _ID, "nm": _number("nm", -10.0, 10.0)}, lambda c, p: c.set_external_torque(p["id"], p["nm"]), "servo {id}: external torque {nm:g} N m"
    ),
    "temperature": Action(
        {"id": _ID, "celsius": _number("celsius", 0, 255, optional=True)}, lambda c, p: c.set_temperature(p["id"], p["celsius"]), "servo {id}: temperature held at {celsius} C"
    ),
    "voltage": Action(
        {"id": _ID, "volts": _number("volts", 0, 25.5, optional=True)}, lambda c, p: c.set_voltage(p["id"], p["volts"]), "servo {id}: voltage held at {volts} V"
    ),
    "pause": Action({}, lambda c, p: c.call(_pause), "simulated time paused"),
    "resume": Action({}, lambda c, p: c.call(_resume), "simulated time resumed"),
    "step": Action({"seconds": _number("seconds", 0.0, 10.0)}, lambda c, p: c.call(_step(p["seconds"])), "stepped {seconds:g} s"),
}


def apply(controls: Controls, message: Any) -> str:
    """Check and carry out one control message ``{"action": NAME, ...params}``; returns the log line."""
    if not isinstance(message, dict):
        raise ControlError("a control message is a JSON object with an 'action'")
    name = message.get("action")
    action = ACTIONS.get(name) if isinstance(name, str) else None
    if action is None:
        raise ControlError(f"unknown action {name!r}; choose one of: {', '.join(ACTIONS)}")
    unknown = set(message) - {"action"} - set(action.params)
    if unknown:
        raise ControlError(f"{name}: unknown parameter(s) {', '.join(sorted(map(str, unknown)))}")
    params: dict[str, Any] = {}
    defaults = action.defaults or {}
    for key, check in action.params.items():
        if key in message:
            params[key] = check(message[key])
        elif key in defaults:
            params[key] = defaults[key]
        else:
            raise ControlError(f"{name}: missing parameter {key!r}")
    try:
        action.run(controls, params)
    except ControlError:
        raise
    except (ValueError, KeyError, NotImplementedError, RuntimeError) as exc:  # e.g. an ID no servo has
        raise ControlError(f"{name}: {exc}") from None
    return action.says.format(**params)
