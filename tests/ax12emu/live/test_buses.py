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
