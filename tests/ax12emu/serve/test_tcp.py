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


def test_a_second_client_that_sends_at_once_sees_eof_not_a_reset(emulator):
    """A real client sends its first packet as it connects; closed with it unread, the socket answered with a reset
    ("connection reset by peer": a network fault, to the client) where the docs promise EOF."""
    served = emulator("--tcp", "127.0.0.1:0")
    host, port = served.port.removeprefix("socket://").rsplit(":", 1)
    first = socket.create_connection((host, int(port)), timeout=2)
    try:
        for _ in range(5):
            second = socket.create_connection((host, int(port)), timeout=2)
            try:
                second.sendall(PING)
                assert second.recv(10) == b""  # raised ConnectionResetError
            finally:
                second.close()
        first.sendall(PING)
        assert first.recv(6) == encode_status(1, 0)  # the first host still holds the bus
    finally:
        first.close()


def test_the_connected_client_is_probed_so_a_vanished_host_lets_go_of_the_bus():
    """A client whose host vanished sends no FIN: without keepalive probes the bus stayed taken for good."""
    from ax12emu.serve.transports import tcp

    transport = tcp.TcpTransport("127.0.0.1", 0)
    try:
        client = socket.create_connection((transport.host, transport.port), timeout=2)
        try:
            deadline = time.monotonic() + 2.0
            while transport._client is None and time.monotonic() < deadline:
                transport.on_readable(transport._listener.fileno())
            conn = transport._client
            assert conn.getsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE) == 1
            if hasattr(socket, "TCP_KEEPIDLE"):  # a dead peer is given up within idle + interval * probes
                idle = conn.getsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPIDLE)
                interval = conn.getsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPINTVL)
                probes = conn.getsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPCNT)
                assert idle + interval * probes <= 10
            if hasattr(socket, "TCP_USER_TIMEOUT"):  # and with a reply unacknowledged, where probes are not sent
                assert 0 < conn.getsockopt(socket.IPPROTO_TCP, socket.TCP_USER_TIMEOUT) <= 10_000
        finally:
            client.close()
    finally:
        transport.close()


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


def _address(served) -> tuple[str, int]:
    host, port = served.port.removeprefix("socket://").rsplit(":", 1)
    return host, int(port)


def test_a_client_that_half_closes_still_gets_its_replies(emulator):
    """shutdown(SHUT_WR) (``printf ... | nc -N``) says "nothing more to send", not "gone" (RFC 9293, 3.6): the
    replies to what it sent reach it, then the server closes its end (it used to close at once: 0 of 100)."""
    served = emulator("--tcp", "127.0.0.1:0", "--ids", "1,2")
    for _ in range(10):
        with socket.create_connection(_address(served), timeout=2) as client:
            client.sendall(PING + encode_instruction(2, 0x01))
            client.shutdown(socket.SHUT_WR)
            received = b""
            while True:
                chunk = client.recv(64)
                if not chunk:
                    break
                received += chunk
        assert received == encode_status(1, 0) + encode_status(2, 0)


def test_a_reply_owed_to_a_client_that_left_is_not_sent_to_the_next(emulator):
    """A new TCP client is a new host: a status packet for the one before it never reaches it."""
    served = emulator("--tcp", "127.0.0.1:0", "--ids", "1", "--delay", "1", "--delay-s", "0.3")  # every reply 0.3 s late
    with socket.create_connection(_address(served), timeout=2) as first:
        first.sendall(PING)  # answered 0.3 s late (an injected delay): the host is gone by then
    time.sleep(0.05)
    with socket.create_connection(_address(served), timeout=2) as second:
        second.settimeout(0.6)
        with pytest.raises(socket.timeout):
            second.recv(16)  # nothing it asked for
        second.sendall(PING)
        second.settimeout(2.0)
        assert second.recv(16) == encode_status(1, 0)  # its own ping: answered
