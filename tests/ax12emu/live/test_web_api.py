"""The live view's HTTP side without a browser: the JSON snapshot, the controls, bad requests, loopback only."""

from __future__ import annotations

import json
import logging
import time
import urllib.error
import urllib.request

import pytest

pytest.importorskip("aiohttp")

from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS  # noqa: E402
from emu_testkit import http_json, sdk_port  # noqa: E402
from emu_testkit import post_json as post  # noqa: E402

from ax12emu import VirtualBus  # noqa: E402
from ax12emu.live.web import MAX_BODY_BYTES, WebServer  # noqa: E402


def get(url: str) -> tuple[int, dict]:
    return http_json(url, method="GET")


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
    # valid JSON whose integer is past the float range: refused as out of range, not a fault inside (500)
    (b'{"action": "step", "seconds": 1' + b"0" * 400 + b"}", 400, "seconds must be a number 0..10"),
    (b'{"action": "external_torque", "id": 1, "nm": -1' + b"0" * 400 + b"}", 400, "nm must be a number -10..10"),
    (b'{"action": "reply_faults", "drop": 1' + b"0" * 400 + b"}", 400, "drop must be a number 0..1"),
]


def test_bad_control_requests_get_a_clear_4xx_and_the_bus_keeps_answering(bus, caplog):
    with caplog.at_level(logging.INFO, logger="ax12emu.live.web"):
        for body, status, says in BAD_CONTROLS:
            got_status, got = post(bus.web_url + "api/control", body if isinstance(body, bytes) else json.dumps(body).encode())
            assert got_status == status and says in got["error"], (body, got)
    logged = [r for r in caplog.records if r.name == "ax12emu.live.web"]
    # one INFO line per refused control, no error, no traceback (the body-less 413 and the unparsed ones: none)
    assert logged and all(r.levelno == logging.INFO and r.exc_info is None and "\n" not in r.getMessage() for r in logged), [
        (r.levelname, r.getMessage()) for r in logged]
    assert sum("seconds must be a number" in r.getMessage() for r in logged) == 1
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


def test_the_page_posts_its_controls_as_json():
    """/api/control takes application/json alone (another origin's page cannot send it unasked): the page's own must."""
    with VirtualBus([1], transport="inprocess", virtual_time=True, web=True) as bus, \
            urllib.request.urlopen(bus.web_url + "assets/app.js", timeout=5) as script:
        text = script.read().decode()
    assert 'fetch("/api/control", {method: "POST", headers: {"Content-Type": "application/json"}' in text


def readings_of(servo: dict) -> dict[str, dict]:
    return {reading["name"]: reading for reading in servo["readings"]}


def test_an_mx_in_multi_turn_mode_shows_a_position_below_zero_as_negative():
    """Multi-turn mode ([classic] multi_turn_limit: both angle limits 4095) holds Goal and Present Position as two's
    complement (-28,672..28,672): a goal 3000 counts back is -3000 (about -264 degrees), not 62,536 (5,498 degrees);
    with Resolution Divider 2 each count is two of the file's units."""
    with VirtualBus(servo="2:mx-64", transport="inprocess", virtual_time=True, web=True) as bus:
        bus.write(2, "cw_angle_limit", 4095)
        bus.write(2, "ccw_angle_limit", 4095)
        bus.write(2, "torque_enable", 1)
        bus.write(2, "goal_position", -3000 & 0xFFFF)  # as a host sends it
        bus.step(3.0)
        shaft_deg = bus.angle_deg(2)
        servo = wait_for(lambda: (s := servos(bus)[2])["registers"]["goal_position"] == 62536 and s)
        assert servo["mode"] == "multi-turn" and servo["limits"] is None
        one = readings_of(servo)
        assert one["goal"]["raw"] == -3000 and one["goal"]["value"] == pytest.approx(-3000 * 360 / 4096, abs=1e-3)
        assert one["position"]["raw"] < 0 and one["position"]["value"] == pytest.approx(shaft_deg, abs=0.5)
        bus.write(2, "torque_enable", 0)
        bus.write(2, "resolution_divider", 2)
        bus.write(2, "torque_enable", 1)
        bus.write(2, "goal_position", -1500 & 0xFFFF)
        bus.step(3.0)
        shaft_deg = bus.angle_deg(2)
        servo = wait_for(lambda: (s := servos(bus)[2])["registers"]["goal_position"] == -1500 & 0xFFFF and s)
        one = readings_of(servo)
        assert one["goal"]["raw"] == -1500 and one["goal"]["value"] == pytest.approx(-1500 * 2 * 360 / 4096, abs=1e-3)
        assert one["position"]["value"] == pytest.approx(shaft_deg, abs=0.5)
        bus.write(2, "torque_enable", 0)
        bus.write(2, "ccw_angle_limit", 3000)  # joint mode: the same registers read unsigned again
        servo = wait_for(lambda: (s := servos(bus)[2])["mode"] == "joint" and s)
        assert readings_of(servo)["goal"]["raw"] == -1500 & 0xFFFF


@pytest.mark.parametrize(("mode", "limits"), [(3, [0, 4095]), (4, None), (5, None)])
def test_the_position_limits_are_shown_where_the_table_applies_them(mode, limits):
    """Goal Position's ranges_when in the model file: the position limits are unused in Extended (4) and
    Current-based (5) Position Control Mode, so the servo takes a goal past them and the view draws none."""
    with VirtualBus(servo="1:xm430-w350", transport="inprocess", virtual_time=True, web=True) as bus:
        bus.write(1, "operating_mode", mode)
        bus.write(1, "torque_enable", 1)
        goal = 6000 if limits is None else 3000
        bus.write(1, "goal_position", goal)
        bus.step(0.1)
        servo = wait_for(lambda: (s := servos(bus)[1])["registers"]["goal_position"] == goal and s)
    assert servo["registers"]["operating_mode"] == mode and servo["limits"] == limits


def test_an_mx64_shows_its_current_in_ma_about_2048():
    """MX-64/MX-106 Current(68): "I = ( 4.5mA ) * (CURRENT - 2048)", 4.5 mA the model file's current_unit_ma."""
    with VirtualBus(servo="2:mx-64,3:mx-28", transport="inprocess", virtual_time=True, web=True) as bus:
        bus.write(2, "torque_enable", 1)
        bus.write(2, "goal_position", 3000)
        bus.step(0.05)  # accelerating: a current flows
        raw = bus.read(2, "current")
        shown = wait_for(lambda: (s := servos(bus))[2]["registers"]["current"] == raw and s)
    current = readings_of(shown[2])["current"]
    assert raw != 2048 and shown[2]["registers"]["current"] == raw
    assert (current["register"], current["raw"], current["unit"]) == ("current", raw - 2048, "mA")  # signed, as plotted
    assert current["value"] == pytest.approx((raw - 2048) * 4.5, abs=1e-3)
    assert "current" not in readings_of(shown[3]) and "load" in readings_of(shown[3])  # the MX-28 senses none
