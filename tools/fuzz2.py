"""Fuzz the Protocol 2.0 bus, and a wire shared by Protocol 1.0 and 2.0 servos, with an oracle checked per packet.

The Protocol 1.0 fuzzer (``tools/fuzz.py``) feeds an AX-12 bus; this one feeds
:class:`ax12emu.bus.bus2.Bus2` (an XL430-W250, an XM430-W350, an XL330-M077 and
an XL-320) or :class:`ax12emu.bus.mixed.MixedBus` (two AX-12As and three of those
on one wire), in virtual time, with the real X-series firmware models behind them.
The XL-320 keeps the classic table (the AX series' registers at other addresses)
on the X firmware: the oracle reads every table by its layout and finds registers
by name, so a check of a register a table lacks (Secondary ID, Bus Watchdog,
indirect addresses, Backup Ready, Drive Mode) is skipped for that servo, and a
power-up's goals are checked against the limits the table has (Goal PWM and Goal
Current on the X series, Torque Limit taking Max Torque on the XL-320).

Generation is structure-aware: valid 2.0 instruction packets of every
instruction (Ping, Read, Write, Reg Write, Action, Factory Reset, Reboot, Clear,
Control Table Backup, Sync/Bulk Read and Write and their fast forms, undefined
codes, other devices' status packets), whose addresses and values come from the
models' control tables (whole registers, parts of them, spans, values in and
out of range, the header pattern ``FF FF FD`` inside data so stuffing is
exercised); then mutated ones (a flipped bit, a wrong CRC, LENGTH or reserved
byte, a cut, a stuffing byte dropped or added with the CRC made right again, an
ID of 0xFD/0xFF/broadcast/absent, repeated header bytes, junk inside, two
packets glued, a Protocol 1.0 packet inside); Protocol 1.0 packets (the 1.0
fuzzer's grammar) and raw garbage.  The stream is cut into chunks fed at random
boundaries, sometimes after a pause longer than the framers' silence timeout,
sometimes after a physics step.

The oracle sees every 2.0 packet the bus's framer completes (the bus's
``dispatch`` is wrapped: the tables are copied before and after each packet)
and checks, with code of its own (CRC, stuffing, the control table's rules read
from the model files):

* no exception, at most ``HANG_S`` of CPU time per chunk, the framers hold less than one
  maximal frame plus the chunk;
* each packet the framer hands on is in the bytes fed, with a right CRC over
  them (or flagged as corrupt), and a whole valid packet sent after a pause is
  never lost;
* every reply is a well-formed 2.0 status packet (header, LENGTH, CRC,
  stuffing, instruction 0x55, an error number the e-manual defines, the Alert
  bit as Hardware Error Status says) from the servo expected, or a Fast
  Sync/Bulk Read's combined status (ID 0xFE, unstuffed, each share's running
  CRC right; servos sharing a listed ID send the header and their shares at
  once, AND-ed on the wire, and the servos after them run the CRC on over the
  collided bytes), with the error number the e-manual's rules give (CRC 3,
  Instruction 2, Result Fail 1 for a malformed packet, Access 7 / Data Length
  5 / Data Range 4 / Data Limit 6 for writes, judged on the table before the
  packet), in the order and at the delays the bus documents;
* who answers: the addressed servos that hear the line's rate, as Status
  Return Level allows; for broadcast Ping every servo in ID order; for the
  listed reads the listed servos in list order up to the first that cannot;
  nobody for a broadcast Read, a corrupt broadcast, a Sync/Bulk instruction
  sent to one ID, a packet to a Secondary ID, a status packet;
* the tables afterwards are exactly what the rules give: a write that got no
  error holds its bytes (through the indirect addresses), a refused one
  changed nothing, EEPROM bytes never change while the torque is on (but by
  Factory Reset or a backup restore), Reboot keeps EEPROM and resets RAM,
  Factory Reset resets all but what its option keeps, Reg Write/Action and the
  backup behave as documented; between packets only the firmware's registers
  (the sensed ones, Realtime Tick, Bus Watchdog's -1, Torque Enable cleared by
  a shutdown) change;
* at the end of each case, after a pause, every X-series servo answers a Ping,
  and a Read of its whole table equals the table;

and on a mixed wire the Protocol 1.0 servos are checked by the 1.0 fuzzer's
oracle (``fuzz.Oracle``) against the same stream.

Usage::

    python tools/fuzz2.py --inputs 1000000               # the full run, both buses
    python tools/fuzz2.py --bus mixed --seconds 10       # a quick one on the mixed wire
    python tools/fuzz2.py --replay fuzz2-failure.json    # rerun a reported failure
"""

from __future__ import annotations

import collections
import dataclasses
import importlib.util
import io
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: Modules the target exercises, for the coverage figure.
TARGET_MODULES = ("protocol/framing2", "protocol/packets2", "protocol/params2", "protocol/crc16", "servo/table2",
                  "servo/servo2", "servo/request_handler2", "servo/plant2", "bus/bus2", "bus/mixed")


sys.path.insert(0, str(Path(__file__).resolve().parent))
from fuzz_coverage import start_coverage  # noqa: E402  (imports nothing of ax12emu)

_COVERAGE = start_coverage(TARGET_MODULES, sys.argv) if __name__ == "__main__" else None


def _load_fuzz1() -> Any:
    """The Protocol 1.0 fuzzer (its choosers, 1.0 grammar and oracle), loaded once under the test kit's name."""
    name = "ax12emu_tool_fuzz"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parent / "fuzz.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


fuzz1 = _load_fuzz1()


from ax12emu.bus.bus import Bus  # noqa: E402
from ax12emu.bus.bus2 import Bus2  # noqa: E402
from ax12emu.bus.clock import VirtualClock  # noqa: E402
from ax12emu.bus.mixed import MixedBus  # noqa: E402
from ax12emu.cli.arg_types import OneLineParser, file_name, positive_float, positive_int  # noqa: E402
from ax12emu.protocol.framing import Framer  # noqa: E402
from ax12emu.protocol.framing2 import DEFAULT_MAX_LENGTH, DEFAULT_SILENCE_TIMEOUT_S  # noqa: E402
from ax12emu.protocol.packets import BROADCAST_ID, Instruction  # noqa: E402
from ax12emu.protocol.packets2 import InstructionPacket2, StatusPacket2  # noqa: E402
from ax12emu.protocol.registers import Access, Area  # noqa: E402
from ax12emu.protocol.servo_models import model  # noqa: E402
from ax12emu.servo.model_factory import ModelChoice, build_model  # noqa: E402
from ax12emu.servo.model_factory2 import build_x_firmware  # noqa: E402
from ax12emu.servo.servo2 import Servo2Options  # noqa: E402
from ax12emu.servo.virtual_servo import ServoOptions  # noqa: E402

FuzzFailure = fuzz1.FuzzFailure
#: What the oracle checked, over the run: (instruction, error number or "silent"/"fast") -> packets.
CHECKED: collections.Counter = collections.Counter()
#: Replies (and shares of combined ones) the oracle checked, by servo model: model name -> replies.
CHECKED_MODELS: collections.Counter = collections.Counter()
#: One chunk taking longer than this counts as a hang.
HANG_S = 2.0
PAUSE_S = max(DEFAULT_SILENCE_TIMEOUT_S, fuzz1.DEFAULT_SILENCE_TIMEOUT_S) * 1.5
#: The buses: X-series servos by ID and model; on the mixed wire AX-12As beside them (IDs are per protocol).
#: The XL-320 has the classic table (the AX series' registers at other addresses) on the X firmware.
BUS2_SERVOS = ((1, "xl430-w250"), (2, "xm430-w350"), (3, "xl330-m077"), (4, "xl-320"))
MIXED_SERVOS2 = ((1, "xl430-w250"), (3, "xl330-m077"), (4, "xl-320"))
MIXED_IDS1 = (1, 2)
#: Every servo starts at 1 Mbps, the AX-12A's rate, so one line rate reaches both protocols.
LINE_BPS = 1_000_000

# -- Protocol 2.0 as the oracle knows it (e-manual "DYNAMIXEL Protocol 2.0"; written here, not imported) --
HEADER = b"\xff\xff\xfd\x00"
STATUS = 0x55
PING, READ, WRITE, REG_WRITE, ACTION, FACTORY_RESET, REBOOT, CLEAR, BACKUP = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x08, 0x10, 0x20
SYNC_READ, SYNC_WRITE, FAST_SYNC_READ, BULK_READ, BULK_WRITE, FAST_BULK_READ = 0x82, 0x83, 0x8A, 0x92, 0x93, 0x9A
#: Error numbers ("Status Packet > Error"): 1 Result Fail .. 7 Access.
RESULT_FAIL, INSTRUCTION_ERROR, CRC_ERROR, DATA_RANGE, DATA_LENGTH, DATA_LIMIT, ACCESS = range(1, 8)
READS = frozenset({READ, SYNC_READ, BULK_READ, FAST_SYNC_READ, FAST_BULK_READ})
LISTED = frozenset({SYNC_READ, BULK_READ, FAST_SYNC_READ, FAST_BULK_READ})
#: Sync/Bulk instructions: executed only when sent to the broadcast ID ("Packet ID field : 0xFE").
BROADCAST_ONLY = LISTED | {SYNC_WRITE, BULK_WRITE}
EXECUTED = frozenset({PING, READ, WRITE, REG_WRITE, ACTION, FACTORY_RESET, REBOOT, CLEAR, BACKUP, SYNC_WRITE, BULK_WRITE})
CLEAR_KEY, BACKUP_KEY = b"DXL\x22", b"CTRL"
GOALS = frozenset({"goal_pwm", "goal_current", "goal_velocity", "goal_position"})
#: Registers a power-up sets (goals at their limits and at Present Position): not compared after a reboot,
#: each of the first set checked against the limit it takes (a classic table's Torque Limit takes Max Torque:
#: e-manual, _includes/en/dxl/control_table_torque_limit.md).
BOOT_LIMITS = {"goal_pwm": "pwm_limit", "goal_current": "current_limit", "torque_limit": "max_torque"}
BOOT_SET = frozenset({*BOOT_LIMITS, "goal_position"})
#: Registers the firmware writes (what it senses); Torque Enable is checked on its own.
SENSED = frozenset({"present_position", "present_velocity", "present_current", "present_load", "present_pwm",
                    "velocity_trajectory", "position_trajectory", "moving", "moving_status",
                    "present_input_voltage", "present_temperature", "hardware_error_status",
                    "present_speed", "present_voltage"})  # the last two: a classic table's (XL-320)
KEEPS = {0xFF: (), 0x01: ("id",), 0x02: ("id", "baud_rate")}
#: The RAM registers a Control Table Backup holds (e-manual, Protocol 2.0, "Available items in Control Table for
#: data backup"), and the Indirect Addresses: what Startup Configuration's RAM Restore brings back at boot.
BACKUP_RAM = frozenset({"velocity_i_gain", "velocity_p_gain", "position_d_gain", "position_i_gain", "position_p_gain",
                        "feedforward_2nd_gain", "feedforward_1st_gain", "profile_acceleration", "profile_velocity"})
#: What Factory Reset never resets: what the servo is (the X series keeps them in bytes 0..6).
IDENTITY = ("model_number", "model_information", "firmware_version")


def _crc_table() -> list[int]:
    table = []
    for index in range(256):
        crc = index << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else crc << 1
        table.append(crc & 0xFFFF)
    return table


_CRC = _crc_table()


def crc(data: bytes, value: int = 0) -> int:
    """CRC-16 of the e-manual's "CRC Calculation" (poly 0x8005, MSB first, init 0)."""
    for byte in data:
        value = ((value << 8) & 0xFFFF) ^ _CRC[((value >> 8) ^ byte) & 0xFF]
    return value


def stuff(payload: bytes) -> bytes:
    """An FD after each FF FF FD of the unstuffed INST + parameters."""
    out = bytearray()
    for index, byte in enumerate(payload):
        out.append(byte)
        if byte == 0xFD and index >= 2 and payload[index - 2] == 0xFF and payload[index - 1] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def unstuff(payload: bytes, strict: bool) -> bytes | None:
    """Drop the FD after each FF FF FD; with ``strict`` a missing one is None (stuffing wrong)."""
    out = bytearray()
    index = 0
    while index < len(payload):
        out.append(payload[index])
        if len(out) >= 3 and out[-1] == 0xFD and out[-2] == 0xFF and out[-3] == 0xFF:
            if index + 1 < len(payload) and payload[index + 1] == 0xFD:
                index += 1
            elif strict:
                return None
        index += 1
    return bytes(out)


def frame(packet_id: int, payload: bytes, *, stuffed: bool = True) -> bytes:
    """Header, ID, LENGTH, payload (stuffed unless told), CRC: any ID, unchecked (the fuzzer sends bad ones too)."""
    body = stuff(payload) if stuffed else payload
    head = HEADER + bytes((packet_id, (len(body) + 2) & 0xFF, (len(body) + 2) >> 8)) + body
    return head + crc(head).to_bytes(2, "little")


def parse_status(data: bytes, where: str) -> tuple[int, int, bytes]:
    """(ID, error byte, parameters) of one status packet, or FuzzFailure naming what is wrong."""
    if len(data) < 11 or data[:4] != HEADER:
        raise FuzzFailure(f"{where}: malformed status packet {data.hex()}")
    if (data[5] | data[6] << 8) + 7 != len(data):
        raise FuzzFailure(f"{where}: LENGTH of {data.hex()} is not its size")
    if crc(data[:-2]) != data[-2] | data[-1] << 8:
        raise FuzzFailure(f"{where}: bad CRC in status packet {data.hex()}")
    payload = unstuff(data[7:-2], strict=True)
    if payload is None or stuff(payload) != data[7:-2]:
        raise FuzzFailure(f"{where}: stuffing wrong in status packet {data.hex()}")
    if payload[0] != STATUS or not 0 <= data[4] <= 0xFC:
        raise FuzzFailure(f"{where}: {data.hex()} is not a status packet from a servo ID")
    if payload[1] & 0x7F > ACCESS:
        raise FuzzFailure(f"{where}: error number {payload[1] & 0x7F} in {data.hex()} is not one the e-manual defines")
    return data[4], payload[1], payload[2:]


# -- the control table's rules, from the model files ------------------------------------
class TableRules:
    """One model's control table as the oracle reads it: entries by address, the write rules."""

    def __init__(self, key: str) -> None:
        spec = model(key)
        self.spec = spec
        layout = spec.layout(None)
        self.layout = layout
        self.size = layout.table_size
        self.eeprom_end = layout.eeprom_end
        self.defaults = bytes(layout.defaults)
        self.by_name = layout.by_name
        self.at: list[Any] = [None] * self.size
        for entry in layout.entries:
            for address in range(entry.address, entry.end):
                self.at[address] = entry
        self.indirect: dict[int, int] = {}
        for entry in layout.entries:
            if entry.name.startswith("indirect_data_"):
                self.indirect[entry.address] = self.by_name["indirect_address_" + entry.name[len("indirect_data_"):]].address
        self.address = {name: entry.address for name, entry in self.by_name.items()}
        self.firmware_bytes = frozenset(a for name in SENSED if name in self.by_name
                                        for a in range(self.by_name[name].address, self.by_name[name].end))
        tick = self.by_name.get("realtime_tick")
        self.tick_bytes = frozenset(range(tick.address, tick.end)) if tick else frozenset()
        self.boot_bytes = frozenset(a for name in BOOT_SET if name in self.by_name
                                    for a in range(self.by_name[name].address, self.by_name[name].end))
        self.rw = [e for e in layout.entries if e.access is Access.RW]

    def get(self, row: bytes, name: str) -> int:
        return self.by_name[name].value_in(row)

    def target(self, row: bytes, address: int) -> int:
        holder = self.indirect.get(address)
        if holder is None:
            return address
        # The chain is followed where an Indirect Address names Indirect Data ("inherits features and properties
        # of the Data from the specific Address", e-manual, Indirect Address), to the byte where it closes.
        seen = {address}
        target = row[holder] | row[holder + 1] << 8
        while target in self.indirect and target not in seen:
            seen.add(target)
            holder = self.indirect[target]
            target = row[holder] | row[holder + 1] << 8
        return target

    def read(self, row: bytes, address: int, length: int) -> tuple[int, bytes]:
        """A read's error and data: past the table Access Error with zeros (up to the table's size)."""
        if address + length > self.size:
            return ACCESS, bytes(min(length, self.size))
        out = bytearray()
        for a in range(address, address + length):
            t = self.target(row, a)
            out.append(row[t] if t < self.size else 0)
        return 0, bytes(out)

    def _range(self, entry: Any, image: bytes) -> tuple[int, int, bool]:
        for mode in entry.mode_ranges:
            if self.get(image, mode.register) in mode.values:
                return mode.minimum, mode.maximum, mode.limits
        return entry.minimum, entry.maximum, True

    def _bound(self, ref: str, image: bytes) -> int:
        value = self.get(image, ref.lstrip("-"))
        return -value if ref.startswith("-") else value

    def write(self, row: bytes, address: int, data: bytes, *, ram_only: bool = False,
              watchdog_error: bool = False) -> tuple[int, bytes]:
        """The error number of a WRITE and the table after it (unchanged when refused).

        Order of the checks as the e-manual lists the errors for a write (table2's docstring
        gives the emulator's reading): Access (past the table, undefined, read-only, EEPROM while
        the torque is on), Data Length (part of a register), Data Range (min/max or the range the
        operating mode selects; any Goal register during a Bus Watchdog Error), Data Limit (the
        bounding registers of the table as it would be after the write).
        """
        if not data or address + len(data) > self.size:
            return ACCESS, row
        changes = {self.target(row, address + k): byte for k, byte in enumerate(data)}
        torque_on = row[self.address["torque_enable"]] != 0
        touched: list[Any] = []
        for t in sorted(changes):
            entry = self.at[t] if t < self.size else None
            if entry is None or entry.access is not Access.RW or (entry.area is Area.EEPROM and torque_on):
                return ACCESS, row
            if not touched or touched[-1] is not entry:
                touched.append(entry)
        for entry in touched:
            if any(a not in changes for a in range(entry.address, entry.end)):
                return DATA_LENGTH, row
        image = bytearray(row)
        for t, byte in changes.items():
            image[t] = byte
        image = bytes(image)
        ranges = [self._range(e, image) for e in touched]
        for entry, (low, high, _) in zip(touched, ranges):
            value = entry.value_in(image)
            allowed = getattr(entry, "allowed", None)  # the values the source lists (Operating Mode)
            # An ID is 0..252 on every X series ("Packet ID"; 0xFD and 0xFF would extend the header).
            if ((watchdog_error and entry.name in GOALS) or not low <= value <= high
                    or (allowed is not None and value not in allowed) or (entry.name == "id" and value > 0xFC)):
                return DATA_RANGE, row
        for entry, (_, _, limits) in zip(touched, ranges):
            value = entry.value_in(image)
            if limits and ((entry.minimum_from and value < self._bound(entry.minimum_from, image))
                           or (entry.maximum_from and value > self._bound(entry.maximum_from, image))):
                return DATA_LIMIT, row
        if ram_only and any(e.area is Area.EEPROM for e in touched):
            return ACCESS, row
        mode = self.by_name.get("operating_mode")
        if mode is not None and mode in touched and mode.value_in(image) != mode.value_in(row):
            image = self._mode_changed(image)
        return 0, image

    def _mode_changed(self, image: bytes) -> bytes:
        """The model file's [mode_change]: registers back to their defaults, or to another register's value."""
        out = bytearray(image)
        change = self.spec.mode_change
        for name in change.defaults:
            entry = self.by_name.get(name)
            if entry is not None:
                out[entry.address:entry.end] = self.defaults[entry.address:entry.end]
        for name, source in change.from_registers:
            entry, origin = self.by_name.get(name), self.by_name.get(source)
            if entry is not None and origin is not None:
                out[entry.address:entry.end] = entry.to_bytes(origin.value_in(bytes(out)))
        return bytes(out)


@dataclass
class Shadow:
    """What the oracle keeps of one X-series servo between packets."""

    rules: TableRules
    row: bytes
    registered: tuple[int, bytes] | None = None
    backup: bytes | None = None


def _wire_rate(rules: TableRules, row: bytes) -> float:
    return float(rules.spec.baud_rates_bps[row[rules.address["baud_rate"]]])


@dataclass
class Expected:
    """A reply the oracle predicts: from ``servo`` (index) as ID ``servo_id``, error byte, parameters."""

    servo: int
    servo_id: int
    error: int
    data: bytes
    #: Servos sharing the ID answered at once: the wire carries their answers AND-ed, no packet to parse.
    collided: bool = False


class Oracle2:
    """The Protocol 2.0 rules for every servo on the bus; ``packet`` predicts one packet's replies and tables."""

    def __init__(self, bus: Bus2, options: Servo2Options) -> None:
        self.options = options
        rules = {key: TableRules(key) for key in {s.spec.name.lower() for s in bus.servos}}
        self.shadows = [Shadow(rules[s.spec.name.lower()], bytes(s.table.row)) for s in bus.servos]

    # -- helpers --------------------------------------------------------------------------
    @staticmethod
    def _hears(shadow: Shadow, row: bytes, line_bps: float | None) -> bool:
        rate = _wire_rate(shadow.rules, row)
        return line_bps is None or abs(line_bps - rate) <= 0.03 * rate

    @staticmethod
    def _answers(rules: TableRules, row: bytes, instruction: int) -> bool:
        level = row[rules.address["status_return_level"]]
        return instruction == PING or level >= 2 or (level == 1 and instruction in READS)

    @staticmethod
    def _alert(rules: TableRules, row: bytes) -> int:
        return 0x80 if "hardware_error_status" in rules.by_name and rules.get(row, "hardware_error_status") else 0

    @staticmethod
    def _secondary(rules: TableRules, row: bytes) -> int | None:
        if "secondary_id" not in rules.by_name:
            return None
        value = rules.get(row, "secondary_id")
        return value if value <= 0xFC else None

    @staticmethod
    def _watchdog_error(rules: TableRules, row: bytes) -> bool:
        return "bus_watchdog" in rules.by_name and row[rules.address["bus_watchdog"]] == 0xFF

    # -- one instruction on one servo -----------------------------------------------------
    def _boot(self, shadow: Shadow, row: bytes, image: bytes) -> bytes:
        """A power-up's table: ``image`` with the registered instruction cleared (goals are not compared)."""
        rules = self._rules(shadow)
        out = bytearray(image)
        if "registered_instruction" in rules.by_name:
            out[rules.address["registered_instruction"]] = 0
        if "backup_ready" in rules.by_name:
            at = rules.address["backup_ready"]
            out[at] = image[at] if shadow.backup is None else 1  # the backup outlives a power-up
        startup = out[rules.address["startup_configuration"]] if "startup_configuration" in rules.by_name else 0
        if startup & 0x02 and shadow.backup is not None:  # RAM Restore: the RAM items a backup carries
            for entry in rules.layout.entries:
                if entry.name in BACKUP_RAM or entry.name.startswith("indirect_address_"):
                    out[entry.address:entry.end] = shadow.backup[entry.address:entry.end]
        if startup & 0x01:  # Startup Torque On
            out[rules.address["torque_enable"]] = 1
        shadow.registered = None
        return bytes(out)

    @staticmethod
    def _rules(shadow: Shadow) -> TableRules:
        return shadow.rules

    def execute(self, shadow: Shadow, row: bytes, instruction: int, params: bytes, *, to_broadcast: bool,
                ram_only: bool = False) -> tuple[int, bytes, bytes, str | None]:
        """(error number, reply data, table after, what else may differ: None, 'boot' or 'sensed')."""
        rules = shadow.rules
        wd = self._watchdog_error(rules, row)
        if instruction in rules.spec.unsupported_instructions:  # the model file's list (the e-manual's "Supported")
            return INSTRUCTION_ERROR, b"", row, None
        if instruction == PING:
            if params:
                return RESULT_FAIL, b"", row, None
            return 0, row[0:2] + row[rules.address["firmware_version"]:][:1], row, None
        if instruction == READ:
            if len(params) != 4:
                return RESULT_FAIL, b"", row, None
            error, data = rules.read(row, params[0] | params[1] << 8, params[2] | params[3] << 8)
            # A Read past the table answers Access Error "with no parameters" (e-manual, Read); a Sync/Bulk Read's
            # share keeps its length (zeros), which the fast reads' one packet announces.  Another error's reply to
            # a Read carries the bytes asked for (zeros), as the emulator pads it (:meth:`Oracle2.packet`).
            return error, b"" if error == ACCESS else data, row, None
        if instruction in (WRITE, REG_WRITE):
            if len(params) < 2:
                return RESULT_FAIL, b"", row, None
            address, data = params[0] | params[1] << 8, params[2:]
            if instruction == WRITE:
                error, after = rules.write(row, address, data, ram_only=ram_only, watchdog_error=wd)
                return error, b"", after, None
            # Through a Secondary ID the EEPROM is out of reach for a Reg Write as for a Write (judged when registered)
            error, _ = rules.write(row, address, data, ram_only=ram_only, watchdog_error=False)
            if error:
                return error, b"", row, None
            shadow.registered = (address, bytes(data))
            out = bytearray(row)
            if "registered_instruction" in rules.by_name:
                out[rules.address["registered_instruction"]] = 1
            return 0, b"", bytes(out), None
        if instruction == ACTION:
            if params:
                return RESULT_FAIL, b"", row, None
            if shadow.registered is None:
                return INSTRUCTION_ERROR, b"", row, None
            address, data = shadow.registered
            shadow.registered = None
            out = bytearray(row)
            if "registered_instruction" in rules.by_name:
                out[rules.address["registered_instruction"]] = 0
            error, after = rules.write(bytes(out), address, data, ram_only=ram_only, watchdog_error=wd)
            return error, b"", after, None
        if instruction == FACTORY_RESET:
            if len(params) != 1 or params[0] not in KEEPS:
                return RESULT_FAIL, b"", row, None
            if to_broadcast and params[0] == 0xFF and rules.spec.broadcast_reset_all == "refused":
                return 0, b"", row, None  # not executed when broadcast (X series FW42 and later; the model file says)
            image = bytearray(rules.defaults)
            for name in KEEPS[params[0]]:
                entry = rules.by_name[name]
                image[entry.address:entry.end] = row[entry.address:entry.end]
            for name in IDENTITY:  # the servo's own, wherever its table keeps them
                if name in rules.by_name:
                    entry = rules.by_name[name]
                    image[entry.address:entry.end] = row[entry.address:entry.end]
            return 0, b"", self._boot(shadow, row, bytes(image)), "boot"
        if instruction == REBOOT:
            if params:
                return RESULT_FAIL, b"", row, None
            image = row[: rules.eeprom_end] + rules.defaults[rules.eeprom_end:]
            return 0, b"", self._boot(shadow, row, image), "boot"
        if instruction == CLEAR:
            if len(params) != 5 or params[0] != 0x01 or params[1:] != CLEAR_KEY:
                return RESULT_FAIL, b"", row, None
            moving = "moving" in rules.by_name and row[rules.address["moving"]]
            if moving:
                return RESULT_FAIL, b"", row, None
            return 0, b"", row, "sensed"  # Present Position back within one turn: the firmware's registers change
        if instruction == BACKUP:
            if len(params) != 5 or params[0] not in (1, 2) or params[1:] != BACKUP_KEY:
                return RESULT_FAIL, b"", row, None
            if row[rules.address["torque_enable"]]:  # "works properly only if Torque Enable ... is set as '0'"
                return RESULT_FAIL, b"", row, None
            if params[0] == 1:
                shadow.backup = row
                out = bytearray(row)
                if "backup_ready" in rules.by_name:
                    out[rules.address["backup_ready"]] = 1
                return 0, b"", bytes(out), None
            if shadow.backup is None:
                return RESULT_FAIL, b"", row, None
            image = shadow.backup[: rules.eeprom_end] + rules.defaults[rules.eeprom_end:]
            return 0, b"", self._boot(shadow, row, image), "boot"
        if instruction == SYNC_WRITE:
            if len(params) < 4:
                return RESULT_FAIL, b"", row, None
            address, length = params[0] | params[1] << 8, params[2] | params[3] << 8
            rest = params[4:]
            if not rest or len(rest) % (length + 1):
                return RESULT_FAIL, b"", row, None
            own = row[rules.address["id"]]
            for at in range(0, len(rest), length + 1):
                if rest[at] == own:
                    error, after = rules.write(row, address, rest[at + 1: at + 1 + length], ram_only=ram_only,
                                               watchdog_error=wd)
                    return error, b"", after, None
            return 0, b"", row, None
        if instruction == BULK_WRITE:
            blocks = []
            at = 0
            while at < len(params):
                if len(params) - at < 5:
                    return RESULT_FAIL, b"", row, None
                length = params[at + 3] | params[at + 4] << 8
                if at + 5 + length > len(params):
                    return RESULT_FAIL, b"", row, None
                blocks.append((params[at], params[at + 1] | params[at + 2] << 8, params[at + 5: at + 5 + length]))
                at += 5 + length
            if not blocks:
                return RESULT_FAIL, b"", row, None
            own = row[rules.address["id"]]
            error, current = 0, row
            for servo_id, address, data in blocks:
                if servo_id == own:
                    e, current = rules.write(current, address, data, ram_only=ram_only,
                                             watchdog_error=self._watchdog_error(rules, current))
                    error = e or error
            return error, b"", current, None
        return INSTRUCTION_ERROR, b"", row, None

    # -- one packet on the bus ------------------------------------------------------------
    def packet(self, packet: InstructionPacket2, rows: list[bytes], line_bps: float | None
               ) -> tuple[list[Expected] | tuple, list[bytes], dict[int, str]]:
        """Replies (a list; for a fast read ``("fast", expected frame, bytes sent, servos, its CRC whole, their IDs)``), tables
        after, boot slots."""
        after = list(rows)
        boots: dict[int, str] = {}
        instruction, params = packet.instruction, bytes(packet.params)
        broadcast = packet.id == BROADCAST_ID
        hearing = [k for k, s in enumerate(self.shadows) if self._hears(s, rows[k], line_bps)]
        ids = {k: rows[k][self.shadows[k].rules.address["id"]] for k in range(len(rows))}
        if not packet.crc_ok:
            if broadcast:
                return [], after, boots
            out = []
            for k in hearing:
                shadow = self.shadows[k]
                if ids[k] == packet.id and self._answers(shadow.rules, rows[k], instruction) \
                        and self.options.reply_on_crc_error:
                    n = min(params[2] | params[3] << 8, shadow.rules.size) if instruction == READ and len(params) == 4 else 0
                    out.append(Expected(k, ids[k], CRC_ERROR | self._alert(shadow.rules, rows[k]), bytes(n)))
            if len(out) > 1:  # servos sharing an ID answer at once
                out = [dataclasses.replace(out[0], collided=True)]
            return out, after, boots
        if not broadcast:
            if instruction in BROADCAST_ONLY:
                return [], after, boots
            out = []
            for k in hearing:
                shadow = self.shadows[k]
                if ids[k] == packet.id:
                    error, data, after[k], mark = self.execute(shadow, rows[k], instruction, params, to_broadcast=False)
                    if mark:
                        boots[k] = mark
                    if self._answers(shadow.rules, rows[k], instruction):
                        if error not in (0, ACCESS) and instruction == READ and len(params) == 4 and not data:
                            data = bytes(min(params[2] | params[3] << 8, shadow.rules.size))  # (Access: none, above)
                        out.append(Expected(k, ids[k], error | self._alert(shadow.rules, rows[k]), data))
                elif self._secondary(shadow.rules, rows[k]) == packet.id and instruction not in (FACTORY_RESET, BACKUP):
                    _, _, after[k], mark = self.execute(shadow, rows[k], instruction, params, to_broadcast=True,
                                                        ram_only=True)
                    if mark:
                        boots[k] = mark
            if len(out) > 1:  # servos sharing an ID answer at once
                out = [dataclasses.replace(out[0], collided=True)]
            return out, after, boots
        if instruction in LISTED:
            return self._listed(instruction, params, rows, hearing, ids), after, boots
        if instruction == PING:
            out = []
            for k in sorted(hearing, key=lambda k: ids[k]):
                shadow = self.shadows[k]
                error, data, _, _ = self.execute(shadow, rows[k], PING, params, to_broadcast=False)
                out.append(Expected(k, ids[k], error | self._alert(shadow.rules, rows[k]), data))
            return out, after, boots
        if instruction in EXECUTED and instruction != READ:
            for k in hearing:
                _, _, after[k], mark = self.execute(self.shadows[k], rows[k], instruction, params, to_broadcast=True)
                if mark:
                    boots[k] = mark
        return [], after, boots

    def _listed(self, instruction: int, params: bytes, rows: list[bytes], hearing: list[int], ids: dict[int, int]):
        if instruction in (SYNC_READ, FAST_SYNC_READ):
            if len(params) < 5:
                return []
            reads = [(i, params[0] | params[1] << 8, params[2] | params[3] << 8) for i in params[4:]]
        else:
            if not params or len(params) % 5:
                return []
            reads = [(params[i], params[i + 1] | params[i + 2] << 8, params[i + 3] | params[i + 4] << 8)
                     for i in range(0, len(params), 5)]
        shares: list[tuple[int, int, int, bytes]] = []
        #: Per share, the other servos holding its ID that answer in its turn (at once: a collision).
        twins: list[list[tuple[int, bytes]]] = []
        for servo_id, address, length in reads:
            holders = [k for k in range(len(rows)) if ids[k] == servo_id]
            if not holders or holders[0] not in hearing:
                break
            k = holders[0]
            rules = self.shadows[k].rules
            if not self._answers(rules, rows[k], instruction) or instruction in rules.spec.unsupported_instructions:
                break
            error, data = rules.read(rows[k], address, length)
            shares.append((k, servo_id, error | self._alert(rules, rows[k]), data))
            twins.append([(self._alert(self.shadows[t].rules, rows[t]) | e, d)
                          for t in holders[1:] if t in hearing and self._answers(self.shadows[t].rules, rows[t], instruction)
                          for e, d in [self.shadows[t].rules.read(rows[t], address, length)]])
        if not shares:
            return []
        if instruction in (SYNC_READ, BULK_READ):  # a servo sharing the listed ID answers in the same turn
            return [Expected(k, servo_id, error, data, bool(twin)) for (k, servo_id, error, data), twin in zip(shares, twins)]
        if 1 + sum(4 + n for _, _, n in reads) > 0xFFFF:
            return []  # no LENGTH can announce the listed shares: nobody starts the packet
        # A share's data is what its servo read (a read past the table: zeros up to the table's size);
        # the shares never sent are announced with the length asked for.  Each servo sending the
        # header announces the shares' lengths with its own share's.
        sizes = [len(shares[i][3]) if i < len(shares) else n for i, (_, _, n) in enumerate(reads)]

        def head(first_size: int) -> bytes:
            length = 1 + sum(4 + n for n in [first_size, *sizes[1:]])
            return HEADER + bytes((BROADCAST_ID, length & 0xFF, length >> 8, STATUS))

        whole = bytearray()
        running = 0
        sent = 0
        for index, (_, _, n) in enumerate(reads):
            error, data = (shares[index][2], shares[index][3]) if index < len(shares) else (0, bytes(n))
            servo_id = shares[index][1] if index < len(shares) else 0
            # Every servo holding the ID sends its share at once: the wire carries their bytes AND-ed
            # (the longer one's tail as sent), each CRC run on from what it heard before its share.
            piece = b""
            for twin_error, twin_data in [(error, data), *(twins[index] if index < len(shares) else ())]:
                body = (head(len(twin_data)) if index == 0 else b"") + bytes((twin_error, servo_id)) + twin_data
                own = body + crc(body, running).to_bytes(2, "little")
                piece = own if not piece else bytes(a & b for a, b in zip(piece, own)) + (piece if len(piece) > len(own)
                                                                                         else own)[min(len(piece), len(own)):]
            running = crc(piece, running)
            whole += piece
            if index < len(shares):
                sent = len(whole)
        # The packet's CRC is the last share's running CRC, unless servos sharing its ID AND-ed theirs.
        return ("fast", bytes(whole), sent, [k for k, *_ in shares], not twins[-1], [servo_id for _, servo_id, *_ in shares])


# -- one case ---------------------------------------------------------------------------
@dataclass
class Case2(fuzz1.Reproducible):
    """The bus and the inputs fed to it: (bytes, pause before, physics step before)."""

    bus: str = "2.0"
    reply_on_crc_error: bool = True
    line_bps: float | None = None
    inputs: list[tuple[bytes, float, float]] = field(default_factory=list)


def build_bus(case: Case2) -> tuple[Any, Bus2, Bus | None, VirtualClock]:
    """The bus a case runs on: X-series servos alone, or beside AX-12As on one wire."""
    clock = VirtualClock()
    servos = BUS2_SERVOS if case.bus == "2.0" else MIXED_SERVOS2
    options = Servo2Options(reply_on_crc_error=case.reply_on_crc_error)
    bus2 = Bus2([(i, model(key)) for i, key in servos], lambda spec, index: build_x_firmware(spec), clock=clock,
                options=options)
    for servo in bus2.servos:
        servo.start_at_baud(LINE_BPS)
    if case.bus == "2.0":
        return bus2, bus2, None, clock
    bus1 = Bus(list(MIXED_IDS1), options=ServoOptions(), clock=clock,
               model=build_model(ModelChoice(name="kinematic"), len(MIXED_IDS1)))
    return MixedBus(bus1, bus2), bus2, bus1, clock


class Recorder:
    """Wraps the 2.0 bus's ``dispatch``: each packet with the tables just before and after it, and its replies."""

    def __init__(self, bus2: Bus2) -> None:
        self.records: list[tuple[Any, float | None, list[bytes], list[bytes], list, list, list]] = []
        self.bus2 = bus2
        original = bus2.dispatch

        def dispatch(packet, *, line_bps=None):
            bus2.catch_up(bus2.clock.now_s() - bus2.request_lag_s)  # physics first, so "before" is what the servos hold
            before = [bytes(s.table.row) for s in bus2.servos]
            state = [(s.registered_write, s.backup) for s in bus2.servos]
            replies = list(original(packet, line_bps=line_bps))
            after = [bytes(s.table.row) for s in bus2.servos]
            self.records.append((packet, line_bps, before, after, replies, state,
                                 [(s.registered_write, s.backup) for s in bus2.servos]))
            return replies

        bus2.dispatch = dispatch


def _between(oracle: Oracle2, rows: list[bytes], where: str) -> None:
    """Between packets only the firmware's registers change (sensed ones, Realtime Tick, Bus Watchdog -1, a shutdown)."""
    for k, shadow in enumerate(oracle.shadows):
        rules, old, new = shadow.rules, shadow.row, rows[k]
        if old == new:
            continue
        for a in range(rules.size):
            if old[a] == new[a] or a in rules.firmware_bytes or a in rules.tick_bytes:
                continue
            if a == rules.address.get("bus_watchdog") and new[a] == 0xFF and 1 <= old[a] <= 0x7F \
                    and old[rules.address["torque_enable"]]:
                continue
            if a == rules.address["torque_enable"] and old[a] == 1 and new[a] == 0:
                continue  # a shutdown (Hardware Error Status) turns the torque off
            if a == rules.address["torque_enable"] and old[a] == 0 and new[a] == 1 \
                    and "drive_mode" in rules.by_name and old[rules.address["drive_mode"]] & 0x08:
                continue  # Drive Mode bit 3, "Torque On by Goal Update": a goal written turns the torque on
            raise FuzzFailure(f"{where}: between packets byte {a} of servo {k} changed {old[a]} -> {new[a]}")
        shadow.row = new


def _compare(oracle: Oracle2, k: int, expected: bytes, actual: bytes, mark: str | None, where: str) -> None:
    """The table after a packet as the rules give it; after a power-up ('boot') the firmware's and the
    boot-set registers, after a Clear ('sensed') the firmware's, are the firmware's to say."""
    boot = mark == "boot"
    rules = oracle.shadows[k].rules
    for a in range(rules.size) if expected != actual else ():
        if expected[a] == actual[a] or a in rules.tick_bytes:
            continue
        if boot and (a in rules.firmware_bytes or a in rules.boot_bytes or a == rules.address["torque_enable"]):
            continue
        if mark == "sensed" and a in rules.firmware_bytes:
            continue
        entry = rules.at[a]
        raise FuzzFailure(f"{where}: servo {k} byte {a} ({entry.name if entry else 'unused'}) is {actual[a]}, "
                          f"the rules give {expected[a]}")
    if boot:
        for goal, limit in BOOT_LIMITS.items():
            if goal in rules.by_name and rules.get(actual, goal) != rules.get(actual, limit):
                raise FuzzFailure(f"{where}: servo {k} {goal} after a power-up is not {limit}")


def _check_record(oracle: Oracle2, record: tuple, stream: bytes, where: str) -> None:
    packet, line_bps, before, after, replies, state, state_after = record
    _between(oracle, before, where)
    for k, (registered, backup) in enumerate(state):
        shadow = oracle.shadows[k]
        if (registered is None) != (shadow.registered is None) or (backup is None) != (shadow.backup is None):
            raise FuzzFailure(f"{where}: servo {k} registered/backup {registered, backup is not None}, "
                              f"the oracle holds {shadow.registered, shadow.backup is not None}")
    if isinstance(packet, StatusPacket2):
        _framed_in(packet.id, STATUS, bytes((packet.error,)) + packet.params, packet.crc_ok, stream, where)
        if replies or after != before:
            raise FuzzFailure(f"{where}: a status packet on the wire changed something or was answered")
        return
    _framed_in(packet.id, packet.instruction, packet.params, packet.crc_ok, stream, where)
    # Realtime Tick is set when a servo hears the packet, before it executes it: take it from after.
    heard = []
    for k, shadow in enumerate(oracle.shadows):
        row = bytearray(before[k])
        for a in shadow.rules.tick_bytes:
            row[a] = after[k][a]
        heard.append(bytes(row))
    expected, tables, boots = oracle.packet(packet, heard, line_bps)
    if not packet.crc_ok:
        CHECKED[("bad CRC", "error 3" if expected else "silent")] += 1
    elif isinstance(expected, tuple):
        CHECKED[(f"{packet.instruction:#04x}", "combined status")] += 1
    else:
        for expect in expected or [None]:
            CHECKED[(f"{packet.instruction:#04x}", f"error {expect.error & 0x7F}" if expect else "silent")] += 1
    for k in (expected[3] if isinstance(expected, tuple) else [e.servo for e in expected]):
        CHECKED_MODELS[oracle.shadows[k].rules.spec.name] += 1
    what = f"{where}, packet id={packet.id} inst={packet.instruction:#04x} params={bytes(packet.params).hex()}" \
           f"{'' if packet.crc_ok else ' (bad CRC)'}"
    if isinstance(expected, tuple):
        _, whole, sent, order, crc_whole, share_ids = expected
        joined = b"".join(r.data for r in replies)
        # One status packet in shares, each named by the servo that sends it (a fault on some IDs reaches the
        # packet they share in), all but the first continuing the first.
        one_packet = [r.continues for r in replies] == [False] + [True] * (len(replies) - 1)
        named = [r.servo_id for r in replies] == share_ids
        if joined != whole[:sent] or not one_packet or not named or len(replies) != len(order):
            raise FuzzFailure(f"{what}: fast read reply {[r.data.hex() for r in replies]}, expected {whole[:sent].hex()}")
        if sent == len(whole) and crc_whole:
            if crc(joined[:-2]) != joined[-2] | joined[-1] << 8:
                raise FuzzFailure(f"{what}: combined status CRC wrong")
    else:
        if len(replies) != len(expected):
            raise FuzzFailure(f"{what}: {len(replies)} replies {[r.data.hex() for r in replies]}, expected "
                              f"{len(expected)} from IDs {[e.servo_id for e in expected]}")
        last_s = -1.0
        for reply, expect in zip(replies, expected):
            if expect.collided:
                if reply.servo_id != expect.servo_id:
                    raise FuzzFailure(f"{what}: colliding answers carried as ID {reply.servo_id}, not {expect.servo_id}")
                last_s = reply.delay_s
                continue
            servo_id, error, data = parse_status(reply.data, what)
            if servo_id != expect.servo_id or reply.servo_id != servo_id:
                raise FuzzFailure(f"{what}: reply {reply.data.hex()} from ID {servo_id}, expected {expect.servo_id}")
            if error != expect.error:
                raise FuzzFailure(f"{what}: reply {reply.data.hex()} has error {error:#04x}, expected {expect.error:#04x}")
            if data != expect.data:
                raise FuzzFailure(f"{what}: reply {reply.data.hex()} carries {data.hex()}, expected {expect.data.hex()}")
            if packet.crc_ok and packet.instruction in LISTED and reply.delay_s <= last_s:  # each after the previous one ended
                raise FuzzFailure(f"{what}: reply delays {[r.delay_s for r in replies]} are not in order")
            last_s = reply.delay_s
        if len(replies) == 1 and packet.id != BROADCAST_ID and not expected[0].collided:
            rules = oracle.shadows[expected[0].servo].rules
            rdt_s = before[expected[0].servo][rules.address["return_delay_time"]] * 2e-6
            if abs(replies[0].delay_s - rdt_s) > 1e-12:
                raise FuzzFailure(f"{what}: reply after {replies[0].delay_s} s, Return Delay Time gives {rdt_s} s")
    for k in range(len(oracle.shadows)):
        _compare(oracle, k, tables[k], after[k], boots.get(k), what)
        oracle.shadows[k].row = after[k]
    for k, (registered, _) in enumerate(state_after):
        shadow = oracle.shadows[k]
        if registered != shadow.registered:
            raise FuzzFailure(f"{what}: servo {k} registered {registered}, the rules give {shadow.registered}")


def _framed_in(packet_id: int, first: int, params: bytes, crc_ok: bool, stream: bytes, where: str) -> None:
    """The framer's packet is in the bytes fed: a header for its ID, a LENGTH that fits, the CRC as flagged."""
    marker = HEADER + bytes((packet_id,))
    at = stream.find(marker)
    while at >= 0:
        length = stream[at + 5] | stream[at + 6] << 8 if at + 7 <= len(stream) else -1
        end = at + 7 + length
        if length >= 3 and end <= len(stream):
            whole = stream[at:end]
            good = crc(whole[:-2]) == whole[-2] | whole[-1] << 8
            payload = whole[7:-2]
            if good == crc_ok:
                if not good:
                    if payload[0] == first:
                        return
                else:
                    combined = packet_id == BROADCAST_ID and payload[0] == STATUS
                    body = payload if combined else unstuff(payload, strict=False)
                    if body == bytes((first,)) + bytes(params):
                        return
        at = stream.find(marker, at + 1)
    raise FuzzFailure(f"{where}: the framer handed on a packet (id={packet_id} inst={first:#04x} "
                      f"params={bytes(params).hex()}) not in the bytes fed")


def _whole_packet_at_start(data: bytes) -> tuple[int, int] | None:
    """(ID, instruction) when ``data`` begins with a whole valid 2.0 instruction packet the framer must not lose."""
    if len(data) < 10 or data[:4] != HEADER or not (data[4] <= 0xFC or data[4] == BROADCAST_ID):
        return None
    length = data[5] | data[6] << 8
    if not 3 <= length <= DEFAULT_MAX_LENGTH or len(data) < 7 + length or data[7] == STATUS:
        return None
    whole = data[: 7 + length]
    if crc(whole[:-2]) != whole[-2] | whole[-1] << 8:
        return None
    return data[4], data[7]


@dataclass
class _One:
    """The 1.0 half of a mixed wire, checked by the 1.0 fuzzer's oracle."""

    bus1: Bus
    oracle: Any
    framer: Framer
    shutdown_register: str


def run_case(case: Case2) -> int:
    """Feed every input of ``case`` to a fresh bus, checking the invariants; return inputs fed."""
    bus, bus2, bus1, clock = build_bus(case)
    recorder = Recorder(bus2)
    oracle = Oracle2(bus2, Servo2Options(reply_on_crc_error=case.reply_on_crc_error))
    one = None
    if bus1 is not None:
        one = _One(bus1, fuzz1.Oracle(bus1.rows, ServoOptions(), case.line_bps), Framer(),
                   fuzz1.layout("ax12a").profile.shutdown_clears)
    wire_s = 0.0
    stream = b""
    fed = 0
    for index, (data, pause_s, physics_dt_s) in enumerate(case.inputs):
        where = f"input {index} ({data.hex() or 'empty'})"
        wire_s += pause_s
        if pause_s > DEFAULT_SILENCE_TIMEOUT_S:
            stream = b""
        if physics_dt_s:
            clock.advance(physics_dt_s)
            bus.advance()
            if one is not None:
                fuzz1._sync_physics(one.bus1, one.oracle, one.shutdown_register, f"{where}, physics step")
        stream = (stream + data)[-(2 * DEFAULT_MAX_LENGTH + len(data) + 16):]
        first = len(recorder.records)
        before1 = one.bus1.rows.copy() if one is not None else None
        alarms_before = [s.alarms for s in one.bus1.servos] if one is not None else None
        model_time_s = one.bus1.plant.model.time_s if one is not None else 0.0
        write_unseen1 = one.bus1.plant.write_unseen if one is not None else False
        started_cpu_s, started_s = time.thread_time(), time.perf_counter()
        replies = bus.receive(data, wire_s, line_bps=case.line_bps)
        # CPU time, so a machine shared with other work does not count as a hang; waiting on
        # something counts by the wall clock, with room for the machine's load.
        if time.thread_time() - started_cpu_s > HANG_S or time.perf_counter() - started_s > 5 * HANG_S:
            raise FuzzFailure(f"{where}: took {time.thread_time() - started_cpu_s:.1f} s of CPU, "
                              f"{time.perf_counter() - started_s:.1f} s")
        fed += 1
        if bus2.framer.buffered > DEFAULT_MAX_LENGTH + 7 + len(data):
            raise FuzzFailure(f"{where}: the 2.0 framer holds {bus2.framer.buffered} bytes")
        records = recorder.records[first:]
        expected_start = _whole_packet_at_start(data) if pause_s > DEFAULT_SILENCE_TIMEOUT_S else None
        if expected_start is not None and (not records or (records[0][0].id, records[0][0].instruction) != expected_start):
            raise FuzzFailure(f"{where}: a whole packet after a pause was not handed on (lost)")
        for k, record in enumerate(records):
            _check_record(oracle, record, stream, f"{where}, packet {k}")
        replies2 = sum(len(r[4]) for r in records)
        if one is not None:
            _check_one(one, replies[: len(replies) - replies2], data, wire_s, clock, before1, alarms_before,
                       model_time_s, write_unseen1, where)
        elif len(replies) != replies2:
            raise FuzzFailure(f"{where}: {len(replies)} replies, the 2.0 servos sent {replies2}")
    _between(oracle, [bytes(s.table.row) for s in bus2.servos], "after the inputs")
    # After a pause every X-series servo answers a Ping, and a Read of its whole table is its table.
    wire_s += PAUSE_S
    for k, servo in enumerate(bus2.servos):
        wire_s += PAUSE_S
        holders = [s for s in bus2.servos if s.id == servo.id]
        got = bus.receive(frame(servo.id, bytes((PING,))), wire_s)
        if len(got) != 1:  # servos sharing an ID answer at once, in one colliding reply
            raise FuzzFailure(f"PING to {servo.id} after the inputs: {len(got)} replies, {len(holders)} servos hold the ID")
        if len(holders) == 1 and servo.status_return_level:
            wire_s += PAUSE_S
            size = oracle.shadows[k].rules.size
            (reply,) = bus.receive(frame(servo.id, bytes((READ, 0, 0, size & 0xFF, size >> 8))), wire_s)
            _, error, data = parse_status(reply.data, "full READ after the inputs")
            if error & 0x7F or data != oracle.shadows[k].rules.read(bytes(servo.table.row), 0, size)[1]:
                raise FuzzFailure(f"full READ of ID {servo.id} after the inputs: error {error}, data differ from the table")
    return fed + 1


def _check_one(one: _One, replies: list, data: bytes, wire_s: float, clock: VirtualClock, before, alarms_before,
               model_time_s: float, write_unseen: bool, where: str) -> None:
    """The 1.0 servos of a mixed wire, as ``fuzz.run_case`` checks them."""
    packets = one.framer.feed(data, wire_s)
    predicted = []
    reset_slots: set[int] = set()
    for packet in packets:
        if packet.checksum_ok and packet.instruction == Instruction.RESET:
            reset_slots |= {i for i, s in enumerate(one.oracle.servos) if packet.id in (BROADCAST_ID, int(s.row[3]))}
        predicted += one.oracle.packet(packet.id, packet.instruction, packet.params, packet.checksum_ok, clock.now_s())
    fuzz1._check_replies(one.bus1, one.oracle, replies, predicted, f"{where} (Protocol 1.0)", alarms_before)
    stepped = one.bus1.plant.model.time_s != model_time_s
    # A write's consequence may show with no step (the model already a step past the clock: ``Plant.catch_up``).
    wrote = write_unseen or any(p.checksum_ok and p.instruction in fuzz1.WRITES for p in packets)
    goal_follows = reset_slots if stepped else set()
    fuzz1._check_tables(one.bus1, one.oracle, before, reset_slots | (set(range(len(MIXED_IDS1))) if stepped or wrote else set()),
                        one.shutdown_register, f"{where} (Protocol 1.0)", goal_follows)


# -- generation -------------------------------------------------------------------------
_RULES = {key: TableRules(key) for key in ("xl430-w250", "xl330-m077", "xl-320")}
#: Registers the grammar writes often: the ones whose rules interact (torque and EEPROM, IDs,
#: Status Return Level, limits and goals, indirect addresses, watchdog, backup), by name.
HOT_REGISTERS = ("torque_enable",) * 4 + ("goal_position",) * 3 + (
    "id", "status_return_level", "return_delay_time", "secondary_id", "operating_mode", "min_position_limit",
    "max_position_limit", "pwm_limit", "goal_pwm", "goal_velocity", "velocity_limit", "bus_watchdog", "bus_watchdog",
    "indirect_address_1", "indirect_address_2", "indirect_data_1", "indirect_data_2", "led", "homing_offset",
    "drive_mode", "profile_velocity", "shutdown", "goal_current", "current_limit", "baud_rate", "hardware_error_status",
    "present_position", "model_number", "registered_instruction")
HOT_IDS2 = (1, 2, 3, 4, 1, 2, 3, 4, BROADCAST_ID, BROADCAST_ID, 0, 5)
#: Values that matter for some registers: IDs that collide, a short watchdog, indirect targets.
SPECIAL_VALUES = {
    "id": (1, 2, 3, 4, 0), "secondary_id": (1, 2, 3, 4, 255), "status_return_level": (0, 1, 2, 2, 2),
    "bus_watchdog": (0, 1, 2, 0), "baud_rate": (3, 3, 3, 1), "operating_mode": (3, 4, 1, 16, 3),
    "indirect_address_1": (116, 117, 64, 7, 132), "indirect_address_2": (64, 118, 8, 65, 227),
}


def _entry(c: Any) -> Any:
    rules = _RULES[c.pick(tuple(_RULES))]
    name = c.pick(HOT_REGISTERS) if c.integer(0, 2) else c.pick(tuple(rules.by_name))
    return rules.by_name.get(name) or rules.by_name["led"]


def _value_bytes(c: Any, entry: Any) -> bytes:
    roll = c.integer(0, 9)
    if entry.name in SPECIAL_VALUES and roll < 5:
        value = c.pick(SPECIAL_VALUES[entry.name])
    elif roll < 6:
        value = c.integer(entry.minimum, entry.maximum)
    elif roll < 8:
        value = c.pick((entry.minimum, entry.maximum, 0))
    elif roll < 9:
        value = c.pick((entry.minimum - 1, entry.maximum + 1))
    else:
        return c.binary(entry.size, entry.size)
    return (value % (1 << 8 * entry.size)).to_bytes(entry.size, "little")


def _u16(value: int) -> bytes:
    return bytes((value & 0xFF, value >> 8 & 0xFF))


def _write_target(c: Any) -> tuple[int, bytes]:
    """Address and data of a write: a whole register mostly; part of one, a span, anywhere, or FF FF FD inside."""
    entry = _entry(c)
    roll = c.integer(0, 19)
    data = _value_bytes(c, entry)
    if roll < 13:
        return entry.address, data
    if roll < 15:
        return entry.address + c.integer(0, entry.size - 1), data[: c.integer(0, entry.size)]
    if roll < 17:
        following = _entry(c)
        return entry.address, data + _value_bytes(c, following)
    if roll < 18:
        return c.integer(0, 700), c.binary(0, 6)
    return c.pick((224, 225, 116, 634)), b"\xff\xff\xfd" + c.binary(0, 2)


def _read_target(c: Any) -> tuple[int, int]:
    entry = _entry(c)
    roll = c.integer(0, 9)
    if roll < 6:
        return entry.address, entry.size
    if roll < 8:
        return entry.address, c.pick((0, 1, 10, 60, 228, 662, 700))
    return c.integer(0, 700), c.integer(0, 300)


def _ids(c: Any) -> bytes:
    return bytes(c.pick(HOT_IDS2[:8] + (0, 5, 200)) for _ in range(c.integer(0, 4)))


KINDS2 = ("write",) * 5 + ("read",) * 3 + ("reg", "action", "ping", "ping", "sync_read", "fast_sync_read", "bulk_read",
                                            "fast_bulk_read", "sync_write", "sync_write", "bulk_write", "clear",
                                            "backup", "reboot", "factory_reset", "undefined")


def instruction2(c: Any) -> tuple[int, int, bytes]:
    """(ID, instruction, parameters) of a plausible packet, often with invalid parameters."""
    kind = c.pick(KINDS2)
    packet_id = c.pick(HOT_IDS2) if c.integer(0, 5) else c.integer(0, 0xFC)
    if kind in ("write", "reg"):
        address, data = _write_target(c)
        code, params = (WRITE if kind == "write" else REG_WRITE), _u16(address) + data
    elif kind == "read":
        address, length = _read_target(c)
        code, params = READ, _u16(address) + _u16(length)
    elif kind in ("sync_read", "fast_sync_read"):
        address, length = _read_target(c)
        code, params = (SYNC_READ if kind == "sync_read" else FAST_SYNC_READ), _u16(address) + _u16(length) + _ids(c)
    elif kind in ("bulk_read", "fast_bulk_read"):
        blocks = b"".join(bytes((i,)) + _u16(a) + _u16(n) for i in _ids(c) for a, n in [_read_target(c)])
        code, params = (BULK_READ if kind == "bulk_read" else FAST_BULK_READ), blocks
    elif kind == "sync_write":
        entry = _entry(c)
        blocks = b"".join(bytes((i,)) + _value_bytes(c, entry) for i in _ids(c))
        code, params = SYNC_WRITE, _u16(entry.address) + _u16(entry.size) + blocks
    elif kind == "bulk_write":
        blocks = b""
        for servo_id in _ids(c):
            address, data = _write_target(c)
            blocks += bytes((servo_id,)) + _u16(address) + _u16(len(data)) + data
        code, params = BULK_WRITE, blocks
    elif kind == "clear":
        code, params = CLEAR, bytes((c.pick((1, 1, 2)),)) + (CLEAR_KEY if c.integer(0, 3) else c.binary(0, 4))
    elif kind == "backup":
        code, params = BACKUP, bytes((c.pick((1, 2, 3)),)) + (BACKUP_KEY if c.integer(0, 3) else c.binary(0, 4))
    elif kind == "factory_reset":
        if c.integer(0, 3):  # mostly refused: a reset wipes what the other packets built up
            return packet_id, WRITE, _u16(64) + b"\x00"
        code, params = FACTORY_RESET, bytes((c.pick((0xFF, 0x01, 0x02, 0x00)),))
    elif kind == "undefined":
        code, params = c.pick((0x00, 0x07, 0x09, 0x55, 0x83, 0xFF, c.integer(0, 255))), c.binary(0, 4)
    else:
        code, params = {"action": ACTION, "ping": PING, "reboot": REBOOT}[kind], b""
    if c.integer(0, 19) == 0:
        params = params[: c.integer(0, len(params))] if c.integer(0, 1) else params + c.binary(1, 3)
    return packet_id, code, params


def packet2(c: Any) -> bytes:
    packet_id, code, params = instruction2(c)
    return frame(packet_id, bytes((code,)) + params)


def _recrc(packet: bytearray) -> bytearray:
    packet[-2:] = crc(bytes(packet[:-2])).to_bytes(2, "little")
    return packet


def mutated2(c: Any) -> bytes:
    """A packet with one fault: see the module docstring."""
    packet = bytearray(packet2(c))
    how = c.pick(("flip", "crc", "cut", "length", "reserved", "unstuff", "overstuff", "id", "ff", "insert", "glue",
                  "v1", "stuffed"))
    at = c.integer(0, len(packet) - 1)
    if how == "flip":
        packet[at] ^= 1 << c.integer(0, 7)
    elif how == "crc":
        packet[-1] ^= c.integer(1, 255)
    elif how == "cut":
        del packet[at:]
    elif how == "length":
        length = packet[5] | packet[6] << 8
        new = c.pick((length - 1, length + 1, 0, 2, 3, 0xFFFF, c.integer(0, 2000)))
        packet[5:7] = _u16(new % 0x10000)
        if c.integer(0, 1):
            _recrc(packet)
    elif how == "reserved":
        packet[3] = c.pick((0xFD, 0x01, 0xFF))
    elif how in ("unstuff", "overstuff", "stuffed"):
        if how == "stuffed" or b"\xff\xff\xfd" not in packet[7:-2]:
            packet = bytearray(frame(c.pick(HOT_IDS2), bytes((WRITE,)) + _u16(224) + b"\xff\xff\xfd" + c.binary(0, 3)))
        if how != "stuffed":
            where = packet.find(b"\xff\xff\xfd", 7) + 3
            if how == "unstuff" and packet[where] == 0xFD:
                del packet[where]
            else:
                packet[where:where] = b"\xfd"
            packet[5:7] = _u16(len(packet) - 7)
            _recrc(packet)
    elif how == "id":
        packet[4] = c.pick((0xFD, 0xFF, BROADCAST_ID, 7, 200))
        _recrc(packet)
    elif how == "ff":
        packet[at:at] = b"\xff" * c.integer(1, 3)
    elif how == "insert":
        packet[at:at] = c.binary(1, 4)
    elif how == "glue":
        packet += packet2(c)
    else:
        packet[at:at] = fuzz1.instruction_packet(c)
    return bytes(packet)


def status2(c: Any) -> bytes:
    """Another device's status packet (the bus hears and ignores it)."""
    return frame(c.pick((1, 2, 3, 9)), bytes((STATUS, c.pick((0, 1, 0x80)))) + c.binary(0, 4))


def piece2(c: Any) -> bytes:
    """Mostly valid 2.0 packets, then mutated ones, 1.0 packets, status packets, garbage."""
    roll = c.integer(0, 99)
    if roll < 55:
        return packet2(c)
    if roll < 80:
        return mutated2(c)
    if roll < 90:
        return fuzz1.instruction_packet(c)
    if roll < 94:
        return status2(c)
    return c.binary(0, 12)


PAUSES = (0.0, 0.0, 0.0, 0.0, 1e-4, PAUSE_S)
#: Physics steps: mostly none, sometimes a few control steps, sometimes long enough for a Bus Watchdog of 1-2 units.
PHYSICS_STEPS = (0.0,) * 14 + (0.001, 0.003, 0.05, 0.05)


def generate_case(c: Any, pieces: int, bus: str | None = None) -> Case2:
    """A bus and a stream of ``pieces`` pieces, each fed whole, cut in two, or glued to the next."""
    case = Case2(bus=bus or c.pick(("2.0", "2.0", "mixed")), reply_on_crc_error=bool(c.integer(0, 3)),
                 line_bps=c.pick((None, None, float(LINE_BPS))))
    case.inputs.extend(fuzz1.stream_inputs(c, pieces, piece2, PAUSES, PHYSICS_STEPS))
    return case


def minimise(case: Case2, budget: int = 2000) -> Case2:
    """Delta-debug a failing case with the Protocol 1.0 fuzzer's minimiser, run by this oracle."""
    return fuzz1.minimise(case, budget, run=run_case)


# -- driver -----------------------------------------------------------------------------
@dataclass
class Stats:
    """Counts of one fuzzing run."""

    inputs: int = 0
    cases: int = 0
    packets: int = 0
    by_bus: dict[str, int] = field(default_factory=dict)
    failure: str | None = None
    reproducer: str | None = None


def fuzz(max_inputs: int, *, seconds: float | None = None, seed: int | None = None, pieces: int = 200,
         batch: int = 100, bus: str | None = None) -> Stats:
    """Run cases until ``max_inputs`` inputs were fed (or ``seconds`` passed) or one fails (``fuzz.drive``)."""
    stats = Stats()

    def counted(case: Case2, fed: int) -> None:
        stats.by_bus[case.bus] = stats.by_bus.get(case.bus, 0) + fed

    return fuzz1.drive(stats, lambda case_seed, count: generate_case(fuzz1.RandomChooser(case_seed), count, bus),
                       run_case, minimise, max_inputs, seconds=seconds,
                       # runs with nearby seeds must not share rounds
                       round_seed=None if seed is None else (lambda k: seed * 1_000_000 + k),
                       pieces=pieces, batch=batch, counted=counted)


def main(argv: list[str] | None = None) -> int:
    """Parse arguments, fuzz, print figures; exit 1 on a failure."""
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--inputs", type=positive_int, default=1_000_000,
                        help="inputs (chunks) to feed (default 1,000,000)")
    parser.add_argument("--seconds", type=positive_float, help="stop after this long even if fewer inputs were fed")
    parser.add_argument("--seed", type=int, help="seed hypothesis (default: random)")
    parser.add_argument("--bus", choices=("2.0", "mixed"), help="only this bus (default: both, 2:1)")
    parser.add_argument("--no-coverage", action="store_true", help="skip coverage measurement (faster)")
    parser.add_argument("--replay", type=file_name, metavar="FILE", help="rerun one case written on a failure")
    parser.add_argument("--failure-file", type=file_name, default="fuzz2-failure.json",
                        help="where a failing case is written")
    args = parser.parse_args(argv)

    if args.replay:
        return fuzz1.replay(args.replay, Case2.from_json, run_case)

    cov = _COVERAGE
    started = time.perf_counter()
    try:
        stats = fuzz(args.inputs, seconds=args.seconds, seed=args.seed, bus=args.bus)
    finally:
        if cov is not None:
            cov.stop()
    elapsed = time.perf_counter() - started
    per_bus = ", ".join(f"{bus}: {n:,}" for bus, n in sorted(stats.by_bus.items()))
    print(f"inputs: {stats.inputs:,} in {stats.cases:,} cases ({per_bus}), {elapsed:.1f} s, "
          f"{stats.inputs / elapsed:,.0f} inputs/s")
    named = {code: name for name, code in globals().items() if isinstance(code, int) and name.isupper()
             and name in ("PING", "READ", "WRITE", "REG_WRITE", "ACTION", "FACTORY_RESET", "REBOOT", "CLEAR", "BACKUP",
                          "SYNC_READ", "SYNC_WRITE", "FAST_SYNC_READ", "BULK_READ", "BULK_WRITE", "FAST_BULK_READ")}
    rows: dict[str, list[str]] = {}
    for (instruction, outcome), count in sorted(CHECKED.items()):
        label = named.get(int(instruction, 16), f"undefined {instruction}") if instruction.startswith("0x") else instruction
        rows.setdefault(label, []).append(f"{outcome} {count:,}")
    print(f"2.0 packets checked: {sum(CHECKED.values()):,}")
    print("  replies checked, by model: " + ", ".join(f"{name} {n:,}" for name, n in sorted(CHECKED_MODELS.items())))
    for label, outcomes in rows.items():
        print(f"  {label}: {', '.join(outcomes)}")
    if cov is not None:
        report = io.StringIO()
        total = cov.report(file=report, show_missing=True, skip_empty=True)
        print(f"coverage, lines and branches of the Protocol 2.0 modules: {total:.1f} %")
        print(report.getvalue().rstrip())
    return fuzz1.report_failure(stats, args.failure_file, "fuzz2.py")


if __name__ == "__main__":
    sys.exit(main())
