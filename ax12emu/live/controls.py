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

Every bus the live view shows takes the same actions: an AX-12 bus (Protocol 1.0), an X-series
bus (2.0, its servos' own faults acted out by their firmware: :class:`~ax12emu.faults.Faults2`)
and a wire with both (:class:`~ax12emu.faults.MixedFaults`).  On a mixed wire IDs are per
protocol, so a servo's action takes ``protocol`` (1.0 or 2.0) where both protocols have its ID;
what a servo cannot take (an alarm its Shutdown does not select, a push on a model without
physics) is refused with the faults' or the model's own reason.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ax12emu.bus import Bus
from ax12emu.bus.bus1x import Bus1X
from ax12emu.bus.bus2 import Bus2
from ax12emu.faults.injection import Faults, MixedFaults, faults_for

from .buses import AnyBus, locate, parts, protocols

__all__ = ["Controls", "ServedControls", "ACTIONS", "ControlError", "apply"]

#: The buses ax12emu.faults serves (Faults, Faults1X, Faults2), as a refusal names them.
FAULT_BUSES = {Bus: "the AX-12 bus", Bus1X: "the MX series' Protocol 1.0 bus", Bus2: "the Protocol 2.0 bus"}

#: The registers ``temperature`` and ``voltage`` pin, the first the servo's table has
#: (AX-12A and XL-320: Present Voltage; X series: Present Input Voltage), and the count per unit.
HELD_READINGS: Mapping[str, tuple[tuple[str, ...], float]] = {
    "temperature": (("present_temperature",), 1.0),
    "voltage": (("present_voltage", "present_input_voltage"), 10.0),
}


class ControlError(ValueError):
    """A control message that cannot be carried out (its text says why)."""


class Controls(Protocol):
    """The part of VirtualBus's API the live view drives (``protocol``: only where the wire mixes protocols)."""

    @property
    def faults(self) -> Any: ...

    def call(self, fn: Callable[[AnyBus], Any]) -> Any: ...

    def set_external_torque(self, servo_id: int, torque_nm: float, **protocol: float) -> None: ...

    def set_temperature(self, servo_id: int, celsius: float | None, **protocol: float) -> None: ...

    def set_voltage(self, servo_id: int, volts: float | None, **protocol: float) -> None: ...


class _FaultsThroughCall:
    """``faults.*``: each Faults method run where the bus is served (as VirtualBus.faults does)."""

    def __init__(self, owner: "ServedControls") -> None:
        self._owner = owner

    def __getattr__(self, name: str) -> Callable[..., Any]:
        def method(*args: Any, **kwargs: Any) -> Any:
            return self._owner.call(lambda bus: getattr(self._owner.faults_of(bus), name)(*args, **kwargs))

        return method


class ServedControls:
    """VirtualBus's control methods for a bus served by a BusServer (``ax12emu serve``), of either protocol or both."""

    def __init__(self, call: Callable[[Callable[[AnyBus], Any]], Any], *, servos: int = 0, seed: int = 0) -> None:
        self.call = call
        self.seed = seed
        #: External torque set from here on each Protocol 1.0 servo, by index: for a model that does not show its own.
        self._torque_nm: dict[int, float] = {}

    def faults_of(self, bus: AnyBus) -> Faults | MixedFaults:
        # ax12emu.faults knows the buses of FAULT_BUSES (and wires of both protocols); another
        # kind of bus would take faults whose hooks it does not call, or calls wrongly.
        other = [type(sub).__name__ for _, sub in parts(bus) if not isinstance(sub, tuple(FAULT_BUSES))]
        if other:
            raise ControlError(f"faults are not available on a {' or '.join(other)} (ax12emu.faults serves "
                               f"{', '.join(FAULT_BUSES.values())}, and wires of both protocols)")
        if bus.faults is None:
            bus.faults = faults_for(bus, seed=self.seed)  # type: ignore[assignment]  # Faults2 on 2.0, MixedFaults on a mixed wire
        return bus.faults  # type: ignore[return-value]

    @property
    def faults(self) -> Any:
        return _FaultsThroughCall(self)

    def _hold(self, what: str, servo_id: int, value: float | None, protocol: float | None) -> None:
        names, per_unit = HELD_READINGS[what]

        def pin(bus: AnyBus) -> None:
            self.faults_of(bus)  # the whole wire's faults first: one seed for both protocols
            _, sub, servo = locate(bus, servo_id, protocol)
            sub = sub.holder(servo)  # an AX-12A beside MX servos: the AX-12 bus inside theirs
            name = next((n for n in names if n in servo.table.layout.by_name), None)
            if name is None:
                raise ControlError(f"{what}: ID {servo_id}'s table has no {' or '.join(names)} register to hold")
            self.faults_of(sub).hold(sub.slots[servo.index], name, None if value is None else round(value * per_unit))

        self.call(pin)

    def set_temperature(self, servo_id: int, celsius: float | None, *, protocol: float | None = None) -> None:
        self._hold("temperature", servo_id, celsius, protocol)

    def set_voltage(self, servo_id: int, volts: float | None, *, protocol: float | None = None) -> None:
        self._hold("voltage", servo_id, volts, protocol)

    def set_external_torque(self, servo_id: int, torque_nm: float, *, protocol: float | None = None) -> None:
        def _set(bus: AnyBus) -> None:
            _, sub, servo = locate(bus, servo_id, protocol)
            sub = sub.holder(servo)  # an AX-12A beside MX servos: the AX-12 bus inside theirs (its model)
            # A Protocol 2.0 servo has a firmware model of its own; the AX-12 bus's one model moves all its servos.
            firmware = getattr(getattr(servo, "plant", None), "firmware", None)
            if callable(getattr(firmware, "set_external_torque", None)):
                firmware.set_external_torque(torque_nm)  # type: ignore[union-attr]
                return
            model = getattr(sub, "model", None)
            if not callable(getattr(model, "set_external_torque", None)):
                holder = firmware if firmware is not None else model
                what = f"its model ({type(holder).__name__}) takes" if holder is not None else f"its bus ({type(sub).__name__}) has"
                raise ControlError(f"external_torque: ID {servo_id}: {what} no external torque")
            # The model's own torques, so one servo's change keeps what serve's --external-torque or an earlier
            # control put on the others; a model that does not show them (one a caller wrote) keeps this object's.
            shown = getattr(model, "external_torque_nm", None)
            if shown is None:
                torques = np.zeros(len(sub.servos))
                self._torque_nm[servo.index] = torque_nm
                for index, nm in self._torque_nm.items():
                    torques[index] = nm
            else:
                torques = np.array(shown, dtype=float)
                torques[servo.index] = torque_nm
            model.set_external_torque(torques)  # type: ignore[union-attr]
            sub.plant.tables_changed()  # type: ignore[union-attr]

        self.call(_set)


# -- parameters ---------------------------------------------------------------------------
#: Longest echo of a refused value in an error: JSON integers have no size limit (``1`` and 400 zeros is one).
_SHOWN_MAX = 40


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= _SHOWN_MAX else f"{text[:_SHOWN_MAX - 3]}... ({len(text)} characters)"


def _int(name: str, low: int, high: int) -> Callable[[Any], int]:
    def check(value: Any) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise ControlError(f"{name} must be an integer {low}..{high}, got {_shown(value)}")
        return value

    return check


def _number(name: str, low: float, high: float, *, optional: bool = False) -> Callable[[Any], float | None]:
    def check(value: Any) -> float | None:
        if value is None and optional:
            return None
        # Compared before any float(): an integer past the float range (JSON has no limit) is refused, not an OverflowError.
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high or not math.isfinite(value):
            raise ControlError(f"{name} must be a number {low:g}..{high:g}{' or null' if optional else ''}, got {_shown(value)}")
        return float(value)

    return check


#: Longest alarm text accepted ("overload,overheating,electrical_shock" is 37 characters).
_ALARM_TEXT_MAX = 80


_ALARM_FORMS = 'alarm names ("overload,overheating" or ["overload", "overheating"]) or a number 1..255'


def _alarm(value: Any) -> int | str:
    """Alarm names or bits; the servo's faults read the names by its protocol (AX-12 alarms, or Hardware Error Status).

    The names come as one comma-separated text or, as a JSON client writes a set of them, a list of texts."""
    if isinstance(value, list) and value and all(isinstance(item, str) for item in value):
        value = ",".join(value)
    if isinstance(value, str):
        if not 0 < len(value) <= _ALARM_TEXT_MAX:
            raise ControlError(f"bits must be {_ALARM_FORMS}, at most {_ALARM_TEXT_MAX} characters of names")
        return value
    if isinstance(value, bool) or not isinstance(value, int):
        raise ControlError(f"bits must be {_ALARM_FORMS}, got {_shown(value)}")
    return _int("bits", 1, 255)(value)


def _protocol(value: Any) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or value not in (1, 2):
        raise ControlError(f"protocol must be 1.0, 2.0 or null, got {_shown(value)}")
    return float(value)


_ID = _int("id", 0, 253)
#: Where the wire mixes protocols, a servo's ID is the protocol's own: ``protocol`` says which (None: the only one).
_PROTOCOL = {"protocol": _protocol}
_NO_PROTOCOL = {"protocol": None}
_SLOT = _int("slot", 0, 253)
_FRACTION = {name: _number(name, 0.0, 1.0) for name in ("drop", "corrupt", "delay")}


def _step(seconds: float) -> Callable[[AnyBus], float]:
    def run(bus: AnyBus) -> float:
        clock = bus.clock
        if not getattr(clock, "paused", True):  # a virtual clock is always "paused": it moves only when stepped
            raise ControlError("pause first: simulated time can be stepped only while it stands still")
        now = clock.advance(seconds)  # type: ignore[union-attr]
        bus.advance()
        return now

    return run


def _pause(bus: AnyBus) -> None:
    if not hasattr(bus.clock, "pause"):
        raise ControlError("this bus runs in virtual time: it is always paused; use step")
    bus.clock.pause()  # type: ignore[union-attr]


def _resume(bus: AnyBus) -> None:
    if not hasattr(bus.clock, "resume"):
        raise ControlError("this bus runs in virtual time: it moves only when stepped")
    bus.clock.resume()  # type: ignore[union-attr]


@dataclass(frozen=True)
class Action:
    """One control: its parameters (name -> checker; a default makes one optional), what it does, how the log says
    it (a format of the parameters, or a function of them where the text depends on a value)."""

    params: Mapping[str, Callable[[Any], Any]]
    run: Callable[[Controls, dict[str, Any]], Any]
    says: str | Callable[[dict[str, Any]], str]
    defaults: Mapping[str, Any] = None  # type: ignore[assignment]

    def said(self, params: dict[str, Any]) -> str:
        return self.says(params) if callable(self.says) else self.says.format(**params)


def _held(what: str, param: str, unit: str) -> Callable[[dict[str, Any]], str]:
    """How the log says a held reading: its value, or "released" for null (the servo's own reading again)."""
    return lambda p: f"servo {p['id']}: {what} " + ("released" if p[param] is None else f"held at {p[param]} {unit}")


def _on(p: dict[str, Any]) -> dict[str, float]:
    """``protocol=`` for the faults and state methods, only where the message gave one (a mixed wire)."""
    return {} if p["protocol"] is None else {"protocol": p["protocol"]}


def _servo_action(params: Mapping[str, Callable[[Any], Any]], run: Callable[[Controls, dict[str, Any]], Any], says: str) -> Action:
    """An action on one servo: its parameters and an optional ``protocol``."""
    return Action({**params, **_PROTOCOL}, run, says, _NO_PROTOCOL)


#: Every control by name.  Servos are named by ID in the state actions and by slot (the ID
#: they were launched with) in the fault actions, as in VirtualBus.
ACTIONS: Mapping[str, Action] = {
    "reply_faults": Action(
        {**_FRACTION, "ids": lambda v: None if v is None else [_int("ids", 0, 253)(i) for i in v] if isinstance(v, list) else _int("ids", 0, 253)(v)},
        lambda c, p: c.faults.set_reply_faults(drop=p["drop"], corrupt=p["corrupt"], delay=p["delay"], ids=p["ids"] if p["ids"] is None or isinstance(p["ids"], list) else [p["ids"]]),
        "reply faults: drop {drop:g}, corrupt {corrupt:g}, delay {delay:g} (IDs: {ids})",
        {"drop": 0.0, "corrupt": 0.0, "delay": 0.0, "ids": None},
    ),
    "vanish": _servo_action({"slot": _SLOT}, lambda c, p: c.faults.vanish(p["slot"], **_on(p)), "servo {slot} vanished"),
    "reappear": _servo_action({"slot": _SLOT}, lambda c, p: c.faults.reappear(p["slot"], **_on(p)), "servo {slot} back"),
    "stall": _servo_action({"slot": _SLOT}, lambda c, p: c.faults.stall(p["slot"], **_on(p)), "servo {slot} stalled"),
    "release": _servo_action({"slot": _SLOT}, lambda c, p: c.faults.release(p["slot"], **_on(p)), "servo {slot} released"),
    "alarm": _servo_action(
        {"slot": _SLOT, "bits": _alarm}, lambda c, p: c.faults.force_alarm(p["slot"], p["bits"], **_on(p)), "servo {slot}: alarm {bits} forced"
    ),
    "clear_alarm": _servo_action({"slot": _SLOT}, lambda c, p: c.faults.clear_alarm(p["slot"], **_on(p)), "servo {slot}: forced alarms lifted"),
    "clear_faults": Action({}, lambda c, p: c.faults.clear(), "every fault lifted"),
    "external_torque": _servo_action(
        {"id": _ID, "nm": _number("nm", -10.0, 10.0)}, lambda c, p: c.set_external_torque(p["id"], p["nm"], **_on(p)), "servo {id}: external torque {nm:g} N m"
    ),
    "temperature": _servo_action(
        {"id": _ID, "celsius": _number("celsius", 0, 255, optional=True)},
        lambda c, p: c.set_temperature(p["id"], p["celsius"], **_on(p)),
        _held("temperature", "celsius", "C"),
    ),
    "voltage": _servo_action(
        {"id": _ID, "volts": _number("volts", 0, 25.5, optional=True)}, lambda c, p: c.set_voltage(p["id"], p["volts"], **_on(p)), _held("voltage", "volts", "V")
    ),
    "pause": Action({}, lambda c, p: c.call(_pause), "simulated time paused"),
    "resume": Action({}, lambda c, p: c.call(_resume), "simulated time resumed"),
    "step": Action({"seconds": _number("seconds", 0.0, 10.0)}, lambda c, p: c.call(_step(p["seconds"])), "stepped {seconds:g} s"),
}


def _check_protocol(controls: Controls, params: dict[str, Any]) -> None:
    """A ``protocol`` the wire does not carry is refused; on a wire of one protocol it is dropped (the ID says it all)."""
    protocol = params.get("protocol")
    if protocol is None:
        return
    on_wire = controls.call(protocols)
    if protocol not in on_wire:
        raise ControlError(f"protocol {protocol:g}: this bus's servos speak Protocol {' and '.join(f'{p:g}' for p in on_wire)}")
    if len(on_wire) == 1:
        params["protocol"] = None


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
            try:
                params[key] = check(message[key])
            except ControlError:
                raise
            except Exception as exc:  # a value no check foresaw is the message's fault, never the emulator's
                raise ControlError(f"{name}: {key} {_shown(message[key])} cannot be taken: {type(exc).__name__}: {exc}") from None
        elif key in defaults:
            params[key] = defaults[key]
        else:
            raise ControlError(f"{name}: missing parameter {key!r}")
    try:
        _check_protocol(controls, params)
        action.run(controls, params)
    except ControlError:
        raise
    except (ValueError, KeyError, NotImplementedError, RuntimeError) as exc:  # e.g. an ID no servo has
        raise ControlError(f"{name}: {exc}") from None
    said = action.said(params)
    return said if params.get("protocol") is None else f"{said} (Protocol {params['protocol']:.1f})"
