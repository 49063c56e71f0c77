"""The same bus over TCP, with pyserial's socket:// as the client."""

from __future__ import annotations

import socket
import time

import pytest
import serial
from emu_testkit import UrlPortHandler

from ax12emu.protocol.packets import encode_instruction, encode_status

#: Real time and real ports: the wall-clock tier (CI runs it too).
pytestmark = pytest.mark.wallclock

PING = encode_instruction(1, 0x01)


def test_socket_url_client_talks_to_the_bus(emulator):
    """serial_for_url('socket://...') pings, reads and writes like a serial port."""
    served = emulator("--tcp", "127.0.0.1:0", "--ids", "1,2")
    assert served.port.startswith("socket://127.0.0.1:")
    with serial.serial_for_url(served.port, timeout=1.0) as link:
        link.write(PING)
        assert link.read(6) == encode_status(1, 0)
        link.write(encode_instruction(2, 0x02, bytes([0, 2])))
        assert link.read(8) == encode_status(2, 0, b"\x0c\x00")


def test_second_client_refused_and_reconnect_after_mid_packet_drop(emulator):
    """A second client gets EOF; a client leaving mid-packet does not stop the bus."""
    served = emulator("--tcp", "127.0.0.1:0")
    host, port = served.port.removeprefix("socket://").rsplit(":", 1)
    first = socket.create_connection((host, int(port)), timeout=2)
    second = socket.create_connection((host, int(port)), timeout=2)
    assert second.recv(10) == b""  # refused: closed at once
    second.close()
    first.sendall(PING[:3])
    first.close()
    time.sleep(0.05)
    with serial.serial_for_url(served.port, timeout=1.0) as link:
        link.write(PING)
        assert link.read(6) == encode_status(1, 0)


def test_dynamixel_sdk_over_tcp_with_url_port_handler(emulator):
    """dynamixel-sdk drives the TCP bus through the README's three-line PortHandler subclass."""
    from dynamixel_sdk import COMM_SUCCESS, PacketHandler

    served = emulator("--tcp", "127.0.0.1:0", "--ids", "3")
    port = UrlPortHandler(served.port)  # the docs' PortHandler subclass (emu_testkit)
    assert port.openPort()
    try:
        ph = PacketHandler(1.0)
        assert ph.ping(port, 3) == (12, COMM_SUCCESS, 0)
        assert ph.write2ByteTxRx(port, 3, 32, 123) == (COMM_SUCCESS, 0)
        assert ph.read2ByteTxRx(port, 3, 32) == (123, COMM_SUCCESS, 0)
    finally:
        port.closePort()
