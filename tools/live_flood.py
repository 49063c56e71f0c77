"""A thousand hostile clients on the live view: does the bus keep answering, does memory stay bounded?

Starts ``ax12emu serve --tcp 127.0.0.1:0 --web 127.0.0.1:0`` and measures
dynamixel-sdk reads of Present Position (rate, failures) and the server's
resident memory, first undisturbed, then while the page's port holds

* ``--connections`` idle TCP connections (default 1000; past the server's
  limit each one is answered 503 and closed),
* ``--stuck`` WebSocket clients that never read (their frames pile up until
  the server drops them),
* ``--oversized`` requests with bodies over the limit, and malformed ones;

then, with ``--requests N``, while N clients (in a process of their own) send
``GET /api/servos`` back to back, as fast as the server answers them.

Prints the phases side by side; the tests (tests/ax12emu/live/test_hostile.py)
do the same with a couple of hundred connections.

Usage: ``python tools/live_flood.py [--connections 1000] [--stuck 50] [--seconds 3] [--requests 100]``
"""

from __future__ import annotations

import base64
import os
import resource
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request

from dynamixel_sdk import COMM_SUCCESS, PacketHandler

import ax12emu  # noqa: E402, F401 - first: once tests/ is on the path its ax12emu folder would shadow the package
import firmware_model  # noqa: E402, F401 - and its firmware_model folder this one
from ax12emu.cli.arg_types import OneLineParser, nonnegative_int, positive_float

sys.path.append(os.path.join(os.path.dirname(__file__), "..", "tests"))
from emu_testkit import UrlPortHandler  # noqa: E402


def rss_kb(pid: int) -> int:
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


def reads(port, ph, seconds: float) -> tuple[float, int]:
    count = failures = 0
    end = time.perf_counter() + seconds
    start = time.perf_counter()
    while time.perf_counter() < end:
        failures += ph.read2ByteTxRx(port, 1, 36)[1] != COMM_SUCCESS
        count += 1
    return count / (time.perf_counter() - start), failures


def stuck_websocket(host: str, port: int) -> socket.socket:
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect((host, port))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(f"GET /ws HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                 f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode())
    return sock


def status_of(url: str, data: bytes | None = None) -> int:
    """A request's HTTP status; a body goes as JSON, as the page sends its controls (another type is refused, 415)."""
    headers = {} if data is None else {"Content-Type": "application/json"}
    try:
        with urllib.request.urlopen(urllib.request.Request(url, data=data, headers=headers), timeout=5) as answer:
            return answer.status
    except urllib.error.HTTPError as error:
        error.close()
        return error.code
    except OSError:
        return 0


#: The request flood's clients, run by ``python -c`` in a process of their own (so they do not share this one's
#: interpreter with the dynamixel-sdk reads being measured): argv url, clients, seconds; prints "status:count ...".
REQUEST_FLOOD = """
import asyncio, sys, time, aiohttp
url, clients, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
counts = {}
async def client(session):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            async with session.get(url) as answer:
                await answer.read()
                counts[answer.status] = counts.get(answer.status, 0) + 1
        except (aiohttp.ClientError, OSError) as error:
            counts[type(error).__name__] = counts.get(type(error).__name__, 0) + 1
async def main():
    async with aiohttp.ClientSession(connector=aiohttp.TCPConnector(limit=0)) as session:
        await asyncio.gather(*[client(session) for _ in range(clients)])
asyncio.run(main())
print(" ".join(f"{status}:{count}" for status, count in sorted(counts.items(), key=str)))
"""


def request_flood(page_url: str, clients: int, seconds: float, port, ph) -> None:
    """Reads measured while ``clients`` GET /api/servos as fast as they are answered; prints the rates."""
    quiet_rate, _ = reads(port, ph, seconds)
    flood = subprocess.Popen([sys.executable, "-c", REQUEST_FLOOD, page_url + "api/servos", str(clients),
                              str(seconds + 1.0)], stdout=subprocess.PIPE, text=True)
    try:
        time.sleep(0.5)  # the clients connect
        rate, failures = reads(port, ph, seconds)
        said = flood.communicate(timeout=seconds + 30)[0].strip()
    finally:
        if flood.poll() is None:
            flood.kill()
            flood.wait()
    answered = sum(int(part.split(":")[1]) for part in said.split() if part.split(":")[0].isdigit())
    print(f"GET flood:   {rate:7.0f} reads/s, {failures} failures, against {quiet_rate:.0f} just before: "
          f"{rate / quiet_rate:.1%} ({clients} clients, {answered / (seconds + 1.0):.0f} requests/s answered: {said})")


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--connections", type=nonnegative_int, default=1000)
    parser.add_argument("--stuck", type=nonnegative_int, default=50, help="WebSocket clients that never read")
    parser.add_argument("--seconds", type=positive_float, default=3.0)
    parser.add_argument("--requests", type=nonnegative_int, default=0, metavar="N",
                        help="also measure while N clients send GET /api/servos back to back")
    args = parser.parse_args(argv)
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, max(soft, args.connections + args.stuck + 256)), hard))
    # The server's own log counts the clients it drops (the page's packet log, which the reads scroll, lost them).
    server_log = tempfile.TemporaryFile(mode="w+")
    process = subprocess.Popen([sys.executable, "-m", "ax12emu", "serve", "--tcp", "127.0.0.1:0", "--web", "127.0.0.1:0"],
                               stdout=subprocess.PIPE, stderr=server_log, text=True)
    held: list[socket.socket] = []
    try:
        bus_url, page_url = process.stdout.readline().strip(), process.stdout.readline().strip()
        host, web_port = page_url.split("//")[1].rstrip("/").rsplit(":", 1)
        port, ph = UrlPortHandler(bus_url), PacketHandler(1.0)
        port.openPort()
        port.setBaudRate(1_000_000)
        reads(port, ph, 0.5)
        quiet_rate, quiet_failures = reads(port, ph, args.seconds)
        quiet_rss = rss_kb(process.pid)
        print(f"undisturbed: {quiet_rate:7.0f} reads/s, {quiet_failures} failures, server RSS {quiet_rss / 1024:.1f} MB")

        for _ in range(args.stuck):  # first, so they get in before the idle ones fill the connection limit
            held.append(stuck_websocket(host, int(web_port)))
        statuses = [status_of(page_url + "api/control", b"x" * 100_000), status_of(page_url + "api/control", b"{bad")]
        refused = 0
        for _ in range(args.connections):
            try:
                held.append(socket.create_connection((host, int(web_port)), timeout=5))
            except OSError:
                refused += 1
        flood_rate, flood_failures = reads(port, ph, args.seconds)
        flood_rss = rss_kb(process.pid)
        page = status_of(page_url + "api/servos")
        print(f"flooded:     {flood_rate:7.0f} reads/s, {flood_failures} failures, server RSS {flood_rss / 1024:.1f} MB "
              f"({args.connections} connections, {refused} refused at connect, {args.stuck} never-reading WebSocket clients)")
        print(f"oversized and malformed control requests answered {statuses}; "
              f"GET /api/servos during the flood: {page}")
        print(f"read rate during the flood: {flood_rate / quiet_rate:.1%} of undisturbed; "
              f"memory grew {(flood_rss - quiet_rss) / 1024:.1f} MB")
        for sock in held[args.stuck:]:  # the idle flood ends; the stuck clients stay
            sock.close()
        del held[args.stuck:]
        # A stuck client is dropped once its kernel buffers and its frame queue are full: about ten
        # seconds for one small servo's frames (about 1 kB each at 25 Hz).
        deadline = time.monotonic() + 60
        dropped = 0
        while time.monotonic() < deadline and dropped < min(args.stuck, 32):
            server_log.seek(0)
            dropped = server_log.read().count("dropped a WebSocket client (not reading)")
            time.sleep(1.0)
        print(f"{dropped} never-reading WebSocket clients dropped after {60 - (deadline - time.monotonic()):.0f} s "
              f"(at most 32 are admitted; server RSS {rss_kb(process.pid) / 1024:.1f} MB)")
        for sock in held:
            sock.close()
        held.clear()
        time.sleep(1.0)
        after = status_of(page_url + "api/servos")
        print(f"after the flood: GET /api/servos {after}, server RSS {rss_kb(process.pid) / 1024:.1f} MB")
        if args.requests:
            request_flood(page_url, args.requests, args.seconds, port, ph)
        port.closePort()
    finally:
        for sock in held:
            sock.close()
        process.terminate()
        process.wait(10)
        server_log.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
