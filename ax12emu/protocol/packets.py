"""Dynamixel Protocol 1.0 packets: instruction codes, status error bits, encoding.

Why it exists: every other layer (framing, request handling, tracing, tests)
speaks in these values, so they are defined once, as enums and small frozen
dataclasses, with the encoders beside them.

Layout (ROBOTIS e-manual, "Protocol 1.0"), all bytes::

    0xFF 0xFF ID LENGTH INSTRUCTION|ERROR PARAM_1 ... PARAM_N CHECKSUM
    LENGTH   = N + 2
    CHECKSUM = ~(ID + LENGTH + INSTRUCTION|ERROR + PARAM_1 + ... + PARAM_N) & 0xFF
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import NamedTuple

__all__ = [
    "BROADCAST_ID",
    "BulkReadRequest",
    "MAX_ID",
    "HEADER",
    "Instruction",
    "StatusError",
    "InstructionPacket",
    "StatusPacket",
    "checksum",
    "encode_instruction",
    "encode_status",
    "parse_bulk_read",
]

#: Packets to this ID are executed by every servo and answered by none.
BROADCAST_ID = 0xFE
#: The highest ID a servo can take (e-manual: ID range 0..253).
MAX_ID = 0xFD
HEADER = b"\xff\xff"


class Instruction(enum.IntEnum):
    """Instruction codes of Protocol 1.0 (e-manual, "Instruction Packet")."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    RESET = 0x06
    #: MX series only, from firmware V40 (e-manual, Protocol 1.0, "Reboot": "Applied Products: MX-12W(V41),
    #: MX-28(V40), MX-64(V40), MX-106(V40)"): the AX-12 answers it with INSTRUCTION error.
    REBOOT = 0x08
    SYNC_WRITE = 0x83
    #: Not implemented by the AX-12 (MX/RX series only): answered with INSTRUCTION error.
    BULK_READ = 0x92


class StatusError(enum.IntFlag):
    """The status packet's error byte (e-manual, "Status Packet"). Bit 7 is never set."""

    NONE = 0
    INPUT_VOLTAGE = 0x01
    ANGLE_LIMIT = 0x02
    OVERHEATING = 0x04
    RANGE = 0x08
    CHECKSUM = 0x10
    OVERLOAD = 0x20
    INSTRUCTION = 0x40


def checksum(body: bytes | bytearray) -> int:
    """Protocol 1.0 checksum of ID, LENGTH, INSTRUCTION/ERROR and parameters."""
    return ~sum(body) & 0xFF


class InstructionPacket(NamedTuple):
    """A decoded instruction packet; ``checksum_ok`` False marks a corrupt one.

    A NamedTuple rather than a dataclass: one is built per request on the hot path.
    """

    id: int
    instruction: int
    params: bytes = b""
    checksum_ok: bool = True

    def encode(self) -> bytes:
        """Wire bytes of this packet (with a correct checksum)."""
        return encode_instruction(self.id, self.instruction, self.params)


@dataclass(frozen=True)
class StatusPacket:
    """A decoded status packet."""

    id: int
    error: int
    params: bytes = b""
    checksum_ok: bool = True

    def encode(self) -> bytes:
        """Wire bytes of this packet (with a correct checksum)."""
        return encode_status(self.id, self.error, self.params)


def _encode(packet_id: int, code: int, params: bytes | bytearray) -> bytes:
    if not 0 <= packet_id <= 0xFE:
        raise ValueError(f"packet id must be 0..254, got {packet_id}")
    if not 0 <= code <= 0xFF:
        raise ValueError(f"instruction/error byte must be 0..255, got {code}")
    if len(params) > 253:
        raise ValueError(f"at most 253 parameter bytes fit in a packet, got {len(params)}")
    body = bytes((packet_id, len(params) + 2, code)) + bytes(params)
    return HEADER + body + bytes((checksum(body),))


def encode_instruction(packet_id: int, instruction: int, params: bytes | bytearray = b"") -> bytes:
    """Build an instruction packet."""
    return _encode(packet_id, instruction, params)


def encode_status(packet_id: int, error: int, params: bytes | bytearray = b"") -> bytes:
    """Build a status packet. Bit 7 of ``error`` is rejected: dynamixel-sdk drops such packets."""
    if error & 0x80:
        raise ValueError(f"status error byte must not have bit 7 set, got {error:#04x}")
    return _encode(packet_id, error, params)


class BulkReadRequest(NamedTuple):
    """One servo's part of a Bulk Read: (ID, start address, length)."""

    servo_id: int
    address: int
    length: int


def parse_bulk_read(params: bytes) -> list[BulkReadRequest] | None:
    """Bulk Read's parameters: 0x00, then (length, ID, address) per servo; None if malformed.

    "If an identical ID is designated multiple times, only the first designated parameter will be
    processed" (e-manual, "Bulk Read"): later repeats are dropped here.
    """
    if len(params) < 4 or (len(params) - 1) % 3 or params[0] != 0x00:
        return None
    seen: set[int] = set()
    out = []
    for at in range(1, len(params), 3):
        length, servo_id, address = params[at], params[at + 1], params[at + 2]
        if servo_id in seen:
            continue
        seen.add(servo_id)
        out.append(BulkReadRequest(servo_id, address, length))
    return out
