"""``serve --monitor``'s table for X-series servos and a mixed wire: each servo in its own units, from a frame in virtual time."""

from __future__ import annotations

import os

from rich.console import Console

from ax12emu import VirtualBus
from ax12emu.live import Sampler
from ax12emu.live.buses import decoder_options
from ax12emu.live.monitor import render
from ax12emu.live.snapshot import REGISTER_UNITS
from ax12emu.protocol.servo_models import model


def text_of(frame: dict) -> str:
    with open(os.devnull, "w") as nowhere:
        console = Console(width=240, record=True, file=nowhere)
        console.print(render(frame))
    return console.export_text()


def test_x_series_rows_show_model_mode_degrees_units_and_errors():
    with VirtualBus(servo="1:xl430-w250,2:xl330-m288", transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "torque_enable", 1)
        bus.write(1, "goal_position", 1000)  # CW: velocity negative
        bus.write(2, "operating_mode", 1)
        bus.faults.force_alarm(2, "overheating")
        bus.step(0.2)
        frame = Sampler(bus.call, **bus.call(decoder_options)).sample()
        one, two = bus.table(1), bus.table(2)
    text = text_of(frame)
    rows = {line.split()[0]: line for line in text.splitlines() if line[:1].isdigit()}
    degrees = one["present_position"] * 360 / 4095  # the dial's: 0..4095 over a turn
    assert "XL430-W250 (P2.0)" in rows["1"] and "position 0..4095" in rows["1"]
    assert f"{one['present_position']} ({degrees:.1f}°)" in rows["1"]
    assert f"1000 ({1000 * 360 / 4095:.1f}°)" in rows["1"]
    velocity_rpm = one["present_velocity"] * REGISTER_UNITS["present_velocity"].per_raw
    assert one["present_velocity"] < 0 and f"{velocity_rpm:+.1f} rpm" in rows["1"]
    assert f"{one['present_load'] * REGISTER_UNITS['present_load'].per_raw:+.1f} %" in rows["1"]  # the XL430's Present Load
    current_ma = two["present_current"] * model("xl330-m288").physical.current_unit_ma
    assert "XL330-M288 (P2.0)" in rows["2"] and "velocity" in rows["2"] and f"{current_ma:+.1f} mA" in rows["2"]
    assert "overheating" in rows["2"] and "alarm 0x04" in rows["2"] and two["torque_enable"] == 0
    assert "Protocol 2.0" in text


def test_a_mixed_wire_shows_both_generations_in_one_table():
    with VirtualBus(servo="1:ax-12a,1:xl430-w250", transport="inprocess", virtual_time=True, baud_bps=1_000_000) as bus:
        frame = Sampler(bus.call, **bus.call(decoder_options)).sample()
    text = text_of(frame)
    assert "AX-12A (P1.0)" in text and "XL430-W250 (P2.0)" in text and "joint 0..1023" in text
    assert "9.6" in text and "11.1" in text  # each model's supply, in volts
    assert "Protocol 1.0 + 2.0" in text
