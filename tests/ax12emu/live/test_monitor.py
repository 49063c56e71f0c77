"""``serve --monitor``'s table for X-series servos and a mixed wire: each servo in its own units, from a frame in virtual time."""

from __future__ import annotations

import io
import logging
import os
import re

import pytest
from rich.cells import cell_len
from rich.console import Console

from ax12emu import VirtualBus
from ax12emu.live import Sampler
from ax12emu.live.buses import decoder_options
from ax12emu.live.monitor import Monitor, render
from ax12emu.live.snapshot import REGISTER_UNITS
from ax12emu.protocol.servo_models import model


def text_of(frame: dict, width: int = 240) -> str:
    with open(os.devnull, "w") as nowhere:
        console = Console(width=width, record=True, file=nowhere)
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
    degrees = one["present_position"] * 360 / 4096  # e-manual X series: 4096 counts a turn
    assert "XL430-W250 (P2.0)" in rows["1"] and "position 0..4095" in rows["1"]
    assert f"{one['present_position']} ({degrees:.1f}°)" in rows["1"]
    assert f"1000 ({1000 * 360 / 4096:.1f}°)" in rows["1"]
    velocity_rpm = one["present_velocity"] * REGISTER_UNITS["present_velocity"].per_raw
    assert one["present_velocity"] < 0 and f"{velocity_rpm:+.1f} rpm" in rows["1"]
    assert f"{one['present_load'] * REGISTER_UNITS['present_load'].per_raw:+.1f} %" in rows["1"]  # the XL430's Present Load
    current_ma = two["present_current"] * model("xl330-m288").physical.current_unit_ma
    assert "XL330-M288 (P2.0)" in rows["2"] and "velocity" in rows["2"] and f"{current_ma:+.1f} mA" in rows["2"]
    assert "overheating" in rows["2"] and "alarm 0x04" in rows["2"] and two["torque_enable"] == 0  # its row's columns
    assert "Protocol 2.0" in text


def test_a_mixed_wire_shows_both_generations_in_one_table():
    with VirtualBus(servo="1:ax-12a,1:xl430-w250", transport="inprocess", virtual_time=True, baud_bps=1_000_000) as bus:
        frame = Sampler(bus.call, **bus.call(decoder_options)).sample()
    text = text_of(frame)
    assert "AX-12A (P1.0)" in text and "XL430-W250 (P2.0)" in text and "joint 0..1023" in text
    assert "9.6" in text and "11.1" in text  # each model's supply, in volts
    assert "Protocol 1.0 + 2.0" in text


def _troubled_frame() -> dict:
    """A mixed wire: an alarm forced on one servo, another vanished, a third in extended position mode."""
    with VirtualBus(servo="1:ax-12a,1:xl430-w250,2:xl330-m288", transport="inprocess", virtual_time=True,
                    baud_bps=1_000_000) as bus:
        bus.faults.force_alarm(1, "overload", protocol=1.0)
        bus.faults.vanish(2, protocol=2.0)
        bus.write(1, "operating_mode", 4, protocol=2.0)  # extended position: the mode text is long
        return Sampler(bus.call, **bus.call(decoder_options)).sample()


@pytest.mark.parametrize("width", [80, 120])
def test_a_common_terminal_shows_every_servos_id_mode_errors_and_faults(width):
    """rich squeezed every column of a table too wide for the terminal, the short ones (ID, the alarm names) to
    nothing: the columns that fit are kept whole, and each servo's errors and faults get a line of their own."""
    text = text_of(_troubled_frame(), width)
    lines = text.splitlines()
    assert all(cell_len(line.rstrip()) <= width for line in lines), text
    header = next(line for line in lines if line.startswith("ID "))
    assert header.split()[:4] == ["ID", "mode", "position", "goal"], header
    rows = [line.split() for line in lines[lines.index(header) + 1:] if line[:1].isdigit()]
    assert [row[0] for row in rows] == ["1", "1", "2"], text
    assert "joint" in rows[0] and "extended" in rows[1] and "…" not in text
    assert "ID 1 (P1.0): errors overload" in text and "ID 2 (P2.0): faults vanished" in text


def test_a_wide_terminal_keeps_every_column():
    text = text_of(_troubled_frame(), 240)
    assert "no room" not in text
    assert "XL330-M288 (P2.0)" in text and "baud" in text and "1M" in text


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_log_lines_print_above_the_table_while_it_is_drawn_in_place():
    """A log handler on the monitor's stream would write into the table, which the next redraw then overwrites:
    while the monitor runs, such a handler prints through its console, which puts the line above the table."""
    with VirtualBus([1], transport="inprocess", virtual_time=True) as bus:
        sampler = Sampler(bus.call, **bus.call(decoder_options))
        terminal = _Terminal()
        handler = logging.StreamHandler(terminal)
        root = logging.getLogger()
        root.addHandler(handler)
        monitor = Monitor(sampler, stream=terminal, force_terminal=True, width=100).start()
        try:
            monitor._draw(sampler.sample())
            drawn = terminal.tell()
            logging.getLogger("ax12emu.test").warning("a line from the log")
            after = terminal.getvalue()[drawn:]
        finally:
            monitor.close()
            root.removeHandler(handler)
    assert handler.stream is terminal  # given back
    said = after.index("a line from the log")
    assert "\x1b[2K" in after[:said]  # the table erased first (rich's Live: cursor up, erase line) ...
    assert "position" in after[said:]  # ... and drawn again under the line


def test_a_wide_terminal_shows_each_servos_errors_in_its_row_however_short_the_terminal():
    """18 servos in a 220x24 terminal: the errors and faults were lines under the table, which rich's Live cut off
    past the terminal's 24 lines; where every column fits, they are the table's last columns, a servo's in its row."""
    troubled = (2, 7, 11, 16)
    with VirtualBus(list(range(1, 19)), transport="inprocess", virtual_time=True) as bus:
        for servo_id in troubled:
            bus.faults.force_alarm(servo_id, "overheating")
        sampler = Sampler(bus.call, **bus.call(decoder_options))
        terminal = _Terminal()
        monitor = Monitor(sampler, stream=terminal, force_terminal=True, width=220)
        monitor.console.height = 24
        monitor.start()
        try:
            monitor._draw(sampler.sample())
            screen = re.sub(r"\x1b\[[0-9;?]*[a-zA-Z]", "", terminal.getvalue())  # what the terminal shows
        finally:
            monitor.close()
    rows = {line.split()[0]: line for line in screen.splitlines() if line[:1].isdigit()}
    assert all("overheating" in rows.get(str(servo_id), "") for servo_id in troubled), screen
    assert not any("overheating" in row for servo_id, row in rows.items() if int(servo_id) not in troubled)
