"""The sampler's bounds: the tap forgets what nobody read, the log shows a bounded number of chunks per frame."""

from __future__ import annotations

import os

import pytest
from emu_testkit import sdk_port

from ax12emu import VirtualBus
from ax12emu.live import ByteTap, Sampler
from ax12emu.protocol.packets import Instruction, InstructionPacket
from ax12emu.tracing.trace import IN

PING = InstructionPacket(1, Instruction.PING, b"").encode()


def test_the_tap_keeps_the_newest_chunks_and_counts_the_lost():
    tap = ByteTap(capacity=10)
    for k in range(25):
        tap.record(IN, PING, float(k))
    chunks, lost = tap.take()
    assert [c.t for c in chunks] == [float(k) for k in range(15, 25)] and lost == 15
    assert tap.take() == ([], 0)


def test_a_busy_line_is_shown_in_part_with_a_line_saying_how_much_was_left_out():
    with VirtualBus([1], transport="inprocess", virtual_time=True) as bus:
        tap = ByteTap(capacity=100)
        sampler = Sampler(bus.call, tap=tap, max_chunks=5)
        for k in range(30):
            tap.record(IN, PING, 1.0 + k * 1e-3)
        frame = sampler.sample()
        assert frame["log"][0]["who"] == "skip" and frame["log"][0]["text"].startswith("25 chunk(s)")
        pings = [line for line in frame["log"] if line["who"] == "host"]
        assert len(pings) == 5 and all(line["ins"] == "PING" and line["id"] == 1 for line in pings)
        assert sampler.stats["log_chunks_skipped"] == 25
        sampler.note("servo 1 vanished", id=1)
        assert sampler.sample()["log"] == [pytest.approx({"t": sampler.log_lines[-1]["t"], "who": "control", "id": 1, "ins": None, "text": "servo 1 vanished"})]


def test_frames_name_every_fault_and_alarm_of_a_servo():
    with VirtualBus([1, 2], transport="inprocess", virtual_time=True) as bus:
        bus.faults.vanish(2)
        bus.faults.force_alarm(1, "overload")
        bus.set_temperature(1, 90)
        with sdk_port(bus.port) as (port, ph):  # alarms are raised as the servo handles a packet
            assert ph.ping(port, 1)[2] & 0x24 == 0x24
        frame = Sampler(bus.call).sample()
        one, two = frame["servos"]
        assert two["faults"] == ["vanished"]
        assert "alarm 0x20" in one["faults"] and "present_temperature held at 90" in one["faults"]
        assert set(one["alarm_names"]) >= {"overload", "overheating"}
        assert frame["virtual_time"] and frame["paused"]


def test_the_monitor_table_shows_signed_speed_and_load():
    from rich.console import Console

    from ax12emu.live.monitor import render
    from ax12emu.live.snapshot import REGISTER_UNITS

    with VirtualBus([1], transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "torque_enable", 1)
        bus.write(1, "goal_position", 100)  # CW: speed and load read with the direction bit set
        bus.step(0.1)  # Present Speed and Load are refreshed every few tens of ms, as on the servo
        frame = Sampler(bus.call).sample()
    with open(os.devnull, "w") as nowhere:
        console = Console(width=200, record=True, file=nowhere)
        console.print(render(frame))
    text = console.export_text()
    speed = frame["servos"][0]["registers"]["present_speed"]
    assert speed & 0x400, "moving CW sets the direction bit"
    rpm = -(speed & 0x3FF) * REGISTER_UNITS["present_speed"].per_raw  # the AX-12A's, about 0.111 rpm
    assert f"{rpm:+.1f} rpm" in text and "AX-12A (P1.0)" in text
