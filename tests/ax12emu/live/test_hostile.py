"""Hostile and careless clients of the live view cannot hurt the bus, and memory stays bounded.

The full thousand connections are tools/live_flood.py's job; here counts are modest.
"""

from __future__ import annotations

import asyncio
import base64
import json
import logging
import os
import socket
import time
import urllib.error
import urllib.request

import pytest

aiohttp = pytest.importorskip("aiohttp")

from dynamixel_sdk import COMM_SUCCESS  # noqa: E402
from emu_testkit import http_json, sdk_port  # noqa: E402

from ax12emu import VirtualBus  # noqa: E402
from ax12emu.live import Sampler  # noqa: E402
from ax12emu.live import web as web_module  # noqa: E402
from ax12emu.live.web import MAX_MESSAGE_BYTES, QUEUE_FRAMES, WebServer  # noqa: E402
from ax12emu.protocol.packets import Instruction, InstructionPacket  # noqa: E402


def get_json(url: str) -> tuple[int, dict]:
    return http_json(url, method="GET")


def host_port(url: str) -> tuple[str, int]:
    host, port = url.split("//")[1].rstrip("/").rsplit(":", 1)
    return host, int(port)


@pytest.fixture
def bus():
    with VirtualBus(list(range(1, 19)), transport="tcp", web=True) as bus:
        yield bus


async def _frames(url: str, seconds: float) -> list[dict]:
    frames = []
    async with aiohttp.ClientSession() as session, session.ws_connect(url.replace("http", "ws") + "ws") as ws:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            message = await ws.receive(timeout=seconds)
            data = json.loads(message.data)
            if data["type"] == "frame":
                frames.append(data)
    return frames


def test_frames_stream_at_20_hz_or_more(bus):
    frames = asyncio.run(_frames(bus.web_url, 1.0))
    assert len(frames) >= 20, len(frames)
    assert len(frames[-1]["servos"]) == 18


def test_many_idle_connections_leave_the_bus_and_the_page_answering(bus):
    host, port = host_port(bus.web_url)
    idle = []
    try:
        for _ in range(200):
            idle.append(socket.create_connection((host, port), timeout=5))
        idle[0].sendall(b"GET /api/servos HTTP/1.1\r\nHost: x\r\n")  # a request that never ends
        with sdk_port(bus.port) as (sdk, ph):
            for servo_id in (1, 18):
                assert ph.ping(sdk, servo_id)[1] == COMM_SUCCESS
        status, body = get_json(bus.web_url + "api/servos")
        assert status == 200 and len(body["servos"]) == 18
    finally:
        for connection in idle:
            connection.close()


def test_connections_past_the_limit_get_503_and_are_closed():
    with VirtualBus([1], transport="inprocess") as bus:
        sampler = Sampler(bus.call).start()
        web = WebServer(sampler, bus, max_connections=20).start()
        held = []
        try:
            for _ in range(20):
                held.append(socket.create_connection(("127.0.0.1", web.port), timeout=5))
            time.sleep(0.2)  # let the server accept them
            with socket.create_connection(("127.0.0.1", web.port), timeout=5) as extra:
                answer = extra.recv(1000)
            assert answer.startswith(b"HTTP/1.1 503") and b"too many connections" in answer
            for connection in held:
                connection.close()
            held.clear()
            deadline = time.monotonic() + 3
            status = None
            while status != 200 and time.monotonic() < deadline:  # the closed ones are counted out: requests get through again
                try:
                    status, _ = get_json(web.url + "api/servos")
                except (urllib.error.URLError, ConnectionError):
                    status = None
                time.sleep(0.05)
            assert status == 200
        finally:
            for connection in held:
                connection.close()
            web.close()
            sampler.close()


def _websocket_handshake(host: str, port: int, receive_buffer: int) -> socket.socket:
    """A raw WebSocket client socket after the handshake (for a client that then never reads)."""
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
    sock.connect((host, port))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        f"GET /ws HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
    )
    assert sock.recv(1024).startswith(b"HTTP/1.1 101")
    return sock


def test_a_client_that_never_reads_is_dropped_while_others_keep_streaming(bus):
    host, port = host_port(bus.web_url)
    stuck = _websocket_handshake(host, port, 4096)
    try:
        web = bus._live.web
        deadline = time.monotonic() + 10
        frames = []
        while web.dropped_clients == 0 and time.monotonic() < deadline:
            frames += asyncio.run(_frames(bus.web_url, 0.5))  # a good client meanwhile
        assert web.dropped_clients >= 1
        assert len(frames) >= 8
        with sdk_port(bus.port) as (sdk, ph):
            assert ph.ping(sdk, 1)[1] == COMM_SUCCESS
        lines = get_json(bus.web_url + "api/log?n=200")[1]["lines"]
        assert any("stopped reading" in line["text"] for line in lines)
    finally:
        stuck.close()
    assert QUEUE_FRAMES <= 16  # what bounds a slow client's memory, with the kernel's send buffer


async def _ws_abuse(url: str) -> tuple[list[dict], int | None]:
    answers = []
    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(url.replace("http", "ws") + "ws", max_msg_size=0) as ws:
            await ws.send_str("{not json")
            await ws.send_bytes(b"\x00\x01")
            await ws.send_str(json.dumps({"action": "vanish", "slot": 42}))
            await ws.send_str(json.dumps({"action": "alarm", "slot": 2, "bits": "overheating"}))
            while len(answers) < 4:
                data = json.loads((await ws.receive(timeout=5)).data)
                if data["type"] in ("error", "reply"):
                    answers.append(data)
        async with session.ws_connect(url.replace("http", "ws") + "ws") as ws:
            await ws.send_str("x" * (MAX_MESSAGE_BYTES + 1))
            while True:
                message = await ws.receive(timeout=5)
                if message.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.CLOSING):
                    break
            return answers, ws.close_code


def test_malformed_and_oversized_websocket_messages_get_clear_errors(bus):
    answers, close_code = asyncio.run(_ws_abuse(bus.web_url))
    assert "not JSON" in answers[0]["error"]
    assert "JSON text" in answers[1]["error"]
    assert answers[2]["status"] == 400 and "no servo launched as ID 42" in answers[2]["error"]
    assert answers[3]["status"] == 200  # a good message still works on the same socket
    assert close_code == 1009  # message too big
    with sdk_port(bus.port) as (sdk, ph):
        _, comm, error = ph.ping(sdk, 2)
        assert comm == COMM_SUCCESS and error & 0x04  # the alarm sent over the socket took
        assert ph.ping(sdk, 3)[1] == COMM_SUCCESS


def _raw_request(host: str, port: int, request: bytes, wait_s: float = 5.0) -> bytes:
    """Send ``request`` as is and return everything the server says until it closes (or ``wait_s`` passes)."""
    with socket.create_connection((host, port), timeout=wait_s) as sock:
        sock.sendall(request)
        answer = b""
        try:
            while chunk := sock.recv(4096):
                answer += chunk
        except TimeoutError:
            pass
        return answer


def test_a_control_body_that_stalls_gets_408_and_its_connection_is_closed(bus, monkeypatch):
    """Headers, then one byte of a 100-byte body, then nothing: answered 408 and closed once BODY_TIMEOUT_S is
    over, where the connection used to stay open (256 such held every slot for good)."""
    monkeypatch.setattr(web_module, "BODY_TIMEOUT_S", 0.5)
    host, port = host_port(bus.web_url)
    start = time.monotonic()
    answer = _raw_request(host, port, f"POST /api/control HTTP/1.1\r\nHost: {host}:{port}\r\nContent-Type: application/json\r\n"
                                      "Content-Length: 100\r\n\r\n{".encode())
    assert answer.startswith(b"HTTP/1.1 408") and b"did not arrive" in answer, answer[:200]
    assert time.monotonic() - start < 4.0  # closed by the server, not by the client's own 5 s timeout


BAD_BODIES = [
    ({"Content-Type": "application/json"}, b"[" * 5000 + b"]" * 5000, "nested too deeply"),
    ({"Content-Type": "application/json; charset=bogus"}, b'{"action": 1}', "action"),  # read as UTF-8 JSON
    ({"Content-Type": "application/json", "Content-Encoding": "gzip"}, b"abcde", "could not be read"),
    ({"Content-Type": "application/json"}, b"\xff\xfe{", "not JSON"),
]


@pytest.mark.parametrize(("headers", "body", "says"), BAD_BODIES, ids=["deep", "charset", "gzip", "bytes"])
def test_malformed_control_bodies_get_400_with_the_reason(bus, headers, body, says):
    status, answer = http_json(bus.web_url + "api/control", body, headers)
    assert status == 400 and says in answer["error"], (status, answer)


def test_a_deeply_nested_websocket_message_gets_an_error_and_the_socket_stays(bus):
    async def run() -> tuple[dict, dict]:
        async with aiohttp.ClientSession() as session, session.ws_connect(bus.web_url.replace("http", "ws") + "ws") as ws:
            await ws.send_str("[" * 2000 + "]" * 2000)
            answers = []
            while len(answers) < 2:
                data = json.loads((await ws.receive(timeout=5)).data)
                if data["type"] == "error":
                    answers.append(data)
                    await ws.send_str(json.dumps({"action": "clear_faults"}))
                elif data["type"] == "reply":
                    answers.append(data)
            return answers[0], answers[1]

    error, reply = asyncio.run(run())
    assert "nested too deeply" in error["error"] and reply["status"] == 200


def test_a_clients_own_faults_are_one_info_line_not_an_error_with_a_traceback(bus, caplog):
    """A malformed request aiohttp answers with 400 and a request dropped mid-body: logged, but not as errors."""
    host, port = host_port(bus.web_url)
    with caplog.at_level(logging.INFO, logger="aiohttp.server"):
        refused = _raw_request(host, port, b"POST /api/control HTTP/1.1\r\nHost: x\r\nContent-Length: -1\r\n\r\n")
        assert refused.split(b"\r\n")[0].endswith(b" 400 Bad Request"), refused[:100]
        with socket.create_connection((host, port), timeout=5) as sock:
            sock.sendall(f"POST /api/control HTTP/1.1\r\nHost: {host}:{port}\r\nContent-Type: application/json\r\n"
                         "Content-Length: 100\r\n\r\n{".encode())
            time.sleep(0.2)
        deadline = time.monotonic() + 3
        while time.monotonic() < deadline and len([r for r in caplog.records if r.name == "aiohttp.server"]) < 2:
            time.sleep(0.05)
    server = [r for r in caplog.records if r.name == "aiohttp.server"]
    assert len(server) >= 2, [r.getMessage() for r in caplog.records]
    assert all(r.levelno == logging.INFO and r.exc_info is None and "a client's request ended" in r.getMessage()
               and "\n" not in r.getMessage() for r in server), [(r.levelname, r.getMessage()) for r in server]


def test_requests_past_the_rate_wait_their_turn_or_get_503(bus, monkeypatch):
    """REQUESTS_PER_S paces every route but the socket's frames: of 20 requests at once at 10 a second with at
    most 0.5 s to wait, about 6 are answered (spread over half a second) and the rest get 503 at once; that is
    what keeps a flood of requests from starving the bus this process also serves."""
    monkeypatch.setattr(web_module, "REQUESTS_PER_S", 10.0)
    monkeypatch.setattr(web_module, "MAX_REQUEST_WAIT_S", 0.5)
    time.sleep(0.3)  # the fixture's own requests' turns are over

    async def burst() -> list[tuple[int, float, str]]:
        start = time.monotonic()
        async with aiohttp.ClientSession() as session:
            async def one() -> tuple[int, float, str]:
                async with session.get(bus.web_url + "api/log?n=1") as answer:
                    return answer.status, time.monotonic() - start, await answer.text()
            return await asyncio.gather(*[one() for _ in range(20)])

    answers = asyncio.run(burst())
    served = sorted(elapsed for status, elapsed, _ in answers if status == 200)
    refused = [text for status, _, text in answers if status == 503]
    assert 4 <= len(served) <= 14 and len(served) + len(refused) == 20, answers
    assert served[-1] >= 0.3  # the last ones waited their turn
    assert all("requests a second" in text for text in refused)


# -- other web pages in the user's browser -------------------------------------------------------


def _faults_of_slot_1(bus) -> list[str]:
    time.sleep(0.15)  # a few sampler periods: a control that went through shows
    return get_json(bus.web_url + "api/servos")[1]["servos"][0]["faults"]


def test_a_control_from_another_origins_page_is_refused_and_logged_in_one_line(bus, caplog):
    """Any page the user opens may POST here: as text/plain (a "simple" request, sent without asking the server
    first) or naming its origin; only the live view's own page (its origin, JSON) is obeyed."""
    url, own = bus.web_url + "api/control", bus.web_url.rstrip("/")
    vanish = b'{"action": "vanish", "slot": 1}'
    with caplog.at_level(logging.INFO, logger="ax12emu.live.web"):
        status, body = http_json(url, vanish, {"Content-Type": "text/plain;charset=UTF-8", "Origin": "http://evil.example"})
        assert status == 403 and "evil.example" in body["error"], body
        assert http_json(url, vanish, {"Content-Type": "application/json", "Origin": "http://evil.example"})[0] == 403
        assert http_json(url, vanish, {"Content-Type": "application/json", "Origin": "null"})[0] == 403  # a sandboxed page
        assert http_json(url, vanish, {"Content-Type": "application/json", "Origin": own.replace("http:", "https:")})[0] == 403
        status, body = http_json(url, vanish, {"Content-Type": "text/plain"})  # no Origin (a form, a script): not JSON
        assert status == 415 and "application/json" in body["error"], body
        assert _faults_of_slot_1(bus) == []
    refusals = [r for r in caplog.records if r.name == "ax12emu.live.web"]
    assert len(refusals) == 5 and all(r.levelno == logging.INFO and r.exc_info is None and "\n" not in r.getMessage()
                                      for r in refusals), [(r.levelname, r.getMessage()) for r in refusals]
    assert http_json(url, vanish, {"Content-Type": "application/json", "Origin": own})[0] == 200  # the page's own
    assert _faults_of_slot_1(bus) == ["vanished"]


def test_a_websocket_from_another_origins_page_is_refused(bus):
    async def connect(origin: str | None) -> int | str:
        async with aiohttp.ClientSession() as session:
            try:
                async with session.ws_connect(bus.web_url.replace("http", "ws") + "ws", origin=origin) as ws:
                    return json.loads((await ws.receive(timeout=5)).data)["type"]
            except aiohttp.WSServerHandshakeError as error:
                return error.status

    assert asyncio.run(connect("http://evil.example")) == 403
    assert asyncio.run(connect(bus.web_url.rstrip("/"))) == "hello"
    assert asyncio.run(connect(None)) == "hello"  # a script's client names no origin


def test_a_request_addressed_to_another_host_is_refused(bus):
    """DNS rebinding: a page on attacker.example whose name then points here is same-origin with itself, so the
    browser sends its own name as Host: only this server's names (with its port) are answered."""
    host, port = host_port(bus.web_url)
    servos = bus.web_url + "api/servos"
    status, body = http_json(servos, b"", {"Host": f"attacker.example:{port}"}, method="GET")
    assert status == 403 and "attacker.example" in body["error"], body
    assert http_json(servos, b"", {"Host": f"{host}:{port + 1}"}, method="GET")[0] == 403  # another port: another origin
    for name in (f"{host}:{port}", f"localhost:{port}", f"LOCALHOST:{port}", f"[::1]:{port}"):
        assert http_json(servos, b"", {"Host": name}, method="GET")[0] == 200, name
    vanish = b'{"action": "vanish", "slot": 1}'
    rebound = {"Host": f"attacker.example:{port}", "Origin": f"http://attacker.example:{port}", "Content-Type": "application/json"}
    assert http_json(bus.web_url + "api/control", vanish, rebound)[0] == 403
    assert _faults_of_slot_1(bus) == []


def test_which_hosts_name_the_server():
    """The bound address, the loopback names, and any IP address where the server binds every interface (a page of
    another site cannot make the browser send an IP address as Host: DNS rebinding needs a name)."""
    def server(host: str) -> WebServer:
        return WebServer(sampler=None, controls=None, host=host, port=8080, allow_remote=True)  # type: ignore[arg-type]

    local, lan, every, every6 = server("127.0.0.1"), server("192.168.1.5"), server("0.0.0.0"), server("::")
    assert local._is_own_host(("localhost", 8080)) and local._is_own_host(("::1", 8080))
    assert not local._is_own_host(("192.168.1.5", 8080)) and not local._is_own_host(("localhost", 80))
    assert lan._is_own_host(("192.168.1.5", 8080)) and not lan._is_own_host(("192.168.1.6", 8080))
    for wildcard in (every, every6):
        assert wildcard._is_own_host(("192.168.1.6", 8080)) and wildcard._is_own_host(("fe80::1", 8080))
        assert not wildcard._is_own_host(("pi.example", 8080)) and not wildcard._is_own_host(None)
    assert web_module._authority("localhost") == ("localhost", 80)
    assert web_module._authority("[::1]:8080") == ("::1", 8080)
    assert web_module._authority("x:port") is None and web_module._authority("a@b:1") is None


# -- every message and upgrade takes a turn ------------------------------------------------------


async def _answers_to_a_flood(url: str, send, seconds: float) -> int:
    """Answers (errors, replies, pongs) to ``send``'s messages kept 16 in flight for ``seconds``."""
    answers = sent = 0
    async with aiohttp.ClientSession() as session, session.ws_connect(url.replace("http", "ws") + "ws", max_msg_size=0,
                                                                      autoping=False) as ws:
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            while sent - answers < 16:
                await send(ws)
                sent += 1
            try:
                message = await ws.receive(timeout=left)
            except asyncio.TimeoutError:
                break
            if message.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                break
            answers += message.type == aiohttp.WSMsgType.PONG or json.loads(message.data)["type"] in ("error", "reply")
    return answers


FLOODS = {
    "malformed text": lambda ws: ws.send_str("not json"),
    "nested too deeply": lambda ws: ws.send_str("[" * 3000),
    "binary": lambda ws: ws.send_bytes(b"\0" * 16),
    "ping": lambda ws: ws.ping(b"x"),
}


@pytest.mark.parametrize("kind", list(FLOODS))
def test_a_flood_of_socket_messages_is_answered_at_most_requests_per_s(bus, kind):
    """Each message takes its turn before it is looked at: malformed, binary or a ping, it is answered no faster
    than a control (unpaced they were answered 5,000-37,000 a second, which slowed the served bus)."""
    seconds = 1.0
    answers = asyncio.run(_answers_to_a_flood(bus.web_url, FLOODS[kind], seconds))
    assert 10 <= answers <= web_module.REQUESTS_PER_S * seconds * 1.1 + 5, answers


def test_websocket_upgrades_are_paced_too(bus):
    """Each upgrade sends a hello with the log: opened and closed in a loop, they cost what any request does."""

    async def upgrades(seconds: float) -> int:
        opened = 0
        async with aiohttp.ClientSession() as session:
            deadline = time.monotonic() + seconds
            while time.monotonic() < deadline:
                async with session.ws_connect(bus.web_url.replace("http", "ws") + "ws") as ws:
                    await ws.receive(timeout=5)
                    opened += 1
        return opened

    seconds = 1.0
    assert asyncio.run(upgrades(seconds)) <= web_module.REQUESTS_PER_S * seconds * 1.1 + 5


async def _answer(ws, seconds: float) -> dict | None:
    """The first reply or error ``ws`` gets within ``seconds`` (frames skipped; None: it was closed first)."""
    deadline = time.monotonic() + seconds
    while True:
        message = await ws.receive(timeout=deadline - time.monotonic())
        if message.type != aiohttp.WSMsgType.TEXT:
            return None
        data = json.loads(message.data)
        if data["type"] in ("reply", "error"):
            return data


def _holding_turns(session, url: str) -> list:
    """Another client's GETs holding the request turns of the next 0.4 s (at 5 a second, 2 turns)."""
    return [asyncio.ensure_future(session.get(url + "api/log?n=1")) for _ in range(2)]


@pytest.fixture
def few_turns(bus, monkeypatch):
    """5 turns a second and 0.3 s of waiting at most: two requests hold the turns past a message's reach."""
    monkeypatch.setattr(web_module, "REQUESTS_PER_S", 5.0)
    monkeypatch.setattr(web_module, "MAX_REQUEST_WAIT_S", 0.3)
    time.sleep(0.5)  # the fixture's own requests' turns are over
    return bus


def test_a_control_socket_stays_open_while_other_clients_hold_the_turns(few_turns):
    """A socket has one message waiting at most, so it is never what floods: where other clients' requests hold
    the turns, its control gets the error reply and the socket stays open (it was closed with 1013), and its next
    control, once the turns are free, is taken."""
    url = few_turns.web_url

    async def run() -> tuple[dict | None, dict | None, int | None]:
        async with aiohttp.ClientSession() as session, session.ws_connect(url.replace("http", "ws") + "ws") as ws:
            await ws.receive(timeout=5)  # hello
            polls = _holding_turns(session, url)
            await asyncio.sleep(0.05)
            await ws.send_json({"action": "clear_faults"})  # its turn past 0.3 s away
            during = await _answer(ws, 3)
            for poll in polls:
                (await poll).release()
            await ws.send_json({"action": "clear_faults"})
            after = await _answer(ws, 3)
            return during, after, ws.close_code

    during, after, close_code = asyncio.run(run())
    assert close_code is None, close_code
    assert during is not None and during["type"] == "error" and "control not taken" in during["error"], during
    assert after is not None and after["type"] == "reply" and after["status"] == 200, after


def test_the_page_connects_its_stream_while_other_clients_hold_the_request_turns(few_turns):
    """WebSocket upgrades take turns of their own: a flood of plain requests does not keep the page from its
    stream (it got 503)."""
    url = few_turns.web_url

    async def run() -> str:
        async with aiohttp.ClientSession() as session:
            polls = _holding_turns(session, url)
            await asyncio.sleep(0.05)
            try:
                async with session.ws_connect(url.replace("http", "ws") + "ws") as ws:
                    return json.loads((await ws.receive(timeout=5)).data)["type"]
            finally:
                for poll in polls:
                    (await poll).release()

    assert asyncio.run(run()) == "hello"


# -- a client's faults in the log -------------------------------------------------------------


@pytest.fixture
def fresh_budget(monkeypatch):
    """The process's client-fault budget, full (other tests' faults spent it: one budget for every live view)."""
    from ax12emu.live import logs

    budget = logs.ClientFaultBudget()
    monkeypatch.setattr(logs, "BUDGET", budget)
    return budget


def _malformed_requests(bus, count: int) -> None:
    host, port = host_port(bus.web_url)
    for _ in range(count):
        answer = _raw_request(host, port, b"POST /api/control HTTP/1.1\r\nHost: x\r\nContent-Length: -1\r\n\r\n")
        assert answer.split(b"\r\n")[0].endswith(b" 400 Bad Request"), answer[:100]


def _client_fault_lines(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "aiohttp.server"]


def test_a_flood_of_malformed_requests_logs_a_bounded_number_of_lines(bus, caplog, fresh_budget):
    """Each malformed request was an INFO line, with no limit: a flood filled the terminal a monitor draws on, or
    a stderr pipe nobody read (the event loop then blocked writing to it).  A burst of lines, then one a second,
    the next one shown saying how many were not."""
    from ax12emu.live.logs import CLIENT_FAULT_BURST, CLIENT_FAULT_LINES_PER_S

    flood = 3 * CLIENT_FAULT_BURST
    with caplog.at_level(logging.INFO, logger="aiohttp.server"):
        start = time.monotonic()
        _malformed_requests(bus, flood)
        elapsed_s = time.monotonic() - start
        shown = len(_client_fault_lines(caplog))
        assert CLIENT_FAULT_BURST <= shown <= CLIENT_FAULT_BURST + elapsed_s * CLIENT_FAULT_LINES_PER_S + 1, shown
        time.sleep(1.0 / CLIENT_FAULT_LINES_PER_S)
        _malformed_requests(bus, 1)
    lines = _client_fault_lines(caplog)
    assert f"(and {flood - shown} more client faults not shown)" in lines[-1], lines[-3:]


def _bad_control(url: str, action: str) -> int:
    return http_json(url + "api/control", json.dumps({"action": action}).encode(), {"Content-Type": "application/json"})[0]


def test_a_client_fault_line_quotes_a_bounded_part_of_what_the_client_sent(bus, caplog, fresh_budget):
    """A control naming a 10,000-character action was quoted whole: one line 10,000 characters long."""
    from ax12emu.live.logs import CLIENT_TEXT_CHARS

    with caplog.at_level(logging.INFO, logger="ax12emu.live.web"):
        assert _bad_control(bus.web_url, "x" * 10_000) == 400
    line = next(r.getMessage() for r in caplog.records if "refused a control" in r.getMessage())
    assert len(line) <= CLIENT_TEXT_CHARS + 80 and line.endswith(" more)"), line[-120:]


def test_client_fault_lines_are_logged_where_they_happen_through_the_users_filters(bus, caplog, fresh_budget):
    """The lines are written as they are logged: a handler (here caplog) has each at once, in order, and a filter
    the user puts on the live view's logger runs and may drop one."""
    seen: list[str] = []

    def users_filter(record: logging.LogRecord) -> bool:
        seen.append(record.getMessage())
        return "drop me" not in record.getMessage()

    logger = logging.getLogger("ax12emu.live.web")
    logger.addFilter(users_filter)
    try:
        with caplog.at_level(logging.INFO, logger="ax12emu.live.web"):
            for action in ("first", "drop me", "third"):
                assert _bad_control(bus.web_url, action) == 400
            shown = [r.getMessage() for r in caplog.records if "refused a control" in r.getMessage()]
    finally:
        logger.removeFilter(users_filter)
    assert len(seen) == 3 and "drop me" in seen[1], seen
    assert len(shown) == 2 and "'first'" in shown[0] and "'third'" in shown[1], shown


def test_every_live_view_in_a_process_shares_one_client_fault_budget(bus, caplog, monkeypatch):
    """The log is the process's: a second live view's client faults are counted against the same lines, and the
    line that next gets through counts every one held back, whichever view it came to."""
    from ax12emu.live import logs

    monkeypatch.setattr(logs, "BUDGET", logs.ClientFaultBudget(burst=3, per_s=1e-9))
    with VirtualBus([1], transport="tcp", web=True) as other, caplog.at_level(logging.INFO, logger="ax12emu.live.web"):
        for url in (bus.web_url, bus.web_url, other.web_url, other.web_url, other.web_url):
            assert _bad_control(url, "nothing") == 400
    lines = [r.getMessage() for r in caplog.records if "refused a control" in r.getMessage()]
    assert len(lines) == 3 and logs.BUDGET.held == 2, lines


# -- statistics a fast host cannot outrun -------------------------------------------------------------


@pytest.mark.parametrize("servo", ["1:ax-12a", "1:xl430-w250"])
def test_status_errors_count_every_reply_however_fast_the_host_polls(servo):
    """The log decodes at most 80 chunks a frame; the status errors are the server's count, so a host polling
    faster than that (here 150 reads between two frames) is counted whole."""
    from ax12emu.live import LiveView
    from ax12emu.protocol.packets2 import Instruction2, InstructionPacket2

    with VirtualBus(servo=servo, transport="tcp", baud_bps=1_000_000) as bus:
        view = bus.call(lambda _: LiveView.for_server(bus._server))  # the tap goes in on the serving thread
        bus.faults.force_alarm(1, "overload")  # every status packet from now on carries an error bit
        before = view.sampler.sample()["stats"]["status_errors"]
        two = "xl430" in servo
        read = (InstructionPacket2(1, Instruction2.READ, bytes([132, 0, 4, 0])) if two
                else InstructionPacket(1, Instruction.READ, bytes([36, 2]))).encode()
        host, port = bus.port.split("//")[1].rsplit(":", 1)
        with socket.create_connection((host, int(port)), timeout=5) as sock:
            for _ in range(150):
                sock.sendall(read)
                got = b""
                while len(got) < (15 if two else 8):
                    got += sock.recv(64)
                assert got[8 if two else 4], got  # the error field
        after = view.sampler.sample()["stats"]
    assert after["status_errors"] - before == 150, after
