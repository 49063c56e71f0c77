"""A wire of both protocols, decoded with protocol="both": random streams of whole packets, every one comes out.

Why: on a mixed wire both framers hunt through every byte, and a 2.0 packet's data may hold ``FF FF``, the start of a
1.0 frame that ends on a checksum that fails.  Such a frame must not claim the 2.0 packet's bytes (a Sync Write of
Goal Velocity -10/+10 disappeared), nor may any frame left over from one packet swallow the packets after it (a
stale partial frame once swallowed later 1.0 packets in 25 of 3,000 random streams).  What cannot be told apart is
left out: a packet whose bytes hold a whole *valid* packet of the other protocol (a servo of that protocol executes
it too, see ``framing2.py``).
"""

from __future__ import annotations

import random

import pytest

from ax12emu.protocol.framing import Framer
from ax12emu.protocol.framing2 import Framer2
from ax12emu.protocol.packets import encode_instruction, encode_status
from ax12emu.protocol.packets2 import encode_instruction2, encode_status2
from ax12emu.tracing.decoder import GARBAGE, decode
from ax12emu.tracing.trace import IN, Chunk

#: Streams per seed and seeds: 3,000 streams in all.
STREAMS, SEEDS = 150, 20


def _data(rng: random.Random, most: int) -> bytes:
    """Bytes that often hold FF, FD and 00 (the headers' bytes), as negative values and stuffed data do."""
    return bytes(rng.choice((0xFF, 0xFF, 0xFD, 0x00, rng.randrange(256))) for _ in range(rng.randint(0, most)))


def _packet(rng: random.Random) -> bytes:
    kind = rng.randrange(4)
    if kind == 0:
        return encode_instruction(rng.randint(0, 253), rng.choice((1, 2, 3, 0x83)), _data(rng, 12))
    if kind == 1:
        return encode_status(rng.randint(0, 253), rng.randrange(0x80), _data(rng, 8))
    if kind == 2:
        return encode_instruction2(rng.randint(0, 252), rng.choice((1, 2, 3, 0x83)), bytes([rng.randrange(256), 0]) + _data(rng, 14))
    return encode_status2(rng.randint(0, 252), rng.randrange(0x80), _data(rng, 8))


def _holds_other_protocols_packet(packet: bytes) -> bool:
    """Whether a whole valid packet of the other protocol lies in ``packet``'s bytes (both servos would take it)."""
    other = Framer() if packet.startswith(b"\xff\xff\xfd\x00") else Framer2()
    found = other.feed(packet)
    return any(getattr(p, "checksum_ok", getattr(p, "crc_ok", False)) for p in found)


def _stream(rng: random.Random) -> list[bytes]:
    packets = []
    while len(packets) < rng.randint(2, 6):
        packet = _packet(rng)
        if _holds_other_protocols_packet(packet):
            continue
        if rng.random() < 0.25:  # corrupt: the checksum or CRC byte is wrong, the frame's length intact
            packet = packet[:-1] + bytes([packet[-1] ^ rng.randint(1, 255)])
        packets.append(packet)
    return packets


@pytest.mark.parametrize("seed", range(SEEDS))
def test_every_packet_of_a_random_mixed_stream_decodes(seed):
    rng = random.Random(seed)
    for _ in range(STREAMS):
        packets = _stream(rng)
        wire = b"".join(packets)
        # One chunk (a raw capture), or cut anywhere (a trace's reads), or packet by packet with times.
        cuts = sorted(rng.sample(range(1, len(wire)), rng.randint(0, min(4, len(wire) - 1))))
        pieces = [wire[a:b] for a, b in zip([0, *cuts], [*cuts, len(wire)])]
        for chunks in ([Chunk(None, None, wire)], [Chunk(None, None, p) for p in pieces],
                       [Chunk(0.001 * i, IN, p) for i, p in enumerate(packets)]):
            decoded = decode(chunks, protocol="both")
            shown = [d.raw for d in decoded if d.kind != GARBAGE]
            assert shown == packets, (seed, [p.hex(" ") for p in packets], [d.text for d in decoded])


def test_a_sync_write_of_negative_velocities_is_one_packet():
    """The data FF FF ... of -10 starts a 1.0 frame inside the 2.0 packet; its checksum fails, and it claims nothing."""
    params = bytes([104, 0, 4, 0, 1]) + (-10 & 0xFFFFFFFF).to_bytes(4, "little") + bytes([2]) + (10).to_bytes(4, "little")
    packet = encode_instruction2(254, 0x83, params)
    for protocol in ("both", "2.0"):
        (item,) = decode([Chunk(0.0, IN, packet)], protocol=protocol, servos="1-2:xl430-w250")
        assert item.text.startswith("SYNC_WRITE id=254")
        assert "[id=1 goal_velocity=-10 (4 bytes)] [id=2 goal_velocity=10 (4 bytes)]" in item.text


def test_protocol_2_0_alone_frames_no_1_0_packet():
    one = encode_instruction(1, 1)
    two = encode_instruction2(1, 1)
    assert [d.raw for d in decode([Chunk(None, None, one + two)], protocol="2.0") if d.kind != GARBAGE] == [two]


def test_auto_takes_2_0_for_a_trace_of_2_0_servos_only():
    """decode()'s auto choice: 2.0 alone for a trace whose header names 2.0 servos only (a raw capture's --servo
    names what one wants named, so it stays on both); both beside a 1.0 servo."""
    one = encode_instruction(1, 1)
    trace = [Chunk(0.0, IN, one)]
    assert [d.kind for d in decode(trace, servos="1:xl430-w250")] == [GARBAGE]
    assert decode(trace, servos="1:xl430-w250,2:ax-12a")[0].text == "PING id=1"
    assert decode([Chunk(None, None, one)], servos="1:xl430-w250")[0].text == "PING id=1"
