"""The same bus over TCP, with pyserial's socket:// as the client."""

from __future__ import annotations

import socket
import time

import serial

from ax12emu.packets import encode_instruction, encode_status

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
