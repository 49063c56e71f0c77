"""The CRC-16 that guards every Protocol 2.0 packet.

Why it exists: Protocol 2.0 replaced Protocol 1.0's one-byte checksum with a
16-bit CRC, and every layer that builds or checks a 2.0 packet (encoder,
framer, the combined Fast Sync Read status) must compute the same one.

The e-manual's "CRC Calculation" page (linked from "Protocol 2.0 > Instruction
Packet > CRC") gives it as C code with a 256-entry table: CRC-16 with
polynomial x^16 + x^15 + x^2 + 1 (0x8005), initial value 0, bits taken most
significant first, no reflection and no final XOR (the parameters of
CRC-16/BUYPASS).  It runs over the packet as sent — header ``FF FF FD 00``
through the last parameter, byte stuffing included — and is appended low byte
first.  The table is derived here from the polynomial instead of copied;
tests check it entry by entry against dynamixel-sdk's ``updateCRC`` table and
against the e-manual's example packets.
"""

from __future__ import annotations

import struct
from array import array

__all__ = ["CRC16_POLYNOMIAL", "CRC16_TABLE", "crc16"]

#: x^16 + x^15 + x^2 + 1, the e-manual's polynomial.
CRC16_POLYNOMIAL = 0x8005


def _table_entry(index: int) -> int:
    crc = index << 8
    for _ in range(8):
        crc = ((crc << 1) ^ CRC16_POLYNOMIAL) if crc & 0x8000 else crc << 1
    return crc & 0xFFFF


#: CRC of each byte value shifted through the register, as in the e-manual's ``crc_table``.
CRC16_TABLE: tuple[int, ...] = tuple(_table_entry(i) for i in range(256))


#: The CRC register after two bytes ``x >> 8, x & 0xFF`` from 0, for every 16-bit ``x``.  The register is 16
#: bits wide and the CRC linear, so two bytes from any register ``r`` take it to ``CRC16_PAIRS[r ^ x]``: half
#: the steps of the byte table (every status packet and every instruction is checked; 128 KiB, a few ms to build).
CRC16_PAIRS = array("H", (((CRC16_TABLE[a] << 8) & 0xFFFF) ^ CRC16_TABLE[((CRC16_TABLE[a] >> 8) ^ b) & 0xFF]
                          for a in range(256) for b in range(256)))


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC of ``data``, continuing from ``crc`` (0 starts a packet).

    Continuing matters for Fast Sync Read, whose per-servo CRCs are the running
    CRC of the combined status packet up to that servo's last data byte.
    """
    pairs = len(data) >> 1
    if pairs:
        table = CRC16_PAIRS
        for word in struct.unpack_from(f">{pairs}H", data):  # big-endian: the first byte is shifted in first
            crc = table[crc ^ word]
    if len(data) & 1:
        crc = ((crc << 8) & 0xFFFF) ^ CRC16_TABLE[((crc >> 8) ^ data[-1]) & 0xFF]
    return crc
