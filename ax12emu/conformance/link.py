"""The host side of the conformance suites: send a packet, time its status packet.

Why it exists: the suites must run against any port (a pty path,
``socket://``, ``ax12emu://``, a real USB2Dynamixel or U2D2) with nothing but
pyserial, and measure round trips themselves.  :class:`Link` speaks Protocol
1.0, :class:`Link2` Protocol 2.0; they differ only in the framer that cuts
the received bytes into packets.  Reads block on the port with a
short timeout rather than spinning, so a bus served by a thread of the same
process is never starved of the GIL.  Every well-formed packet sent is kept
in :attr:`Link.sent`, so a trace can be checked against it.

Silence is judged over its own window, :attr:`Link.silence_s`, which defaults
to the reply timeout: a device that answers when asked does so within the
timeout, so a reply that must not come would come within it too.  A real
servo answers within its Return Delay Time (at most 254 x 2 us = 508 us on
both protocols: e-manual, AX-12A "Return Delay Time(5)" and XL430-W250
"Return Delay Time(9)") plus its packet's wire time, but a USB adapter holds
received bytes for up to its latency timer (FTDI's default 16 ms), and a busy
host adds its own delay; hence the safe default.  Against a bus that answers
at once (the emulator in process, on a pty or TCP), a short window saves the
wait without losing what it judges: a status packet that arrives after a
silence window, yet before the next packet is sent, is kept in
:attr:`Link.late` rather than flushed away, and the suite fails the check
during which it was found.
"""

from __future__ import annotations

import socket
import time
import urllib.parse
from typing import NamedTuple

import serial

from ax12emu.protocol.framing import Framer
from ax12emu.protocol.framing2 import Framer2
from ax12emu.protocol.packets import StatusPacket
from ax12emu.protocol.packets2 import InstructionPacket2, StatusPacket2

__all__ = ["Link", "Link2", "Response", "Response2", "check_waits", "open_port"]

#: How long one blocking read may wait before the deadline is checked again.
_POLL_S = 0.002



def check_waits(timeout_s: float, silence_s: float | None) -> None:
    """ValueError unless the reply timeout and the silence window are positive finite seconds: NaN waited for ever,
    0 or less listened for nothing (an answering ID passed as silent, a good servo failed as not answering)."""
    for name, value in (("timeout_s", timeout_s), ("silence_s", timeout_s if silence_s is None else silence_s)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < float("inf"):
            raise ValueError(f"{name} must be a positive finite number of seconds, got {value!r}")

class Response(NamedTuple):
    """A status packet (None: silence until the timeout) and the round trip it took."""

    status: StatusPacket | None
    rtt_s: float


class Response2(NamedTuple):
    """A Protocol 2.0 status packet (None: silence until the timeout) and the round trip it took."""

    status: StatusPacket2 | None
    rtt_s: float


#: The options pyserial's ``socket://`` URL takes, each with its values; the form its errors name.
_SOCKET_URL_OPTIONS = {"logging": ("debug", "info", "warning", "error")}
_SOCKET_URL_FORM = "socket://HOST:PORT[?logging=debug|info|warning|error] (PORT 1..65535)"


def _check_socket_url(url: str) -> None:
    """ValueError naming the ``socket://HOST:PORT`` form for a socket URL pyserial cannot read (other names pass).

    pyserial's own parser leaves such a URL to fail deep inside: with no port it compares None with 0 (a
    ``TypeError`` about ``'<='``), and a port that is no number or out of range, or an unknown option, breaks the
    template of its own message (the whole error reads ``'debug|info|warning|error'``).  Read here as pyserial
    reads it (``urlsplit``), so what passes is what its parser takes, bar port 0, where no server listens."""
    parts = urllib.parse.urlsplit(url)
    if parts.scheme != "socket":
        return
    try:
        port = parts.port
    except ValueError:  # not a number, or out of range
        port = None
    options = urllib.parse.parse_qs(parts.query, keep_blank_values=True)
    known = all(value in _SOCKET_URL_OPTIONS.get(name, ()) for name, values in options.items() for value in values)
    if not port or not known:  # None: no port, or one urlsplit cannot read; 0: no server listens there
        raise ValueError(f"expected {_SOCKET_URL_FORM}, got {url!r}")


def open_port(port: str, baud: int) -> serial.SerialBase:
    """Open a device path or any pyserial URL at ``baud``; ValueError for a ``socket://`` URL pyserial cannot read.

    pyserial's ``socket://`` leaves Nagle's algorithm on, which holds back a
    packet's later bytes for a delayed ACK (~40 ms), past the servo's
    partial-packet timeout; a serial line never does that, so it is turned off.
    """
    _check_socket_url(port)
    link = serial.serial_for_url(port, baudrate=baud, timeout=_POLL_S, write_timeout=1.0)
    sock = getattr(link, "_socket", None)
    if sock is not None:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return link


class Link:
    """One host on one port: transactions, raw writes, the host's baud rate."""

    def __init__(self, port: serial.SerialBase, *, timeout_s: float = 0.05, silence_s: float | None = None) -> None:
        check_waits(timeout_s, silence_s)
        self.port = port
        self.timeout_s = timeout_s
        #: How long a transaction that must get no answer listens (default: the reply timeout; see the module).
        self.silence_s = timeout_s if silence_s is None else silence_s
        #: Status packets that came after a transaction had been judged silent, as "packet sent -> reply" lines.
        self.late: list[str] = []
        # The last packet whose transaction ended in silence: what arrives before the next send answered it late.
        self._silenced: bytes | None = None
        #: Every packet sent with :meth:`transact` or :meth:`send`, in order.
        self.sent: list[bytes] = []
        # Bytes after a status packet stay here for the next receive (two replies in one read).
        self._framer = self._new_framer()
        self._ready: list = []

    def _new_framer(self) -> Framer | Framer2:
        return Framer()

    def _is_echo(self, packet, echo: bytes) -> bool:
        # Protocol 1.0 status and instruction packets share one frame: only the echo itself is skipped, compared
        # field by field, so the echo of a packet sent with a wrong checksum (re-encoded, a right one) is found too.
        return (len(echo) >= 6 and packet.id == echo[2] and packet.instruction == echo[4]
                and bytes(packet.params) == bytes(echo[5:-1]))

    def _status(self, packet, rtt_s: float) -> Response | Response2:
        if packet is None:
            return Response(None, rtt_s)
        return Response(StatusPacket(packet.id, packet.instruction, bytes(packet.params), packet.checksum_ok), rtt_s)

    @property
    def baud(self) -> int:
        """The host's bit rate."""
        return int(self.port.baudrate)

    @baud.setter
    def baud(self, bps: int) -> None:
        self.port.baudrate = bps

    def flush_input(self) -> None:
        """Forget bytes received so far (a late reply must not answer the next packet)."""
        self._silenced = None
        self.port.reset_input_buffer()
        self._framer.reset()
        self._ready.clear()

    def send(self, packet: bytes) -> None:
        """Write a packet that gets no answer (broadcast, or a low status return level)."""
        self._catch_late()
        self.flush_input()
        self.port.write(packet)
        self.sent.append(bytes(packet))

    def write_raw(self, data: bytes) -> None:
        """Write bytes that are not a packet (garbage, halves); not recorded in :attr:`sent`."""
        self.port.write(data)

    def transact(self, packet: bytes, *, timeout_s: float | None = None) -> Response:
        """Send ``packet`` and wait for one status packet (an echo of the packet is skipped)."""
        start = time.perf_counter()
        self.send(packet)
        response = self.receive(timeout_s, start=start, echo=packet)
        self._silenced = bytes(packet) if response.status is None else None
        return response

    def _catch_late(self) -> None:
        """Keep in :attr:`late` any valid status packet that arrived since the last transaction ended in silence."""
        packet, self._silenced = self._silenced, None
        if packet is None:
            return
        waiting = self.port.in_waiting
        if waiting:
            self._ready.extend(self._framer.feed(self.port.read(waiting)))
        for received in self._ready:
            if self._is_echo(received, packet):
                continue
            status = self._status(received, 0.0).status
            if self._valid(status):
                self.late.append(f"{packet.hex(' ')} -> {received.encode().hex(' ')}")

    def _valid(self, status) -> bool:
        return bool(status.checksum_ok)

    def receive(self, timeout_s: float | None = None, *, start: float | None = None, echo: bytes = b"") -> Response:
        """Wait for the next status packet."""
        start = time.perf_counter() if start is None else start
        deadline = start + (self.timeout_s if timeout_s is None else timeout_s)
        while True:
            while self._ready:
                packet = self._ready.pop(0)
                if self._is_echo(packet, echo):
                    echo = b""
                    continue
                return self._status(packet, time.perf_counter() - start)
            now = time.perf_counter()
            if now >= deadline:
                return self._status(None, now - start)
            data = self.port.read(max(1, self.port.in_waiting))
            if data:
                self._ready.extend(self._framer.feed(data))

    def drain(self, seconds: float) -> bytes:
        """Read and return whatever arrives within ``seconds``."""
        deadline = time.perf_counter() + seconds
        out = bytearray()
        while time.perf_counter() < deadline:
            out += self.port.read(max(1, self.port.in_waiting))
        return bytes(out)

    def close(self) -> None:
        """Close the port."""
        self.port.close()


class Link2(Link):
    """The same host speaking Protocol 2.0: :meth:`transact` and :meth:`receive` give :class:`Response2`.

    A 2.0 framer yields instruction packets too (a half-duplex adapter echoes
    what the host sent, and a servo never sends one), so every instruction
    packet received is skipped, not only the echo of the last one sent.
    """

    def _new_framer(self) -> Framer2:
        return Framer2()

    def _is_echo(self, packet, echo: bytes) -> bool:
        return isinstance(packet, InstructionPacket2)

    def _status(self, packet, rtt_s: float) -> Response2:
        return Response2(packet, rtt_s)

    def _valid(self, status) -> bool:
        return isinstance(status, StatusPacket2) and bool(status.crc_ok)
