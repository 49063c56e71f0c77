"""Incremental Protocol 1.0 framer: any chunking of bytes in, whole packets out.

Why it exists: a serial line delivers bytes in arbitrary pieces (one at a
time, or several packets in one read), with noise, truncation and repeated
header bytes.  This module turns that stream into packets the way the servo's
firmware does, with no I/O and no clock of its own (the caller passes ``now``).

Frame::

    +------+------+----+--------+-------------+---------+----------+
    | 0xFF | 0xFF | ID | LENGTH | INSTRUCTION | PARAM.. | CHECKSUM |
    +------+------+----+--------+-------------+---------+----------+
                   <------- LENGTH + 1 bytes after LENGTH -------->

Resynchronisation, case by case:

* garbage before a header: bytes are dropped up to the next ``0xFF 0xFF``;
* repeated ``0xFF`` (``0xFF 0xFF 0xFF ID``): an ID of 0xFF is impossible, so
  one ``0xFF`` is dropped and the header is taken one byte later;
* an impossible LENGTH (below 2, or above ``max_length``): the first header
  byte is dropped and the hunt starts again;
* a wrong checksum: the whole frame of LENGTH bytes is consumed, as the
  firmware does, and reported as a packet with ``checksum_ok=False`` so the
  servo can answer with the checksum error bit;
* a truncated frame: when no byte has arrived for ``silence_timeout_s`` the
  partial frame is dropped (the firmware's receive timeout), so the next
  packet after a pause is read cleanly.

The buffer never holds more than one maximal frame (259 bytes) plus the
unparsed rest of the chunk being fed.
"""

from __future__ import annotations

from .packets import InstructionPacket, checksum

__all__ = ["Framer", "MAX_FRAME_BYTES", "DEFAULT_SILENCE_TIMEOUT_S"]

#: 2 header + ID + LENGTH + up to 255 counted bytes.
MAX_FRAME_BYTES = 4 + 255
#: The AX-12's partial-packet timeout is not documented; 20 ms is longer than
#: any gap inside one packet from a USB adapter and short enough that a client
#: retrying after its own timeout (about 34 ms in dynamixel-sdk) is heard.
DEFAULT_SILENCE_TIMEOUT_S = 0.020


class FrameBuffer:
    """What every framer keeps between feeds: the bytes of a partial frame, dropped after silence.

    Shared by the Protocol 1.0 :class:`Framer` and the Protocol 2.0 ``Framer2``; each
    subclass hunts for its own header and lengths in ``_buf``.
    """

    def __init__(self, *, silence_timeout_s: float, max_length: int, length_span: tuple[int, int]) -> None:
        if silence_timeout_s <= 0:
            raise ValueError(f"silence_timeout_s must be positive, got {silence_timeout_s}")
        low, high = length_span
        if not low <= max_length <= high:
            raise ValueError(f"max_length must be {low}..{high}, got {max_length}")
        self.silence_timeout_s = silence_timeout_s
        self.max_length = max_length
        self._buf = bytearray()
        self._last_byte_s: float | None = None
        #: Bytes thrown away while hunting for a frame, and frames dropped on silence.
        self.discarded_bytes = 0
        self.dropped_partials = 0

    @property
    def buffered(self) -> int:
        """Bytes held waiting for the rest of a frame."""
        return len(self._buf)

    def reset(self) -> None:
        """Forget any partial frame (e.g. after a line break or collision)."""
        self.discarded_bytes += len(self._buf)
        self._buf.clear()

    def expire(self, now_s: float | None) -> bool:
        """Drop a partial frame that has seen no byte for the silence timeout; True if dropped."""
        if (
            now_s is not None
            and self._buf
            and self._last_byte_s is not None
            and now_s - self._last_byte_s > self.silence_timeout_s
        ):
            self.dropped_partials += 1
            self.reset()
            return True
        return False


class Framer(FrameBuffer):
    """Feed bytes, get :class:`InstructionPacket` objects; never raises on input."""

    def __init__(self, *, silence_timeout_s: float = DEFAULT_SILENCE_TIMEOUT_S, max_length: int = 255) -> None:
        super().__init__(silence_timeout_s=silence_timeout_s, max_length=max_length, length_span=(2, 255))

    def feed(self, data: bytes | bytearray, now_s: float | None = None) -> list[InstructionPacket]:
        """Add bytes received at ``now_s`` (None: ignore timing); return the packets completed."""
        self.expire(now_s)
        if now_s is not None and data:
            self._last_byte_s = now_s
        # Fast path: one whole well-formed packet and nothing pending (the usual request).
        if not self._buf and len(data) >= 6 and data[0] == 0xFF == data[1] and data[3] + 4 == len(data):
            if data[2] != 0xFF and data[3] <= self.max_length and ~sum(data[2:-1]) & 0xFF == data[-1]:
                return [InstructionPacket(data[2], data[4], bytes(data[5:-1]), True)]
        if data:
            self._buf += data
        return self._extract()

    def _drop(self, count: int) -> None:
        self.discarded_bytes += count
        del self._buf[:count]

    def _extract(self) -> list[InstructionPacket]:
        out: list[InstructionPacket] = []
        buf = self._buf
        while len(buf) >= 2:
            if buf[0] != 0xFF or buf[1] != 0xFF:
                start = buf.find(b"\xff\xff", 1)
                if start < 0:
                    # Keep a trailing 0xFF: it may be the first half of a header.
                    self._drop(len(buf) - 1 if buf[-1] == 0xFF else len(buf))
                    break
                self._drop(start)
                continue
            if len(buf) < 4:
                if len(buf) == 3 and buf[2] == 0xFF:
                    self._drop(1)
                    continue
                break
            packet_id, length = buf[2], buf[3]
            if packet_id == 0xFF:
                self._drop(1)
                continue
            if length < 2 or length > self.max_length:
                self._drop(1)
                continue
            total = length + 4
            if len(buf) < total:
                break
            body = bytes(buf[2 : total - 1])
            ok = checksum(body) == buf[total - 1]
            out.append(InstructionPacket(id=packet_id, instruction=body[2], params=body[3:], checksum_ok=ok))
            del buf[:total]
        return out
