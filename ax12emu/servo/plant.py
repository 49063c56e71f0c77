"""The adapter between control tables and a servo model: commands out, sensed values in.

Why it exists: it is the only place that knows both the control table's byte
layout and the model's interface, so the model stays free of packets and the
protocol code free of physics.  All N servos are read and written at once
from the bus's shared ``(N, 50)`` byte array.

It also applies the firmware's reaction to alarms: Alarm Shutdown (address
18) acts on the bits it selects, as the table's profile says (e-manual:
Torque Limit set to 0; 2006 manual: torque off).  The model acts on it at
the control step it finds an alarm (Alarm Shutdown is one of its commands),
however long the step it was asked for, and reports the cut
(``Sensed.output_cut``), which is written here even if the alarm has gone
again since; alarms the model is not shown (a forced one, a held reading)
are applied here and by the faults.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence

import numpy as np

from ax12emu.protocol.control_table import Layout
from firmware_model.grouped import GroupedModel
from firmware_model.interface import Commands, Sensed, ServoModel, SteppableTo
from firmware_model.physical import PhysicalModel

from .plant2 import GRID_SLACK_S, step_due
from .virtual_servo import VirtualServo

__all__ = ["Plant"]


def _columns(lay: Layout, names: Sequence[str]) -> dict[str, tuple[int, int]]:
    return {name: (lay.by_name[name].address, lay.by_name[name].size) for name in names}


def _check_edition(model: ServoModel, clears: str) -> None:
    """ValueError where a part of ``model`` acts out another edition's Alarm Shutdown than the tables' (``clears``).

    Why: the model cuts inside a step, however long, and the tables then show the cut it reports; a model built for
    one edition behind another's tables drove a cut servo as neither edition does (2006 tables, e-manual model:
    Torque Limit 0 with torque on inside the step, torque off written after it).
    """
    for part in model.models if isinstance(model, GroupedModel) else [model]:
        if isinstance(part, PhysicalModel) and part.shutdown_clears != clears:
            raise ValueError(f"the model's Alarm Shutdown clears {part.shutdown_clears}, these servos' clears {clears}: "
                             f"build it for their profile (ModelChoice(profile=...), PhysicalModel(shutdown_clears={clears!r}))")


class Plant:
    """Runs ``model`` behind the servos whose tables are the rows of ``rows``."""

    def __init__(self, model: ServoModel, rows: np.ndarray, servos: Sequence[VirtualServo]) -> None:
        if model.n != len(servos) or rows.shape[0] != len(servos):
            raise ValueError(f"model has {model.n} servos, bus has {len(servos)}")
        self.model = model
        self.rows = rows
        self.servos = servos
        lay = servos[0].table.layout
        self._profile = lay.profile
        self._commands = _columns(lay, Commands.field_names())
        self._sensed = _columns(lay, [n for n in Sensed.field_names() if n not in ("alarms", "output_cut")])
        self._torque_limit = lay.by_name["torque_limit"].address
        self._torque_enable = lay.by_name["torque_enable"].address
        self._shutdown = lay.by_name["shutdown"].address
        _check_edition(model, self._profile.shutdown_clears or "torque_limit")
        self._cached_commands: Commands | None = None
        #: Called before the model steps on tables changed since its last step (see :meth:`_step_commands`):
        #: the Alarm Shutdown of alarms the model is not shown (the faults' forced ones) acts on them first.
        self.before_step: Callable[[], None] | None = None
        #: Whether the model can step without sensing (checked once: a protocol test is slow per step).
        self._steps_to = isinstance(model, SteppableTo)
        self._any_alarm = True
        #: Whether the model reported an Alarm Shutdown cut at the last write-back.
        self._any_cut = True
        #: The arrays last written, by register: a model may hand over the same read-only
        #: array until the value changes (see ServoModel.sense), which then needs no copying.
        #: A register set by name (``ControlTable.set``, as faults and harnesses do) drops this
        #: and the decoded commands through ``on_set``, so the model's value returns at the next
        #: write-back; bytes written into a row directly (a packet) are followed by tables_changed.
        self._written: dict[str, object] = {}
        self._refreshes = 0
        #: Client writes counted, the count the tables show the firmware's answer to, and the
        #: model's time at the last write (see :meth:`catch_up`).
        self._writes = self._writes_shown = 0
        self._write_time_s = model.time_s
        for servo in servos:
            servo.table.on_set = self._on_set
        for name, (address, size) in {**self._commands, **self._sensed}.items():
            if size == 2 and address % 2:
                raise AssertionError(f"{name} at odd address {address}: the word view cannot read it")
        self.refresh()

    def commands(self) -> Commands:
        """The command registers of every servo, as int64 arrays (cached until a table changes)."""
        if self._cached_commands is None:
            as_bytes = self.rows.astype(np.int64)
            # Every 2-byte entry starts at an even address, so a little-endian word view reads it.
            as_words = self.rows.view("<u2").astype(np.int64)
            self._cached_commands = Commands(
                **{
                    name: as_words[:, address // 2] if size == 2 else as_bytes[:, address]
                    for name, (address, size) in self._commands.items()
                }
            )
        return self._cached_commands

    def _step_commands(self) -> Commands:
        """:meth:`commands` for a step, after ``before_step`` where the tables changed since the last.

        Why: an alarm the model is not shown lasts between steps, and the firmware's Alarm Shutdown
        acts on the registers every control step finds, so a Torque Limit (Torque Enable in the
        2006 edition) written while it lasts is cut before a step can drive with it, whoever wrote
        it: a packet (after which the bus applies the faults at once) or a register set by name.
        """
        if self._cached_commands is None and self.before_step is not None:
            self.before_step()
        return self.commands()

    def _on_set(self, name: str) -> None:
        self.tables_changed()

    def tables_changed(self) -> None:
        """Tell the plant a client may have written commands (or any register: all are rewritten next)."""
        self._cached_commands = None
        self._written.clear()

    def wrote(self) -> None:
        """A client's packet may have written registers: the next request must see the firmware's answer.

        Why: the AX-12 runs its control loop every 1 ms (the motor-control
        interrupt, xevelabs' USB2AX protocol notes), and over USB a host's
        next packet cannot arrive before it has run, so a client that writes
        a goal and polls Moving always finds the move started.  The model
        steps on its own grid, up to a step behind the clock (``Bus.request_lag_s``),
        so without this the first poll could be answered from a step taken
        before the write.
        """
        self.tables_changed()
        self._writes += 1
        self._write_time_s = self.model.time_s

    @property
    def write_unseen(self) -> bool:
        """Whether the tables do not yet show a step taken after the last client write."""
        return self._writes != self._writes_shown

    def catch_up(self, sim_time_s: float, clock_s: float | None = None) -> None:
        """:meth:`advance` for a request: also one step past the last client write.

        That step may end up to one step past ``clock_s`` (the clock's present:
        ``sim_time_s`` plus any request lag): the time the control loop had
        before the request could arrive.  Only the first request after a write
        pays for it; if the serving loop's tick already stepped after the write
        (its sensors not yet copied), only the copying is left.  A model already
        a step past the clock takes no other: a real servo's loop never runs
        ahead of its own clock, so a write in the same control period (a client
        faster than 1 kHz, possible over a pty, not over USB) is taken as the
        firmware takes a packet between two ticks, the new commands acted on
        (goal, limits, torque: the sensed registers that follow from them alone,
        such as Moving) with no time passing; the physics waits for the clock.
        """
        model = self.model
        if step_due(model, sim_time_s):
            self.advance(sim_time_s)
        if self._writes != self._writes_shown:
            writes = self._writes
            if model.time_s > self._write_time_s:
                sensed = model.sense()
            elif model.time_s <= (sim_time_s if clock_s is None else clock_s) + GRID_SLACK_S:
                sensed = model.advance(model.time_s + model.step_s, self._step_commands())
            else:
                sensed = model.advance(model.time_s, self._step_commands())
            self._write_back(sensed)
            self._writes_shown = writes

    def advance(self, sim_time_s: float) -> bool:
        """Advance the model to ``sim_time_s`` if a whole step is due; True if it moved."""
        model = self.model
        if not step_due(model, sim_time_s):
            return False
        writes = self._writes
        self._write_back(model.advance(sim_time_s, self._step_commands()))
        self._writes_shown = writes
        return True

    def tick(self, sim_time_s: float) -> Iterator[None]:
        """:meth:`advance` in three pieces, step, read the sensors, write them back, yielding between them.

        Why: behind a host polling as fast as it can, a serving loop runs one
        piece per pass, each just after it answered a packet, while the host
        is busy with the reply; a whole step at once (about 0.1 ms for 18
        servos on the development VM, several times its cost in a quiet loop)
        would keep the next request waiting.  Until the last piece the tables
        show the previous step (see ``Bus.request_lag_s``).
        """
        model = self.model
        if not self._steps_to or not step_due(model, sim_time_s):
            self.advance(sim_time_s)  # without step_to (it is optional), the whole step at once
            return
        writes = self._writes
        model.step_to(sim_time_s, self._step_commands())  # type: ignore[attr-defined]
        stepped_to_s = model.time_s
        yield
        sensed = model.sense()
        refreshes = self._refreshes
        yield
        # Unless, in between, a request stepped again or someone refreshed the tables (after
        # changing the model, e.g. turning a shaft by hand): their values are newer.
        if model.time_s == stepped_to_s and self._refreshes == refreshes:
            self._write_back(sensed)
            self._writes_shown = writes  # writes that came between the pieces stay unseen

    def refresh(self, *, alarms: bool = True) -> None:
        """Copy the model's present sensed values into the tables without advancing.

        ``alarms=False`` after a RESET: the model's last step judged its alarms under the
        limits the RESET has just erased, and tripping the Alarm Shutdown with them would
        zero Torque Limit on the factory table.  The next control step (which a RESET, a
        write, earns before the next request) judges them under the factory limits.
        """
        self._written.clear()
        self._refreshes += 1
        self._write_back(self.model.sense(), alarms=alarms)

    def _write_back(self, sensed: Sensed, *, alarms: bool = True) -> None:
        rows, written = self.rows, self._written
        words = rows.view("<u2")
        for name, (address, size) in self._sensed.items():
            value = getattr(sensed, name)
            if written.get(name) is value and not value.flags.writeable:
                continue  # the very array written last time, and nobody can have changed it
            written[name] = value
            if size == 2:
                words[:, address // 2] = value
            else:
                rows[:, address] = value
        if not alarms:
            return
        # The servos the model's own Alarm Shutdown cut at a control step (the alarm may have gone since).
        cut = sensed.output_cut
        if cut is None:  # a model that leaves Alarm Shutdown to the alarms shown here
            self._any_cut = False
        elif (self._any_cut or written.get("output_cut") is not cut or cut.flags.writeable):
            written["output_cut"] = cut
            cut = np.asarray(cut) != 0
            self._any_cut = bool(cut.any())
        if not self._any_cut:
            cut = None
            if written.get("alarms") is sensed.alarms and not (self._any_alarm or sensed.alarms.flags.writeable):
                return  # no alarm then, the same read-only bits now
        written["alarms"] = sensed.alarms
        alarms = np.asarray(sensed.alarms, dtype=np.int64) & 0x7F
        any_alarm = bool(alarms.any())
        if not (any_alarm or self._any_alarm or cut is not None):
            return  # no alarm now nor at the last step, no cut: nothing to clear or trip
        self._any_alarm = any_alarm
        for servo, bits in zip(self.servos, alarms.tolist()):
            servo.alarms = bits
        tripped = (alarms & rows[:, self._shutdown]) != 0
        if cut is not None:
            tripped |= cut
        if tripped.any():
            self._cached_commands = None
            if self._profile.shutdown_clears == "torque_enable":
                rows[tripped, self._torque_enable] = 0
            else:
                words[tripped, self._torque_limit // 2] = 0
        if cut is not None:
            # Hand the model the registers its cut wrote at once, with no time passing: it then holds the cut
            # no longer, and a Torque Limit a client writes before the next step is a new value, as on the servo.
            model = self.model
            if self._steps_to:
                model.step_to(model.time_s, self.commands())  # type: ignore[attr-defined]
            else:
                model.advance(model.time_s, self.commands())
