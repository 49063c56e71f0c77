"""``VirtualBus(servo=..., web=...)``: the live page of any wire the servo text builds, over a real WebSocket client,
in virtual time, as ``ax12emu serve --servo ... --web`` shows it."""

from __future__ import annotations

import asyncio
import json
import time
import urllib.request

import pytest

aiohttp = pytest.importorskip("aiohttp")

from dynamixel_sdk import COMM_SUCCESS, PacketHandler  # noqa: E402
from emu_testkit import UrlPortHandler  # noqa: E402

from ax12emu import VirtualBus  # noqa: E402

BAUD = 1_000_000


async def _talk(url: str, messages: list[str], *, until) -> list[dict]:
    """Send ``messages`` on one socket; collect what comes back until ``until(received)``."""
    received: list[dict] = []
    async with aiohttp.ClientSession() as session, session.ws_connect(url.replace("http", "ws") + "ws") as ws:
        for message in messages:
            await ws.send_str(message)
        while not until(received):
            message = await ws.receive(timeout=5)
            assert message.type == aiohttp.WSMsgType.TEXT, message
            received.append(json.loads(message.data))
    return received


def get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=5) as answer:
        return json.loads(answer.read())


def frames(received: list[dict]) -> list[dict]:
    return [m for m in received if m["type"] == "frame"]


@pytest.mark.parametrize("transport", ["inprocess", "tcp"])
def test_a_mixed_wire_with_an_mx_streams_every_servo_and_follows_a_write(transport):
    with VirtualBus(servo="1:mx-28,2:ax-12a,1:xl430-w250", transport=transport, virtual_time=True, baud_bps=BAUD,
                    web=True) as bus:
        assert bus.web_url is not None and bus.web_url.startswith("http://127.0.0.1:")
        received = asyncio.run(_talk(bus.web_url, [], until=lambda got: len(frames(got)) >= 1))
        assert received[0]["type"] == "hello"
        frame = frames(received)[0]
        assert frame["protocols"] == ["1.0", "2.0"] and frame["virtual_time"]
        shown = sorted((s["protocol"], s["id"], s["model"]) for s in frame["servos"])
        assert shown == [("1.0", 1, "MX-28"), ("1.0", 2, "AX-12A"), ("2.0", 1, "XL430-W250")]
        bus.write(1, "goal_position", 3000, protocol=1.0)

        def goal_shown(got: list[dict]) -> bool:
            return any(s["protocol"] == "1.0" and s["id"] == 1 and s["registers"]["goal_position"] == 3000
                       for f in frames(got) for s in f["servos"])

        asyncio.run(_talk(bus.web_url, [], until=goal_shown))


def test_the_page_controls_act_on_an_mx_and_its_log_names_its_registers():
    with VirtualBus(servo="mx-64", transport="inprocess", virtual_time=True, baud_bps=BAUD, web=True) as bus:
        message = json.dumps({"action": "step", "seconds": 0.1})
        got = asyncio.run(_talk(bus.web_url, [message], until=lambda got: any(m["type"] == "reply" for m in got)))
        assert next(m for m in got if m["type"] == "reply")["log"] == "stepped 0.1 s"
        assert bus.now_s == pytest.approx(0.1)
        port = UrlPortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(BAUD)
        try:  # Goal Acceleration(73): an MX register the AX-12 table has not
            assert PacketHandler(1.0).write1ByteTxRx(port, 1, 73, 5)[0] == COMM_SUCCESS
        finally:
            port.closePort()

        def logged() -> list[str]:
            return [line["text"] for line in get(bus.web_url + "api/log?n=200")["lines"]]

        deadline = time.monotonic() + 2.0  # the sampler's log is up to a period (40 ms) behind the bus
        while not any("goal_acceleration=5" in text for text in logged()) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert any("goal_acceleration=5" in text for text in logged()), logged()
