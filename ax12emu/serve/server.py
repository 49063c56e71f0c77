"""The real-time serving loop: one thread, select on the transport, timed replies.

Why it exists: a client such as dynamixel-sdk busy-waits on a core for its
reply with a ~34 ms timeout, so the emulator must react to input at once (no
sleeps in the serving path) and put each status packet on the line exactly
Return Delay Time after the instruction ended.  It sleeps in ``select`` until
the next event (input, a reply falling due, a physics tick) and spins only
while a host is mid-conversation (a fraction of a millisecond after each
instruction and each reply) and before a reply falls due, where a timeout
would be too coarse.  The 1 kHz physics step runs on the loop's tick, which
lands when the model's next step falls due, in pieces (step, sensors,
tables: ``Bus.advance_in_pieces``), and while a host polls, each piece just
after a packet was answered: the host is then busy with the reply, so the
step costs it almost nothing.  The step a Protocol 2.0 client's write earns
(``Bus2.settle_in_pieces``) is taken in the pass right after the packet
that wrote, rather than when the next packet arrives; while such a bus holds
a robot's Sync Write for the next step (``Bus2.parked``), settling waits and
the tick is taken whole, hot or not, since the host's next read needs the
step.  Such a robot cycles faster than 1 kHz and leaves the loop one short
pause after each reply (about 75 us), too short for the whole step; so the
step is split over the two pauses before it falls due: the held goals taken
in the first (``Bus2.take_parked_early``), the step and the next answer in
the second, up to 0.15 ms early (``Bus2.advance_in_pieces``).

The wire, as it is modelled here:

* replies are released ``delay`` after the instruction's last byte arrived;
* ``pace``: bytes take 10 bit-times each (start, 8 data, stop) at the servo's
  baud, both the host's instruction and the reply, so throughput is the
  wire's; host bytes arriving while a reply is still on the wire collide and
  both come out garbled (wired-AND: each bit is the AND of both drivers);
* replies of several servos to one packet (broadcast PING, duplicate IDs)
  that overlap in time are merged the same way, slot by slot;
* ``echo``: the adapter reads back its own transmission, so the host sees its
  instruction bytes before the status packet.
"""

from __future__ import annotations

import bisect
import collections
import logging
import math
import os
import select
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FuturesTimeout
from typing import Any

from ax12emu.bus import BITS_PER_BYTE, Bus, Reply, merge_replies
from ax12emu.bus.clock import WallClock
from ax12emu.protocol.crc16 import crc16
from ax12emu.protocol.packets import checksum
from ax12emu.tracing.trace import IN, OUT, TraceWriter

from .transports.base import Transport

__all__ = ["BusServer", "ServerStopped"]

log = logging.getLogger(__name__)

#: Below this much time to the next reply, busy-wait instead of sleeping in select.
SPIN_S = 0.0003
#: Below this much time to the next release, wait for it on the clock alone (no system call).
EXACT_S = 0.00002
#: At most this many reads of pending input before a call runs (see ``BusServer._read_pending``).
READS_BEFORE_CALLS = 4
#: After input or a reply, keep polling without sleeping this long: the host's next packet usually
#: follows within a few tens of microseconds, and waking from a sleep costs about as much.
HOT_S = 0.0002
#: A physics step is put off while a reply is due sooner than this (a step of many servos takes
#: ~0.1 ms), so it cannot delay the reply; a longer Return Delay Time hides the step inside it.
PHYSICS_DEFER_S = 0.0003
#: How early a physics step is taken right after a reply while a robot cycles with its Sync Writes held
#: (``Bus2.parked``): about one host cycle (a Sync Read and Sync Write of six servos take ~0.12 ms), so the
#: step lands in the time the host spends on the reply rather than on its next packet.
EARLY_STEP_S = 0.00015
#: What ``next`` returns from a finished physics step.
_DONE = object()
#: Where a status packet's error field is, by whether it is a Protocol 2.0 one (header FF FF FD 00, then ID,
#: length, 0x55, Error; Protocol 1.0: FF FF, ID, length, Error; a 1.0 packet's length byte is never 0).
_ERROR_AT = (4, 8)


def _intact(replies: Sequence[Reply], k: int, two: bool) -> bool:
    """Whether the status packet ``replies[k]`` begins has the checksum (1.0) or CRC (2.0) it was built with: one the
    fault injection corrupted (or twin servos garbled) reaches the host as a checksum error, not a status error.
    Asked only of a packet with error bits, so the common reply costs nothing more."""
    if not two:
        data = replies[k].data
        return checksum(data[2:-1]) == data[-1]
    shares = [replies[k].data]  # a Fast Sync Read's packet: its CRC ends the last share
    for reply in replies[k + 1 :]:
        if not reply.continues:
            break
        shares.append(reply.data)
    packet = b"".join(shares)
    return crc16(packet[:-2]) == int.from_bytes(packet[-2:], "little")


class ServerStopped(RuntimeError):
    """A call that the serving loop will never run: it stopped first (its bus is being closed)."""


class BusServer:
    """Serves ``bus`` over ``transport`` until :meth:`stop`."""

    def __init__(
        self,
        bus: Bus,
        transport: Transport,
        *,
        pace: bool = False,
        echo: bool = False,
        physics_period_s: float = 1e-3,
        trace: TraceWriter | None = None,
    ) -> None:
        self.bus = bus
        if isinstance(bus.clock, WallClock):  # read at every tick from here on: a catch-up past the model's speed slips
            bus.clock.bound_strides()
        #: Records every byte in and out; None (the default) costs one test per chunk.
        self.trace = trace
        #: The trace file itself (``trace`` may be wrapped later, by the live view's tap): it records the echo
        #: setting in its header and, paced, each instruction's wire end.
        self._trace_file = trace if isinstance(trace, TraceWriter) else None
        if self._trace_file is not None:
            self._trace_file.note(echo=echo)
        #: Functions to run on the serving thread (see :meth:`call`).
        self._calls: collections.deque[tuple[Callable[[Bus], Any], Future]] = collections.deque()
        self.transport = transport
        self.pace = pace
        self.echo = echo
        self.physics_period_s = physics_period_s
        #: Simulated seconds per wall second when the bus follows the wall clock; None in virtual time.
        self._time_scale: float | None = getattr(bus.clock, "time_scale", None)
        # The loop steps physics between packets, so a request may find it up to one
        # period behind, as the AX-12's own registers are (its control loop runs every 1 ms).
        # Faster than real time, a tick takes several steps, and a request between ticks pays
        # for the steps past that: the registers stay about one step old in simulated time.
        bus.request_lag_s = physics_period_s
        self._queue: list[list] = []  # [release_s, seq, data, is_reply], sorted
        self._seq = 0
        self._stop = False
        #: The loop has ended: a call queued now would never run (see :meth:`call`).
        self._stopped = False
        self._rx_busy_until = 0.0
        self._hot_until = 0.0
        #: Whether the pass under way put a status packet on the line.
        self._replied = False
        #: The due time of the physics step whose held goals were taken early (``Bus2.take_parked_early``).
        self._taken_early_for: float | None = None
        self._connections = getattr(transport, "connections", None)
        self._yield_after_reply = getattr(transport, "yield_after_reply", False) and hasattr(os, "sched_yield")
        #: Tells the transport nothing more is owed to its host (a TCP client that half-closed can go); None: not asked.
        self._replies_sent: Callable[[], None] | None = getattr(transport, "replies_sent", None)
        #: The bus times several replies to one packet one after another (see ``merge_replies``).
        self._in_sequence = bus.replies_in_sequence
        #: Whether the clock is fine enough to wait on for a few microseconds (not Windows before 3.13).
        self._exact_clock = time.get_clock_info("monotonic").resolution <= 1e-6
        self._next_physics = time.monotonic()
        # Linux only: elsewhere poll() may not take a pty's descriptor (macOS returns POLLNVAL).
        self._poller = select.poll() if sys.platform.startswith("linux") else None
        self._polled_fds: list[int] = []
        #: The physics step under way, in pieces (Bus.advance_in_pieces), or None.
        self._physics: Iterator[None] | None = None
        #: The steps a bus's servos owe after a packet, in pieces (``Bus2.settle_in_pieces``), if it has them.
        self._settle: Callable[[], Iterator[None]] | None = getattr(bus, "settle_in_pieces", None)
        #: A packet was handled since the last settling began (only with ``_settle``).
        self._unsettled = False
        if self._settle is not None and hasattr(bus, "defer_settling"):
            # This loop settles right after each packet, so a read may leave for then what its reply cannot show.
            bus.defer_settling = True
        #: Whether the bus holds a packet for the next one or the next physics step (``Bus2.parked``).
        self._bus_parked: Callable[[], bool] = (lambda: bus.parked) if hasattr(bus, "parked") else (lambda: False)
        #: Takes what a reply went out before (``Bus2.take_deferred``), before a call sees the bus; None: nothing to take.
        self._take_deferred: Callable[[], None] | None = getattr(bus, "take_deferred", None)
        #: Tells the bus a call may have changed its servos (``Bus2.changed_outside``); None: nothing to tell.
        self._changed_outside: Callable[[], None] | None = getattr(bus, "changed_outside", None)
        #: Counters for diagnostics and tests.
        self.packets_in = 0
        self.bytes_dropped = 0
        self.collisions = 0
        #: Status packets put on the line with error bits set and their checksum or CRC intact (the live view's "status
        #: errors": counted here, where every reply passes, because its packet log decodes only part of a fast host's
        #: traffic; a corrupted one the host takes as a checksum error).  A Fast Sync Read's one packet counts the
        #: first servo's error field alone.  Counted only while ``count_status_errors`` (a live view sets it): the look
        #: at every reply costs a few percent of a fast host's cycle rate, which a server nobody watches need not pay.
        self.status_errors = 0
        self.count_status_errors = False

    def stop(self) -> None:
        """Ask the loop to end after the current iteration (safe from a signal handler)."""
        self._stop = True

    # -- output ------------------------------------------------------------------------
    # The queue holds [release_s, seq, data, is_reply] lists, sorted; seq breaks ties.
    def _schedule(self, chunks: list[tuple[float, bytes]], *, is_reply: bool = True) -> None:
        for release_s, data in chunks:
            self._seq += 1
            bisect.insort(self._queue, [release_s, self._seq, bytearray(data), is_reply])

    def _flush(self, now: float) -> bool:
        """Put on the line whatever is due; True if anything was."""
        queue = self._queue
        count = 0
        while count < len(queue) and queue[count][0] <= now:
            count += 1
        if not count:
            return False
        if getattr(self.transport, "connections", None) != self._connections:
            self._new_host()  # what was owed to the host before is not this one's
            return False
        data = queue[0][2] if count == 1 else b"".join(item[2] for item in queue[:count])
        self._replied = self._replied or any(item[3] for item in queue[:count])
        del queue[:count]
        self._emit(bytes(data), now)
        # The host's next packet follows a reply within tens of microseconds: meet it spinning, not
        # asleep in select (waking took about 20 us of each read at Return Delay Time 250).
        self._hot_until = now + HOT_S
        if self._yield_after_reply and not (queue or self.pace):
            os.sched_yield()
        return True

    def _send_now(self, data: bytes, now: float) -> None:
        """:meth:`_flush` of ``data`` alone, with nothing queued."""
        self._replied = True
        self._emit(data, now)
        self._hot_until = now + HOT_S
        if self._yield_after_reply and not self.pace:
            os.sched_yield()

    def _emit(self, data: bytes, now: float) -> None:
        self._account(data, self.transport.write(data), now)

    def _account(self, data: bytes, sent: int, now: float) -> None:
        """Trace what went out of ``data``; count what did not."""
        if self.trace is not None:
            self.trace.record(OUT, data[:sent], now)
        if sent < len(data):
            self.bytes_dropped += len(data) - sent  # nobody is reading: the bytes are lost, as on a bus

    def _byte_s(self) -> float:
        return BITS_PER_BYTE / self.bus.servos[0].baud_bps

    def _new_host(self) -> None:
        """A new TCP client is a new host: the last one's half packet, the replies it was owed and the wire time
        its bytes took (``pace``) are not its business."""
        self._connections = getattr(self.transport, "connections", None)
        self.bus.framer.reset()
        self._queue.clear()
        self._rx_busy_until = 0.0

    # -- input -------------------------------------------------------------------------
    def _on_bytes(self, data: bytes, now: float) -> None:
        if getattr(self.transport, "connections", None) != self._connections:
            self._new_host()
        line_bps = self.transport.line_bps()
        end = now
        if self.pace:
            byte_s = BITS_PER_BYTE / line_bps if line_bps else self._byte_s()
            begin = max(now, self._rx_busy_until)
            end = begin + len(data) * byte_s
            self._rx_busy_until = end
            if self._trace_file is not None and self.trace is not None:  # the decoder measures a reply's latency from the instruction's end
                self._trace_file.on_wire(end, byte_s)
        if self.trace is not None:
            self.trace.record(IN, data, now)
        if self.pace:
            data = self._collide(data, begin, byte_s)
            if self.echo:
                self._schedule([(begin + (i + 1) * byte_s, bytes((b,))) for i, b in enumerate(data)], is_reply=False)
        elif self.echo:
            self._schedule([(now, data)], is_reply=False)
        if not self.pace:  # a poller's repeated READ, the short way (with pace, bytes may have collided)
            cached = self.bus.cached_replies(data, line_bps)
            if cached is not None:
                self.packets_in += 1
                self._answer(cached, now, end)
                return
        if self.pace and data.count(b"\xff\xff") > 1:
            # Several packets in one host write: on the wire each ends at its own last byte, and each servo answers
            # its Return Delay Time after that (two packets to two servos at 1 Mbps: replies some 80 us apart, not
            # merged). Fed a byte at a time, each packet completes at its end.
            scheduled = self._seq
            for i in range(len(data)):
                for replies in self.bus.answer(data[i : i + 1], now, line_bps=line_bps, cache=False, looked_up=False):
                    self.packets_in += 1
                    self._answer(replies, now, begin + (i + 1) * byte_s)
                    self._unsettled = self._settle is not None
            self._collide_with_own_write(data, scheduled, begin, end, byte_s)
            return
        for replies in self.bus.answer(data, now, line_bps=line_bps, cache=not self.pace, looked_up=not self.pace):
            self.packets_in += 1
            self._answer(replies, now, end)
            self._unsettled = self._settle is not None

    def _count_status_errors(self, replies: Sequence[Reply]) -> None:
        for k, reply in enumerate(replies):
            data = reply.data
            # (The later servos' shares of a Fast Sync Read's one packet carry their errors elsewhere: not counted.)
            if not reply.continues and len(data) > 4:
                two = data[2] == 0xFD and data[3] == 0
                at = _ERROR_AT[two]
                if at < len(data) and data[at] and _intact(replies, k, two):
                    self.status_errors += 1

    def _answer(self, replies: Sequence[Reply], now: float, end: float) -> None:
        """Put one packet's replies on the line: now, or queued for their delay (and pace)."""
        if not replies:
            return
        if self.count_status_errors:
            self._count_status_errors(replies)
        if len(replies) == 1 and replies[0].delay_s == 0.0 and not (self.pace or self._queue):
            data = replies[0].data  # the common case at Return Delay Time 0: _emit, one call shorter
            self._replied = True
            sent = self.transport.write(data)
            if sent < len(data) or self.trace is not None:
                self._account(data, sent, now)
            if self._yield_after_reply:
                os.sched_yield()
            return
        chunks = merge_replies(replies, end, per_byte=self.pace, in_sequence=self._in_sequence)
        if not (self.pace or self._queue) and chunks[-1][0] <= now:
            # All due now (a Sync Read's answers at Return Delay Time 0, in order): what _flush would send, unqueued.
            self._send_now(b"".join(data for _, data in chunks), now)
            return
        self._schedule(chunks)
        if not self.pace and replies[0].delay_s == 0.0:
            self._flush(now)

    def _collide_with_own_write(self, data: bytes, scheduled: int, begin: float, end: float, byte_s: float) -> None:
        """Reply bytes put on the wire while the host is still sending the rest of its write (a reply's Return Delay
        Time shorter than the packets after the one it answers: 8 bytes at 57,600 bps take 1.39 ms): the host's byte
        on the wire then and the reply's become their AND, as :meth:`_collide` does for a write into a reply."""
        collided = False
        for release_s, seq, byte, is_reply in self._queue:
            start = release_s - byte_s
            if seq > scheduled and is_reply and start < end:
                k = int((start - begin) / byte_s)
                if 0 <= k < len(data):
                    byte[0] &= data[k]
                    collided = True
        if collided:
            self.collisions += 1
            log.debug("collision: a reply began while the host was still sending its write")

    def _collide(self, data: bytes, begin: float, byte_s: float) -> bytes:
        """Host bytes overlapping reply bytes still on the wire: both become their AND."""
        horizon = begin + len(data) * byte_s
        on_wire = [item for item in self._queue if item[3] and item[0] - byte_s < horizon]
        if not on_wire:
            return data
        garbled = bytearray(data)
        for k, item in enumerate(on_wire[: len(data)]):
            mixed = garbled[k] & item[2][0]
            garbled[k] = mixed
            item[2][0] = mixed
        self.collisions += 1
        log.debug("collision: host sent %d bytes while a servo was replying", len(data))
        return bytes(garbled)

    # -- loop --------------------------------------------------------------------------
    def serve_forever(self) -> None:
        """Run until :meth:`stop` is called; then fail the calls left waiting (no pass will run them)."""
        try:
            while not self._stop:
                self.run_once()
        finally:
            self._stopped = True  # before the calls are failed: a call queued from now on fails itself
            self._fail_calls()

    def run_once(self) -> None:
        """Wait for the next event and handle everything that is due."""
        now = time.monotonic()
        queue = self._queue
        answered = False  # a pass that put a reply on the line counts as one that answered a packet
        self._replied = False  # (a status packet among what it put on the line)
        # A release a few microseconds away is met on the clock, with no system call (host bytes
        # that come meanwhile are read just after it: with pace, a collision window at most
        # EXACT_S short, where checking for them first would put a system call before every
        # paced byte).
        if queue and queue[0][0] - now < EXACT_S and self._exact_clock:
            due = queue[0][0]
            while now < due:
                now = time.monotonic()
            answered = self._flush(now)
        hot = now < self._hot_until
        if queue and queue[0][0] - now < SPIN_S or hot or self._physics is not None:
            wait_s = 0.0  # a reply is nearly due, a host is mid-conversation or a step is half done: spin
        else:
            deadline = min(self._next_physics, queue[0][0] - SPIN_S) if queue else self._next_physics
            # Capped at one period: calls and stop() are seen within it, even when slow motion spaces the ticks out.
            wait_s = min(max(0.0, deadline - now), self.physics_period_s)
        fds = self.transport.fds()
        if wait_s == 0.0 and self._poller is not None:  # spinning: poll() costs half what select() does
            if fds != self._polled_fds:
                self._poller = select.poll()
                for fd in fds:
                    self._poller.register(fd, select.POLLIN)
                self._polled_fds = fds
            readable = [fd for fd, _ in self._poller.poll(0)]
        else:  # select() takes microseconds; poll/epoll round a timeout up to whole milliseconds
            readable, _, _ = select.select(fds, (), (), wait_s)
        now = time.monotonic()
        for fd in readable:
            data = self.transport.on_readable(fd)
            if data:
                self._on_bytes(data, now)
                self._hot_until = now + HOT_S
                answered = True
        now = time.monotonic()  # handling input may have taken a while (a yield, a timeslice)
        if queue and self._flush(now):
            answered = True
        if not queue and self._replies_sent is not None:
            self._replies_sent()
        # Step physics on the loop's tick, not in the request path: a request then rarely pays
        # for a step (see Bus.request_lag_s).  The step comes in pieces, one per pass; while a
        # host is mid-conversation, a piece runs just after a packet was answered or a delayed
        # reply went out, when the host is busy with the reply rather than waiting for one.
        # A bus holding a write (``Bus2.parked``) takes it with the step, whole, hot or not: the next read must
        # see the step.  While a robot cycles with its writes held, the step is taken in the host's own time:
        # right after the reply before it falls due (see ``Bus2.advance_in_pieces``), its goals right after
        # the reply before that (the module docstring).
        if not (queue and queue[0][0] - now < PHYSICS_DEFER_S) and (answered or not hot or self._bus_parked()):
            whole = self._bus_parked()
            # (After a status packet only: after a write with none, the host's next packet is on its way.)
            lead_s = EARLY_STEP_S if whole and self._replied and self._time_scale is not None else 0.0
            if (lead_s and self._physics is None and self._taken_early_for != self._next_physics
                    and lead_s < self._next_physics - now <= 2 * lead_s):
                # The step is two host cycles off: its goals taken in this pause, the step in the next (see
                # ``Bus2.take_parked_early``); nothing left for settling to copy meanwhile.
                self.bus.take_parked_early()
                self._taken_early_for = self._next_physics
                self._unsettled = False
            elif self._physics is None and now + lead_s >= self._next_physics:
                # (A step taken more than a host cycle late, the loop held up past it, takes every write held: none
                # is then deferred past the step that would have taken it, however many steps the catch-up runs.)
                early = self._taken_early_for == self._next_physics and now < self._next_physics + EARLY_STEP_S
                if lead_s:
                    lead_s = max(0.0, self._next_physics - now)
                    self._physics = self.bus.advance_in_pieces(lead_s * self._time_scale, take=not early)
                elif early:
                    self._physics = self.bus.advance_in_pieces(take=False)
                else:
                    self._physics = self.bus.advance_in_pieces()
                self.bus.expire(now)
                self._next_physics = self._next_tick_s(now, lead_s)
                if whole:
                    # All pieces at once: the host's next packets need the whole step (a write held over it
                    # earns one now), and between pieces they would find some servos stepped and others
                    # owing a step, which their own handling would then take while the host waits.
                    for _ in self._physics:
                        pass
                    self._physics = None
            if self._physics is not None and next(self._physics, _DONE) is _DONE:
                self._physics = None
        # The step a client's write earned, taken while the host is busy with the reply or its next
        # packet (a Sync Write has no reply to wait for) rather than when that packet arrives.  Owed to
        # that packet anyway, so taken in this pass, hot or not, all its pieces at once (a pass between
        # pieces cost a poll and the loop's checks, about 2 us a piece, and the host's next packet meets
        # the same work either way); never inside a half-done physics step, whose copy back would then
        # follow a step it did not take, nor just before a reply.
        # While the bus holds a packet (a Sync Write a read may overtake), settling waits: the next packet or
        # the physics step takes it, and a robot's next Sync Write of the same goals supersedes it.
        if (self._physics is None and self._unsettled
                and not (queue and queue[0][0] - now < PHYSICS_DEFER_S) and not self._bus_parked()):
            self._unsettled = False
            for _ in self._settle():
                pass
        if self._calls:
            self._run_calls()

    def _next_tick_s(self, now: float, lead_s: float = 0.0) -> float:
        """When the physics tick after the one starting now falls due (``now``: the pass's clock).

        On the model's own step grid: the tick comes as soon as its whole steps
        are due, so at real time a request pays for a step only when the loop
        was held up (a tick on a free-running 1 ms beat could fall up to a
        whole step after the step was due, and a request just before it paid).
        ``lead_s``: the tick starting now was taken that much wall time early.
        """
        scale = self._time_scale
        if scale is None:  # virtual time: the clock moves only when a test moves it
            return max(self._next_physics + self.physics_period_s, now)
        step_s = self.bus.physics_step_s
        steps = max(1, round(self.physics_period_s * scale / step_s))  # one at real time, more when faster
        sim_now_s = self.bus.clock.now_s() + lead_s * scale
        wall_s = time.monotonic() + lead_s  # read second: the tick may come a hair late, never early
        due_sim_s = (math.floor(sim_now_s / step_s + 1e-9) + steps) * step_s
        return wall_s + (due_sim_s - sim_now_s) / scale

    def _read_pending(self) -> None:
        """Handle what the host wrote before a call was made, so the call does not overtake it.

        Why: a packet with no reply (Sync Write, Status Return Level 0) leaves the host nothing to wait
        for, so its next move may be a call (``VirtualBus.step``) made before this loop read the packet.
        Two ways the pass that saw the call may not have read the bytes: the pass's read came just
        before they did, or, on a pty in packet mode, it read only the status byte of the host's input
        flush (dynamixel-sdk's ``clearPort`` before every packet), which a read returns on its own
        (Linux ``n_tty_read``/``pty``: a pending packet-mode status is returned instead of data).
        A zero-timeout poll also waits out bytes still in the kernel's flip buffer: Linux ``n_tty_poll``
        calls ``tty_buffer_flush_work`` when no input is ready (measured here: 60,000 writes to a pty's
        slave, each polled on the master at once, none missed).  Bounded: a status byte then the data
        take two reads; a descriptor that stays readable with nothing to give stops after a few.
        """
        for _ in range(READS_BEFORE_CALLS):
            readable, _, _ = select.select(self.transport.fds(), (), (), 0.0)
            if not readable:
                return
            for fd in readable:
                data = self.transport.on_readable(fd)
                if data:
                    now = time.monotonic()
                    self._on_bytes(data, now)
                    self._hot_until = now + HOT_S

    # -- calls from other threads -----------------------------------------------------
    def call(self, fn: Callable[[Bus], Any], timeout_s: float = 5.0) -> Any:
        """Run ``fn(bus)`` on the serving thread between packets and return its result.

        Why: the bus is not thread-safe, and a test thread changing a servo
        (or its faults) mid-packet would race the serving loop.  The loop
        wakes at least once per physics period, so this waits about 1 ms.
        A call the loop will never run (it stopped before or while the call
        waited) fails at once with :class:`ServerStopped`.
        """
        future: Future = Future()
        self._calls.append((fn, future))
        if self._stopped:  # the loop ended before it could see this call: waiting would only time out
            self._fail_calls()
        try:
            return future.result(timeout_s)
        except FuturesTimeout:
            raise TimeoutError(f"the serving loop did not finish the call within {timeout_s:g} s (a long step, "
                               "or a loop held up); it may still run") from None

    def _fail_calls(self) -> None:
        """Fail every queued call with :class:`ServerStopped` (each is taken off the queue once, by one thread)."""
        while True:
            try:
                _, future = self._calls.popleft()
            except IndexError:
                return
            future.set_exception(ServerStopped("the serving loop has stopped; the call did not run"))

    def _run_calls(self) -> None:
        self._read_pending()
        if self._take_deferred is not None:
            self._take_deferred()  # a caller may read any register, the ones a reply could not show included
        while self._calls:
            fn, future = self._calls.popleft()
            try:
                result = fn(self.bus)
            except BaseException as exc:  # handed to the caller, never kills the loop
                result, error = None, exc
            else:
                error = None
            if self._changed_outside is not None:
                self._changed_outside()  # before the caller hears back: its next packet meets the change
            if error is None:
                future.set_result(result)
            else:
                future.set_exception(error)
