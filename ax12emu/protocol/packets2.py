"""Dynamixel Protocol 2.0 packets: header, byte stuffing, encoding and decoding.

Why it exists: the X-series servos speak Protocol 2.0, which differs from
Protocol 1.0 (``packets.py``) in every field: a four-byte header, a 16-bit
LENGTH, a CRC-16 instead of a checksum, byte stuffing so the header cannot
appear inside a packet, an explicit status instruction, numbered errors
instead of error bits, and a larger instruction set.  This module holds all of
that as data and pure functions; framing a byte stream is ``framing2.py``'s job
and the meaning of each instruction's parameters is ``params2.py``'s.

Layout (ROBOTIS e-manual, "DYNAMIXEL Protocol 2.0", sections "Instruction
Packet" and "Status Packet")::

    instruction: FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAM_1 ... PARAM_N | CRC_L CRC_H
    status:      FF FF FD 00 | ID | LEN_L LEN_H | 0x55 | ERR | PARAM_1 ... PARAM_N | CRC_L CRC_H
                 <- header ->                    <----- LENGTH bytes, CRC included ----->

    LENGTH = bytes from INST to CRC_H inclusive, after stuffing (N + 3; N + 4 for a status)
    CRC    = crc16(everything from the first 0xFF to the last parameter), as sent

"Packet ID": servos take IDs 0..252 (0xFC); 0xFE is the broadcast ID; 0xFD and
0xFF are never used, so that an ID cannot extend the header.

Byte stuffing ("Packet Process"): over the instruction and parameters (not the
header, LENGTH or CRC), every ``FF FF FD`` is sent as ``FF FF FD FD``; LENGTH
and CRC are computed over the stuffed bytes.  A receiver finds the header
``FF FF FD`` "ignoring" ``FF FF FD FD`` (the reserved byte after a header is
0x00, never 0xFD), checks the CRC over the stuffed bytes and only then removes
the stuffing.  The one exception, from "Fast Sync Read (0x8A)" and "Fast Bulk
Read (0x9A)": their combined status packet (always sent with ID 0xFE) is *not*
stuffed, so it is not unstuffed either.

The error byte ("Status Packet > Error"): bit 7 is Alert (a hardware error is
latched; the Hardware Error Status register says which), bits 0..6 an error
number 1..7 (:class:`ErrorNumber`).
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from typing import NamedTuple

from .crc16 import crc16
from .packets import BROADCAST_ID

__all__ = [
    "ALERT_BIT",
    "BROADCAST_ID",
    "ERROR_NUMBER_MASK",
    "HEADER2",
    "MAX_ID2",
    "MIN_INSTRUCTION_LENGTH",
    "MIN_STATUS_LENGTH",
    "ErrorNumber",
    "FastStatusPart",
    "Instruction2",
    "InstructionPacket2",
    "Malformed",
    "StatusPacket2",
    "decode_packet2",
    "encode_fast_status",
    "encode_instruction2",
    "encode_status2",
    "fast_status_pieces",
    "is_valid_packet_id",
    "packet_from_frame",
    "status_error",
    "stuff",
    "unstuff",
]

#: Header and reserved byte; the reserved byte is 0x00 so ``FF FF FD FD`` (stuffing) is never a header.
HEADER2 = b"\xff\xff\xfd\x00"
#: The highest ID a Protocol 2.0 servo can take ("Packet ID": 0..252).
MAX_ID2 = 0xFC
#: LENGTH of a packet with no parameters: INST + CRC_L + CRC_H.
MIN_INSTRUCTION_LENGTH = 3
#: LENGTH of a status packet with no parameters: 0x55 + ERR + CRC_L + CRC_H.
MIN_STATUS_LENGTH = 4
#: Bit 7 of the status error byte: the servo has latched a hardware error.
ALERT_BIT = 0x80
#: Bits 0..6 of the status error byte: the :class:`ErrorNumber` of this instruction's processing.
ERROR_NUMBER_MASK = 0x7F
_STUFFING_PATTERN = b"\xff\xff\xfd"


class Instruction2(enum.IntEnum):
    """Instruction codes of Protocol 2.0 (e-manual, "Instruction Packet > Instruction")."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    CONTROL_TABLE_BACKUP = 0x20
    #: The instruction byte of every status packet.
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A
    BULK_READ = 0x92
    BULK_WRITE = 0x93
    FAST_BULK_READ = 0x9A


class ErrorNumber(enum.IntEnum):
    """Bits 0..6 of the status error byte (e-manual, "Status Packet > Error")."""

    NONE = 0x00
    #: Failed to process the instruction (e.g. Clear while moving, Backup with torque on).
    RESULT_FAIL = 0x01
    #: Undefined instruction, or Action with nothing registered by Reg Write.
    INSTRUCTION = 0x02
    #: The instruction packet's CRC does not match.
    CRC = 0x03
    #: Value outside the register's minimum/maximum.
    DATA_RANGE = 0x04
    #: Fewer bytes written than the register holds (e.g. 2 bytes of a 4-byte register).
    DATA_LENGTH = 0x05
    #: Value outside the configured limit register (e.g. beyond Max Position Limit).
    DATA_LIMIT = 0x06
    #: Write to read-only or undefined address, read of write-only or undefined, EEPROM write with torque on.
    ACCESS = 0x07


def status_error(number: int = ErrorNumber.NONE, *, alert: bool = False) -> int:
    """The status error byte for ``number`` with the Alert bit set when ``alert``."""
    if not 0 <= number <= ERROR_NUMBER_MASK:
        raise ValueError(f"error number must be 0..127, got {number}")
    return number | (ALERT_BIT if alert else 0)


def is_valid_packet_id(packet_id: int) -> bool:
    """True for IDs a packet may carry: 0..252 and broadcast 0xFE (never 0xFD or 0xFF)."""
    return 0 <= packet_id <= MAX_ID2 or packet_id == BROADCAST_ID


def stuff(payload: bytes | bytearray) -> bytes:
    """Apply byte stuffing to INST + parameters: each ``FF FF FD`` becomes ``FF FF FD FD``.

    The pattern is looked for in the unstuffed bytes, so ``FF FF FD FD`` becomes
    ``FF FF FD FD FD`` and unstuffs back to itself, as in dynamixel-sdk's ``addStuffing``.
    """
    if _STUFFING_PATTERN not in payload:
        return bytes(payload)
    out = bytearray()
    for index, byte in enumerate(payload):
        out.append(byte)
        if byte == 0xFD and index >= 2 and payload[index - 1] == 0xFF and payload[index - 2] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def unstuff(payload: bytes | bytearray) -> bytes:
    """Remove byte stuffing: drop the ``FD`` that follows each ``FF FF FD`` of the unstuffed bytes.

    Never raises: a ``FF FF FD`` not followed by ``FD`` (which a correct sender
    never produces) is kept as it is.
    """
    if _STUFFING_PATTERN not in payload:
        return bytes(payload)
    out = bytearray()
    index, size = 0, len(payload)
    while index < size:
        byte = payload[index]
        out.append(byte)
        index += 1
        if byte == 0xFD and len(out) >= 3 and out[-2] == 0xFF and out[-3] == 0xFF and index < size and payload[index] == 0xFD:
            index += 1
    return bytes(out)


class Malformed(NamedTuple):
    """Bytes from the wire that do not form what was expected, and why; returned, never raised."""

    reason: str


class InstructionPacket2(NamedTuple):
    """A decoded instruction packet; ``params`` are unstuffed.

    ``crc_ok`` False marks a corrupt packet: its ``params`` are then the bytes
    as received (the e-manual removes stuffing only once the CRC matches), and
    only ``id`` is worth reading, to answer with a CRC error.
    """

    id: int
    instruction: int
    params: bytes = b""
    crc_ok: bool = True

    def encode(self) -> bytes:
        """Wire bytes of this packet (stuffed, with a correct CRC)."""
        return encode_instruction2(self.id, self.instruction, self.params)


class StatusPacket2(NamedTuple):
    """A decoded status packet (instruction 0x55).

    For a Fast Sync/Bulk Read's combined status (ID 0xFE), ``error`` is the
    first servo's error and ``params`` the rest of the combined body, unstuffed
    because it was never stuffed; ``params2.parse_fast_status`` splits it.
    """

    id: int
    error: int
    params: bytes = b""
    crc_ok: bool = True

    @property
    def alert(self) -> bool:
        """Bit 7: the servo has a hardware error latched."""
        return bool(self.error & ALERT_BIT)

    @property
    def error_number(self) -> int:
        """Bits 0..6: the :class:`ErrorNumber` (an int if the value is undefined)."""
        number = self.error & ERROR_NUMBER_MASK
        try:
            return ErrorNumber(number)
        except ValueError:
            return number

    def encode(self) -> bytes:
        """Wire bytes of this packet (stuffed, with a correct CRC)."""
        return encode_status2(self.id, self.error, self.params)


def _frame(packet_id: int, payload: bytes) -> bytes:
    length = len(payload) + 2
    if length > 0xFFFF:
        raise ValueError(f"packet too long for a 16-bit LENGTH: {length}")
    body = HEADER2 + bytes((packet_id, length & 0xFF, length >> 8)) + payload
    return body + crc16(body).to_bytes(2, "little")


def _check_id(packet_id: int) -> None:
    if not is_valid_packet_id(packet_id):
        raise ValueError(f"packet id must be 0..{MAX_ID2} or {BROADCAST_ID} (0xFD and 0xFF extend the header), got {packet_id}")


def _check_byte(name: str, value: int) -> None:
    if not 0 <= value <= 0xFF:
        raise ValueError(f"{name} must be 0..255, got {value}")


def encode_instruction2(packet_id: int, instruction: int, params: bytes | bytearray = b"") -> bytes:
    """Build an instruction packet: stuffed, LENGTH and CRC over the stuffed bytes."""
    _check_id(packet_id)
    _check_byte("instruction", instruction)
    return _frame(packet_id, stuff(bytes((instruction,)) + bytes(params)))


def encode_status2(packet_id: int, error: int, params: bytes | bytearray = b"") -> bytes:
    """Build a status packet from one servo (ID 0..252), stuffed."""
    if not 0 <= packet_id <= MAX_ID2:
        raise ValueError(f"a status packet comes from a servo ID 0..{MAX_ID2}, got {packet_id} (combined statuses: encode_fast_status)")
    _check_byte("error", error)
    if error != 0xFF and _STUFFING_PATTERN not in params:
        # Nothing to stuff (0x55 and an ERR below 0xFF cannot begin the pattern): the bytes before the data
        # depend on the ID, ERR and the data's length alone, so their CRC is carried on over the data.
        key = (packet_id, error, len(params))
        known = _STATUS_PREFIXES.get(key)
        if known is None:
            if len(_STATUS_PREFIXES) >= _MAX_STATUS_PREFIXES:
                _STATUS_PREFIXES.clear()
            length = len(params) + 4
            prefix = HEADER2 + bytes((packet_id, length & 0xFF, length >> 8, Instruction2.STATUS, error))
            known = _STATUS_PREFIXES[key] = (prefix, crc16(prefix))
        prefix, crc = known
        return b"".join((prefix, params, crc16(params, crc).to_bytes(2, "little")))
    return _frame(packet_id, stuff(bytes((Instruction2.STATUS, error)) + bytes(params)))


#: (ID, ERR, data length) -> a status packet's bytes before its data and their CRC (``encode_status2``).
_STATUS_PREFIXES: dict[tuple[int, int, int], tuple[bytes, int]] = {}
_MAX_STATUS_PREFIXES = 4096


class FastStatusPart(NamedTuple):
    """One servo's share of a Fast Sync/Bulk Read reply."""

    id: int
    error: int
    data: bytes


def fast_status_pieces(parts: Sequence[FastStatusPart]) -> list[bytes]:
    """What each servo transmits of a Fast Sync/Bulk Read's combined status, in order.

    From "Fast Sync Read (0x8A)": one status packet with ID 0xFE answers for
    every servo; the first servo sends the header, ID 0xFE, the LENGTH of the
    whole packet and 0x55, then each servo sends ``ERR ID DATA CRC_L CRC_H``,
    where its CRC is the running CRC of the packet up to its last data byte
    (checked against the e-manual's examples), so the last servo's CRC is the
    packet's.  Nothing is stuffed.  Each servo hears the ones before it, which
    is how it can continue the CRC; the bus must deliver the pieces back to back.
    """
    if not parts:
        raise ValueError("a combined status needs at least one servo")
    length = 1 + sum(4 + len(part.data) for part in parts)
    if length > 0xFFFF:
        raise ValueError(f"combined status too long for a 16-bit LENGTH: {length}")
    head = HEADER2 + bytes((BROADCAST_ID, length & 0xFF, length >> 8, Instruction2.STATUS))
    pieces: list[bytes] = []
    crc = crc16(head)
    for index, part in enumerate(parts):
        if not 0 <= part.id <= MAX_ID2:
            raise ValueError(f"servo ID must be 0..{MAX_ID2}, got {part.id}")
        _check_byte("error", part.error)
        body = bytes((part.error, part.id)) + bytes(part.data)
        crc = crc16(body, crc)
        piece = body + crc.to_bytes(2, "little")
        crc = crc16(piece[-2:], crc)
        pieces.append(head + piece if index == 0 else piece)
    return pieces


def encode_fast_status(parts: Sequence[FastStatusPart]) -> bytes:
    """The whole combined status packet of a Fast Sync/Bulk Read (see :func:`fast_status_pieces`)."""
    return b"".join(fast_status_pieces(parts))


def packet_from_frame(frame: bytes | bytearray) -> InstructionPacket2 | StatusPacket2:
    """Decode one whole frame whose header, ID and LENGTH the caller has already checked.

    ``frame`` runs from the header to CRC_H.  Used by the framer, which checks
    the rest; :func:`decode_packet2` is the checking entry point.
    """
    packet_id = frame[4]
    payload = bytes(frame[7:-2])
    crc_ok = crc16(frame[:-2]) == frame[-2] | (frame[-1] << 8)
    # Unstuff only once the CRC matches ("Processing Order of Reception"), and never the
    # combined Fast Sync/Bulk Read status (ID 0xFE), which is sent unstuffed.
    combined_status = packet_id == BROADCAST_ID and payload[0] == Instruction2.STATUS
    if crc_ok and not combined_status:
        payload = unstuff(payload)
    if payload[0] == Instruction2.STATUS:
        return StatusPacket2(packet_id, payload[1], payload[2:], crc_ok)
    return InstructionPacket2(packet_id, payload[0], payload[1:], crc_ok)


def decode_packet2(data: bytes | bytearray) -> InstructionPacket2 | StatusPacket2 | Malformed:
    """Decode exactly one packet; malformed input gives :class:`Malformed` (never raises)."""
    if len(data) < 7 + MIN_INSTRUCTION_LENGTH:
        return Malformed(f"{len(data)} bytes is shorter than the shortest packet (10)")
    if bytes(data[:4]) != HEADER2:
        return Malformed(f"header is {bytes(data[:4]).hex(' ')}, not ff ff fd 00")
    if not is_valid_packet_id(data[4]):
        return Malformed(f"packet ID {data[4]:#04x} is never used (0xFD and 0xFF would extend the header)")
    length = data[5] | (data[6] << 8)
    if length + 7 != len(data):
        return Malformed(f"LENGTH {length} says {length + 7} bytes, got {len(data)}")
    if data[7] == Instruction2.STATUS and length < MIN_STATUS_LENGTH:
        return Malformed("status packet without an error byte")
    return packet_from_frame(data)
