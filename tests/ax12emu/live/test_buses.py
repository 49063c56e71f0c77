"""The live view's decoder options: every servo's registers named by its own model's table, in virtual time."""

from __future__ import annotations

from ax12emu import VirtualBus
from ax12emu.live import ByteTap, Sampler
from ax12emu.live.buses import decoder_options
from ax12emu.protocol.packets import Instruction, InstructionPacket
from ax12emu.protocol.packets2 import Instruction2, InstructionPacket2
from ax12emu.tracing.trace import IN


def host_lines(servo: str, *packets: bytes) -> list[str]:
    """The packet log's host lines for ``packets`` as the live view of a ``servo`` wire decodes them."""
    with VirtualBus(servo=servo, transport="inprocess", virtual_time=True) as bus:
        tap = ByteTap()
        sampler = Sampler(bus.call, tap=tap, **bus.call(decoder_options))
        for n, packet in enumerate(packets):
            tap.record(IN, packet, 1.0 + 0.01 * n)
        frame = sampler.sample()
    return [line["text"] for line in frame["log"] if line["who"] == "host"]


def write1(servo_id: int, address: int, *data: int) -> bytes:
    return InstructionPacket(servo_id, Instruction.WRITE, bytes([address, *data])).encode()


def test_an_mx_is_named_by_its_table_beside_an_ax12a():
    """Address 26..28 is the MX's D, I, P gains and the AX-12A's compliance margins and slope."""
    mx, ax = host_lines("1:mx-28,2:ax-12a", write1(1, 26, 0, 0, 32), write1(2, 26, 1, 1, 32))
    assert "d_gain=0" in mx and "p_gain=32" in mx and "compliance" not in mx
    assert "cw_compliance_margin=1" in ax and "cw_compliance_slope=32" in ax


def test_an_mx_beside_the_x_series_and_an_ax18a_alone():
    mx, x = host_lines("1:mx-64,1:xl430-w250", write1(1, 73, 5),
                       InstructionPacket2(1, Instruction2.WRITE, bytes([64, 0, 1])).encode())
    assert "goal_acceleration=5" in mx and "torque_enable=1" in x
    # The AX-18A's table is the AX-12A's in names; its own file is what names it (the wire's servos text).
    with VirtualBus(servo="ax-18a", transport="inprocess", virtual_time=True) as bus:
        assert bus.call(decoder_options)["servos"] == "1:ax-18a"


def test_the_default_ax12_bus_keeps_its_profile():
    from ax12emu.servo.virtual_servo import ServoOptions

    with VirtualBus(ids=[1, 2], transport="inprocess", virtual_time=True, options=ServoOptions(profile="ax12-2006")) as bus:
        options = bus.call(decoder_options)
    assert options["protocol"] == "1.0" and options["profile"] == "ax12-2006"


def test_a_wire_of_one_protocol_is_framed_by_that_protocol_alone():
    """A differential drive's Sync Write of Goal Velocity -3/+3 to two XL430s holds ``ff ff ff 02 03 00 00 00``, a
    1.0 frame's start: framed by both protocols, that false frame completed first and the Sync Write was lost."""
    with VirtualBus(servo="xl430-w250", ids=[1, 2], transport="inprocess", virtual_time=True) as bus:
        assert bus.call(decoder_options)["protocol"] == "2.0"
    with VirtualBus(servo="1:ax-12a,2:xl430-w250", transport="inprocess", virtual_time=True) as bus:
        assert bus.call(decoder_options)["protocol"] == "both"
    data = (1).to_bytes(1, "little") + (-3).to_bytes(4, "little", signed=True) + (2).to_bytes(1, "little") + (3).to_bytes(4, "little")
    sync_write = InstructionPacket2(0xFE, Instruction2.SYNC_WRITE, bytes([104, 0, 4, 0]) + data).encode()
    lines = host_lines("xl430-w250", sync_write, sync_write)
    assert len(lines) == 2 and all("goal_velocity=-3" in line and "goal_velocity=3" in line for line in lines), lines


def test_a_reply_byte_identical_to_its_ping_is_the_servos_on_a_wire_with_no_echo():
    """A PING answered with the Input Voltage alarm (error 0x01, where PING's code is) is ``ff ff 01 02 01 fb`` both
    ways. The live log of an in-process bus (its link echoes nothing) shows the answer as the servo's, where on a
    wire that may echo it reads as the adapter's echo."""
    import time

    import serial
    from emu_testkit import http_json

    ping = InstructionPacket(1, Instruction.PING, b"").encode()
    with VirtualBus(ids=[1], transport="inprocess", virtual_time=True, web=("127.0.0.1", 0)) as bus:
        bus.faults.force_alarm(1, "input_voltage")
        port = serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.2)
        try:
            port.write(ping)
            assert port.read(6) == ping
        finally:
            port.close()
        deadline = time.monotonic() + 5.0
        while True:  # the page samples the bus 25 times a second
            status, answer = http_json(f"{bus.web_url}api/log?n=50", method="GET")
            lines = answer["lines"] if isinstance(answer, dict) else answer
            whos = [line["who"] for line in lines if line["who"] in ("host", "servo", "echo")]
            if len(whos) >= 2 or time.monotonic() > deadline:
                break
            time.sleep(0.05)
    assert status == 200 and whos == ["host", "servo"], lines


def test_pace_and_echo_are_refused_in_process():
    import pytest

    for flag in ("pace", "echo"):
        with pytest.raises(ValueError, match="in-process link has none"):
            VirtualBus(transport="inprocess", **{flag: True})
