"""What each Protocol 2.0 instruction's parameters say, as data and as parsers.

Why it exists: the servo (to execute), the trace decoder (to describe) and the
tests (to build requests) all need the parameter layouts of the e-manual's
"Instruction Details" sections; they are written once here.  Every parser
takes the unstuffed parameter bytes as they came off the wire and returns a
value or :class:`~.packets2.Malformed` with the reason; none raises.

Parsers check structure only (field counts, block sizes, the fixed key bytes
of Clear and Control Table Backup, the documented option values).  What a
servo answers to a structurally bad packet is not written in the e-manual, so
no error number is chosen here; the servo layer decides.  Semantic checks that
need the control table (address ranges, Data Length/Range/Limit, Access) are
the servo's too.

All multi-byte fields are little-endian ("Low-order byte ... High-order byte").
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from .crc16 import crc16
from .packets import BROADCAST_ID
from .packets2 import HEADER2, Instruction2, Malformed, StatusPacket2

__all__ = [
    "BACKUP_KEY",
    "CLEAR_KEY",
    "INSTRUCTION_SPECS",
    "BackupOption",
    "Broadcast",
    "BulkRead",
    "BulkWrite",
    "ClearOption",
    "ControlTableBackup",
    "Clear",
    "FactoryReset",
    "FactoryResetOption",
    "FastStatusEntry",
    "InstructionSpec",
    "NoParams",
    "Params",
    "PingReply",
    "Read",
    "SyncRead",
    "SyncWrite",
    "Write",
    "parse_fast_status",
    "parse_params",
    "parse_ping_reply",
]


class FactoryResetOption(enum.IntEnum):
    """Factory Reset's one parameter ("Factory Reset (0x06) > Parameters")."""

    #: Reset everything.  Not executed when sent to the broadcast ID (X series FW42 and later).
    ALL = 0xFF
    ALL_EXCEPT_ID = 0x01
    ALL_EXCEPT_ID_AND_BAUD_RATE = 0x02


class ClearOption(enum.IntEnum):
    """Clear's first parameter ("Clear (0x10)"); 0x02..0xFF are reserved."""

    #: Reset Present Position to within one turn; Result Fail while the servo is moving.
    MULTI_TURN = 0x01


class BackupOption(enum.IntEnum):
    """Control Table Backup's first parameter ("Control Table Backup (0x20)"); 0x03..0xFF are reserved."""

    #: Store the control table to the backup area (Result Fail with torque on).
    STORE = 0x01
    #: Restore EEPROM from the backup area, then reboot.
    RESTORE = 0x02


#: Clear's fixed parameters 2..5 ("DXL\"").
CLEAR_KEY = b"\x44\x58\x4c\x22"
#: Control Table Backup's fixed parameters 2..5 ("CTRL").
BACKUP_KEY = b"\x43\x54\x52\x4c"


class Broadcast(enum.Enum):
    """What an instruction sent to ID 0xFE does (e-manual, "Packet ID" warning and each instruction)."""

    #: Executed by every servo, each of which answers (Ping: in ID order; see the bus).
    EACH_ANSWERS = "each answers"
    #: Executed by every servo, none answers.
    SILENT = "executed, no answer"
    #: Not executed ("Read Instructions are not executed when sent to the Broadcast ID").
    NOT_EXECUTED = "not executed"
    #: Must be sent to 0xFE; the listed servos answer one by one, in the order listed.
    REQUIRED_EACH_ANSWERS = "broadcast only; listed servos answer in order"
    #: Must be sent to 0xFE; the listed servos build one combined status packet.
    REQUIRED_COMBINED_ANSWER = "broadcast only; one combined answer"
    #: Must be sent to 0xFE; no servo answers.
    REQUIRED_SILENT = "broadcast only; no answer"


@dataclass(frozen=True)
class InstructionSpec:
    """One row of the instruction table: its parameter layout and broadcast behaviour."""

    layout: str
    broadcast: Broadcast
    #: Anchor of the e-manual section on the "DYNAMIXEL Protocol 2.0" page.
    section: str


#: The e-manual's instructions, their parameters ("u16" little-endian) and what broadcast does.
INSTRUCTION_SPECS: Mapping[Instruction2, InstructionSpec] = {
    Instruction2.PING: InstructionSpec("(none)", Broadcast.EACH_ANSWERS, "#ping-0x01"),
    Instruction2.READ: InstructionSpec("address:u16 length:u16", Broadcast.NOT_EXECUTED, "#read-0x02"),
    Instruction2.WRITE: InstructionSpec("address:u16 data...", Broadcast.SILENT, "#write-0x03"),
    Instruction2.REG_WRITE: InstructionSpec("address:u16 data...", Broadcast.SILENT, "#reg-write-0x04"),
    Instruction2.ACTION: InstructionSpec("(none)", Broadcast.SILENT, "#action-0x05"),
    Instruction2.FACTORY_RESET: InstructionSpec("option:u8 (0xFF all, 0x01 keep ID, 0x02 keep ID and baud)",
                                                Broadcast.SILENT, "#factory-reset-0x06"),
    Instruction2.REBOOT: InstructionSpec("(none)", Broadcast.SILENT, "#reboot-0x08"),
    Instruction2.CLEAR: InstructionSpec("option:u8 (0x01) key:44 58 4C 22", Broadcast.SILENT, "#clear-0x10"),
    Instruction2.CONTROL_TABLE_BACKUP: InstructionSpec("option:u8 (0x01 store, 0x02 restore) key:43 54 52 4C",
                                                       Broadcast.SILENT, "#control-table-backup-0x20"),
    Instruction2.SYNC_READ: InstructionSpec("address:u16 length:u16 id...", Broadcast.REQUIRED_EACH_ANSWERS,
                                            "#sync-read-0x82"),
    Instruction2.SYNC_WRITE: InstructionSpec("address:u16 length:u16 (id data[length])...", Broadcast.REQUIRED_SILENT,
                                             "#sync-write-0x83"),
    Instruction2.FAST_SYNC_READ: InstructionSpec("address:u16 length:u16 id...", Broadcast.REQUIRED_COMBINED_ANSWER,
                                                 "#fast-sync-read-0x8a"),
    Instruction2.BULK_READ: InstructionSpec("(id address:u16 length:u16)...", Broadcast.REQUIRED_EACH_ANSWERS,
                                            "#bulk-read-0x92"),
    Instruction2.BULK_WRITE: InstructionSpec("(id address:u16 length:u16 data[length])...", Broadcast.REQUIRED_SILENT,
                                             "#bulk-write-0x93"),
    Instruction2.FAST_BULK_READ: InstructionSpec("(id address:u16 length:u16)...", Broadcast.REQUIRED_COMBINED_ANSWER,
                                                 "#fast-bulk-read-0x9a"),
}


@dataclass(frozen=True)
class NoParams:
    """Ping, Action, Reboot: nothing to parse."""


@dataclass(frozen=True)
class Read:
    address: int
    length: int


@dataclass(frozen=True)
class Write:
    """Write or Reg Write."""

    address: int
    data: bytes


@dataclass(frozen=True)
class FactoryReset:
    option: FactoryResetOption


@dataclass(frozen=True)
class Clear:
    option: ClearOption


@dataclass(frozen=True)
class ControlTableBackup:
    option: BackupOption


@dataclass(frozen=True)
class SyncRead:
    """Sync Read or Fast Sync Read: the same address and length from each listed servo, in list order."""

    address: int
    length: int
    ids: tuple[int, ...]


@dataclass(frozen=True)
class SyncWrite:
    address: int
    length: int
    #: (id, data) per servo, each data ``length`` bytes.
    writes: tuple[tuple[int, bytes], ...]


@dataclass(frozen=True)
class BulkRead:
    """Bulk Read or Fast Bulk Read.  The e-manual allows each ID once; duplicates are passed on, not judged."""

    #: (id, address, length) per servo, in the order they answer.
    reads: tuple[tuple[int, int, int], ...]


@dataclass(frozen=True)
class BulkWrite:
    #: (id, address, data) per servo.
    writes: tuple[tuple[int, int, bytes], ...]


Params = NoParams | Read | Write | FactoryReset | Clear | ControlTableBackup | SyncRead | SyncWrite | BulkRead | BulkWrite


def _u16(params: bytes, at: int) -> int:
    return params[at] | (params[at + 1] << 8)


def _no_params(params: bytes) -> NoParams | Malformed:
    return NoParams() if not params else Malformed(f"expects no parameters, got {len(params)}")


def _read(params: bytes) -> Read | Malformed:
    if len(params) != 4:
        return Malformed(f"expects 4 parameter bytes (address, length), got {len(params)}")
    return Read(_u16(params, 0), _u16(params, 2))


def _write(params: bytes) -> Write | Malformed:
    if len(params) < 2:
        return Malformed(f"expects a 2-byte address before the data, got {len(params)} bytes")
    return Write(_u16(params, 0), bytes(params[2:]))


def _option(params: bytes, options: type[enum.IntEnum], key: bytes | None) -> enum.IntEnum | Malformed:
    expected = 1 + (len(key) if key else 0)
    if len(params) != expected:
        return Malformed(f"expects {expected} parameter bytes, got {len(params)}")
    try:
        option = options(params[0])
    except ValueError:
        known = ", ".join(f"{o.value:#04x} {o.name}" for o in options)
        return Malformed(f"option {params[0]:#04x} is not one of {known}")
    if key is not None and bytes(params[1:]) != key:
        return Malformed(f"fixed bytes are {bytes(params[1:]).hex(' ')}, must be {key.hex(' ')}")
    return option


def _factory_reset(params: bytes) -> FactoryReset | Malformed:
    option = _option(params, FactoryResetOption, None)
    return option if isinstance(option, Malformed) else FactoryReset(FactoryResetOption(option))


def _clear(params: bytes) -> Clear | Malformed:
    option = _option(params, ClearOption, CLEAR_KEY)
    return option if isinstance(option, Malformed) else Clear(ClearOption(option))


def _backup(params: bytes) -> ControlTableBackup | Malformed:
    option = _option(params, BackupOption, BACKUP_KEY)
    return option if isinstance(option, Malformed) else ControlTableBackup(BackupOption(option))


def _sync_read(params: bytes) -> SyncRead | Malformed:
    if len(params) < 5:
        return Malformed(f"expects address, length and at least one ID (5 bytes), got {len(params)}")
    return SyncRead(_u16(params, 0), _u16(params, 2), tuple(params[4:]))


def _sync_write(params: bytes) -> SyncWrite | Malformed:
    if len(params) < 4:
        return Malformed(f"expects address and length (4 bytes) first, got {len(params)}")
    address, length = _u16(params, 0), _u16(params, 2)
    rest = params[4:]
    block = 1 + length
    if not rest or len(rest) % block:
        return Malformed(f"{len(rest)} bytes after the header are not whole blocks of ID + {length} data bytes")
    writes = tuple((rest[i], bytes(rest[i + 1 : i + block])) for i in range(0, len(rest), block))
    return SyncWrite(address, length, writes)


def _bulk_read(params: bytes) -> BulkRead | Malformed:
    if not params or len(params) % 5:
        return Malformed(f"{len(params)} bytes are not whole blocks of ID, address, length (5 bytes each)")
    return BulkRead(tuple((params[i], _u16(params, i + 1), _u16(params, i + 3)) for i in range(0, len(params), 5)))


def _bulk_write(params: bytes) -> BulkWrite | Malformed:
    if not params:
        return Malformed("expects at least one block of ID, address, length and data")
    writes: list[tuple[int, int, bytes]] = []
    at = 0
    while at < len(params):
        if len(params) - at < 5:
            return Malformed(f"block at byte {at} has {len(params) - at} bytes, fewer than ID, address and length")
        servo_id, address, length = params[at], _u16(params, at + 1), _u16(params, at + 3)
        end = at + 5 + length
        if end > len(params):
            return Malformed(f"block for ID {servo_id} announces {length} data bytes, {len(params) - at - 5} follow")
        writes.append((servo_id, address, bytes(params[at + 5 : end])))
        at = end
    return BulkWrite(tuple(writes))


_PARSERS: Mapping[int, Callable[[bytes], Params | Malformed]] = {
    Instruction2.PING: _no_params,
    Instruction2.READ: _read,
    Instruction2.WRITE: _write,
    Instruction2.REG_WRITE: _write,
    Instruction2.ACTION: _no_params,
    Instruction2.FACTORY_RESET: _factory_reset,
    Instruction2.REBOOT: _no_params,
    Instruction2.CLEAR: _clear,
    Instruction2.CONTROL_TABLE_BACKUP: _backup,
    Instruction2.SYNC_READ: _sync_read,
    Instruction2.SYNC_WRITE: _sync_write,
    Instruction2.FAST_SYNC_READ: _sync_read,
    Instruction2.BULK_READ: _bulk_read,
    Instruction2.BULK_WRITE: _bulk_write,
    Instruction2.FAST_BULK_READ: _bulk_read,
}


def parse_params(instruction: int, params: bytes | bytearray) -> Params | Malformed:
    """Parse an instruction's parameters; an undefined instruction is Malformed too (the servo's Instruction Error)."""
    parser = _PARSERS.get(instruction)
    if parser is None:
        return Malformed(f"instruction {instruction:#04x} is not defined in Protocol 2.0")
    return parser(bytes(params))


@dataclass(frozen=True)
class PingReply:
    """A Ping status packet's parameters ("Ping (0x01) > Packet Parameters")."""

    model_number: int
    firmware_version: int


def parse_ping_reply(params: bytes | bytearray) -> PingReply | Malformed:
    """Model number (u16) and firmware version (u8) from a Ping's status parameters."""
    if len(params) != 3:
        return Malformed(f"a Ping reply has 3 parameter bytes, got {len(params)}")
    return PingReply(_u16(bytes(params), 0), params[2])


@dataclass(frozen=True)
class FastStatusEntry:
    """One servo's share of a combined Fast Sync/Bulk Read status."""

    id: int
    error: int
    data: bytes
    #: This servo's running CRC matched (the last servo's is the packet CRC).
    crc_ok: bool


def parse_fast_status(status: StatusPacket2, data_length: int | Mapping[int, int]) -> list[FastStatusEntry] | Malformed:
    """Split a combined status (ID 0xFE) into its servos' entries, checking each running CRC.

    ``data_length`` is the Fast Sync Read's length, or for Fast Bulk Read a
    mapping of ID to length (each share carries its ID, as dynamixel-sdk's
    ``fastBulkReadRx`` relies on).  Layout, from "Fast Sync Read (0x8A)":
    ``ERR1 | ID1 DATA1 CRC1 | ERR2 ID2 DATA2 CRC2 | ... | ERRn IDn DATAn`` and
    the packet's CRC, where ``ERR1`` is the status packet's error byte.
    """
    if status.id != BROADCAST_ID:
        return Malformed(f"a combined status comes with ID 0xFE, got {status.id}")
    body = bytes((status.error,)) + bytes(status.params)
    # Rebuild the bytes as sent so each intermediate CRC can be checked; nothing was stuffed.
    length = len(body) + 3
    running = crc16(HEADER2 + bytes((BROADCAST_ID, length & 0xFF, length >> 8, Instruction2.STATUS)))
    entries: list[FastStatusEntry] = []
    at = 0
    while at < len(body):
        if len(body) - at < 2:
            return Malformed(f"share at byte {at} is cut before its ID")
        error, servo_id = body[at], body[at + 1]
        size = data_length if isinstance(data_length, int) else data_length.get(servo_id)
        if size is None:
            return Malformed(f"ID {servo_id} was not asked for")
        end = at + 2 + size
        last = end == len(body)
        if end > len(body) or (not last and end + 2 > len(body)):
            return Malformed(f"share of ID {servo_id} is shorter than its {size} data bytes and CRC")
        running = crc16(body[at:end], running)
        if last:
            crc_ok = status.crc_ok
        else:
            crc_ok = running == body[end] | (body[end + 1] << 8)
            running = crc16(body[end : end + 2], running)
            end += 2
        entries.append(FastStatusEntry(servo_id, error, bytes(body[at + 2 : at + 2 + size]), crc_ok))
        at = end
    return entries
