"""A half-duplex bus of Protocol 2.0 servos (the X series): bytes in, timed status packets out.

Why it exists: Protocol 2.0 servos share the wire differently from Protocol 1.0 ones, so the
bus that owns them decides more than who hears a packet: which servo answers when, in one
order, for the instructions several servos answer.  It offers the serving loop
(:class:`ax12emu.serve.BusServer`) what :class:`ax12emu.bus.Bus` offers, so the same loop, pty
and TCP transports serve it, and it does no I/O.

Who answers, and when (ROBOTIS e-manual, "DYNAMIXEL Protocol 2.0"; times from the end of the
instruction, byte times at each servo's baud, 10 bits a byte; each reply's ``delay_s`` counts the
wire time of the replies before it, and its ``wire_s`` says how much of it that is.  A serving loop
with ``--pace`` keeps that wire time; without it bytes take no time, so it sends each reply at
``delay_s - wire_s``: the same order, each Return Delay Time after the one before, no byte time;
see ``reply.merge_replies``):

* an instruction to one ID: that servo, Return Delay Time after (2 us units), as on Protocol 1.0;
* broadcast Ping: "All devices send their Status Packet according to their arranged order".
  The e-manual gives no times.  Each servo answers in the slot of its ID: the servo with ID n
  starts ``RDT + n * (its Ping status time + the longest RDT, 508 us)`` after the instruction, so the
  answers never overlap whatever Return Delay Time each servo has.  A slot per ID rather than "after the previous answer" because
  a lone servo with a high ID answers late on real hardware (Dynamixel2Arduino issue 106: at
  2 Mbps a lone ID 5 needed a longer timeout than IDs 1 and 2), and dynamixel-sdk's broadcastPing
  and Dynamixel2Arduino's wait grow with the highest ID (3 ms per ID), not with the servo count;
* Sync Read and Bulk Read: the listed servos answer one at a time in list order, each Return
  Delay Time after the previous servo's status packet ended (each hears the one before it);
* Fast Sync Read and Fast Bulk Read: one status packet with ID 0xFE that the listed servos build
  together (``packets2.fast_status_pieces``): the first sends the header and its share Return
  Delay Time after the instruction, each next one its share right after the previous share ended;
* a servo listed in a Sync/Bulk/Fast read that is absent or silent (another baud, Status Return
  Level 0) breaks the chain: the servos listed after it wait for a status that never comes and stay
  silent.  The e-manual does not say what they do; a client sees a timeout or a short packet,
  as it would from a broken chain of real servos;
* Read to the broadcast ID: not executed ("Status Packet will not be returned for READ and WRITE
  Instructions"); Write, Reg Write, Action, Factory Reset, Reboot, Clear and Backup to the broadcast
  ID: executed by every servo, answered by none; Sync/Bulk instructions are executed only when sent
  to the broadcast ID ("Packet ID field : 0xFE"), and ignored otherwise;
* a packet to a servo's Secondary ID (12) (and not to its ID, which "has a higher priority"): executed
  on the RAM area only and answered by nobody (e-manual, X series, "Secondary ID(12)"); Sync/Bulk
  lists name IDs, not Secondary IDs;
* status packets on the wire (another servo's answer) are heard and ignored.

Time: before any request the firmware models are brought to the present (and one control step
past a client's write, but never more than one step past the clock), as the Protocol 1.0 bus does
with ``Plant.catch_up``; the Bus Watchdog of
each servo measures the silence since the last instruction packet it heard.

EEPROM areas persist in a :class:`~ax12emu.bus.state_store.StateStore` as on the 1.0 bus (by
register name, keyed by the ID a servo was launched with).

Faults (``bus.faults``, :class:`ax12emu.faults.Faults2`): the wire's, a status packet dropped,
corrupted or delayed, a servo unplugged (it hears nothing, and a Sync/Bulk Read's chain breaks at
it); a servo's own (an error, a blocked shaft, pinned readings) act inside its firmware model, so
the bus only shows what the firmware reports.  Two servos with one ID (``duplicate``) both act and
answer at once; the bus collides their answers (``reply.collide``: AND-ed as on the wire).  In a Sync or
Bulk Read both answer in the ID's turn; in a Fast Sync/Bulk Read both send their share in its turn
and the servos after it run their CRC on over the collided bytes they heard.
Not modelled: the reply cache (the Protocol 1.0 bus has one), a servo's busy time after a write to
its EEPROM, and the time a rebooting servo is deaf.  The live view (:mod:`ax12emu.live`) shows this
bus's servos as it shows the 1.0 bus's.
"""

from __future__ import annotations

import functools
import logging
import math
import operator
from collections.abc import Callable, Iterable, Iterator

from ax12emu.protocol.crc16 import crc16
from ax12emu.protocol.framing2 import Framer2
from ax12emu.protocol.packets import BROADCAST_ID
from ax12emu.protocol.packets2 import (
    MAX_ID2,
    ErrorNumber,
    FastStatusPart,
    Instruction2,
    InstructionPacket2,
    StatusPacket2,
    encode_status2,
    fast_status_pieces,
)
from ax12emu.protocol.params2 import INSTRUCTION_SPECS, Broadcast, BulkRead, SyncRead, SyncWrite
from ax12emu.protocol.servo_models import ServoModel
from ax12emu.servo.plant2 import GRID_SLACK_S, plant_for
from ax12emu.servo.request_handler2 import (
    answers,
    first_writes,
    handle2,
    listed_read,
    params_bytes,
    parsed_params,
    status_byte,
    sync_write_all,
)
from ax12emu.servo.servo2 import Servo2, Servo2Options
from firmware_model.xseries.interface import XServoModel

from .bus import Interceptor
from .clock import VirtualClock, WallClock
from .decoded import DecodedBus
from .lookup import ServosById, check_ids
from .reply import BITS_PER_BYTE, Reply, collide
from .state_store import StateStore

__all__ = ["Bus2", "FirmwareFactory"]

log = logging.getLogger(__name__)

#: Builds one servo's firmware model from its model file (``spec``) and its index on the bus.
FirmwareFactory = Callable[[ServoModel, int], XServoModel]

#: More distinct Sync Writes (and reads after them) than a client sends; past it the remembered ones start over.
_MAX_REMEMBERED = 64
#: More Sync Writes than a robot sends in one control step, each superseding the one before (see
#: ``Bus2._answer_holding``); past it the held ones are taken.
_MAX_SUPERSEDED = 32
#: How recently a read must have overtaken a held write for a step to have its next answer ready
#: (``Bus2._prepare_overtaking``): a robot's cycle comes every few milliseconds at most.
_PREPARE_WITHIN_S = 0.005
#: The largest LENGTH a packet can announce.
MAX_LENGTH = 0xFFFF
_EXECUTED_SILENTLY = frozenset({Broadcast.SILENT, Broadcast.EACH_ANSWERS})
_LISTED_READS = frozenset({Broadcast.REQUIRED_EACH_ANSWERS, Broadcast.REQUIRED_COMBINED_ANSWER})
_REQUIRED_BROADCAST = _LISTED_READS | {Broadcast.REQUIRED_SILENT}
#: ``encode_status2`` remembered for the last answers (``data``: bytes, as ``Table2.read`` gives): a robot's
#: Sync Read asks the same servos for the same registers every cycle, and a servo at rest, or read again
#: within one control step, answers the same bytes.
_status_packet = functools.lru_cache(maxsize=1024)(encode_status2)


def _listed_reads(params: object) -> list[tuple[int, int, int]] | None:
    """A Sync or Bulk Read's parameters as (ID, address, length) per read; None for any other parameters."""
    if isinstance(params, SyncRead):
        return [(servo_id, params.address, params.length) for servo_id in params.ids]
    if isinstance(params, BulkRead):
        return list(params.reads)
    return None


class Bus2(ServosById[Servo2], DecodedBus):
    """Protocol 2.0 servos on one wire, each with its own model file and firmware model (bytes in and
    the life cycle: :class:`~.decoded.DecodedBus`)."""

    #: Several replies to one packet are timed one after another (see the module docstring): the
    #: serving loop sends each at its own time.
    replies_in_sequence = True
    #: The protocol its servos speak (``protocol=`` of the harness and the faults).
    protocol = 2.0

    def __init__(
        self,
        servos: Iterable[tuple[int, ServoModel]],
        firmware: FirmwareFactory,
        *,
        clock: WallClock | VirtualClock | None = None,
        options: Servo2Options = Servo2Options(),
        framer: Framer2 | None = None,
        state_store: StateStore | None = None,
    ) -> None:
        slots = list(servos)
        ids = [servo_id for servo_id, _ in slots]
        check_ids(ids, MAX_ID2, " (Protocol 2.0)")
        self.slots = ids
        self.clock = clock if clock is not None else WallClock()
        self.framer = framer if framer is not None else Framer2()
        self.servos: list[Servo2] = []
        for index, (servo_id, spec) in enumerate(slots):
            model = firmware(spec, index)
            self.servos.append(Servo2(spec, lambda servo, m=model: plant_for(m, servo.table, servo.spec),
                                      servo_id=servo_id, index=index, options=options))
        #: Where each servo's EEPROM area persists, keyed by the ID it was launched with; None: nowhere.
        self.state_store = state_store
        if state_store is not None:
            for slot, servo in zip(ids, self.servos):
                if state_store.load(slot, servo.table):  # first: another model's file is refused as that
                    servo.backup = state_store.load_backup(slot, len(servo.table.row))  # before power-up reads it
                    servo.power_on()
        self._by_id: dict[int, list[Servo2]] = {}
        self.reindex()
        #: How far behind the clock physics may be when a packet is served (see ``Bus.request_lag_s``).
        self.request_lag_s = 0.0
        #: Injected faults (``ax12emu.faults.Faults2``: replies dropped, corrupted or delayed,
        #: servos unplugged; the servos' own act in their firmware); None costs one test per packet.
        self.faults: Interceptor | None = None
        #: Set by a serving loop that takes the steps the servos owe right after each packet
        #: (``settle_in_pieces``): a Sync/Bulk Read may then leave a servo's catch-up for after its reply
        #: where the reply cannot tell (``Plant2.defer_catch_up``).  Off, every request catches up first.
        self.defer_settling = False
        #: A Sync Write held (see :meth:`answer`): (packet, line speed, the bus time it was heard at), or None;
        #: and whether it still waits for the read a robot sends after it (False once a read went before it).
        self._parked: tuple[InstructionPacket2, float | None, float] | None = None
        self._waiting = False
        #: Older held Sync Writes the held one supersedes (see :meth:`_answer_holding`), oldest first.
        self._superseded: list[InstructionPacket2] = []
        #: Counts what may have changed a servo since (packets handled, catch-ups, steps, writes taken, callers'
        #: turns): a remembered answer (:meth:`_overtaking_again`) holds only while it stands still.
        self._changes = 0
        #: (read, its parameters, line speed, the held write's shape) -> (changes, clock time it holds until, the
        #: servos that hear it, replies) of a read that overtook the held write.
        self._overtaken: dict[tuple, tuple[int, float, list[Servo2], tuple[Reply, ...]]] = {}
        #: Per (read, its parameters): whether it reads what hearing a packet changes (or is malformed).
        self._reads_heard: dict[tuple, bool] = {}
        #: The read that last overtook a held write the long way: (read, line speed, that write, its shape), or None;
        #: and when a read last overtook one, either way (clock time).
        self._last_overtaking: tuple[InstructionPacket2, float | None, InstructionPacket2, tuple] | None = None
        self._overtook_at_s = 0.0
        #: What :meth:`_may_hold` held the write by: (address, length, the IDs listed, line speed).
        self._parked_key: tuple = ()
        #: What :meth:`_may_hold` and :meth:`_read_unchanged_by` find from the IDs and layouts alone, per write
        #: (and read), with the lookup (``_by_id``) they were found under.
        self._holdable: dict[tuple, tuple[dict, list[Servo2], bool]] = {}
        #: What :meth:`_may_hold` found of the servos' state under a count of changes (``_changes``): that count,
        #: the listed servos it was found for, whether every Bus Watchdog is off, from when a write earns one a step.
        self._hold_state: tuple[int, list[Servo2], bool, float] | None = None
        self._overtaking: dict[tuple, tuple[dict, list | None]] = {}
        self._sensed_by_read: dict[object, tuple[dict, dict]] = {}
        #: A Sync/Bulk Read's answers per (instruction, parameters, line speed): the lookup they were found under,
        #: per servo consulted [servo, the picker of the bytes its answer depends on, those bytes, its whole row as
        #: last seen with them], and the replies (see :meth:`_listed`).
        self._listed_answers: dict[tuple, tuple[dict, tuple[list, ...], list[Reply]]] = {}
        #: Those pickers per (servo, its reads): they depend on the servo's layout alone.
        self._answer_pickers: dict[tuple, Callable[[bytearray], tuple]] = {}
        self._closed = False

    # -- lookup (reindex, servo, ids: ServosById) ---------------------------------------
    @property
    def physics_step_s(self) -> float:
        """The shortest control step of the servos' firmware models."""
        return min(servo.plant.firmware.step_s for servo in self.servos)

    def reindex(self) -> None:
        """Look servos up by the IDs in their tables again; the same lookup while no ID changed.

        Why keep it: it runs after every packet that may have written, and what is remembered per
        lookup (the Sync Write held for the next read, :meth:`_read_unchanged_by`) stays good.
        """
        ids = tuple(servo.id for servo in self.servos)
        if ids != getattr(self, "_indexed_ids", None):
            super().reindex()
            self._indexed_ids = ids

    # -- time --------------------------------------------------------------------------
    def catch_up(self, sim_time_s: float, clock_s: float | None = None,
                 reads: dict[Servo2, tuple[tuple[int, int], ...] | None] | None = None) -> None:
        """Every servo's firmware brought to ``sim_time_s`` (and past a client's write, at most a step past
        the clock's present ``clock_s``: ``Plant2.catch_up``); watchdogs checked.

        ``reads``: for a read the serving loop settles after (see :attr:`defer_settling`), the spans each
        listed servo's answer reads of its sensed registers (None: it reads one it cannot leave); a servo
        whose catch-up would change none of them takes it after the reply (``Plant2.defer_catch_up``).
        """
        self._changes += 1
        for servo in self.servos:
            plant = servo.plant
            deadline_s = servo.watchdog_deadline_s()  # None unless armed with the torque on (the usual case)
            if deadline_s is not None and deadline_s < sim_time_s:
                # The Bus Watchdog stops the servo when the silence runs out, not at the packet that ends it (a
                # bus brought to its time in one stretch: virtual time, an in-process port).
                if plant.due(deadline_s):
                    plant.catch_up(deadline_s)
                servo.check_watchdog(sim_time_s)
            if plant.due(sim_time_s, clock_s):
                spans = reads.get(servo) if reads is not None else None
                if spans is None or clock_s is None or not plant.defer_catch_up(sim_time_s, clock_s, spans):
                    plant.catch_up(sim_time_s, clock_s)
            if deadline_s is not None:
                servo.check_watchdog(sim_time_s)

    def advance(self) -> bool:
        """Bring the physics up to the clock's present time; True if a servo stepped."""
        self.take_parked()
        sim_time_s = self.clock.now_s()
        due = any(servo.plant.due(sim_time_s) for servo in self.servos)
        self.catch_up(sim_time_s)
        return due

    def advance_in_pieces(self, lead_s: float = 0.0, *, take: bool = True) -> Iterator[None]:
        """:meth:`advance` one servo piece at a time, for a serving loop to interleave with packets.

        Held Sync Writes are taken first, their commands shown by the step that follows rather than by a copy
        of their own (``take_parked(show=False)``: a servo whose step is not yet due copies them when it is
        next caught up, as it would have right after them).

        ``lead_s``: steps falling due within this much bus time are taken now, as if the clock were that far
        on.  Why: a robot cycling faster than 1 kHz sends its next packets at once after each reply, and a
        step taken when it falls due lands on them; taken right after a reply, in the time the host spends on
        it, the step shows the servo's next 1 ms loop a fraction of a period early, which no host can tell
        from a loop running at another phase.

        ``take``: False after :meth:`take_parked_early` for this step, whose goals the step then acts on; a write
        held since is left for the next step.
        """
        if take:
            self.take_parked(show=False)
        sim_time_s = self.clock.now_s()
        for servo in self.servos:
            for _ in servo.plant.tick(sim_time_s + lead_s):
                self._changes += 1  # a packet may come between the pieces: nothing remembered of before holds
                yield
            servo.check_watchdog(sim_time_s)  # (silence is timed on the clock itself)
        self._changes += 1
        self._prepare_overtaking()

    def settle_in_pieces(self) -> Iterator[None]:
        """The steps the servos owe, one servo at a time: a client's write earns one (``Plant2.catch_up``).

        For a serving loop, right after a packet: taken while the host reads the reply or, after a
        packet nobody answers (a Sync Write), prepares its next one, instead of in that packet's
        catch-up.  The model takes the same steps either way (the packet's catch-up finds nothing
        left to do); only the host's wait is shorter.  A Sync Write held for the next packet is taken first.
        """
        self.take_parked()
        for servo in self.servos:
            plant, clock_s = servo.plant, self.clock.now_s()
            sim_time_s = clock_s - self.request_lag_s
            if plant.due(sim_time_s, clock_s):
                plant.catch_up(sim_time_s, clock_s)
                self._changes += 1  # (before the pause: a packet may come between the pieces)
                yield

    def take_deferred(self) -> None:
        """Every catch-up a reply went out before (``Plant2.defer_catch_up``), taken now at the times it was due.

        For a serving loop before it hands the bus to a caller, who may read any register; a Sync Write
        held for the next packet is taken too.
        """
        self._changes += 1
        self.take_parked()
        for servo in self.servos:
            servo.plant.catch_up_deferred()

    def changed_outside(self) -> None:
        """A caller may have changed servos outside the packets (a serving loop's calls, a fault acting): what
        was remembered of them before (:meth:`_overtaking_again`) no longer holds."""
        self._changes += 1

    # -- bytes in, replies out (receive, answer, expire: DecodedBus) ---------------------
    def answer(self, data: bytes, now_s: float | None = None, *, line_bps: float | None = None,
               cache: bool = True, looked_up: bool = False) -> list[list[Reply]]:
        """Feed bytes; return the replies to each packet they completed, one list per packet.

        With :attr:`defer_settling` (a serving loop that settles after each packet), a broadcast Sync
        Write of Goal and profile registers only (``Servo2.writes_goals_only``) that comes while the servos'
        models are ahead of the clock is held (:attr:`parked`) until a packet or a step needs it taken.  Why:
        a robot's cycle sends it and at once a Sync Read, and the host waits for the read's answer while the
        write is handled.  If the next packet is a Sync/Bulk Read whose answer the write provably cannot change
        (:meth:`_read_unchanged_by`), the read is answered first; a Sync Write of the same registers for the
        same servos after such a read supersedes the held one (:meth:`_answer_holding`), so a robot writing
        faster than the servos' 1 kHz control loop pays for one write a control step, not one a cycle;
        anything else takes the held writes first, as they came.  Either way the replies and the tables are
        the bytes they would be (``tests/ax12emu/bus/test_bus2_held_write.py``).
        """
        if self._parked is None and not self.defer_settling:
            return [self.dispatch(packet, line_bps=line_bps) for packet in self.framer.feed(data, now_s)]
        return [self._answer_holding(packet, line_bps) for packet in self.framer.feed(data, now_s)]

    @property
    def parked(self) -> bool:
        """Whether a Sync Write is held (see :meth:`answer`): a serving loop leaves it to the next packet or the
        next physics step (:meth:`advance_in_pieces`), which take it before anything else."""
        return self._parked is not None

    def close(self) -> None:
        """Take a Sync Write still held for the next packet, then save state (``DecodedBus.close``)."""
        if not self._closed:
            self.take_parked()
        super().close()

    def take_parked_early(self) -> None:
        """Take the held Sync Writes now for the next physics step, which follows with ``take=False``
        (:meth:`advance_in_pieces`), keeping the answer remembered for the read that overtook them.

        Why: a host cycling faster than 1 kHz leaves the serving loop one short pause after each reply, too
        short for taking the write, stepping six servos and making the next answer ready at once; in the pause
        before, the take fits alone.  So the step acts on the goals held one host cycle before it is taken,
        as from a servo whose loop reads its goal registers that long before it shows the step's result (a
        write held meanwhile is the next step's).  Their commands are read back by that step, not by a copy
        of their own (as ``take_parked(show=False)``; a packet that must see them first catches up itself).
        The read that overtook them is answered as before: when it was remembered, taking a write of these
        registers for these servos was found to leave every byte it answers as it is
        (:meth:`_read_unchanged_by`), and nothing else has changed since.
        """
        if self._parked is None:
            return
        before, key = self._changes, self._parked_key
        self.take_parked(show=False)
        for known_key, known in self._overtaken.items():
            if known_key[3] == key and known[0] == before:
                self._overtaken[known_key] = (self._changes, *known[1:])

    def take_parked(self, *, show: bool = True) -> None:
        """Take the held Sync Writes, if any (see :meth:`answer`), as if each had been taken when it came.

        Each servo takes the newest held write it accepts (those it refuses change nothing) and, with
        ``show``, reads its commands back at once, the step they earn owed (``Plant2.show_unstepped``): when
        each came the models were ahead of the clock, so the catch-up right after it would have copied and
        not stepped, and none has stepped since.  Writing the same registers again before a step leaves no
        trace of the earlier goals: the table keeps the last bytes and the firmware plans from its tick's
        state (``XFirmware._start_profile``).  The servos hear the newest write when it came (Realtime
        Tick), unless a later packet reached them since.
        """
        parked = self._parked
        if parked is None:
            return
        self._parked = None
        self._changes += 1
        packet, line_bps, heard_s = parked
        writes = [*self._superseded, packet]
        self._superseded = []
        targets = [servo for servo in self.servos if self._hears(servo, line_bps)]
        for servo in targets:
            last_s = servo.last_instruction_s
            if last_s is None or heard_s > last_s:
                servo.heard(heard_s)
        tried: list[tuple[int, dict[int, bytes]]] = []  # newest first, each read when a servo first needs it
        for servo in targets:
            for k in range(len(writes)):
                if k == len(tried):
                    tried.append(_writes_by_id(writes[-1 - k]))
                address, by_id = tried[k]
                data = by_id.get(servo.id)
                if data is not None and servo.write(address, data) == ErrorNumber.NONE:
                    if show:
                        servo.plant.show_unstepped()
                    break
        # (No IDs to look up again nor EEPROM to save: only writes of Goal and profile registers are held.)

    def _answer_holding(self, packet: InstructionPacket2 | StatusPacket2, line_bps: float | None) -> list[Reply]:
        parked = self._parked
        if parked is not None:
            if not self._waiting and len(self._superseded) < _MAX_SUPERSEDED and isinstance(packet, InstructionPacket2):
                held_key = self._parked_key
                if self._may_hold(packet, line_bps) and self._parked_key == held_key:
                    # Nothing could see the held write (a read went before it), and this one may be held itself
                    # and stores the same registers of the same servos at the same speed: it supersedes the held one.
                    self._superseded.append(parked[0])
                    self._parked, self._waiting = (packet, line_bps, self._heard_now_s()), True
                    return []
                self._parked_key = held_key
            if isinstance(packet, InstructionPacket2) and parked[1] == line_bps:
                replies = self._overtaking_again(packet, line_bps)
                if replies is not None:
                    self._waiting = False
                    return replies
                if self._read_unchanged_by(packet, parked[0], line_bps):
                    self._waiting = False  # overtaken: held on for the next packet or step
                    changes = self._changes
                    replies = self.dispatch(packet, line_bps=line_bps)
                    if self._changes == changes + 2:  # (its own dispatch and catch-up; nothing else changed)
                        self._remember_overtaking(packet, line_bps, replies)
                    self._last_overtaking = (packet, line_bps, parked[0], self._parked_key)
                    self._overtook_at_s = self.clock.now_s()
                    return replies
            self.take_parked()
        if self.defer_settling and isinstance(packet, InstructionPacket2) and self._may_hold(packet, line_bps):
            self._parked, self._waiting = (packet, line_bps, self._heard_now_s()), True
            return []
        return self.dispatch(packet, line_bps=line_bps)

    def _overtaking_again(self, packet: InstructionPacket2, line_bps: float | None) -> list[Reply] | None:
        """The replies a read that overtook the held write gave last time, if nothing has changed since and the
        clock has not reached a servo's next step (:meth:`_remember_overtaking`); None otherwise.

        Why: between two control steps a robot's cycle finds the same state each time (its Sync Write is held
        and superseded, its Sync Read overtakes it), so the read's checks and answers come out the same; only
        the servos' hearing it (Realtime Tick, the last instruction's time) is new.
        """
        if not (packet.crc_ok and packet.id == BROADCAST_ID):
            return None
        raw = params_bytes(packet)
        known = self._overtaken.get((packet.instruction, raw, line_bps, self._parked_key))
        if known is None or known[0] != self._changes or self.faults is not None:
            return None
        clock_s = self.clock.now_s()
        if clock_s >= known[1]:
            return None
        heard_s = clock_s - self.request_lag_s
        for servo in known[2]:
            servo.heard(heard_s)
        self._overtook_at_s = clock_s
        return list(known[3])

    def _remember_overtaking(self, packet: InstructionPacket2, line_bps: float | None, replies: list[Reply]) -> None:
        """Remember what a read that overtook the held write answered, for :meth:`_overtaking_again`.

        Its answer depends on the servos' state and on the clock: so remembered with the count of changes as
        it stands after the answer, and with the time the first servo's model falls due (no step due, none
        owed, no write earning one: :meth:`_read_unchanged_by`).  Not for a read of Realtime Tick, which each
        hearing changes.
        """
        if self.faults is not None:
            return
        raw = params_bytes(packet)
        reads_heard = self._reads_heard.get((packet.instruction, raw))
        if reads_heard is None:  # (the tables' layouts decide it: the same for a read each time)
            heard = [servo.heard_span for servo in self.servos if servo.heard_span is not None]
            reads = _listed_reads(parsed_params(packet.instruction, raw))
            reads_heard = reads is None or any(address < end and start < address + length
                                               for _, address, length in reads for start, end in heard)
            if len(self._reads_heard) >= _MAX_REMEMBERED:
                self._reads_heard.clear()
            self._reads_heard[(packet.instruction, raw)] = reads_heard
        if reads_heard:
            return
        until_s = min(servo.plant.firmware.time_s for servo in self.servos) - GRID_SLACK_S
        targets = [servo for servo in self.servos if self._hears(servo, line_bps)]
        if len(self._overtaken) >= _MAX_REMEMBERED:
            self._overtaken.clear()
        self._overtaken[(packet.instruction, raw, line_bps, self._parked_key)] = (
            self._changes, until_s, targets, tuple(replies))

    def _prepare_overtaking(self) -> None:
        """After a step, when the host is busy elsewhere: answer the read that last overtook a held write as it
        would be answered now, and remember it (:meth:`_remember_overtaking`), so that when the robot's next
        cycle brings the same write and read, the read finds its answer ready.

        Only when nothing is held but a write like the one it overtook (the step took the rest, or left that
        one for the next step: :meth:`take_parked_early`), the read could overtake such a write now, and no
        servo is due a catch-up, so the read's own handling would change nothing but what the servos
        hear (which :meth:`_overtaking_again` does when it comes).
        """
        last = self._last_overtaking
        if last is None or self.faults is not None:
            return
        packet, line_bps, write, key = last
        if self._parked is not None and self._parked_key != key:
            return  # (a write of those registers held for the next step is what the read overtakes next)
        clock_s = self.clock.now_s()
        if clock_s - self._overtook_at_s > _PREPARE_WITHIN_S:
            return  # no robot cycling now: no answer to have ready
        sim_time_s = clock_s - self.request_lag_s
        if any(servo.plant.due(sim_time_s, clock_s) for servo in self.servos):
            return
        held_key, self._parked_key = self._parked_key, key
        try:
            if self._read_unchanged_by(packet, write, line_bps):
                self._remember_overtaking(packet, line_bps, self._listed(packet, line_bps))
        finally:
            self._parked_key = held_key

    def _heard_now_s(self) -> float:
        """The bus time a packet heard now is heard at (as :meth:`dispatch` takes it)."""
        return self.clock.now_s() - self.request_lag_s

    def _may_hold(self, packet: InstructionPacket2, line_bps: float | None) -> bool:
        """A broadcast Sync Write, good CRC, no faults, storing only Goal and profile registers on every servo it
        lists, no Bus Watchdog on, and none of those servos earning a step by it now."""
        if not (packet.instruction == Instruction2.SYNC_WRITE and packet.crc_ok and packet.id == BROADCAST_ID
                and self.faults is None):
            return False
        params = parsed_params(packet.instruction, params_bytes(packet))
        if not isinstance(params, SyncWrite):
            return False
        ids = tuple(servo_id for servo_id, _ in params.writes)
        key = (params.address, params.length, ids, line_bps)
        known = self._holdable.get(key)
        if known is None or known[0] is not self._by_id:  # an ID changed since: other servos, other tables
            listed = set(ids)
            # Every listed servo, heard or not: a servo's baud may change without a new lookup.
            known = (self._by_id, [servo for servo in self.servos if servo.id in listed],
                     all(servo.writes_goals_only(params.address, params.length) for servo in self.servos
                         if servo.id in listed))
            if len(self._holdable) >= _MAX_REMEMBERED:
                self._holdable.clear()
            self._holdable[key] = known
        if not known[2]:
            return False
        # Both below change only with what the count of changes counts (a packet handled, a step, a caller):
        # found once while a robot's cycles supersede and overtake, which change nothing.
        state = self._hold_state
        if state is None or state[0] != self._changes or state[1] is not known[1]:
            state = self._hold_state = (self._changes, known[1], all(servo.watchdog_off for servo in self.servos),
                                        min((servo.plant.writes_earn_step_from_s() for servo in known[1]),
                                            default=math.inf))
        if not state[2]:
            return False  # (a Bus Watchdog that is on times every instruction: a held one would reach it late)
        # A write that earns its servo a step now (``Plant2.write_earns_step``: its model is not ahead of the
        # clock) is taken now: no read could go before it, and the loop takes the step while the host prepares
        # its next packet.
        if self.clock.now_s() >= state[3]:
            return False
        self._parked_key = key
        return True

    def _read_unchanged_by(self, packet: InstructionPacket2, write: InstructionPacket2, line_bps: float | None) -> bool:
        """Whether ``packet`` is a Sync/Bulk Read whose answer and effects are the same before ``write`` (a
        Sync Write :meth:`_may_hold` held, taken at the same time) as after it.

        So when: no faults; no servo's Bus Watchdog is on (the write would restart its interval); and for
        every servo the write stores into, the read reads none of the bytes it stores, nor Indirect Data,
        and the store with the catch-up it earns leaves the sensed registers the read reads as they are
        (``Plant2.goal_write_unseen_by``: no step before the read, commands that keep the frame and the
        torque).  Nothing else the read's handling looks at (ID, baud, Return Delay Time, Status Return
        Level, Torque Enable, Hardware Error Status) is among what the write stores (``Servo2.writes_goals_only``).
        """
        if not (packet.crc_ok and packet.id == BROADCAST_ID and self.faults is None):
            return False
        spec = INSTRUCTION_SPECS.get(packet.instruction)
        if spec is None or spec.broadcast not in _LISTED_READS:
            return False
        raw = params_bytes(packet)
        key = (packet.instruction, raw, self._parked_key)  # the read's bytes; what _may_hold found of the write
        known = self._overtaking.get(key)
        if known is None or known[0] is not self._by_id:
            written = parsed_params(write.instruction, params_bytes(write))
            known = (self._by_id, self._servos_to_judge(parsed_params(packet.instruction, raw), written, line_bps))
            if len(self._overtaking) >= _MAX_REMEMBERED:
                self._overtaking.clear()
            self._overtaking[key] = known
        judged = known[1]
        if judged is None:
            return False
        if not all(servo.watchdog_off for servo in self.servos):
            return False
        clock_s = self.clock.now_s()
        sim_time_s = clock_s - self.request_lag_s
        for servo, spans in judged:
            if not servo.plant.goal_write_unseen_by(sim_time_s, clock_s, spans):
                return False
        return True

    def _servos_to_judge(self, params: object, written: SyncWrite,
                         line_bps: float | None) -> list[tuple[Servo2, tuple[tuple[int, int], ...]]] | None:
        """What :meth:`_read_unchanged_by` finds from the IDs and the tables' layouts alone: each servo the write
        stores into whose registers the read reads, with the sensed spans it reads (``Plant2.sensed_spans``);
        None if the read reads bytes the write stores, Indirect Data or a trajectory register of such a servo,
        or is malformed."""
        reads = _listed_reads(params)
        if reads is None:
            return None
        start, end = written.address, written.address + written.length
        listed = {servo_id for servo_id, _ in written.writes}
        read_by: dict[Servo2, list[tuple[int, int]]] = {}
        for servo_id, address, length in reads:
            for servo in self._by_id.get(servo_id, ()):
                read_by.setdefault(servo, []).append((address, length))
        judged = []
        for servo in self.servos:
            if servo not in read_by or servo.id not in listed:
                continue  # the write stores nothing the read reads (heard or not: a baud may change without a new lookup)
            spans: tuple[tuple[int, int], ...] = ()
            for address, length in read_by[servo]:
                if address < end and start < address + length or servo.table.reads_indirect(address, length):
                    return None
                more = servo.plant.sensed_spans(address, length)
                if more is None:
                    return None
                spans += more
            judged.append((servo, spans))
        return judged

    def dispatch(self, packet: InstructionPacket2 | StatusPacket2, *, line_bps: float | None = None) -> list[Reply]:
        """Run one decoded packet on the servos it reaches; return their replies, timed."""
        if isinstance(packet, StatusPacket2):
            return []  # another device's answer: every servo hears it, none acts
        self._changes += 1
        clock_s = self.clock.now_s()
        now_s = clock_s - self.request_lag_s
        broadcast = packet.id == BROADCAST_ID
        spec = INSTRUCTION_SPECS.get(packet.instruction)
        kind = spec.broadcast if spec is not None else None
        faults = self.faults
        reads = (self._sensed_reads(packet) if self.defer_settling and broadcast and packet.crc_ok
                 and kind in _LISTED_READS and faults is None else None)
        self.catch_up(now_s, clock_s, reads)
        targets = [s for s in (self.servos if broadcast else self._by_id.get(packet.id, ()))
                   if self._hears(s, line_bps)]
        if log.isEnabledFor(logging.DEBUG):
            log.debug("rx id=%d inst=%#04x params=%s -> IDs %s", packet.id, packet.instruction, packet.params.hex(" "),
                      [s.id for s in targets])
        # Servos whose Secondary ID this is (and not their ID: "ID(7) has a higher priority").
        grouped = [] if broadcast else [s for s in self.servos if s.secondary_id == packet.id and s.id != packet.id
                                        and self._hears(s, line_bps)]
        if faults is not None:  # an unplugged servo hears nothing (ax12emu.faults: wire faults)
            targets = [s for s in targets if faults.admit(s)]
            grouped = [s for s in grouped if faults.admit(s)]
        for servo in (*targets, *grouped):
            servo.heard(now_s)
        if not packet.crc_ok or not broadcast:
            replies = [] if kind in _REQUIRED_BROADCAST and packet.crc_ok else self._each_own(packet, targets)
            if packet.crc_ok and kind not in _REQUIRED_BROADCAST:
                for servo in grouped:
                    handle2(servo, packet, secondary=True)
        elif kind in _LISTED_READS:
            replies = self._listed(packet, line_bps)
        elif packet.instruction == Instruction2.PING:
            replies = self._broadcast_ping(packet, targets)
        elif packet.instruction == Instruction2.SYNC_WRITE:
            sync_write_all(targets, packet)
            replies = []
        elif kind in _EXECUTED_SILENTLY or kind is Broadcast.REQUIRED_SILENT:
            for servo in targets:
                handle2(servo, packet)
            replies = []
        else:
            replies = []  # Read to the broadcast ID, or an undefined instruction: not executed
        if packet.crc_ok and kind not in _LISTED_READS and packet.instruction != Instruction2.PING:
            self._after_writes()
        if faults is not None and replies:
            replies = faults.on_replies(replies)
        return replies

    def _sensed_reads(self, packet: InstructionPacket2) -> dict[Servo2, tuple[tuple[int, int], ...] | None] | None:
        """For a Sync/Bulk Read (or a fast one): each listed servo's sensed-register spans its answer reads
        (``Plant2.sensed_spans``; None where it reads Indirect Data or a register a command changes at once)."""
        params = parsed_params(packet.instruction, params_bytes(packet))
        known = self._sensed_by_read.get(params)
        if known is not None and known[0] is self._by_id:  # no ID changed since: the same servos, the same tables
            return known[1]
        reads = _listed_reads(params)
        if reads is None:
            return None
        spans_by_servo: dict[Servo2, tuple[tuple[int, int], ...] | None] = {}
        by_id = self._by_id
        for servo_id, address, length in reads:
            for servo in by_id.get(servo_id, ()):
                spans = None if servo.table.reads_indirect(address, length) else servo.plant.sensed_spans(address, length)
                if servo in spans_by_servo:  # listed twice: both reads count
                    before = spans_by_servo[servo]
                    spans = None if before is None or spans is None else before + spans
                spans_by_servo[servo] = spans
        if len(self._sensed_by_read) >= _MAX_REMEMBERED:
            self._sensed_by_read.clear()
        self._sensed_by_read[params] = (self._by_id, spans_by_servo)
        return spans_by_servo

    def _each_own(self, packet: InstructionPacket2, targets: list[Servo2]) -> list[Reply]:
        if packet.id == BROADCAST_ID:
            return []  # a corrupt broadcast: nobody may answer it
        replies = []
        for servo in targets:
            outcome = handle2(servo, packet)
            if outcome.reply is not None:
                replies.append(Reply(outcome.reply_id, outcome.reply, outcome.delay_s, servo.baud_bps))
        if len(replies) > 1:  # servos sharing an ID (a fault) answer at once: their answers collide
            return [collide(replies)]
        return replies

    def _broadcast_ping(self, packet: InstructionPacket2, targets: list[Servo2]) -> list[Reply]:
        replies = []
        for servo in sorted(targets, key=lambda s: s.id):
            outcome = handle2(servo, packet._replace(id=servo.id))
            if outcome.reply is None:
                continue
            # A slot as wide as an answer after the longest Return Delay Time: each servo answers in its own
            # whatever delay the others have (slots of their own delays overlapped: one servo left at the
            # factory 500 us among servos set to 0 collided with the next ID's answer).
            wire_s = len(outcome.reply) * BITS_PER_BYTE / servo.baud_bps
            replies.append(Reply(servo.id, outcome.reply, servo.return_delay_s + servo.id * (wire_s + MAX_RETURN_DELAY_S),
                                 servo.baud_bps, servo.id * wire_s))
        return replies

    def _listed(self, packet: InstructionPacket2, line_bps: float | None) -> list[Reply]:
        """Sync/Bulk Read and their fast forms: the listed servos answer in list order (see the module docstring).

        Remembered: a robot sends the same Sync Read every cycle, and its answers are a function of the
        instruction, its parameters, the line speed, which servo has each ID and, in the row of each servo
        consulted, the bytes it reads and the registers that decide whether and how it answers (ID, Baud
        Rate, Return Delay Time, Status Return Level, Hardware Error Status for the Alert bit:
        :func:`_answer_spans`).  So while no fault is set, the lookup is the same and all those bytes are
        as they were when the answers were made, they are those answers again; a step, write, reboot or
        torque change that changes any of them makes them anew, and a new goal in a register the read
        does not read does not.
        """
        raw = params_bytes(packet)
        key = (packet.instruction, raw, line_bps)
        if self.faults is None:
            known = self._listed_answers.get(key)
            if known is not None and known[0] is self._by_id:
                for check in known[1]:
                    row = check[0].table.row
                    if row == check[3]:
                        continue  # the whole row as it was last seen here: one comparison instead of several
                    if check[1](row) != check[2]:
                        break
                    check[3] = bytes(row)
                else:
                    return list(known[2])
        consulted: list[tuple[tuple[Servo2, ...], int, int]] = []
        replies = self._listed_anew(packet, raw, line_bps, consulted)
        if self.faults is None and all(len(found) == 1 for found, _, _ in consulted):  # (servos sharing an ID: a fault)
            spans: dict[Servo2, list[tuple[int, int]]] = {}
            for (servo,), address, length in consulted:
                spans.setdefault(servo, []).append((address, length))
            checks = []
            pickers = self._answer_pickers
            for servo, reads in spans.items():
                pick = pickers.get((servo, *reads))
                if pick is None:
                    if len(pickers) >= _MAX_REMEMBERED:
                        pickers.clear()
                    pick = pickers[(servo, *reads)] = _answer_spans(servo, reads)
                checks.append([servo, pick, pick(servo.table.row), bytes(servo.table.row)])
            if len(self._listed_answers) >= _MAX_REMEMBERED:
                self._listed_answers.clear()
            self._listed_answers[key] = (self._by_id, tuple(checks), list(replies))
        return replies

    def _listed_anew(self, packet: InstructionPacket2, raw: bytes, line_bps: float | None,
                     consulted: list[tuple[tuple[Servo2, ...], int, int]]) -> list[Reply]:
        """:meth:`_listed` made from the servos' rows; ``consulted`` gets the servos under each ID it looked at,
        with the address and length read there."""
        params = parsed_params(packet.instruction, raw)
        if isinstance(params, SyncRead):
            reads = [(servo_id, params.address, params.length) for servo_id in params.ids]
        elif isinstance(params, BulkRead):
            reads = list(params.reads)
        else:
            return []  # malformed: no listed servo can tell it is listed
        fast = INSTRUCTION_SPECS[packet.instruction].broadcast is Broadcast.REQUIRED_COMBINED_ANSWER
        answered: list[tuple[Servo2, int, bytes]] = []
        #: Servos answering at once to an ID another servo also has (a fault): k in answered -> their answers.
        twins: dict[int, list[tuple[Servo2, int, bytes]]] = {}
        by_id, faults = self._by_id, self.faults
        for servo_id, address, length in reads:
            found = by_id.get(servo_id, ())
            if found:
                consulted.append((tuple(found), address, length))
            servo = found[0] if found else None
            if (servo is None or not (line_bps is None or self._hears(servo, line_bps))
                    or not answers(servo, packet.instruction) or packet.instruction in servo.spec.unsupported_instructions
                    or (faults is not None and not faults.admit(servo))):
                break
            data, error = servo.table.read(address, length)  # listed_read's, without the call
            if len(found) > 1:
                twins[len(answered)] = [(twin, *listed_read(twin, address, length)) for twin in found[1:]
                                        if self._hears(twin, line_bps) and answers(twin, packet.instruction)
                                        and (self.faults is None or self.faults.admit(twin))]
            answered.append((servo, error, data))
        if not answered:
            return []
        replies: list[Reply] = []
        if fast:
            # The first servo's header announces every listed share; those never sent stand in as zeros.
            if 1 + sum(4 + length for _, _, length in reads) > MAX_LENGTH:
                return []  # no LENGTH can announce them: nobody can start the packet
            parts = [FastStatusPart(0, 0, bytes(length)) for _, _, length in reads]
            for k, (servo, error, data) in enumerate(answered):
                parts[k] = FastStatusPart(servo.id, status_byte(servo, error), data)
            pieces = fast_status_pieces(parts)[: len(answered)]
            if twins:  # servos sharing an ID (a fault) send their shares in its turn, at once
                pieces = _fast_shares_on_wire(pieces, parts, answered, twins)
            at_s = answered[0][0].return_delay_s
            wire_s = 0.0
            for k, ((servo, _, _), piece) in enumerate(zip(answered, pieces)):
                # Each share is named by its servo (a fault on some IDs reaches the packet they share in).
                replies.append(Reply(servo.id, piece, at_s + wire_s, servo.baud_bps, wire_s, continues=k > 0))
                wire_s += len(piece) * BITS_PER_BYTE / servo.baud_bps
            return replies
        at_s = wire_s = 0.0
        for k, (servo, error, data) in enumerate(answered):
            servo_id, baud = servo.id, servo.baud_bps
            status = _status_packet(servo_id, status_byte(servo, error), data)
            at_s += servo.return_delay_s
            reply = Reply(servo_id, status, at_s + wire_s, baud, wire_s)
            if twins and k in twins:  # the same turn: their answers collide on the wire
                reply = collide([reply, *(Reply(twin.id, encode_status2(twin.id, status_byte(twin, twin_error), twin_data),
                                                at_s + wire_s + twin.return_delay_s - servo.return_delay_s, twin.baud_bps,
                                                wire_s)
                                          for twin, twin_error, twin_data in twins[k])])
            replies.append(reply)
            wire_s += len(status) * BITS_PER_BYTE / baud
        return replies


#: The longest Return Delay Time (254 in 2 us units, e-manual "Return Delay Time(9)"): the width a broadcast Ping's
#: slot leaves for a servo's delay.
MAX_RETURN_DELAY_S = 254 * 2e-6


def _writes_by_id(packet: InstructionPacket2) -> tuple[int, dict[int, bytes]]:
    """A held Sync Write's address and the data it lists first under each ID (as ``sync_write_all`` reads it)."""
    params = parsed_params(packet.instruction, params_bytes(packet))
    assert isinstance(params, SyncWrite)  # only well-formed ones are held (Bus2._may_hold)
    return params.address, first_writes(params)


def _answer_spans(servo: Servo2, reads: list[tuple[int, int]]) -> Callable[[bytearray], tuple]:
    """A function picking from ``servo``'s row every byte its answers to ``reads`` (address, length) depend on.

    Those are the bytes read and the registers the bus and the status packet consult: ID, Baud Rate,
    Return Delay Time, Status Return Level and Hardware Error Status (the Alert bit).  A read of Indirect
    Data depends on the Indirect Addresses and what they point at, so it picks the whole row.  Adjacent
    spans are picked as one.
    """
    table = servo.table
    if any(table.reads_indirect(address, length) for address, length in reads):
        return lambda row: (bytes(row),)
    spans = [(address, address + length) for address, length in reads]
    spans += [(at, at + 1) for at in (servo._id_at, servo._baud_at, servo._return_delay_at, servo._level_at)]
    error = servo._hardware_error
    if error is not None:
        spans.append((error.address, error.end))
    merged: list[list[int]] = []
    for start, end in sorted(spans):
        if merged and start <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], end)
        else:
            merged.append([start, end])
    return operator.itemgetter(*(slice(start, end) for start, end in merged), slice(0, 0))


def _fast_shares_on_wire(pieces: list[bytes], parts: list[FastStatusPart],
                         answered: list[tuple[Servo2, int, bytes]],
                         twins: dict[int, list[tuple[Servo2, int, bytes]]]) -> list[bytes]:
    """A Fast Sync/Bulk Read's shares as the wire carries them when servos share a listed ID (a fault).

    Every servo with the ID sends its share in the ID's turn, at once (a different Return Delay Time of
    the first share's twin is not modelled), so their bytes collide, AND-ed as ``reply.collide`` does for
    other answers.  Each servo's CRC is the running CRC of what it heard before its share
    (``packets2.fast_status_pieces``), so the servos after a collision continue from the collided bytes.
    A twin of the first listed ID sends the header too, announcing every listed share as its twin does
    (both read the same instruction), so the two headers agree.
    """
    out: list[bytes] = []
    crc = 0
    for k, (servo, _, _) in enumerate(answered):
        sent = [pieces[k], *(fast_status_pieces([*parts[:k], FastStatusPart(twin.id, status_byte(twin, error), data),
                                                 *parts[k + 1:]])[k]
                             for twin, error, data in twins.get(k, ()))]
        wire = collide([Reply(BROADCAST_ID, piece[:-2] + crc16(piece[:-2], crc).to_bytes(2, "little"), 0.0,
                              servo.baud_bps) for piece in sent]).data
        out.append(wire)
        crc = crc16(wire, crc)
    return out
