"""What a Protocol 2.0 servo does with one instruction, and what it answers.

Why it exists: the policy of Protocol 2.0 (which error number, what is written, who answers)
lives here in one place, one small handler per instruction in a table keyed by instruction code;
the bus decides who hears a packet and when each answer goes out.  Wire errors are values
(:class:`~ax12emu.protocol.packets2.ErrorNumber`); nothing here raises on bad input.

Policy, with sources (ROBOTIS e-manual, "DYNAMIXEL Protocol 2.0"; X series "Status Return Level(68)"):

* the status error byte is this instruction's error number, with bit 7 (Alert) set while Hardware
  Error Status is non-zero ("Status Packet > Error");
* Status Return Level 0 answers PING only, 1 PING and the read instructions (Read, Sync Read,
  Bulk Read and their fast forms: the e-manual says "READ Instruction"; a Sync Read that nobody
  answered would be useless), 2 everything; PING is answered "regardless of the Status Return Level";
* a packet to this ID whose CRC does not match: CRC Error (3) (see :class:`Servo2Options`);
* an undefined instruction, or Action with nothing registered: Instruction Error (2);
* parameters whose structure is wrong (a Read without its 4 bytes, a Clear without its fixed
  bytes, a Factory Reset option not in the table): Result Fail (1), "Failed to process the sent
  Instruction Packet" -- the e-manual names no error for them;
* Write, Reg Write, Sync Write and Bulk Write: the table's checks (:mod:`ax12emu.servo.table2`),
  Access, Data Length, Data Range, Data Limit, all or nothing;
* Clear while moving: Result Fail ("Clear (0x10)"); Control Table Backup store with the torque
  on: Result Fail; restore with nothing stored: Result Fail;
* Factory Reset 0xFF sent to the broadcast ID is not executed (X series FW42 and later);
* the status packet is built before the instruction takes effect on ID, baud, Return Delay Time
  and Status Return Level: a servo whose ID changes answers from its old ID, and Factory Reset and
  Reboot answer before they reset (the e-manual's examples answer from ID 1 after both);
* a READ that fails still carries the bytes asked for, zero (up to the table's size):
  dynamixel-sdk indexes the data of an erroring reply, and a short one would crash the client
  instead of reporting the error.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable, Mapping
from typing import NamedTuple

from ax12emu.protocol.packets import BROADCAST_ID
from ax12emu.protocol.packets2 import (
    ALERT_BIT,
    ErrorNumber,
    Instruction2,
    InstructionPacket2,
    Malformed,
    encode_status2,
)
from ax12emu.protocol.params2 import (
    BackupOption,
    BulkWrite,
    Clear,
    ControlTableBackup,
    FactoryReset,
    FactoryResetOption,
    Params,
    Read,
    SyncWrite,
    Write,
    parse_params,
)

from .servo2 import Servo2

__all__ = ["HANDLERS", "READ_INSTRUCTIONS", "Outcome2", "answers", "first_writes", "handle2", "listed_read", "params_bytes",
           "parsed_params", "status_byte", "sync_write_all"]

#: ``parse_params`` remembered for the last packets: a broadcast Sync/Bulk Write reaches every servo,
#: and each would parse the same parameters again, and a robot sends the same Sync Read every cycle
#: (the results are frozen, so sharing them is safe).  ``params`` must be ``bytes`` (hashable).
parsed_params = functools.lru_cache(maxsize=64)(parse_params)

#: Instructions Status Return Level 1 answers besides PING.
READ_INSTRUCTIONS = frozenset(int(i) for i in (Instruction2.READ, Instruction2.SYNC_READ, Instruction2.BULK_READ,
                                               Instruction2.FAST_SYNC_READ, Instruction2.FAST_BULK_READ))
#: Registers Factory Reset keeps, per option ("Factory Reset (0x06) > Parameters").
FACTORY_RESET_KEEPS: Mapping[FactoryResetOption, tuple[str, ...]] = {
    FactoryResetOption.ALL: (),
    FactoryResetOption.ALL_EXCEPT_ID: ("id",),
    FactoryResetOption.ALL_EXCEPT_ID_AND_BAUD_RATE: ("id", "baud_rate"),
}


class Outcome2(NamedTuple):
    """What one servo does in answer to one packet."""

    #: The encoded status packet, or None for silence.
    reply: bytes | None
    #: The ID the reply carries (the ID at reception).
    reply_id: int
    #: Return Delay Time at reception, seconds.
    delay_s: float
    #: This instruction's error number (also in the reply, when there is one).
    error: int = ErrorNumber.NONE
    #: The reply's parameters (a read's data), for replies the bus assembles itself.
    data: bytes = b""


Handler = Callable[[Servo2, Params], tuple[int, bytes]]


def status_byte(servo: Servo2, error: int) -> int:
    """The status packet's error byte: the error number and the Alert bit."""
    return error | (ALERT_BIT if servo.alert else 0)


def listed_read(servo: Servo2, address: int, length: int) -> tuple[int, bytes]:
    """One servo's share of a Read, Sync Read or Bulk Read: the error number and ``length`` bytes."""
    data, error = servo.table.read(address, length)
    return error, data


def _ping(servo: Servo2, params: Params) -> tuple[int, bytes]:
    table = servo.table
    return ErrorNumber.NONE, table.get("model_number").to_bytes(2, "little") + bytes((table.get("firmware_version"),))


def _read(servo: Servo2, params: Read) -> tuple[int, bytes]:
    if params.address + params.length > servo.table.size:
        # "If the requested item is outside the range of the Control Table, the returned Status packet will include
        # an Access Error in its error field, and return with no parameters" (e-manual, Protocol 2.0, Read): a client
        # that indexes the data anyway (dynamixel-sdk's read4ByteTxRx) fails here as on a real servo.
        return ErrorNumber.ACCESS, b""
    return listed_read(servo, params.address, params.length)


def _write(servo: Servo2, params: Write) -> tuple[int, bytes]:
    return servo.write(params.address, params.data), b""


def _reg_write(servo: Servo2, params: Write) -> tuple[int, bytes]:
    # Judged as a Write when registered: through the Secondary ID the EEPROM area is refused ("The EEPROM area of
    # the Control Table cannot be modified with control packets addressed to a Secondary ID(12)", e-manual,
    # Secondary(Shadow) ID), or a broadcast Action would carry an ID or baud change to every servo sharing it.
    error = servo.judge_write(params.address, params.data)
    if error:
        return error, b""
    servo.registered_write = (params.address, params.data)
    if servo.table.has("registered_instruction"):
        servo.table.set("registered_instruction", 1)
    return ErrorNumber.NONE, b""


def _action(servo: Servo2, params: Params) -> tuple[int, bytes]:
    if servo.registered_write is None:
        return ErrorNumber.INSTRUCTION, b""
    address, data = servo.registered_write
    servo.registered_write = None
    if servo.table.has("registered_instruction"):
        servo.table.set("registered_instruction", 0)
    return servo.write(address, data), b""


def _factory_reset(servo: Servo2, params: FactoryReset) -> tuple[int, bytes]:
    return ErrorNumber.NONE, b""  # done after the reply is built: see AFTER_REPLY


def _reboot(servo: Servo2, params: Params) -> tuple[int, bytes]:
    return ErrorNumber.NONE, b""  # done after the reply is built: see AFTER_REPLY


def _clear(servo: Servo2, params: Clear) -> tuple[int, bytes]:
    if servo.table.has("moving") and servo.table.get("moving"):
        return ErrorNumber.RESULT_FAIL, b""
    servo.plant.clear_multi_turn()
    return ErrorNumber.NONE, b""


def _backup(servo: Servo2, params: ControlTableBackup) -> tuple[int, bytes]:
    """Store the table, or check a restore can run (it runs after the reply).  Either way only with the torque
    off: "If the Torque Enable is set as '1' (Torque On), Status Packet with Result Fail will be returned"
    (e-manual, Protocol 2.0, Control Table Backup)."""
    table = servo.table
    if table.torque_on:
        return ErrorNumber.RESULT_FAIL, b""
    if params.option is BackupOption.STORE:
        servo.backup = bytes(table.row)
        servo.eeprom_dirty = True  # the backup area is non-volatile too: a state store keeps it
        if table.has("backup_ready"):
            table.set("backup_ready", 1)
        return ErrorNumber.NONE, b""
    if servo.backup is None:
        return ErrorNumber.RESULT_FAIL, b""
    return ErrorNumber.NONE, b""  # the restore and its reboot follow the reply: see AFTER_REPLY


def _sync_write(servo: Servo2, params: SyncWrite) -> tuple[int, bytes]:
    for servo_id, data in params.writes:
        if servo_id == servo.id:
            return servo.write(params.address, data), b""
    return ErrorNumber.NONE, b""


def sync_write_all(servos: Iterable[Servo2], packet: InstructionPacket2) -> None:
    """:func:`handle2` of a broadcast Sync Write with a good CRC on each of ``servos`` in turn, as one call.

    The same outcome: each servo writes the data listed first under its ID (``_sync_write``), a servo
    not listed does nothing, malformed parameters write nothing, and nobody answers a broadcast.  Why:
    a robot's control cycle sends one every cycle, and the parameters are looked at once here instead
    of once per servo, each searching the list for its ID.
    """
    params = parsed_params(packet.instruction, params_bytes(packet))
    if isinstance(params, Malformed):
        return  # Result Fail on every servo, which nobody reports
    first = first_writes(params)
    address = params.address
    for servo in servos:
        data = first.get(servo.id)  # its ID now: a servo ahead of it may have taken another one
        if data is not None:
            servo.write(address, data)


def params_bytes(packet: InstructionPacket2) -> bytes:
    """A packet's parameters as ``bytes`` (hashable, as ``parsed_params`` needs them), copied only if they are not."""
    return packet.params if type(packet.params) is bytes else bytes(packet.params)


def first_writes(params: SyncWrite) -> dict[int, bytes]:
    """Each ID's data in a Sync Write: the first listed under it (a servo listed twice takes its first)."""
    first: dict[int, bytes] = {}
    for servo_id, data in params.writes:
        first.setdefault(servo_id, data)
    return first


def _bulk_write(servo: Servo2, params: BulkWrite) -> tuple[int, bytes]:
    own = servo.id
    error = ErrorNumber.NONE
    for servo_id, address, data in params.writes:
        if servo_id == own:
            error = servo.write(address, data) or error
    return error, b""


#: One handler per instruction a servo executes on its own; the listed reads are the bus's
#: (it orders the answers), built from :func:`listed_read`.
HANDLERS: Mapping[int, Handler] = {
    Instruction2.PING: _ping,
    Instruction2.READ: _read,
    Instruction2.WRITE: _write,
    Instruction2.REG_WRITE: _reg_write,
    Instruction2.ACTION: _action,
    Instruction2.FACTORY_RESET: _factory_reset,
    Instruction2.REBOOT: _reboot,
    Instruction2.CLEAR: _clear,
    Instruction2.CONTROL_TABLE_BACKUP: _backup,
    Instruction2.SYNC_WRITE: _sync_write,
    Instruction2.BULK_WRITE: _bulk_write,
}


def _restore(servo: Servo2, params: ControlTableBackup) -> None:
    if params.option is BackupOption.RESTORE and servo.backup is not None:
        end = servo.table.layout.eeprom_end
        servo.table.row[:end] = servo.backup[:end]
        servo.eeprom_dirty = True
        servo.reboot()


#: What takes effect only once the reply is built (it changes the ID, baud or the whole table).
AFTER_REPLY: Mapping[int, Callable[[Servo2, Params], None]] = {
    Instruction2.FACTORY_RESET: lambda servo, params: servo.factory_reset(FACTORY_RESET_KEEPS[params.option]),
    Instruction2.REBOOT: lambda servo, params: servo.reboot(),
    Instruction2.CONTROL_TABLE_BACKUP: _restore,
}


def answers(servo: Servo2, instruction: int) -> bool:
    """Whether Status Return Level lets ``servo`` answer ``instruction`` (before errors)."""
    if instruction == Instruction2.PING:
        return True
    level = servo.status_return_level
    return level >= 2 or (level == 1 and instruction in READ_INSTRUCTIONS)


def _read_length(servo: Servo2, packet: InstructionPacket2) -> int:
    """Bytes a READ asked for (at most the table's size), so an erroring reply still carries them."""
    if packet.instruction == Instruction2.READ and len(packet.params) == 4:
        return min(packet.params[2] | (packet.params[3] << 8), servo.table.size)
    return 0


#: What a packet to the Secondary ID does not do: it "cannot modify" the EEPROM area (e-manual, Secondary ID(12)).
_NOT_BY_SECONDARY_ID = frozenset({int(Instruction2.FACTORY_RESET), int(Instruction2.CONTROL_TABLE_BACKUP)})


def handle2(servo: Servo2, packet: InstructionPacket2, *, secondary: bool = False) -> Outcome2:
    """Execute ``packet`` (addressed to ``servo``, its Secondary ID, or broadcast) and build the servo's own answer.

    Broadcast packets are executed here but answered by nobody (the bus calls this only for
    instructions a broadcast executes silently); the listed reads are the bus's.  A packet to the
    Secondary ID (``secondary``) is executed without an answer ("If Instruction Packet ID is the
    same as Secondary ID(12), the Status Packet will not be returned") and reaches the RAM area only.
    """
    if secondary:
        if packet.instruction in _NOT_BY_SECONDARY_ID:
            return Outcome2(None, servo.id, servo.return_delay_s, ErrorNumber.ACCESS)
        servo.ram_only = True
        try:
            outcome = handle2(servo, packet._replace(id=BROADCAST_ID))
        finally:
            servo.ram_only = False
        return outcome
    reply_id = servo.id
    delay_s = servo.return_delay_s
    instruction = packet.instruction
    talks = packet.id != BROADCAST_ID and answers(servo, instruction)
    if not packet.crc_ok:
        error, data = ErrorNumber.CRC, bytes(_read_length(servo, packet))
        talks = talks and servo.options.reply_on_crc_error
    else:
        params = parsed_params(instruction, params_bytes(packet))
        handler = None if instruction in servo.spec.unsupported_instructions else HANDLERS.get(instruction)
        if handler is None:
            error, data = ErrorNumber.INSTRUCTION, bytes(_read_length(servo, packet))
        elif isinstance(params, Malformed):
            error, data = ErrorNumber.RESULT_FAIL, bytes(_read_length(servo, packet))
        elif (packet.id == BROADCAST_ID and instruction == Instruction2.FACTORY_RESET
              and params.option is FactoryResetOption.ALL and servo.spec.broadcast_reset_all == "refused"):
            return Outcome2(None, reply_id, delay_s, ErrorNumber.NONE)
        else:
            error, data = handler(servo, params)
            reply = encode_status2(reply_id, status_byte(servo, error), data) if talks else None
            after = AFTER_REPLY.get(instruction)
            if after is not None and not error:
                after(servo, params)
            return Outcome2(reply, reply_id, delay_s, error, data)
    reply = encode_status2(reply_id, status_byte(servo, error), data) if talks else None
    return Outcome2(reply, reply_id, delay_s, error, data)

