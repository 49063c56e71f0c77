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
    #: Of ``delay_s``, the time on the wire of the replies laid before this one (a bus that lays its
    #: replies one after another, ``in_sequence``); without pacing bytes take no time, so it is left out.
    wire_s: float = 0.0
    #: This is the next part of the previous reply's status packet (a servo's share of a Fast Sync/Bulk Read's
    #: one packet): lost, late or corrupt, the packet is, not the share.
    continues: bool = False


def merge_replies(replies: Sequence[Reply], start_s: float, *, per_byte: bool,
                  in_sequence: bool = False) -> list[tuple[float, bytes]]:
    """Lay replies on the wire as (release time, bytes) chunks; colliding byte slots are AND-ed.

    Each reply starts ``delay_s`` after ``start_s`` and takes one byte time
    (10 bits at its servo's baud) per byte.  Bytes of different replies that
    fall in the same byte slot are AND-ed, as on an open-drain TTL line.
    With ``per_byte`` each byte is released when its last bit has arrived
    (wire pacing); otherwise a single reply goes out whole at its due time.
    ``in_sequence``: the bus timed its replies one after another (Protocol 2.0's
    broadcast Ping slots, Sync Read's answers in list order), each ``delay_s``
    counting the wire time of those before it (``wire_s``).  With pacing that
    is the wire as it is: each reply's bytes follow the previous reply's.
    Without pacing, bytes take no time anywhere else (a lone reply goes out
    whole at its Return Delay Time), so the same holds here: each reply goes
    out whole at ``delay_s - wire_s``, which keeps the real bus's order and
    each servo's Return Delay Time after the reply before it, but no byte
    time (six Sync Read answers at Return Delay Time 0 go out together, in
    list order, rather than 150 us apart at 1 Mbps).
    """
    if in_sequence and not per_byte:
        chunks, at_s = [], start_s
        for reply in replies:
            # Never before the reply before it: ``delay_s - wire_s`` may round a hair below it.
            at_s = max(at_s, start_s + reply.delay_s - reply.wire_s)
            chunks.append((at_s, reply.data))
        return chunks
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
    return Reply(first.servo_id, data, at_s, first.baud_bps, first.wire_s)
