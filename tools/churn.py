"""Connection churn: clients come and go, mid-packet too, and the bus keeps serving.

* pty: a client opens the port, does one of (nothing, a PING and its reply,
  half a packet, a READ whose reply is left mostly unread), and closes it;
  ``--pty-opens`` times (the next open flushes unread bytes, as pyserial and
  dynamixel-sdk do);
* TCP: a client connects, sends a PING or half a packet, disconnects, and
  the next client reconnects at once; ``--tcp-connects`` times;
* TCP, second client: while a host is connected and polling, other clients
  connect and send WRITEs; each is accepted and closed at once (it reads
  EOF), none of its bytes reaches the bus (the register it wrote is
  unchanged) and the host's reply stream holds only its own replies.

After each phase a PING and a dynamixel-sdk read must succeed, and the
emulator process must still be running.

Usage: ``python tools/churn.py [--pty-opens 1000] [--tcp-connects 1000]``
"""

from __future__ import annotations

import random
import select
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field

import serial

from ax12emu.cli.arg_types import OneLineParser, nonnegative_int
from ax12emu.protocol.framing import DEFAULT_SILENCE_TIMEOUT_S
from ax12emu.protocol.packets import encode_instruction, encode_status

PING = encode_instruction(1, 0x01)
PONG = encode_status(1, 0)
READ_LED = encode_instruction(1, 0x02, bytes([25, 1]))
#: Silence after a half packet, so the emulator drops it before the next packet: several times the
#: framer's timeout, which runs from when the emulator read the half (late, if it was held up).
QUIET_S = 5 * DEFAULT_SILENCE_TIMEOUT_S


@dataclass
class ChurnReport:
    """Counts of one churn phase."""

    cycles: int = 0
    pings_answered: int = 0
    partial_packets: int = 0
    refused_clients: int = 0
    host_replies: int = 0
    failures: list[str] = field(default_factory=list)


def check_alive(port: str, process: subprocess.Popen | None = None) -> None:
    """The emulator still runs and answers a PING on ``port`` (a pty path or socket:// URL)."""
    if process is not None and process.poll() is not None:
        raise AssertionError(f"the emulator exited with {process.returncode}")
    time.sleep(QUIET_S)  # past the framer's silence timeout: a partial packet is dropped
    with serial.serial_for_url(port, baudrate=1_000_000, timeout=1.0) as link:
        link.reset_input_buffer()
        link.write(PING)
        reply = link.read(6)
    if reply != PONG:
        raise AssertionError(f"PING after churn got {reply.hex()}")


def pty_churn(path: str, opens: int, *, seed: int = 0) -> ChurnReport:
    """Open and close the pty ``opens`` times, doing a random small thing each time."""
    rng = random.Random(seed)
    report = ChurnReport()
    for cycle in range(opens):
        action = rng.choice(("nothing", "ping", "ping", "half", "unread"))
        with serial.Serial(path, 1_000_000, timeout=0.5) as link:
            if action == "ping":
                link.write(PING)
                reply = link.read(6)
                if reply != PONG:
                    report.failures.append(f"open {cycle}: PING got {reply.hex()}")
                    break
                report.pings_answered += 1
            elif action == "half":
                link.write(PING[: rng.randint(1, len(PING) - 1)])
                report.partial_packets += 1
            elif action == "unread":
                link.write(READ_LED)
                link.read(2)  # the reply has arrived; 5 of its bytes stay unread at close
        if action == "half":
            time.sleep(QUIET_S)  # the next opener's packet must not be glued to this half (silence timeout)
        report.cycles += 1
    return report


def _host_port(url: str) -> tuple[str, int]:
    host, port = url.removeprefix("socket://").rsplit(":", 1)
    return host, int(port)


def tcp_churn(url: str, connects: int, *, seed: int = 0) -> ChurnReport:
    """Connect, send a PING (and read it) or half a packet, disconnect; ``connects`` times."""
    rng = random.Random(seed)
    address = _host_port(url)
    report = ChurnReport()
    for cycle in range(connects):
        with socket.create_connection(address, timeout=2.0) as sock:
            if rng.random() < 0.5:
                sock.sendall(PING)
                reply = _recv_exactly(sock, 6)
                if reply != PONG:
                    report.failures.append(f"connection {cycle}: PING got {reply.hex()}")
                    break
                report.pings_answered += 1
            else:
                sock.sendall(PING[: rng.randint(1, len(PING) - 1)])
                report.partial_packets += 1
                time.sleep(0.025)  # the framer drops the half packet after its silence timeout
        report.cycles += 1
    return report


def _recv_exactly(sock: socket.socket, count: int) -> bytes:
    data = b""
    while len(data) < count:
        chunk = sock.recv(count - len(data))
        if not chunk:
            break
        data += chunk
    return data


def second_clients(url: str, intruders: int) -> ChurnReport:
    """A host polls LED while ``intruders`` other clients connect and write LED=1: all refused, nothing mixed."""
    address = _host_port(url)
    report = ChurnReport()
    with socket.create_connection(address, timeout=2.0) as host:
        host.sendall(PING)
        if _recv_exactly(host, 6) != PONG:
            report.failures.append("host PING failed before the intruders")
            return report
        for cycle in range(intruders):
            with socket.create_connection(address, timeout=2.0) as intruder:
                try:
                    intruder.sendall(encode_instruction(1, 0x03, bytes([25, 1])) + PING * 3)
                except OSError:
                    pass  # already closed by the server: as good as refused
                try:
                    closed = intruder.recv(16) == b""
                except ConnectionResetError:
                    closed = True
                if not closed:
                    report.failures.append(f"intruder {cycle} was answered")
                    break
                report.refused_clients += 1
            host.sendall(READ_LED)
            reply = _recv_exactly(host, 7)
            if reply != encode_status(1, 0, b"\x00"):
                report.failures.append(f"cycle {cycle}: host READ of LED got {reply.hex()} (expected LED 0, no extra bytes)")
                break
            report.host_replies += 1
            report.cycles += 1
        host.setblocking(False)
        try:
            extra = host.recv(64)
        except BlockingIOError:
            extra = b""
        if extra:
            report.failures.append(f"host received bytes it did not ask for: {extra.hex()}")
    return report


def _start(*args: str) -> tuple[subprocess.Popen, str]:
    process = subprocess.Popen([sys.executable, "-m", "ax12emu", "serve", *args],
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    ready, _, _ = select.select([process.stdout], [], [], 20)
    line = process.stdout.readline().strip() if ready else ""
    if not line:
        process.kill()
        raise RuntimeError("the emulator did not start")
    return process, line


def _sdk_read(path: str) -> None:
    from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

    port = PortHandler(path)
    assert port.openPort() and port.setBaudRate(1_000_000)
    try:
        value, comm, error = PacketHandler(1.0).read2ByteTxRx(port, 1, 0)
        assert (value, comm, error) == (12, COMM_SUCCESS, 0), (value, comm, error)
    finally:
        port.closePort()


def main(argv: list[str] | None = None) -> int:
    """Run the three phases against fresh emulators; print counts; exit 1 on a failure."""
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    # 0 leaves a phase out; a negative count ran it as 0 and printed it as done
    parser.add_argument("--pty-opens", type=nonnegative_int, default=1000)
    parser.add_argument("--tcp-connects", type=nonnegative_int, default=1000)
    parser.add_argument("--intruders", type=nonnegative_int, default=200)
    args = parser.parse_args(argv)
    failures = 0
    process, path = _start()
    try:
        started = time.monotonic()
        report = pty_churn(path, args.pty_opens)
        check_alive(path, process)
        _sdk_read(path)
        print(f"pty: {report.cycles} opens/closes in {time.monotonic() - started:.1f} s, {report.pings_answered} PINGs "
              f"answered, {report.partial_packets} closed mid-packet; bus still serving (PING, dynamixel-sdk read)")
        failures += len(report.failures)
        for failure in report.failures:
            print(f"FAILURE: {failure}")
    finally:
        process.kill()
        process.wait()
    process, url = _start("--tcp", "127.0.0.1:0")
    try:
        started = time.monotonic()
        report = tcp_churn(url, args.tcp_connects)
        check_alive(url, process)
        print(f"tcp: {report.cycles} connects in {time.monotonic() - started:.1f} s, {report.pings_answered} PINGs "
              f"answered, {report.partial_packets} disconnects mid-packet; bus still serving")
        intruders = second_clients(url, args.intruders)
        check_alive(url, process)
        print(f"tcp second clients: {intruders.refused_clients} accepted and closed at once while a host polled; "
              f"host got exactly its {intruders.host_replies} replies, LED never written by an intruder")
        for failure in report.failures + intruders.failures:
            print(f"FAILURE: {failure}")
        failures += len(report.failures) + len(intruders.failures)
    finally:
        process.kill()
        process.wait()
    print(f"failures: {failures}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
