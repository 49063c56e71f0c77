"""Protocol 2.0 packets: e-manual vectors, byte stuffing both ways, and dynamixel-sdk as a second witness."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ax12emu.protocol.packets2 import (
    FastStatusPart,
    InstructionPacket2,
    Malformed,
    StatusPacket2,
    decode_packet2,
    encode_fast_status,
    encode_instruction2,
    encode_status2,
    fast_status_pieces,
    status_error,
    stuff,
    unstuff,
)

sdk = pytest.importorskip("dynamixel_sdk.protocol2_packet_handler")
group_sync_read = pytest.importorskip("dynamixel_sdk.group_sync_read")


def h(text: str) -> bytes:
    return bytes.fromhex(text)


class CapturePort:
    """Enough of dynamixel-sdk's PortHandler to record what it writes and play back a reply."""

    def __init__(self, reply: bytes = b"") -> None:
        self.written = bytearray()
        self.reply = bytearray(reply)
        self.is_using = False

    def clearPort(self):  # (the SDK's method names)
        pass

    def writePort(self, packet):
        self.written += bytes(packet)
        return len(packet)

    def readPort(self, length):
        out = list(self.reply[:length])
        del self.reply[:length]
        return out

    def setPacketTimeout(self, length):
        pass

    def setPacketTimeoutMillis(self, ms):
        pass

    def isPacketTimeout(self):
        return True

    def getBaudRate(self):
        return 1_000_000


def sdk_bytes(call) -> bytes:
    port = CapturePort()
    call(sdk.Protocol2PacketHandler(), port)
    return bytes(port.written)


@pytest.mark.parametrize(
    ("packet", "wire"),
    [
        (InstructionPacket2(1, 0x01), "FF FF FD 00 01 03 00 01 19 4E"),
        (InstructionPacket2(1, 0x02, h("84 00 04 00")), "FF FF FD 00 01 07 00 02 84 00 04 00 1D 15"),
        (InstructionPacket2(1, 0x03, h("74 00 00 02 00 00")), "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89"),
        (InstructionPacket2(0xFE, 0x82, h("84 00 04 00 01 02")), "FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA"),
        (StatusPacket2(1, 0, h("06 04 26")), "FF FF FD 00 01 07 00 55 00 06 04 26 65 5D"),
        (StatusPacket2(1, 0, h("A6 00 00 00")), "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0"),
        (StatusPacket2(1, 0), "FF FF FD 00 01 04 00 55 00 A1 0C"),
    ],
)
def test_emanual_examples_encode_and_decode(packet, wire):
    """The e-manual's packets are what encode() builds, and decode back to the same packet."""
    assert packet.encode() == h(wire)
    assert decode_packet2(h(wire)) == packet


@pytest.mark.parametrize(
    ("ours", "theirs"),
    [
        (lambda: encode_instruction2(7, 0x01), lambda ph, port: ph.ping(port, 7)),
        (lambda: encode_instruction2(3, 0x02, h("84 00 04 00")), lambda ph, port: ph.readTx(port, 3, 132, 4)),
        (lambda: encode_instruction2(3, 0x03, h("74 00 00 02 00 00")),
         lambda ph, port: ph.write4ByteTxOnly(port, 3, 116, 512)),
        (lambda: encode_instruction2(3, 0x04, h("68 00 C8 00")), lambda ph, port: ph.regWriteTxOnly(port, 3, 104, 2, [200, 0])),
        (lambda: encode_instruction2(0xFE, 0x05), lambda ph, port: ph.action(port, 0xFE)),
        (lambda: encode_instruction2(2, 0x06, h("02")), lambda ph, port: ph.factoryReset(port, 2, 0x02)),
        (lambda: encode_instruction2(2, 0x08), lambda ph, port: ph.reboot(port, 2)),
        (lambda: encode_instruction2(2, 0x10, h("01 44 58 4C 22")), lambda ph, port: ph.clearMultiTurn(port, 2)),
        (lambda: encode_instruction2(0xFE, 0x82, h("84 00 04 00 01 02 05")),
         lambda ph, port: ph.syncReadTx(port, 132, 4, [1, 2, 5], 3, False)),
        (lambda: encode_instruction2(0xFE, 0x8A, h("84 00 04 00 01 02 05")),
         lambda ph, port: ph.syncReadTx(port, 132, 4, [1, 2, 5], 3, True)),
        (lambda: encode_instruction2(0xFE, 0x83, h("74 00 02 00 01 10 00 02 20 00")),
         lambda ph, port: ph.syncWriteTxOnly(port, 116, 2, [1, 0x10, 0, 2, 0x20, 0], 6)),
        (lambda: encode_instruction2(0xFE, 0x92, h("01 90 00 02 00 02 92 00 01 00")),
         lambda ph, port: ph.bulkReadTx(port, [1, 0x90, 0, 2, 0, 2, 0x92, 0, 1, 0], 10, False)),
        (lambda: encode_instruction2(0xFE, 0x9A, h("03 84 00 04 00 07 7C 00 02 00 04 92 00 01 00")),
         lambda ph, port: ph.bulkReadTx(port, list(h("03 84 00 04 00 07 7C 00 02 00 04 92 00 01 00")), 15, True)),
        (lambda: encode_instruction2(0xFE, 0x93, h("01 20 00 02 00 A0 00 02 1F 00 01 00 50")),
         lambda ph, port: ph.bulkWriteTxOnly(port, list(h("01 20 00 02 00 A0 00 02 1F 00 01 00 50")), 13)),
    ],
)
def test_same_bytes_as_dynamixel_sdk(ours, theirs):
    """Every instruction dynamixel-sdk can send is byte for byte what the encoder builds."""
    assert ours() == sdk_bytes(theirs)


def test_stuffed_status_read_by_dynamixel_sdk():
    """A READ reply whose data holds FF FF FD is stuffed on the wire and the SDK reads the data back."""
    data = h("FF FF FD 07")
    reply = encode_status2(4, 0, data)
    assert reply == h("FF FF FD 00 04 09 00 55 00 FF FF FD FD 07") + reply[-2:]
    port = CapturePort(reply)
    value, result, error = sdk.Protocol2PacketHandler().read4ByteTxRx(port, 4, 132)
    assert (result, error, value) == (0, 0, int.from_bytes(data, "little"))


def test_sdk_sends_stuffing_patterns_unstuffed():
    """dynamixel-sdk's Python txPacket drops addStuffing's lengthened copy, so FF FF FD in written data
    goes out unstuffed with the unstuffed LENGTH.  Such a packet still has a good CRC; unstuffing it
    keeps FF FF FD 01 whole, but would swallow the second FD of FF FF FD FD, as a servo would."""
    sent = sdk_bytes(lambda ph, port: ph.writeTxOnly(port, 1, 116, 4, list(h("FF FF FD 01"))))
    assert sent[5] == 9 and h("FF FF FD 01") in sent  # not stuffed
    assert decode_packet2(sent) == InstructionPacket2(1, 0x03, h("74 00 FF FF FD 01"))
    assert encode_instruction2(1, 0x03, h("74 00 FF FF FD 01"))[5] == 10  # this encoder stuffs
    lossy = sdk_bytes(lambda ph, port: ph.writeTxOnly(port, 1, 116, 4, list(h("FF FF FD FD"))))
    assert decode_packet2(lossy).params == h("74 00 FF FF FD")


@pytest.mark.parametrize(
    ("raw", "stuffed"),
    [
        ("03 74 00 FF FF FD 01", "03 74 00 FF FF FD FD 01"),
        ("FF FF FD", "FF FF FD FD"),
        ("FF FF FD FD", "FF FF FD FD FD"),
        ("FF FF FF FD", "FF FF FF FD FD"),
        ("FF FF FD FF FF FD", "FF FF FD FD FF FF FD FD"),
        ("FF FD FF FD", "FF FD FF FD"),
        ("55 FF FF FD 00", "55 FF FF FD FD 00"),
    ],
)
def test_stuffing_cases(raw, stuffed):
    """Each FF FF FD of the unstuffed bytes gains one FD, and unstuff undoes exactly that."""
    assert stuff(h(raw)) == h(stuffed)
    assert unstuff(h(stuffed)) == h(raw)


@settings(max_examples=400, deadline=None)
@given(st.lists(st.sampled_from([0x00, 0x01, 0xFD, 0xFF]), max_size=40).map(bytes))
def test_stuffing_round_trip_and_no_header_inside(payload):
    """unstuff inverts stuff; a stuffed payload never holds a header (FF FF FD 00); the SDK stuffs the same."""
    stuffed = stuff(payload)
    assert unstuff(stuffed) == payload
    assert b"\xff\xff\xfd\x00" not in stuffed
    # addStuffing's own result (txPacket discards it; see above) matches ours.
    packet = [0xFF, 0xFF, 0xFD, 0x00, 1, (len(payload) + 3) & 0xFF, (len(payload) + 3) >> 8, 0x03, *payload, 0, 0]
    sdk_packet = sdk.Protocol2PacketHandler().addStuffing(packet)
    assert bytes(sdk_packet[8:-2]) == stuffed


@settings(max_examples=300, deadline=None)
@given(
    packet_id=st.integers(0, 0xFC) | st.just(0xFE),
    instruction=st.integers(0, 0xFF).filter(lambda i: i != 0x55),
    params=st.binary(max_size=60) | st.lists(st.sampled_from([0xFD, 0xFF, 0x00]), max_size=30).map(bytes),
)
def test_instruction_encode_decode_identity(packet_id, instruction, params):
    packet = InstructionPacket2(packet_id, instruction, params)
    assert decode_packet2(packet.encode()) == packet


@settings(max_examples=300, deadline=None)
@given(
    packet_id=st.integers(0, 0xFC),
    error=st.integers(0, 0xFF),
    params=st.binary(max_size=60) | st.lists(st.sampled_from([0xFD, 0xFF, 0x00]), max_size=30).map(bytes),
)
def test_status_encode_decode_identity(packet_id, error, params):
    packet = StatusPacket2(packet_id, error, params)
    assert decode_packet2(packet.encode()) == packet


@given(
    packet_id=st.integers(0, 0xFC),
    error=st.sampled_from([0, 0x80, 0x7F, 0xFE, 0xFF]) | st.integers(0, 0xFF),
    params=st.binary(max_size=12) | st.lists(st.sampled_from([0xFD, 0xFF, 0x00]), max_size=12).map(bytes),
)
def test_status_packets_carry_one_crc_over_every_byte_from_the_header(packet_id, error, params):
    """The encoder carries a remembered CRC of the bytes before the data over the data: the same CRC, over the
    stuffed bytes from the header on, as the e-manual's, computed whole (a second time, to check the first)."""
    from ax12emu.protocol.crc16 import crc16

    first = encode_status2(packet_id, error, params)
    assert encode_status2(packet_id, error, bytearray(params)) == first
    assert int.from_bytes(first[-2:], "little") == crc16(first[:-2])
    length = len(stuff(bytes((0x55, error)) + params)) + 2
    assert first[:7] == bytes((0xFF, 0xFF, 0xFD, 0x00, packet_id, length & 0xFF, length >> 8))


def test_error_byte():
    """Alert is bit 7, the error number bits 0..6 (e-manual, Status Packet > Error)."""
    assert status_error(4, alert=True) == 0x84
    packet = StatusPacket2(1, 0x84)
    assert packet.alert and packet.error_number == 4 and packet.error_number.name == "DATA_RANGE"
    assert StatusPacket2(1, 0x09).error_number == 9  # undefined numbers stay ints
    with pytest.raises(ValueError):
        status_error(128)


@pytest.mark.parametrize(
    ("wire", "reason"),
    [
        ("FF FF FD 00 01 03 00", "shorter"),
        ("FF FF FD FD 01 03 00 01 19 4E", "header"),
        ("FF FF FD 00 FD 03 00 01 19 4E", "never used"),
        ("FF FF FD 00 01 04 00 01 19 4E", "LENGTH 4"),
        ("FF FF FD 00 01 03 00 55 19 4E", "error byte"),
    ],
)
def test_decode_rejects_malformed_without_raising(wire, reason):
    result = decode_packet2(h(wire))
    assert isinstance(result, Malformed) and reason in result.reason


def test_bad_crc_keeps_id_and_raw_params():
    """A corrupt packet keeps its ID (for the CRC Error answer) and its bytes as received."""
    wire = bytearray(encode_instruction2(5, 0x03, h("74 00 FF FF FD 01")))
    wire[-1] ^= 0xFF
    assert decode_packet2(wire) == InstructionPacket2(5, 0x03, h("74 00 FF FF FD FD 01"), crc_ok=False)


def test_encoder_refuses_what_the_wire_cannot_carry():
    for bad_id in (0xFD, 0xFF, -1, 256):
        with pytest.raises(ValueError):
            encode_instruction2(bad_id, 0x01)
    with pytest.raises(ValueError):
        encode_status2(0xFE, 0)  # a servo never answers as broadcast; combined replies have their own encoder
    with pytest.raises(ValueError):
        encode_instruction2(1, 0x100)


EMANUAL_FAST_SYNC = h(
    "FF FF FD 00 FE 19 00 55 00 03 A6 00 00 00 84 08 00 07 1F 08 00 00 16 CA 00 04 FF 03 00 00 D1 9E"
)


def test_fast_status_matches_emanual_and_splits_per_servo():
    """The combined Fast Sync Read status of the e-manual, and where each servo's share starts."""
    parts = [FastStatusPart(3, 0, h("A6 00 00 00")), FastStatusPart(7, 0, h("1F 08 00 00")), FastStatusPart(4, 0, h("FF 03 00 00"))]
    assert encode_fast_status(parts) == EMANUAL_FAST_SYNC
    pieces = fast_status_pieces(parts)
    assert pieces[1] == h("00 07 1F 08 00 00 16 CA") and pieces[2] == h("00 04 FF 03 00 00 D1 9E")
    bulk = [FastStatusPart(3, 0, h("A6 00 00 00")), FastStatusPart(7, 0, h("A5 01")), FastStatusPart(4, 0, h("1F"))]
    assert encode_fast_status(bulk) == h("FF FF FD 00 FE 14 00 55 00 03 A6 00 00 00 67 A4 00 07 A5 01 24 74 00 04 1F D9 C1")


def test_fast_status_is_not_stuffed_and_decodes_unchanged():
    """Combined statuses are sent unstuffed, so decoding must not unstuff them (e-manual note)."""
    parts = [FastStatusPart(1, 0, h("FF FF FD FD")), FastStatusPart(2, 0, h("00 00 00 00"))]
    wire = encode_fast_status(parts)
    assert h("FF FF FD FD") in wire and wire[5] == 1 + 8 + 8
    decoded = decode_packet2(wire)
    assert isinstance(decoded, StatusPacket2) and decoded.crc_ok
    assert decoded.params[1:5] == h("FF FF FD FD")


def test_fast_status_read_by_dynamixel_sdk():
    """dynamixel-sdk's GroupSyncRead.fastSyncRead reads each servo's data out of the combined packet."""
    parts = [FastStatusPart(3, 0, h("A6 00 00 00")), FastStatusPart(7, 0, h("1F 08 00 00")), FastStatusPart(4, 0, h("FF 03 00 00"))]
    port = CapturePort(encode_fast_status(parts))
    reader = group_sync_read.GroupSyncRead(port, sdk.Protocol2PacketHandler(), 132, 4)
    for servo_id in (3, 7, 4):
        assert reader.addParam(servo_id)
    assert reader.fastSyncRead() == 0
    assert port.written == encode_instruction2(0xFE, 0x8A, h("84 00 04 00 03 07 04"))
    assert [reader.getData(i, 132, 4) for i in (3, 7, 4)] == [166, 2079, 1023]
