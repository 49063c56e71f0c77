"""collide: replies sent at once, as the wire carries them (reply.py)."""

from __future__ import annotations

from ax12emu.bus.reply import BITS_PER_BYTE, Reply, collide

BAUD = 1_000_000
BYTE_S = BITS_PER_BYTE / BAUD


def test_replies_at_one_time_are_anded_byte_by_byte():
    a, b = bytes([0xFF, 0x0F, 0x33]), bytes([0xFF, 0xF0, 0x31])
    assert collide([Reply(1, a, 0.0001, BAUD), Reply(1, b, 0.0001, BAUD)]) == Reply(1, bytes([0xFF, 0x00, 0x31]), 0.0001, BAUD)


def test_equal_replies_collide_into_themselves():
    a = bytes([0xFF, 0xFF, 0xFD, 0x00, 0x01])
    assert collide([Reply(1, a, 0.0002, BAUD)] * 2).data == a


def test_a_later_reply_collides_from_its_first_byte():
    a, b = bytes([0xFF] * 4), bytes([0x0F, 0xF0])
    reply = collide([Reply(2, b, 2 * BYTE_S, BAUD), Reply(1, a, 0.0, BAUD)])
    assert (reply.servo_id, reply.data, reply.delay_s) == (1, bytes([0xFF, 0xFF, 0x0F, 0xF0]), 0.0)
