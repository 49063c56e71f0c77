"""Incremental Protocol 2.0 framer: any chunking of bytes in, whole packets out.

Why it exists: as for Protocol 1.0 (``framing.py``), a serial line delivers
bytes in arbitrary pieces, with noise, truncation and repeated header bytes,
and every device on a half-duplex bus hears every packet — instructions and
other servos' status packets alike.  This turns that stream into
:class:`~.packets2.InstructionPacket2` and :class:`~.packets2.StatusPacket2`
the way the e-manual's "Processing Order of Reception" describes, with no
I/O and no clock of its own (the caller passes ``now_s``).

Frame::

    +----+----+----+----+----+-------+-------+------+-------------------+-------+-------+
    | FF | FF | FD | 00 | ID | LEN_L | LEN_H | INST | PARAM.. (stuffed) | CRC_L | CRC_H |
    +----+----+----+----+----+-------+-------+------+-------------------+-------+-------+
     <----- HEADER2 ----->                   <------- LENGTH bytes after LEN_H -------->

Resynchronisation, case by case:

* garbage before a header: bytes are dropped up to the next ``FF FF FD 00``;
  a tail that could begin a header (``FF``, ``FF FF``, ``FF FF FD``) is kept;
* repeated ``FF`` (``FF FF FF FD 00``): the header is found one byte later;
* stuffing (``FF FF FD FD``) and any other reserved byte than 0x00: not a
  header ("Search for packet Header ... ignoring any found Byte Stuffing");
* an ID the e-manual never uses (0xFD, 0xFF), a LENGTH below 3 (INST + CRC),
  a status (INST 0x55) with LENGTH below 4 (no error byte), or a LENGTH above
  ``max_length``: the first header byte is dropped and the hunt starts again
  ("If the Packet ID is valid, prepare to receive ... the size of Length");
* a wrong CRC: the whole frame of LENGTH bytes is consumed and reported with
  ``crc_ok=False`` (parameters left stuffed), so the addressed servo can
  answer with a CRC Error (error number 3);
* a truncated frame: when no byte has arrived for ``silence_timeout_s`` the
  partial frame is dropped, as the firmware does after its byte-to-byte time,
  so the next packet after a pause is read cleanly.

A bus with Protocol 1.0 and 2.0 servos (both hear every packet):

* a 2.0 packet seen by the 1.0 framer: ``FF FF FD 00 ...`` reads as a 1.0
  header with ID 0xFD and LENGTH 0x00, which is impossible (LENGTH >= 2), so
  the 1.0 framer drops a byte and hunts on through the 2.0 packet's body.
  Any ``FF FF`` there restarts it.  Every stuffed 2.0 packet holds
  ``FF FF FD FD``: a 1.0 header for ID 0xFD with LENGTH 253, so the 1.0 servo
  waits for 253 more bytes and swallows the 1.0 packets that follow until its
  silence timeout.  And a ``FF FF`` that starts a well-formed 1.0 packet with
  a good checksum (a 2.0 WRITE whose data carry a 1.0 packet) is executed by
  the 1.0 servo: 2.0 stuffing guards only ``FF FF FD``.
* a 1.0 packet seen by this framer: its 1.0 LENGTH byte sits where the
  reserved byte is, and a 1.0 LENGTH is never 0x00, so even a 1.0 packet to
  ID 0xFD (``FF FF FD LEN ...``) is not a 2.0 header; the 1.0 packet is
  discarded unless its parameters carry a whole valid 2.0 packet.
* a partial frame of one protocol swallows the other protocol's packet that
  follows without a pause longer than the silence timeout; this is the
  firmware's behaviour too.

The buffer never holds more than one frame of ``max_length`` plus the
unparsed rest of the chunk being fed.
"""

from __future__ import annotations

from .framing import FrameBuffer
from .packets2 import (
    HEADER2,
    MIN_INSTRUCTION_LENGTH,
    MIN_STATUS_LENGTH,
    Instruction2,
    InstructionPacket2,
    StatusPacket2,
    is_valid_packet_id,
    packet_from_frame,
)

__all__ = ["BYTE_TO_BYTE_TIMEOUT_S", "DEFAULT_MAX_LENGTH", "DEFAULT_SILENCE_TIMEOUT_S", "Framer2"]

#: e-manual "Byte to Byte Time": a gap over 1.5 ms inside an instruction packet makes the servo
#: drop it and wait for the next header.  For a bus that models wire timing.
BYTE_TO_BYTE_TIMEOUT_S = 0.0015
#: The default is longer than the servo's 1.5 ms because the emulator's bytes arrive through a pty or
#: TCP, where one packet may come in pieces separated by scheduling delays; 20 ms matches the Protocol
#: 1.0 framer and is still shorter than dynamixel-sdk's shortest retry.
DEFAULT_SILENCE_TIMEOUT_S = 0.020
#: dynamixel-sdk's Protocol 2.0 handler never sends a packet over 1024 bytes (TXPACKET_MAX_LEN) and
#: rejects a status whose LENGTH exceeds 1024 (RXPACKET_MAX_LEN); the servos' own buffer size is not
#: documented.  A LENGTH above this is taken as noise.
DEFAULT_MAX_LENGTH = 1024
_HEADER_BYTES = len(HEADER2)
#: Header, ID, LEN_L, LEN_H and INST: enough to validate a frame's start.
_PREAMBLE_BYTES = _HEADER_BYTES + 4


def _header_prefix_kept(buf: bytearray) -> int:
    """How many trailing bytes of ``buf`` could be the start of a header still to come."""
    for keep in range(min(len(buf), _HEADER_BYTES - 1), 0, -1):
        if buf[-keep:] == HEADER2[:keep]:
            return keep
    return 0


class Framer2(FrameBuffer):
    """Feed bytes, get :class:`InstructionPacket2` and :class:`StatusPacket2`; never raises on input."""

    def __init__(self, *, silence_timeout_s: float = DEFAULT_SILENCE_TIMEOUT_S, max_length: int = DEFAULT_MAX_LENGTH) -> None:
        super().__init__(silence_timeout_s=silence_timeout_s, max_length=max_length,
                         length_span=(MIN_STATUS_LENGTH, 0xFFFF))
        #: The last input that was whole frames only, and its packets (see :meth:`feed`).
        self._last_whole = b""
        self._last_packets: tuple[InstructionPacket2 | StatusPacket2, ...] = ()

    def feed(self, data: bytes | bytearray, now_s: float | None = None) -> list[InstructionPacket2 | StatusPacket2]:
        """Add bytes received at ``now_s`` (None: ignore timing); return the packets completed."""
        self.expire(now_s)
        if now_s is not None and data:
            self._last_byte_s = now_s
        # Fast path: whole plausible frames only and nothing pending (the usual request, or a robot's Sync
        # Write and Sync Read read at once); the CRC is still checked by packet_from_frame, so a corrupt one
        # is reported as on the slow path.  The same bytes as the last such input are the same packets: a
        # robot sends the same cycle again and again.
        if not self._buf and len(data) >= _PREAMBLE_BYTES and data.startswith(HEADER2):
            if data == self._last_whole:
                return list(self._last_packets)
            packets = self._whole_frames(data)
            if packets is not None:
                self._last_whole, self._last_packets = bytes(data), tuple(packets)
                return packets
        if data:
            self._buf += data
        return self._extract()

    def _whole_frames(self, data: bytes | bytearray) -> list[InstructionPacket2 | StatusPacket2] | None:
        """``data`` as the packets of plausible frames back to back that end with it; None if it is anything else."""
        packets: list[InstructionPacket2 | StatusPacket2] = []
        at, end = 0, len(data)
        while at < end:
            if end - at < _PREAMBLE_BYTES or data[at : at + 4] != HEADER2:
                return None
            length = data[at + 5] | (data[at + 6] << 8)
            total = _HEADER_BYTES + 3 + length
            if (at + total > end or not is_valid_packet_id(data[at + 4])
                    or not (MIN_STATUS_LENGTH if data[at + 7] == Instruction2.STATUS else MIN_INSTRUCTION_LENGTH)
                    <= length <= self.max_length):
                return None
            packets.append(packet_from_frame(data if total == end else data[at : at + total]))
            at += total
        return packets

    def _drop(self, count: int) -> None:
        self.discarded_bytes += count
        del self._buf[:count]

    def _extract(self) -> list[InstructionPacket2 | StatusPacket2]:
        out: list[InstructionPacket2 | StatusPacket2] = []
        buf = self._buf
        while buf:
            if not buf.startswith(HEADER2):
                start = buf.find(HEADER2, 1)
                if start < 0:
                    self._drop(len(buf) - _header_prefix_kept(buf))
                    break
                self._drop(start)
                continue
            if len(buf) < _PREAMBLE_BYTES:
                break
            length = buf[5] | (buf[6] << 8)
            shortest = MIN_STATUS_LENGTH if buf[7] == Instruction2.STATUS else MIN_INSTRUCTION_LENGTH
            if not is_valid_packet_id(buf[4]) or not shortest <= length <= self.max_length:
                self._drop(1)
                continue
            total = _HEADER_BYTES + 3 + length
            if len(buf) < total:
                break
            out.append(packet_from_frame(bytes(buf[:total])))
            del buf[:total]
        return out
