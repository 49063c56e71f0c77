"""A Fast Sync/Bulk Read listing an ID two servos share (a fault): the combined status the wire carries.

Both servos parse the same instruction packet, so when the shared ID is listed first both send the
header, and both announce the LENGTH of every listed share ("Fast Sync Read (0x8A)": the first
device sends the header of the one status packet answering for all of them); their headers agree and
AND to themselves, only their shares differ.
"""

from __future__ import annotations

import pytest

from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock
from ax12emu.protocol.crc16 import crc16
from ax12emu.protocol.packets2 import Instruction2, encode_instruction2
from ax12emu.protocol.servo_models import model
from ax12emu.servo.model_factory2 import build_x_firmware

PRESENT_INPUT_VOLTAGE = 144
HEADER = 8  # FF FF FD 00 FE LEN_L LEN_H 55


def _bus_with_two_on_id_2() -> Bus2:
    """An XL430-W250 on ID 1, an XM430-W350 on ID 2 and an XL330-M077 moved to ID 2 (their voltages differ)."""
    bus = Bus2([(1, model("xl430-w250")), (2, model("xm430-w350")), (3, model("xl330-m077"))],
               lambda spec, index: build_x_firmware(spec), clock=VirtualClock())
    assert bus.receive(encode_instruction2(3, Instruction2.WRITE, bytes((7, 0, 2)))) != []
    assert [s.id for s in bus.servos] == [1, 2, 2]
    return bus


@pytest.mark.parametrize("instruction, params", [
    (Instruction2.FAST_SYNC_READ, bytes((PRESENT_INPUT_VOLTAGE, 0, 2, 0, 2, 1, 1, 1))),
    (Instruction2.FAST_BULK_READ, b"".join(bytes((i, PRESENT_INPUT_VOLTAGE, 0, 2, 0)) for i in (2, 1, 1, 1))),
])
def test_servos_sharing_the_first_listed_id_announce_every_share(instruction, params):
    bus = _bus_with_two_on_id_2()
    voltages = [s.table.get("present_input_voltage") for s in bus.servos]
    assert voltages[1] != voltages[2], "the shared ID's two readings differ, so the collision shows"
    wire = b"".join(r.data for r in bus.receive(encode_instruction2(0xFE, instruction, params)))
    shares = 4
    length = 1 + shares * (4 + 2)
    assert wire[5] | wire[6] << 8 == length  # both headers announce the four listed shares
    assert len(wire) == 7 + length
    assert wire[HEADER:HEADER + 2] == bytes((0, 2))
    assert int.from_bytes(wire[HEADER + 2:HEADER + 4], "little") == voltages[1] & voltages[2]  # AND-ed on the wire
    assert int.from_bytes(wire[-2:], "little") == crc16(wire[:-2])  # ID 1's last share runs on over what it heard
