"""A protocol view of captured bytes: chunks in, decoded packets out.

Why it exists: ``ax12emu decode`` shows a trace the way a logic analyser's
protocol decoder does: one line per packet with time, direction,
instruction or status, ID, register names and values, error bits, and the
bytes thrown away while hunting for a frame.  It reuses the emulator's own
framer (status packets share the instruction packets' framing) and
:mod:`ax12emu.protocol.describe`, so the decoder and the servos agree on every byte.

Direction: a trace says which way each chunk went.  A raw capture does not,
so each packet is classified by context: a packet from the ID the last
instruction expects an answer from is a status packet (``0xFE`` PING: any ID),
an exact repeat of the last instruction is the adapter's echo, a code that is
no instruction but a plausible error byte is a status packet, and anything
else is an instruction.  Without timestamps a truncated packet cannot be told
from one still arriving, so it may swallow the start of the next.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

from ax12emu.protocol.control_table import DEFAULT_PROFILE
from ax12emu.protocol.describe import describe_instruction, describe_status
from ax12emu.protocol.framing import Framer
from ax12emu.protocol.packets import BROADCAST_ID, Instruction, InstructionPacket

from .trace import IN, OUT, Chunk

__all__ = ["Decoded", "Decoder", "decode", "format_decoded", "INSTRUCTION", "STATUS", "ECHO", "GARBAGE"]

INSTRUCTION, STATUS, ECHO, GARBAGE = "instruction", "status", "echo", "garbage"
_INSTRUCTIONS = frozenset(int(code) for code in Instruction)


class Decoded(NamedTuple):
    """One decoded packet (or a run of discarded bytes)."""

    t: float | None
    kind: str
    packet: InstructionPacket | None
    text: str
    #: For a status packet: seconds since the instruction it answers ended (traces only).
    latency_s: float | None = None
    #: For garbage: how many bytes were thrown away.
    discarded: int = 0

    @property
    def raw(self) -> bytes:
        """Wire bytes of the packet (with its checksum as received if it was corrupt)."""
        if self.packet is None:
            return b""
        data = self.packet.encode()
        return data if self.packet.checksum_ok else data[:-1] + bytes((data[-1] ^ 0xFF,))


class _Stream:
    """One framer per direction, counting what it throws away."""

    def __init__(self) -> None:
        self.framer = Framer()
        self.discarded = 0

    def feed(self, data: bytes, t: float | None) -> tuple[list[InstructionPacket], int]:
        packets = self.framer.feed(data, t)
        lost = self.framer.discarded_bytes - self.discarded
        self.discarded = self.framer.discarded_bytes
        return packets, lost


class _Conversation:
    """The last instruction: it names a READ's data and says who may answer."""

    def __init__(self) -> None:
        self.request: InstructionPacket | None = None
        self.t: float | None = None
        self.answered = False

    def classify(self, packet: InstructionPacket, direction: str | None) -> str:
        last = self.request
        if direction == IN:
            return INSTRUCTION
        if last is not None and packet == last:
            return ECHO
        if direction == OUT:
            return STATUS
        broadcast_ping = last is not None and last.id == BROADCAST_ID and last.instruction == Instruction.PING
        if last is not None and (broadcast_ping or (packet.id == last.id and not self.answered)):
            return STATUS
        if packet.instruction not in _INSTRUCTIONS and packet.instruction < 0x80:
            return STATUS
        return INSTRUCTION

    def describe(self, packet: InstructionPacket, chunk: Chunk, profile: str) -> Decoded:
        kind = self.classify(packet, chunk.direction)
        if kind == STATUS:
            latency = None if chunk.t is None or self.t is None else chunk.t - self.t
            self.answered = True
            text = describe_status(packet.id, packet.instruction, packet.params, self.request, profile, packet.checksum_ok)
            return Decoded(chunk.t, STATUS, packet, text, latency)
        if kind == ECHO:
            return Decoded(chunk.t, ECHO, packet, "echo of " + describe_instruction(packet, profile))
        self.request, self.t, self.answered = packet, chunk.t, False
        return Decoded(chunk.t, INSTRUCTION, packet, describe_instruction(packet, profile))


class Decoder:
    """Decodes chunks as they come (a live view), keeping the framers and the conversation between calls."""

    def __init__(self, *, profile: str = DEFAULT_PROFILE) -> None:
        self.profile = profile
        self._streams = {IN: _Stream(), OUT: _Stream(), None: _Stream()}
        self._talk = _Conversation()

    def feed(self, chunk: Chunk, out: list[Decoded] | None = None) -> list[Decoded]:
        """Append the packets ``chunk`` completes to ``out`` (a new list by default) and return it."""
        out = [] if out is None else out
        stream = self._streams[chunk.direction]
        # Byte by byte, so discarded bytes are reported where they were on the line.
        for offset in range(len(chunk.data)):
            packets, lost = stream.feed(chunk.data[offset : offset + 1], chunk.t)
            if lost:
                if out and out[-1].kind == GARBAGE and out[-1].t == chunk.t:
                    lost += out.pop().discarded
                out.append(Decoded(chunk.t, GARBAGE, None, f"{lost} byte(s) discarded while hunting for a frame", discarded=lost))
            out.extend(self._talk.describe(packet, chunk, self.profile) for packet in packets)
        return out


def decode(chunks: Iterable[Chunk], *, profile: str = DEFAULT_PROFILE) -> list[Decoded]:
    """Decode chunks (a trace or a raw capture) into packets in line order."""
    decoder = Decoder(profile=profile)
    out: list[Decoded] = []
    for chunk in chunks:
        decoder.feed(chunk, out)
    return out


#: Column shown for each kind.
_WHO = {INSTRUCTION: "host ", STATUS: "servo", ECHO: "echo ", GARBAGE: "noise"}


def format_decoded(item: Decoded) -> str:
    """One line: time, who, description, and a status packet's latency."""
    when = f"{item.t:11.6f}" if item.t is not None else " " * 11
    line = f"{when}  {_WHO[item.kind]}  {item.text}"
    if item.latency_s is not None:
        line += f"  (+{item.latency_s * 1e6:.0f} us)"
    return line
