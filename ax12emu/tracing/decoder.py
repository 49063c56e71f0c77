"""A protocol view of captured bytes: chunks in, decoded packets out.

Why it exists: ``ax12emu decode`` shows a trace the way a logic analyser's
protocol decoder does: one line per packet with time, direction,
instruction or status, ID, register names and values, error bits, and the
bytes thrown away while hunting for a frame.  It reuses the emulator's own
framer (status packets share the instruction packets' framing) and
:mod:`ax12emu.protocol.describe`, so the decoder and the servos agree on every byte.

Direction: a trace says which way each chunk went.  A raw capture does not,
so each packet is classified by context: a packet from the ID the last
instruction expects an answer from is a status packet (``0xFE`` PING: any ID) if
it can be that answer (on Protocol 1.0 only a READ's has parameters, exactly the
length asked), a repeat of the last instruction right after it (nothing decoded
between) is the adapter's echo, a code that is no instruction but a plausible
error byte is a status packet, and anything else is an instruction.  A trace
whose header says ``"echo": false`` (``serve`` without ``--echo``) has no echo
at all: a servo's bytes are its status packets, however much they look like the
instruction (a PING answered with Input Voltage Error is byte for byte a PING).
Without timestamps a truncated packet cannot be told from one still arriving,
so it may swallow the start of the next.

Protocol 2.0 (the X series), alone or on one wire with Protocol 1.0 servos: with
``protocol="both"`` every byte goes to both protocols' framers, as on a mixed wire
each servo frames the stream by its own rules.  The first framer to complete a packet
claims its bytes (the other framer's partial frame is dropped: it was that packet's
bytes), and the bytes no packet claimed are shown as noise before the next packet;
but a packet with a bad checksum or CRC claims nothing while the other framer holds a
frame that began before it (a 2.0 packet's data may hold ``FF FF``, the start of a
1.0 frame, which then ends with a checksum that fails: that frame is no packet).
``protocol="2.0"`` frames 2.0 only (a wire of X-series servos alone).
A 2.0 packet says itself whether it is a status (instruction 0x55), so only the echo
needs the conversation.  Registers of 2.0 packets are named by the servos' model files
when ``servos`` gives them (a trace of a 2.0 bus records them), else by address;
signed registers (Goal Velocity, Present Current ...) read as signed.
:func:`decode` picks ``"2.0"`` by itself for a trace whose ``servos`` (its header's) are 2.0
servos only, ``"both"`` when ``servos`` names some or the bytes hold a 2.0 header.

Latency: a status's time since the instruction it answers ended.  A trace of a paced
wire (``serve --pace``) records each instruction's wire end and byte time, and the
status's is then measured from its first byte's start, so it shows the Return Delay
Time rather than that plus both packets' time on the wire.

Registers of 1.0 packets are named by the AX-12 table of ``profile``, or, for an ID ``servos``
names with a Protocol 1.0 model (a trace records every servo of a ``--servo`` wire: an AX-18A's, an
MX's), by that model file's table, so an MX's Goal Acceleration(73) is not an unknown address.
"""

from __future__ import annotations

import collections
from collections.abc import Iterable, Iterator, Mapping
from typing import NamedTuple

from ax12emu.protocol.control_table import AX12_MODEL, DEFAULT_PROFILE, Layout
from ax12emu.protocol.describe import describe_instruction, describe_status
from ax12emu.protocol.describe2 import RegisterName, describe_instruction2, describe_status2
from ax12emu.protocol.framing import DEFAULT_SILENCE_TIMEOUT_S, Framer
from ax12emu.protocol.framing2 import DEFAULT_MAX_LENGTH, Framer2
from ax12emu.protocol.packets import BROADCAST_ID, Instruction, InstructionPacket, StatusError, parse_bulk_read
from ax12emu.protocol.packets2 import HEADER2, Instruction2, InstructionPacket2, StatusPacket2
from ax12emu.protocol.servo_models import model, model_names
from ax12emu.protocol.servo_spec import parse_servo_spec

from .trace import IN, OUT, Chunk

__all__ = ["Decoded", "Decoder", "choose_protocol", "decode", "iter_decode", "format_decoded", "register_names",
           "tables_by_protocol", "INSTRUCTION", "STATUS", "ECHO", "GARBAGE", "PROTOCOLS"]

INSTRUCTION, STATUS, ECHO, GARBAGE = "instruction", "status", "echo", "garbage"
_INSTRUCTIONS = frozenset(int(code) for code in Instruction)
#: What a Decoder frames: Protocol 1.0 only (the AX-12 bus, as before there was a 2.0 bus), 2.0 only, or both.
PROTOCOLS = ("1.0", "2.0", "both")
#: Bytes of a 2.0 frame around its parameters: header, ID, LENGTH, INST and CRC.
_FRAME2_OVERHEAD = len(HEADER2) + 1 + 2 + 1 + 2
#: A packet a Decoder shows: Protocol 1.0 or 2.0.
AnyPacket = InstructionPacket | InstructionPacket2 | StatusPacket2


def tables_by_protocol(servos: str, profile: str = DEFAULT_PROFILE) -> dict[str, dict[int, Layout]]:
    """Each ID's table by protocol ("1.0", "2.0"), from the ``--servo`` text of a wire (``1:mx-28,2-5:xm430-w350``).

    IDs are per protocol, so one ID may have a table on each.  An AX-12A's is ``profile``'s (its
    trace's header names the profile); every other model's is its model file's.
    """
    also = tuple(key for key in model_names() if "2.0" not in model(key).protocols)
    tables: dict[str, dict[int, Layout]] = {"1.0": {}, "2.0": {}}
    for servo_id, key in parse_servo_spec(servos, also=also):
        spec = model(key)
        protocol = "2.0" if "2.0" in spec.protocols else "1.0"
        tables[protocol][servo_id] = spec.layout(profile if key == AX12_MODEL else None)
    return tables


def _names(table: Layout) -> dict[int, str]:
    """Address -> register name of a table; a signed register's name says so (it reads as signed)."""
    return {entry.address: RegisterName(entry.name, signed=entry.signed, size=entry.size) if entry.signed else entry.name
            for entry in table.entries}


def register_names(servos: str) -> dict[int, dict[int, str]]:
    """Address -> register name per ID of the Protocol 2.0 servos in a ``--servo`` text (``1-5:xm430-w350,...``);
    a signed register's name is a :class:`~ax12emu.protocol.describe2.RegisterName` that says so."""
    return {servo_id: _names(table) for servo_id, table in tables_by_protocol(servos)["2.0"].items()}


def _wire2(packet: InstructionPacket2 | StatusPacket2) -> int:
    """How many bytes the 2.0 ``packet`` took on the wire (stuffing included)."""
    combined_status = isinstance(packet, StatusPacket2) and packet.id == BROADCAST_ID
    if packet.crc_ok and not combined_status:
        return len(packet.encode())
    return _FRAME2_OVERHEAD + (1 if isinstance(packet, StatusPacket2) else 0) + len(packet.params)


class Decoded(NamedTuple):
    """One decoded packet (or a run of discarded bytes)."""

    t: float | None
    kind: str
    packet: AnyPacket | None
    text: str
    #: For a status packet: seconds since the instruction it answers ended (traces only).
    latency_s: float | None = None
    #: For garbage: how many bytes were thrown away.
    discarded: int = 0
    #: The packet's bytes as they were on the line (``protocol="both"``); empty: rebuilt from ``packet``.
    wire: bytes = b""

    @property
    def raw(self) -> bytes:
        """Wire bytes of the packet (with its checksum as received if it was corrupt): as the decoder saw them,
        else rebuilt (a packet made in code, with a correct checksum)."""
        if self.wire or self.packet is None:
            return self.wire
        return self.packet.encode()


#: A packet a stream completed: the packet, its wire bytes (a corrupt one's checksum as received), and when its
#: first byte came (the chunk's time; None: untimed).
_Framed = tuple[AnyPacket, bytes, "float | None"]


class _Stream:
    """One framer per direction (Protocol 1.0 or 2.0), counting what it throws away and keeping the bytes of the
    packets it completes."""

    #: Bytes kept to give a packet its wire bytes: the longest frame either protocol's framer accepts.
    _KEEP = DEFAULT_MAX_LENGTH + _FRAME2_OVERHEAD + 1

    def __init__(self, protocol: str = "1.0") -> None:
        self.framer: Framer | Framer2 = Framer2() if protocol == "2.0" else Framer()
        self._length = _wire2 if protocol == "2.0" else _wire1
        self.discarded = 0
        self.recent = bytearray()
        #: The time of each byte in ``recent`` (its chunk's).
        self.times: collections.deque[float | None] = collections.deque(maxlen=self._KEEP)

    def feed(self, data: bytes, t: float | None) -> tuple[list[_Framed], int]:
        """Bytes in; the packets they complete, and how many bytes were thrown away."""
        self.recent += data
        del self.recent[: -self._KEEP]
        self.times.extend([t] * len(data))
        packets = self.framer.feed(data, t)
        lost = self.framer.discarded_bytes - self.discarded
        self.discarded = self.framer.discarded_bytes
        out: list[_Framed] = []
        for packet in packets:
            size = self._length(packet)
            out.append((packet, bytes(self.recent[-size:]), self.times[-size] if size <= len(self.times) else t))
        return out, lost


class _BothStream:
    """A Protocol 1.0 and a 2.0 framer on one direction's bytes; the first packet completed claims its bytes, unless
    it is corrupt and the other framer's frame began before it (it is then that frame's data)."""

    #: Bytes kept to give a packet its wire bytes: the longest frame either framer accepts.
    _KEEP = DEFAULT_MAX_LENGTH + _FRAME2_OVERHEAD + 1

    def __init__(self) -> None:
        self.framer1, self.framer2 = Framer(), Framer2()
        self.recent = bytearray()
        self.times: collections.deque[float | None] = collections.deque(maxlen=self._KEEP)
        #: Bytes since the last packet ended that no packet has claimed yet.
        self.unclaimed = 0

    def feed(self, byte: bytes, t: float | None) -> tuple[list[_Framed], int]:
        """One byte in; the packets it completes, and the noise before them."""
        self.unclaimed += 1
        self.recent += byte
        del self.recent[: -self._KEEP]
        self.times.append(t)
        out: list[_Framed] = []
        lost = 0
        for framer, other, length in ((self.framer2, self.framer1, _wire2), (self.framer1, self.framer2, _wire1)):
            for packet in framer.feed(byte, t):
                size = length(packet)
                # A corrupt frame inside the other protocol's frame (which holds more bytes than it: it began
                # earlier) is that frame's data: a 2.0 packet's data may hold FF FF, and the 1.0 frame it starts
                # ends on a checksum that fails.  It claims nothing; the other frame goes on.
                if not _intact(packet) and other.buffered > size:
                    continue
                lost += max(self.unclaimed - size, 0)
                self.unclaimed = 0
                other.reset()
                out.append((packet, bytes(self.recent[-size:]), self.times[-size] if size <= len(self.times) else t))
            if out:
                break  # the other framer was reset: the byte was this packet's
        return out, lost


def _wire1(packet: InstructionPacket) -> int:
    return len(packet.params) + 6


def _intact(packet: AnyPacket) -> bool:
    """Whether a packet's checksum (1.0) or CRC (2.0) held."""
    return packet.checksum_ok if isinstance(packet, InstructionPacket) else packet.crc_ok


def _asked_of(request, servo_id: int):
    """``request`` (the last instruction, either protocol) if a status from ``servo_id`` can answer it (it went to
    that ID, or to all): the status's data is named by that request's addresses, and by no other servo's."""
    return request if request is not None and request.id in (servo_id, BROADCAST_ID) else None


#: How long after a Bulk Read (or its last answer) the next listed servo's answer may come: its Return Delay Time
#: (at most 508 us) and the wire time of a status, well inside a servo's own partial-packet timeout.
BULK_ANSWER_WINDOW_S = DEFAULT_SILENCE_TIMEOUT_S


def _may_answer(request: InstructionPacket, packet: InstructionPacket) -> bool:
    """Whether ``packet`` can be the Protocol 1.0 status answering ``request``: only a READ's answer has parameters,
    exactly the length it asked, and it never carries Angle Limit Error alone (that answers a goal write), which is
    READ's code: a packet that cannot be the answer is the host's next instruction (the last got no reply: Status
    Return Level 1, or a reply lost)."""
    if request.instruction == Instruction.READ and request.checksum_ok and len(request.params) == 2:
        return len(packet.params) == request.params[1] and packet.instruction != StatusError.ANGLE_LIMIT
    return not packet.params


class _Conversation:
    """The last instruction: it names a READ's data and says who may answer."""

    def __init__(self, echo: bool | None = None) -> None:
        #: Whether the wire echoes the host's bytes (a trace's header says; None: not known, an echo is possible).
        self.echo = echo
        self.request: InstructionPacket | None = None
        #: When the last instruction ended (a paced trace records its wire end) and, paced, a byte's wire time.
        self.t: float | None = None
        self.byte_s: float | None = None
        self.answered = False
        #: A Bulk Read's listed IDs yet to answer, each with its block's length, in list order (they answer in turn),
        #: and when the Bulk Read or the last of its answers was seen.
        self.bulk_pending: list[tuple[int, int]] = []
        self.bulk_t: float | None = None
        self.request2: InstructionPacket2 | None = None
        self.t2: float | None = None
        self.byte_s2: float | None = None
        #: The instruction (either protocol) decoded last, while nothing has been decoded since: only then can a
        #: repeat of it be the adapter's echo, which comes right after it, before any reply.
        self.echo_due: AnyPacket | None = None

    def _may_echo(self, packet: AnyPacket, last: AnyPacket | None, direction: str | None) -> bool:
        return (direction != IN and self.echo is not False and last is not None and self.echo_due is last
                and packet == last)

    @staticmethod
    def _latency(since: float | None, byte_s: float | None, chunk: Chunk, first_t: float | None) -> float | None:
        """Seconds from the instruction's end to the status: on a paced wire from the status's first byte's start
        (its chunk came when that byte's last bit had), else to the chunk that completed it."""
        if chunk.t is None or since is None:
            return None
        if byte_s is not None and first_t is not None:
            return first_t - byte_s - since
        return chunk.t - since

    def classify(self, packet: InstructionPacket, direction: str | None, t: float | None = None) -> str:
        last = self.request
        if direction == IN:
            return INSTRUCTION
        if self._may_echo(packet, last, direction):
            return ECHO
        if direction == OUT:
            return STATUS
        # After a broadcast PING every servo answers, each with a bare status (no parameters on Protocol 1.0): a
        # packet with parameters is the host's next instruction (a capture went on reading everything as replies).
        broadcast_ping = (last is not None and last.id == BROADCAST_ID and last.instruction == Instruction.PING
                          and not packet.params)
        if last is not None and (broadcast_ping or (packet.id == last.id and not self.answered
                                                    and _may_answer(last, packet))):
            return STATUS
        # After a Bulk Read each listed servo answers with its block's data (its error byte can equal an
        # instruction code: Input Voltage is PING's), in list order, each right after the one before it: a packet
        # later than that is the host's (a retry READ to the ID whose answer was lost has the block's length).
        if self.bulk_pending and (packet.id, len(packet.params)) == self.bulk_pending[0] and (
                t is None or self.bulk_t is None or t - self.bulk_t <= BULK_ANSWER_WINDOW_S):
            return STATUS
        if packet.instruction not in _INSTRUCTIONS and packet.instruction < 0x80:
            return STATUS
        return INSTRUCTION

    def describe2(self, packet: InstructionPacket2 | StatusPacket2, wire: bytes, chunk: Chunk,
                  names: Mapping[int, Mapping[int, str]], first_t: float | None = None) -> Decoded:
        """A Protocol 2.0 packet: a status says so itself; a repeat of the last instruction right after it is the
        echo."""
        last = self.request2
        if isinstance(packet, StatusPacket2):
            self.echo_due = None
            latency = self._latency(self.t2, self.byte_s2, chunk, first_t)
            text = describe_status2(packet, _asked_of(last, packet.id), names.get(packet.id, self._common(names)))
            return Decoded(chunk.t, STATUS, packet, text, latency, wire=wire)
        table = names.get(packet.id, self._common(names))
        if self._may_echo(packet, last, chunk.direction):
            self.echo_due = None
            return Decoded(chunk.t, ECHO, packet, "echo of " + describe_instruction2(packet, table, names), wire=wire)
        self.request2, self.t2, self.byte_s2 = packet, _ended(chunk), chunk.byte_s
        self.echo_due = packet
        return Decoded(chunk.t, INSTRUCTION, packet, describe_instruction2(packet, table, names), wire=wire)

    @staticmethod
    def _common(names: Mapping[int, Mapping[int, str]]) -> Mapping[int, str] | None:
        """Names for a packet to the broadcast ID: the first servo's table (the X series share their addresses)."""
        return next(iter(names.values()), None)

    def describe(self, packet: InstructionPacket, wire: bytes, chunk: Chunk, profile: str, tables: Mapping[int, Layout],
                 first_t: float | None = None) -> Decoded:
        """A Protocol 1.0 packet, its registers named by its ID's table in ``tables``, else ``profile``'s."""
        kind = self.classify(packet, chunk.direction, chunk.t)
        if kind == STATUS:
            self.echo_due = None
            latency = self._latency(self.t, self.byte_s, chunk, first_t)
            self.answered = True
            if self.bulk_pending and self.bulk_pending[0][0] == packet.id:
                del self.bulk_pending[0]
                self.bulk_t = chunk.t
            text = describe_status(packet.id, packet.instruction, packet.params, _asked_of(self.request, packet.id),
                                   tables.get(packet.id, profile), packet.checksum_ok)
            return Decoded(chunk.t, STATUS, packet, text, latency, wire=wire)
        if kind == ECHO:
            self.echo_due = None
            return Decoded(chunk.t, ECHO, packet, "echo of " + describe_instruction(packet, profile, tables), wire=wire)
        self.request, self.t, self.byte_s, self.answered = packet, _ended(chunk), chunk.byte_s, False
        self.echo_due = packet
        blocks = parse_bulk_read(bytes(packet.params)) if packet.instruction == Instruction.BULK_READ else None
        self.bulk_pending, self.bulk_t = [(b.servo_id, b.length) for b in blocks or ()], chunk.t
        return Decoded(chunk.t, INSTRUCTION, packet, describe_instruction(packet, profile, tables), wire=wire)


def _ended(chunk: Chunk) -> float | None:
    """When an instruction ending in ``chunk`` ended: its wire end where the trace records one (paced), else the
    chunk's time."""
    return chunk.end if chunk.end is not None else chunk.t


class Decoder:
    """Decodes chunks as they come (a live view), keeping the framers and the conversation between calls.

    ``echo``: whether the wire echoes the host's bytes (a trace's header says so as ``"echo"``); False: no packet
    is an echo; None (not known): a repeat of an instruction right after it is taken as its echo.
    """

    def __init__(self, *, profile: str = DEFAULT_PROFILE, protocol: str = "1.0", servos: str | None = None,
                 echo: bool | None = None) -> None:
        if protocol not in PROTOCOLS:
            raise ValueError(f"protocol must be one of {', '.join(PROTOCOLS)}, got {protocol!r}")
        self.profile = profile
        self.protocol = protocol
        tables = tables_by_protocol(servos, profile) if servos else {"1.0": {}, "2.0": {}}
        #: Protocol 1.0 tables per ID that ``servos`` (the ``--servo`` text) names; other IDs: ``profile``'s.
        self.tables1 = tables["1.0"]
        #: Protocol 2.0 register names per ID (``servos``), else addresses; a signed register's name says so.
        self.names = {servo_id: _names(table) for servo_id, table in tables["2.0"].items()}
        if protocol == "both":
            self._both = {IN: _BothStream(), OUT: _BothStream(), None: _BothStream()}
        self._streams = {IN: _Stream(protocol), OUT: _Stream(protocol), None: _Stream(protocol)}
        self._talk = _Conversation(echo)

    def _follow_id_write(self, packet: AnyPacket) -> None:
        """A WRITE of the ID register moves that servo's table to its new ID (its later packets are named by it)."""
        if isinstance(packet, InstructionPacket):
            table = self.tables1.get(packet.id)
            if (table is not None and packet.instruction == Instruction.WRITE and packet.checksum_ok
                    and len(packet.params) >= 2 and packet.params[0] == table.by_name["id"].address
                    and packet.params[1] < BROADCAST_ID):
                self.tables1[packet.params[1]] = self.tables1.pop(packet.id)
        elif isinstance(packet, InstructionPacket2):
            names = self.names.get(packet.id)
            if (names is not None and packet.instruction == Instruction2.WRITE and packet.crc_ok
                    and len(packet.params) >= 3 and names.get(packet.params[0] | packet.params[1] << 8) == "id"
                    and packet.params[2] < 0xFD):
                self.names[packet.params[2]] = self.names.pop(packet.id)

    def _show(self, framed: list[_Framed], chunk: Chunk, out: list[Decoded]) -> None:
        for packet, wire, first_t in framed:
            if isinstance(packet, InstructionPacket):
                out.append(self._talk.describe(packet, wire, chunk, self.profile, self.tables1, first_t))
            else:
                out.append(self._talk.describe2(packet, wire, chunk, self.names, first_t))
            if out[-1].kind == INSTRUCTION:
                self._follow_id_write(packet)

    def feed(self, chunk: Chunk, out: list[Decoded] | None = None) -> list[Decoded]:
        """Append the packets ``chunk`` completes to ``out`` (a new list by default) and return it."""
        out = [] if out is None else out
        if self.protocol == "both":
            return self._feed_both(chunk, out)
        stream = self._streams[chunk.direction]
        # Byte by byte, so discarded bytes are reported where they were on the line.
        for offset in range(len(chunk.data)):
            framed, lost = stream.feed(chunk.data[offset : offset + 1], chunk.t)
            if lost:
                if out and out[-1].kind == GARBAGE and out[-1].t == chunk.t:
                    lost += out.pop().discarded
                out.append(Decoded(chunk.t, GARBAGE, None, f"{lost} byte(s) discarded while hunting for a frame", discarded=lost))
            self._show(framed, chunk, out)
        return out

    def finish(self, out: list[Decoded] | None = None) -> list[Decoded]:
        """Append what is left at the end of a trace, bytes no frame completed, to ``out`` (a new list by default)."""
        out = [] if out is None else out
        if self.protocol == "both":
            left = {direction: stream.unclaimed for direction, stream in self._both.items()}
        else:
            left = {direction: stream.framer.buffered for direction, stream in self._streams.items()}
        for count in left.values():
            if count:
                out.append(Decoded(None, GARBAGE, None, f"{count} byte(s) at the end that no frame completed", discarded=count))
        return out

    def _feed_both(self, chunk: Chunk, out: list[Decoded]) -> list[Decoded]:
        stream = self._both[chunk.direction]
        for offset in range(len(chunk.data)):
            framed, lost = stream.feed(chunk.data[offset : offset + 1], chunk.t)
            if lost:
                out.append(Decoded(chunk.t, GARBAGE, None, f"{lost} byte(s) discarded while hunting for a frame", discarded=lost))
            self._show(framed, chunk, out)
        return out


def choose_protocol(chunks: Iterable[Chunk], servos: str | None = None) -> str:
    """The protocol :func:`decode` frames ``chunks`` by when not told: ``"2.0"`` for a trace (every chunk has its
    direction) whose ``servos`` (its header's: every servo on the wire) are Protocol 2.0 servos only, else
    ``"both"`` when ``servos`` names 2.0 servos or the bytes of one direction hold a 2.0 header, else ``"1.0"``
    (a raw capture's ``servos`` name the registers of the servos one wants named, not every servo on its wire).

    One pass, in memory flat in the length of ``chunks``: each direction's last bytes are kept only to find a
    header split across its chunks, and the pass stops as soon as the answer is known.
    """
    tables = tables_by_protocol(servos) if servos else {"1.0": {}, "2.0": {}}
    if tables["2.0"] and tables["1.0"]:
        return "both"
    if tables["2.0"]:  # 2.0 servos named only: a chunk of no direction (a raw capture) may hold 1.0 packets too
        # A trace records every chunk's direction and a raw capture none: the first chunk says which (reading on
        # through a trace read every line once more before the first was printed)
        first = next(iter(chunks), None)
        return "both" if first is not None and first.direction is None else "2.0"
    keep = len(HEADER2) - 1
    tails: dict[str | None, bytes] = {}
    for chunk in chunks:
        tail = tails.get(chunk.direction, b"")
        if HEADER2 in chunk.data or HEADER2 in tail + chunk.data[:keep]:
            return "both"
        tails[chunk.direction] = (tail + chunk.data[-keep:])[-keep:]
    return "1.0"


#: The most bytes of one chunk fed at a time (a raw capture is one chunk of the whole file): the lines they decode
#: to are handed on before the next piece is fed.
_PIECE_BYTES = 4096


def _pieces(chunk: Chunk) -> Iterator[Chunk]:
    """``chunk`` cut into pieces of at most :data:`_PIECE_BYTES`, each with its time, direction and wire end: the
    decoder takes bytes one at a time, so the pieces decode as the whole chunk does."""
    if len(chunk.data) <= _PIECE_BYTES:
        yield chunk
        return
    for start in range(0, len(chunk.data), _PIECE_BYTES):
        yield chunk._replace(data=chunk.data[start : start + _PIECE_BYTES])


def iter_decode(chunks: Iterable[Chunk], *, profile: str = DEFAULT_PROFILE, protocol: str | None = None,
                servos: str | None = None, echo: bool | None = None) -> Iterator[Decoded]:
    """:func:`decode`'s lines as they are decoded: each line comes once its packet is complete, and the memory
    held is a packet's, however long the trace.  ``ax12emu decode`` prints through it.

    ``protocol`` None (choose, :func:`choose_protocol`) reads ``chunks`` twice, so it must be a collection, not
    an iterator: the choice needs every byte (a 2.0 servo that first speaks late in a trace makes it ``"both"``,
    which a prefix would miss and decode that servo's packets as noise).  To decode a file as it is read, choose
    from a first reading of it and decode a second: ``iter_decode(read_capture(path),
    protocol=choose_protocol(read_capture(path), servos), ...)``.
    """
    if protocol is None:
        if iter(chunks) is chunks:
            raise TypeError("iter_decode chooses the protocol from every chunk: give a collection, or the protocol "
                            "(choose_protocol over a first reading)")
        protocol = choose_protocol(chunks, servos)
    decoder = Decoder(profile=profile, protocol=protocol, servos=servos, echo=echo)
    held: list[Decoded] = []
    for chunk in chunks:
        for piece in _pieces(chunk):
            decoder.feed(piece, held)
            # Discarded bytes at one time are one line (Decoder.feed adds to its last): a run the next piece may
            # go on is held back until a packet ends it.
            ready = len(held) - (1 if held and held[-1].kind == GARBAGE else 0)
            yield from held[:ready]
            del held[:ready]
    yield from decoder.finish(held)


def decode(chunks: Iterable[Chunk], *, profile: str = DEFAULT_PROFILE, protocol: str | None = None,
           servos: str | None = None, echo: bool | None = None) -> list[Decoded]:
    """Decode chunks (a trace or a raw capture) into packets in line order (:func:`iter_decode`, as one list).

    ``protocol``: ``"1.0"``, ``"2.0"``, ``"both"``, or None to choose (:func:`choose_protocol`: the chunks are
    then read into a list first).
    ``echo``: whether the wire echoed the host's bytes (a trace header's ``"echo"``; None: not known).
    """
    if protocol is None:
        chunks = list(chunks)
        protocol = choose_protocol(chunks, servos)
    return list(iter_decode(chunks, profile=profile, protocol=protocol, servos=servos, echo=echo))


#: Column shown for each kind.
_WHO = {INSTRUCTION: "host ", STATUS: "servo", ECHO: "echo ", GARBAGE: "noise"}


def format_decoded(item: Decoded) -> str:
    """One line: time, who, description, and a status packet's latency."""
    when = f"{item.t:11.6f}" if item.t is not None else " " * 11
    line = f"{when}  {_WHO[item.kind]}  {item.text}"
    if item.latency_s is not None:
        line += f"  (+{item.latency_s * 1e6:.0f} us)"
    return line
