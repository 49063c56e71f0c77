"""A servo's reply on the wire, and how several replies share it.

Why a leaf module: the bus makes replies, the fault filter bends them, the
reply cache keeps them, the serving loop and the in-process link lay them on
the wire.  Each of those imports this module and none of them imports the
others for it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

__all__ = ["BITS_PER_BYTE", "Reply", "collide", "merge_replies"]

#: Bits per byte on the wire: start + 8 data + stop (8N1, e-manual).
BITS_PER_BYTE = 10


class Reply(NamedTuple):
    """A status packet to put on the line ``delay_s`` after the instruction ended."""

    servo_id: int
    data: bytes
    delay_s: float
    #: The replying servo's bit rate, for pacing and collision timing.
    baud_bps: float


def merge_replies(replies: Sequence[Reply], start_s: float, *, per_byte: bool,
                  in_sequence: bool = False) -> list[tuple[float, bytes]]:
    """Lay replies on the wire as (release time, bytes) chunks; colliding byte slots are AND-ed.

    Each reply starts ``delay_s`` after ``start_s`` and takes one byte time
    (10 bits at its servo's baud) per byte.  Bytes of different replies that
    fall in the same byte slot are AND-ed, as on an open-drain TTL line.
    With ``per_byte`` each byte is released when its last bit has arrived
    (wire pacing); otherwise a single reply goes out whole at its due time.
    ``in_sequence``: the bus timed its replies one after another (Protocol 2.0's
    broadcast Ping slots, Sync Read's answers in list order); without pacing
    each then goes out whole at its own due time instead of all at the first's.
    """
    if in_sequence and not per_byte:
        return [(start_s + reply.delay_s, reply.data) for reply in replies]
    if len(replies) == 1 and not per_byte:
        reply = replies[0]
        return [(start_s + reply.delay_s, reply.data)]
    byte_s = BITS_PER_BYTE / replies[0].baud_bps
    slots: dict[int, int] = {}
    for reply in replies:
        first_slot = round(reply.delay_s / byte_s)
        for i, value in enumerate(reply.data):
            slots[first_slot + i] = slots.get(first_slot + i, 0xFF) & value
    ordered = sorted(slots)
    if per_byte:
        return [(start_s + (slot + 1) * byte_s, bytes((slots[slot],))) for slot in ordered]
    return [(start_s + ordered[0] * byte_s, bytes(slots[slot] for slot in ordered))]


def collide(replies: Sequence[Reply]) -> Reply:
    """Replies sent at once (two servos answering one ID) as the one the wire carries: overlapping bytes AND-ed.

    For a bus that lays its replies one after another (``in_sequence``): it collides those it
    times together itself, so the serving loop's sequence stays untouched.
    """
    first = min(replies, key=lambda reply: reply.delay_s)
    [(at_s, data)] = merge_replies(replies, 0.0, per_byte=False)
    return Reply(first.servo_id, data, at_s, first.baud_bps)
