"""``serve --servo ax-18a``: AX-18As on Protocol 1.0 from the command line, alone or beside X-series servos."""

from __future__ import annotations

import subprocess
import sys

import pytest
from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, PacketHandler

from ax12emu.cli.main import parse_args


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ax12emu", *args], capture_output=True, text=True, timeout=30)


def test_dynamixel_sdk_pings_an_ax18a_and_reads_model_number_18(emulator):
    from emu_testkit import PatientPortHandler

    port = PatientPortHandler(emulator("--servo", "ax-18a", "--ids", "1,3").port)
    assert port.openPort() and port.setBaudRate(1_000_000)
    try:
        ph = PacketHandler(1.0)
        assert ph.ping(port, 1) == (18, COMM_SUCCESS, 0)
        assert ph.read2ByteTxRx(port, 3, 0) == (18, COMM_SUCCESS, 0)
        assert ph.ping(port, 2)[1] == COMM_RX_TIMEOUT
    finally:
        port.closePort()


def test_ax18as_beside_x_series_servos(emulator):
    from emu_testkit import PatientPortHandler

    port = PatientPortHandler(emulator("--servo", "1-2:ax-18a,1:xl430-w250", "--baud", "1000000").port)
    assert port.openPort() and port.setBaudRate(1_000_000)
    try:
        assert PacketHandler(1.0).ping(port, 2) == (18, COMM_SUCCESS, 0)
        assert PacketHandler(2.0).ping(port, 1) == (1060, COMM_SUCCESS, 0)
    finally:
        port.closePort()


def test_ax12as_and_ax18as_on_one_wire(emulator):
    from emu_testkit import PatientPortHandler

    port = PatientPortHandler(emulator("--servo", "1-2:ax-12a,3:ax-18a").port)
    assert port.openPort() and port.setBaudRate(1_000_000)
    try:
        ph = PacketHandler(1.0)
        assert [ph.ping(port, i) for i in (1, 2, 3)] == [(12, COMM_SUCCESS, 0), (12, COMM_SUCCESS, 0), (18, COMM_SUCCESS, 0)]
    finally:
        port.closePort()


def test_the_spec_takes_ax18a():
    assert parse_args(["serve", "--servo", "ax-18a", "--ids", "1-2"]).servo_models == [(1, "ax-18a"), (2, "ax-18a")]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--servo", "ax-18a", "--voltage", "7"], "AX-18A"),
    ],
)
def test_mistakes_are_one_line(args, message):
    result = run("serve", *args)
    assert result.returncode != 0, result
    assert "Traceback" not in result.stderr
    assert message in result.stderr, result.stderr


def test_the_ax_series_flags_reach_the_ax_servos_on_a_servo_wire(tmp_path):
    """--params, --goal-torque, --eeprom-busy-ms and the other AX bus flags shape the AX servos of a --servo wire:
    a twin fitted to an AX-18A's recording serves AX-18As; an X-series servo beside them is untouched."""
    from ax12emu.bus.clock import VirtualClock
    from ax12emu.cli.main import build_serve_wire
    from firmware_model.params import ServoParams

    twin = ServoParams(static_friction_nm=0.21, supply_voltage_v=11.1)
    twin.to_toml(tmp_path / "twin.toml")
    bus = build_serve_wire(parse_args(["serve", "--servo", "ax-18a", "--ids", "1-2", "--params", str(tmp_path / "twin.toml"),
                                       "--goal-torque", "unchanged", "--eeprom-busy-ms", "0"]), VirtualClock())
    assert bus.model.params == twin
    assert [(s.options.goal_position_enables_torque, s.options.eeprom_busy_s_per_byte) for s in bus.servos] == [(False, 0.0)] * 2
    mixed = build_serve_wire(parse_args(["serve", "--servo", "1:ax-18a,2:xl430-w250", "--baud", "1000000",
                                         "--reset-reply-id", "new", "--broadcast-ping", "silent"]), VirtualClock())
    (ax,) = mixed.bus1.servos
    assert ax.options.reset_reply_from_new_id and not ax.options.reply_to_broadcast_ping
    mx = build_serve_wire(parse_args(["serve", "--servo", "mx-28", "--goal-torque", "unchanged"]), VirtualClock())
    assert not mx.servos[0].options.goal_position_enables_torque
