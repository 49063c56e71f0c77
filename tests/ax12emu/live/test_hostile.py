"""Hostile and careless clients of the live view cannot hurt the bus, and memory stays bounded.

The full thousand connections are tools/live_flood.py's job; here counts are modest.
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import socket
import time
import urllib.error
import urllib.request

import pytest

aiohttp = pytest.importorskip("aiohttp")

from dynamixel_sdk import COMM_SUCCESS  # noqa: E402
from emu_testkit import sdk_port  # noqa: E402

from ax12emu import VirtualBus  # noqa: E402
from ax12emu.live import Sampler  # noqa: E402
from ax12emu.live.web import MAX_MESSAGE_BYTES, QUEUE_FRAMES, WebServer  # noqa: E402


def get_json(url: str) -> tuple[int, dict]:
    try:
        with urllib.request.urlopen(url, timeout=5) as answer:
            return answer.status, json.loads(answer.read())
    except urllib.error.HTTPError as error:
        with error:
            return error.code, json.loads(error.read())


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
