"""A wire shared by AX-12As (Protocol 1.0) and X-series servos (Protocol 2.0): each protocol's servos answer only their own."""

from __future__ import annotations

import pytest
from x2_testkit import RecordingFirmware

from ax12emu.bus.bus import Bus
from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock
from ax12emu.bus.mixed import MixedBus
from ax12emu.protocol.packets import Instruction, encode_instruction
from ax12emu.protocol.packets2 import Instruction2, decode_packet2, encode_instruction2
from ax12emu.protocol.servo_models import model


def mixed() -> MixedBus:
    clock = VirtualClock()
    return MixedBus(Bus([1, 2], clock=clock), Bus2([(1, model("xl430-w250")), (3, model("xl430-w250"))],
                                                  lambda spec, index: RecordingFirmware(), clock=clock))


def test_each_protocol_reaches_its_own_servos_even_with_the_same_id():
    bus = mixed()
    (reply,) = bus.receive(encode_instruction(1, Instruction.PING))
    assert reply.data[:3] == b"\xff\xff\x01" and len(reply.data) == 6  # an AX-12A's status
    (reply,) = bus.receive(encode_instruction2(1, Instruction2.PING))
    assert decode_packet2(reply.data).params[:2] == (1060).to_bytes(2, "little")
    assert bus.receive(encode_instruction(3, Instruction.PING)) == []
    assert bus.receive(encode_instruction2(2, Instruction2.PING)) == []
    assert sorted(bus.ids) == [1, 1, 2, 3]


def test_a_stuffed_2_0_packet_makes_the_1_0_servos_wait_for_their_silence_timeout():
    """framing2: FF FF FD FD in a stuffed 2.0 packet reads as a 1.0 header with LENGTH 253 to the 1.0 servos."""
    bus = mixed()
    stuffed = encode_instruction2(1, Instruction2.WRITE, bytes((224, 0, 0xFF, 0xFF, 0xFD, 0)))
    assert b"\xff\xff\xfd\xfd" in stuffed
    assert len(bus.receive(stuffed, now_s=0.0)) == 1  # the 2.0 servo answers its write
    assert bus.receive(encode_instruction(2, Instruction.PING), now_s=0.001) == []  # swallowed by the 1.0 framer
    assert len(bus.receive(encode_instruction(2, Instruction.PING), now_s=0.1)) == 1  # after the silence timeout


def test_one_clock_for_both():
    with pytest.raises(ValueError, match="one clock"):
        MixedBus(Bus([1], clock=VirtualClock()), Bus2([(1, model("xl430-w250"))], lambda s, i: RecordingFirmware(),
                                                      clock=VirtualClock()))


@pytest.mark.parametrize(("servo", "default_v"), [("ax-12a", None), ("ax-18a", 11.1)])
def test_a_protocol_1_servo_has_one_default_supply_alone_and_beside_x_series_servos(servo, default_v):
    """Present Voltage (0.1 V) of an AX servo on a Protocol 1.0 bus of its own and on a mixed wire: the same,
    the documented default (the AX-12A's physics' supply, another AX model's recommended supply)."""
    from ax12emu import VirtualBus
    from firmware_model import ServoParams

    expected = round(10 * (ServoParams().supply_voltage_v if default_v is None else default_v))
    seen = {}
    for name, kwargs in (("alone", {"ids": [1]} if servo == "ax-12a" else {"servo": f"1:{servo}"}),
                         ("kinematic", {"ids": [1], "model": "kinematic"} if servo == "ax-12a" else None),
                         ("mixed", {"servo": f"1:{servo},2:xl430-w250"})):
        if kwargs is None:
            continue
        with VirtualBus(transport="inprocess", virtual_time=True, **kwargs) as bus:
            bus.step(0.05)
            seen[name] = bus.call(lambda b: getattr(b, "bus1", b).servo(1).table.get("present_voltage"))
    assert set(seen.values()) == {expected}, seen


@pytest.mark.parametrize(("spec", "named"), [
    ("1:ax-12a,1:xl430-w250", "AX-12A on 1.0, XL430-W250 on 2.0"),
    ("1:ax-18a,1:xl330-m077", "AX-18A on 1.0, XL330-M077 on 2.0"),
    ("1:mx-64,1:xm430-w350", "MX-64 on 1.0, XM430-W350 on 2.0"),
])
def test_an_id_on_both_protocols_is_refused_naming_each_model(spec, named):
    from ax12emu.harness.servos2 import build_wire

    bus = build_wire(spec, clock=VirtualClock())
    with pytest.raises(ValueError, match=f"ID 1 answers on both protocols of this wire \\({named}\\)"):
        bus.servo(1)
    assert bus.holder(bus.servo(1, 1.0)) is bus.bus1 and bus.holder(bus.servo(1, 2.0)) is bus.bus2


def test_an_ax_12a_beside_mx_servos_is_held_by_the_ax_12_bus_inside_theirs():
    from ax12emu.harness.servos2 import build_wire

    bus = build_wire("1:mx-28,2:ax-12a,3:xl430-w250", clock=VirtualClock())
    ax12a, mx28 = bus.servo(2, 1.0), bus.servo(1, 1.0)
    assert bus.holder(ax12a) is bus.bus1.ax_bus and bus.holder(mx28) is bus.bus1
    assert bus.bus1.ax_bus.slots[ax12a.index] == 2 and bus.bus1.slots[mx28.index] == 1
