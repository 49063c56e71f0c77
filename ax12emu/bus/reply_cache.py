"""Replies to a repeated READ or PING, replayed while nothing they depend on has changed.

Why it exists: a client polling a register sends the same few bytes thousands
of times a second, and decoding, dispatching and encoding each one costs more
than the pty round trip itself (the serving loop's throughput goal: tools/bench_protocol.py).  The reply to a
READ or PING addressed to one ID depends only on the addressed servos'
control tables (the data read, ID, Status Return Level, Return Delay Time,
baud), their alarm bits and the host's line speed.  So each entry keeps the
table bytes and alarms it was computed from, and is replayed only while they
are unchanged.  Comparing snapshots, instead of trusting every writer to
announce itself, means a table changed by physics, a client, a fault or a
test in-process is never answered stale.

What is never cached: broadcast packets, packets with a bad checksum, other
instructions (they change state), a bus with faults installed (they act per
packet), and anything while debug logging is on (``-v`` logs every packet).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from ax12emu.protocol.packets import BROADCAST_ID, Instruction, InstructionPacket

if TYPE_CHECKING:
    from ax12emu.servo.virtual_servo import VirtualServo

    from .reply import Reply

__all__ = ["ReplyCache", "CACHEABLE"]

#: Instructions whose reply is a pure function of the addressed servos' state.
CACHEABLE = frozenset({Instruction.READ, Instruction.PING})
#: More distinct packets than a poller uses; past it the cache starts over.
MAX_ENTRIES = 256


class ReplyCache:
    """Packet bytes and line speed -> the replies they got, with the state those came from."""

    def __init__(self) -> None:
        #: (packet, line speed) -> (the servos reached, (servo, its table bytes, its alarms) each, replies).
        self._entries: dict[tuple[bytes, float | None], tuple[list, tuple, tuple[Reply, ...]]] = {}
        self.hits = 0

    def lookup(self, data: bytes, line_bps: float | None,
               by_id: dict[int, list[VirtualServo]]) -> tuple[Reply, ...] | None:
        """The replies stored for ``data`` if the servos it reached are unchanged; else None."""
        entry = self._entries.get((data, line_bps))
        if entry is None:
            return None
        targets, snapshot, replies = entry
        if by_id.get(data[2]) is not targets:  # an ID changed since: another set of servos answers
            return None
        for servo, row, alarms in snapshot:
            if servo.alarms != alarms or servo.table.row.tobytes() != row:
                return None
        self.hits += 1
        return replies

    def store(self, data: bytes, line_bps: float | None, packet: InstructionPacket,
              targets: list[VirtualServo] | None, replies: Sequence[Reply]) -> None:
        """Keep ``replies`` to ``data`` if it was exactly one cacheable packet to one ID."""
        if (targets is None or packet.id == BROADCAST_ID or not packet.checksum_ok or packet.instruction not in CACHEABLE
                or len(data) < 6 or len(data) != data[3] + 4 or data[:2] != b"\xff\xff"
                or data[2] != packet.id or data[4] != packet.instruction or data[5:-1] != packet.params):
            return  # not exactly this one packet: a chunk may have finished a partial one held before it
        if len(self._entries) >= MAX_ENTRIES:
            self._entries.clear()
        snapshot = tuple((servo, servo.table.row.tobytes(), servo.alarms) for servo in targets)
        self._entries[(bytes(data), line_bps)] = (targets, snapshot, tuple(replies))
