"""The live view's HTTP side without a browser: the JSON snapshot, the controls, bad requests, loopback only."""

from __future__ import annotations

import json
import time
import urllib.error
import urllib.request

import pytest

pytest.importorskip("aiohttp")

from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS  # noqa: E402
from emu_testkit import sdk_port  # noqa: E402

from ax12emu import VirtualBus  # noqa: E402
from ax12emu.live.web import MAX_BODY_BYTES, WebServer  # noqa: E402


def get(url: str) -> tuple[int, dict]:
    try:
        with urllib.request.urlopen(url, timeout=5) as answer:
            return answer.status, json.loads(answer.read())
    except urllib.error.HTTPError as error:
        return error.code, json.loads(error.read())


def post(url: str, body: bytes | dict) -> tuple[int, dict]:
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    request = urllib.request.Request(url, data=data, method="POST", headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(request, timeout=5) as answer:
            return answer.status, json.loads(answer.read())
    except urllib.error.HTTPError as error:
        return error.code, json.loads(error.read())


def wait_for(predicate, timeout_s: float = 2.0):
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(0.02)


@pytest.fixture
def bus():
    with VirtualBus([1, 2, 7], transport="tcp", web=True) as bus:
        yield bus


def servos(bus) -> dict[int, dict]:
    status, body = get(bus.web_url + "api/servos")
    assert status == 200, body
    return {servo["id"]: servo for servo in body["servos"]}


def test_snapshot_lists_every_servo_with_its_registers_and_follows_a_write(bus):
    first = wait_for(lambda: servos(bus))
    assert sorted(first) == [1, 2, 7]
    assert first[7]["model"] == "AX-12A" and first[7]["protocol"] == "1.0"
    assert first[1]["registers"]["goal_position"] == 512
    bus.write(2, "goal_position", 700)
    assert wait_for(lambda: servos(bus)[2]["registers"]["goal_position"] == 700)
    assert servos(bus)[1]["registers"]["goal_position"] == 512


def test_controls_act_like_virtual_bus_and_show_in_the_log(bus):
    with sdk_port(bus.port) as (port, ph):
        assert ph.ping(port, 1)[1] == COMM_SUCCESS
        assert post(bus.web_url + "api/control", {"action": "vanish", "slot": 1}) == (200, {"ok": True, "log": "servo 1 vanished"})
        assert ph.ping(port, 1)[1] == COMM_RX_TIMEOUT
        assert ph.ping(port, 2)[1] == COMM_SUCCESS
        assert post(bus.web_url + "api/control", {"action": "reappear", "slot": 1})[0] == 200
        assert ph.ping(port, 1)[1] == COMM_SUCCESS
        assert post(bus.web_url + "api/control", {"action": "temperature", "id": 2, "celsius": 90})[0] == 200
        _, _, error = ph.ping(port, 2)
        assert error & 0x04  # Overheating, as VirtualBus.set_temperature gives
        assert ph.read1ByteTxRx(port, 2, 43)[0] == 90  # Present Temperature
    assert "present_temperature held at 90" in " ".join(servos(bus)[2]["faults"])

    def logged():
        lines = get(bus.web_url + "api/log?n=200")[1]["lines"]
        return lines if any(line["who"] == "servo" for line in lines) else None

    lines = wait_for(logged)
    texts = [line["text"] for line in lines]
    assert "servo 1 vanished" in texts and "servo 1 back" in texts
    # The decoder's lines for the SDK's packets: instructions with their ID, and the servos' answers.
    pings = [line for line in lines if line["who"] == "host" and line["ins"] == "PING"]
    assert {line["id"] for line in pings} >= {1, 2}
    assert any(line["who"] == "servo" and line["id"] == 2 for line in lines)


def test_stats_count_packets_and_injected_timeouts(bus):
    assert post(bus.web_url + "api/control", {"action": "reply_faults", "drop": 1.0})[0] == 200
    with sdk_port(bus.port) as (port, ph):
        for _ in range(2):
            assert ph.ping(port, 1)[1] == COMM_RX_TIMEOUT
    stats = wait_for(lambda: (s := get(bus.web_url + "api/servos")[1]["stats"])["timeouts_injected"] >= 2 and s)
    assert stats["timeouts_injected"] == 2 and stats["packets"] >= 2


def test_virtual_time_is_stepped_from_the_page():
    with VirtualBus([1], transport="inprocess", virtual_time=True, web=True) as bus:
        bus.write(1, "torque_enable", 1)
        bus.write(1, "goal_position", 900)
        before = bus.read(1, "present_position")
        assert post(bus.web_url + "api/control", {"action": "step", "seconds": 0.5}) == (200, {"ok": True, "log": "stepped 0.5 s"})
        assert bus.now_s == pytest.approx(0.5)
        assert bus.read(1, "present_position") > before + 100
        status, body = post(bus.web_url + "api/control", {"action": "pause"})
        assert status == 400 and "virtual time" in body["error"]


def test_wall_clock_pauses_and_steps():
    with VirtualBus([1], transport="tcp", web=True) as bus:
        assert post(bus.web_url + "api/control", {"action": "step", "seconds": 0.1})[0] == 400  # running: pause first
        assert post(bus.web_url + "api/control", {"action": "pause"})[0] == 200
        paused_at = bus.now_s
        time.sleep(0.1)
        assert bus.now_s == paused_at
        assert post(bus.web_url + "api/control", {"action": "step", "seconds": 0.25})[0] == 200
        assert bus.now_s == pytest.approx(paused_at + 0.25)
        assert wait_for(lambda: get(bus.web_url + "api/servos")[1]["paused"])
        assert post(bus.web_url + "api/control", {"action": "resume"})[0] == 200
        assert wait_for(lambda: bus.now_s > paused_at + 0.3)


#: Bad control requests and what the answer must say.
BAD_CONTROLS = [
    (b"not json", 400, "not JSON"),
    (b"[1, 2]", 400, "JSON object"),
    ({"action": "explode"}, 400, "unknown action"),
    ({"action": "vanish"}, 400, "missing parameter 'slot'"),
    ({"action": "vanish", "slot": 99}, 400, "no servo launched as ID 99"),
    ({"action": "vanish", "slot": "1"}, 400, "slot must be an integer"),
    ({"action": "reply_faults", "drop": 2}, 400, "drop must be a number 0..1"),
    ({"action": "temperature", "id": 1, "celsius": float("nan")}, 400, "celsius must be a number"),
    ({"action": "vanish", "slot": 1, "extra": 1}, 400, "unknown parameter"),
    (b"x" * (MAX_BODY_BYTES + 1), 413, "over"),
]


def test_bad_control_requests_get_a_clear_4xx_and_the_bus_keeps_answering(bus):
    for body, status, says in BAD_CONTROLS:
        got_status, got = post(bus.web_url + "api/control", body if isinstance(body, bytes) else json.dumps(body).encode())
        assert got_status == status and says in got["error"], (body, got)
    with sdk_port(bus.port) as (port, ph):
        for servo_id in (1, 2, 7):
            assert ph.ping(port, servo_id)[1] == COMM_SUCCESS  # nothing half-done: no servo vanished
    assert sorted(servos(bus)) == [1, 2, 7]


def test_unknown_paths_and_bad_queries_are_4xx(bus):
    assert get(bus.web_url + "api/log?n=abc")[0] == 400
    assert get(bus.web_url + "api/log?n=100000")[0] == 400
    with pytest.raises(urllib.error.HTTPError) as missing:
        urllib.request.urlopen(bus.web_url + "nothing-here", timeout=5)
    assert missing.value.code == 404
    missing.value.close()
    with pytest.raises(urllib.error.HTTPError) as escape:
        urllib.request.urlopen(bus.web_url + "assets/..%2f..%2fweb.py", timeout=5)
    assert escape.value.code in (403, 404)
    escape.value.close()


def test_binds_loopback_only_unless_allowed():
    with VirtualBus([1], transport="inprocess", web=("127.0.0.1", 0)) as bus:
        assert bus.web_url.startswith("http://127.0.0.1:")
    with pytest.raises(ValueError, match="--allow-remote"):
        WebServer(sampler=None, controls=None, host="0.0.0.0", port=0)  # type: ignore[arg-type]
