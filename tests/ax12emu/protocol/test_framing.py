"""The incremental framer: any chunking decodes the same, garbage never raises or grows the buffer."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ax12emu.protocol.framing import MAX_FRAME_BYTES, Framer
from ax12emu.protocol.packets import InstructionPacket, encode_instruction

PING = encode_instruction(1, 0x01)
READ = encode_instruction(1, 0x02, bytes([0x2B, 0x01]))


def test_emanual_examples_decode():
    """The e-manual's READ example FF FF 01 04 02 2B 01 CC decodes with a good checksum."""
    assert READ == bytes.fromhex("ffff010402 2b01cc".replace(" ", ""))
    assert Framer().feed(READ) == [InstructionPacket(1, 2, bytes([0x2B, 0x01]), True)]
    assert encode_instruction(1, 3, bytes([0x0C, 0x64, 0xAA])) == bytes.fromhex("ffff0105030c64aadc")


@pytest.mark.parametrize("split", range(1, len(READ)))
def test_any_split_point(split):
    """A packet split at any byte decodes once, after its last byte."""
    framer = Framer()
    assert framer.feed(READ[:split]) == []
    assert framer.feed(READ[split:]) == [InstructionPacket(1, 2, bytes([0x2B, 0x01]))]
    assert framer.buffered == 0


@pytest.mark.parametrize(
    "noise",
    [b"\x00\x13\x37", b"\xff", b"\xff\xff\xff\xff", b"\xff\x00\xff", b"\xff\xff\x01\x00", b"\xff\xff\x05\x01"],
)
def test_resync_after_noise(noise):
    """Garbage, repeated 0xFF and impossible lengths before a packet are skipped."""
    assert Framer().feed(noise + PING) == [InstructionPacket(1, 1, b"")]


def test_bad_checksum_is_reported_and_consumed():
    """A wrong checksum yields a packet marked bad; the next packet still decodes."""
    bad = PING[:-1] + bytes([PING[-1] ^ 0x01])
    packets = Framer().feed(bad + READ)
    assert packets[0] == InstructionPacket(1, 1, b"", False)
    assert packets[1].checksum_ok and packets[1].instruction == 2


def test_truncated_packet_dropped_after_silence():
    """A partial packet is dropped after the silence timeout, so the next packet is clean."""
    framer = Framer(silence_timeout_s=0.02)
    assert framer.feed(READ[:5], now_s=0.0) == []
    assert framer.feed(PING, now_s=0.1) == [InstructionPacket(1, 1, b"")]
    assert framer.dropped_partials == 1
    # Without the pause the partial packet swallows the next bytes into one corrupt frame, as on the servo.
    framer = Framer(silence_timeout_s=0.02)
    framer.feed(READ[:5], now_s=0.0)
    assert framer.feed(PING, now_s=0.001) == [InstructionPacket(1, 2, b"\xff\xff", False)]


def _stream():
    packet = st.builds(
        lambda i, ins, params: encode_instruction(i, ins, params),
        st.integers(0, 0xFE),
        st.integers(0, 0xFF),
        st.binary(max_size=40),
    )
    return st.lists(packet, min_size=1, max_size=8).map(b"".join)


@settings(max_examples=300, deadline=None)
@given(stream=_stream(), cuts=st.lists(st.integers(0, 400), max_size=20))
def test_random_chunkings_decode_identically(stream, cuts):
    """Feeding valid packets in random chunks gives exactly the packets of one whole feed."""
    whole = Framer().feed(stream)
    framer = Framer()
    pieces, last = [], 0
    for cut in sorted(set(c for c in cuts if c < len(stream))) + [len(stream)]:
        pieces.append(stream[last:cut])
        last = cut
    chunked = [p for piece in pieces for p in framer.feed(piece)]
    assert chunked == whole
    assert all(p.checksum_ok for p in whole)
    assert framer.buffered == 0


@settings(max_examples=300, deadline=None)
@given(chunks=st.lists(st.binary(max_size=300), max_size=30))
def test_random_bytes_never_raise_and_stay_bounded(chunks):
    """Random bytes in random chunks never raise; the buffer never exceeds one frame."""
    framer = Framer()
    for chunk in chunks:
        framer.feed(chunk, now_s=0.0)
        assert framer.buffered < MAX_FRAME_BYTES
    # A valid PING after any garbage is decoded once the silence timeout has passed.
    assert framer.feed(PING, now_s=10.0)[-1] == InstructionPacket(1, 1, b"")
