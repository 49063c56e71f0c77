"""A Protocol 1.0 wire with MX-series servos (each its own model's table and X-series firmware), AX-12As beside them if any.

Why it exists: the AX-12 bus (:class:`~.bus.Bus`) serves tables of the AX-12's shape from numpy
rows under one batched plant, and its fast paths (the reply cache, the plant's batched step) are
what keep a polling host fast (``tools/bench_protocol.py``).  The MX series' 1.0 tables and
firmware differ (:mod:`ax12emu.servo.servo1x`), so they get their own servos here, and AX-12As
on the same wire stay on an AX-12 bus held inside: one framer frames the wire's bytes once and each
packet goes to the AX-12 bus (:meth:`Bus.dispatch`) and to the MX servos, as every servo on a real
wire hears every packet.  A wire of AX-12As alone stays a plain :class:`~.bus.Bus`, so its speed
does not change.

Who answers, and when (ROBOTIS e-manual, "Protocol 1.0", https://emanual.robotis.com/docs/en/dxl/protocol1/):
as on the AX-12 bus (a packet to one ID: that servo after its Return Delay Time; broadcast: executed by
all, answered by none but PING, whose answers collide), plus Bulk Read (0x92) to the broadcast ID:
"Dynamixel with ID 2 monitors the status packet being sent from ID 1 ... and when device ID 1's
status packet transmission is completed, ID 2 sends its own status packet" -- each listed servo
answers its Return Delay Time after the previous one's status packet ended, in list order; a listed ID
no MX answers (absent, another baud, an AX-12A, which has no Bulk Read) breaks the chain there, as
the next servo waits for a status packet that never comes.

Faults (``bus.faults``, :class:`ax12emu.faults.injection.Faults1X`): the wire's act on every reply
of the wire (AX-12As' too) and on each MX servo (unplugged, it hears nothing and a Bulk Read's chain
breaks at it); an MX servo's own (an error, a blocked shaft, pinned readings) act inside its
firmware model, the AX-12As' through their bus's own :class:`~ax12emu.faults.injection.Faults`.
Not modelled for MX servos: the busy time after an EEPROM write (the AX-12's measured figure is an
AX-12's); the live view shows them and state persists as on the other buses.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator

from ax12emu.protocol.describe import describe_instruction
from ax12emu.protocol.framing import Framer
from ax12emu.protocol.packets import BROADCAST_ID, MAX_ID, Instruction, InstructionPacket, encode_status, parse_bulk_read
from ax12emu.protocol.servo_models import ServoModel
from ax12emu.servo.request_handler1x import handle1x, listed_read, status_byte
from ax12emu.servo.servo1x import Servo1X, Servo1XOptions

from .bus import Bus, Interceptor
from .clock import VirtualClock, WallClock
from .decoded import DecodedBus
from .lookup import check_ids
from .reply import BITS_PER_BYTE, Reply, collide
from .state_store import StateStore

__all__ = ["Bus1X", "PlantFactory"]

log = logging.getLogger(__name__)

#: Builds one MX servo's plant (firmware model behind its table) from its model file and the servo.
PlantFactory = Callable[[ServoModel, Servo1X], object]


class Bus1X(DecodedBus):
    """MX-series servos on a Protocol 1.0 wire, and optionally an AX-12 bus sharing it."""

    #: Replies to one packet may collide (broadcast PING): the serving loop merges them.
    replies_in_sequence = False
    #: The protocol its servos speak (``protocol=`` of the harness and the faults).
    protocol = 1.0

    def __init__(
        self,
        servos: Iterable[tuple[int, ServoModel]],
        plant: PlantFactory,
        *,
        ax_bus: Bus | None = None,
        clock: WallClock | VirtualClock | None = None,
        options: Servo1XOptions = Servo1XOptions(),
        state_store: StateStore | None = None,
    ) -> None:
        slots = list(servos)
        if not slots:
            raise ValueError("a bus needs at least one servo")
        check_ids([servo_id for servo_id, _ in slots] + (ax_bus.slots if ax_bus is not None else []), MAX_ID)
        if ax_bus is not None and clock is not None and ax_bus.clock is not clock:
            raise ValueError("the AX-12 bus and the MX servos of one wire must keep one clock")
        self.clock = ax_bus.clock if ax_bus is not None else (clock if clock is not None else WallClock())
        self.ax_bus = ax_bus
        if ax_bus is not None:
            ax_bus.logs_every_packet = False
        self.slots_mx = [servo_id for servo_id, _ in slots]
        self.framer = Framer()
        self.servos_mx: list[Servo1X] = [
            Servo1X(spec, lambda servo, s=spec: plant(s, servo), servo_id=servo_id, index=index, options=options)
            for index, (servo_id, spec) in enumerate(slots)
        ]
        self.state_store = state_store
        if state_store is not None:
            for slot, servo in zip(self.slots_mx, self.servos_mx):
                if state_store.load(slot, servo.table):
                    servo.plant.command()
                    servo.power_on()
        self._by_id: dict[int, list[Servo1X]] = {}
        self.reindex()
        #: How far behind the clock physics may be when a packet is served (see ``Bus.request_lag_s``).
        self._request_lag_s = 0.0
        #: Injected faults (``ax12emu.faults.injection.Faults1X``); None costs one test per packet.
        self.faults: Interceptor | None = None
        self._closed = False

    # -- lookup ------------------------------------------------------------------------
    @property
    def servos(self) -> list:
        """The MX servos, then the AX-12As."""
        return [*self.servos_mx, *(self.ax_bus.servos if self.ax_bus is not None else ())]

    @property
    def slots(self) -> list[int]:
        return [*self.slots_mx, *(self.ax_bus.slots if self.ax_bus is not None else ())]

    @property
    def ids(self) -> list[int]:
        return [servo.id for servo in self.servos]

    def reindex(self) -> None:
        by_id: dict[int, list[Servo1X]] = {}
        for servo in self.servos_mx:
            by_id.setdefault(servo.id, []).append(servo)
        self._by_id = by_id
        if self.ax_bus is not None:
            self.ax_bus.reindex()

    def servo(self, servo_id: int, protocol: float | None = None):
        """The (first) servo answering to ``servo_id`` now, MX or AX-12A; ``protocol``, if given, must be 1.0 (ValueError)."""
        if protocol is not None and protocol != self.protocol:
            raise ValueError(f"protocol={protocol}: this bus's servos all speak Protocol {self.protocol}")
        found = self._by_id.get(servo_id)
        if found:
            return found[0]
        if self.ax_bus is not None:
            try:
                return self.ax_bus.servo(servo_id)
            except KeyError:
                pass
        raise KeyError(f"no servo with ID {servo_id} on the bus (IDs now: {sorted(self.ids)})")

    def holder(self, servo) -> "Bus1X | Bus":
        """The bus that holds ``servo``: the AX-12 bus inside for an AX-12A (its model, its faults), else this one."""
        if self.ax_bus is not None and any(servo is s for s in self.ax_bus.servos):
            return self.ax_bus
        return self

    @property
    def request_lag_s(self) -> float:
        return self._request_lag_s

    @request_lag_s.setter
    def request_lag_s(self, lag_s: float) -> None:
        self._request_lag_s = lag_s
        if self.ax_bus is not None:
            self.ax_bus.request_lag_s = lag_s

    @property
    def physics_step_s(self) -> float:
        steps = [servo.plant.firmware.step_s for servo in self.servos_mx]
        if self.ax_bus is not None:
            steps.append(self.ax_bus.physics_step_s)
        return min(steps)

    # -- time --------------------------------------------------------------------------
    def catch_up(self, sim_time_s: float, clock_s: float | None = None) -> None:
        for servo in self.servos_mx:
            if servo.plant.due(sim_time_s, clock_s):
                servo.plant.catch_up(sim_time_s, clock_s)

    def advance(self) -> bool:
        sim_time_s = self.clock.now_s()
        due = any(servo.plant.due(sim_time_s) for servo in self.servos_mx)
        self.catch_up(sim_time_s)
        if self.ax_bus is not None:
            due = self.ax_bus.advance() or due
        return due

    def advance_in_pieces(self) -> Iterator[None]:
        sim_time_s = self.clock.now_s()
        for servo in self.servos_mx:
            yield from servo.plant.tick(sim_time_s)
        if self.ax_bus is not None:
            yield from self.ax_bus.advance_in_pieces()

    # -- bytes in, replies out (receive, answer, expire: DecodedBus) ---------------------
    def dispatch(self, packet: InstructionPacket, *, line_bps: float | None = None) -> list[Reply]:
        """Run one packet on every servo it reaches (AX-12As first); return the replies."""
        replies = self.ax_bus.dispatch(packet, line_bps=line_bps) if self.ax_bus is not None else []
        now_s = self.clock.now_s()
        self.catch_up(now_s - self._request_lag_s, now_s)
        broadcast = packet.id == BROADCAST_ID
        targets = [s for s in (self.servos_mx if broadcast else self._by_id.get(packet.id, ())) if self._hears(s, line_bps)]
        faults = self.faults
        if faults is not None:  # an unplugged servo hears nothing (ax12emu.faults: wire faults)
            targets = [s for s in targets if faults.admit(s)]
        if log.isEnabledFor(logging.DEBUG):  # named by each MX's own table (the AX-12's names were wrong for it)
            tables = {s.id: s.table.layout for s in self.servos_mx}
            log.debug("rx %s -> MX IDs %s", describe_instruction(packet, next(iter(tables.values())), tables),
                      [s.id for s in targets])
        for servo in targets:
            servo.heard(now_s)
        if broadcast and packet.instruction == Instruction.BULK_READ and packet.checksum_ok:
            replies = [*replies, *self._bulk_read(packet, line_bps)]
            return faults.on_replies(replies) if faults is not None and replies else replies
        for servo in targets:
            baud = servo.baud_bps  # the rate the reply goes out at: a Baud Rate write takes effect after it
            outcome = handle1x(servo, packet)
            if outcome.reply is not None:
                replies.append(Reply(outcome.reply_id, outcome.reply, outcome.delay_s, baud))
        if targets and packet.checksum_ok and packet.instruction not in (Instruction.PING, Instruction.READ):
            self._after_writes()
        if faults is not None and replies:  # the AX-12As' too: the wire's faults are the wire's
            replies = faults.on_replies(replies)
        return replies

    def _bulk_read(self, packet: InstructionPacket, line_bps: float | None) -> list[Reply]:
        requests = parse_bulk_read(bytes(packet.params))
        if requests is None:
            return []  # malformed: no listed servo can tell it is listed
        replies: list[Reply] = []
        at_s = 0.0
        for request in requests:
            found = self._by_id.get(request.servo_id)
            servo = found[0] if found else None
            # Status Return Level 0 answers PING only; an unplugged servo hears nothing
            if (servo is None or not self._hears(servo, line_bps) or servo.status_return_level < 1
                    or (self.faults is not None and not self.faults.admit(servo))):
                break
            error, data = listed_read(servo, request.address, request.length)
            status = encode_status(servo.id, status_byte(servo, error), data)
            at_s += servo.return_delay_s
            reply = Reply(servo.id, status, at_s, servo.baud_bps)
            # Servos sharing the ID (a fault) each heard the one before and answer in its turn, at once: their
            # answers collide on the wire (only the first answered, clean, and the other's value was never seen).
            twins = [twin for twin in found[1:] if self._hears(twin, line_bps) and twin.status_return_level >= 1
                     and (self.faults is None or self.faults.admit(twin))]
            if twins:
                answers = [reply]
                for twin in twins:
                    twin_error, twin_data = listed_read(twin, request.address, request.length)
                    answers.append(Reply(twin.id, encode_status(twin.id, status_byte(twin, twin_error), twin_data),
                                         at_s - servo.return_delay_s + twin.return_delay_s, twin.baud_bps))
                reply = collide(answers)
            replies.append(reply)
            at_s += len(reply.data) * BITS_PER_BYTE / servo.baud_bps
        return replies

    # -- life cycle (save_state, __enter__, __exit__: DecodedBus) -----------------------
    def _persisted(self) -> Iterable[tuple[int, Servo1X]]:
        return zip(self.slots_mx, self.servos_mx)  # the AX-12As' are their bus's to keep

    def close(self) -> None:
        if not self._closed:
            super().close()
            if self.ax_bus is not None:
                self.ax_bus.close()
