"""The Protocol 2.0 framer: any chunking decodes the same, every resync case, and a bus mixing 1.0 and 2.0."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from protocol2_vectors import EMANUAL_ERRATA, EMANUAL_PACKETS

from ax12emu.protocol.framing import Framer
from ax12emu.protocol.framing2 import DEFAULT_MAX_LENGTH, Framer2
from ax12emu.protocol.packets import InstructionPacket, encode_instruction, encode_status
from ax12emu.protocol.packets2 import (
    FastStatusPart,
    InstructionPacket2,
    Malformed,
    StatusPacket2,
    decode_packet2,
    encode_fast_status,
    encode_instruction2,
    encode_status2,
)


def h(text: str) -> bytes:
    return bytes.fromhex(text)


PING = encode_instruction2(1, 0x01)
WRITE_STUFFED = encode_instruction2(1, 0x03, h("74 00 FF FF FD 00"))
STATUS = encode_status2(1, 0, h("06 04 26"))
FAST = encode_fast_status([FastStatusPart(3, 0, h("A6 00 00 00")), FastStatusPart(7, 0, h("1F 08 00 00"))])
#: Instruction, stuffed instruction, status and combined status: every kind a servo hears.
SAMPLES = [PING, WRITE_STUFFED, STATUS, FAST]
EXPECTED = [
    InstructionPacket2(1, 0x01),
    InstructionPacket2(1, 0x03, h("74 00 FF FF FD 00")),
    StatusPacket2(1, 0, h("06 04 26")),
    StatusPacket2(0xFE, 0, h("03 A6 00 00 00") + FAST[14:16] + h("00 07 1F 08 00 00")),
]


def test_each_kind_decodes():
    assert [Framer2().feed(wire) for wire in SAMPLES] == [[p] for p in EXPECTED]
    assert Framer2().feed(b"".join(SAMPLES)) == EXPECTED


@pytest.mark.parametrize("index", range(len(SAMPLES)))
def test_every_split_point(index):
    """Each packet split at every byte decodes once, after its last byte, leaving nothing buffered."""
    wire = SAMPLES[index]
    for split in range(1, len(wire)):
        framer = Framer2()
        assert framer.feed(wire[:split]) == [], split
        assert framer.feed(wire[split:]) == [EXPECTED[index]], split
        assert framer.buffered == 0 and framer.discarded_bytes == 0


#: Every packet the e-manual prints, and the two with misprinted CRCs as printed (their CRC fails).
EMANUAL_WIRES = [h(text) for text in EMANUAL_PACKETS.values()] + [
    h(text) + printed.to_bytes(2, "little") for text, printed, _ in EMANUAL_ERRATA.values()
]


@pytest.mark.parametrize("wire", EMANUAL_WIRES, ids=[*EMANUAL_PACKETS, *EMANUAL_ERRATA])
def test_emanual_packets_in_every_split(wire):
    """Each e-manual packet split at every byte frames once, the same as decoding it whole."""
    whole = decode_packet2(wire)
    assert not isinstance(whole, Malformed)
    for split in range(len(wire) + 1):
        framer = Framer2()
        assert framer.feed(wire[:split]) + framer.feed(wire[split:]) == [whole], split
        assert framer.buffered == 0


def test_emanual_packets_back_to_back():
    """All the e-manual's packets in one stream: each comes out, the misprinted two marked bad."""
    packets = Framer2().feed(b"".join(EMANUAL_WIRES))
    assert packets == [decode_packet2(wire) for wire in EMANUAL_WIRES]
    assert [p.crc_ok for p in packets].count(False) == len(EMANUAL_ERRATA)


def test_the_same_whole_frames_again_are_the_same_packets():
    """Whole frames fed at once (a robot's Sync Write and Sync Read read together), again and again: the same
    packets each time, a corrupt copy reported as corrupt, a part frame still buffered."""
    stream = b"".join(SAMPLES)
    framer = Framer2()
    assert framer.feed(stream) == EXPECTED
    assert framer.feed(stream) == EXPECTED
    corrupt = bytearray(stream)
    corrupt[-1] ^= 0xFF
    assert [p.crc_ok for p in framer.feed(bytes(corrupt))] == [True, True, True, False]
    assert framer.feed(stream[:-3]) == EXPECTED[:-1] and framer.buffered == len(SAMPLES[-1]) - 3
    assert framer.feed(stream[-3:]) == EXPECTED[-1:] and framer.buffered == 0
    assert framer.feed(stream) == EXPECTED


def test_byte_by_byte():
    framer = Framer2()
    out = [p for byte in b"".join(SAMPLES) for p in framer.feed(bytes((byte,)))]
    assert out == EXPECTED


@pytest.mark.parametrize(
    "noise",
    [
        h("00 13 37"),
        h("FF"),
        h("FF FF"),
        h("FF FF FD"),
        h("FF FF FF FF FF"),  # repeated header bytes
        h("FF FF FD FD 01 03 00"),  # stuffing, not a header
        h("FF FF FD 01"),  # reserved byte not 0x00
        h("FF FF FD 00 FD 03 00 01"),  # ID 0xFD is never used
        h("FF FF FD 00 FF 03 00 01"),  # nor 0xFF
        h("FF FF FD 00 01 02 00 01"),  # LENGTH below INST + CRC
        h("FF FF FD 00 01 03 00 55"),  # a status without its error byte
        h("FF FF FD 00 01 01 04 02"),  # LENGTH 1025, above the limit
        h("FF FF FD 00 01 00 00"),
    ],
)
def test_resync_after_noise(noise):
    """Garbage, repeated FF, stuffing, bad reserved byte, unused IDs and impossible lengths are skipped."""
    framer = Framer2()
    assert framer.feed(noise + PING) == [InstructionPacket2(1, 0x01)]
    assert framer.buffered == 0
    assert framer.discarded_bytes == len(noise)


def test_header_prefix_kept_across_feeds():
    """A tail that may start a header waits for the next chunk; a tail that cannot is dropped at once."""
    framer = Framer2()
    assert framer.feed(h("00 01 FF FF FD")) == [] and framer.buffered == 3
    assert framer.feed(PING[3:]) == [InstructionPacket2(1, 0x01)]
    framer = Framer2()
    framer.feed(h("12 34 56"))
    assert framer.buffered == 0


def test_bad_crc_is_reported_consumed_and_left_stuffed():
    """A wrong CRC consumes LENGTH bytes and is reported for the CRC Error answer; the next packet decodes."""
    bad = bytearray(WRITE_STUFFED)
    bad[-1] ^= 0x01
    packets = Framer2().feed(bytes(bad) + PING)
    assert packets == [InstructionPacket2(1, 0x03, h("74 00 FF FF FD FD 00"), False), InstructionPacket2(1, 0x01)]


def test_bad_crc_on_a_status_is_a_status():
    bad = bytearray(STATUS)
    bad[9] ^= 0x01
    assert Framer2().feed(bytes(bad)) == [StatusPacket2(1, 0, h("07 04 26"), False)]


def test_truncated_packet_dropped_after_silence():
    """A partial packet is dropped after the silence timeout; without a pause it swallows the next bytes."""
    framer = Framer2(silence_timeout_s=0.0015)
    assert framer.feed(WRITE_STUFFED[:9], now_s=0.0) == []
    assert framer.feed(PING, now_s=0.002) == [InstructionPacket2(1, 0x01)]
    assert framer.dropped_partials == 1
    framer = Framer2(silence_timeout_s=0.0015)
    framer.feed(WRITE_STUFFED[:9], now_s=0.0)
    swallowed = framer.feed(PING, now_s=0.001)
    assert len(swallowed) == 1 and not swallowed[0].crc_ok
    assert framer.buffered == 0  # the PING's last two bytes cannot start a header: dropped at once


def test_max_length_bounds_a_frame():
    """A LENGTH over max_length is noise; at max_length it is accepted."""
    framer = Framer2(max_length=10)
    long_write = encode_instruction2(1, 0x03, bytes(8))  # LENGTH 11
    assert framer.feed(long_write + PING) == [InstructionPacket2(1, 0x01)]
    assert Framer2(max_length=11).feed(long_write) == [InstructionPacket2(1, 0x03, bytes(8))]
    with pytest.raises(ValueError):
        Framer2(max_length=2)
    with pytest.raises(ValueError):
        Framer2(silence_timeout_s=0)


def _stream():
    instruction = st.builds(
        encode_instruction2,
        st.integers(0, 0xFC) | st.just(0xFE),
        st.integers(0, 0xFF).filter(lambda i: i != 0x55),
        st.binary(max_size=30) | st.lists(st.sampled_from([0x00, 0xFD, 0xFF]), max_size=20).map(bytes),
    )
    status = st.builds(
        encode_status2,
        st.integers(0, 0xFC),
        st.integers(0, 0xFF),
        st.binary(max_size=30) | st.lists(st.sampled_from([0x00, 0xFD, 0xFF]), max_size=20).map(bytes),
    )
    return st.lists(instruction | status, min_size=1, max_size=8)


@settings(max_examples=300, deadline=None)
@given(packets=_stream(), cuts=st.lists(st.integers(0, 600), max_size=20))
def test_encode_frame_decode_identity_in_any_chunking(packets, cuts):
    """Encoded packets fed in random chunks come out as the packets they were built from, in order."""
    stream = b"".join(packets)
    framer = Framer2()
    out, last = [], 0
    for cut in sorted(set(c for c in cuts if c < len(stream))) + [len(stream)]:
        out += framer.feed(stream[last:cut])
        last = cut
    assert [p.encode() for p in out] == packets
    assert all(p.crc_ok for p in out) and framer.buffered == 0 and framer.discarded_bytes == 0


@settings(max_examples=300, deadline=None)
@given(
    chunks=st.lists(
        st.binary(max_size=200) | st.lists(st.sampled_from([0x00, 0x01, 0x03, 0xFD, 0xFF]), max_size=60).map(bytes),
        max_size=30,
    )
)
def test_random_bytes_never_raise_and_stay_bounded(chunks):
    """Random bytes never raise; the buffer never holds more than one maximal frame plus the chunk just fed."""
    framer = Framer2()
    for chunk in chunks:
        framer.feed(chunk, now_s=0.0)
        assert framer.buffered <= 7 + DEFAULT_MAX_LENGTH + len(chunk)
    assert framer.feed(PING, now_s=10.0)[-1] == InstructionPacket2(1, 0x01)


# A bus with Protocol 1.0 and 2.0 servos: each servo's framer hears the other protocol's packets.


def test_protocol1_framer_discards_protocol2_packets():
    """FF FF FD 00 is a 1.0 header for ID 0xFD with LENGTH 0, impossible: a 2.0 packet without FF FF
    in its body yields nothing and leaves nothing buffered."""
    framer = Framer()
    stream = PING + STATUS + encode_instruction2(0xFE, 0x83, h("74 00 04 00 01 96 00 00 00"))
    assert framer.feed(stream) == [] and framer.buffered == 0
    assert framer.feed(encode_instruction(1, 0x01)) == [InstructionPacket(1, 0x01, b"")]


def test_stuffed_protocol2_packet_holds_a_protocol1_servo_until_silence():
    """Every stuffed 2.0 packet contains FF FF FD FD: to a 1.0 servo, a header for ID 0xFD with LENGTH 253.
    It waits for 253 more bytes and swallows the 1.0 packets that follow without a pause; after its
    silence timeout it hears them again."""
    framer = Framer(silence_timeout_s=0.02)
    assert framer.feed(WRITE_STUFFED, now_s=0.0) == [] and framer.buffered > 0
    assert framer.feed(encode_instruction(1, 0x01), now_s=0.001) == []
    assert framer.feed(encode_instruction(1, 0x01), now_s=0.05) == [InstructionPacket(1, 0x01, b"")]
    assert framer.dropped_partials == 1


def test_protocol2_framer_discards_protocol1_packets():
    """A 1.0 LENGTH (never 0) sits where the 2.0 reserved byte must be 0, even for 1.0 ID 0xFD."""
    framer = Framer2()
    stream = b"".join(
        [
            encode_instruction(1, 0x01),
            encode_instruction(0xFD, 0x03, h("1E 00 02")),  # FF FF FD 05 ...
            encode_status(0xFD, 0, h("00 02")),
            encode_instruction(0xFE, 0x83, h("1E 02 01 00 02 02 00 02")),
        ]
    )
    assert framer.feed(stream) == []
    assert framer.feed(PING) == [InstructionPacket2(1, 0x01)]


def test_packet_of_one_protocol_inside_the_other_is_heard():
    """Neither protocol protects the other: a 2.0 WRITE whose data carry a whole 1.0 packet is, to a 1.0 servo,
    that 1.0 packet (2.0 stuffing only guards FF FF FD), and a 1.0 packet can carry a 2.0 one likewise."""
    inner1 = encode_instruction(1, 0x03, h("1E 00 02"))
    outer2 = encode_instruction2(2, 0x03, h("40 00") + inner1)
    assert Framer2().feed(outer2) == [InstructionPacket2(2, 0x03, h("40 00") + inner1)]
    assert Framer().feed(outer2) == [InstructionPacket(1, 0x03, h("1E 00 02"))]
    inner2 = encode_instruction2(1, 0x01)
    outer1 = encode_instruction(2, 0x03, h("06") + inner2)
    assert Framer().feed(outer1) == [InstructionPacket(2, 0x03, h("06") + inner2)]
    assert Framer2().feed(outer1) == [InstructionPacket2(1, 0x01)]


@settings(max_examples=200, deadline=None)
@given(
    first=st.lists(st.booleans(), min_size=1, max_size=10),
    ids=st.lists(st.integers(0, 0xFC), min_size=10, max_size=10),
)
def test_mixed_bus_each_framer_finds_its_own(first, ids):
    """Interleaved 1.0 and 2.0 PINGs: each framer yields exactly its own protocol's packets, in order."""
    stream, own1, own2 = b"", [], []
    for use1, servo_id in zip(first, ids):
        if use1:
            stream += encode_instruction(servo_id, 0x01)
            own1.append(InstructionPacket(servo_id, 0x01, b""))
        else:
            stream += encode_instruction2(servo_id, 0x01)
            own2.append(InstructionPacket2(servo_id, 0x01))
    assert Framer().feed(stream) == own1
    assert Framer2().feed(stream) == own2
