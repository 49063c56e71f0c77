"""Fuzz the framer and the servos' request handling, with an oracle checked after every input.

A case is a stream of mostly near-valid instruction packets (right header,
LENGTH and checksum; random IDs, instructions, addresses, lengths and
values), mutated ones (a flipped byte or checksum, a cut, a wrong LENGTH,
stray 0xFF) and raw garbage, cut into chunks fed to a two-servo
:class:`ax12emu.bus.bus.Bus` in virtual time, sometimes after a pause longer
than the framer's silence timeout and sometimes after a physics step.

After every input (one chunk) the harness checks:

* no exception escapes, and the chunk is handled within ``HANG_S``;
* the framer holds less than one maximal frame;
* every control-table byte equals what an independent model of the
  instruction rules predicts (:class:`Oracle`): bytes change only through a
  valid WRITE, REG_WRITE + ACTION, SYNC_WRITE or RESET addressed to that
  servo, read-only and unused bytes never change, the firmware-owned
  Present*/Moving bytes change only through physics or RESET, and Alarm
  Shutdown may only zero Torque Limit (Torque Enable in the 2006 profile)
  while an alarm it selects is raised, and must when an instruction's
  Range, Checksum or Instruction Error it selects comes;
* the replies are those predicted (who answers, from which ID, with which
  error bits, READ data), and each parses: header, LENGTH, checksum, bit 7
  of the error byte clear;

and at the end of each case a PING after a pause is answered cleanly.

A third of the cases run on the MX wire instead (:class:`ax12emu.bus.bus1x.Bus1X`: an MX-28 and
an MX-64, each its model file's table with the X-series firmware behind it, and an AX-12A beside
them), fed the same grammar plus whole MX registers (by the model files' layouts) and Bulk Reads.
The AX-12A is checked as above; for the MX servos, whose write rules this oracle does not restate,
the checks are those any Protocol 1.0 servo keeps, per packet (the wire's ``dispatch`` wrapped):

* every MX reply parses (header, LENGTH, checksum, bit 7 clear) and comes from the ID the packet
  named (a Bulk Read: the listed IDs in list order, a prefix of them; another broadcast but PING:
  none), no more replies than servos holding the ID;
* error bits valid: Checksum Error exactly when the packet's checksum is wrong, Instruction Error
  exactly for an undefined instruction (not judged for Action, Sync Write and Bulk Read sent to one
  ID), none and no data for a plain PING; a READ answers the length asked, its bytes the table's
  (but the sensed ones) when one servo holds the ID;
* table bytes change only by an accepted write to that servo (WRITE, SYNC_WRITE, ACTION of the
  registered write: each byte then holds what was written; refused, by its reply's error bits,
  nothing), Registered by REG_WRITE/ACTION, Torque Enable/Torque Limit as a write's side effects,
  RESET to the factory table (Torque Limit at Max Torque), or by the firmware (the sensed
  registers, Realtime Tick, an Alarm Shutdown clearing Torque Enable or Torque Limit); Torque Limit 0 after a
  packet whose reply carries a Range, Checksum or Instruction Error that Alarm Shutdown selects (a Bulk Read's
  too), and, where no reply tells, only where Shutdown selects one of them;
* at the end of a case every MX with an ID of its own answers a PING after a pause.

Protocol 2.0 servos, and a wire shared by 1.0 and 2.0 servos, are fuzzed by
``tools/fuzz2.py``, which drives this file's 1.0 grammar and oracle for the 1.0 side.

Usage::

    python tools/fuzz.py --inputs 1000000          # the full run, both wires
    python tools/fuzz.py --wire mx --seconds 10    # a quick one on the MX wire
    python tools/fuzz.py --seconds 5 --no-coverage # a quick one
    python tools/fuzz.py --replay failure.json     # rerun a reported failure

Generation: one packet grammar, driven two ways.  In the test suite
hypothesis draws every choice (``DataChooser``), so a failure shrinks.  Here,
for volume, hypothesis draws each case's seed and length and a seeded PRNG
expands the grammar (``RandomChooser``, ~20x faster); a failing case is then
minimised by delta debugging and written as JSON for ``--replay``.  It is
not coverage-guided; coverage is measured with coverage.py over the ax12emu
modules the target reaches and printed with the missed lines.
"""

from __future__ import annotations

import dataclasses
import io
import json
import random
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: Modules the target exercises, for the coverage figure.
TARGET_MODULES = ("protocol/framing", "protocol/packets", "protocol/control_table", "servo/request_handler",
                  "servo/virtual_servo", "servo/plant", "bus/bus", "bus/clock", "bus/bus1x", "servo/servo1x",
                  "servo/request_handler1x", "servo/plant1x")


sys.path.insert(0, str(Path(__file__).resolve().parent))
from fuzz_coverage import start_coverage  # noqa: E402  (imports nothing of ax12emu)

_COVERAGE = start_coverage(TARGET_MODULES, sys.argv) if __name__ == "__main__" else None

import hypothesis  # noqa: E402
import numpy as np  # noqa: E402
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from ax12emu.bus.bus import Bus
from ax12emu.bus.bus1x import Bus1X
from ax12emu.bus.clock import VirtualClock
from ax12emu.cli.arg_types import OneLineParser, file_name, positive_float, positive_int
from ax12emu.protocol.control_table import TABLE_SIZE, Access, layout
from ax12emu.protocol.framing import DEFAULT_SILENCE_TIMEOUT_S, MAX_FRAME_BYTES, Framer
from ax12emu.protocol.packets import BROADCAST_ID, Instruction, StatusError, checksum, encode_instruction, encode_status
from ax12emu.protocol.servo_models import model as servo_model
from ax12emu.servo.model_factory import ModelChoice, build_model
from ax12emu.servo.plant1x import build_plant1x
from ax12emu.servo.servo1x import Servo1XOptions
from ax12emu.servo.virtual_servo import ServoOptions, baud_bps

#: One chunk taking longer than this counts as a hang.
HANG_S = 2.0
#: Bytes the physics writes (Present Position .. Present Temperature, Moving).
FIRMWARE_OWNED = frozenset(range(36, 44)) | {46}
SLOTS = (1, 2)
#: Instructions that write tables: after one, the bus runs a control step before the next packet.
WRITES = frozenset({Instruction.WRITE, Instruction.ACTION, Instruction.SYNC_WRITE, Instruction.RESET})
PAUSE_S = DEFAULT_SILENCE_TIMEOUT_S * 1.5

R = StatusError.RANGE
#: Bytes an Alarm Shutdown clears: Torque Limit (34, 35), or Torque Enable (24) in the 2006 profile.
SHUTDOWN_CLEARED = frozenset({24, 34, 35})
#: The error bits the physics raises (the others answer the instruction).
PHYSICAL_ALARMS = int(StatusError.INPUT_VOLTAGE | StatusError.OVERHEATING | StatusError.OVERLOAD)
#: An instruction's errors that Alarm Shutdown(18) may select besides Angle Limit (Range, CheckSum, Instruction:
#: e-manual, control_table_alarm_shutdown.md, "the motor output becomes 0 % by resetting ... Torque Limit(34) to 0"):
#: where it selects one, that error zeroes Torque Limit (Torque Enable in the 2006 profile); a bad checksum only on
#: a servo that answers it (``reply_on_checksum_error``: a silent one drops the packet unheard).
SHUTDOWN_INSTRUCTION_BITS = int(StatusError.RANGE | StatusError.CHECKSUM | StatusError.INSTRUCTION)


class FuzzFailure(AssertionError):
    """An invariant broke; the message says which and where."""


# -- the oracle -------------------------------------------------------------------------
@dataclass
class ShadowServo:
    """What the oracle believes one servo holds."""

    row: np.ndarray
    registered: tuple[int, bytes] | None = None
    #: Bytes the packet being handled wrote into the EEPROM area, and until when the servo is deaf for it.
    eeprom_bytes: int = 0
    busy_until_s: float = float("-inf")


@dataclass
class Predicted:
    """A reply the oracle expects: from ``servo_id`` with these error bits and data."""

    slot: int
    servo_id: int
    error: int
    data: bytes
    #: READ: (address, length) whose non-firmware bytes must match the table.
    read: tuple[int, int] | None = None


class Oracle:
    """An independent statement of the Protocol 1.0 write rules, from the control table's data only."""

    def __init__(self, rows: np.ndarray, options: ServoOptions, line_bps: float | None) -> None:
        self.layout = layout(options.profile)
        self.options = options
        self.line_bps = line_bps
        self.servos = [ShadowServo(row.copy()) for row in rows]
        self.entry_at: list[Any] = [None] * TABLE_SIZE
        for entry in self.layout.entries:
            for address in range(entry.address, entry.end):
                self.entry_at[address] = entry
        self.defaults = np.frombuffer(self.layout.defaults, dtype=np.uint8)

    # -- write rules ---------------------------------------------------------------------
    def _check(self, row: np.ndarray, address: int, data: bytes) -> tuple[np.ndarray | None, int]:
        """Validate a write's bytes: range, access, the Lock window."""
        end = address + len(data)
        if not data or end > TABLE_SIZE:
            return None, R
        window = self.layout.profile.lock_writable
        if row[47] and not (address in window and end - 1 in window):
            return None, R
        entries = []
        for a in range(address, end):
            entry = self.entry_at[a]
            if entry is None or entry.access is not Access.RW:
                return None, R
            if not entries or entries[-1] is not entry:
                entries.append(entry)
        candidate = row.copy()
        candidate[address:end] = list(data)
        for entry in entries:
            value = int.from_bytes(bytes(candidate[entry.address : entry.end]), "little")
            if not entry.minimum <= value <= entry.maximum:
                return None, R
        return candidate, 0

    def _judge(self, row: np.ndarray, address: int, data: bytes) -> tuple[np.ndarray | None, int]:
        """Validate a WRITE or a REG_WRITE fully (range, access, Lock window, Lock release, the Angle Limit rule)."""
        candidate, error = self._check(row, address, data)
        if candidate is None:
            return None, error
        if row[47] and not candidate[47]:
            return None, R
        if address <= 31 and address + len(data) > 30:
            cw = int(candidate[6]) | int(candidate[7]) << 8
            ccw = int(candidate[8]) | int(candidate[9]) << 8
            goal = int(candidate[30]) | int(candidate[31]) << 8
            if (cw or ccw) and not cw <= goal <= ccw:
                return None, StatusError.ANGLE_LIMIT
        return candidate, 0

    def _write(self, shadow: ShadowServo, address: int, data: bytes) -> int:
        """A WRITE (or an ACTION's): validated as :meth:`_judge`, applied if valid; a goal past the Angle Limits
        with Alarm Shutdown's Angle Limit bit set takes the output to 0 (Torque Limit 0)."""
        candidate, error = self._judge(shadow.row, address, data)
        if candidate is None:
            if error & StatusError.ANGLE_LIMIT and shadow.row[18] & StatusError.ANGLE_LIMIT:
                entry = self.layout.by_name[self.layout.profile.shutdown_clears or "torque_limit"]
                shadow.row[entry.address:entry.end] = 0  # as the edition's Alarm Shutdown does
            return error
        if address < 24:  # the EEPROM area: the servo writes it after answering, deaf meanwhile
            shadow.eeprom_bytes += min(len(data), 24 - address)
        if self.options.goal_position_enables_torque and address <= 33 and address + len(data) > 30:
            candidate[24] = 1  # a write touching Goal Position or Moving Speed turns the torque on
        shadow.row[:] = candidate
        return 0

    def _execute(self, shadow: ShadowServo, instruction: int, params: bytes) -> tuple[int, bytes, tuple | None]:
        row = shadow.row
        if instruction == Instruction.PING:
            return 0, b"", None
        if instruction == Instruction.READ:
            if len(params) != 2:
                return R, b"", None
            address, length = params
            n = min(length, 253)
            error = R if length > 253 or (n and address + n > TABLE_SIZE) else 0  # only missing bytes are an error
            data = bytes(row[address : min(address + n, TABLE_SIZE)]) if address < TABLE_SIZE else b""
            return error, data.ljust(n, b"\0"), (address, n)
        if instruction in (Instruction.WRITE, Instruction.REG_WRITE):
            if len(params) < 2:
                return R, b"", None
            if instruction == Instruction.WRITE:
                return self._write(shadow, params[0], params[1:]), b"", None
            candidate, error = self._judge(row, params[0], params[1:])
            if candidate is None:
                return error, b"", None
            shadow.registered = (params[0], params[1:])
            row[44] = 1
            return 0, b"", None
        if instruction == Instruction.ACTION:
            if shadow.registered is None:
                return StatusError.INSTRUCTION, b"", None
            address, data = shadow.registered
            shadow.registered = None
            row[44] = 0
            return self._write(shadow, address, data), b"", None
        if instruction == Instruction.RESET:
            if row[47]:  # Lock: the EEPROM area cannot be modified, a RESET refused as a write to it
                return StatusError.RANGE, b"", None
            present = row[36:38].copy()
            row[:] = self.defaults
            row[36:38] = present
            row[34:36] = row[14:16]  # Torque Limit loads Max Torque
            row[30:32] = present  # Goal Position follows Present Position
            row[44] = 0
            shadow.registered = None
            return 0, b"", None
        if instruction == Instruction.SYNC_WRITE:
            if len(params) < 2 or params[1] == 0 or (len(params) - 2) % (params[1] + 1):
                return R, b"", None
            size = params[1]
            for start in range(2, len(params), size + 1):
                if params[start] == row[3]:
                    return self._write(shadow, params[0], params[start + 1 : start + 1 + size]), b"", None
            return 0, b"", None
        return StatusError.INSTRUCTION, b"", None

    def packet(self, packet_id: int, instruction: int, params: bytes, checksum_ok: bool, now_s: float) -> list[Predicted]:
        """Apply one decoded packet, arriving at bus-clock time ``now_s``, to every servo it reaches; return the replies expected."""
        targets = [
            (slot, s) for slot, s in enumerate(self.servos) if packet_id == BROADCAST_ID or s.row[3] == packet_id
        ]
        out: list[Predicted] = []
        for slot, shadow in targets:
            baud = baud_bps(int(shadow.row[4]))
            if self.line_bps is not None and abs(self.line_bps - baud) > 0.03 * baud:
                continue  # deaf: listens at another rate
            if now_s < shadow.busy_until_s:
                continue  # deaf: writing its EEPROM
            reply_id = int(shadow.row[3])
            level = int(shadow.row[16])
            if packet_id == BROADCAST_ID:
                answers = instruction == Instruction.PING and self.options.reply_to_broadcast_ping
            else:
                answers = instruction == Instruction.PING or level >= 2 or (level == 1 and instruction == Instruction.READ)
            read = None
            if not checksum_ok:
                error = StatusError.CHECKSUM
                n = min(params[1], 253) if instruction == Instruction.READ and len(params) == 2 else 0
                data = bytes(n)
                answers = answers and self.options.reply_on_checksum_error
            else:
                error, data, read = self._execute(shadow, instruction, params)
                if instruction == Instruction.RESET and self.options.reset_reply_from_new_id:
                    reply_id = int(shadow.row[3])
                if shadow.eeprom_bytes and self.options.eeprom_busy_s_per_byte:
                    shadow.busy_until_s = now_s + shadow.eeprom_bytes * self.options.eeprom_busy_s_per_byte
                shadow.eeprom_bytes = 0
            if int(error) & int(shadow.row[18]) & SHUTDOWN_INSTRUCTION_BITS and (checksum_ok or self.options.reply_on_checksum_error):
                # Alarm Shutdown selects this instruction's error: output 0, as the edition's Alarm Shutdown makes it
                entry = self.layout.by_name[self.layout.profile.shutdown_clears or "torque_limit"]
                shadow.row[entry.address:entry.end] = 0
            if answers:
                out.append(Predicted(slot, reply_id, int(error), data, read))
        return out


# -- one case ---------------------------------------------------------------------------
class Reproducible:
    """A case as a JSON reproducer (for ``--replay FILE``): its options as they are, its inputs as
    ``[hex bytes, pause before, physics step before]``; shared by both fuzzers' cases."""

    inputs: list[tuple[bytes, float, float]]

    def to_json(self) -> str:
        """The reproducer's text."""
        document = {k: v for k, v in self.__dict__.items() if k != "inputs"}
        document["inputs"] = [[data.hex(), pause, dt] for data, pause, dt in self.inputs]
        return json.dumps(document)

    @classmethod
    def from_json(cls, text: str):
        """Read a reproducer written by :meth:`to_json`."""
        document = json.loads(text)
        inputs = [(bytes.fromhex(h), float(p), float(d)) for h, p, d in document.pop("inputs")]
        return cls(**document, inputs=inputs)


@dataclass
class Case(Reproducible):
    """Options of the bus and the inputs fed to it: (bytes, pause before, physics step before)."""

    profile: str = "ax12a"
    model: str = "kinematic"
    #: "ax12": two AX-12As (the oracle above); "mx": an MX-28, an MX-64 and an AX-12A (``run_mx_case``).
    wire: str = "ax12"
    reply_on_checksum_error: bool = True
    reply_to_broadcast_ping: bool = True
    reset_reply_from_new_id: bool = False
    goal_position_enables_torque: bool = True
    eeprom_busy_s_per_byte: float = 0.0
    line_bps: float | None = None
    inputs: list[tuple[bytes, float, float]] = field(default_factory=list)


def _parse_status(reply: bytes) -> tuple[int, int, bytes]:
    if len(reply) < 6 or reply[:2] != b"\xff\xff" or reply[3] != len(reply) - 4:
        raise FuzzFailure(f"malformed status packet {reply.hex()}")
    if checksum(reply[2:-1]) != reply[-1]:
        raise FuzzFailure(f"bad checksum in status packet {reply.hex()}")
    if reply[4] & 0x80:
        raise FuzzFailure(f"bit 7 set in status packet {reply.hex()}")
    return reply[2], reply[4], reply[5:-1]


def _options(case: Case) -> ServoOptions:
    """The AX-12As' options of ``case``."""
    return ServoOptions(
        profile=case.profile,
        reply_on_checksum_error=case.reply_on_checksum_error,
        reply_to_broadcast_ping=case.reply_to_broadcast_ping,
        reset_reply_from_new_id=case.reset_reply_from_new_id,
        goal_position_enables_torque=case.goal_position_enables_torque,
        eeprom_busy_s_per_byte=case.eeprom_busy_s_per_byte,
    )


def _predict(oracle: Oracle, packets: list, now_s: float) -> tuple[list, list[Predicted], set[int]]:
    """The AX-12 oracle's answers to one input's packets, and the slots a RESET among them reached.

    Why the slots: a RESET rewrites its servo's table, so the table checks after the input
    judge those slots by the reset rules rather than byte by byte.
    """
    predicted: list[Predicted] = []
    reset_slots: set[int] = set()
    for packet in packets:
        if packet.checksum_ok and packet.instruction == Instruction.RESET:
            reset_slots |= {i for i, s in enumerate(oracle.servos) if packet.id in (BROADCAST_ID, int(s.row[3]))}
        predicted += oracle.packet(packet.id, packet.instruction, packet.params, packet.checksum_ok, now_s)
    return packets, predicted, reset_slots


def run_case(case: Case) -> int:
    """Feed every input of ``case`` to a fresh bus, checking the invariants; return inputs fed."""
    if case.wire == "mx":
        return run_mx_case(case)
    options = _options(case)
    clock = VirtualClock()
    bus = Bus(list(SLOTS), options=options, clock=clock, model=build_model(ModelChoice(name=case.model, profile=case.profile), len(SLOTS)))
    oracle = Oracle(bus.rows, options, case.line_bps)
    shadow_framer = Framer()
    shutdown_register = layout(case.profile).profile.shutdown_clears
    wire_s = 0.0
    fed = 0
    for index, (data, pause_s, physics_dt_s) in enumerate(case.inputs):
        where = f"input {index} ({data.hex() or 'empty'})"
        wire_s += pause_s
        if physics_dt_s:
            clock.advance(physics_dt_s)
            bus.advance()
            _sync_physics(bus, oracle, shutdown_register, f"{where}, physics step")
        before = bus.rows.copy()
        alarms_before = [servo.alarms for servo in bus.servos]
        write_unseen, model_time_s = bus.plant.write_unseen, bus.plant.model.time_s
        started = time.perf_counter()
        replies = bus.receive(data, wire_s, line_bps=case.line_bps)
        if time.perf_counter() - started > HANG_S:
            raise FuzzFailure(f"{where}: took {time.perf_counter() - started:.1f} s")
        fed += 1
        if bus.framer.buffered >= MAX_FRAME_BYTES:
            raise FuzzFailure(f"{where}: framer holds {bus.framer.buffered} bytes")
        packets, predicted, reset_slots = _predict(oracle, shadow_framer.feed(data, wire_s), clock.now_s())
        # Physics catches up with the clock when a packet is handled, and the control step after a
        # write runs before the next packet is answered, so firmware bytes may change within this
        # input; the model may run ahead of the clock only for a write (before this input or in it).
        stepped = bus.plant.model.time_s != model_time_s
        ahead = bus.plant.model.time_s > max(model_time_s, clock.now_s()) + 1e-9
        wrote = write_unseen or any(p.checksum_ok and p.instruction in WRITES for p in packets)
        if ahead and not wrote:
            raise FuzzFailure(f"{where}: physics ran past the clock while handling packets, with no write before them")
        _check_replies(bus, oracle, replies, predicted, where, alarms_before, reset_slots)
        # RESET sets Goal Position to Present Position, which a control step after an earlier write
        # in the same input may have moved by the time the RESET ran (the oracle sees positions only
        # between inputs): there Goal Position is checked against nothing but its own rule below.
        goal_follows = reset_slots if stepped else set()
        # A write's consequence shows at the next request with no step when the model is already a
        # step past the clock (``Plant.catch_up``): the firmware acting on new commands between ticks.
        _check_tables(bus, oracle, before, reset_slots | (set(range(len(SLOTS))) if stepped or wrote else set()),
                      shutdown_register, where, goal_follows)
    # A PING after a pause is answered cleanly by every servo holding the ID (past any EEPROM write).
    wire_s += PAUSE_S
    busy_s = max(s.busy_until_s for s in oracle.servos) - clock.now_s()
    if busy_s > 0:
        clock.advance(busy_s)
    target = int(oracle.servos[0].row[3])
    replies = bus.receive(encode_instruction(target, Instruction.PING), wire_s)
    holders = [i for i, s in enumerate(oracle.servos) if int(s.row[3]) == target]
    expected = [encode_status(target, bus.servos[i].alarms) for i in holders]
    if [r.data for r in replies] != expected:
        raise FuzzFailure(f"PING to {target} after the inputs: got {[r.data.hex() for r in replies]}")
    return fed + 1


def _check_replies(bus: Bus, oracle: Oracle, replies: list, predicted: list[Predicted], where: str,
                   alarms_before: list[int], reset_slots: set[int] = frozenset()) -> None:
    """Each reply as predicted; its physical alarm bits may be those before the input or after it.

    A control step runs right after a write, within the input, so an alarm that a write cleared
    (a voltage limit reset) can still be in a reply sent before that step.  In a slot a RESET
    reached in the input, an alarm raised by that step (a write of the limits) and cleared by the
    RESET shows in neither: there the physical alarm bits are not judged.
    """
    if len(replies) != len(predicted):
        raise FuzzFailure(
            f"{where}: {len(replies)} replies {[r.data.hex() for r in replies]}, expected {len(predicted)} "
            f"from IDs {[p.servo_id for p in predicted]}"
        )
    for reply, expect in zip(replies, predicted):
        servo_id, status, data = _parse_status(reply.data)
        alarms = bus.servos[expect.slot].alarms | alarms_before[expect.slot]
        if expect.slot in reset_slots:
            alarms |= PHYSICAL_ALARMS
        if servo_id != expect.servo_id or reply.servo_id != servo_id:
            raise FuzzFailure(f"{where}: reply {reply.data.hex()} from ID {servo_id}, expected {expect.servo_id}")
        if (status & ~alarms) != (expect.error & ~alarms) or (status & expect.error) != expect.error:
            raise FuzzFailure(f"{where}: reply {reply.data.hex()} has error {status:#x}, expected {expect.error:#x}")
        if len(data) != len(expect.data):
            raise FuzzFailure(f"{where}: reply {reply.data.hex()} carries {len(data)} bytes, expected {len(expect.data)}")
        if expect.read is not None:
            address, _ = expect.read
            for k, (got, want) in enumerate(zip(data, expect.data)):
                if address + k < TABLE_SIZE and address + k not in FIRMWARE_OWNED and got != want:
                    # An Alarm Shutdown by the control step a write earned, taken in this input before
                    # the READ: the oracle's table learns of it after the input (``_shutdown_explains``).
                    if got == 0 and address + k in SHUTDOWN_CLEARED and alarms & int(bus.rows[expect.slot, 18]):
                        continue
                    raise FuzzFailure(f"{where}: READ of {address + k} gave {got}, table holds {want}")


def _check_tables(bus: Bus, oracle: Oracle, before: np.ndarray, firmware_free: set[int], shutdown_register: str,
                  where: str, goal_follows: set[int] = frozenset()) -> None:
    """Every byte as the rules say; firmware-owned bytes unchanged except in ``firmware_free`` slots (RESET, a step).

    In ``goal_follows`` slots Goal Position (30, 31) was set by a RESET to a Present Position the
    oracle did not see: it must lie within the position range, and is not compared byte by byte.
    """
    for slot, shadow in enumerate(oracle.servos):
        actual = bus.rows[slot]
        if slot in goal_follows:
            goal = int(actual[30]) | int(actual[31]) << 8
            if goal > 1023:
                raise FuzzFailure(f"{where}: slot {slot} Goal Position {goal} after RESET is outside 0..1023")
            shadow.row[30:32] = actual[30:32]
        for address in range(TABLE_SIZE):
            if address in FIRMWARE_OWNED:
                if slot not in firmware_free and actual[address] != before[slot, address]:
                    raise FuzzFailure(f"{where}: firmware byte {address} of slot {slot} changed without physics or RESET")
                continue
            if actual[address] != shadow.row[address]:
                if _shutdown_explains(bus, slot, address, shutdown_register):
                    continue
                raise FuzzFailure(
                    f"{where}: slot {slot} byte {address} is {actual[address]}, the rules give {shadow.row[address]} "
                    f"(was {before[slot, address]})"
                )
        shadow.row[:] = actual
        if (bus.servos[slot].registered_write is None) != (shadow.registered is None):
            raise FuzzFailure(f"{where}: slot {slot} registered write {bus.servos[slot].registered_write}, expected {shadow.registered}")


def _shutdown_explains(bus: Bus, slot: int, address: int, shutdown_register: str) -> bool:
    """Alarm Shutdown may zero Torque Limit (or Torque Enable) while a selected alarm is raised."""
    servo = bus.servos[slot]
    addresses = (34, 35) if shutdown_register == "torque_limit" else (24,)
    return address in addresses and bus.rows[slot, address] == 0 and bool(servo.alarms & int(bus.rows[slot, 18]))


def _sync_physics(bus: Bus, oracle: Oracle, shutdown_register: str, where: str) -> None:
    for slot, shadow in enumerate(oracle.servos):
        actual = bus.rows[slot]
        for address in range(TABLE_SIZE):
            if address not in FIRMWARE_OWNED and actual[address] != shadow.row[address]:
                if not _shutdown_explains(bus, slot, address, shutdown_register):
                    raise FuzzFailure(f"{where}: physics changed byte {address} of slot {slot}")
        shadow.row[:] = actual


# -- the MX wire: MX-series servos and an AX-12A on one Protocol 1.0 wire ------------------
#: An MX-28 and an MX-64 (each its model's table, the X-series firmware behind it: ``Bus1X``) and an
#: AX-12A beside them (on the AX-12 bus the wire holds, checked by :class:`Oracle` as above).
MX_SERVOS = ((1, "mx-28"), (2, "mx-64"))
MX_AX_IDS = (3,)
#: Registers an MX's firmware writes (what it senses, and the clock it keeps): they change with no write.
MX_SENSED = frozenset({"present_position", "present_speed", "present_load", "present_voltage", "present_temperature",
                       "moving", "current", "realtime_tick"})
#: What a write sets besides its own bytes: Goal Position may turn the torque on (``Servo1XOptions``), Angle
#: Limit Error with Shutdown's bit zeroes Torque Limit (e-manual, control_table_mx_goal_position.md).
MX_WRITE_SIDE = frozenset({"torque_enable", "torque_limit"})
#: Error bits an instruction's handling sets (the others are the servo's alarms: voltage, overheating, overload).
INSTRUCTION_BITS = int(StatusError.RANGE | StatusError.INSTRUCTION | StatusError.CHECKSUM | StatusError.ANGLE_LIMIT)
MX_KNOWN = frozenset({Instruction.PING, Instruction.READ, Instruction.WRITE, Instruction.REG_WRITE, Instruction.ACTION,
                      Instruction.RESET, Instruction.REBOOT, Instruction.SYNC_WRITE, Instruction.BULK_READ})
#: Instruction Error not judged: Action (an error without a registered write) and the instructions the e-manual
#: sends to the broadcast ID only (Sync Write, Bulk Read), whose answer sent to one ID it does not give.
MX_UNJUDGED = frozenset({Instruction.ACTION, Instruction.SYNC_WRITE, Instruction.BULK_READ})


class MXRules:
    """What the MX checks need of one model's table, read from its model file by register name."""

    def __init__(self, key: str) -> None:
        self.layout = servo_model(key).layout()
        self.size = self.layout.table_size
        self.defaults = bytes(self.layout.defaults)
        #: Where the RAM area begins: a REBOOT keeps the EEPROM area before it.
        self.ram_start = self.layout.eeprom_end
        self.by_name = self.layout.by_name
        self.at: list[Any] = [None] * self.size
        for entry in self.layout.entries:
            for address in range(entry.address, entry.end):
                self.at[address] = entry

    def span(self, *names: str) -> frozenset[int]:
        return frozenset(a for name in names if name in self.by_name
                         for a in range(self.by_name[name].address, self.by_name[name].end))


@dataclass
class MXRecord:
    """One packet the MX wire handled: tables of its MX servos before and after, registered writes, replies."""

    packet: Any
    line_bps: float | None
    before: list[bytes]
    after: list[bytes]
    registered: list[tuple[int, bytes] | None]
    replies: list
    ax_replies: int


def build_mx_wire(case: Case) -> tuple[Bus1X, Bus]:
    """The MX wire of ``case``: the MX servos on a ``Bus1X`` holding an AX-12 bus with the AX-12A."""
    clock = VirtualClock()
    options = _options(case)
    ax = Bus(list(MX_AX_IDS), options=options, clock=clock, model=build_model(ModelChoice(name=case.model, profile=case.profile), len(MX_AX_IDS)))
    mx_options = Servo1XOptions(reply_on_checksum_error=case.reply_on_checksum_error,
                                reply_to_broadcast_ping=case.reply_to_broadcast_ping,
                                goal_position_enables_torque=case.goal_position_enables_torque)
    wire = Bus1X([(i, servo_model(key)) for i, key in MX_SERVOS],
                 lambda spec, servo: build_plant1x(spec, servo.table), ax_bus=ax, clock=clock, options=mx_options)
    return wire, ax


def _record_mx(wire: Bus1X, ax: Bus, records: list[MXRecord]) -> None:
    """Wrap the wire's ``dispatch``: each packet with the MX tables just before and after it."""
    original, ax_original = wire.dispatch, ax.dispatch
    ax_count: list[int] = [0]

    def ax_dispatch(packet, *, line_bps=None):
        replies = ax_original(packet, line_bps=line_bps)
        ax_count[0] = len(replies)
        return replies

    def dispatch(packet, *, line_bps=None):
        now_s = wire.clock.now_s()
        wire.catch_up(now_s - wire.request_lag_s, now_s)  # physics first, so "before" is what the servos hold
        before = [bytes(s.table.row) for s in wire.servos_mx]
        registered = [s.registered_write for s in wire.servos_mx]
        ax_count[0] = 0
        replies = list(original(packet, line_bps=line_bps))
        records.append(MXRecord(packet, line_bps, before, [bytes(s.table.row) for s in wire.servos_mx], registered,
                                replies, ax_count[0]))
        return replies

    ax.dispatch = ax_dispatch
    wire.dispatch = dispatch


def _mx_between(rules: list[MXRules], old: list[bytes], new: list[bytes], where: str) -> None:
    """Between packets an MX table changes only in what its firmware writes, or by an Alarm Shutdown."""
    for k, (r, a, b) in enumerate(zip(rules, old, new)):
        free = r.span(*MX_SENSED) | r.span("torque_enable", "torque_limit")
        for address in range(r.size):
            if a[address] != b[address] and address not in free:
                raise FuzzFailure(f"{where}: between packets byte {address} ({_mx_name(r, address)}) of MX {k} changed "
                                  f"{a[address]} -> {b[address]}")
        for name in ("torque_enable", "torque_limit"):  # a shutdown only ever clears them
            entry = r.by_name[name]
            if entry.value_in(a) != entry.value_in(b) and entry.value_in(b) != 0:
                raise FuzzFailure(f"{where}: between packets {name} of MX {k} went {entry.value_in(a)} -> {entry.value_in(b)}")


def _mx_name(rules: MXRules, address: int) -> str:
    entry = rules.at[address] if address < rules.size else None
    return entry.name if entry is not None else "unused"


def _mx_writes(packet: Any, servo_id: int, registered: tuple[int, bytes] | None) -> list[tuple[int, bytes]] | str:
    """The writes ``packet`` asks of the MX holding ``servo_id`` ([] none), or "reset" (the factory table) or "reboot"
    (the RAM area's defaults).  A broadcast RESET is not carried out (e-manual: "Broadcast ID(0xFE) cannot be used
    for Reset instruction", MX firmware V40 on)."""
    code, params = packet.instruction, bytes(packet.params)
    if code == Instruction.RESET:
        return [] if packet.id == BROADCAST_ID else "reset"
    if code == Instruction.REBOOT:
        return "reboot"
    if code == Instruction.WRITE and len(params) >= 2:
        return [(params[0], params[1:])]
    if code == Instruction.ACTION and registered is not None:
        return [registered]
    if code == Instruction.SYNC_WRITE and len(params) >= 2 and params[1]:  # to one ID too, as the AX-12's oracle has it
        size = params[1]
        if (len(params) - 2) % (size + 1) == 0:
            return [(params[0], params[at + 1: at + 1 + size]) for at in range(2, len(params), size + 1)
                    if params[at] == servo_id][:1]
    return []


def _check_mx_record(rules: list[MXRules], record: MXRecord, where: str, reply_on_checksum_error: bool = True) -> None:
    """The invariants any Protocol 1.0 servo keeps, for the MX servos' part of one packet (see the docstring);
    ``reply_on_checksum_error``: the servos' option (a silent one drops a bad checksum unheard, no shutdown)."""
    packet = record.packet
    what = f"{where}, packet id={packet.id} inst={packet.instruction:#04x} params={bytes(packet.params).hex()}" \
           f"{'' if packet.checksum_ok else ' (bad checksum)'}"
    replies = record.replies[record.ax_replies:]
    ids_before = [r.by_name["id"].value_in(row) for r, row in zip(rules, record.before)]
    ids_after = [r.by_name["id"].value_in(row) for r, row in zip(rules, record.after)]
    reached = [k for k, i in enumerate(ids_before) if packet.id in (i, BROADCAST_ID)]
    broadcast = packet.id == BROADCAST_ID
    bulk = broadcast and packet.instruction == Instruction.BULK_READ and packet.checksum_ok
    if bulk:
        listed = _bulk_list(bytes(packet.params))
        if [r.servo_id for r in replies] != listed[: len(replies)]:
            raise FuzzFailure(f"{what}: Bulk Read answered by IDs {[r.servo_id for r in replies]}, listed {listed}")
    elif broadcast and packet.instruction != Instruction.PING and replies:
        raise FuzzFailure(f"{what}: {len(replies)} MX replies to a broadcast")
    elif len(replies) > len(reached):
        raise FuzzFailure(f"{what}: {len(replies)} MX replies, {len(reached)} MX servos hold ID {packet.id}")
    # In a Bulk Read, servos sharing an ID answer in its turn at once: the bus gives that turn's collided bytes.
    shared = {servo_id for servo_id in ids_before if ids_before.count(servo_id) > 1} if bulk else set()
    replies = [reply for reply in replies if reply.servo_id not in shared]
    for reply in replies:
        servo_id, error, data = _parse_status(reply.data)
        if servo_id != reply.servo_id or not (servo_id in ids_before or servo_id in ids_after):
            raise FuzzFailure(f"{what}: MX reply {reply.data.hex()} from ID {servo_id}, MX IDs {ids_before}")
        if not broadcast and servo_id != packet.id:
            raise FuzzFailure(f"{what}: MX reply {reply.data.hex()} from ID {servo_id}, not the packet's")
        if bool(error & StatusError.CHECKSUM) != (not packet.checksum_ok):
            raise FuzzFailure(f"{what}: MX reply {reply.data.hex()}: Checksum Error bit against the packet's checksum")
        if packet.checksum_ok and packet.instruction not in MX_UNJUDGED \
                and (packet.instruction not in MX_KNOWN) != bool(error & StatusError.INSTRUCTION):
            raise FuzzFailure(f"{what}: MX reply {reply.data.hex()}: Instruction Error bit against the instruction")
        if packet.checksum_ok and packet.instruction == Instruction.PING and (error & INSTRUCTION_BITS or data) \
                and not bytes(packet.params):
            raise FuzzFailure(f"{what}: MX reply {reply.data.hex()} to a plain PING carries an error or data")
        if packet.checksum_ok and packet.instruction == Instruction.READ and len(packet.params) == 2:
            address, length = bytes(packet.params)
            if len(data) != min(length, 253):
                raise FuzzFailure(f"{what}: MX READ of {length} bytes answered with {len(data)}")
            holders = [k for k in reached if ids_before[k] == servo_id]
            k = holders[0] if len(holders) == 1 else None  # MX servos sharing the ID each answer: whose is whose?
            if k is not None and not error & INSTRUCTION_BITS:
                sensed = rules[k].span(*MX_SENSED)
                for offset, byte in enumerate(data):
                    a = address + offset
                    if a not in sensed and byte != record.before[k][a]:
                        raise FuzzFailure(f"{what}: MX READ byte {a} ({_mx_name(rules[k], a)}) is {byte}, "
                                          f"the table holds {record.before[k][a]}")
    refused = {r.servo_id for r in replies if _parse_status(r.data)[1] & INSTRUCTION_BITS}
    errors = {r.servo_id: _parse_status(r.data)[1] for r in replies}
    heard = packet.checksum_ok or reply_on_checksum_error
    for k, r in enumerate(rules):
        old, new = record.before[k], record.after[k]
        torque_limit = r.by_name["torque_limit"]
        selected = r.by_name["shutdown"].value_in(old) & SHUTDOWN_INSTRUCTION_BITS if heard else 0
        sole = sum(ids_before[j] == ids_before[k] for j in range(len(rules))) == 1
        if sole and errors.get(ids_before[k], 0) & selected and torque_limit.value_in(new) != 0 \
                and (k in reached or bulk):
            raise FuzzFailure(f"{what}: MX {k} answered error {errors[ids_before[k]]:#x}, which Alarm Shutdown "
                              f"{r.by_name['shutdown'].value_in(old):#x} selects, and kept Torque Limit {torque_limit.value_in(new)}")
        if old == new:
            continue
        free = set(r.span(*MX_SENSED))
        if packet.checksum_ok and k in reached and not bulk and packet.instruction in (Instruction.REG_WRITE,
                                                                                      Instruction.ACTION):
            free |= r.span("registered")
        writes = _mx_writes(packet, ids_before[k], record.registered[k]) if packet.checksum_ok and k in reached else []
        if writes == "reset" and r.by_name["lock"].value_in(old):
            writes = []  # refused while Lock is 1, as the AX-12A refuses it
        if isinstance(writes, str):  # RESET: the factory table; REBOOT: its RAM area (both but for what power-up sets)
            boot = free | r.span("goal_position", "torque_limit")
            kept = range(r.ram_start) if writes == "reboot" else range(0)
            wrong = [a for a in range(r.size) if a not in boot and a not in kept and new[a] != r.defaults[a]]
            wrong += [a for a in kept if new[a] != old[a]]
            if wrong:
                raise FuzzFailure(f"{what}: after {writes.upper()} MX {k} byte {wrong[0]} ({_mx_name(r, wrong[0])}) is "
                                  f"{new[wrong[0]]}, the factory table holds {r.defaults[wrong[0]]}")
            if r.by_name["torque_limit"].value_in(new) != r.by_name["max_torque"].value_in(new):
                raise FuzzFailure(f"{what}: after {writes.upper()} MX {k} Torque Limit is not Max Torque")
            continue
        # Refused when its reply says so; with no reply (Status Return Level, broadcast) or a shared ID (whose
        # answer is whose?) only the written bytes may change, to what was written.
        shared = sum(ids_before[j] == ids_before[k] for j in reached) > 1
        accepted = ids_before[k] not in refused or broadcast or shared
        written: dict[int, int] = {}
        for address, data in writes if accepted else ():
            written.update({address + i: byte for i, byte in enumerate(data)})
        side = r.span(*MX_WRITE_SIDE) if writes else frozenset()
        if selected and (k in reached or bulk) and torque_limit.value_in(new) == 0:
            side = side | r.span("torque_limit")  # an instruction's error that Alarm Shutdown selects
        for a in range(r.size):
            if old[a] == new[a] or a in free or a in side:
                continue
            if a in written and new[a] == written[a]:
                continue
            raise FuzzFailure(f"{what}: MX {k} byte {a} ({_mx_name(r, a)}) changed {old[a]} -> {new[a]}, "
                              f"{'written ' + str(written.get(a)) if a in written else 'not written'}")


def _bulk_list(params: bytes) -> list[int]:
    """The IDs a Protocol 1.0 Bulk Read lists (0x00, then LEN ID ADDR each), first of each ID only."""
    if len(params) < 4 or (len(params) - 1) % 3 or params[0] != 0:
        return []
    out: list[int] = []
    for at in range(1, len(params), 3):
        if params[at + 1] not in out:
            out.append(params[at + 1])
    return out


def run_mx_case(case: Case) -> int:
    """Feed every input of an MX-wire ``case``: the MX servos' invariants per packet, the AX-12A's by :class:`Oracle`."""
    wire, ax = build_mx_wire(case)
    records: list[MXRecord] = []
    _record_mx(wire, ax, records)
    rules = [MXRules(key) for _, key in MX_SERVOS]
    shadow = [bytes(s.table.row) for s in wire.servos_mx]
    options = _options(case)
    oracle = Oracle(ax.rows, options, case.line_bps)
    ax_framer = Framer()
    shutdown_register = layout(case.profile).profile.shutdown_clears
    clock = wire.clock
    wire_s = 0.0
    fed = 0
    for index, (data, pause_s, physics_dt_s) in enumerate(case.inputs):
        where = f"input {index} ({data.hex() or 'empty'})"
        wire_s += pause_s
        if physics_dt_s:
            clock.advance(physics_dt_s)
            wire.advance()
            _sync_physics(ax, oracle, shutdown_register, f"{where}, physics step")
        before = ax.rows.copy()
        alarms_before = [servo.alarms for servo in ax.servos]
        write_unseen, model_time_s = ax.plant.write_unseen, ax.plant.model.time_s
        first = len(records)
        started_cpu_s, started_s = time.thread_time(), time.perf_counter()
        replies = wire.receive(data, wire_s, line_bps=case.line_bps)
        if time.thread_time() - started_cpu_s > HANG_S or time.perf_counter() - started_s > 5 * HANG_S:
            raise FuzzFailure(f"{where}: took {time.thread_time() - started_cpu_s:.1f} s of CPU")
        fed += 1
        if wire.framer.buffered >= MAX_FRAME_BYTES:
            raise FuzzFailure(f"{where}: framer holds {wire.framer.buffered} bytes")
        ax_replies = []
        for k, record in enumerate(records[first:]):
            _mx_between(rules, shadow, record.before, f"{where}, packet {k}")
            _check_mx_record(rules, record, f"{where}, packet {k}", case.reply_on_checksum_error)
            shadow = record.after
            ax_replies += record.replies[: record.ax_replies]
        if len(replies) != sum(len(r.replies) for r in records[first:]):
            raise FuzzFailure(f"{where}: {len(replies)} replies, the packets' dispatch gave another count")
        packets, predicted, reset_slots = _predict(oracle, ax_framer.feed(data, wire_s), clock.now_s())
        _check_replies(ax, oracle, ax_replies, predicted, f"{where} (AX-12A)", alarms_before, reset_slots)
        stepped = ax.plant.model.time_s != model_time_s
        wrote = write_unseen or any(p.checksum_ok and p.instruction in WRITES for p in packets)
        _check_tables(ax, oracle, before, reset_slots | (set(range(len(MX_AX_IDS))) if stepped or wrote else set()),
                      shutdown_register, f"{where} (AX-12A)", reset_slots if stepped else set())
    now = [bytes(s.table.row) for s in wire.servos_mx]
    _mx_between(rules, shadow, now, "after the inputs")
    # After a pause every MX servo with an ID of its own on the wire, at the line's rate, answers a PING cleanly.
    for servo in wire.servos_mx:
        wire_s += PAUSE_S
        if wire.ids.count(servo.id) != 1 or (case.line_bps is not None
                                             and abs(case.line_bps - servo.baud_bps) > 0.03 * servo.baud_bps):
            continue
        got = wire.receive(encode_instruction(servo.id, Instruction.PING), wire_s)
        if [r.data for r in got] != [encode_status(servo.id, servo.alarms)]:
            raise FuzzFailure(f"PING to MX {servo.id} after the inputs: got {[r.data.hex() for r in got]}")
    return fed + 1


# -- generation -------------------------------------------------------------------------
# The grammar is written once against a chooser, so hypothesis can drive it in the test
# suite (shrinkable draws) and a seeded PRNG can drive it at volume in this tool.
class RandomChooser:
    """Choices from a seeded PRNG: fast, for the million-input run."""

    def __init__(self, seed: int) -> None:
        self._rng = random.Random(seed)

    def integer(self, low: int, high: int) -> int:
        """An integer in low..high."""
        return self._rng.randint(low, high)

    def pick(self, options: tuple) -> Any:
        """One of ``options``."""
        return options[self._rng.randrange(len(options))]

    def binary(self, low: int, high: int) -> bytes:
        """Random bytes, low..high of them."""
        return self._rng.randbytes(self._rng.randint(low, high))


class DataChooser:
    """Choices drawn through hypothesis (``st.data()``): slower, but they shrink."""

    def __init__(self, data: st.DataObject) -> None:
        self._data = data

    def integer(self, low: int, high: int) -> int:
        """An integer in low..high."""
        return self._data.draw(st.integers(low, high))

    def pick(self, options: tuple) -> Any:
        """One of ``options``."""
        return self._data.draw(st.sampled_from(options))

    def binary(self, low: int, high: int) -> bytes:
        """Random bytes, low..high of them."""
        return self._data.draw(st.binary(min_size=low, max_size=high))


HOT_ADDRESSES = (0, 2, 3, 4, 5, 6, 7, 8, 10, 11, 12, 13, 14, 16, 18, 19, 20, 24, 29, 30, 31, 32, 34, 36, 44, 45, 46, 47, 48, 49)
HOT_VALUES = (0, 1, 2, 3, 4, 0x20, 0x64, 0x7F, 0x80, 0xFD, 0xFE, 0xFF)
HOT_IDS = (1, 2, 1, 2, BROADCAST_ID, 0, 3)
KINDS = ("write", "write", "read", "read", "reg", "action", "sync", "ping", "reset", "reboot", "other")


def _value(c: Any) -> int:
    return c.pick(HOT_VALUES) if c.integer(0, 1) else c.integer(0, 255)


def _address(c: Any) -> int:
    return c.pick(HOT_ADDRESSES) if c.integer(0, 3) else c.integer(0, 255)


def _id(c: Any) -> int:
    return c.pick(HOT_IDS) if c.integer(0, 3) else c.integer(0, 0xFE)


def _data(c: Any, low: int = 0, high: int = 4) -> bytes:
    return bytes(_value(c) for _ in range(c.integer(low, high)))


def instruction_packet(c: Any) -> bytes:
    """A well-framed instruction packet with plausible, often invalid, parameters."""
    kind = c.pick(KINDS)
    if kind in ("write", "reg"):
        code = Instruction.WRITE if kind == "write" else Instruction.REG_WRITE
        params = bytes([_address(c)]) + _data(c)
    elif kind == "read":
        code = Instruction.READ
        length = c.pick((0, 1, 2, 4, 50, 253, 254, 255)) if c.integer(0, 1) else c.integer(0, 255)
        params = bytes([_address(c), length])
        if c.integer(0, 9) == 0:
            params = params[: c.integer(0, 1)] + _data(c)
    elif kind == "sync":
        code = Instruction.SYNC_WRITE
        size = c.integer(0, 4)
        blocks = b"".join(bytes([_id(c)]) + _data(c, size, size) for _ in range(c.integer(0, 4)))
        params = bytes([_address(c), size]) + blocks
        if c.integer(0, 9) == 0:
            params += _data(c)
    elif kind == "other":
        code, params = c.integer(0, 255), _data(c)
    else:
        code = {"action": Instruction.ACTION, "ping": Instruction.PING, "reset": Instruction.RESET,
                "reboot": Instruction.REBOOT}[kind]
        params = _data(c) if c.integer(0, 7) == 0 else b""
    return encode_instruction(_id(c), code, params)


def mutated_packet(c: Any) -> bytes:
    """A packet with one of: a flipped bit, a bad checksum, a cut, a wrong LENGTH, extra 0xFF, junk inside."""
    packet = bytearray(instruction_packet(c))
    how = c.pick(("flip", "checksum", "cut", "length", "ff", "insert"))
    at = c.integer(0, len(packet) - 1)
    if how == "flip":
        packet[at] ^= 1 << c.integer(0, 7)
    elif how == "checksum":
        packet[-1] ^= c.integer(1, 255)
    elif how == "cut":
        del packet[at:]
    elif how == "length":
        packet[3] = c.integer(0, 3) if c.integer(0, 1) else c.integer(0, 255)
    elif how == "ff":
        packet[at:at] = b"\xff" * c.integer(1, 3)
    else:
        packet[at:at] = c.binary(1, 4)
    return bytes(packet)


def piece(c: Any) -> bytes:
    """Mostly valid packets, then mutated ones, then raw garbage."""
    roll = c.integer(0, 9)
    if roll < 6:
        return instruction_packet(c)
    if roll < 9:
        return mutated_packet(c)
    return c.binary(0, 12)


PAUSES = (0.0, 0.0, 0.0, 0.0, 1e-4, PAUSE_S)
PHYSICS_STEPS = (0.0,) * 14 + (0.001, 0.003)


_MX_RULES = [MXRules(key) for _, key in MX_SERVOS]


def mx_piece(c: Any) -> bytes:
    """On the MX wire: a whole MX register read or written (a value in its range mostly), a Bulk Read, or :func:`piece`."""
    roll = c.integer(0, 9)
    if roll < 3:
        entry = c.pick(_MX_RULES[c.integer(0, len(_MX_RULES) - 1)].layout.entries)
        code = c.pick((Instruction.WRITE, Instruction.WRITE, Instruction.REG_WRITE, Instruction.READ))
        if code == Instruction.READ:
            return encode_instruction(_id(c), code, bytes((entry.address, entry.size)))
        value = c.integer(entry.minimum, entry.maximum) if c.integer(0, 2) else c.integer(0, (1 << 8 * entry.size) - 1)
        return encode_instruction(_id(c), code, bytes((entry.address,)) + (value % (1 << 8 * entry.size)).to_bytes(entry.size, "little"))
    if roll < 5:
        reads = b"".join(bytes((c.pick((1, 2, 4, 8, 74, 0)), _id(c), c.pick((0, 24, 30, 36, 50, 68, 73, c.integer(0, 255)))))
                         for _ in range(c.integer(0, 4)))
        params = (b"\x00" if c.integer(0, 9) else _data(c, 1, 1)) + reads
        return encode_instruction(BROADCAST_ID if c.integer(0, 5) else _id(c), Instruction.BULK_READ, params)
    return piece(c)


def generate_case(c: Any, pieces: int, wire: str | None = None) -> Case:
    """Options plus a stream of ``pieces`` pieces, each fed whole, cut in two, or glued to the next.

    ``wire``: "ax12" or "mx" only; None: both, 2:1.
    """
    wire = wire or c.pick(("ax12", "ax12", "mx"))
    case = Case(
        wire=wire,
        profile=c.pick(("ax12a", "ax12a", "ax12-2006")),
        model=c.pick(("kinematic", "kinematic", "physical")),
        reply_on_checksum_error=bool(c.integer(0, 1)),
        reply_to_broadcast_ping=bool(c.integer(0, 1)),
        reset_reply_from_new_id=bool(c.integer(0, 1)),
        goal_position_enables_torque=bool(c.integer(0, 1)),
        # Mostly without the EEPROM busy time: while a servo is deaf, few other rules are reached.
        eeprom_busy_s_per_byte=c.pick((0.0, 0.0, 0.0, 0.002)),
        line_bps=c.pick((None, None, 1e6)),
    )
    case.inputs.extend(stream_inputs(c, pieces, mx_piece if wire == "mx" else piece, PAUSES, PHYSICS_STEPS))
    return case


def stream_inputs(c: Any, pieces: int, make_piece: Callable[[Any], bytes], pauses: Sequence[float],
                  physics_steps: Sequence[float]) -> list[tuple[bytes, float, float]]:
    """``pieces`` pieces from ``make_piece``, each fed whole, cut in two, or glued to the next, with a pause and a physics step after each."""
    inputs: list[tuple[bytes, float, float]] = []
    pending = b""
    for _ in range(pieces):
        data = pending + make_piece(c)
        pending = b""
        shape = c.pick(("whole", "whole", "cut", "glue"))
        if shape == "glue":
            pending = data
            continue
        parts = [data]
        if shape == "cut" and len(data) > 1:
            at = c.integer(1, len(data) - 1)
            parts = [data[:at], data[at:]]
        for part in parts:
            inputs.append((part, c.pick(pauses), c.pick(physics_steps)))
    if pending:
        inputs.append((pending, 0.0, 0.0))
    return inputs


def minimise(case: Any, budget: int = 2000, run: Callable[[Any], object] | None = None) -> Any:
    """Delta-debug a failing case: drop inputs, then pauses and physics steps, while ``run`` (default :func:`run_case`) still fails."""
    run = run or run_case

    def fails(candidate: Any) -> bool:
        try:
            run(candidate)
        except Exception:
            return True
        return False

    inputs = list(case.inputs)
    chunk = max(1, len(inputs) // 2)
    while chunk >= 1 and budget > 0:
        i, removed = 0, False
        while i < len(inputs) and budget > 0:
            trial = inputs[:i] + inputs[i + chunk :]
            budget -= 1
            if fails(dataclasses.replace(case, inputs=trial)):
                inputs, removed = trial, True
            else:
                i += chunk
        if not removed:
            chunk //= 2
    for i, (data, pause, dt) in enumerate(inputs):
        for simpler in ((data, 0.0, dt), (data, pause, 0.0)):
            trial = inputs[:i] + [simpler] + inputs[i + 1 :]
            if simpler != inputs[i] and fails(dataclasses.replace(case, inputs=trial)):
                inputs = trial
                data, pause, dt = simpler
    return dataclasses.replace(case, inputs=inputs)


# -- driver -----------------------------------------------------------------------------
@dataclass
class Stats:
    """Counts of one fuzzing run."""

    inputs: int = 0
    cases: int = 0
    failure: str | None = None
    reproducer: str | None = None
    by_wire: dict[str, int] = field(default_factory=dict)


def _watchdog(signum: int, frame: object) -> None:
    raise TimeoutError(f"one case ran over {HANG_S * 10:.0f} s: a hang")


def drive(stats: Any, make_case: Callable[[int, int], Any], run: Callable[[Any], int], shrink: Callable[[Any], Any],
          max_inputs: int, *, seconds: float | None = None, round_seed: Callable[[int], int] | None = None,
          pieces: int = 200, batch: int = 100, counted: Callable[[Any, int], None] | None = None) -> Any:
    """Run cases until ``max_inputs`` inputs were fed (or ``seconds`` passed) or one fails: both fuzzers' loop.

    Hypothesis draws each case's seed and length; ``make_case(seed, length)``
    expands the fuzzer's grammar into that many pieces and ``run`` feeds the
    case to its oracle, returning the inputs fed (``counted(case, fed)`` for
    the fuzzer's own tallies).  ``round_seed(k)`` seeds hypothesis's k-th
    round of ``batch`` cases (None: random).  The first failing case is
    minimised by ``shrink`` and kept in ``stats`` as a JSON reproducer, with
    its first error: hypothesis may report another of the batch's failures.
    ``stats`` needs ``inputs``, ``cases``, ``failure`` and ``reproducer``.
    """
    deadline = None if seconds is None else time.monotonic() + seconds
    failing: list[Any] = []
    first_error: list[str] = []
    use_alarm = threading.current_thread() is threading.main_thread()

    @settings(max_examples=batch, deadline=None, database=None, phases=(Phase.generate,),
              suppress_health_check=list(HealthCheck))
    @given(st.integers(0, 2**64 - 1), st.integers(1, pieces))
    def target(case_seed: int, count: int) -> None:
        if stats.inputs >= max_inputs or (deadline is not None and time.monotonic() > deadline):
            return  # budget spent: let hypothesis finish the batch cheaply
        case = make_case(case_seed, count)
        if use_alarm:
            signal.setitimer(signal.ITIMER_REAL, HANG_S * 10)
        try:
            fed = run(case)
        except BaseException as exc:
            if not failing:
                failing[:] = [case]
                first_error.append(f"{type(exc).__name__}: {exc}")
            raise
        finally:
            if use_alarm:
                signal.setitimer(signal.ITIMER_REAL, 0)
        stats.inputs += fed
        if counted is not None:
            counted(case, fed)
        stats.cases += 1

    previous = signal.signal(signal.SIGALRM, _watchdog) if use_alarm else None
    rounds = 0
    try:
        while stats.inputs < max_inputs and not (deadline is not None and time.monotonic() > deadline):
            if round_seed is not None:
                hypothesis.seed(round_seed(rounds))(target)
            rounds += 1
            target()
    except Exception as exc:
        stats.failure = first_error[0] if first_error else f"{type(exc).__name__}: {exc}"
        if failing:
            small = shrink(failing[0])
            try:
                run(small)
            except Exception as again:
                stats.failure += f"\nminimised ({len(small.inputs)} inputs): {type(again).__name__}: {again}"
            stats.reproducer = small.to_json()
    finally:
        if use_alarm:
            signal.signal(signal.SIGALRM, previous)
    return stats


def fuzz(
    max_inputs: int, *, seconds: float | None = None, seed: int | None = None, pieces: int = 200, batch: int = 100,
    wire: str | None = None,
) -> Stats:
    """Run Protocol 1.0 cases until ``max_inputs`` inputs were fed (or ``seconds`` passed) or one fails (:func:`drive`).

    A PRNG with each case's seed expands the grammar; a failing case is
    minimised by delta debugging and returned as a JSON reproducer.
    """
    stats = Stats()

    def counted(case: Case, fed: int) -> None:
        stats.by_wire[case.wire] = stats.by_wire.get(case.wire, 0) + fed

    return drive(stats, lambda case_seed, count: generate_case(RandomChooser(case_seed), count, wire), run_case,
                 # runs with nearby seeds must not share rounds
                 minimise, max_inputs, seconds=seconds, round_seed=None if seed is None else (lambda k: seed * 1_000_000 + k),
                 pieces=pieces, batch=batch, counted=counted)


def replay(path: str, load: Callable[[str], Any], run: Callable[[Any], int]) -> int:
    """Rerun the case written to ``path`` on a failure (``load`` reads its JSON); exit status 1 if it still fails,
    2 if the file holds no case of this fuzzer."""
    try:
        case = load(Path(path).read_text())
    except (OSError, ValueError, TypeError, KeyError) as exc:  # no file, not JSON, or another fuzzer's case
        print(f"error: {path}: not a case of this fuzzer ({type(exc).__name__}: {exc})", file=sys.stderr)
        return 2
    try:
        fed = run(case)
    except Exception as exc:
        print(f"FAIL: {type(exc).__name__}: {exc}")
        return 1
    print(f"ok: {fed} inputs pass")
    return 0


def report_failure(stats: Any, failure_file: str, tool: str) -> int:
    """Print the run's failure (writing its reproducer to ``failure_file``) and return 1, or "failures: 0" and 0."""
    if stats.failure:
        print(f"FAILURE: {stats.failure}")
        if stats.reproducer:
            Path(failure_file).write_text(stats.reproducer + "\n")
            print(f"reproducer written to {failure_file}: python tools/{tool} --replay {failure_file}")
            print(stats.reproducer)
        return 1
    print("failures: 0")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Parse arguments, fuzz, print figures; exit 1 on a failure."""
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--inputs", type=positive_int, default=1_000_000,
                        help="inputs (chunks) to feed (default 1,000,000)")
    parser.add_argument("--seconds", type=positive_float, help="stop after this long even if fewer inputs were fed")
    parser.add_argument("--seed", type=int, help="seed hypothesis (default: random)")
    parser.add_argument("--wire", choices=("ax12", "mx"), help="only this wire (default: both, 2:1)")
    parser.add_argument("--no-coverage", action="store_true", help="skip coverage measurement (faster)")
    parser.add_argument("--replay", type=file_name, metavar="FILE", help="rerun one case written on a failure")
    parser.add_argument("--failure-file", type=file_name, default="fuzz-failure.json",
                        help="where a failing case is written")
    args = parser.parse_args(argv)

    if args.replay:
        return replay(args.replay, Case.from_json, run_case)

    cov = _COVERAGE
    started = time.perf_counter()
    try:
        stats = fuzz(args.inputs, seconds=args.seconds, seed=args.seed, wire=args.wire)
    finally:
        if cov is not None:
            cov.stop()
    elapsed = time.perf_counter() - started
    per_wire = ", ".join(f"{wire}: {n:,}" for wire, n in sorted(stats.by_wire.items()))
    print(f"inputs: {stats.inputs:,} in {stats.cases:,} cases ({per_wire}), {elapsed:.1f} s, "
          f"{stats.inputs / elapsed:,.0f} inputs/s")
    if cov is not None:
        report = io.StringIO()
        total = cov.report(file=report, show_missing=True, skip_empty=True)
        print(f"coverage, lines and branches of ax12emu/{{{','.join(TARGET_MODULES)}}}.py: {total:.1f} %")
        print(report.getvalue().rstrip())
    return report_failure(stats, args.failure_file, "fuzz.py")


if __name__ == "__main__":
    sys.exit(main())
