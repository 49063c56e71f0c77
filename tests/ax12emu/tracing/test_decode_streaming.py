"""Decoding as the chunks come: a line is handed on once its packet is complete, so a long trace's first lines
come at once and the memory held is a packet's; the lines are decode()'s, and auto still chooses from every byte."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from ax12emu.protocol.packets import Instruction, encode_instruction, encode_status
from ax12emu.protocol.packets2 import encode_instruction2
from ax12emu.tracing import decoder as decoder_module
from ax12emu.tracing.decoder import GARBAGE, INSTRUCTION, STATUS, Decoder, choose_protocol, decode, iter_decode
from ax12emu.tracing.trace import IN, OUT, Chunk

PING = encode_instruction(1, Instruction.PING)
ANSWER = encode_status(1, 0)


def _whole(chunks: list[Chunk], **options) -> list[tuple[str, str, int]]:
    """What one Decoder gives with every chunk fed whole into one list (decode()'s lines before it streamed)."""
    decoder = Decoder(**options)
    out: list = []
    for chunk in chunks:
        decoder.feed(chunk, out)
    return [(d.kind, d.text, d.discarded) for d in decoder.finish(out)]


def test_the_first_line_comes_before_the_chunks_run_out():
    pulled = 0

    def conversation() -> Iterator[Chunk]:
        nonlocal pulled
        for k in range(1000):
            pulled += 1
            yield Chunk(k * 1e-3, IN, PING)
            yield Chunk(k * 1e-3 + 5e-4, OUT, ANSWER)

    lines = iter_decode(conversation(), protocol="1.0")
    assert next(lines).kind == INSTRUCTION and pulled == 1
    assert next(lines).kind == STATUS and pulled == 1
    assert sum(1 for _ in lines) == 1998 and pulled == 1000


def test_a_raw_capture_is_decoded_a_piece_at_a_time(monkeypatch):
    """A raw capture is one chunk of the whole file: its first line comes before the rest of it is framed."""
    fed: list[int] = []
    feed = Decoder.feed
    monkeypatch.setattr(Decoder, "feed", lambda self, chunk, out=None: fed.append(len(chunk.data)) or feed(self, chunk, out))
    capture = (PING + ANSWER) * 2000
    lines = iter_decode([Chunk(None, None, capture)], protocol="1.0")
    assert next(lines).text == "PING id=1"
    assert sum(fed) <= decoder_module._PIECE_BYTES < len(capture)
    assert sum(1 for _ in lines) == 3999 and sum(fed) == len(capture)


@pytest.mark.parametrize("split", [len(PING) + 1, len(PING) + 2, 3 * len(PING)])
def test_noise_across_chunks_of_one_time_is_one_line_as_before(split):
    """Discarded bytes of one time (a raw capture's: none) are one line though a chunk ends inside them."""
    capture = PING + b"\x00\x13\x07" + ANSWER + PING
    chunks = [Chunk(None, None, capture[:split]), Chunk(None, None, capture[split:])]
    assert [(d.kind, d.text, d.discarded) for d in iter_decode(chunks, protocol="1.0")] == _whole([Chunk(None, None, capture)])
    assert [d.discarded for d in decode(chunks) if d.kind == GARBAGE] == [3]


@pytest.mark.parametrize("protocol", ["1.0", "both"])
def test_a_chunk_longer_than_a_piece_decodes_as_it_did_whole(protocol):
    """Noise and a packet straddling where a long chunk is cut decode as they did from the whole chunk."""
    piece = decoder_module._PIECE_BYTES
    head = (PING + ANSWER) * (piece // len(PING + ANSWER))
    capture = head + b"\x00" * (piece - len(head) - 2) + b"\x13\x00\x07\x01" + PING + ANSWER + encode_instruction(1, 2, bytes([36, 2]))
    capture += b"\xff\xff\x01"  # a frame left open at the end
    chunks = [Chunk(0.5, IN, capture)]
    assert [(d.kind, d.text, d.discarded) for d in iter_decode(chunks, protocol=protocol)] == _whole(chunks, protocol=protocol)


def test_auto_needs_chunks_it_can_read_twice():
    with pytest.raises(TypeError, match="choose_protocol"):
        next(iter_decode(iter([Chunk(0.0, IN, PING)])))
    assert [d.text for d in iter_decode([Chunk(0.0, IN, PING)])] == ["PING id=1"]


def test_the_choice_reads_every_byte_and_each_direction_on_its_own():
    """A 2.0 servo that first speaks late, or a header cut between two chunks of one direction, makes it both;
    a header's bytes taken from both directions are no header."""
    late = [Chunk(k * 1e-3, IN, PING) for k in range(5000)] + [Chunk(5.0, IN, encode_instruction2(1, 1))]
    assert choose_protocol(late) == "both"
    assert (decode(late)[-1].kind, decode(late)[-1].raw) == (INSTRUCTION, encode_instruction2(1, 1))
    header = encode_instruction2(1, 1)
    cut = [Chunk(0.0, IN, header[:2]), Chunk(0.1, OUT, ANSWER), Chunk(0.2, IN, header[2:])]
    assert choose_protocol(cut) == "both"
    across = [Chunk(0.0, IN, b"\xff\xff"), Chunk(0.1, OUT, b"\xfd\x00")]
    assert choose_protocol(across) == "1.0"
    assert choose_protocol([Chunk(0.0, IN, b"\xff"), Chunk(0.1, IN, b"\xff"), Chunk(0.2, IN, b"\xfd"),
                            Chunk(0.3, IN, b"\x00")]) == "both"
    assert choose_protocol([], servos="1:xl430-w250") == "2.0"
    assert choose_protocol([Chunk(None, None, PING)], servos="1:xl430-w250") == "both"


def test_a_trace_of_protocol_2_servos_only_is_chosen_from_its_first_line():
    """Its header names only 2.0 servos and every line has a direction: the choice needs no more, and reading on
    read the whole trace once more before the first decoded line was printed."""

    def trace():
        yield Chunk(0.0, IN, encode_instruction2(1, 1))
        raise AssertionError("read past the first line")

    assert choose_protocol(trace(), servos="1:xl430-w250") == "2.0"
