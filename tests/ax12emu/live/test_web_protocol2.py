"""The live page's server for Protocol 2.0 and mixed buses, over a real WebSocket client and HTTP, in-process and in virtual time.

Frames carry each X-series servo's registers and readings; controls sent over the socket or
posted act on the servos' firmware; hostile messages get a clear error and the bus keeps answering.
"""

from __future__ import annotations

import asyncio
import json
import time
import urllib.error
import urllib.request

import pytest

aiohttp = pytest.importorskip("aiohttp")

from dynamixel_sdk import COMM_SUCCESS, PacketHandler  # noqa: E402
from emu_testkit import UrlPortHandler  # noqa: E402
from emu_testkit import post_json as post  # noqa: E402

from ax12emu import VirtualBus  # noqa: E402
from ax12emu.live import ByteTap, LiveView, ServedControls  # noqa: E402
from ax12emu.live.buses import decoder_options  # noqa: E402
from ax12emu.live.snapshot import take  # noqa: E402
from ax12emu.live.web import MAX_BODY_BYTES, MAX_MESSAGE_BYTES  # noqa: E402

BAUD = 1_000_000


def get(url: str) -> tuple[int, dict]:
    with urllib.request.urlopen(url, timeout=5) as answer:
        return answer.status, json.loads(answer.read())


def wait_for(predicate, timeout_s: float = 2.0):
    """The sampler's newest frame is up to a period (40 ms) behind the bus."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(0.02)


def served(servo: str):
    """A bus of ``servo`` in virtual time with its live view as ``ax12emu serve`` builds one: tap, counters, ServedControls."""
    bus = VirtualBus(servo=servo, transport="inprocess", virtual_time=True, baud_bps=BAUD).start()
    link = bus._link
    tap = ByteTap(link.trace)
    link.trace = tap
    view = LiveView(bus.call, controls=ServedControls(bus.call), tap=tap, counters=lambda: {"packets_in": link.packets_in},
                    web=("127.0.0.1", 0), **bus.call(decoder_options))
    try:
        view.start()
    except BaseException:
        bus.close()
        raise
    return bus, view


@pytest.fixture
def x_view():
    bus, view = served("1:xl430-w250,2:xl330-m288")
    try:
        yield bus, view
    finally:
        view.close()
        bus.close()


async def _talk(url: str, messages: list, *, until: callable, max_msg_size: int = 0) -> list[dict]:
    """Send ``messages`` (str or bytes) on one socket; collect what comes back until ``until(received)``."""
    received: list[dict] = []
    async with aiohttp.ClientSession() as session, session.ws_connect(url.replace("http", "ws") + "ws", max_msg_size=max_msg_size) as ws:
        for message in messages:
            await (ws.send_bytes(message) if isinstance(message, bytes) else ws.send_str(message))
        while not until(received):
            message = await ws.receive(timeout=5)
            assert message.type == aiohttp.WSMsgType.TEXT, message
            received.append(json.loads(message.data))
    return received


def replies(received: list[dict]) -> list[dict]:
    return [m for m in received if m["type"] in ("reply", "error")]


def test_frames_stream_x_series_servos_and_follow_a_write(x_view):
    bus, view = x_view
    received = asyncio.run(_talk(view.url, [], until=lambda got: sum(m["type"] == "frame" for m in got) >= 2))
    assert received[0]["type"] == "hello" and "alarm" in received[0]["actions"]
    frame = next(m for m in received if m["type"] == "frame")
    assert frame["protocols"] == ["2.0"]
    assert [(s["id"], s["model"], s["protocol"]) for s in frame["servos"]] == [(1, "XL430-W250", "2.0"), (2, "XL330-M288", "2.0")]
    names = {r["name"] for r in frame["servos"][1]["readings"]}
    assert {"position", "goal", "velocity", "current", "pwm", "voltage", "temperature"} <= names
    bus.write(1, "goal_position", 3000)

    def goal_shown(got: list[dict]) -> bool:
        return any(m["type"] == "frame" and m["servos"][0]["registers"]["goal_position"] == 3000 for m in got)

    asyncio.run(_talk(view.url, [], until=goal_shown))
    status, snapshot = get(view.url + "api/servos")
    assert status == 200 and snapshot["servos"][0]["mode"] == "position" and "log" not in snapshot


def test_controls_over_the_socket_and_http_act_on_the_firmware(x_view):
    bus, view = x_view
    messages = [json.dumps({"action": "temperature", "id": 2, "celsius": 70}), json.dumps({"action": "alarm", "slot": 1, "bits": "overload"})]
    got = replies(asyncio.run(_talk(view.url, messages, until=lambda got: len(replies(got)) >= 2)))
    assert [m["status"] for m in got] == [200, 200]
    assert got[0]["log"] == "servo 2: temperature held at 70.0 C" and got[1]["log"] == "servo 1: alarm overload forced"
    assert bus.read(2, "present_temperature") == 70 and bus.read(1, "hardware_error_status") == 0x20
    assert post(view.url + "api/control", {"action": "step", "seconds": 0.1}) == (200, {"ok": True, "log": "stepped 0.1 s"})
    assert bus.now_s == pytest.approx(0.1)
    assert wait_for(lambda: "servo 1: alarm overload forced" in [line["text"] for line in get(view.url + "api/log?n=200")[1]["lines"]])


#: Hostile or careless socket messages and what the answer must say (the error or the reply's error).
HOSTILE = [
    ("{not json", "not JSON"),
    (b"\x00\x01", "JSON text"),
    ("[1, 2]", "JSON object"),
    (json.dumps({"action": "explode"}), "unknown action 'explode'"),
    (json.dumps({"action": "temperature", "id": 1, "celsius": 1e308}), "celsius must be a number 0..255"),
    (json.dumps({"action": "voltage", "id": 1, "volts": "high"}), "volts must be a number"),
    (json.dumps({"action": "alarm", "slot": 1, "bits": "input_voltage"}), "Shutdown(63)"),
    (json.dumps({"action": "alarm", "slot": 1, "bits": [{"overload": 1}]}), "bits must be alarm names"),
    (json.dumps({"action": "stall", "slot": 1, "protocol": 1.0}), "speak Protocol 2"),
    (json.dumps({"action": "vanish", "slot": 7}), "no servo launched as ID 7"),
    (json.dumps({"action": "external_torque", "id": 300, "nm": 0.1}), "id must be an integer 0..253"),
    (json.dumps({"action": "reply_faults", "ids": [1, "x"]}), "ids must be an integer"),
]


def test_hostile_socket_messages_get_clear_errors_and_the_bus_keeps_answering(x_view):
    bus, view = x_view
    got = replies(asyncio.run(_talk(view.url, [m for m, _ in HOSTILE], until=lambda got: len(replies(got)) >= len(HOSTILE))))
    for (message, says), answer in zip(HOSTILE, got):
        assert says in answer["error"], (message, answer)
        assert answer.get("status", 400) == 400

    async def oversized() -> int | None:
        async with aiohttp.ClientSession() as session, session.ws_connect(view.url.replace("http", "ws") + "ws") as ws:
            await ws.send_str("x" * (MAX_MESSAGE_BYTES + 1))
            while (await ws.receive(timeout=5)).type not in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.CLOSING):
                pass
            return ws.close_code

    assert asyncio.run(oversized()) == 1009  # message too big
    assert post(view.url + "api/control", b"x" * (MAX_BODY_BYTES + 1))[0] == 413
    assert post(view.url + "api/control", b'{"action": "stall", "slot": 1')[0] == 400
    # Nothing half done, and the bus and the page still answer.
    assert all(not s["faults"] for s in bus.call(take)["servos"]) and bus.read(1, "hardware_error_status") == 0
    assert get(view.url + "api/servos")[0] == 200
    port = UrlPortHandler(bus.port)
    assert port.openPort() and port.setBaudRate(BAUD)
    try:
        assert PacketHandler(2.0).ping(port, 1)[1] == COMM_SUCCESS
    finally:
        port.closePort()


def test_a_mixed_wire_takes_the_protocol_over_the_socket():
    bus, view = served("1:ax-12a,1:xl430-w250")
    try:
        messages = [json.dumps({"action": "vanish", "slot": 1}), json.dumps({"action": "vanish", "slot": 1, "protocol": 1.0})]
        got = replies(asyncio.run(_talk(view.url, messages, until=lambda got: len(replies(got)) >= 2)))
        assert got[0]["status"] == 400 and "give protocol=1.0 or protocol=2.0" in got[0]["error"]
        assert got[1]["status"] == 200 and got[1]["log"] == "servo 1 vanished (Protocol 1.0)"
        faults = lambda: [(s["protocol"], s["faults"]) for s in get(view.url + "api/servos")[1]["servos"]]  # noqa: E731
        assert wait_for(lambda: faults() == [("1.0", ["vanished"]), ("2.0", [])]), faults()
    finally:
        view.close()
        bus.close()


def test_a_control_failing_inside_the_emulator_is_a_500_with_the_reason_and_the_page_stays_up():
    """Controls whose ``call`` hands them no bus (a wiring mistake, not the message's): the error is reported, not raised."""
    from ax12emu.live import Sampler
    from ax12emu.live.web import WebServer

    with VirtualBus(servo="1:xl430-w250", transport="inprocess", virtual_time=True) as bus:
        sampler = Sampler(bus.call, **bus.call(decoder_options)).start()
        web = WebServer(sampler, ServedControls(lambda fn: fn(None))).start()
        try:
            status, body = post(web.url + "api/control", {"action": "external_torque", "id": 1, "nm": 0.1})
            assert status == 500 and "inside the emulator: AttributeError" in body["error"]
            assert wait_for(lambda: get(web.url + "api/servos")[0] == 200)
        finally:
            web.close()
            sampler.close()
