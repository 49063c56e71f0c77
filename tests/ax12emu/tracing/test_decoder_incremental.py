"""The incremental Decoder (the live log) gives the same lines as decode() over a whole capture."""

from __future__ import annotations

from ax12emu.protocol.packets import Instruction, InstructionPacket
from ax12emu.tracing.decoder import Decoder, decode
from ax12emu.tracing.trace import IN, OUT, Chunk


def _capture() -> list[Chunk]:
    read = InstructionPacket(1, Instruction.READ, bytes((36, 2))).encode()
    status = bytes((0xFF, 0xFF, 1, 4, 0, 0x00, 0x02)) + bytes(((~(1 + 4 + 0 + 0 + 2)) & 0xFF,))
    ping = InstructionPacket(2, Instruction.PING, b"").encode()
    chunks = [Chunk(0.001, IN, read), Chunk(0.0015, OUT, status[:3]), Chunk(0.0016, OUT, status[3:])]
    chunks += [Chunk(0.002, IN, b"\x00\x13" + ping[:4]), Chunk(0.0021, IN, ping[4:])]  # noise, then a split packet
    return chunks


def test_feeding_chunk_by_chunk_equals_decoding_the_whole():
    chunks = _capture()
    whole = decode(chunks)
    decoder = Decoder()
    pieces = [line for chunk in chunks for line in decoder.feed(chunk)]
    assert [(d.kind, d.text) for d in pieces] == [(d.kind, d.text) for d in whole]
    assert [d.kind for d in whole] == ["instruction", "status", "garbage", "instruction"]
    assert "present_position=512" in whole[1].text
