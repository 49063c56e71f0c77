"""One-line descriptions of Protocol 2.0 packets, as the trace decoder will print them."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ax12emu.protocol.describe2 import describe_error2, describe_instruction2, describe_status2
from ax12emu.protocol.packets2 import InstructionPacket2, StatusPacket2, decode_packet2


def h(text: str) -> bytes:
    return bytes.fromhex(text)


@pytest.mark.parametrize(
    ("wire", "line"),
    [
        ("FF FF FD 00 01 03 00 01 19 4E", "PING id=1"),
        ("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15", "READ id=1 @132 length=4"),
        ("FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89", "WRITE id=1 @116=512 (4 bytes)"),
        ("FF FF FD 00 01 04 00 06 01 A1 E6", "FACTORY_RESET id=1 ALL_EXCEPT_ID"),
        ("FF FF FD 00 01 08 00 10 01 44 58 4C 22 B1 DC", "CLEAR id=1 MULTI_TURN"),
        ("FF FF FD 00 01 08 00 20 01 43 54 52 4C 16 F5", "CONTROL_TABLE_BACKUP id=1 STORE"),
        ("FF FF FD 00 FE 0A 00 8A 84 00 04 00 03 07 04 20 F2", "FAST_SYNC_READ id=254 @132 length=4 ids=3,7,4"),
        ("FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87",
         "SYNC_WRITE id=254 [id=1 @116=150 (4 bytes)] [id=2 @116=170 (4 bytes)]"),
        ("FF FF FD 00 FE 0D 00 92 01 90 00 02 00 02 92 00 01 00 1A 05",
         "BULK_READ id=254 [id=1 @144 length=2] [id=2 @146 length=1]"),
        ("FF FF FD 00 FE 10 00 93 01 20 00 02 00 A0 00 02 1F 00 01 00 50 B7 68",
         "BULK_WRITE id=254 [id=1 @32=160 (2 bytes)] [id=2 @31=80 (1 byte)]"),
    ],
)
def test_instructions(wire, line):
    assert describe_instruction2(decode_packet2(h(wire))) == line


def test_register_names_and_odd_cases():
    write = decode_packet2(h("FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89"))
    assert describe_instruction2(write, names={116: "goal_position"}) == "WRITE id=1 goal_position=512 (4 bytes)"
    assert describe_instruction2(InstructionPacket2(1, 0x03, h("74 00 01 02 03"))) == "WRITE id=1 @116=01 02 03 (3 bytes)"
    assert describe_instruction2(InstructionPacket2(1, 0x02, h("84"), crc_ok=False)) == "READ id=1 BAD-CRC"
    assert describe_instruction2(InstructionPacket2(1, 0x02, h("84"))) == (
        "READ id=1 MALFORMED (expects 4 parameter bytes (address, length), got 1) params=84"
    )
    assert describe_instruction2(InstructionPacket2(1, 0x07)).startswith("INSTR_0x07 id=1 MALFORMED")


def test_errors():
    assert describe_error2(0) == "ok"
    assert describe_error2(0x04) == "DATA_RANGE"
    assert describe_error2(0x80) == "ALERT"
    assert describe_error2(0x87) == "ALERT|ACCESS"
    assert describe_error2(0x09) == "ERROR_0x09"


def test_statuses_named_from_their_request():
    ping = decode_packet2(h("FF FF FD 00 01 03 00 01 19 4E"))
    pong = decode_packet2(h("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D"))
    assert describe_status2(pong, ping) == "STATUS id=1 ok model=1030 firmware=38"
    read = decode_packet2(h("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15"))
    value = decode_packet2(h("FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0"))
    assert describe_status2(value, read, names={132: "present_position"}) == "STATUS id=1 ok present_position=166"
    assert describe_status2(value) == "STATUS id=1 ok params=a6 00 00 00"
    bulk = decode_packet2(h("FF FF FD 00 FE 0D 00 92 01 90 00 02 00 02 92 00 01 00 1A 05"))
    temperature = decode_packet2(h("FF FF FD 00 02 05 00 55 00 24 8B A9"))
    assert describe_status2(temperature, bulk) == "STATUS id=2 ok @146=36"
    assert describe_status2(StatusPacket2(1, 0x87)) == "STATUS id=1 ALERT|ACCESS"
    assert describe_status2(StatusPacket2(1, 0, b"", crc_ok=False)) == "STATUS id=1 ok BAD-CRC"


def test_fast_status_described_per_servo():
    request = decode_packet2(h("FF FF FD 00 FE 0A 00 8A 84 00 04 00 03 07 04 20 F2"))
    reply = decode_packet2(
        h("FF FF FD 00 FE 19 00 55 00 03 A6 00 00 00 84 08 00 07 1F 08 00 00 16 CA 00 04 FF 03 00 00 D1 9E")
    )
    assert describe_status2(reply, request) == "FAST-STATUS [id=3 ok 166] [id=7 ok 2079] [id=4 ok 1023]"


@settings(max_examples=300, deadline=None)
@given(
    instruction=st.integers(0, 0xFF),
    params=st.binary(max_size=40),
    request_params=st.binary(max_size=20),
    request_instruction=st.sampled_from([0x01, 0x02, 0x82, 0x8A, 0x92, 0x9A]),
)
def test_any_packet_describes_without_raising(instruction, params, request_params, request_instruction):
    request = InstructionPacket2(0xFE, request_instruction, request_params)
    assert describe_instruction2(InstructionPacket2(1, instruction, params))
    assert describe_status2(StatusPacket2(0xFE, instruction, params), request)
    assert describe_status2(StatusPacket2(1, instruction, params), request)
