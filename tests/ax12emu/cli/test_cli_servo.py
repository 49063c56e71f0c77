"""``serve --servo``: the Protocol 2.0 bus from the command line; every mistake is one line and exit 2."""

from __future__ import annotations

import subprocess
import sys

import pytest

from ax12emu.cli.main import parse_args


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ax12emu", *args], capture_output=True, text=True, timeout=30)


def test_a_model_for_every_id_and_per_id_models():
    assert parse_args(["serve", "--servo", "xl430-w250", "--ids", "1-3"]).servo_models == [
        (1, "xl430-w250"), (2, "xl430-w250"), (3, "xl430-w250")]
    assert parse_args(["serve", "--servo", "xl430-w250"]).servo_models == [(1, "xl430-w250")]
    assert parse_args(["serve", "--servo", "1-2:xm430-w350,6:xl330-m077"]).servo_models == [
        (1, "xm430-w350"), (2, "xm430-w350"), (6, "xl330-m077")]
    assert not hasattr(parse_args(["serve"]), "servo_models")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--servo", "xl999"], "unknown servo model 'xl999'"),
        (["--servo", "1-3:xl430-w250", "--ids", "1-3"], "both name the IDs"),
        (["--servo", "1-3:xl430-w250,3:xm430-w350"], "ID 3 is given two models"),
        (["--servo", "xl430-w250", "--ids", "253"], "outside 0..252"),
        (["--servo", "1:ax-12a,1:xl430-w250", "--vanish", "1"], "ID 1 was launched on both protocols"),
        (["--servo", "xl430-w250", "--voltage", "30"], "runs on 6.5..12 V, not 30 V"),
        (["--baud", "1000000"], "--baud applies with --servo"),
        (["--servo", "xl430-w250", "--baud", "250000"], "runs at 9600, 57600, 115200, 1000000"),
        (["--servo", "1:ax-12a,2:xl430-w250", "--baud", "4500000"], "ID 1 (AX-12A) cannot run at 4500000 bps"),
        (["--servo", "ax-12a", "--arm", "0.1,0.1"], "--arm is not available with --servo yet"),
        (["--servo", "1:ax-12a,1:ax-12a,2:xl430-w250"], "ID 1 is given two models"),
        (["--servo", "xl430-w250", "--goal-torque", "unchanged"], "--goal-torque applies to AX series and MX series"),
        (["--servo", "mx-28", "--eeprom-busy-ms", "0"], "--eeprom-busy-ms applies to AX series servos"),
        (["--servo", "1:ax-12a,2:ax-18a", "--params", "twin.toml"], "on a wire of several models (ax-12a, ax-18a)"),
        (["--servo", "ax-18a", "--arm", "0.1,0.1"], "--arm is not available with --servo yet"),
    ],
)
def test_mistakes_are_one_line_and_exit_2(args, message):
    result = run("serve", *args)
    assert result.returncode == 2, result
    assert "Traceback" not in result.stderr
    assert message in result.stderr, result.stderr


def test_servo_faults_from_the_flags(emulator):
    """--alarm, --stall and --duplicate are taken with --servo: Overload latched on ID 2 (Alert in its status),
    ID 1 untouched, the servo launched as 3 answering as ID 1."""
    from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, PacketHandler
    from emu_testkit import PatientPortHandler

    port = PatientPortHandler(emulator("--servo", "xl430-w250", "--ids", "1-3", "--alarm", "2:overload", "--stall", "1",
                                       "--duplicate", "3:1").port)
    assert port.openPort() and port.setBaudRate(57600)
    try:
        ph = PacketHandler(2.0)
        assert ph.read1ByteTxRx(port, 2, 70) == (0x20, COMM_SUCCESS, 0x80)  # Hardware Error Status, Alert bit
        assert ph.read1ByteTxRx(port, 1, 70) == (0, COMM_SUCCESS, 0)  # both servos on ID 1 answer the same
        assert ph.ping(port, 3)[1] == COMM_RX_TIMEOUT
    finally:
        port.closePort()


def test_ax12as_alone_start_at_another_rate_with_servo_and_baud(emulator):
    """`--servo ax-12a --baud 57600` was refused ("no Protocol 2.0 servo", though AX-18As alone were taken), so
    AX-12As could only start at 1 Mbps: at 57,600 bps they answer, their Baud Rate register 34."""
    import serial

    from ax12emu.protocol.packets import Instruction, encode_instruction

    served = emulator("--servo", "ax-12a", "--ids", "1-2", "--baud", "57600", "--tcp", "127.0.0.1:0")
    with serial.serial_for_url(served.port, baudrate=57600, timeout=1.0) as link:
        link.write(encode_instruction(2, Instruction.READ, bytes((4, 1))))
        reply = link.read(7)
    assert reply[2] == 2 and reply[5] == 34, reply.hex(" ")
