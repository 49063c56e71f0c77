"""The pty transport: raw bytes both ways, and the host's line speed as its termios say, kept up to date."""

from __future__ import annotations

import fcntl
import os
import select
import sys
import termios
import time

import pytest
import serial

from ax12emu.serve.transports import pty as pty_transport
from ax12emu.serve.transports.pty import PtyTransport

#: Real time and real ports: the wall-clock tier (CI runs it too).
pytestmark = pytest.mark.wallclock

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="packet mode is used on Linux only")


@pytest.fixture
def transport():
    link = PtyTransport()
    yield link
    link.close()


def _receive(transport: PtyTransport, timeout_s: float = 2.0) -> bytes:
    """The next data the host sent, skipping the status bytes of packet mode."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        select.select(transport.fds(), [], [], max(0.0, deadline - time.monotonic()))
        data = transport.on_readable(transport.fds()[0])
        if data:
            return data
    raise AssertionError("nothing arrived")


def test_bytes_pass_unchanged_both_ways(transport):
    """Every byte value, 0x00 and the line editing characters included, crosses in both directions."""
    everything = bytes(range(256))
    with serial.Serial(transport.slave_path, 1_000_000, timeout=1.0) as host:
        host.write(everything)
        received = b""
        while len(received) < len(everything):
            received += _receive(transport)
        assert received == everything
        assert transport.write(everything) == len(everything)
        assert host.read(len(everything)) == everything


def test_line_speed_follows_every_change_the_host_makes(transport):
    """Standard rates, a non-standard one (pyserial sets it with BOTHER), and a reopen at another rate."""
    with serial.Serial(transport.slave_path, 1_000_000, timeout=1.0) as host:
        for bps in (57_600, 250_000, 1_000_000, 9_600):
            host.baudrate = bps
            host.write(b"x")
            assert _receive(transport) == b"x"
            assert transport.line_bps() == bps
    with serial.Serial(transport.slave_path, 115_200, timeout=1.0) as host:
        host.write(b"y")
        assert _receive(transport) == b"y"
        assert transport.line_bps() == 115_200


@linux_only
def test_speed_is_read_once_until_the_host_changes_its_termios(transport, monkeypatch):
    """Between changes the speed costs no system call; a change is announced before the host's next byte."""
    calls = []
    real_ioctl = fcntl.ioctl

    def counting_ioctl(fd, request, *args):
        if request == pty_transport._TCGETS2 and fd == transport._slave:  # pyserial calls it too
            calls.append(fd)
        return real_ioctl(fd, request, *args)

    monkeypatch.setattr(pty_transport.fcntl, "ioctl", counting_ioctl)
    with serial.Serial(transport.slave_path, 1_000_000, timeout=1.0) as host:
        host.write(b"a")
        assert _receive(transport) == b"a"
        assert [transport.line_bps() for _ in range(100)] == [1_000_000] * 100
        assert len(calls) == 1
        host.baudrate = 57_600
        host.write(b"b")
        assert _receive(transport) == b"b"
        assert transport.line_bps() == 57_600
        assert len(calls) == 2


@linux_only
def test_a_host_that_clears_extproc_gets_a_fresh_reading_for_every_packet(transport):
    """Without EXTPROC the kernel announces nothing, so the speed is read each time, and stays right."""
    host = os.open(transport.slave_path, os.O_RDWR | os.O_NOCTTY)
    try:
        attributes = termios.tcgetattr(host)
        attributes[3] &= ~pty_transport._EXTPROC
        termios.tcsetattr(host, termios.TCSANOW, attributes)
        os.write(host, b"a")
        assert _receive(transport) == b"a"
        assert transport.line_bps() == 38_400.0  # a fresh pty's rate, B38400
        for speed, bps in ((termios.B57600, 57_600), (termios.B9600, 9_600)):
            attributes = termios.tcgetattr(host)
            attributes[4] = attributes[5] = speed
            termios.tcsetattr(host, termios.TCSANOW, attributes)  # no announcement now
            assert transport.line_bps() == bps
    finally:
        os.close(host)


@linux_only
def test_a_kernel_that_announces_nothing_gets_a_fresh_reading_for_every_packet(monkeypatch):
    """If the start-up check sees no announcement, packet mode stays off and every reading is fresh."""
    monkeypatch.setattr(pty_transport, "_TIOCPKT_IOCTL", 0)  # the check then sees no announcement
    link = PtyTransport()
    try:
        assert not link._packet_mode
        assert not termios.tcgetattr(link._slave)[3] & pty_transport._EXTPROC  # the flag is taken back
        with serial.Serial(link.slave_path, 1_000_000, timeout=1.0) as host:
            host.write(b"\x00a")
            assert _receive(link) == b"\x00a"  # no status byte to strip
            assert link.line_bps() == 1_000_000
            host.baudrate = 57_600
            assert link.line_bps() == 57_600
    finally:
        link.close()


@linux_only
def test_a_host_that_is_not_raw_gets_its_line_discipline_back(transport):
    """EXTPROC would switch off a host's ICRNL and echo; at its first packet the emulator takes it off."""
    with serial.Serial(transport.slave_path, 1_000_000, timeout=1.0) as host:
        attributes = termios.tcgetattr(host.fd)
        attributes[0] |= termios.ICRNL  # CR to NL on input, as a port left half-cooked would do
        termios.tcsetattr(host.fd, termios.TCSANOW, attributes)
        assert termios.tcgetattr(host.fd)[3] & pty_transport._EXTPROC  # kept by the host's read-modify-write
        host.write(b"a")
        assert _receive(transport) == b"a"
        assert transport.line_bps() == 1_000_000
        assert not termios.tcgetattr(host.fd)[3] & pty_transport._EXTPROC
        assert transport.write(b"\r") == 1
        assert host.read(1) == b"\n"  # what the host's line discipline makes of it on hardware too
        host.baudrate = 57_600  # no longer announced: read for every packet
        assert transport.line_bps() == 57_600


def test_a_link_left_at_this_transports_own_pty_is_taken_without_a_warning(tmp_path, monkeypatch, caplog):
    """A run killed before it removed its --link left it at a pty number; the next run got that number and warned
    the link "pointed at /dev/pts/N, which is there (another server's pty?)": its own."""
    link = tmp_path / "ax12"
    opened = pty_transport.pty.openpty

    def openpty_as_the_crashed_run_left_it():
        master, slave = opened()
        link.symlink_to(os.ttyname(slave))
        return master, slave

    monkeypatch.setattr(pty_transport.pty, "openpty", openpty_as_the_crashed_run_left_it)
    with caplog.at_level("WARNING", logger=pty_transport.__name__):
        own = PtyTransport(link=link)
    try:
        assert os.readlink(link) == own.slave_path
        assert [record.getMessage() for record in caplog.records] == []
    finally:
        own.close()


def test_a_link_at_another_open_pty_is_taken_with_a_warning(tmp_path, caplog):
    link = tmp_path / "ax12"
    other = PtyTransport(link=link)
    try:
        with caplog.at_level("WARNING", logger=pty_transport.__name__):
            second = PtyTransport(link=link)
        second.close()
        assert [f"pointed at {other.slave_path}, which is there" in record.getMessage() for record in caplog.records] == [True]
    finally:
        other.close()
