"""The adapter between one X-series control table and its firmware model: commands out, sensed values in.

Why it exists: as :mod:`ax12emu.servo.plant` does for the AX-12, it is the one place that knows
both the table's registers and the model's seam (:mod:`firmware_model.xseries.interface`), so
neither imports the other.  A Protocol 2.0 bus may mix models with different tables, so there is
one plant per servo, and registers are matched by name: a model's table without a register
(the XL430 has no Goal Current) leaves that command at its default.

What it adds to the seam, from the e-manual (X series, "Bus Watchdog(98)"):
:meth:`hold` stops the servo as the Bus Watchdog does ("the DYNAMIXEL will stop"): the model is
commanded to hold its present position at zero velocity (and zero PWM or current in the modes
whose goal they are), whatever the Goal registers say, until :meth:`release` (the next goal a client writes after the error is cleared).
Shutdown is the firmware's: it reports Torque Enable among the sensed registers.
"""

from __future__ import annotations

import dataclasses
import operator
import struct
from collections.abc import Callable, Iterator

from ax12emu.protocol.registers import Entry
from ax12emu.protocol.servo_models import ServoModel
from firmware_model.xseries.interface import TRAJECTORY_SENSED, OperatingMode, XCommands, XSensed, XServoModel

from .classic import ClassicMap
from .table2 import Table2

__all__ = ["ClassicPlant2", "GRID_SLACK_S", "Plant2", "SENSED_REGISTERS", "SteppedPlant", "plant_for", "step_due"]

#: Where each sensed value goes: the first of these registers the table has (the XL430's
#: register 126 is Present Load, the current-sensing models' Present Current).
SENSED_REGISTERS: dict[str, tuple[str, ...]] = {
    name: (name,) for name in XSensed.field_names()
}
SENSED_REGISTERS["present_current"] = ("present_current", "present_load")

#: How far a model's time may sit past the clock and still count as not ahead of it: both add up
#: steps of a millisecond in floating point, so equal times may differ in their last bits.
GRID_SLACK_S = 1e-9

#: Sensed registers the bus reads while handling any packet: the Bus Watchdog checks Torque Enable, and
#: every status packet's Alert bit is Hardware Error Status.
_READ_PER_PACKET = ("torque_enable", "hardware_error_status")
#: The command registers that move the frame or the torque (``XFirmware.keeps_sensing``), in this order.
_FRAME_REGISTERS = ("drive_mode", "operating_mode", "homing_offset", "torque_enable")
#: More distinct reads than a client makes; past it the remembered spans start over.
_MAX_SPANS = 256
_UNKNOWN = object()

#: struct codes of a little-endian register by (size, signed).
_CODES = {(1, False): "B", (1, True): "b", (2, False): "H", (2, True): "h", (4, False): "I", (4, True): "i"}


def _reader(entries: list[Entry]) -> tuple[tuple[str, ...], Callable[[bytearray], tuple[int, ...]]]:
    """The entries' names, and a function reading all their values from a row in one ``struct`` call.

    Why: the firmware is handed every command register after each client write, for each servo
    a Sync Write reaches, and one unpack replaces two dozen register reads.  The
    values are ``Entry.value_in``'s (little-endian, two's complement where signed).
    """
    ordered = sorted(entries, key=lambda entry: entry.address)
    names = tuple(entry.name for entry in ordered)
    at, fmt = 0, "<"
    for entry in ordered:
        code = _CODES.get((entry.size, entry.signed))
        if code is None or entry.address < at:  # not a struct size, or overlapping: one by one
            return names, lambda row: tuple(entry.value_in(row) for entry in ordered)
        fmt += f"{entry.address - at}x{code}"
        at = entry.end
    unpack = struct.Struct(fmt).unpack_from
    return names, unpack


def _writer(entries: list[Entry]) -> Callable[[bytearray, tuple[int, ...]], None]:
    """A function storing values (one per entry, in ``entries``' order) into a row as ``Table2.set`` does.

    Why: every step of every servo copies a dozen sensed registers back; one ``struct`` call per run of
    adjacent registers replaces a slice assignment each.  Values are masked to their size first, as
    ``Entry.to_bytes`` does (two's complement where signed).
    """
    order = sorted(range(len(entries)), key=lambda k: entries[k].address)
    runs: list[list] = []  # [address, end, format, indices, masks]
    for k in order:
        entry = entries[k]
        code = _CODES.get((entry.size, False))
        if code is None or (runs and entry.address < runs[-1][1]):  # not a struct size, or overlapping
            slots = [(entry.address, entry.end, entry.to_bytes) for entry in entries]

            def one_by_one(row: bytearray, values: tuple[int, ...], slots=slots) -> None:
                for (start, end, to_bytes), value in zip(slots, values):
                    row[start:end] = to_bytes(value)
            return one_by_one
        if runs and entry.address == runs[-1][1]:
            run = runs[-1]
            run[1], run[2] = entry.end, run[2] + code
        else:
            run = [entry.address, entry.end, "<" + code, [], []]
            runs.append(run)
        run[3].append(k)
        run[4].append((1 << (8 * entry.size)) - 1)
    packers = [(address, struct.Struct(fmt).pack_into, tuple(zip(indices, masks)))
               for address, _, fmt, indices, masks in runs]

    def by_runs(row: bytearray, values: tuple[int, ...]) -> None:
        for address, pack_into, picks in packers:
            pack_into(row, address, *[values[k] & mask for k, mask in picks])
    return by_runs


def step_due(model, sim_time_s: float) -> bool:
    """Whether a whole control step of ``model`` falls due by ``sim_time_s``: within :data:`GRID_SLACK_S`, the
    slack every model's ``step_to`` takes a step by (``firmware_model.interface.STEP_SLACK`` of a step)."""
    return sim_time_s + GRID_SLACK_S >= model.time_s + model.step_s


class SteppedPlant:
    """A firmware model brought to the bus's time: the steps due by then, one past a client's write, then the copy.

    Why a class of its own: the X series' plant (:class:`Plant2`) and the MX series' on Protocol 1.0
    (:class:`~.plant1x.Plant1X`) run the same firmware model against the same clock and differ only
    in how the table's commands reach it and its readings come back.  A subclass holds ``firmware``,
    sets ``_write_unseen`` when it commands the model, and copies the readings in ``write_back()``.
    """

    firmware: XServoModel
    _write_unseen: bool
    #: Writes handed to the model so far (see :meth:`tick`: one between its pieces stays unseen).
    _writes: int = 0
    #: A client's write came while the model was ahead of the clock: its commands were read back at once and
    #: the step it earns is taken as soon as the clock reaches the model's time (see :meth:`catch_up`).
    _step_owed: bool = False
    #: The (sim_time_s, clock_s) of a catch-up left for after a reply it could not change (see
    #: :meth:`Plant2.defer_catch_up`), taken before anything else reaches the model; None: none.
    _deferred: tuple[float, float | None] | None = None

    def _wrote(self) -> None:
        """A client's write was handed to the model: the next request sees a step taken after it."""
        self._write_unseen = True
        self._writes += 1

    def due(self, sim_time_s: float, clock_s: float | None = None) -> bool:
        """Whether a whole step is due by ``sim_time_s``, a client's write is not yet shown, or the step a write
        earned is owed and the clock (``clock_s``, else ``sim_time_s``) has reached the model's time."""
        model = self.firmware
        if self._write_unseen or step_due(model, sim_time_s):
            return True
        return self._step_owed and model.time_s <= (sim_time_s if clock_s is None else clock_s) + GRID_SLACK_S

    def catch_up(self, sim_time_s: float, clock_s: float | None = None) -> None:
        """Step to ``sim_time_s``, and one step past a client's write, then copy the sensed registers.

        Why one step past a write: as on the AX-12 (``Plant.wrote``), the firmware's control loop
        runs before a host's next packet can arrive, so a client that writes a goal and then reads
        Moving finds the move started.  That step may take the model at most one step past the
        clock (``clock_s``: the clock's present, ``sim_time_s`` plus any request lag): a servo's
        loop never runs ahead of its own clock, so a second write in the same control period (a
        client faster than 1 kHz, possible over a pty, not over USB) is taken as the firmware takes
        a packet between two ticks: the commands it handed the model (:meth:`command`: profile
        restarted, torque and mode acted on, at the model's time) read back at once, and the
        step waits for the clock: it is taken at the first catch-up or tick once the clock has reached
        the model's time, as the servo's next tick runs with the last commands it was given.
        """
        if self._deferred is not None:
            self.catch_up_deferred()
        model = self.firmware
        copy = False
        # A step judged due by the grid's slack that the model did not take (its own slack narrower) must not pass
        # for one: the write it was owed to would be marked seen with nothing run.
        if step_due(model, sim_time_s) and self._stepped(model, sim_time_s):
            copy, self._step_owed = True, False
        elif self._write_unseen or self._step_owed:
            if model.time_s <= (sim_time_s if clock_s is None else clock_s) + GRID_SLACK_S:
                model.step_to(model.time_s + model.step_s)
                copy, self._step_owed = True, False
            else:
                copy, self._step_owed = self._write_unseen, True
        self._write_unseen = False
        if copy:
            self.write_back()

    def tick(self, sim_time_s: float) -> Iterator[None]:
        """:meth:`catch_up` in two pieces (step, then the copy), for a serving loop to interleave with packets
        (``sim_time_s``: the clock's present; the loop has no request lag)."""
        if self._deferred is not None:
            self.catch_up_deferred()
        model = self.firmware
        if not (step_due(model, sim_time_s) and self._stepped(model, sim_time_s)):
            if not ((self._write_unseen or self._step_owed) and model.time_s <= sim_time_s + GRID_SLACK_S):
                return
            model.step_to(model.time_s + model.step_s)
        writes = self._writes
        yield
        # The table shows the step from the copy on. A write handed over between the pieces came after the step:
        # it stays unseen, and earns a step of its own before the next request is answered (marked seen here, the
        # next read showed the old goal held). Cleared before the pause instead, a read between the pieces found
        # nothing due and was answered from the table the copy had not reached.
        self._step_owed = False
        self._write_unseen = self._writes != writes
        self.write_back()

    @staticmethod
    def _stepped(model: XServoModel, to_time_s: float) -> bool:
        """Step ``model`` to ``to_time_s``; whether it moved."""
        before = model.time_s
        model.step_to(to_time_s)
        return model.time_s > before

    def show_unstepped(self) -> None:
        """What :meth:`catch_up` does after a client's write while the model is ahead of the clock: the commands
        read back at once (the copy), the step owed for when the clock reaches the model's time.

        For a bus that took the write later than it came (``Bus2``'s held Sync Write): when it came the model
        was ahead, so the catch-up right after it would have copied and not stepped; the model has not
        stepped since, so the copy is the same, whenever it is taken.
        """
        if self._write_unseen:
            self._write_unseen = False
            self._step_owed = True
            self.write_back()

    def catch_up_deferred(self) -> None:
        """The catch-up a reply went out before, if any, at the times it was due (the model has not changed since)."""
        deferred = self._deferred
        if deferred is not None:
            self._deferred = None
            self.catch_up(*deferred)


class Plant2(SteppedPlant):
    """Runs ``firmware`` behind ``table``; brought to a time by the bus before each request."""

    def __init__(self, firmware: XServoModel, table: Table2) -> None:
        self.firmware = firmware
        self.table = table
        by_name = table.layout.by_name
        self._commands = [(name, by_name[name]) for name in XCommands.field_names() if name in by_name]
        self._sensed = []
        for field, candidates in SENSED_REGISTERS.items():
            present = [by_name[name] for name in candidates if name in by_name]
            if present:
                self._sensed.append((field, present[0]))
        self._command_names, self._read_commands = _reader([entry for _, entry in self._commands])
        # The registers of the frame and the torque (XFirmware.keeps_sensing), in that order (0 where the table has none).
        frame = [by_name[name] for name in _FRAME_REGISTERS if name in by_name]
        if len(frame) == len(_FRAME_REGISTERS):
            self._read_frame = _reader(frame)[1] if [e.name for e in sorted(frame, key=lambda e: e.address)] == list(
                _FRAME_REGISTERS) else (lambda row, frame=frame: tuple(entry.value_in(row) for entry in frame))
        else:
            self._read_frame = lambda row: None  # never equal: the commands are built in full
        # write_back runs every step of every servo: the sensed fields in one call, and where each goes.
        getter = operator.attrgetter(*(field for field, _ in self._sensed))  # Torque Enable at least (Table2 needs it)
        self._sense_fields = getter if len(self._sensed) > 1 else lambda sensed: (getter(sensed),)
        self._store_sensed = _writer([entry for _, entry in self._sensed])
        #: Goals the firmware holds instead of the table's (Bus Watchdog stop), or None.
        self._held: dict[str, int] | None = None
        #: A client changed the commands since the tables last showed a step (see :meth:`catch_up`).
        self._write_unseen = False
        #: The command registers last handed to the firmware, and the commands made of them (see :meth:`command`).
        self._commanded_values: tuple[int, ...] | None = None
        self._commanded: XCommands | None = None
        #: The table's bytes and the firmware's ``sensing_epoch`` as of the last :meth:`write_back` (see :meth:`defer_catch_up`).
        self._written_back_row = b""
        self._written_back_epoch: int | None = None
        #: The registers whose bytes a sensed value other than the trajectory ones lands in, and the trajectory ones'.
        self._steady_sensed = tuple((entry.address, entry.end) for field, entry in self._sensed if field not in TRAJECTORY_SENSED)
        self._trajectory_sensed = tuple((entry.address, entry.end) for field, entry in self._sensed if field in TRAJECTORY_SENSED)
        #: (address, length) -> the steady sensed registers' spans among those bytes, or None if a trajectory one is.
        self._spans: dict[tuple[int, int], tuple[tuple[int, int], ...] | None] = {}
        self.command()
        self.write_back()

    @property
    def held(self) -> bool:
        return self._held is not None

    def commands(self) -> XCommands:
        """The command registers as the firmware takes them (held goals in place of the table's)."""
        values = dict(zip(self._command_names, self._read_commands(self.table.row)))
        if self._held is not None:
            values.update(self._held)
        return XCommands(**values)

    def command(self, *, goal_written: bool = False) -> None:
        """Hand the model the table's commands now; the next request sees a step taken after them."""
        if self._deferred is not None:
            self.catch_up_deferred()
        values = self._read_commands(self.table.row)
        if self._held is not None or values != self._commanded_values:
            # A robot writes the same goals cycle after cycle: equal registers, the same (never mutated) object;
            # held goals are not the registers', so those commands are never reused.
            self._commanded_values = values if self._held is None else None
            self._commanded = self.commands()
        self.firmware.command(self._commanded, goal_written=goal_written)
        self._wrote()

    def hold(self) -> None:
        """Stop where the shaft is (Bus Watchdog): goal = present position, zero velocity, and zero PWM or current in the modes that take them as goals.

        Goal PWM (and Goal Current in Current-based Position mode) also cap the drive in the other
        modes; zeroing them there would leave the servo limp instead of stopped.
        """
        if self._deferred is not None:
            self.catch_up_deferred()
        present = self.table.get("present_position") if self.table.has("present_position") else 0
        # "When it stops, the Profile Acceleration(108) and Profile Velocity(112) are applied as '0'" (e-manual, Bus
        # Watchdog example): the stop is a step, not a ramp; the registers keep their values for the next goal.
        held = {"goal_velocity": 0, "goal_position": present, "profile_acceleration": 0, "profile_velocity": 0}
        mode = self.table.get("operating_mode") if self.table.has("operating_mode") else OperatingMode.POSITION
        if mode == OperatingMode.PWM:
            held["goal_pwm"] = 0
        elif mode == OperatingMode.CURRENT:
            held["goal_current"] = 0
        self._held = held
        self.command(goal_written=True)

    def release(self) -> None:
        """Take the table's goals again (called with a goal write, which then commands the model)."""
        if self._deferred is not None:
            self.catch_up_deferred()
        self._held = None

    # -- time: due, catch_up, tick (SteppedPlant) ----------------------------------------
    def write_back(self) -> None:
        """Copy what the firmware senses into the table (Torque Enable too, which Shutdown clears)."""
        if self._deferred is not None:
            self.catch_up_deferred()  # which writes back itself
        row = self.table.row
        self._store_sensed(row, self._sense_fields(self.firmware.sense()))
        self._written_back_row = bytes(row)
        self._written_back_epoch = getattr(self.firmware, "sensing_epoch", None)

    def sensed_spans(self, address: int, length: int) -> tuple[tuple[int, int], ...] | None:
        """The byte spans of the sensed registers among ``address``..``+length`` other than the trajectory ones,
        with Torque Enable and Hardware Error Status (which every packet's handling reads: the Bus Watchdog,
        the Alert bit); None if a trajectory register is among those bytes."""
        key = (address, length)
        spans = self._spans.get(key, _UNKNOWN)
        if spans is _UNKNOWN:
            end = address + length
            if any(start < end and address < stop for start, stop in self._trajectory_sensed):
                spans = None
            else:
                always = {self.table.layout.by_name[name].address for name in _READ_PER_PACKET if self.table.has(name)}
                spans = tuple((start, stop) for start, stop in self._steady_sensed
                              if (start < end and address < stop) or start in always)
            if len(self._spans) >= _MAX_SPANS:
                self._spans.clear()
            self._spans[key] = spans
        return spans

    def defer_catch_up(self, sim_time_s: float, clock_s: float, spans: tuple[tuple[int, int], ...]) -> bool:
        """Leave the catch-up a request owes for after its reply, if the reply provably cannot tell; True if left.

        Why: a robot's cycle sends a Sync Write and at once a Sync Read; the copy of the write's effects
        into six tables (``write_back``) before the read is answered is on the host's wait, and a read of,
        say, Present Position cannot see it.  Left only when the catch-up would not step the model (no
        step due by ``sim_time_s``, and the one a write earns would run past ``clock_s``), so all it
        would do is copy what the firmware senses; and that copy would leave every byte of ``spans``
        (see :meth:`sensed_spans`) as it is: the firmware's ``sensing_epoch`` has not moved since the last
        copy (so none of those values changed) and nobody wrote those bytes since.  The catch-up is taken
        later at the same times (``sim_time_s``, ``clock_s``) before anything else reaches the model, so
        the tables end as they would have.
        """
        if not self._unchanged_unless_stepped(sim_time_s, clock_s, spans):
            return False
        model = self.firmware
        if self._deferred is None:
            if not self._write_unseen or model.time_s <= clock_s + GRID_SLACK_S:
                return False  # nothing owed, or the write earns a step the read must see
        if self._deferred is None:
            self._deferred = (sim_time_s, clock_s)
        return True

    def _unchanged_unless_stepped(self, sim_time_s: float, clock_s: float, spans: tuple[tuple[int, int], ...]) -> bool:
        """No step due by ``sim_time_s`` nor owed by ``clock_s``, and a copy of what the firmware senses now would
        leave ``spans`` as they are."""
        model = self.firmware
        if step_due(model, sim_time_s) or self._step_owed and model.time_s <= clock_s + GRID_SLACK_S:
            return False  # a step is due: the read must see it
        if self._written_back_epoch is None or getattr(model, "sensing_epoch", None) != self._written_back_epoch:
            return False
        row, before = self.table.row, self._written_back_row
        for start, stop in spans:
            if row[start:stop] != before[start:stop]:
                return False
        return True

    def write_earns_step(self, clock_s: float) -> bool:
        """Whether a client's write now would earn a step of the model (:meth:`catch_up`: it is not ahead of ``clock_s``)."""
        return clock_s >= self.writes_earn_step_from_s()

    def writes_earn_step_from_s(self) -> float:
        """From which clock time on a client's write earns a step (:meth:`write_earns_step`), until the model moves."""
        return self.firmware.time_s - GRID_SLACK_S

    def goal_write_unseen_by(self, sim_time_s: float, clock_s: float, spans: tuple[tuple[int, int], ...]) -> bool:
        """Whether a write of Goal or profile registers (none of the frame's or the torque's) taken now, with
        the catch-up it earns, would leave ``spans`` (see :meth:`sensed_spans`) as they are: a read of them
        answered before it answers the same bytes as after it.

        True when no step is due by ``sim_time_s`` and the one the write earns would run past ``clock_s``
        (so the catch-up only copies what the firmware senses), that copy leaves ``spans`` as they are
        (as in :meth:`defer_catch_up`), and the firmware says the commands the write gives (the table's
        frame and torque registers, a goal written) change no sensed value but the trajectory ones.
        """
        if not self._unchanged_unless_stepped(sim_time_s, clock_s, spans):
            return False
        if self.write_earns_step(clock_s):
            return False  # the write would earn a step before the read
        model = self.firmware
        keeps_sensing = getattr(model, "keeps_sensing", None)
        if keeps_sensing is None:
            return False
        # The frame and torque registers are the table's whether or not goals are held (hold() replaces goals only).
        commands = self._commanded
        if commands is None or self._read_frame(self.table.row) != (
                commands.drive_mode, commands.operating_mode, commands.homing_offset, commands.torque_enable):
            commands = self.commands()
        return keeps_sensing(commands, goal_written=True)

    # -- instructions that reach the firmware ---------------------------------------------
    def reboot(self) -> None:
        """REBOOT: the model restarts; the table's RAM area returns to its defaults."""
        if self._deferred is not None:
            self.catch_up_deferred()
        self.firmware.reboot()
        self.table.ram_defaults()
        self._held = None
        self.write_back()
        self.command()

    def clear_multi_turn(self) -> None:
        """CLEAR option 0x01: the model drops Present Position's turn count."""
        if self._deferred is not None:
            self.catch_up_deferred()
        self.firmware.clear_multi_turn()
        self.write_back()


class ClassicPlant2(Plant2):
    """A classic table (the XL-320's) behind the X-series firmware: its registers go through a :class:`ClassicMap`.

    Why a subclass: the X tables' registers are the firmware's own and are copied by name (the fast
    path above); a classic table's mean the same things in other units, so each command and reading
    is translated.  A write to Moving Speed starts a new move as a Goal register write does (in joint
    mode the new speed takes over from where the trajectory is, as the X firmware's velocity override).
    """

    def __init__(self, firmware: XServoModel, table: Table2, classic: ClassicMap) -> None:
        self.classic = classic
        by_name = table.layout.by_name
        self._classic_names, self._read_classic = _reader([by_name[name] for name in classic.command_registers])
        self._classic_slots = [(name, by_name[name]) for name in classic.sensed_registers]
        self._last_values: dict[str, int] | None = None
        self._last_commands = XCommands()
        super().__init__(firmware, table)

    def commands(self) -> XCommands:
        values = dict(zip(self._classic_names, self._read_classic(self.table.row)))
        commands = self.classic.commands(values)
        if self._held is not None:
            commands = dataclasses.replace(commands, **self._held)
        return commands

    def command(self, *, goal_written: bool = False) -> None:
        values = dict(zip(self._classic_names, self._read_classic(self.table.row)))
        goal_written = goal_written or self.classic.goal_changed(self._last_values, values)
        self._last_values = values
        commands = self.classic.commands(values)
        if self._held is not None:
            commands = dataclasses.replace(commands, **self._held)
        self._last_commands = commands
        self.firmware.command(commands, goal_written=goal_written)
        self._wrote()

    def hold(self) -> None:
        """Stop where the shaft is: the firmware's own position (pulses) as the goal, and zero output in wheel mode."""
        held = {"goal_velocity": 0, "goal_position": self.firmware.sense().present_position}
        if self._last_commands.operating_mode == OperatingMode.PWM:
            held["goal_pwm"] = 0
        self._held = held
        self.command(goal_written=True)

    def write_back(self) -> None:
        registers = self.classic.sensed_to_registers(self.firmware.sense(), self._last_commands, self._last_values)
        row = self.table.row
        for name, entry in self._classic_slots:
            row[entry.address : entry.end] = entry.to_bytes(registers[name])


def plant_for(firmware: XServoModel, table: Table2, spec: ServoModel) -> Plant2:
    """The plant for a model's table: the X-series tables' own, or a classic table's (a ``[classic]`` section) translated."""
    if spec.classic is not None:
        return ClassicPlant2(firmware, table, ClassicMap.from_model(spec, step_s=firmware.step_s))
    return Plant2(firmware, table)
