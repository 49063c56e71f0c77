"""The adapter between an MX-series Protocol 1.0 control table and the X-series firmware model.

Why it exists: the MX series (MX-28, MX-64, MX-106 with their Protocol 1.0 firmware) is the X
series' PID predecessor: a 4096-pulse magnetic encoder, a position PID, speed and acceleration
limits on the way to a goal, a speed loop in wheel mode and (MX-64/106) a current loop.  So an MX is
the X-series firmware model (:mod:`firmware_model.xseries`) behind a different table: the registers
go through the model file's ``[classic]`` numbers (:class:`~.classic.ClassicMap`: units, gains, wheel,
multi-turn and torque control modes, goal acceleration), and this is the one place that knows both
the table and the model's seam, as :mod:`.plant2` is for the X series.

What the Protocol 1.0 firmware adds here (ROBOTIS e-manual, MX-28 page and its shared texts in
github ROBOTIS-GIT/emanual _includes/en/dxl/):

* The status packet's alarm bits are conditions, not latched errors: "Input Voltage Error: When the
  applied voltage is out of the range of operating voltage set in the Control table", "OverHeating
  Error: When the internal temperature is out of the range of operating temperature", "Overload Error:
  When the current load cannot be controlled with the set maximum torque" (control_table_alarm_shutdown.md,
  the same text as the AX-12A's). So every status packet carries the conditions present now, whatever
  Alarm Shutdown(18) selects, as on the AX-12A beside it on the wire (``ax12emu.servo.plant``): the
  X-series firmware model's ``present_errors``.
* Alarm Shutdown acts through Torque Limit: "If the function of Alarm LED(17)/Shutdown(18) is triggered,
  the motor loses its torque because Torque Limit(34) becomes 0. Once error conditions are resolved and
  Torque Limit(34) is changed to the value other than 0, the motor can be operated again"
  (control_table_torque_limit.md). The firmware model runs with ``shutdown_cuts_output``: an error
  Shutdown selects cuts its output at the step it is detected (not latched, torque not turned off), the
  copy shows Torque Limit 0, and a Torque Limit written non-zero restores the output; a condition still
  present cuts it again at the next step. Torque Enable stays the client's.
* With the output cut the firmware cannot judge the load, so an Overload that cut it stays in the status
  packets until Torque Limit is written non-zero, as the AX-12A's does while its shaft is held off its
  goal with no torque to reach it.
"""

from __future__ import annotations

from ax12emu.protocol.servo_models import ServoModel
from firmware_model.xseries.interface import XCommands, XServoModel

from .classic import ClassicMap
from .plant2 import SteppedPlant
from .table2 import Table2

__all__ = ["Plant1X", "build_plant1x"]


class Plant1X(SteppedPlant):
    """Runs ``firmware`` (an X-series model) behind an MX table through ``classic``; brought to a time by the bus."""

    def __init__(self, firmware: XServoModel, table: Table2, classic: ClassicMap) -> None:
        self.firmware = firmware
        self.table = table
        self.classic = classic
        by_name = table.layout.by_name
        self._command_entries = [(name, by_name[name]) for name in classic.command_registers]
        # Torque Enable stays the client's on Protocol 1.0 (a shutdown acts through Torque Limit: module docstring).
        self._sensed_entries = [(name, by_name[name]) for name in classic.sensed_registers if name != "torque_enable"]
        self._values: dict[str, int] = {}
        self._commands = XCommands()
        self._write_unseen = False
        #: The status packets' alarm bits at the last copy (Protocol 1.0 bits).
        self._alarms = 0
        self.command()
        self.write_back()

    # -- table -> firmware -----------------------------------------------------------------
    def values(self) -> dict[str, int]:
        """The command registers as the table holds them, by name."""
        row = self.table.row
        return {name: entry.value_in(row) for name, entry in self._command_entries}

    def command(self, *, goal_written: bool = False) -> None:
        """Hand the model the table's commands now; the next request sees a step taken after them."""
        values = self.values()
        goal_written = goal_written or self.classic.goal_changed(self._values or None, values)
        self._values = values
        self._commands = self.classic.commands(values)
        self.firmware.command(self._commands, goal_written=goal_written)
        self._wrote()

    # -- time: due, catch_up, tick (SteppedPlant); firmware -> table ------------------------
    def write_back(self) -> None:
        """Copy what the firmware senses into the table; an output cut by Alarm Shutdown shows as Torque Limit 0."""
        firmware = self.firmware
        sensed = firmware.sense()
        registers = self.classic.sensed_to_registers(sensed, self._commands, self._values)
        row = self.table.row
        for name, entry in self._sensed_entries:
            row[entry.address : entry.end] = entry.to_bytes(registers[name])
        self._alarms = self.classic.errors_to_classic(firmware.present_errors)
        if firmware.cut_errors and self.table.get("torque_limit"):
            self.table.set("torque_limit", 0)
            self.command()  # the table and the firmware agree: no output until the client writes it

    @property
    def alarms(self) -> int:
        """The status packets' alarm bits now: the conditions present, as Protocol 1.0 bits."""
        return self._alarms

    def torque_limit_written(self) -> None:
        """Torque Limit written non-zero: the output cut by an Alarm Shutdown comes back (module docstring)."""
        if self.firmware.cut_errors:
            self.firmware.restore_output()
            self.write_back()

    def reboot(self) -> None:
        """Power-up (RESET): the firmware restarts; the servo has put the table back."""
        self.firmware.reboot()  # which clears a cut output too
        self._values = {}
        self.write_back()
        self.command()


def build_plant1x(spec: ServoModel, table: Table2, choice=None) -> Plant1X:
    """One MX's plant from its model file: the X-series firmware from the data sheet (``build_x_firmware``) and
    the ``[classic]`` map; ``ValueError`` with the reason when the file cannot give one."""
    from .model_factory2 import XModelChoice, build_x_firmware

    firmware = build_x_firmware(spec, choice if choice is not None else XModelChoice())
    firmware.shutdown_cuts_output = True  # Protocol 1.0's Alarm Shutdown (module docstring)
    firmware.overload_by_current = False  # Protocol 1.0's Overload: the output at its limit, the load winning
    firmware.single_turn_position = True  # joint mode works within one turn (multi-turn mode is Extended Position)
    return Plant1X(firmware, table, ClassicMap.from_model(spec, step_s=firmware.step_s))
