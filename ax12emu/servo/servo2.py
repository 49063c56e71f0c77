"""One Protocol 2.0 servo's firmware state: its model's table, the registered write, the Bus Watchdog.

Why it exists: the Protocol 2.0 request handler and bus need what an X-series firmware keeps
between packets (ID, baud, Return Delay Time and Status Return Level read from its table, a Reg
Write waiting for Action, when it last heard an instruction, the stopped state of a Bus Watchdog
Error) and one place that writes the table with the firmware's side effects.  The model is data:
its table layout, model number, firmware version and baud rates come from its file
(:mod:`ax12emu.protocol.servo_models`); nothing here names a model.
"""

from __future__ import annotations

from dataclasses import dataclass

from ax12emu.protocol.packets2 import ErrorNumber
from ax12emu.protocol.registers import Area, Entry
from ax12emu.protocol.servo_models import ServoModel

from .plant2 import Plant2
from .table2 import Table2, WriteCheck
from .table_servo import TableServo

__all__ = ["BACKUP_RAM_PREFIX", "BACKUP_RAM_REGISTERS", "STARTUP_RAM_RESTORE", "STARTUP_TORQUE_ON", "GOAL_REGISTERS",
           "SECONDARY_ID_MAX", "Servo2", "Servo2Options", "WATCHDOG_ERROR", "WATCHDOG_UNIT_S"]

#: The Goal registers ("Goal Value": e-manual, X series, "Bus Watchdog(98)"); writing one starts a new profile.
GOAL_REGISTERS = frozenset({"goal_pwm", "goal_current", "goal_velocity", "goal_position"})
#: Bus Watchdog(98) reads -1 during a Bus Watchdog Error (stored as the byte 0xFF).
WATCHDOG_ERROR = 0xFF
#: Bus Watchdog(98)'s unit: 20 ms.
WATCHDOG_UNIT_S = 0.020
#: Goal registers a booting X-series firmware sets to the limit that bounds them (e-manual, X series,
#: "Goal PWM(100)" and "Goal Current(102)" take PWM Limit and Current Limit at power-up; without it a
#: default Goal PWM of 0 would allow no output at all); on the XL-320's classic table "When the power is turned
#: on, Torque Limit(35) is reset to the value of Max Torque(15)" (e-manual, _includes/en/dxl/control_table_torque_limit.md).
BOOT_GOALS = {"goal_pwm": "pwm_limit", "goal_current": "current_limit", "torque_limit": "max_torque"}
#: The RAM registers a Control Table Backup carries besides the EEPROM area ("Available items in Control Table for
#: data backup: All Data in EEPROM, Velocity P.I Gains, Position P.I.D Gains, Feedforward 1st & 2nd Gains, Profile
#: Acceleration, Profile Velocity, Indirect Addresses": e-manual, Protocol 2.0, Control Table Backup (0x20)); the
#: Indirect Addresses by their prefix.
BACKUP_RAM_REGISTERS = frozenset({"velocity_i_gain", "velocity_p_gain", "position_d_gain", "position_i_gain",
                                  "position_p_gain", "feedforward_2nd_gain", "feedforward_1st_gain",
                                  "profile_acceleration", "profile_velocity"})
BACKUP_RAM_PREFIX = "indirect_address_"
#: Startup Configuration(60)'s bits: "Bit 0 Startup Torque On ... [1] Torque On on startup (Torque Enable(64) is set
#: to 1)"; "Bit 1 RAM Restore ... [1] On startup, use the backup data to restore the RAM area" (e-manual, X series,
#: e.g. https://emanual.robotis.com/docs/en/dxl/x/xl430-w250/#startup-configuration60; firmware v45 on, v46 on X330).
STARTUP_TORQUE_ON, STARTUP_RAM_RESTORE = 0x01, 0x02
#: The highest active Secondary ID(12); 253..255 switch the function off.
SECONDARY_ID_MAX = 252
#: RAM registers whose write is not one :meth:`Servo2.writes_goals_only` lets through: what the bus reads per
#: packet (Status Return Level, the Bus Watchdog, Torque Enable), what the firmware acts on beyond the
#: motion (Torque Enable again), the registered-write bookkeeping and Lock; the Indirect Addresses and Data
#: are refused by their prefix (what Indirect Data reads depends on them).
QUIET_WRITE_REFUSED = frozenset({"torque_enable", "status_return_level", "bus_watchdog", "registered_instruction", "lock"})
#: ``refused`` of a write outside a Bus Watchdog Error.
_NOTHING_REFUSED: frozenset[str] = frozenset()
#: More distinct sets of registers written than a client uses; past it the remembered ones start over.
_MAX_WRITTEN = 256
#: Realtime Tick(120) counts milliseconds from 0 to 32767 and wraps (e-manual, "Realtime Tick(120)").
REALTIME_TICK_PERIOD = 32768


@dataclass(frozen=True)
class Servo2Options:
    """Behaviours where the e-manual is silent; defaults follow the documented reading."""

    #: A packet to this servo's ID with a wrong CRC is answered with CRC Error (3): the e-manual
    #: defines the error ("CRC of the sent Packet does not match"), so it is meant to be reported.
    #: False: silent.
    reply_on_crc_error: bool = True


def _byte_at(entry: Entry | None) -> int | None:
    """The address of a one-byte unsigned register, read as ``row[address]``; None for any other (or none)."""
    return entry.address if entry is not None and entry.size == 1 and not entry.signed else None


class Servo2(TableServo):
    """Firmware-side state of one Protocol 2.0 servo on the bus (ID, Return Delay Time, Status Return Level,
    the registered write: :class:`~.table_servo.TableServo`)."""

    def __init__(self, spec: ServoModel, plant_factory, *, servo_id: int, index: int,
                 options: Servo2Options = Servo2Options(), profile: str | None = None) -> None:
        self.require(spec, "2.0")
        if not spec.baud_rates_bps:
            raise ValueError(f"{spec.path}: a Protocol 2.0 model needs model.baud_rates_bps")
        super().__init__(spec, Table2(spec.layout(profile)), servo_id=servo_id, index=index, options=options)
        by_name = self.table.layout.by_name
        # More registers the bus consults on every packet, looked up once (None: the model has none):
        # a Sync Read or Write of six servos reads each of them for every servo.
        self._secondary = by_name.get("secondary_id")
        self._hardware_error = by_name.get("hardware_error_status")
        self._watchdog = by_name.get("bus_watchdog")
        self._tick = by_name.get("realtime_tick")
        # Where these one-byte registers are read straight from the row (None: the model has none, or they are wider).
        self._watchdog_at = _byte_at(self._watchdog)
        #: Realtime Tick's bytes in the row, and the millisecond count last written there with its bytes: a
        #: robot's Sync Read is heard by every servo several times within one millisecond.
        self._tick_span = (self._tick.address, self._tick.end) if self._tick is not None else None
        self._tick_ms: tuple[int, bytes] = (-1, b"")
        self._hardware_error_at = _byte_at(self._hardware_error)
        self._bauds_bps = tuple(float(bps) for bps in spec.baud_rates_bps)
        if spec.firmware_version is not None and self.table.has("firmware_version"):
            self.table.set("firmware_version", spec.firmware_version)
        #: Bus-clock time of the last instruction packet this servo heard (Bus Watchdog).
        self.last_instruction_s: float | None = None
        #: True while a packet addressed to the Secondary ID is handled: the EEPROM area is out of reach.
        self.ram_only = False
        #: id(entries) -> (entries, what they write): see :meth:`_what_is_written`.
        self._written: dict[int, tuple[tuple[Entry, ...], tuple[bool, bool, bool]]] = {}
        self.plant: Plant2 = plant_factory(self)
        self.power_on()

    # -- what the bus reads per packet (id, return_delay_s, status_return_level: TableServo) --
    @property
    def baud_bps(self) -> float:
        return self._bauds_bps[self.table.row[self._baud_at]]

    @property
    def secondary_id(self) -> int | None:
        """Secondary ID(12) when active (0..252), else None (e-manual: "253 or higher ... deactivated")."""
        if self._secondary is None:
            return None
        value = self._secondary.value_in(self.table.row)
        return value if value <= SECONDARY_ID_MAX else None

    @property
    def alert(self) -> bool:
        """The status packets' Alert bit: set while Hardware Error Status(70) is non-zero."""
        if self._hardware_error_at is not None:
            return self.table.row[self._hardware_error_at] != 0
        return self._hardware_error is not None and self._hardware_error.value_in(self.table.row) != 0

    def _watchdog_value(self) -> int:
        """Bus Watchdog(98)'s value (0 where the model has none)."""
        if self._watchdog_at is not None:
            return self.table.row[self._watchdog_at]
        return 0 if self._watchdog is None else self._watchdog.value_in(self.table.row)

    def start_at_baud(self, bps: float) -> None:
        """Set Baud Rate to the value whose rate is ``bps`` (a bus started at another rate than the factory's)."""
        rates = self.spec.baud_rates_bps
        if bps not in rates:
            raise ValueError(f"{self.spec.name} runs at {', '.join(map(str, rates))} bps, not {bps:.0f}")
        self.table.set("baud_rate", rates.index(int(bps)))

    # -- firmware events ------------------------------------------------------------------
    def power_on(self) -> None:
        """Power-up and reboot: Goal PWM/Current at their limits, Goal Position at Present Position, nothing registered.

        Why: a servo that boots holds where it is when the torque is turned on; clients that
        turn the torque off and on again see it move to the old Goal Position (reported by
        pollen-robotics/reachy_mini issue 1136), so only boot sets the goal, never Torque Enable.
        """
        table = self.table
        for goal, limit in BOOT_GOALS.items():
            if table.has(goal) and table.has(limit):
                table.set(goal, table.get(limit))
        if table.has("goal_position") and table.has("present_position"):
            low, high, _ = table.range_of(table.layout.by_name["goal_position"])
            table.set("goal_position", max(low, min(high, table.get("present_position"))))
        self.registered_write = None
        if table.has("registered_instruction"):
            table.set("registered_instruction", 0)
        if table.has("backup_ready"):  # the backup area outlives a reboot, so the firmware finds it again at boot
            table.set("backup_ready", int(self.backup is not None))
        startup = table.get("startup_configuration") if table.has("startup_configuration") else 0
        if startup & STARTUP_RAM_RESTORE and self.backup is not None:
            self.restore_ram(self.backup)
        if startup & STARTUP_TORQUE_ON:
            table.set("torque_enable", 1)  # the goal is Present Position (above): it holds where it booted
        self.plant.command()

    def restore_ram(self, backup: bytes) -> None:
        """The RAM registers a backup carries (:data:`BACKUP_RAM_REGISTERS` and the Indirect Addresses), from
        ``backup`` (the table's bytes when it was stored)."""
        table = self.table
        for entry in table.layout.entries:
            if entry.name in BACKUP_RAM_REGISTERS or entry.name.startswith(BACKUP_RAM_PREFIX):
                table.set(entry.name, entry.value_in(backup))

    @property
    def heard_span(self) -> tuple[int, int] | None:
        """The bytes :meth:`heard` writes (Realtime Tick: start, end), or None if the table has none."""
        tick = self._tick
        return None if tick is None else (tick.address, tick.end)

    def heard(self, now_s: float) -> None:
        """An instruction packet reached this servo at ``now_s`` (bus clock): the Bus Watchdog's interval restarts."""
        if self._watchdog_at is None or self.table.row[self._watchdog_at]:
            self.check_watchdog(now_s)  # (a Bus Watchdog of 0 is off: nothing to check)
        self.last_instruction_s = now_s
        span = self._tick_span
        if span is not None:  # as Table2.set does
            ms = int(now_s * 1000.0) % REALTIME_TICK_PERIOD
            known = self._tick_ms
            if known[0] != ms:
                known = self._tick_ms = (ms, self._tick.to_bytes(ms))
            self.table.row[span[0] : span[1]] = known[1]

    def check_watchdog(self, now_s: float) -> None:
        """Bus Watchdog(98): with the torque on, a silence longer than its value x 20 ms stops the servo.

        e-manual (X series, "Bus Watchdog(98)"): "If the measured communication interval (time)
        is larger than the set value of Bus Watchdog(98), the DYNAMIXEL will stop. Bus Watchdog(98)
        will be changed to '-1'", and the Goal registers become read-only until it is written 0.
        """
        deadline_s = self.watchdog_deadline_s()
        if deadline_s is not None and now_s > deadline_s:
            self.table.set("bus_watchdog", WATCHDOG_ERROR)
            self.plant.hold()

    def watchdog_deadline_s(self) -> float | None:
        """The time past which silence trips Bus Watchdog(98), while it is armed with the torque on; else None."""
        if self.last_instruction_s is None:
            return None
        value = self._watchdog_value()
        if not value:
            return None  # off, or no such register (the usual case: asked for every servo on every packet)
        if not 1 <= value < WATCHDOG_ERROR or not self.table.torque_on:
            return None
        return self.last_instruction_s + value * WATCHDOG_UNIT_S

    @property
    def watchdog_off(self) -> bool:
        """Bus Watchdog(98) is 0 (or the model has none): silence stops nothing, and an instruction's time is not measured."""
        return self._watchdog_value() == 0

    @property
    def watchdog_error(self) -> bool:
        return self._watchdog is not None and self._watchdog_value() == WATCHDOG_ERROR

    def judge_write(self, address: int, data: bytes) -> int:
        """The error number a write of ``data`` at ``address`` would get now, nothing written (a Reg Write is
        judged so when it is registered, as a Write would be)."""
        return self._checked(address, data)[1]

    def _checked(self, address: int, data: bytes) -> tuple[WriteCheck, int]:
        """The table's check of a client's write and its error number (this servo's refusals included)."""
        tripped = self.watchdog_error
        check = self.table.check_write(address, data, refused=GOAL_REGISTERS if tripped else _NOTHING_REFUSED)
        if check.error:
            return check, check.error
        if tripped and check.changes.get(self._watchdog_at, 0):
            # e-manual (X series, Bus Watchdog(98)): "If the value of Bus Watchdog(98) is changed to '0', Bus
            # Watchdog Error will be cleared"; 0 is the one value its table gives for it.  Stored, another value
            # cleared it too, and a reconnect that re-armed without writing 0 first passed here, not on a servo.
            return check, ErrorNumber.DATA_RANGE
        if self.ram_only and self._what_is_written(check.entries)[2]:
            return check, ErrorNumber.ACCESS  # "The EEPROM area ... cannot be modified with Secondary ID(12)"
        return check, ErrorNumber.NONE

    def write(self, address: int, data: bytes) -> int:
        """A client's write, all or nothing, with the firmware's side effects; returns the error number."""
        table = self.table
        check, error = self._checked(address, data)
        if error:
            return error
        mode_written, goal_written, eeprom = self._what_is_written(check.entries)
        mode_before = table.get("operating_mode") if mode_written else None
        table.apply(check)
        if mode_before is not None and table.get("operating_mode") != mode_before:
            self._mode_changed()
        if goal_written and self.plant.held and not self.watchdog_error:
            self.plant.release()
        if eeprom:
            self.eeprom_dirty = True
        self.plant.command(goal_written=goal_written)
        return ErrorNumber.NONE

    def writes_goals_only(self, address: int, length: int) -> bool:
        """Whether a write of ``length`` bytes at ``address`` can only store RAM registers that steer the motion
        (Goal, profile, gains, LED: :data:`QUIET_WRITE_REFUSED` aside) and fails on nothing but their values.

        Such a write changes nothing the bus reads to handle a packet (ID, baud, Return Delay Time, Status
        Return Level, the Bus Watchdog, Torque Enable, Hardware Error Status) and no sensed register, and
        its command keeps the frame and the torque: the bus may answer a read that reads none of its bytes
        before taking it (``Bus2``).
        """
        entries = self.table.registers_written(address, length)
        return entries is not None and not any(entry.name in QUIET_WRITE_REFUSED or entry.name.startswith("indirect_")
                                               for entry in entries)

    def _what_is_written(self, entries: tuple[Entry, ...]) -> tuple[bool, bool, bool]:
        """Whether ``entries`` hold Operating Mode, a Goal register, an EEPROM register.

        Remembered by the tuple's identity: a write of the same registers gets the same tuple from the
        table's plans (``Table2._plan``), and a robot writes the same ones every cycle.
        """
        known = self._written.get(id(entries))
        if known is not None and known[0] is entries:  # the tuple itself is kept, so its id is not reused meanwhile
            return known[1]
        names = {entry.name for entry in entries}
        facts = ("operating_mode" in names, bool(names & GOAL_REGISTERS),
                 any(entry.area is Area.EEPROM for entry in entries))
        if len(self._written) >= _MAX_WRITTEN:
            self._written.clear()
        self._written[id(entries)] = (entries, facts)
        return facts

    def _mode_changed(self) -> None:
        """Operating Mode(11) took a new value: the registers the model's ``[mode_change]`` names are reset.

        e-manual (XL430-W250, Operating Mode(11) NOTE): "When the value of the Operating Mode(11) register
        changes, the Velocity PI(76, 78); Position PID(80, 82, 84); Feedforward(88, 90), will be reset
        according to the selected Operating Mode(11) ... Profile Velocity(112) and Profile Acceleration(108)
        will be set to '0' ... Goal PWM(100) is reset to the value of PWM Limit(36)"; the models with a
        current loop add "Goal PWM(100), Goal Current(102) : Reset to PWM Limit(36), Current Limit(38)".
        """
        table, change = self.table, self.spec.mode_change
        defaults = table.layout.defaults
        for name in change.defaults:
            if table.has(name):
                table.set(name, table.layout.by_name[name].value_in(defaults))
        for name, source in change.from_registers:
            if table.has(name) and table.has(source):
                table.set(name, table.get(source))

    def factory_reset(self, keep: tuple[str, ...]) -> None:
        """FACTORY_RESET: every register to its default except ``keep``; the sensed registers stay the model's."""
        self.table.factory_defaults(keep)
        if self.spec.firmware_version is not None and self.table.has("firmware_version"):
            self.table.set("firmware_version", self.spec.firmware_version)  # the firmware's own, not a setting
        self.plant.release()
        self.plant.command()  # the firmware takes the defaults (torque off) before its registers are copied back
        self.plant.write_back()
        self.eeprom_dirty = True
        self.power_on()

    def reboot(self) -> None:
        """REBOOT: the firmware restarts with the EEPROM area kept (the plant clears the RAM area)."""
        self.plant.reboot()
        self.power_on()
