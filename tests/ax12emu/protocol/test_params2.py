"""Protocol 2.0 parameter layouts: the e-manual's examples parse to their stated meaning; bad input is a value."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ax12emu.protocol.packets2 import (
    FastStatusPart,
    Instruction2,
    Malformed,
    StatusPacket2,
    decode_packet2,
    encode_fast_status,
)
from ax12emu.protocol.params2 import (
    INSTRUCTION_SPECS,
    BackupOption,
    Broadcast,
    BulkRead,
    BulkWrite,
    Clear,
    ClearOption,
    ControlTableBackup,
    FactoryReset,
    FactoryResetOption,
    FastStatusEntry,
    NoParams,
    PingReply,
    Read,
    SyncRead,
    SyncWrite,
    Write,
    parse_fast_status,
    parse_params,
    parse_ping_reply,
)


def h(text: str) -> bytes:
    return bytes.fromhex(text)


def params_of(wire: str):
    packet = decode_packet2(h(wire))
    assert packet.crc_ok
    return parse_params(packet.instruction, packet.params)


@pytest.mark.parametrize(
    ("wire", "meaning"),
    [
        ("FF FF FD 00 01 03 00 01 19 4E", NoParams()),
        # Present Position (132, 4 bytes) of ID 1.
        ("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15", Read(132, 4)),
        # Goal Position (116) = 512.
        ("FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89", Write(116, (512).to_bytes(4, "little"))),
        # Goal Velocity (104) = 200, registered.
        ("FF FF FD 00 01 09 00 04 68 00 C8 00 00 00 AE 8E", Write(104, (200).to_bytes(4, "little"))),
        ("FF FF FD 00 01 04 00 06 01 A1 E6", FactoryReset(FactoryResetOption.ALL_EXCEPT_ID)),
        ("FF FF FD 00 01 08 00 10 01 44 58 4C 22 B1 DC", Clear(ClearOption.MULTI_TURN)),
        ("FF FF FD 00 01 08 00 20 01 43 54 52 4C 16 F5", ControlTableBackup(BackupOption.STORE)),
        ("FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA", SyncRead(132, 4, (1, 2))),
        ("FF FF FD 00 FE 0A 00 8A 84 00 04 00 03 07 04 20 F2", SyncRead(132, 4, (3, 7, 4))),
        # ID 1 Goal Position 150, ID 2 Goal Position 170.
        ("FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87",
         SyncWrite(116, 4, ((1, h("96 00 00 00")), (2, h("AA 00 00 00"))))),
        # ID 1 Present Voltage (144, 2 bytes), ID 2 Present Temperature (146, 1 byte).
        ("FF FF FD 00 FE 0D 00 92 01 90 00 02 00 02 92 00 01 00 1A 05", BulkRead(((1, 144, 2), (2, 146, 1)))),
        # ID 1 Max Voltage Limit (32) = 160, ID 2 Temperature Limit (31) = 80.
        ("FF FF FD 00 FE 10 00 93 01 20 00 02 00 A0 00 02 1F 00 01 00 50 B7 68",
         BulkWrite(((1, 32, h("A0 00")), (2, 31, h("50"))))),
    ],
)
def test_emanual_examples_mean_what_the_emanual_says(wire, meaning):
    assert params_of(wire) == meaning


def test_fast_bulk_read_example_with_its_crc_corrected():
    """The e-manual's Fast Bulk Read asks ID 3 for 4 bytes at 132, ID 7 for 2 at 124, ID 4 for 1 at 146."""
    assert params_of("FF FF FD 00 FE 12 00 9A 03 84 00 04 00 07 7C 00 02 00 04 92 00 01 00 DA 2D") == BulkRead(
        ((3, 132, 4), (7, 124, 2), (4, 146, 1))
    )


@pytest.mark.parametrize(
    ("instruction", "params", "reason"),
    [
        (Instruction2.PING, "00", "no parameters"),
        (Instruction2.READ, "84 00 04", "4 parameter bytes"),
        (Instruction2.WRITE, "74", "2-byte address"),
        (Instruction2.FACTORY_RESET, "03", "not one of"),
        (Instruction2.FACTORY_RESET, "", "expects 1"),
        (Instruction2.CLEAR, "01 44 58 4C 23", "fixed bytes"),
        (Instruction2.CLEAR, "02 44 58 4C 22", "not one of"),
        (Instruction2.CONTROL_TABLE_BACKUP, "03 43 54 52 4C", "not one of"),
        (Instruction2.CONTROL_TABLE_BACKUP, "01 43 54 52", "expects 5"),
        (Instruction2.SYNC_READ, "84 00 04 00", "at least one ID"),
        (Instruction2.SYNC_WRITE, "74 00 04 00 01 96 00 00", "whole blocks"),
        (Instruction2.BULK_READ, "01 90 00 02", "whole blocks"),
        (Instruction2.BULK_READ, "", "whole blocks"),
        (Instruction2.BULK_WRITE, "01 20 00 02 00 A0", "announces 2"),
        (Instruction2.BULK_WRITE, "01 20 00 01 00 A0 02 1F", "fewer than ID"),
        (0x07, "", "not defined"),
        (0x55, "00", "not defined"),
    ],
)
def test_malformed_parameters_are_values(instruction, params, reason):
    result = parse_params(instruction, h(params))
    assert isinstance(result, Malformed) and reason in result.reason, result


def test_zero_length_sync_write():
    """No blocks at all is malformed; IDs with zero data bytes are well formed (the servo judges the length)."""
    assert isinstance(parse_params(Instruction2.SYNC_WRITE, h("74 00 00 00")), Malformed)
    assert parse_params(Instruction2.SYNC_WRITE, h("74 00 00 00 01 02")) == SyncWrite(116, 0, ((1, b""), (2, b"")))


@settings(max_examples=500, deadline=None)
@given(instruction=st.sampled_from(list(Instruction2)) | st.integers(0, 0xFF), params=st.binary(max_size=80))
def test_random_parameters_never_raise(instruction, params):
    """Any bytes for any instruction give a parsed value or Malformed."""
    parse_params(instruction, params)


@settings(max_examples=200, deadline=None)
@given(
    writes=st.lists(
        st.tuples(st.integers(0, 252), st.integers(0, 0xFFFF), st.binary(max_size=8)), min_size=1, max_size=6
    )
)
def test_bulk_write_blocks_round_trip(writes):
    params = b"".join(
        bytes((i,)) + a.to_bytes(2, "little") + len(d).to_bytes(2, "little") + d for i, a, d in writes
    )
    assert parse_params(Instruction2.BULK_WRITE, params) == BulkWrite(tuple(writes))


def test_every_instruction_has_a_spec_and_a_parser():
    """The spec table covers the instruction set except STATUS; broadcast answers follow the e-manual's warning."""
    assert set(INSTRUCTION_SPECS) == set(Instruction2) - {Instruction2.STATUS}
    broadcast_answered = {i for i, s in INSTRUCTION_SPECS.items() if "answer" in s.broadcast.value and "no answer" not in s.broadcast.value}
    assert broadcast_answered == {Instruction2.PING, Instruction2.SYNC_READ, Instruction2.BULK_READ,
                                  Instruction2.FAST_SYNC_READ, Instruction2.FAST_BULK_READ}
    assert INSTRUCTION_SPECS[Instruction2.READ].broadcast is Broadcast.NOT_EXECUTED
    for instruction in INSTRUCTION_SPECS:  # a parser for each: never "not defined"
        result = parse_params(instruction, b"")
        assert not (isinstance(result, Malformed) and "not defined" in result.reason)


def test_ping_reply():
    """The e-manual's XM430-W210: model 1030, firmware 38."""
    status = decode_packet2(h("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D"))
    assert parse_ping_reply(status.params) == PingReply(1030, 38)
    assert isinstance(parse_ping_reply(h("06 04")), Malformed)


EMANUAL_FAST_SYNC = "FF FF FD 00 FE 19 00 55 00 03 A6 00 00 00 84 08 00 07 1F 08 00 00 16 CA 00 04 FF 03 00 00 D1 9E"
EMANUAL_FAST_BULK = "FF FF FD 00 FE 14 00 55 00 03 A6 00 00 00 67 A4 00 07 A5 01 24 74 00 04 1F D9 C1"


def test_fast_sync_status_split_with_crcs_checked():
    status = decode_packet2(h(EMANUAL_FAST_SYNC))
    assert parse_fast_status(status, 4) == [
        FastStatusEntry(3, 0, h("A6 00 00 00"), True),
        FastStatusEntry(7, 0, h("1F 08 00 00"), True),
        FastStatusEntry(4, 0, h("FF 03 00 00"), True),
    ]


def test_fast_bulk_status_split_by_id():
    status = decode_packet2(h(EMANUAL_FAST_BULK))
    entries = parse_fast_status(status, {3: 4, 7: 2, 4: 1})
    assert [(e.id, int.from_bytes(e.data, "little"), e.crc_ok) for e in entries] == [(3, 166, True), (7, 421, True), (4, 31, True)]


def test_fast_status_flags_the_servo_whose_share_is_corrupt():
    """A corrupted byte in the second share fails that share's CRC and every CRC after it (they run on)."""
    wire = bytearray(h(EMANUAL_FAST_SYNC))
    wire[19] ^= 0x01  # ID 7's second data byte
    status = decode_packet2(wire)
    entries = parse_fast_status(status, 4)
    assert [e.crc_ok for e in entries] == [True, False, False]
    assert status.crc_ok is False


@pytest.mark.parametrize(
    ("status", "lengths", "reason"),
    [
        (StatusPacket2(1, 0, h("03 A6")), 4, "ID 0xFE"),
        (StatusPacket2(0xFE, 0, h("03 A6 00")), 4, "shorter"),
        (StatusPacket2(0xFE, 0, h("09 A6")), {3: 1}, "not asked"),
        (StatusPacket2(0xFE, 0, h("03 A6 84 08 00")), 1, "cut before its ID"),
    ],
)
def test_fast_status_malformed(status, lengths, reason):
    result = parse_fast_status(status, lengths)
    assert isinstance(result, Malformed) and reason in result.reason, result


@settings(max_examples=200, deadline=None)
@given(
    shares=st.lists(st.tuples(st.integers(0, 252), st.integers(0, 0xFF), st.binary(min_size=3, max_size=3)), min_size=1, max_size=8)
)
def test_fast_status_round_trip(shares):
    wire = encode_fast_status([FastStatusPart(*s) for s in shares])
    entries = parse_fast_status(decode_packet2(wire), 3)
    assert [(e.id, e.error, e.data) for e in entries] == shares and all(e.crc_ok for e in entries)
