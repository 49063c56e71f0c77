"""One virtual servo's protocol state: control table, options, alarms, registered write.

Why it exists: the request handler needs a small object holding what a real
servo's firmware holds between packets, and the bus needs to know a servo's
ID, baud and return delay without knowing the table's layout.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ax12emu.protocol.control_table import DEFAULT_PROFILE, PROFILES, ControlTable, Layout

__all__ = ["EEPROM_BUSY_MAX_S", "ServoOptions", "VirtualServo", "baud_bps", "power_on_1"]


def power_on_1(servo) -> None:
    """Protocol 1.0 power-up rules, the AX-12's and the MX series' firmware alike: Torque Limit loads
    Max Torque (e-manual, the Torque Limit entry of both), Goal Position follows Present Position,
    nothing registered."""
    table = servo.table
    table.set("torque_limit", table.get("max_torque"))
    table.set("goal_position", table.get("present_position"))
    table.set("registered", 0)
    servo.registered_write = None


def baud_bps(value: int) -> float:
    """Baud Rate register to bits per second: 2,000,000 / (value + 1) (e-manual, Baud Rate)."""
    return 2_000_000.0 / (value + 1)

#: The longest EEPROM pause per byte a servo may be given: far past the measured 6 ms, and still a servo that answers.
EEPROM_BUSY_MAX_S = 1.0


@dataclass(frozen=True)
class ServoOptions:
    """Behaviours where the sources are silent or disagree; defaults follow the documented one."""

    #: Control-table profile: "ax12a" (e-manual) or "ax12-2006" (2006 User's Manual).
    profile: str = DEFAULT_PROFILE
    #: A packet with a wrong checksum gets a status packet with the Checksum Error
    #: bit (the e-manual defines the bit, so it is meant to be reported); False:
    #: stay silent, as some firmware is reported to do.
    reply_on_checksum_error: bool = True
    #: PING to the broadcast ID is answered (2006 manual: "regardless of whether
    #: the Broadcasting ID is used ... a Status Packet is always returned by the
    #: PING instruction"); with several servos the replies collide.  False: silent.
    reply_to_broadcast_ping: bool = True
    #: RESET's status packet comes from the ID the packet was sent to (e-manual
    #: example: RESET to ID 0 answered by ID 0); True: from the new ID 1.
    reset_reply_from_new_id: bool = False
    #: Writing Goal Position (or, on the AX series, Moving Speed) turns the torque on (Torque Enable becomes 1).  The
    #: e-manual's Torque Enable and Goal Position entries say nothing of it, but
    #: users and maintainers of AX/MX client libraries report it: pypot's author
    #: (Luos-io/Examples PR #17, "the goal position should only be set when the
    #: compliance is turned off, otherwise it will turn the motor back stiff"),
    #: poppy-docs issue #36 (after setting a goal position the motor "is no longer
    #: compliant") and pypot issue #121 (a goal sent to compliant motors makes them
    #: twitch until the library turns torque off again).  On the AX series writing
    #: Moving Speed does it too: Luos-io/Pyluos issue #59 ("When doing the same
    #: operation on a AX motors, it turn the motor stiff"; on MX motors it does not;
    #: its maintainer: "a feature from dynamixel"), and pyax12's wheel example turns
    #: the shaft with CW/CCW Angle Limit 0 and a Moving Speed write alone.  False:
    #: torque stays off.
    goal_position_enables_torque: bool = True
    #: Seconds the servo ignores every packet (stays silent, acts on nothing) per
    #: byte written into the EEPROM area, counted from the write.  xevelabs' USB2AX
    #: protocol notes (https://www.xevelabs.com/doku.php?id=product:usb2ax:dynamixel_protocol_notes,
    #: "Timing"): a write to EEPROM is answered as usual, "but then the servo will not
    #: answer to another command before many milliseconds (up to 9 ms per byte based
    #: on the ATMega8 datasheet, though experimental verification put it at around
    #: 6 +/-1 ms per byte)".  0: answer at once.
    eeprom_busy_s_per_byte: float = 0.006

    def __post_init__(self) -> None:
        if self.profile not in PROFILES:
            raise ValueError(f"unknown profile {self.profile!r}; choose one of: {', '.join(PROFILES)}")
        if not 0.0 <= self.eeprom_busy_s_per_byte <= EEPROM_BUSY_MAX_S:  # also refuses NaN
            raise ValueError(f"eeprom_busy_s_per_byte must lie in 0..{EEPROM_BUSY_MAX_S:g} s, got {self.eeprom_busy_s_per_byte!r}")


class VirtualServo:
    """Firmware-side state of one AX-12 on the bus."""

    def __init__(self, table: ControlTable, options: ServoOptions, *, index: int) -> None:
        self.table = table
        self.options = options
        by_name = table.layout.by_name
        # Read on every packet: the addresses are looked up once, by name.
        self._id_at = by_name["id"].address
        self._baud_rate_at = by_name["baud_rate"].address
        self._return_delay_at = by_name["return_delay_time"].address
        self._status_return_level_at = by_name["status_return_level"].address
        #: Position in the bus's arrays (rows, model state), fixed for life.
        self.index = index
        #: Physical alarm bits raised by the model (voltage, overheating, overload).
        self.alarms = 0
        #: The REG_WRITE waiting for ACTION: (address, data), or None.
        self.registered_write: tuple[int, bytes] | None = None
        #: Set when a write changed the EEPROM area; the bus persists and clears it.
        self.eeprom_dirty = False
        #: Bytes written into the EEPROM area by the packet being handled; the bus turns
        #: them into :attr:`busy_until_s` (see ``ServoOptions.eeprom_busy_s_per_byte``) and clears them.
        self.eeprom_bytes_written = 0
        #: Bus-clock time until which the servo is writing its EEPROM and ignores packets.
        self.busy_until_s = float("-inf")

    @classmethod
    def fresh(cls, servo_id: int, options: ServoOptions, *, index: int, row: np.ndarray | None = None,
              table_layout: Layout | None = None) -> "VirtualServo":
        """A servo at factory defaults with its ID set; ``table_layout``: another 1.0 model's table than the profile's."""
        servo = cls(ControlTable(row, profile=options.profile, table_layout=table_layout), options, index=index)
        servo.table.set("id", servo_id)
        return servo

    @property
    def id(self) -> int:
        """Present ID."""
        return int(self.table.row[self._id_at])

    @property
    def baud_bps(self) -> float:
        """The rate this servo listens and talks at."""
        return baud_bps(int(self.table.row[self._baud_rate_at]))

    @property
    def baud_rates_bps(self) -> dict[int, float]:
        """Every Baud Rate value this servo's table takes (its model file's range) and the rate it runs at, so a
        bus started at another rate than the factory's asks the servo rather than assuming the AX-12A's."""
        entry = self.table.layout.by_name["baud_rate"]
        return {value: baud_bps(value) for value in range(entry.minimum, entry.maximum + 1)}

    @property
    def return_delay_s(self) -> float:
        """Return Delay Time in seconds: 2 us per unit (e-manual)."""
        return int(self.table.row[self._return_delay_at]) * 2e-6

    @property
    def status_return_level(self) -> int:
        """0: answer PING only; 1: PING and READ; 2: everything (e-manual)."""
        return int(self.table.row[self._status_return_level_at])

    #: Power-up rules (:func:`power_on_1`).
    power_on = power_on_1
