"""One MX-series servo on Protocol 1.0: its model's table, the registered write, the firmware's write rules.

Why it exists: the AX-12's 1.0 servo (:mod:`.virtual_servo`) lives in the bus's numpy rows of the
AX table's 50 bytes, under a batched plant; the MX series' Protocol 1.0 tables are longer (74
bytes), hold PID gains, goal acceleration, multi-turn offset, and run the X-series firmware model
(:mod:`.plant1x`).  This keeps one MX's state between packets on a :class:`~.table2.Table2`
(the layout from the model file, all-or-nothing write checks) and answers in Protocol 1.0's terms:
every write error is a status *bit* (:class:`~ax12emu.protocol.packets.StatusError`), not an error
number.  Nothing here names a model.

Write rules (ROBOTIS e-manual, "Protocol 1.0" > "Status Packet" > "Error",
https://emanual.robotis.com/docs/en/dxl/protocol1/#status-packet):

* "Range Error: When an instruction is out of the range for use": a byte past the table, an
  undefined or read-only address, a register written in part, a value outside its range, an EEPROM
  byte while Lock(47) is 1 ("Locking EEPROM"; only power-off releases it, as on the AX-12);
  Table2's Access, Data Length, Data Range and Data Limit errors all become this bit;
* "Angle Limit Error: When Goal Position is written out of the range from CW Angle Limit to CCW Angle
  Limit": in joint mode only (multi-turn mode takes -28,672..28,672, e-manual
  control_table_mx_goal_position.md; wheel mode ignores Goal Position); nothing is written, and with
  Shutdown's Angle Limit bit set "the motor's output will be 0 [%]" (Torque Limit 0, as an Alarm Shutdown);
* the EEPROM area is writable with the torque on (the Protocol 2.0 firmware's torque lock is not the
  1.0 firmware's; its Lock register freezes the EEPROM instead);
* Torque Limit(34) written non-zero after an Alarm Shutdown lets the motor run again
  (control_table_torque_limit.md); at power-up Torque Limit takes Max Torque(14) and Goal Position
  the Present Position (as on the AX-12, :func:`~.virtual_servo.power_on_1`).
"""

from __future__ import annotations

from dataclasses import dataclass

from ax12emu.protocol.packets import StatusError
from ax12emu.protocol.registers import Area
from ax12emu.protocol.servo_models import ServoModel

from .plant1x import Plant1X
from .request_handler import INSTRUCTION_SHUTDOWN_BITS
from .table2 import Table2
from .table_servo import TableServo
from .virtual_servo import power_on_1

__all__ = ["Servo1X", "Servo1XOptions", "baud_bps_1x"]
#: Baud Rate(4) 0..249 is 2,000,000 / (value + 1) bps; the MX pages add "For BPS over 250 values".
_HIGH_BAUDS_BPS = {250: 2_250_000.0, 251: 2_500_000.0, 252: 3_000_000.0}
#: Realtime Tick(50) counts milliseconds from 0 to 32,767 and wraps (e-manual, control_table_realtime_tick.md).
REALTIME_TICK_PERIOD = 32768


def baud_bps_1x(value: int) -> float:
    """Baud Rate(4) of an MX on Protocol 1.0 to bits per second (e-manual, MX-28 "Baud Rate (4)")."""
    return _HIGH_BAUDS_BPS.get(value, 2_000_000.0 / (value + 1))


@dataclass(frozen=True)
class Servo1XOptions:
    """Behaviours where the sources are silent; the defaults are the AX-12 bus's (``ServoOptions``)."""

    #: A packet with a wrong checksum is answered with the Checksum Error bit; False: silent.
    reply_on_checksum_error: bool = True
    #: PING to the broadcast ID is answered (replies of several servos collide); False: silent.
    reply_to_broadcast_ping: bool = True
    #: Writing Goal Position turns the torque on, as AX/MX client libraries' users and maintainers report
    #: (the sources are ``ServoOptions.goal_position_enables_torque``'s); False: Torque Enable stays.
    goal_position_enables_torque: bool = True


class _Table1X(Table2):
    """A Protocol 1.0 MX table: the torque does not lock the EEPROM (Lock(47) does, checked by the servo)."""

    @property
    def torque_on(self) -> bool:  # Table2 refuses EEPROM writes while this is True
        return False


class Servo1X(TableServo):
    """Firmware-side state of one MX-series servo on a Protocol 1.0 wire (ID, Return Delay Time, Status Return
    Level, the registered write: :class:`~.table_servo.TableServo`)."""

    def __init__(self, spec: ServoModel, plant_factory, *, servo_id: int, index: int,
                 options: Servo1XOptions = Servo1XOptions()) -> None:
        self.require(spec, "1.0")
        super().__init__(spec, _Table1X(spec.layout()), servo_id=servo_id, index=index, options=options)
        self._lock_writable = self.table.layout.profile.lock_writable
        #: Bus-clock time until which the servo ignores packets (kept for the bus's interface; MX writes are not timed).
        self.busy_until_s = float("-inf")
        self.plant: Plant1X = plant_factory(self)
        self.power_on()

    # -- what the bus reads per packet (id, return_delay_s, status_return_level: TableServo) --
    @property
    def baud_bps(self) -> float:
        return baud_bps_1x(self.table.row[self._baud_at])

    @property
    def baud_rates_bps(self) -> dict[int, float]:
        """Every Baud Rate value this servo's table takes (its model file's range) and the rate it runs at: up to
        3 Mbps at 252 (MX-106 e-manual, https://emanual.robotis.com/docs/en/dxl/mx/mx-106/: "Baud Rate |
        7,834 [bps] ~ 3 [Mbps]"), which the AX-12A's 2,000,000 / (value + 1) never reaches."""
        entry = self.table.layout.by_name["baud_rate"]
        return {value: baud_bps_1x(value) for value in range(entry.minimum, entry.maximum + 1)}

    @property
    def alarms(self) -> int:
        """The alarm bits every status packet carries (Input Voltage, Overheating, Overload)."""
        return self.plant.alarms

    def heard(self, now_s: float) -> None:
        """An instruction reached this servo: Realtime Tick(50) shows the time in ms."""
        if self.table.has("realtime_tick"):
            self.table.set("realtime_tick", int(now_s * 1000.0) % REALTIME_TICK_PERIOD)

    # -- firmware events ---------------------------------------------------------------------
    def power_on(self) -> None:
        """Power-up as on the AX-12 (:func:`~.virtual_servo.power_on_1`), then the firmware takes the commands."""
        power_on_1(self)
        self.plant.command()

    def reset(self) -> None:
        """RESET (0x06): the factory table (ID 1), the shaft where it is, the firmware restarted."""
        self.table.factory_defaults()
        self.plant.reboot()
        self.eeprom_dirty = True
        self.power_on()

    def reboot(self) -> None:
        """REBOOT (0x08, firmware V40 on): as a power cycle, the RAM area back to its defaults, the EEPROM kept, the
        firmware restarted with the shaft where it is."""
        self.table.ram_defaults()
        self.plant.reboot()
        self.power_on()

    def instruction_error(self, error: int) -> None:
        """An instruction's own error (Range, Checksum, Instruction): with its bit in Alarm Shutdown(18) the output goes
        to 0 through Torque Limit, as for every Alarm Shutdown ("the motor output becomes 0 % by resetting the value of
        Torque Limit(34) to 0", control_table_alarm_shutdown.md; :data:`~.request_handler.INSTRUCTION_SHUTDOWN_BITS`)."""
        table = self.table
        if int(error) & table.get("shutdown") & INSTRUCTION_SHUTDOWN_BITS and table.get("torque_limit"):
            table.set("torque_limit", 0)
            self.plant.command()

    def check_write(self, address: int, data: bytes) -> tuple[object | None, StatusError]:
        """Judge a write without applying it: (Table2's accepted check, NONE) or (None, the error bits)."""
        table = self.table
        end = address + len(data)
        if table.get("lock") and not (address in self._lock_writable and end - 1 in self._lock_writable):
            return None, StatusError.RANGE
        check = table.check_write(address, data)
        if check.error:
            return None, StatusError.RANGE
        goal = table.layout.by_name["goal_position"]
        if address < goal.end and end > goal.address:
            values = self._values_after(check.changes)
            classic = self.plant.classic
            if classic.is_multi_turn(values):
                signed = values["goal_position"] - 0x10000 if values["goal_position"] & 0x8000 else values["goal_position"]
                if abs(signed) > classic.units.multi_turn_goal_limit:
                    return None, StatusError.RANGE
            elif not classic.is_wheel(values) and not values.get("torque_ctrl_mode_enable", 0):
                if not values["cw_angle_limit"] <= values["goal_position"] <= values["ccw_angle_limit"]:
                    return None, StatusError.ANGLE_LIMIT
            if self.options.goal_position_enables_torque:
                torque = table.layout.by_name["torque_enable"]
                check.changes[torque.address] = 1
                check.entries = tuple(sorted({*check.entries, torque}, key=lambda entry: entry.address))
        return check, StatusError.NONE

    def write(self, address: int, data: bytes) -> StatusError:
        """A client's write, all or nothing, with the firmware's side effects; returns the error bits."""
        check, error = self.check_write(address, data)
        if check is None:
            if error & StatusError.ANGLE_LIMIT and self.table.get("shutdown") & StatusError.ANGLE_LIMIT:
                # "providing that Angle Limit Error Bit(0x01) in Alarm LED/Shutdown is set, ... the motor's output
                # will be 0 [%]" (control_table_mx_goal_position.md; the bit is the status packet's, 0x02)
                self.table.set("torque_limit", 0)
                self.plant.command()
            return error
        table = self.table
        torque_limit_before = table.get("torque_limit")
        lock = table.layout.by_name["lock"]
        if table.get("lock") and lock.address in check.changes and not check.changes[lock.address]:
            return StatusError.RANGE  # Lock is released only by power-off (e-manual, Lock)
        table.apply(check)
        names = {entry.name for entry in check.entries}
        if any(entry.area is Area.EEPROM for entry in check.entries):
            self.eeprom_dirty = True
        if "torque_limit" in names and table.get("torque_limit") and not torque_limit_before:
            self.plant.torque_limit_written()
        self.plant.command(goal_written=bool(names & self.plant.classic.goal_registers))
        return StatusError.NONE

    def _values_after(self, changes: dict[int, int]) -> dict[str, int]:
        """The registers a mode check reads, as the table would hold them after the write."""
        image = bytearray(self.table.row)
        for at, byte in changes.items():
            image[at] = byte
        by_name = self.table.layout.by_name
        names = ("goal_position", "cw_angle_limit", "ccw_angle_limit", "torque_ctrl_mode_enable")
        return {name: by_name[name].value_in(image) for name in names if name in by_name}
