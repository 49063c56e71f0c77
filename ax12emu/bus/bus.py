"""A half-duplex bus of virtual AX-12 servos: bytes in, timed status packets out.

Why it exists: it is the one place that owns the servos, their shared table
array, the model behind them and the framer, and decides who hears a packet.
It does no I/O: a transport loop (``server.py``) or a test feeds it bytes with
the time they arrived and sends what it returns after each reply's delay.

Hardware semantics kept: every servo sees every packet and acts on its own
ID or the broadcast ID; a servo listening at a baud rate more than 3 % away
from the line's hears only garbage and stays silent; a servo writing its
EEPROM ignores packets for a while after the write (``ServoOptions.eeprom_busy_s_per_byte``),
timed by the bus's clock, so in virtual time too; two servos given the
same ID both act and both answer (the server merges colliding replies); an ID
written by a client moves the servo at once.  Not modelled here: bit timing
and collisions on the wire (``server.py``), electrical faults.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator, Sequence
from typing import Protocol

import numpy as np

from ax12emu.protocol.control_table import TABLE_SIZE, Layout
from ax12emu.protocol.describe import describe_error, describe_instruction
from ax12emu.protocol.framing import Framer
from ax12emu.protocol.packets import BROADCAST_ID, MAX_ID, Instruction, InstructionPacket
from ax12emu.servo.model_factory import ModelChoice, build_model
from ax12emu.servo.plant import Plant
from ax12emu.servo.plant2 import GRID_SLACK_S
from ax12emu.servo.request_handler import handle
from ax12emu.servo.virtual_servo import ServoOptions, VirtualServo
from firmware_model.interface import ServoModel

from .clock import VirtualClock, WallClock
from .lookup import ServosById, check_ids
from .reply import Reply
from .reply_cache import ReplyCache
from .state_store import StateStore

__all__ = ["Bus", "BAUD_TOLERANCE", "Interceptor"]

log = logging.getLogger(__name__)

#: Instructions that can change command registers; after any other the model's inputs stand.
_CHANGES_TABLES = frozenset(int(i) for i in (Instruction.WRITE, Instruction.ACTION, Instruction.RESET, Instruction.SYNC_WRITE))
#: A UART samples mid-bit; beyond about 3 % rate mismatch the stop bit is missed.
BAUD_TOLERANCE = 0.03


class Interceptor(Protocol):
    """What the bus calls around packets and physics so faults can bend them (:class:`ax12emu.faults.Faults`).

    Declared here, implemented above: the bus knows when to call, the
    fault layer what to do, and the bus imports nothing of it.
    """

    def after_physics(self) -> None:
        """After the model stepped or a packet changed tables: hold what is held."""
        ...

    def admit(self, servo: VirtualServo) -> bool:
        """Before ``servo`` handles a packet: False if it is absent from the wire."""
        ...

    def on_replies(self, replies: list[Reply]) -> list[Reply]:
        """The replies as they reach the wire (dropped, corrupted, delayed)."""
        ...


class Bus(ServosById[VirtualServo]):
    """Virtual servos on one wire, with their model, in wall-clock or virtual time."""

    def __init__(
        self,
        ids: Iterable[int],
        *,
        options: ServoOptions = ServoOptions(),
        model: ServoModel | None = None,
        clock: WallClock | VirtualClock | None = None,
        state_store: StateStore | None = None,
        framer: Framer | None = None,
        table_layout: Layout | Sequence[Layout | None] | None = None,
    ) -> None:
        """``table_layout``: every servo's table is this Protocol 1.0 model's (e.g. the AX-18A's,
        ``servo_models.model("ax-18a").layout()``), or one per slot (None: the AX-12A profile
        ``options.profile``), instead of the profile's; ``model`` should then carry each model's
        physics (``firmware_model.grouped.GroupedModel`` for several)."""
        slots = list(ids)
        check_ids(slots, MAX_ID)
        self.slots = slots
        self.options = options
        self.clock = clock if clock is not None else WallClock()
        self.framer = framer if framer is not None else Framer()
        self.state_store = state_store
        self.rows = np.zeros((len(slots), TABLE_SIZE), dtype=np.uint8)
        layouts = [table_layout] * len(slots) if table_layout is None or isinstance(table_layout, Layout) else list(table_layout)
        if len(layouts) != len(slots):
            raise ValueError(f"{len(layouts)} table layouts for {len(slots)} servos")
        self.servos: list[VirtualServo] = [
            VirtualServo.fresh(slot, options, index=index, row=self.rows[index], table_layout=layouts[index])
            for index, slot in enumerate(slots)
        ]
        # The plant applies one Alarm Shutdown rule for the wire (what a shutdown clears).
        if len({servo.table.profile.shutdown_clears for servo in self.servos}) > 1:
            raise ValueError("servos whose Alarm Shutdown clears different registers cannot share this bus")
        if state_store is not None:
            for slot, servo in zip(slots, self.servos):
                state_store.load(slot, servo.table)
        # The default model cuts as these tables do (an AX-18A's table is its model file's, whatever the profile).
        clears = self.servos[0].table.profile.shutdown_clears or "torque_limit"
        self.model = model if model is not None else build_model(ModelChoice(profile=options.profile), len(slots), clears)
        self.plant = Plant(self.model, self.rows, self.servos)
        for servo in self.servos:
            servo.power_on()
        self._by_id: dict[int, list[VirtualServo]] = {}
        self.reindex()
        #: How far behind the clock physics may be when a packet is served.  0 (the
        #: default) brings it to the present first; a serving loop that steps physics
        #: between packets sets one step, so requests rarely pay for a step.
        self.request_lag_s = 0.0
        #: Injected faults (an :class:`Interceptor`, normally ``ax12emu.faults.Faults``); None costs one test per packet.
        self.faults: Interceptor | None = None
        #: Whether ``-v`` logs every packet this bus hears (False inside an MX wire, whose bus logs those to its servos).
        self.logs_every_packet = True
        #: Replies to repeated READ / PING packets (see :mod:`ax12emu.bus.reply_cache`).
        self.reply_cache = ReplyCache()
        #: The latest ``busy_until_s`` of any servo: until then a packet may meet a servo that
        #: ignores it, so nothing is answered from or stored in the reply cache.
        self._busy_until_s = float("-inf")
        self._closed = False

    # -- lookup (reindex, servo, ids: ServosById) ---------------------------------------
    #: Replies to one packet may overlap on the wire (broadcast PING, duplicate IDs): the serving
    #: loop merges them (``merge_replies``) rather than laying them one after another.
    replies_in_sequence = False
    #: The protocol its servos speak (``protocol=`` of the harness and the faults).
    protocol = 1.0

    @property
    def physics_step_s(self) -> float:
        """The model's control step: the serving loop's physics tick lands on its grid."""
        return self.plant.model.step_s

    # -- time --------------------------------------------------------------------------
    def advance(self) -> bool:
        """Bring the physics up to the clock's present time; True if a step was taken."""
        moved = self.plant.advance(self.clock.now_s())
        if self.faults is not None:
            self.faults.after_physics()
        return moved

    def catch_up_for_request(self, now_s: float | None = None) -> None:
        """Bring the physics to where a request at ``now_s`` (default: the clock's present) finds it: to that time
        and, after a packet that wrote registers, one control step past it (``Plant.catch_up``), so it sees the
        consequence of the writes before it."""
        if now_s is None:
            now_s = self.clock.now_s()
        self.plant.catch_up(now_s - self.request_lag_s, now_s)
        if self.faults is not None:
            self.faults.after_physics()

    def advance_in_pieces(self) -> Iterator[None]:
        """:meth:`advance` in the plant's pieces (see ``Plant.tick``), for a serving loop to interleave with packets."""
        yield from self.plant.tick(self.clock.now_s())
        if self.faults is not None:
            self.faults.after_physics()

    # -- bytes in, replies out ---------------------------------------------------------
    def receive(self, data: bytes, now_s: float | None = None, *, line_bps: float | None = None) -> list[Reply]:
        """Feed bytes that arrived at wall time ``now_s``; return the replies they cause.

        ``line_bps`` is the rate the host transmits at, when the transport
        knows it (a pty's termios speed); None means every servo hears.
        """
        return [reply for replies in self.answer(data, now_s, line_bps=line_bps) for reply in replies]

    def cached_replies(self, data: bytes, line_bps: float | None = None) -> Sequence[Reply] | None:
        """The replies to ``data`` from the reply cache, or None when it must be decoded.

        Why apart from :meth:`answer`: a host polling one register runs this
        path thousands of times a second, so it holds nothing but the checks
        a hit needs (the throughput goal of tools/bench_protocol.py).  A hit needs exactly one
        whole READ or PING in ``data`` with no partial packet held before it,
        no faults installed (they act per packet), no debug logging (``-v``
        logs every packet), and the servos it reached unchanged since (see
        :mod:`ax12emu.bus.reply_cache`); physics is brought up first, as
        :meth:`dispatch` does.
        """
        now_s = self.clock.now_s()
        if (self.faults is not None or len(data) < 6 or len(data) != data[3] + 4 or self.framer.buffered
                or now_s < self._busy_until_s or log.isEnabledFor(logging.DEBUG)):
            return None
        plant = self.plant
        model, sim_time_s = plant.model, now_s - self.request_lag_s
        # Plant.catch_up's own tests (step_due, GRID_SLACK_S), without the calls: this is the repeated READ's short way
        if sim_time_s + GRID_SLACK_S >= model.time_s + model.step_s or plant.write_unseen:
            plant.catch_up(sim_time_s, now_s)
        return self.reply_cache.lookup(data if type(data) is bytes else bytes(data), line_bps, self._by_id)

    def answer(self, data: bytes, now_s: float | None = None, *, line_bps: float | None = None,
               cache: bool = True, looked_up: bool = False) -> list[Sequence[Reply]]:
        """Feed bytes; return the replies to each packet they completed, one sequence per packet.

        With ``cache`` a repeated READ or PING is answered from the reply
        cache (:meth:`cached_replies`) and a new one is stored there;
        ``cache=False`` bypasses it, e.g. when bytes may have collided.
        ``looked_up`` says the caller already asked :meth:`cached_replies`
        for ``data`` and missed: only the storing is left.
        """
        if cache:
            cached = None if looked_up else self.cached_replies(data, line_bps)
            if cached is not None:
                return [cached]
            # Only a packet that stands alone is stored (see ReplyCache.store).
            cache = (self.faults is None and not self.framer.buffered and not log.isEnabledFor(logging.DEBUG)
                     and self.clock.now_s() >= self._busy_until_s)
        packets = self.framer.feed(data, now_s)
        answers = [self.dispatch(packet, line_bps=line_bps) for packet in packets]
        if cache and len(packets) == 1 and not self.framer.buffered:
            packet = packets[0]
            self.reply_cache.store(bytes(data), line_bps, packet, self._by_id.get(packet.id), answers[0])
        return answers

    def expire(self, now_s: float) -> None:
        """Let the framer drop a partial packet after silence."""
        if self.framer.expire(now_s):
            log.debug("dropped a partial packet after %.0f ms of silence", self.framer.silence_timeout_s * 1e3)

    def dispatch(self, packet: InstructionPacket, *, line_bps: float | None = None) -> list[Reply]:
        """Run one decoded packet on the servos it addresses; return their replies.

        Physics is brought to the present first and, after a packet that wrote
        registers, one control step past it (``Plant.catch_up``): each request
        sees the consequence of the writes before it, as on a real servo.
        """
        now_s = self.clock.now_s()
        self.catch_up_for_request(now_s)
        faults = self.faults
        targets = self.servos if packet.id == BROADCAST_ID else self._by_id.get(packet.id, ())
        debug = log.isEnabledFor(logging.DEBUG)
        if debug and (targets or self.logs_every_packet):  # inside an MX wire: its packets are the MX bus's to log
            log.debug("rx %s -> IDs %s", describe_instruction(packet, self.options.profile), [s.id for s in targets])
        replies: list[Reply] = []
        moved = False
        for servo in targets:
            baud = servo.baud_bps
            if line_bps is not None and abs(line_bps - baud) > BAUD_TOLERANCE * baud:
                if debug:
                    log.debug("ID %d listens at %.0f bps, the host sends at %.0f: it hears garbage", servo.id, baud, line_bps)
                continue
            if servo.busy_until_s > now_s:
                if debug:
                    log.debug("ID %d is writing its EEPROM for %.1f ms more: it ignores the packet",
                              servo.id, (servo.busy_until_s - now_s) * 1e3)
                continue
            if faults is not None and not faults.admit(servo):
                continue
            if packet.instruction in _CHANGES_TABLES:
                old_id = servo.id
                outcome = handle(servo, packet)
                moved = moved or servo.id != old_id
            else:
                outcome = handle(servo, packet)
            if outcome.reply is not None:
                replies.append(Reply(outcome.reply_id, outcome.reply, outcome.delay_s, baud))
                if debug:
                    log.debug("tx id=%d %s after %.0f us", outcome.reply_id, describe_error(outcome.reply[4]), outcome.delay_s * 1e6)
            if servo.eeprom_bytes_written:
                busy_s = servo.eeprom_bytes_written * servo.options.eeprom_busy_s_per_byte
                servo.eeprom_bytes_written = 0
                if busy_s > 0.0:
                    servo.busy_until_s = now_s + busy_s
                    self._busy_until_s = max(self._busy_until_s, servo.busy_until_s)
            if servo.eeprom_dirty:
                servo.eeprom_dirty = False
                if self.state_store is not None:
                    self.state_store.save_or_say(self.slots[servo.index], servo.table)
        instruction = packet.instruction
        if instruction in _CHANGES_TABLES and targets and packet.checksum_ok:
            self.plant.wrote()
            if instruction == Instruction.RESET:
                self.plant.refresh(alarms=False)
            if faults is not None:
                # Held registers and a stall's drive timer see the write now, at its time, not at
                # whichever comes next of a physics tick or a packet (in virtual time, a later step).
                faults.after_physics()
        if moved:
            self.reindex()
        if faults is not None and replies:
            replies = faults.on_replies(replies)
        return replies

    # -- life cycle --------------------------------------------------------------------
    def save_state(self) -> None:
        """Write every servo's EEPROM to the state store (if any); a failure is said once, as mid-session, and the
        bus closes anyway (a server told to stop exits cleanly, whatever became of its state directory)."""
        if self.state_store is not None:
            for slot, servo in zip(self.slots, self.servos):
                self.state_store.save_or_say(slot, servo.table)

    def close(self) -> None:
        """Save state; safe to call more than once."""
        if not self._closed:
            self._closed = True
            self.save_state()

    def __enter__(self) -> "Bus":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
