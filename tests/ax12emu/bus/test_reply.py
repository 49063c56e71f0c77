"""merge_replies: how several replies share the wire (reply.py)."""

from __future__ import annotations

from ax12emu.bus.reply import BITS_PER_BYTE, Reply, merge_replies

BAUD = 1_000_000
BYTE_S = BITS_PER_BYTE / BAUD


def test_replies_in_sequence_that_overlap_collide():
    """Two answers at one time (two servos, one ID) are AND-ed even where the bus lays replies in sequence."""
    a, b = bytes([0xFF, 0x0F, 0x33]), bytes([0xFF, 0xF0, 0x31])
    chunks = merge_replies([Reply(1, a, 0.0001, BAUD), Reply(1, b, 0.0001, BAUD)], 1.0, per_byte=False, in_sequence=True)
    assert chunks == [(1.0001, bytes([0xFF, 0x00, 0x31]))]


def test_replies_back_to_back_go_out_whole_each_at_its_time():
    a, b, c = b"\x01\x02\x03", b"\x04\x05", b"\x06"
    start_b = 0.0001 + len(a) * BYTE_S  # right after a, Return Delay Time 0
    replies = [Reply(1, a, 0.0001, BAUD), Reply(2, b, start_b, BAUD), Reply(3, c, start_b + len(b) * BYTE_S + 0.0002, BAUD)]
    chunks = merge_replies(replies, 0.0, per_byte=False, in_sequence=True)
    assert [data for _, data in chunks] == [a, b, c]
    assert [t for t, _ in chunks] == [r.delay_s for r in replies]


def test_a_reply_starting_inside_another_collides_from_its_first_byte():
    a, b = bytes([0xFF] * 4), bytes([0x0F, 0xF0])
    chunks = merge_replies([Reply(1, a, 0.0, BAUD), Reply(2, b, 2 * BYTE_S, BAUD)], 0.0, per_byte=False, in_sequence=True)
    assert chunks == [(0.0, bytes([0xFF, 0xFF, 0x0F, 0xF0]))]
