"""The conformance checks, one small function each, in a table.

Why it exists: the same checks must judge the emulator and a real AX-12,
so each one states what Protocol 1.0 (e-manual, 2006 manual) says a servo
does and measures what the device did.  Every Protocol 1.0 servo (AX-12A,
AX-18A, the MX series) keeps its Model Number at address 0, so the suite
reads it first (:meth:`Context.identify`) and takes that model file's table:
its registers' addresses, sizes, ranges and factory defaults, and what its
firmware knows (:func:`knows_bulk_read`).  The AX-12A's is ``--profile``'s
edition of its table.  A check returns its measured figure
(pass), raises :class:`Failed` with the figure (fail) or :class:`Skipped`
with the reason, or returns a :class:`Note` where the sources allow more
than one behaviour (the figure says which one this device shows).

After every write into the EEPROM area a check waits before the next packet,
as any client of a real AX-12 must: the servo ignores packets while it writes
its EEPROM (:data:`EEPROM_WAIT_S_PER_BYTE`).

Every check restores what it wrote (in ``finally``), so the non-destructive
set leaves the device's table as it found it; ``destructive`` checks (ID,
baud rate, RESET) also put things back, but a failure halfway may leave the
servo at another ID or baud, which the report says.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, ClassVar, NamedTuple

from ax12emu.bus.wire import servo_family
from ax12emu.protocol.control_table import AX12_MODEL, EEPROM_END, Access, layout
from ax12emu.protocol.describe import describe_error
from ax12emu.protocol.packets import BROADCAST_ID, Instruction, StatusError, encode_instruction
from ax12emu.protocol.registers import Entry, Layout
from ax12emu.protocol.servo_models import ServoModel, model, model_names
from ax12emu.servo.servo1x import baud_bps_1x

from .link import Link, Response

__all__ = ["Check", "CHECKS", "Context", "Failed", "Skipped", "Note", "DYNAMIC", "table_differences", "knows_bulk_read",
           "model_for_number1"]

#: Registers the firmware changes by itself; never compared.  The AX tables' sensed values, and the MX
#: series' Realtime Tick(50) (milliseconds since power-up) and Current(68) (2048 + the sensed current).
DYNAMIC = frozenset(
    {"present_position", "present_speed", "present_load", "present_voltage", "present_temperature", "moving",
     "realtime_tick", "current"}
)
#: Where every Protocol 1.0 table keeps Model Number (2 bytes at address 0: e-manual, each 1.0 model's
#: "Control Table"), read before the servo's model, hence its table, is known.
MODEL_NUMBER_AT = layout().by_name["model_number"]
#: An instruction code no Protocol 1.0 firmware defines (the e-manual's instruction table stops at 0x06, 0x08,
#: 0x83 and 0x92): the undefined instruction sent to a servo whose firmware knows Bulk Read.
UNDEFINED_INSTRUCTION = 0x50
#: Host bit rates a USB adapter offers: a Baud Rate value's rate (2,000,000 / (value + 1), e-manual "Baud
#: Rate(4)") is taken as the nearest of them within a UART's 3 % (34 gives 57,142 bps: the adapter's 57,600).
_HOST_RATES_BPS = (9600, 19200, 38400, 57600, 115200, 200_000, 250_000, 400_000, 500_000, 1_000_000, 2_000_000)
#: How long to leave a servo alone per byte written into its EEPROM: it answers the write,
#: then ignores packets while it writes (xevelabs' USB2AX protocol notes: "up to 9 ms per
#: byte based on the ATMega8 datasheet", measured about 6 +/- 1 ms), so the datasheet's bound.
EEPROM_WAIT_S_PER_BYTE = 0.009
#: Baud Rate register value the baud check moves a servo to, and the one it takes where the servo runs at that
#: already (the MX series' factory 34): 57,600 and 1,000,000 bps, rates every AX and MX page lists.
_SLOW_BAUD_REGISTER, _FAST_BAUD_REGISTER = 34, 1


class Failed(Exception):
    """The device did not do what the protocol says; the message is the measured figure."""


class Skipped(Exception):
    """The check cannot run here; the message says why."""


class Note(NamedTuple):
    """A behaviour the sources leave open: not a failure, the figure says what was seen."""

    figure: str


def expect(condition: bool, figure: str) -> None:
    """Fail with ``figure`` unless ``condition``."""
    if not condition:
        raise Failed(figure)


def put_all(ctx: Any, puts: "list[tuple[Any, ...]]") -> None:
    """``ctx.put(*args)`` for each of ``puts``, every one tried though one fails (a restore in ``finally`` that stopped
    at the first unanswered put left the other servos changed); :class:`Failed` naming those that failed."""
    failed = []
    for args in puts:
        try:
            ctx.put(*args)
        except (Failed, OSError) as exc:
            failed.append(f"{exc}")
    expect(not failed, "could not put back: " + "; ".join(failed))


def host_bps(baud_register: int) -> int:
    """The host rate that talks to a servo whose Baud Rate register is ``baud_register`` (the servo's own rate,
    :func:`~ax12emu.servo.servo1x.baud_bps_1x`, taken as the nearest an adapter offers)."""
    nominal = baud_bps_1x(baud_register)
    nearest = min(_HOST_RATES_BPS, key=lambda rate: abs(rate - nominal))
    return nearest if abs(nearest - nominal) <= 0.03 * nominal else round(nominal)


def model_for_number1(number: int) -> ServoModel | None:
    """The shipped Protocol 1.0 model file whose model number is ``number``."""
    return next((model(key) for key in model_names()
                 if model(key).model_number == number and "1.0" in model(key).protocols), None)


def knows_bulk_read(spec: ServoModel) -> bool:
    """Whether ``spec``'s Protocol 1.0 firmware knows Bulk Read (0x92).

    The MX series' does (:mod:`ax12emu.servo.request_handler1x`: "adds Bulk Read (0x92), which the AX-12
    lacks"); the AX series' answers it with Instruction Error, as any undefined instruction (the 2006 AX-12
    manual lists no 0x92).  The model files do not say it for Protocol 1.0 (``unsupported_instructions`` is
    Protocol 2.0's), so the suite asks the one place that gives each Protocol 1.0 model its firmware, the
    AX series' or the MX series', as the emulator itself does when it builds a wire.
    """
    return servo_family(spec.key) == "MX"


def table_differences(before: bytes, after: bytes, table: Layout | str, ignore: frozenset[str] = DYNAMIC) -> list[str]:
    """Registers of ``table`` (a layout, or an AX-12A profile's name) that differ between two images, as "name a->b"."""
    out = []
    for entry in (layout(table) if isinstance(table, str) else table).entries:
        if entry.name in ignore:
            continue
        a = int.from_bytes(before[entry.address : entry.end], "little")
        b = int.from_bytes(after[entry.address : entry.end], "little")
        if a != b:
            out.append(f"{entry.name} {a}->{b}")
    return out


class Transactions:
    """The link's transactions as both suites' checks make them: the answer one servo must give, silence, round trips.

    Protocol 1.0's packets here; ``checks2.Context2`` names Protocol 2.0's (class attributes, below).
    """

    #: The protocol's instruction packet encoder, its instruction names, and the status packet's field and word
    #: for "its checksum matched".
    encode_packet: ClassVar[Callable[..., bytes]] = staticmethod(encode_instruction)
    instructions: ClassVar[type[IntEnum]] = Instruction
    check_ok: ClassVar[tuple[str, str]] = ("checksum_ok", "checksum")
    #: Bytes of a Ping and its status on the wire (Protocol 1.0: 6 and 6).
    ping_exchange_bytes: ClassVar[int] = 12
    link: Any

    def transact(self, packet: bytes, *, timeout_s: float | None = None) -> Any:
        """``link.transact``."""
        return self.link.transact(packet, timeout_s=timeout_s)

    def silent(self, packet: bytes) -> bool:
        """Send ``packet`` and report whether nothing came back within the link's silence window."""
        return self.transact(packet, timeout_s=self.link.silence_s).status is None

    def answers(self, packet: bytes) -> bool:
        """Send ``packet`` and report whether a status packet came back within the reply timeout."""
        return self.transact(packet).status is not None

    def status(self, servo_id: int, instruction: int, params: bytes = b"", *, timeout_s: float | None = None) -> Any:
        """A transaction that must be answered by ``servo_id`` with a matching checksum."""
        response = self.transact(self.encode_packet(servo_id, instruction, params), timeout_s=timeout_s)
        known = self.instructions._value2member_map_
        name = known[instruction].name if instruction in known else f"{instruction:#04x}"
        expect(response.status is not None, f"no reply to {name} id={servo_id}")
        status = response.status
        field_name, word = self.check_ok
        expect(getattr(status, field_name), f"reply to {name} id={servo_id} has a bad {word}")
        expect(status.id == servo_id, f"reply to {name} id={servo_id} came from id={status.id}")
        return status

    def refusal(self, check: "Check") -> str | None:
        """Why ``check`` must not run on this bus (None: it may); Protocol 2.0's Secondary IDs give reasons."""
        return None

    def put_back_levels(self) -> str:
        """Put back every Status Return Level :meth:`raise_levels` raised; the figure says which (Failed if one stays)."""
        raised: dict[int, int] = getattr(self, "raised", {})
        wrong = []
        for servo_id, level in raised.items():
            try:
                entry = self.entry(servo_id, "status_return_level")
                # at the level put back (below 2) the WRITE gets no answer: listened to for the silence window
                self.transact(self.encode_packet(servo_id, self.instructions["WRITE"], self.address_bytes(entry.address)
                                                 + bytes((level,))), timeout_s=self.link.silence_s)
                now = self.get(servo_id, "status_return_level")
            except (Failed, OSError) as exc:
                wrong.append(f"ID {servo_id}: {exc}")
                continue
            if now != level:
                wrong.append(f"ID {servo_id} reads {now}, not {level}")
        expect(not wrong, "Status Return Level not put back: " + "; ".join(wrong))
        return ", ".join(f"ID {i}: {level} -> 2 for the run (the checks need every instruction answered), put back to {level}"
                         for i, level in raised.items())

    def raise_levels(self) -> None:
        """Raise every ID's Status Return Level below 2 to 2 for the run, keeping the old level in ``raised``.

        A servo at level 1 (e-manual: PING and READ answered only, a legitimate setting) failed every check that
        writes with "no reply to WRITE", and the restores in ``finally`` stopped at the first unanswered one,
        leaving tables changed.  Level 0 answers no READ: :meth:`identify` cannot read the table, and says so.
        """
        raised: dict[int, int] = self.raised  # type: ignore[attr-defined]
        for servo_id in self.ids:
            if servo_id in raised or servo_id in self.shadowed_ids():
                continue
            entry = self.entry(servo_id, "status_return_level")
            level = self.get(servo_id, "status_return_level")
            if level >= 2:
                continue
            raised[servo_id] = level
            self.transact(self.encode_packet(servo_id, self.instructions["WRITE"], self.address_bytes(entry.address) + b"\x02"),
                          timeout_s=self.link.silence_s)
            now = self.get(servo_id, "status_return_level")
            expect(now == 2, f"ID {servo_id}: Status Return Level {level}, and a WRITE of 2 left it at {now}")

    def shadowed_ids(self) -> dict[int, list[int]]:
        """IDs under test that other servos answer to silently (Protocol 2.0's Secondary ID): none on Protocol 1.0."""
        return {}

    def address_bytes(self, address: int) -> bytes:
        """A register address as the protocol's READ and WRITE carry it (1 byte on Protocol 1.0)."""
        return bytes((address,))

    def ping_rtts(self, servo_id: int, count: int) -> list[float]:
        """Round trips of ``count`` PINGs."""
        packet = self.encode_packet(servo_id, self.instructions["PING"])
        rtts = []
        for _ in range(count):
            response = self.link.transact(packet)
            expect(response.status is not None, f"PING id={servo_id} unanswered")
            rtts.append(response.rtt_s)
        return rtts


@dataclass
class Context(Transactions):
    """What the checks share: the link, the IDs under test, each ID's model and the tables found at the start."""

    link: Link
    ids: list[int]
    profile: str = "ax12a"
    destructive: bool = False
    #: Model file of each ID, found from the Model Number it holds (:meth:`identify`); None where no Protocol 1.0
    #: model file has that number.  An ID never looked up is taken for an AX-12A.
    models: dict[int, ServoModel | None] = field(default_factory=dict)
    #: Table image of each ID read before the first check.
    before: dict[int, bytes] = field(default_factory=dict)
    #: Status Return Level of each ID that had it below 2, raised to 2 for the run (:meth:`raise_levels`).
    raised: dict[int, int] = field(default_factory=dict)

    @property
    def target(self) -> int:
        """The servo most checks work on."""
        return self.ids[0]

    def free_id(self) -> int:
        """An ID no servo under test has (counting down from 253)."""
        return next(i for i in range(253, -1, -1) if i not in self.ids)

    # -- each servo's model and table ---------------------------------------------------
    def identify(self) -> None:
        """Read every ID's Model Number and look up its Protocol 1.0 model file (None: there is none).

        An unknown number does not stop the suite: the model-number check fails saying so, and the
        other checks judge the servo by the AX-12A's table.  A user with a servo the project has no
        file for (an RX or EX series servo, a newer firmware's number) learns more from a table whose
        protocol checks mostly still apply, the Protocol 1.0 series sharing its first 50 addresses,
        than from a run that stops; only the checks that need the model's own factory table (defaults,
        RESET) skip.
        """
        for servo_id in self.ids:
            try:
                data = self.read(servo_id, MODEL_NUMBER_AT.address, MODEL_NUMBER_AT.size)
            except Failed as exc:
                if self.link.transact(encode_instruction(servo_id, Instruction.PING)).status is None:
                    raise
                raise Failed(f"{exc}, yet it answers PING: Status Return Level 0? (the suite reads every table; "
                             "set it to 1 or 2)") from None
            self.models[servo_id] = model_for_number1(int.from_bytes(data, "little"))
        self.raise_levels()

    def spec(self, servo_id: int) -> ServoModel | None:
        """``servo_id``'s model file: None if its model number names none, the AX-12A's if it was never looked up."""
        return self.models[servo_id] if servo_id in self.models else model(AX12_MODEL)

    def known(self, servo_id: int) -> ServoModel:
        """``servo_id``'s model file; :class:`Skipped` where its model number names none."""
        spec = self.spec(servo_id)
        if spec is None:
            raise Skipped(f"ID {servo_id}: its model number names no model file, so its factory table is unknown")
        return spec

    def layout(self, servo_id: int) -> Layout:
        """The table of ``servo_id``'s model (the AX-12A's in ``profile``'s edition); the AX-12A's for an unknown model."""
        spec = self.spec(servo_id)
        if spec is None:
            return layout(self.profile)
        return spec.layout(self.profile if self.profile in spec.profiles else None)

    def entry(self, servo_id: int, name: str, table: Layout | None = None) -> Entry:
        """A register of ``servo_id``'s table (or of ``table``); skips the check where the model has none."""
        entry = (self.layout(servo_id) if table is None else table).by_name.get(name)
        if entry is None:
            raise Skipped(f"ID {servo_id}'s table has no {name}")
        return entry

    # -- transactions (status, silent, ping_rtts: :class:`Transactions`) ----------------
    def transact(self, packet: bytes, *, timeout_s: float | None = None) -> Response:
        """``link.transact``, then, after a WRITE into the EEPROM area, the wait the servo needs."""
        response = self.link.transact(packet, timeout_s=timeout_s)
        eeprom_wait(packet)
        return response

    def send(self, packet: bytes) -> None:
        """``link.send`` (no reply expected), then the EEPROM wait as :meth:`transact`."""
        self.link.send(packet)
        eeprom_wait(packet)

    def read(self, servo_id: int, address: int, length: int) -> bytes:
        """READ that must succeed without error bits."""
        status = self.status(servo_id, Instruction.READ, bytes((address, length)))
        expect(len(status.params) == length, f"READ {address}+{length} returned {len(status.params)} bytes")
        expect(not status.error & ~_ALARMS, f"READ {address}+{length}: {describe_error(status.error)}")
        return status.params

    def get(self, servo_id: int, name: str, table: Layout | None = None) -> int:
        """A register by name, from ``servo_id``'s table (or ``table``: a servo that has just moved ID)."""
        entry = self.entry(servo_id, name, table)
        return int.from_bytes(self.read(servo_id, entry.address, entry.size), "little")

    def put(self, servo_id: int, name: str, value: int, table: Layout | None = None) -> int:
        """WRITE a register by name; returns the reply's instruction error bits (alarms masked)."""
        entry = self.entry(servo_id, name, table)
        status = self.status(servo_id, Instruction.WRITE, bytes((entry.address,)) + value.to_bytes(entry.size, "little"))
        return status.error & ~_ALARMS

    def must_put(self, servo_id: int, name: str, value: int) -> None:
        """WRITE that must succeed."""
        error = self.put(servo_id, name, value)
        expect(not error, f"WRITE {name}={value}: {describe_error(error)}")

    def table(self, servo_id: int, table: Layout | None = None) -> bytes:
        """The whole control table of ``servo_id``'s model (or ``table``), in one READ."""
        return self.read(servo_id, 0, (self.layout(servo_id) if table is None else table).table_size)

    def address(self, name: str) -> int:
        """The address of register ``name`` in every table under test, for a packet they all act on (SYNC_WRITE, a
        broadcast WRITE); skips the check where two tables disagree."""
        found = {self.entry(servo_id, name).address for servo_id in self.ids}
        if len(found) != 1:
            raise Skipped(f"{name} is at different addresses in the tables under test ({sorted(found)})")
        return found.pop()


def eeprom_wait(packet: bytes) -> None:
    """After a WRITE whose data reaches the EEPROM area, wait while the servo writes it."""
    if len(packet) > 6 and packet[4] == Instruction.WRITE and packet[5] < EEPROM_END:
        written = min(len(packet) - 7, EEPROM_END - packet[5])
        time.sleep(written * EEPROM_WAIT_S_PER_BYTE)


#: Alarm bits may be set by a warm or loaded servo; instruction checks ignore them.
_ALARMS = int(StatusError.INPUT_VOLTAGE | StatusError.OVERHEATING | StatusError.OVERLOAD)


@dataclass(frozen=True)
class Check:
    """One named check; ``destructive`` ones and ``motion`` ones (they turn the shaft) run only when asked."""

    name: str
    run: Callable[[Context], "str | Note"]
    destructive: bool = False
    motion: bool = False
    #: The check only reads, pings and listens: it writes nothing to any servo (see ``Transactions.refusal``).
    reads_only: bool = False


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.2f} ms"


# -- framing ----------------------------------------------------------------------------
def check_ping(ctx: Context) -> str:
    """Every ID answers PING with an empty status packet."""
    rtts = []
    for servo_id in ctx.ids:
        status = ctx.status(servo_id, Instruction.PING)
        expect(not status.params, f"PING id={servo_id} carried {len(status.params)} parameter bytes")
        rtts.extend(ctx.ping_rtts(servo_id, 5))
    return f"IDs {','.join(map(str, ctx.ids))}; median {_ms(statistics.median(rtts))}"


def check_absent_id(ctx: Context) -> str:
    """An ID nobody has gets silence."""
    free = ctx.free_id()
    expect(ctx.silent(encode_instruction(free, Instruction.PING)), f"ID {free} answered")
    return f"ID {free} silent for {_ms(ctx.link.silence_s)}"


def check_split_packet(ctx: Context) -> str:
    """A packet arriving one byte at a time (1 ms apart) is still one packet."""
    packet = encode_instruction(ctx.target, Instruction.PING)
    start = time.perf_counter()
    ctx.link.flush_input()
    for byte in packet[:-1]:
        ctx.link.write_raw(bytes((byte,)))
        time.sleep(0.001)
    ctx.link.sent.append(packet)
    ctx.link.write_raw(packet[-1:])
    response = _reply_past_echoes(ctx, (packet,), start=time.perf_counter())
    expect(response.status is not None and response.status.id == ctx.target, "no reply to a PING sent byte by byte")
    return f"{len(packet)} bytes over {_ms(time.perf_counter() - start)}"


def _reply_past_echoes(ctx: Context, sent: tuple[bytes, ...], *, start: float | None = None):
    """The next status packet, skipping the echoes of ``sent`` a half-duplex adapter hands back (an echo read as
    the reply passed these checks with no servo at all)."""
    while True:
        response = ctx.link.receive(start=start)
        if response.status is None or response.status.encode() not in sent:
            return response


def check_back_to_back(ctx: Context) -> "str | Note":
    """Two packets in one write get two replies, in order.

    Only where the line leaves room for it: the first reply comes the target's Return Delay Time (2 us a unit) after
    the first packet, while the host is still sending the second if that one's wire time is longer (8 bytes at
    57,600 bps are 1.39 ms, the factory delay 0.5 ms); on a half-duplex line the two then collide, so a real servo
    cannot pass.  There a failure is a note saying so (a larger Return Delay Time or a faster rate judges it).
    """
    second = ctx.ids[-1]
    first = encode_instruction(ctx.target, Instruction.PING)
    then = encode_instruction(second, Instruction.READ, bytes((0, 2)))
    ctx.link.flush_input()
    ctx.link.sent.extend((first, then))
    ctx.link.write_raw(first + then)
    a = _reply_past_echoes(ctx, (first, then))
    b = _reply_past_echoes(ctx, (first, then))
    try:
        expect(a.status is not None and a.status.id == ctx.target, "first packet unanswered")
        expect(b.status is not None and b.status.id == second and len(b.status.params) == 2, "second packet unanswered")
    except Failed as exc:
        before = ctx.before.get(ctx.target)
        if before is None:
            raise
        wire_s = len(then) * 10 / ctx.link.baud
        delay_s = ctx.entry(ctx.target, "return_delay_time").value_in(before) * 2e-6
        if wire_s <= delay_s:
            raise
        ctx.link.drain(0.01)  # what is left of colliding replies
        return Note(f"{exc}: the second packet's {len(then)} bytes take {_ms(wire_s)} at {ctx.link.baud} bps, longer than "
                    f"ID {ctx.target}'s Return Delay Time ({delay_s * 1e6:.0f} us), so its reply starts while the host still "
                    "sends: on a half-duplex line they collide (raise Return Delay Time or the rate to judge this)")
    return f"replies from {ctx.target} then {second}"


def _clean_ping(ctx: Context) -> None:
    """A PING answered as a PING is: no instruction error bits and no parameters (a reply to the garbage glued to
    the PING, with Instruction or Checksum Error and bytes of data, passed as "answered")."""
    status = ctx.status(ctx.target, Instruction.PING)
    expect(not status.error & ~_ALARMS and not status.params,
           f"PING answered with {describe_error(status.error & ~_ALARMS) or 'no error'} and {len(status.params)} data bytes")


def check_resync(ctx: Context) -> str:
    """After garbage, repeated 0xFF, a truncated packet and an impossible LENGTH, the next PING is answered."""
    ctx.link.write_raw(bytes(range(0, 0xFE, 7)) + b"\xff\xff\xff\xff" + bytes((ctx.target,)) + b"\x04\x02")
    time.sleep(0.1)
    _clean_ping(ctx)
    ctx.link.write_raw(b"\xff\xff" + bytes((ctx.target,)) + b"\x00\x00")
    _clean_ping(ctx)
    return "PING answered after garbage + truncated packet (100 ms pause) and after LENGTH 0"


def check_checksum(ctx: Context) -> "str | Note":
    """A packet with a wrong checksum is not executed."""
    led = ctx.get(ctx.target, "led")
    bad = bytearray(encode_instruction(ctx.target, Instruction.WRITE, bytes((ctx.entry(ctx.target, "led").address, 1 - led))))
    bad[-1] ^= 0xFF
    response = ctx.link.transact(bytes(bad))
    try:
        expect(ctx.get(ctx.target, "led") == led, "a WRITE with a bad checksum was executed")
    finally:
        ctx.put(ctx.target, "led", led)
    if response.status is None:
        return Note("not executed; no reply")
    expect(bool(response.status.error & StatusError.CHECKSUM), f"reply without the Checksum bit: {describe_error(response.status.error)}")
    return "not executed; reply with CHECKSUM"


# -- instructions ------------------------------------------------------------------------
def check_model_number(ctx: Context) -> str:
    """READ of Model Number gives, on every ID, a number a Protocol 1.0 model file has (12 the AX-12A, 29 the MX-28, ...)."""
    figures, unknown = [], []
    for servo_id in ctx.ids:
        data = ctx.read(servo_id, MODEL_NUMBER_AT.address, 3)
        number = int.from_bytes(data[:2], "little")
        spec = model_for_number1(number)
        if spec is None:
            unknown.append(f"ID {servo_id}: model number {number}")
        else:
            figures.append(f"{servo_id}: model {number} ({spec.name}) fw {data[2]}")
    if unknown:
        known = ", ".join(f"{other.name} {other.model_number}" for other in map(model, model_names()) if "1.0" in other.protocols)
        raise Failed("; ".join(unknown) + f" names no Protocol 1.0 model file (known: {known}); the other checks judged "
                     "it by the AX-12A's table, its defaults and RESET unchecked")
    return "; ".join(figures)


def check_read_table(ctx: Context) -> str:
    """READ of the whole table (the model's: 50 bytes on the AX series, 74 on the MX) in one packet."""
    data = ctx.table(ctx.target)
    return f"{len(data)} bytes"


def check_read_past_table(ctx: Context) -> str:
    """READ from the table's last address past its end sets the Range bit."""
    last = ctx.layout(ctx.target).table_size - 1
    status = ctx.status(ctx.target, Instruction.READ, bytes((last, 2)))
    expect(bool(status.error & StatusError.RANGE), f"READ {last}+2: {describe_error(status.error)}")
    return f"{describe_error(status.error & ~_ALARMS)}, {len(status.params)} data bytes"


def check_write(ctx: Context) -> str:
    """WRITE of a 1-byte (LED) and a 2-byte register (Punch) reads back; both restored."""
    led = ctx.get(ctx.target, "led")
    punch = ctx.get(ctx.target, "punch")
    new_punch = punch + 1 if punch < 1023 else punch - 1
    try:
        ctx.must_put(ctx.target, "led", 1 - led)
        expect(ctx.get(ctx.target, "led") == 1 - led, "LED did not change")
        ctx.must_put(ctx.target, "punch", new_punch)
        expect(ctx.get(ctx.target, "punch") == new_punch, "Punch did not change")
    finally:
        put_all(ctx, [(ctx.target, "led", led), (ctx.target, "punch", punch)])
    return f"led {led}->{1 - led}, punch {punch}->{new_punch}"


def check_range_errors(ctx: Context) -> str:
    """Out-of-range and read-only writes set Range and change nothing."""
    torque = ctx.get(ctx.target, "torque_enable")
    error = ctx.put(ctx.target, "torque_enable", 2)
    expect(bool(error & StatusError.RANGE), f"Torque Enable = 2: {describe_error(error)}")
    expect(ctx.get(ctx.target, "torque_enable") == torque, "the rejected write changed Torque Enable")
    error = ctx.put(ctx.target, "model_number", 13)
    expect(bool(error & StatusError.RANGE), f"write to Model Number: {describe_error(error)}")
    return "torque_enable=2: RANGE; model_number=13: RANGE"


def check_angle_limit(ctx: Context) -> str:
    """Goal Position outside the angle limits sets Angle Limit and is not taken."""
    if ctx.get(ctx.target, "torque_enable"):
        raise Skipped("torque is on: changing limits could move the servo")
    cw, ccw = ctx.get(ctx.target, "cw_angle_limit"), ctx.get(ctx.target, "ccw_angle_limit")
    goal = ctx.get(ctx.target, "goal_position")
    if cw == ccw == 0:
        raise Skipped("wheel mode")
    limit = max(cw, min(ccw, 1000) - 1, goal)
    if limit >= ctx.entry(ctx.target, "goal_position").maximum:  # 1023 on the AX series, 4095 on the MX
        raise Skipped("no room above Goal Position")
    try:
        if limit != ccw:
            ctx.must_put(ctx.target, "ccw_angle_limit", limit)
        error = ctx.put(ctx.target, "goal_position", limit + 1)
        expect(bool(error & StatusError.ANGLE_LIMIT), f"goal {limit + 1} past limit {limit}: {describe_error(error)}")
        expect(ctx.get(ctx.target, "goal_position") == goal, "the rejected goal was taken")
    finally:
        ctx.put(ctx.target, "ccw_angle_limit", ccw)
    return f"goal {limit + 1} > CCW limit {limit}: ANGLE_LIMIT"


def check_instruction_error(ctx: Context) -> str:
    """An undefined instruction and ACTION with nothing registered set Instruction.

    The undefined instruction is Bulk Read (0x92) where the model's firmware lacks it (the AX series), else
    one no Protocol 1.0 firmware defines (0x50): an MX answers Bulk Read, and a servo of unknown model may.
    """
    spec = ctx.spec(ctx.target)
    undefined = Instruction.BULK_READ if spec is not None and not knows_bulk_read(spec) else UNDEFINED_INSTRUCTION
    name = Instruction.BULK_READ.name if undefined == Instruction.BULK_READ else f"{undefined:#04x}"
    status = ctx.status(ctx.target, undefined, b"\x00")
    expect(bool(status.error & StatusError.INSTRUCTION), f"{name}: {describe_error(status.error)}")
    if ctx.get(ctx.target, "registered"):
        raise Skipped("a REG_WRITE is pending on the device")
    status = ctx.status(ctx.target, Instruction.ACTION)
    expect(bool(status.error & StatusError.INSTRUCTION), f"ACTION: {describe_error(status.error)}")
    return f"{name}: INSTRUCTION; bare ACTION: INSTRUCTION"


def check_reg_write_action(ctx: Context) -> str:
    """REG_WRITE sets Registered and waits; ACTION applies it and clears Registered."""
    led = ctx.get(ctx.target, "led")
    try:
        status = ctx.status(ctx.target, Instruction.REG_WRITE, bytes((ctx.entry(ctx.target, "led").address, 1 - led)))
        expect(not status.error & ~_ALARMS, f"REG_WRITE: {describe_error(status.error)}")
        expect(ctx.get(ctx.target, "registered") == 1, "Registered is not 1 after REG_WRITE")
        expect(ctx.get(ctx.target, "led") == led, "REG_WRITE took effect before ACTION")
        ctx.status(ctx.target, Instruction.ACTION)
        expect(ctx.get(ctx.target, "led") == 1 - led, "ACTION did not apply the registered write")
        expect(ctx.get(ctx.target, "registered") == 0, "Registered still 1 after ACTION")
    finally:
        ctx.put(ctx.target, "led", led)
    return "registered 0->1->0, LED applied on ACTION"


def check_sync_write(ctx: Context) -> str:
    """SYNC_WRITE (to 0xFE) sets every listed servo and nobody answers."""
    leds = {i: ctx.get(i, "led") for i in ctx.ids}
    at = ctx.address("led")
    body = bytes((at, 1)) + b"".join(bytes((i, 1 - leds[i])) for i in ctx.ids)
    try:
        expect(ctx.silent(encode_instruction(BROADCAST_ID, Instruction.SYNC_WRITE, body)), "SYNC_WRITE was answered")
        for servo_id in ctx.ids:
            expect(ctx.get(servo_id, "led") == 1 - leds[servo_id], f"ID {servo_id} not written")
    finally:
        restore = bytes((at, 1)) + b"".join(bytes((i, leds[i])) for i in ctx.ids)
        ctx.link.send(encode_instruction(BROADCAST_ID, Instruction.SYNC_WRITE, restore))
        time.sleep(0.005)
    return f"{len(ctx.ids)} servo(s) written, silent"


def check_bulk_read(ctx: Context) -> str:
    """Bulk Read (0x92) to 0xFE: each listed servo answers its own block (ID, address, length), in list order.

    On the servos under test whose firmware knows it (:func:`knows_bulk_read`); at least two, as the e-manual
    says of it "this cannot be used to read a single module" (Protocol 1.0, "Bulk Read").  Each reads a
    block of its own table read at the start (from address 0: Model Number, Firmware Version, ID).
    """
    listed = [servo_id for servo_id in ctx.ids if (spec := ctx.spec(servo_id)) is not None and knows_bulk_read(spec)]
    if len(listed) < 2:
        raise Skipped(f"needs two servos whose firmware knows Bulk Read (the MX series); {len(listed)} under test")
    blocks = {servo_id: (MODEL_NUMBER_AT.address, 4 + k % 2) for k, servo_id in enumerate(listed)}  # lengths 4, 5, 4, ...
    packet = encode_instruction(BROADCAST_ID, Instruction.BULK_READ,
                                b"\x00" + b"".join(bytes((length, servo_id, address)) for servo_id, (address, length) in blocks.items()))
    first = ctx.link.transact(packet)
    answers = [first] + [_reply_past_echoes(ctx, (packet,)) for _ in listed[1:]]
    for servo_id, response in zip(listed, answers):
        address, length = blocks[servo_id]
        status = response.status
        expect(status is not None, f"no answer from ID {servo_id} in its turn (IDs {', '.join(map(str, listed))} listed)")
        assert status is not None
        expect(status.checksum_ok and status.id == servo_id,
               f"ID {servo_id}'s turn answered by id={status.id}{'' if status.checksum_ok else ', checksum bad'}")
        expect(not status.error & ~_ALARMS, f"ID {servo_id}: {describe_error(status.error)}")
        want = ctx.before[servo_id][address : address + length]
        expect(bytes(status.params) == want, f"ID {servo_id} read {bytes(status.params).hex(' ')}, its table holds {want.hex(' ')}")
    return f"IDs {', '.join(map(str, listed))} answered in list order"


def check_broadcast_write(ctx: Context) -> str:
    """WRITE to 0xFE acts on every servo and nobody answers."""
    leds = {i: ctx.get(i, "led") for i in ctx.ids}
    try:
        expect(ctx.silent(encode_instruction(BROADCAST_ID, Instruction.WRITE, bytes((ctx.address("led"), 1)))),
               "broadcast WRITE answered")
        for servo_id in ctx.ids:
            expect(ctx.get(servo_id, "led") == 1, f"ID {servo_id} not written")
    finally:
        # The broadcast also lit the LED of any servo on the bus that is not under test: put every LED back to its
        # factory 0 the same way, then those under test to what they were.
        ctx.silent(encode_instruction(BROADCAST_ID, Instruction.WRITE, bytes((ctx.address("led"), 0))))  # (its echo too)
        put_all(ctx, [(servo_id, "led", led) for servo_id, led in leds.items()])
    return "all written, silent"


def check_broadcast_ping(ctx: Context) -> Note:
    """PING to 0xFE: the 2006 manual says it is answered (colliding with several servos)."""
    response = ctx.link.transact(encode_instruction(BROADCAST_ID, Instruction.PING))
    ctx.link.drain(0.01)
    if response.status is None:
        return Note("silent")
    return Note(f"answered (id={response.status.id}{', checksum bad' if not response.status.checksum_ok else ''})")


def check_status_return_level(ctx: Context) -> str:
    """Level 1 answers PING and READ only; level 0 answers PING only; restored to what it was."""
    servo = ctx.target
    level = ctx.get(servo, "status_return_level")
    led = ctx.get(servo, "led")
    led_at, level_at = ctx.entry(servo, "led").address, ctx.entry(servo, "status_return_level").address
    write_led = encode_instruction(servo, Instruction.WRITE, bytes((led_at, led)))
    read_led = encode_instruction(servo, Instruction.READ, bytes((led_at, 1)))
    ping = encode_instruction(servo, Instruction.PING)
    try:
        ctx.transact(encode_instruction(servo, Instruction.WRITE, bytes((level_at, 1))))
        expect(ctx.silent(write_led), "level 1 answered a WRITE")
        expect(ctx.answers(read_led), "level 1 did not answer a READ")
        expect(ctx.answers(ping), "level 1 did not answer PING")
        # at level 1 this WRITE gets no answer: listened to for the silence window, not the reply timeout
        ctx.transact(encode_instruction(servo, Instruction.WRITE, bytes((level_at, 0))), timeout_s=ctx.link.silence_s)
        expect(ctx.silent(read_led), "level 0 answered a READ")
        expect(ctx.answers(ping), "level 0 did not answer PING")
    finally:
        ctx.send(encode_instruction(servo, Instruction.WRITE, bytes((level_at, 2))))
        if level != 2:
            ctx.put(servo, "status_return_level", level)
    return "0: PING only; 1: PING+READ; 2: all"


def check_return_delay(ctx: Context) -> "str | Note":
    """Return Delay Time (2 us per unit) shows in the round trip: measured against a delay of 0."""
    return return_delay_figure(ctx, ctx.target)


#: A fastest round trip at Return Delay Time 0 this long is the link's own latency, not the servo's: a USB adapter's
#: latency timer (an FTDI's 16 ms by default) holds a short status back whatever the servo's half millisecond.
LINK_HIDES_DELAY_S = 0.002


def return_delay_figure(ctx: Any, servo: int) -> "str | Note":
    """The fastest PING round trip at Return Delay Time 250 (or the servo's own, if 100 or more) less the fastest
    at 0 must be at least 0.6 x the delay (both protocols: 2 us a unit); the register is restored.  Where the link
    itself takes :data:`LINK_HIDES_DELAY_S` or more, a difference too small is a note, not a failure: the
    adapter, not the servo, decides when the reply is seen."""
    original = ctx.get(servo, "return_delay_time")
    slow = original if original >= 100 else 250
    count = 30
    try:
        ctx.must_put(servo, "return_delay_time", slow)
        # Minimums, not medians: a busy host only ever adds time, so the fastest round trip
        # of each set is the one least disturbed, on a loaded CI machine as on a USB adapter.
        slow_rtt = min(ctx.ping_rtts(servo, count))
        ctx.must_put(servo, "return_delay_time", 0)
        fast_rtt = min(ctx.ping_rtts(servo, count))
    finally:
        ctx.put(servo, "return_delay_time", original)
    expected = slow * 2e-6
    measured = slow_rtt - fast_rtt
    figure = f"{slow} ({expected * 1e6:.0f} us): {_ms(slow_rtt)}; 0: {_ms(fast_rtt)} (fastest of {count}); difference {measured * 1e6:.0f} us"
    # Lower bound only: a busy host adds time to both, never removes the servo's wait.
    # The link's own latency is the round trip less the packets' time on the wire (4.2 ms of a 2.0 Ping and its status
    # at 57,600 bps is the line, not the adapter: without it no servo at a factory rate could fail).
    latency_s = fast_rtt - ctx.ping_exchange_bytes * 10 / ctx.link.baud
    if measured < 0.6 * expected and latency_s >= LINK_HIDES_DELAY_S:
        return Note(f"{figure}: the link's own latency (about {_ms(latency_s)} beyond the wire's time) is too coarse "
                    "to see the delay; lower the adapter's latency timer (FTDI: 1 ms) to judge it")
    expect(measured >= 0.6 * expected, figure)
    return figure


def check_alarms(ctx: Context) -> "str | Note":
    """The alarm bits each servo's PING carries (Input Voltage, Overheating, Overload: "Status Packet" > "Error").

    Not a failure of the protocol: the other checks look past them, so they are said here, where a servo
    that is overheating or out of its voltage range would otherwise pass unseen.
    """
    raised = {}
    for servo_id in ctx.ids:
        alarms = ctx.status(servo_id, Instruction.PING).error & _ALARMS
        if alarms:
            raised[servo_id] = describe_error(alarms)
    if raised:
        return Note("alarms: " + "; ".join(f"ID {servo_id} {what}" for servo_id, what in raised.items()))
    return "none"


def check_defaults(ctx: Context) -> "str | Note":
    """Registers at the model's factory defaults (the AX-12A's: the profile's; ID, and values the firmware sets, excepted)."""
    ignore = DYNAMIC | {"id", "goal_position", "torque_limit"}
    ctx.known(ctx.target)
    lay = ctx.layout(ctx.target)
    differ = table_differences(lay.defaults, ctx.before[ctx.target], lay, ignore)
    if differ:
        return Note("differs: " + ", ".join(differ))
    return "all at defaults"


# -- destructive ---------------------------------------------------------------------------
def check_id_change(ctx: Context) -> str:
    """Writing the ID is answered from the old ID; then only the new ID answers; restored.

    Restored also when the write's reply was lost: a servo that moved is moved back whatever the check
    found (left at the free ID, a real robot's servo would be lost to its program).
    """
    old, new = ctx.target, ctx.free_id()
    table = ctx.layout(old)  # the servo's own, at whichever ID it answers
    expect(ctx.silent(encode_instruction(new, Instruction.PING)), f"ID {new}, the free ID this check moves to, answers")
    try:
        ctx.must_put(old, "id", new)
        ctx.status(new, Instruction.PING)
        expect(ctx.silent(encode_instruction(old, Instruction.PING)), f"old ID {old} still answers")
    finally:
        if ctx.answers(encode_instruction(new, Instruction.PING)):
            ctx.put(new, "id", old, table)
    ctx.status(old, Instruction.PING)
    return f"{old}->{new}->{old}"


def check_baud_change(ctx: Context) -> "str | Note":
    """After Baud Rate 34 the servo answers at 57,600 bps (after 1, at 1,000,000, where it runs at 34); restored."""
    servo = ctx.target
    original = ctx.get(servo, "baud_rate")
    value = _SLOW_BAUD_REGISTER if original != _SLOW_BAUD_REGISTER else _FAST_BAUD_REGISTER
    rate = host_bps(value)
    host = ctx.link.baud
    try:
        ctx.must_put(servo, "baud_rate", value)
        old_rate_silent = ctx.silent(encode_instruction(servo, Instruction.PING))
        ctx.link.baud = rate
        rtt = statistics.median(ctx.ping_rtts(servo, 3))
    finally:
        # Restored wherever the servo answers at the new rate, the write's reply lost or not.
        ctx.link.baud = rate
        if ctx.answers(encode_instruction(servo, Instruction.PING)):
            ctx.put(servo, "baud_rate", original)
        ctx.link.baud = host
    ctx.status(servo, Instruction.PING)
    figure = f"answers at {rate} bps ({_ms(rtt)}); at {host} bps: {'silent' if old_rate_silent else 'still answered'}"
    return figure if old_rate_silent else Note(figure + " (the port carries no line rate?)")


def check_reset(ctx: Context) -> str:
    """RESET restores the model's factory defaults (ID 1, its factory rate: 1 Mbps on the AX series, 57,600 bps
    on the MX); the table is then written back.

    Only where nothing else answers at ID 1, where the reset servo lands: two servos there would collide,
    and the write-back would rewrite both ("If Dynamixel with the same ID is connected, packet will
    collide", e-manual).  The write-back runs however the check ends, a lost reply to the RESET included.
    Skipped for a model no file describes: its factory table is unknown, and a write-back by the AX-12A's
    table would leave its other registers at their factory values.
    """
    servo = 1 if 1 in ctx.ids else ctx.target
    ctx.known(servo)
    lay = ctx.layout(servo)
    factory = host_bps(lay.by_name["baud_rate"].default)
    host = ctx.link.baud
    if servo != 1:
        ctx.link.baud = factory
        try:
            taken = ctx.answers(encode_instruction(1, Instruction.PING))
        finally:
            ctx.link.baud = host
        if taken:
            raise Skipped("a servo not under test answers at ID 1, where RESET would put this one")
    before = ctx.table(servo)
    try:
        status = ctx.status(servo, Instruction.RESET)
        figure = f"answered by id={status.id}"
        ctx.link.baud = factory
        after = ctx.table(1, lay)
        # Firmware Version and Moving Speed have no initial value on the e-manual's AX-12A page ("-"): a real
        # servo's are its own, not this profile's.
        differ = table_differences(lay.defaults, after, lay,
                                   DYNAMIC | {"goal_position", "torque_limit", "firmware_version", "moving_speed"})
        expect(not differ, "after RESET: " + ", ".join(differ))
    finally:
        ctx.link.baud = factory  # where a reset servo listens, the RESET's reply seen or not
        try:
            _write_back(ctx, before, lay)
        finally:
            ctx.link.baud = host
    ctx.status(servo, Instruction.PING)
    return figure + "; table at defaults; restored"


#: Registers whose write turns the torque on, on the AX series and (Goal Position) the MX: users report it
#: (``ax12emu.servo.virtual_servo.ServoOptions.goal_position_enables_torque`` gives the sources).
TORQUE_ON_WRITES = frozenset({"goal_position", "moving_speed"})


def _write_back(ctx: Context, image: bytes, lay: Layout) -> None:
    """Write a saved table (of layout ``lay``) back to the reset servo (now ID 1 at its factory rate): ID and baud last.

    Registers the firmware sets (:data:`DYNAMIC`; the MX's Current(68) is writable) are left to it.  Where the saved
    Torque Enable is 0, Goal Position and Moving Speed are written with Torque Limit at 0, then Torque Enable 0, then
    Torque Limit: on an AX (Goal Position on an MX too) such a write turns the torque on, and the shaft, turned by
    hand since the goal was set, was driven back to the stale goal until Torque Enable 0 came (45 degrees behind a
    16 ms adapter latency); with no torque to give it stays where it is.  Every write is tried though one fails, so
    ID and baud are put back."""
    last = ("id", "baud_rate")
    by_name = lay.by_name
    torque = by_name["torque_enable"].value_in(image)
    limp = not torque and "torque_limit" in by_name and TORQUE_ON_WRITES & set(by_name)
    puts: list[tuple[Any, ...]] = [(1, "torque_limit", 0, lay)] if limp else []
    for entry in lay.entries:
        if entry.access is not Access.RW or entry.name in last or entry.name == "lock" or entry.name in DYNAMIC:
            continue
        if entry.name == "torque_enable" or (limp and entry.name == "torque_limit"):
            continue
        puts.append((1, entry.name, int.from_bytes(image[entry.address : entry.end], "little"), lay))
    puts.append((1, "torque_enable", torque, lay))
    if limp:
        puts.append((1, "torque_limit", by_name["torque_limit"].value_in(image), lay))
    servo_id = by_name["id"].value_in(image)
    try:
        put_all(ctx, puts)
    finally:
        put_all(ctx, [(1, "id", servo_id, lay), (servo_id, "baud_rate", by_name["baud_rate"].value_in(image), lay)])


CHECKS: tuple[Check, ...] = (
    Check("ping", check_ping),
    Check("absent ID is silent", check_absent_id),
    Check("model number", check_model_number),
    Check("read whole table", check_read_table),
    Check("alarms", check_alarms),
    Check("defaults", check_defaults),
    Check("packet split into bytes", check_split_packet),
    Check("two packets in one write", check_back_to_back),
    Check("resync after garbage", check_resync),
    Check("bad checksum not executed", check_checksum),
    Check("write 1 and 2 bytes", check_write),
    Check("range error", check_range_errors),
    Check("read past the table", check_read_past_table),
    Check("angle limit error", check_angle_limit),
    Check("instruction error", check_instruction_error),
    Check("REG_WRITE + ACTION", check_reg_write_action),
    Check("SYNC_WRITE", check_sync_write),
    Check("BULK_READ", check_bulk_read),
    Check("broadcast WRITE", check_broadcast_write),
    Check("broadcast PING", check_broadcast_ping),
    Check("status return levels", check_status_return_level),
    Check("return delay", check_return_delay),
    Check("ID change", check_id_change, destructive=True),
    Check("baud change", check_baud_change, destructive=True),
    Check("RESET", check_reset, destructive=True),
)
