"""Pseudo-terminal transport: the host opens the slave side as if it were a USB2Dynamixel.

URL format: ``pty://[?link=PATH]``

Why the details matter (each one checked with dynamixel-sdk on Linux):

* the slave is made raw at creation, or the line discipline echoes our own
  replies back to us and mangles 0x0D/0x0A bytes;
* the emulator keeps its own handle on the slave open for its whole life, or
  the master fails with EIO the moment a client closes the port (dynamixel-sdk
  closes and reopens it inside ``setBaudRate``), and termios settings would
  be lost between opens;
* the master is non-blocking: about 17 KB of unread replies fill a pty, and a
  blocked write would freeze every servo;
* the host's bit rate is read from the slave's termios (``TCGETS2`` gives the
  exact rate, also for non-standard ones set with ``BOTHER``), so a servo at
  another baud can be deaf to the host, as on hardware;
* that read is a system call, which per packet cost about 4 % of the serving loop's
  poll rate, so on Linux the rate is read once and again only after the host
  changed its termios: the master runs in packet mode (``TIOCPKT``) and the
  slave carries ``EXTPROC`` in its local flags, which makes the kernel put a
  ``TIOCPKT_IOCTL`` status byte in the master's read stream at every termios
  change.  It comes ahead of whatever the host wrote after the change, but
  for bytes that arrive while one read of ours is under way (a window of
  microseconds, never seen in 3,000 tries); per-packet reading had the
  mirror image, bytes sent just before a change judged at the new rate.
* ``EXTPROC`` leaves a raw-mode host untouched (``stty -a`` shows it), as
  every Dynamixel library is; but it would switch off a host's own input
  processing (``ICRNL``, echo, canonical mode, ``IXON``) that on a real
  adapter would mangle its packets.  So when a host that asks for any of
  that sends a packet, the emulator takes ``EXTPROC`` off first, and reads
  the rate for every packet from then on, as it does once a host clears the
  flag itself (the C DynamixelSDK sets all local flags to 0) and on any
  platform but Linux.  The flag is not put back for a later host (one that
  copies the flags it finds, as pyserial does, keeps it off), since that
  would be a second write racing the host's own.  Taking it off writes the
  termios just read back, so a change the host makes in the microseconds
  between would be lost: only a host that is not raw, and reconfigures its
  port at once after writing a packet, could meet that.
"""

from __future__ import annotations

import errno
import fcntl
import logging
import os
import pty
import struct
import sys
import termios
import tty
from pathlib import Path

from .base import Transport

__all__ = ["PtyTransport"]

log = logging.getLogger(__name__)

# struct termios2 on Linux: 4 tcflag_t, c_line, 19 cc, then c_ispeed, c_ospeed.
_TERMIOS2 = struct.Struct("4IB19B2I")
#: One tcflag_t or speed_t field of it, and where the ones read here sit.
_FIELD = struct.Struct("I")
_IFLAG_OFFSET, _LFLAG_OFFSET, _OSPEED_OFFSET = 0, 3 * _FIELD.size, _TERMIOS2.size - _FIELD.size
_TCGETS2 = getattr(termios, "TCGETS2", 0x802C542A)
_TIOCPKT = getattr(termios, "TIOCPKT", 0x5420)
#: Packet mode's first byte of a read: data follows, or (alone) what happened to the slave.
_TIOCPKT_DATA = 0
_TIOCPKT_IOCTL = 0x40
_EXTPROC = getattr(termios, "EXTPROC", 0o200000)
_TCSETS2 = getattr(termios, "TCSETS2", 0x402C542B)
#: Input processing a host can ask of its line discipline that EXTPROC switches off (n_tty then
#: takes its raw receive path and makes no canonical reads; ISTRIP and IUCLC it still applies).
#: These are the flags of n_tty's own test for raw mode, in which EXTPROC is inert.
_COOKED_IFLAG = termios.IGNCR | termios.ICRNL | termios.INLCR | termios.IXON | termios.PARMRK
_COOKED_LFLAG = termios.ICANON | termios.ISIG | termios.ECHO
_SPEEDS = {
    getattr(termios, f"B{rate}"): float(rate)
    for rate in (
        50, 75, 110, 134, 150, 200, 300, 600, 1200, 1800, 2400, 4800, 9600, 19200, 38400, 57600,
        115200, 230400, 460800, 500000, 576000, 921600, 1000000, 1152000, 1500000, 2000000,
        2500000, 3000000, 3500000, 4000000,
    )
    if hasattr(termios, f"B{rate}")
}


class PtyTransport(Transport):
    """A pty pair; ``link`` makes a symlink to the slave that is removed on close."""

    #: Bytes written to a pty master reach the slave through a kernel worker (the tty flip
    #: buffer's), which on a two-core machine whose other core runs a busy-waiting client
    #: often needs this CPU: yielding at once lets the reply through before the loop goes on
    #: (measured with tools/bench_protocol.py: about 3 % more reads per second).
    yield_after_reply = True

    def __init__(self, link: str | os.PathLike[str] | None = None) -> None:
        self._master, self._slave = pty.openpty()
        tty.setraw(self._slave)
        flags = fcntl.fcntl(self._master, fcntl.F_GETFL)
        fcntl.fcntl(self._master, fcntl.F_SETFL, flags | os.O_NONBLOCK)
        self.slave_path = os.ttyname(self._slave)
        self.link: Path | None = None
        self._closed = False
        self._termios2 = True
        # Filled in place by the ioctl (no new bytes object per call: it may run once per packet).
        self._termios2_buffer = bytearray(_TERMIOS2.size)
        #: The line speed last read, kept while the kernel will announce the next change.
        self._line_bps: float | None = None
        self._line_bps_known = False
        self._packet_mode = sys.platform.startswith("linux") and self._enter_packet_mode()
        if link is not None:
            path = Path(link)
            if path.is_symlink():
                # It leads somewhere: another server's pty, or a pty number a crashed run freed, which another
                # program may hold now; or this transport's own, the number the crashed run freed: nothing to say.
                if path.exists() and os.path.realpath(path) != os.path.realpath(self.slave_path):
                    log.warning("--link %s pointed at %s, which is there (another server's pty?); it points here now, "
                                "and the other keeps it only if it started after this one", path, os.readlink(path))
                path.unlink()  # a stale link from a crashed run
            elif path.exists():
                self.close()
                raise FileExistsError(f"{path} exists and is not a symlink; refusing to replace it")
            try:
                path.symlink_to(self.slave_path)
            except OSError:
                self.close()
                raise
            self.link = path
        self.name = str(self.link or self.slave_path)

    @property
    def url(self) -> str:
        """The slave side's device path (``/dev/pts/N``); the link, when one was asked for, points at it."""
        return self.slave_path

    def fds(self) -> list[int]:
        return [self._master]

    def _enter_packet_mode(self) -> bool:
        """Set ``EXTPROC`` on the slave and packet mode on the master, and check that a change is announced.

        The check (set the same termios again, expect ``TIOCPKT_IOCTL`` at
        once) guards against an ``EXTPROC`` value that is not this kernel's
        (it differs on a few architectures) and anything else that would
        leave a change unannounced; then both are undone and the speed is
        read for every packet.
        """
        try:
            original = termios.tcgetattr(self._slave)
        except termios.error:
            return False
        attributes = termios.tcgetattr(self._slave)
        attributes[3] |= _EXTPROC
        try:
            termios.tcsetattr(self._slave, termios.TCSANOW, attributes)
            fcntl.ioctl(self._master, _TIOCPKT, struct.pack("i", 1))
            termios.tcsetattr(self._slave, termios.TCSANOW, attributes)
            status = os.read(self._master, 1)
            if status[:1] and status[0] & _TIOCPKT_IOCTL:
                return True
        except (OSError, termios.error):  # BlockingIOError included: nothing was announced
            pass
        try:
            fcntl.ioctl(self._master, _TIOCPKT, struct.pack("i", 0))
            termios.tcsetattr(self._slave, termios.TCSANOW, original)
        except (OSError, termios.error):
            pass
        return False

    def on_readable(self, fd: int) -> bytes:
        try:
            data = os.read(self._master, 4097)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if exc.errno == errno.EIO:  # no reader on the other side (cannot happen while we hold the slave)
                return b""
            raise
        if not (self._packet_mode and data):
            return data
        if data[0] == _TIOCPKT_DATA:
            return data[1:]
        if data[0] & _TIOCPKT_IOCTL:
            self._line_bps_known = False  # the host changed its termios: read the speed again
        return b""  # a status byte alone (also the flush before each of dynamixel-sdk's packets)

    def write(self, data: bytes) -> int:
        try:
            return os.write(self._master, data)
        except BlockingIOError:
            return 0
        except OSError as exc:
            if exc.errno == errno.EIO:
                return 0
            raise

    def line_bps(self) -> float | None:
        if self._line_bps_known:
            return self._line_bps
        speed: float | None = None
        lflag = 0
        if self._termios2:
            buffer = self._termios2_buffer
            try:
                fcntl.ioctl(self._slave, _TCGETS2, buffer, True)
                ospeed = _FIELD.unpack_from(buffer, _OSPEED_OFFSET)[0]
                lflag = _FIELD.unpack_from(buffer, _LFLAG_OFFSET)[0]
                speed = float(ospeed) if ospeed else None
                if lflag & _EXTPROC and self._packet_mode and (
                        _FIELD.unpack_from(buffer, _IFLAG_OFFSET)[0] & _COOKED_IFLAG or lflag & _COOKED_LFLAG):
                    lflag &= ~_EXTPROC  # a host that is not raw: let its line discipline work as on hardware
                    _FIELD.pack_into(buffer, _LFLAG_OFFSET, lflag)
                    try:
                        fcntl.ioctl(self._slave, _TCSETS2, buffer)
                    except OSError:
                        lflag |= _EXTPROC  # still set, so still announced: keep the reading until then
            except OSError:
                self._termios2 = False  # not Linux, or an old kernel: fall back to termios constants
        if speed is None:
            attributes = termios.tcgetattr(self._slave)
            speed, lflag = _SPEEDS.get(attributes[5]), attributes[3]
        # Kept only while EXTPROC is set: then the next change, even one clearing it, is announced.
        self._line_bps, self._line_bps_known = speed, self._packet_mode and bool(lflag & _EXTPROC)
        return speed

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self.link is not None:
            try:  # only our own: a link another server has put there since is its
                if self.link.is_symlink() and os.readlink(self.link) == self.slave_path:
                    self.link.unlink()
            except OSError:
                pass
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
