"""Fault injection: the unhappy paths of a real bus, on demand and reproducible.

Why it exists: hardware shows a lost reply, a noisy line or an overheating
servo rarely and never on cue, yet robot code must survive them.  A
:class:`Faults` object attached to a :class:`~ax12emu.bus.bus.Bus` (``bus.faults``)
bends what the servos do; with none attached the bus pays one ``is None``
test per packet.  Every random choice comes from one ``random.Random(seed)``
drawn once per status packet, so a run is repeatable with the same seed and
the same traffic.

What a client sees, fault by fault (dynamixel-sdk's names):

* ``drop``: a fraction of status packets is never sent -> ``COMM_RX_TIMEOUT``;
  the instruction was still executed.
* ``corrupt``: a fraction of status packets carries a wrong checksum ->
  ``COMM_RX_CORRUPT``.
* ``delay``: a fraction of status packets leaves ``delay_s`` late (default
  100 ms, past dynamixel-sdk's ~34 ms timeout) -> ``COMM_RX_TIMEOUT``, and the
  late bytes arrive during a later transaction unless the client waits or
  flushes (the SDK flushes its input before each packet it sends).
* ``vanish``: the servo is unplugged: it neither hears nor answers (->
  ``COMM_RX_TIMEOUT``) until it comes back, with its table as it was;
  optionally periodic (absent ``for_s`` out of every ``every_s`` simulated s).
* ``duplicate``: the servo launched as ``slot`` takes the ID ``as_id``, as if
  renumbered (it no longer answers as ``slot``), so two servos share an ID: both act on every packet and both answer at once;
  their replies are AND-ed on the wire (``server.merge_replies``), so equal
  replies look clean and different ones (e.g. Present Position) arrive
  garbled -> ``COMM_RX_CORRUPT`` or wrong values.
* ``alarm``: alarm bits (overload, overheating, input voltage) are raised as
  if the model had: every status packet of the servo carries them (the SDK's
  ``error`` value, e.g. ``0x20``) and Alarm Shutdown (address 18) acts on them
  (torque limit 0, or torque off in the 2006 profile), as the firmware does.
* ``stall``: the shaft is blocked: Present Position freezes, Present Speed
  reads 0 and Present Load full scale.  The physical model holds the shaft in
  its own mechanics (the motor pushes against the block: full drive, heating,
  its Overload after ``ServoParams.overload_delay_s``, Moving as its setpoint
  says); for the kinematic model the registers are held here, its
  ``angle_rad`` pinned, Moving stays 1 while the goal is not reached, and the
  Overload bit (0x20) comes after ``overload_after_s`` simulated seconds of
  driving.

Servos are named by *slot*, the ID they were launched with (``--ids``), so a
fault stays on the same servo when a client changes its ID.

A Protocol 2.0 bus (:class:`~ax12emu.bus.bus2.Bus2`) takes :class:`Faults2`: the
wire's faults (``drop``, ``corrupt``, ``delay``, ``vanish``) as here (a corrupt Protocol 2.0
status packet has a wrong CRC, its last byte flipped -> ``COMM_RX_CORRUPT``), and the faults of
a servo's own (``alarm``, ``stall``, ``hold``) acted out by its firmware model, which reports
them otherwise: Hardware Error Status, the Alert bit, Shutdown latching until REBOOT (see
:class:`Faults2`); ``duplicate`` as here, replies overlapping on the wire colliding.

A Protocol 1.0 wire with MX servos (:class:`~ax12emu.bus.bus1x.Bus1X`) takes :class:`Faults1X`: the
wire's faults as here, an MX's own acted out by its X-series firmware and shown as the Protocol 1.0
firmware shows them (status-packet alarm bits, Torque Limit 0 until a client writes it).
"""

from __future__ import annotations

import logging
import math
import operator
import random
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ax12emu.protocol.packets import StatusError
from firmware_model.interface import AngleSettable, Blockable
from firmware_model.units import RAD_PER_POSITION_UNIT
from firmware_model.xseries.interface import (
    HW_ERROR_ELECTRICAL_SHOCK,
    HW_ERROR_INPUT_VOLTAGE,
    HW_ERROR_MOTOR_ENCODER,
    HW_ERROR_OVERHEATING,
    HW_ERROR_OVERLOAD,
    XFaultable,
)

if TYPE_CHECKING:
    from ax12emu.bus import Bus, Reply
    from ax12emu.bus.bus2 import Bus2
    from ax12emu.bus.mixed import MixedBus
    from ax12emu.servo.servo2 import Servo2
    from ax12emu.servo.virtual_servo import VirtualServo

__all__ = ["Faults", "Faults2", "Faults1X", "MixedFaults", "ALARM_NAMES", "HW_ERROR_NAMES", "MAX_REPLY_DELAY_S",
           "DEFAULT_REPLY_DELAY_S", "parse_alarm_bits", "faults_for"]

log = logging.getLogger(__name__)

#: Alarm names accepted by ``alarm`` and ``--alarm``, to status-byte bits.
ALARM_NAMES: Mapping[str, int] = {
    "overload": int(StatusError.OVERLOAD),
    "overheating": int(StatusError.OVERHEATING),
    "input_voltage": int(StatusError.INPUT_VOLTAGE),
    "voltage": int(StatusError.INPUT_VOLTAGE),
}
#: The alarms' bits together, and each alarm's first name (not the aliases), for messages.
_ALARM_BITS = sum(set(ALARM_NAMES.values()))
_ALARM_FIRST = {name: bit for name, bit in ALARM_NAMES.items() if name == next(n for n, b in ALARM_NAMES.items() if b == bit)}
#: Present Load full scale with the direction bit clear (e-manual, Present Load).
_FULL_LOAD = 1023
#: The longest reply delay taken: far beyond any client's timeout a reply is already lost to it; a longer one
#: (inf) overflowed the wire's pacing and stopped the server.
MAX_REPLY_DELAY_S = 60.0
#: How late a delayed reply leaves unless told: past dynamixel-sdk's ~34 ms timeout.
DEFAULT_REPLY_DELAY_S = 0.1


def parse_alarm_bits(text: str, names: Mapping[str, int] | None = None) -> int:
    """"overload,overheating" (or a number) to status-byte bits; ``names``: the table (default :data:`ALARM_NAMES`)."""
    names = ALARM_NAMES if names is None else names
    bits = 0
    for name in text.replace("+", ",").split(","):
        name = name.strip().lower()
        if name.isdigit() or name.startswith("0x"):
            value = int(name, 0)
        elif name in names:
            value = names[name]
        else:
            raise ValueError(f"unknown alarm {name!r}; use {', '.join(names)} or a number")
        if not 0 < value < 0x80:
            raise ValueError(f"alarm bits must be 1..127, got {value}")
        bits |= value
    return bits


@dataclass
class _Stall:
    position: int
    #: How long the firmware drives against the block before Overload (each stall its own).
    overload_after_s: float = 1.0
    driving_since_s: float | None = None


def _warn_if_unanswered(reply_ids: frozenset[int] | None, bus: object) -> None:
    """Say when the reply faults' IDs are none a servo of ``bus`` answers as: said, not refused, since a client
    may move a servo there."""
    answering = {servo.id for servo in getattr(bus, "servos", ())}
    if reply_ids and answering and not reply_ids & answering:
        log.warning("reply faults on IDs %s, which no servo answers as now (IDs %s)", sorted(reply_ids),
                    sorted(answering))


class Faults:
    """Live faults on one bus; change them at any time (from the thread serving the bus)."""

    def __init__(self, bus: "Bus", *, seed: int = 0) -> None:
        self.bus = bus
        self.seed = seed
        self._rng = random.Random(seed)
        self.drop = 0.0
        self.corrupt = 0.0
        self.delay = 0.0
        self.delay_s = DEFAULT_REPLY_DELAY_S
        #: Wire IDs the reply faults apply to; None: every ID.
        self.reply_ids: frozenset[int] | None = None
        self._vanished: dict[int, tuple[float | None, float | None]] = {}
        self._alarms: dict[int, int] = {}
        self._duplicates: dict[int, int] = {}
        self._stalls: dict[int, _Stall] = {}
        #: Servos whose shaft the model itself holds (see stall()).
        self._blocked: set[int] = set()
        self._held: dict[int, dict[str, int]] = {}
        #: What was done, for tests and logs.
        self.dropped = 0
        self.corrupted = 0
        self.delayed = 0
        self._before_steps(bus)

    def _before_steps(self, bus: "Bus") -> None:
        """Have the bus's plant apply the installed faults' Alarm Shutdown before each step (:meth:`before_step`).

        The plant asks the bus's faults, whichever are installed when it steps, not this object: faults built for
        the bus but never installed act on nothing, as the bus calls only its own.
        """
        def before_step() -> None:
            faults = bus.faults
            if isinstance(faults, Faults):
                faults.before_step()

        bus.plant.before_step = before_step

    # -- configuration -------------------------------------------------------------
    def _index(self, slot: int) -> int:
        try:
            return self.bus.slots.index(slot)
        except ValueError:
            raise ValueError(f"no servo launched as ID {slot} (slots: {self.bus.slots})") from None

    def set_reply_faults(
        self,
        *,
        drop: float = 0.0,
        corrupt: float = 0.0,
        delay: float = 0.0,
        delay_s: float = DEFAULT_REPLY_DELAY_S,
        ids: Iterable[int] | None = None,
        warn_unanswered: bool = True,
    ) -> None:
        """Set the fractions of status packets dropped, corrupted or delayed (all 0: off).

        ``warn_unanswered`` False: ``ids`` no servo of this bus answers as is not said here (half of a mixed wire,
        whose other half may hold the ID, leaves it to :meth:`MixedFaults.set_reply_faults`)."""
        for name, value in (("drop", drop), ("corrupt", corrupt), ("delay", delay)):
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be a fraction 0..1, got {value}")
        if drop + corrupt + delay > 1.0 + 1e-12:
            raise ValueError(f"drop + corrupt + delay must not exceed 1, got {drop + corrupt + delay}")
        if not 0 <= delay_s <= MAX_REPLY_DELAY_S:  # (NaN too) an infinite delay overflowed the wire's pacing
            raise ValueError(f"delay_s must lie in 0..{MAX_REPLY_DELAY_S:g} s, got {delay_s}")
        self.drop, self.corrupt, self.delay, self.delay_s = drop, corrupt, delay, delay_s
        self.reply_ids = None if ids is None else frozenset(ids)
        if warn_unanswered:
            _warn_if_unanswered(self.reply_ids, self.bus)

    def vanish(self, slot: int, *, every_s: float | None = None, for_s: float | None = None) -> None:
        """Unplug the servo; with ``every_s``/``for_s`` it is absent ``for_s`` of every ``every_s`` (simulated)."""
        if (every_s is None) != (for_s is None) or (every_s is not None and not 0 < for_s < every_s):  # type: ignore[operator]
            raise ValueError("vanish needs both every_s and for_s, with 0 < for_s < every_s, or neither")
        if every_s is not None and not math.isfinite(every_s):  # absent the first for_s, then never again
            raise ValueError(f"vanish: every_s must be a finite period, got {every_s} (to unplug for good, give neither)")
        self._vanished[self._index(slot)] = (every_s, for_s)

    def reappear(self, slot: int) -> None:
        """Plug the servo back in (its table is as it was)."""
        self._vanished.pop(self._index(slot), None)

    def force_alarm(self, slot: int, bits: int | str) -> None:
        """Raise alarm bits (int or names such as "overload,overheating") until :meth:`clear_alarm`."""
        value = parse_alarm_bits(bits) if isinstance(bits, str) else operator.index(bits)  # 1.7 was taken as 0x01
        # The status bits an AX-12's firmware raises on its own (Input Voltage, Overheating, Overload); the others
        # (Angle Limit, Range, Checksum, Instruction) answer one packet, they are not a state to force.
        if not value or value & ~_ALARM_BITS:
            raise ValueError(f"the AX-12's alarm bits are {', '.join(f'{k} {v:#04x}' for k, v in _ALARM_FIRST.items())}; "
                             f"got {value:#04x}")
        index = self._index(slot)
        # Added to those already forced, as the MX and X servos' faults add them: replaced, the first stayed raised
        # on the servo and clear_alarm no longer knew it (Torque Limit 0 for good).
        self._alarms[index] = self._alarms.get(index, 0) | value
        self._raise_forced(self.bus.servos[index], value)  # at once, not at the next packet: a live view shows it

    def _raise_forced(self, servo: "VirtualServo", bits: int) -> None:
        """The firmware's own reaction to alarms it finds: the bits in every status, Alarm Shutdown's output cut."""
        servo.alarms |= bits
        self._shutdown(servo, bits)

    def clear_alarm(self, slot: int) -> None:
        """Lift forced alarms; the model's own alarms, if any, return at its next step."""
        index = self._index(slot)
        bits = self._alarms.pop(index, 0)
        self.bus.servos[index].alarms &= ~bits
        self.bus.plant.refresh()

    def duplicate(self, slot: int, as_id: int) -> None:
        """Give the servo launched as ``slot`` the ID ``as_id`` (normally another servo's)."""
        index = self._index(slot)
        if not 0 <= as_id <= 253:
            raise ValueError(f"ID {as_id} is outside 0..253")
        servo = self.bus.servos[index]
        self._duplicates.setdefault(index, servo.id)
        store = getattr(self.bus, "state_store", None)
        if store is not None:  # a --state-dir keeps the servo's own ID, not the fault's (it outlived the run)
            store.own_ids[slot] = self._duplicates[index]
        servo.table.set("id", as_id)
        self.bus.reindex()

    def unduplicate(self, slot: int) -> None:
        """Give the servo back the ID it had before :meth:`duplicate`."""
        index = self._index(slot)
        if index in self._duplicates:
            self.bus.servos[index].table.set("id", self._duplicates.pop(index))
            store = getattr(self.bus, "state_store", None)
            if store is not None:
                store.own_ids.pop(slot, None)
            self.bus.reindex()

    def _model_blocks(self) -> bool:
        """Whether the model itself can hold a shaft (the physical model can)."""
        return isinstance(self.bus.model, Blockable)

    def _set_model_blocked(self) -> None:
        blocked = [index in self._blocked for index in range(len(self.bus.servos))]
        model = self.bus.model
        assert isinstance(model, Blockable)
        model.set_blocked(blocked)
        self.bus.plant.tables_changed()

    def stall(self, slot: int, *, overload_after_s: float | None = None) -> None:
        """Block the shaft where it is now.

        A model that can hold a shaft (the physical one) does it in its
        mechanics, so speed, load, heating and the overload alarm follow from
        the motor pushing against the block (after the model's own overload
        delay, ``ServoParams.overload_delay_s``: a time given here is refused);
        otherwise the registers are held here, Overload after
        ``overload_after_s`` (default 1 s).
        """
        index = self._index(slot)
        if self._model_blocks():
            if overload_after_s is not None:  # it was ignored, silently
                raise ValueError("stall: the physical model trips Overload after its own overload delay "
                                 "(ServoParams.overload_delay_s, in a params file), not a time given here")
            self._blocked.add(index)
            self._set_model_blocked()
            return
        after_s = 1.0 if overload_after_s is None else overload_after_s
        if not 0 <= after_s < float("inf"):
            raise ValueError(f"stall: overload_after_s must be a finite time >= 0, got {overload_after_s}")
        self._stalls[index] = _Stall(self.bus.servos[index].table.get("present_position"), after_s)
        self.after_physics()

    def release(self, slot: int) -> None:
        """Unblock the shaft; the model takes over again from the held position."""
        index = self._index(slot)
        if index in self._blocked:
            self._blocked.discard(index)
            self._set_model_blocked()
            return
        if self._stalls.pop(index, None) is not None:
            servo = self.bus.servos[index]
            servo.alarms &= ~int(StatusError.OVERLOAD) | self._alarms.get(index, 0)
            self.bus.plant.tables_changed()
            self.bus.plant.refresh()

    def hold(self, slot: int, name: str, value: int | None) -> None:
        """Pin a sensed register (e.g. present_temperature) at ``value``; None lets the model drive it again.

        A held temperature above Temperature Limit raises Overheating, a
        held voltage outside the voltage limits raises Input Voltage, as the
        firmware does with real readings.
        """
        index = self._index(slot)
        servo = self.bus.servos[index]
        if value is not None:
            value = _in_bytes(servo.table.layout.by_name[name], value)  # KeyError for an unknown register
        else:
            servo.table.layout.by_name[name]  # KeyError for an unknown register
        held = self._held.setdefault(index, {})
        if value is None:
            held.pop(name, None)
            if not held:
                del self._held[index]
            servo.alarms &= ~_HELD_ALARMS | self._alarms.get(index, 0)
            self.bus.plant.refresh()
        else:
            held[name] = int(value)
            self.after_physics()

    def clear(self) -> None:
        """Lift every fault."""
        self.set_reply_faults()
        for index in list(self._held):
            for name in list(self._held[index]):
                self.hold(self.bus.slots[index], name, None)
        self._vanished.clear()
        for index in list(self._alarms):
            self.clear_alarm(self.bus.slots[index])
        for index in list(self._duplicates):
            self.unduplicate(self.bus.slots[index])
        # A stall is held either in the model's mechanics (_blocked) or in the registers (_stalls).
        for index in sorted(self._blocked | self._stalls.keys()):
            self.release(self.bus.slots[index])

    def active(self, slot: int) -> list[str]:
        """What is done to the servo launched as ``slot`` now, in words (for live views and logs)."""
        index = self._index(slot)
        out = []
        if index in self._vanished:
            every_s, for_s = self._vanished[index]
            out.append("vanished" if every_s is None else f"vanishes {for_s:g} s of every {every_s:g} s")
        if index in self._blocked or index in self._stalls:
            out.append("stalled")
        if index in self._alarms:
            out.append(f"alarm {self._alarms[index]:#04x}")
        if index in self._duplicates:
            out.append(f"answers as ID {self.bus.servos[index].id}")
        out.extend(f"{name} held at {value}" for name, value in self._held.get(index, {}).items())
        out.extend(self._on_replies_of(self.bus.servos[index].id))
        return out

    def _on_replies_of(self, servo_id: int) -> list[str]:
        """The reply faults that reach the status packets of ``servo_id``, in words (none: empty)."""
        if (self.drop or self.corrupt or self.delay) and (self.reply_ids is None or servo_id in self.reply_ids):
            return [f"replies: drop {self.drop:g}, corrupt {self.corrupt:g}, delay {self.delay:g}"]
        return []

    # -- hooks called by the bus -----------------------------------------------------
    def admit(self, servo: "VirtualServo") -> bool:
        """Before ``servo`` handles a packet: False if it is absent; apply forced alarms."""
        index = servo.index
        if index in self._vanished:
            every_s, for_s = self._vanished[index]
            if every_s is None or self.bus.clock.now_s() % every_s < for_s:  # type: ignore[operator]
                return False
        bits = self._alarms.get(index, 0)
        if index in self._held:
            bits |= _held_alarms(servo)
        if bits:
            self._raise_forced(servo, bits)
        return True

    def _shutdown(self, servo: "VirtualServo", bits: int) -> None:
        table = servo.table
        if not bits & table.get("shutdown"):
            return
        register = table.profile.shutdown_clears or "torque_limit"  # the register this edition's Shutdown clears
        if table.get(register):  # (at every step while a pinned reading's alarm lasts: no news once it is 0)
            table.set(register, 0)

    def on_replies(self, replies: "list[Reply]") -> "list[Reply]":
        """Drop, corrupt or delay status packets by the configured fractions."""
        if not (self.drop or self.corrupt or self.delay):
            return replies
        # One status packet may come in parts (a Fast Sync/Bulk Read's, a share from each servo): one fate for it.
        packets: list[list[Reply]] = []
        for reply in replies:
            if reply.continues and packets:
                packets[-1].append(reply)
            else:
                packets.append([reply])
        out: list[Reply] = []
        for parts in packets:
            if self.reply_ids is not None and not any(part.servo_id in self.reply_ids for part in parts):
                out.extend(parts)
                continue
            draw = self._rng.random()
            if draw < self.drop:
                self.dropped += 1
                continue
            if draw < self.drop + self.corrupt:
                self.corrupted += 1
                last = parts[-1]  # its checksum or CRC
                parts[-1] = last._replace(data=last.data[:-1] + bytes((last.data[-1] ^ 0xFF,)))
            elif draw < self.drop + self.corrupt + self.delay:
                self.delayed += 1
                parts = [part._replace(delay_s=part.delay_s + self.delay_s) for part in parts]
            out.extend(parts)
        return out

    def before_step(self) -> None:
        """Alarm Shutdown of the forced alarms and the pinned readings' on the registers the next step runs on.

        Why: held only after each step, a Torque Limit (2006 edition: Torque Enable) set by name while such an
        alarm lasted (a harness's write, a test's) drove the shaft for the whole next step, however long, and
        with a command delay the model acted on it later still; the firmware's Alarm Shutdown finds the alarm at
        every control step, so no step drives with the register written back.
        """
        self._raise_lasting()

    def _raise_lasting(self) -> None:
        """Raise the forced alarms and the pinned readings' alarms with their Alarm Shutdown, as the firmware finds
        them at each step (the readings judged as they are pinned)."""
        for index, bits in self._alarms.items():
            self._raise_forced(self.bus.servos[index], bits)
        for index in self._held:
            servo = self.bus.servos[index]
            bits = _held_alarms(servo)
            if bits:
                self._raise_forced(servo, bits)

    def after_physics(self) -> None:
        """Hold stalled shafts, forced alarms and pinned readings after the model has stepped (its step wrote its own
        alarms: a forced one showed only from the next packet, and a Torque Limit written meanwhile drove the shaft
        until then); a pinned reading's alarm (Overheating, Input Voltage) and its Alarm Shutdown act here too, at
        the step, as the firmware judges its readings, not when a packet comes."""
        if not (self._stalls or self._held or self._alarms):
            return
        bus = self.bus
        for index, held in self._held.items():
            table = bus.servos[index].table
            for name, value in held.items():
                table.set(name, value)
        self._raise_lasting()  # the firmware judges the pinned readings at its step, not at a packet
        now_s = bus.clock.now_s()
        # A model that cannot block its shaft (else the stall would be there) is held at the stall's angle.
        model = bus.model
        holdable = isinstance(model, AngleSettable)
        for index, stall in self._stalls.items():
            servo = bus.servos[index]
            table = servo.table
            goal = table.get("goal_position")
            margin = max(table.get("cw_compliance_margin"), table.get("ccw_compliance_margin"), 1)
            driving = bool(table.get("torque_enable")) and abs(goal - stall.position) > margin
            table.set("present_position", stall.position)
            table.set("present_speed", 0)
            table.set("moving", int(driving))
            table.set("present_load", (_FULL_LOAD | (0x400 if goal < stall.position else 0)) if driving else 0)
            if driving:
                if stall.driving_since_s is None:
                    stall.driving_since_s = now_s
                if now_s - stall.driving_since_s >= stall.overload_after_s:
                    servo.alarms |= int(StatusError.OVERLOAD)
                    self._shutdown(servo, int(StatusError.OVERLOAD))
            else:
                stall.driving_since_s = None
            if holdable:
                model.set_angle(index, stall.position * RAD_PER_POSITION_UNIT)


def _in_bytes(entry, value: int) -> int:
    """``value`` if the register ``entry`` can show it; a ValueError otherwise (it wrapped: a held 300 degrees read
    44 while an X-series firmware judged 300)."""
    low, high = entry.byte_range
    if not low <= int(value) <= high:
        raise ValueError(f"hold: {entry.name} holds {low}..{high}, got {value}")
    return int(value)


#: Alarm bits a held sensor reading can raise.
_HELD_ALARMS = int(StatusError.OVERHEATING | StatusError.INPUT_VOLTAGE)


def _held_alarms(servo: "VirtualServo") -> int:
    """What the firmware concludes from the (held) readings in the table."""
    table = servo.table
    bits = 0
    if table.get("present_temperature") > table.get("temperature_limit"):
        bits |= int(StatusError.OVERHEATING)
    if not table.get("min_voltage_limit") <= table.get("present_voltage") <= table.get("max_voltage_limit"):
        bits |= int(StatusError.INPUT_VOLTAGE)
    return bits


#: Hardware Error Status (70) bits by name (e-manual, X series "Hardware Error Status(70)"); the three
#: the AX-12 has too (overload, overheating, input voltage) sit at the same bits as its alarms.
HW_ERROR_NAMES: Mapping[str, int] = {
    "overload": HW_ERROR_OVERLOAD,
    "overheating": HW_ERROR_OVERHEATING,
    "input_voltage": HW_ERROR_INPUT_VOLTAGE,
    "voltage": HW_ERROR_INPUT_VOLTAGE,
    "electrical_shock": HW_ERROR_ELECTRICAL_SHOCK,
    "motor_encoder": HW_ERROR_MOTOR_ENCODER,
    "encoder": HW_ERROR_MOTOR_ENCODER,
}
_HW_ERROR_BITS = HW_ERROR_OVERLOAD | HW_ERROR_OVERHEATING | HW_ERROR_INPUT_VOLTAGE | HW_ERROR_ELECTRICAL_SHOCK | HW_ERROR_MOTOR_ENCODER


class Faults2(Faults):
    """The faults of a Protocol 2.0 bus: the wire's, and the X-series servos' own through their firmware.

    The wire's (``drop``, ``corrupt``, ``delay``, ``vanish``) act as on the AX-12 bus.  A servo's own
    act inside its firmware model (:class:`firmware_model.xseries.interface.XFaultable`), so the
    firmware's rules follow, which differ from the AX-12's:

    * ``alarm``: the firmware detects the errors now.  Only those Shutdown(63) selects are detected
      (e-manual: "when 0x05 is defined as Shutdown, DYNAMIXEL can detect both Input Voltage Error
      and Overheating Error"), so asking for another is a ValueError.  A detected error latches in
      Hardware Error Status, sets the Alert bit (0x80) of every status packet and turns the torque
      off, and only REBOOT clears it: an event, not a lasting condition as on the AX-12.
      :meth:`clear_alarm` reboots the servo as the REBOOT instruction does.
    * ``stall``: the shaft is held still while the firmware keeps driving, so Present Velocity
      reads 0, the current rises as far as the drive's limits let it and the overload protection
      trips once its current account fills (1 s at the full stall current, never under a quarter
      of it: ``firmware_model.xseries.firmware.OVERLOAD_CURRENT_SHARE``; Overload, torque off, if
      Shutdown selects it).
    * ``hold``: a sensed register pinned as a stuck sensor would pin it; a pinned Present
      Temperature or Present Input Voltage outside its limits raises the error as a real reading does.
    * ``duplicate``: as on the AX-12 bus, both servos act on every packet to the ID and answer at
      once; the bus lays replies one after another but collides those it times together
      (``reply.collide``), so equal answers look clean and different ones fail the CRC.  In a Sync
      or Bulk Read both answer in the ID's turn; in a Fast Sync/Bulk Read only the first does.
    """

    def _before_steps(self, bus) -> None:
        """Nothing: each servo's firmware acts out its own faults at its own steps."""

    def before_step(self) -> None:
        """Nothing: as :meth:`_before_steps`."""

    def _servo2(self, slot: int) -> "Servo2":
        return self.bus.servos[self._index(slot)]  # type: ignore[return-value]

    def _firmware(self, slot: int, what: str) -> XFaultable:
        firmware = self._servo2(slot).plant.firmware
        if not isinstance(firmware, XFaultable):
            raise ValueError(f"{what}: {type(firmware).__name__} (ID {slot}) cannot be made to fail (no XFaultable methods)")
        return firmware

    def force_alarm(self, slot: int, bits: int | str) -> None:
        """The servo's firmware detects Hardware Error Status ``bits`` (int or names, e.g. "overload,electrical_shock") now."""
        value = parse_alarm_bits(bits, HW_ERROR_NAMES) if isinstance(bits, str) else operator.index(bits)
        if not value or value & ~_HW_ERROR_BITS:
            raise ValueError(f"Hardware Error Status bits are {', '.join(f'{k} {v:#04x}' for k, v in HW_ERROR_NAMES.items())}; "
                             f"got {value:#04x}")
        servo = self._servo2(slot)
        firmware = self._firmware(slot, "alarm")
        # Shutdown as the firmware takes it: in its own bits (a classic table's, the XL-320's Shutdown(18), translated).
        shutdown = servo.plant.commands().shutdown
        if value & ~shutdown:
            first_names = {bit: name for name, bit in reversed(list(HW_ERROR_NAMES.items()))}  # not the aliases
            unselected = [name for bit, name in sorted(first_names.items()) if bit & value & ~shutdown]
            raise ValueError(f"alarm: ID {slot}'s Shutdown({servo.table.layout.by_name['shutdown'].address}) is "
                             f"{servo.table.get('shutdown'):#04x}, which does not select {', '.join(unselected)}: "
                             "the firmware detects only the errors Shutdown selects (write Shutdown first)")
        firmware.raise_error(value)
        servo.plant.write_back()
        index = self._index(slot)
        self._alarms[index] = self._alarms.get(index, 0) | value

    def clear_alarm(self, slot: int) -> None:
        """A latched error clears only by REBOOT: the servo reboots, as the REBOOT instruction does; not if the client
        has already rebooted it (a second reboot turned off a torque it had turned back on)."""
        index = self._index(slot)
        if index in self._alarms:
            self._forget_cleared_alarms(index, self._servo2(slot).plant.firmware.sense().hardware_error_status)
        if self._alarms.pop(index, None) is not None:
            self._servo2(slot).reboot()

    def stall(self, slot: int, *, overload_after_s: float | None = None) -> None:
        """Block the shaft where it is; the overload follows as the firmware's current account fills."""
        if overload_after_s is not None:
            raise ValueError("stall: an X-series servo trips on overload after its firmware's overload time "
                             "(XFirmware.overload_time_s), not a time given here")
        self._firmware(slot, "stall").set_blocked(True)
        self._blocked.add(self._index(slot))

    def release(self, slot: int) -> None:
        """Free the shaft (a latched Overload stays until REBOOT, as on a real servo)."""
        index = self._index(slot)
        if index in self._blocked:
            self._firmware(slot, "stall").set_blocked(False)
            self._blocked.discard(index)

    def hold(self, slot: int, name: str, value: int | None) -> None:
        """Pin a sensed register (the model's table's name, e.g. present_temperature) at ``value``; None frees it."""
        from ax12emu.servo.plant2 import SENSED_REGISTERS  # loaded with the Protocol 2.0 bus, not before

        servo = self._servo2(slot)
        if name not in servo.table.layout.by_name:
            raise KeyError(f"{servo.spec.name} has no register {name!r}")
        if servo.spec.classic is not None:  # a classic table (the XL-320's): only the readings in the firmware's units
            if name not in _CLASSIC_HELD:
                raise ValueError(f"hold: {name!r} is not a register the firmware senses in its units; those are {', '.join(_CLASSIC_HELD)}")
            field = _CLASSIC_HELD[name]
        else:
            field = next((field for field, names in SENSED_REGISTERS.items() if name in names), None)
        if field is None:
            raise ValueError(f"hold: {name!r} is not a register the firmware senses; those are "
                             f"{', '.join(n for names in SENSED_REGISTERS.values() for n in names if n in servo.table.layout.by_name)}")
        self._hold_reading(slot, name, field, value)

    def _hold_reading(self, slot: int, name: str, field: str, value: int | None) -> None:
        """Pin the firmware's reading ``field`` (the table's register ``name``) at ``value``; None frees it."""
        if value is not None:
            value = _in_bytes(self._servo2(slot).table.layout.by_name[name], value)
        self._firmware(slot, "hold").hold_reading(field, value)
        self._servo2(slot).plant.write_back()
        index = self._index(slot)
        held = self._held.setdefault(index, {})
        if value is None:
            held.pop(name, None)
            if not held:
                del self._held[index]
        else:
            held[name] = int(value)

    def _forget_cleared_alarms(self, index: int, latched_bits: int) -> None:
        """Keep of the alarms forced on servo ``index`` only those still in ``latched_bits`` (the servo's, in their terms)."""
        latched = self._alarms[index] & latched_bits
        if latched:
            self._alarms[index] = latched
        else:
            del self._alarms[index]

    def active(self, slot: int) -> list[str]:
        """As :meth:`Faults.active`; a forced alarm a REBOOT has cleared is no longer listed."""
        index = self._index(slot)
        if index in self._alarms:  # the firmware's bits
            self._forget_cleared_alarms(index, self._servo2(slot).plant.firmware.sense().hardware_error_status)
        return super().active(slot)

    def clear(self) -> None:
        """Lift every fault (a servo with a forced alarm reboots: see :meth:`clear_alarm`)."""
        super().clear()

    def duplicate(self, slot: int, as_id: int) -> None:
        """Give the servo launched as ``slot`` the ID ``as_id`` (0..252 on Protocol 2.0, normally another servo's)."""
        from ax12emu.protocol.packets2 import MAX_ID2  # loaded with the Protocol 2.0 bus, not before

        if not 0 <= as_id <= MAX_ID2:
            raise ValueError(f"ID {as_id} is outside 0..{MAX_ID2} (Protocol 2.0)")
        super().duplicate(slot, as_id)

    def admit(self, servo: "VirtualServo") -> bool:  # type: ignore[override]
        """Before ``servo`` handles a packet: False if it is unplugged (its other faults live in its firmware)."""
        vanished = self._vanished.get(servo.index)
        if vanished is None:
            return True
        every_s, for_s = vanished
        return not (every_s is None or self.bus.clock.now_s() % every_s < for_s)  # type: ignore[operator]

    def after_physics(self) -> None:
        """Nothing: the firmware itself holds a stalled shaft and pinned readings."""


#: The readings an MX's Protocol 1.0 table shows unchanged from the firmware's (``ClassicMap.sensed_to_registers``
#: copies them: degrees C, 0.1 V on both), by register name: what ``hold`` can pin, as the firmware's field.
_CLASSIC_HELD: Mapping[str, str] = {"present_temperature": "present_temperature", "present_voltage": "present_input_voltage"}


class Faults1X(Faults2):
    """The faults of a Protocol 1.0 wire with MX-series servos (:class:`~ax12emu.bus.bus1x.Bus1X`), AX-12As beside them if any.

    An MX on Protocol 1.0 runs the X-series firmware model behind its classic table (``ax12emu.servo.plant1x``),
    so its own faults act inside that firmware as :class:`Faults2`'s do, and show as the Protocol 1.0 firmware
    shows them: the status packets carry the conditions present, and those Alarm Shutdown(18) selects set
    Torque Limit to 0 (ROBOTIS e-manual, MX-28 (Protocol 1.0), "Torque Limit(34)": "If the function of Alarm
    LED(17)/Shutdown(18) is triggered, the motor loses its torque because Torque Limit(34) becomes 0. Once
    error conditions are resolved and Torque Limit(34) is changed to the value other than 0, the motor can be
    operated again."):

    * ``alarm``: status-packet alarm bits by the model file's ``[classic] errors`` names (overload,
      overheating, input_voltage) or as bits, raised until :meth:`clear_alarm` as on the AX-12 bus: every
      status packet carries them and, where Shutdown(18) selects them, Torque Limit drops to 0 and stays
      there until the client writes it once they are lifted.
    * ``stall``: the shaft is held while the firmware drives; its overload protection trips after the
      firmware's own overload time (Overload, Torque Limit 0, if Shutdown selects it).
    * ``hold``: Present Temperature or Present Voltage pinned, judged by the firmware's limits.
    * the wire's (``drop``, ``corrupt``, ``delay``) act on every status packet of the wire, the AX-12As'
      too (one random stream); ``vanish`` and ``duplicate`` (IDs 0..253) on any servo of it.

    An AX-12A on the same wire is named by its slot as well (slots are unique on one protocol): its
    faults are its bus's (:class:`Faults`, ``bus.ax_bus.faults``), reached through this object.
    """

    #: Per-servo methods an AX-12A's slot is routed to its own bus's :class:`Faults` for.
    _ROUTED = ("vanish", "reappear", "force_alarm", "clear_alarm", "duplicate", "unduplicate", "stall", "release", "hold")

    def __init__(self, bus, *, seed: int = 0) -> None:
        super().__init__(bus, seed=seed)
        ax_bus = bus.ax_bus
        #: The AX-12As' faults (their bus's); its reply faults stay off: this object's act on the whole wire.
        self.ax: Faults | None = None
        if ax_bus is not None:
            if ax_bus.faults is None:
                ax_bus.faults = Faults(ax_bus, seed=seed)
            self.ax = ax_bus.faults  # type: ignore[assignment]

    def _index(self, slot: int) -> int:
        try:
            return self.bus.slots_mx.index(slot)
        except ValueError:
            raise ValueError(f"no servo launched as ID {slot} (slots: {self.bus.slots})") from None

    def force_alarm(self, slot: int, bits: int | str) -> None:
        """Raise the alarms ``bits`` (status-packet bits, or names such as "overload") until :meth:`clear_alarm`.

        As on the AX-12A: every status packet carries them, whatever Shutdown(18) selects, and those it
        selects set Torque Limit to 0 (``ax12emu.servo.plant1x``).
        """
        servo = self._servo2(slot)
        names = dict(servo.plant.classic.units.errors)  # the family's Shutdown/status bits by name, from its model file
        value = parse_alarm_bits(bits, names) if isinstance(bits, str) else operator.index(bits)
        if not value or value & ~sum(names.values()):
            raise ValueError(f"{servo.spec.name}'s alarm bits are {', '.join(f'{k} {v:#04x}' for k, v in names.items())}; "
                             f"got {value:#04x}")
        index = self._index(slot)
        self._alarms[index] = self._alarms.get(index, 0) | value
        self._hold_alarms(slot, self._alarms[index])

    def clear_alarm(self, slot: int) -> None:
        """Lift forced alarms; the firmware's own conditions, if any, stay (Torque Limit stays as it is)."""
        self._alarms.pop(self._index(slot), None)
        self._hold_alarms(slot, 0)

    def _hold_alarms(self, slot: int, bits: int) -> None:
        """The MX's firmware holds the conditions of the status-packet ``bits`` (0: none) present, then the copy."""
        servo = self._servo2(slot)
        self._firmware(slot, "alarm").hold_errors(servo.plant.classic.errors_to_x(bits))
        servo.plant.write_back()

    def duplicate(self, slot: int, as_id: int) -> None:
        """Give the servo launched as ``slot`` the ID ``as_id`` (0..253 on Protocol 1.0, normally another servo's)."""
        Faults.duplicate(self, slot, as_id)

    def hold(self, slot: int, name: str, value: int | None) -> None:
        """Pin Present Temperature or Present Voltage (register units) at ``value``; None frees it."""
        servo = self._servo2(slot)
        if name not in servo.table.layout.by_name:
            raise KeyError(f"{servo.spec.name} has no register {name!r}")
        if name not in _CLASSIC_HELD:
            raise ValueError(f"hold: {name!r} is not a register the firmware senses; those are {', '.join(_CLASSIC_HELD)}")
        self._hold_reading(slot, name, _CLASSIC_HELD[name], value)

    def active(self, slot: int) -> list[str]:
        """As :meth:`Faults.active`; a forced alarm the client has cleared (Torque Limit written) is no longer listed."""
        if self.ax is not None and slot in self.ax.bus.slots:  # the AX-12A's own, and the wire's reply faults
            return [*self.ax.active(slot), *self._on_replies_of(self.ax.bus.servos[self.ax._index(slot)].id)]
        return Faults.active(self, slot)

    def clear(self) -> None:
        """Lift every fault, the AX-12As' too."""
        super().clear()
        if self.ax is not None:
            self.ax.clear()


def _routed_to_ax(name: str):
    """``Faults1X.<name>``, sending an AX-12A's slot to its own bus's faults."""
    own = getattr(Faults1X, name)

    def method(self: Faults1X, slot: int, *args, **kwargs):
        if self.ax is not None and slot in self.ax.bus.slots:
            return getattr(self.ax, name)(slot, *args, **kwargs)
        return own(self, slot, *args, **kwargs)

    method.__name__, method.__qualname__, method.__doc__ = name, f"Faults1X.{name}", own.__doc__
    return method


for _name in Faults1X._ROUTED:
    setattr(Faults1X, _name, _routed_to_ax(_name))


class MixedFaults:
    """The faults of a wire mixing Protocol 1.0 servos (AX-12A, AX-18A, MX) and X-series servos (Protocol 2.0).

    Each protocol's bus keeps its own :class:`Faults`, :class:`Faults1X` or :class:`Faults2` (``bus1.faults``,
    ``bus2.faults``), both from one seed.  The wire's reply faults apply to both.  A servo is named
    by its slot; launch IDs are per protocol, so a slot both protocols have needs ``protocol=1.0``
    or ``2.0`` (a ValueError says so), which the CLI flags and URL options cannot give.
    """

    def __init__(self, bus: "MixedBus", *, seed: int = 0) -> None:
        self.bus = bus
        self.seed = seed
        self.by_protocol: dict[float, Faults] = {}
        for protocol, sub in ((1.0, bus.bus1), (2.0, bus.bus2)):
            if sub.faults is None:
                sub.faults = faults_for(sub, seed=seed)
            self.by_protocol[protocol] = sub.faults  # type: ignore[assignment]
        # One random stream for the wire's replies, as on a bus of one protocol: two streams from one seed drew
        # alike, so a 1.0 and a 2.0 reply were always lost together, never one of them.
        self.by_protocol[2.0]._rng = self.by_protocol[1.0]._rng

    def of(self, slot: int, protocol: float | None = None) -> Faults:
        """The faults of the protocol whose servo was launched as ``slot``."""
        if protocol is not None:
            if protocol not in self.by_protocol:
                raise ValueError(f"protocol must be 1.0 or 2.0, got {protocol!r}")
            return self.by_protocol[protocol]
        have = [faults for faults in self.by_protocol.values() if slot in faults.bus.slots]
        if not have:
            raise ValueError(f"no servo launched as ID {slot} (Protocol 1.0 slots: {self.bus.bus1.slots}, "
                             f"Protocol 2.0: {self.bus.bus2.slots})")
        if len(have) > 1:
            raise ValueError(f"ID {slot} was launched on both protocols of this wire: give protocol=1.0 or protocol=2.0")
        return have[0]

    def set_reply_faults(self, **kwargs: object) -> None:
        """As :meth:`Faults.set_reply_faults`, on both protocols' replies; the IDs are checked against the whole
        wire's servos, once (each half knows only its own, and a 1.0 ID is no 2.0 servo's)."""
        for faults in self.by_protocol.values():
            faults.set_reply_faults(**kwargs, warn_unanswered=False)  # type: ignore[arg-type]
        _warn_if_unanswered(self.by_protocol[1.0].reply_ids, self.bus)

    def clear(self) -> None:
        for faults in self.by_protocol.values():
            faults.clear()

    def after_physics(self) -> None:
        """Nothing: each protocol's bus calls its own faults."""

    @property
    def dropped(self) -> int:
        return sum(faults.dropped for faults in self.by_protocol.values())

    @property
    def corrupted(self) -> int:
        return sum(faults.corrupted for faults in self.by_protocol.values())

    @property
    def delayed(self) -> int:
        return sum(faults.delayed for faults in self.by_protocol.values())

    def __getattr__(self, name: str):
        """A per-servo method of Faults (vanish, stall, force_alarm, hold, active, ...), routed by slot."""
        if name.startswith("_") or not callable(getattr(Faults, name, None)):
            raise AttributeError(name)

        def method(slot: int, *args: object, protocol: float | None = None, **kwargs: object) -> object:
            return getattr(self.of(slot, protocol), name)(slot, *args, **kwargs)

        return method


def faults_for(bus: "Bus | Bus2 | MixedBus", *, seed: int = 0) -> "Faults | MixedFaults":
    """The faults a bus can take: :class:`Faults` on the AX-12 bus, :class:`Faults2` on a Protocol 2.0 bus,
    :class:`Faults1X` on a Protocol 1.0 wire with MX servos, both protocols' on a mixed wire."""
    # A Bus2 exists only once its module is loaded: the AX-12 bus's users do not pay for importing it.
    bus2 = sys.modules.get("ax12emu.bus.bus2")
    if bus2 is not None and isinstance(bus, bus2.Bus2):
        return Faults2(bus, seed=seed)  # type: ignore[arg-type]
    bus1x = sys.modules.get("ax12emu.bus.bus1x")
    if bus1x is not None and isinstance(bus, bus1x.Bus1X):
        return Faults1X(bus, seed=seed)
    mixed = sys.modules.get("ax12emu.bus.mixed")
    if mixed is not None and isinstance(bus, mixed.MixedBus):
        return MixedFaults(bus, seed=seed)
    return Faults(bus, seed=seed)  # type: ignore[arg-type]
