"""Who sent a packet, by context: a repeat is an echo only right after its instruction; a reply must fit its request."""

from __future__ import annotations

from ax12emu.protocol.packets import encode_instruction, encode_status
from ax12emu.protocol.packets2 import Instruction2, encode_instruction2, encode_status2
from ax12emu.tracing.decoder import ECHO, INSTRUCTION, STATUS, Decoder, decode
from ax12emu.tracing.trace import IN, OUT, Chunk

READ = encode_instruction(1, 0x02, bytes([36, 2]))
PING = encode_instruction(1, 0x01)


def _kinds(capture: bytes, **options) -> list[str]:
    return [d.kind for d in decode([Chunk(None, None, capture)], **options)]


def test_a_host_polling_the_same_read_is_no_echo():
    """Raw capture: each poll answered; every poll is the host's, not only the first."""
    capture = READ + encode_status(1, 0, bytes([0, 2])) + READ + encode_status(1, 0, bytes([4, 2]))
    capture += PING + encode_status(1, 0) + PING + encode_status(1, 0)
    assert _kinds(capture) == [INSTRUCTION, STATUS] * 4


def test_polling_with_an_alarm_whose_error_byte_is_an_instruction_code():
    """Input Voltage (0x01) is PING's code: the answers stay answers, the polls polls."""
    capture = READ + encode_status(1, 0, bytes([0, 2])) + (READ + encode_status(1, 1, bytes([4, 2]))) * 2
    decoded = decode([Chunk(None, None, capture)])
    assert [d.kind for d in decoded] == [INSTRUCTION, STATUS] * 3
    assert decoded[-1].text == "STATUS id=1 INPUT_VOLTAGE present_position=516"


def test_a_2_0_host_polling_the_same_read_is_no_echo():
    read = encode_instruction2(1, Instruction2.READ, bytes([132, 0, 4, 0]))
    capture = b"".join(read + encode_status2(1, 0, (2048 + i).to_bytes(4, "little")) for i in range(3))
    assert _kinds(capture, servos="1:xl430-w250") == [INSTRUCTION, STATUS] * 3


def test_the_echo_right_after_its_instruction_is_still_an_echo():
    capture = READ + READ + encode_status(1, 0, bytes([0, 2])) + READ + READ + encode_status(1, 0, bytes([0, 2]))
    assert _kinds(capture) == [INSTRUCTION, ECHO, STATUS] * 2
    read2 = encode_instruction2(1, Instruction2.READ, bytes([132, 0, 4, 0]))
    answer2 = encode_status2(1, 0, (2048).to_bytes(4, "little"))
    chunks = [Chunk(0.0, IN, read2), Chunk(0.001, OUT, read2), Chunk(0.002, OUT, answer2)]
    assert [d.kind for d in decode(chunks)] == [INSTRUCTION, ECHO, STATUS]
    assert [d.kind for d in decode(chunks, echo=True)] == [INSTRUCTION, ECHO, STATUS]


def test_a_trace_without_echo_shows_a_ping_answered_with_input_voltage_as_its_answer():
    """``ff ff 01 02 01 fb`` is a PING and its answer with Input Voltage Error alike: the header says no echo."""
    answer = encode_status(1, 0x01)
    assert answer == PING
    chunks = [Chunk(0.0, IN, PING), Chunk(0.0005, OUT, answer), Chunk(0.001, IN, READ),
              Chunk(0.0015, OUT, encode_status(1, 0x01, bytes([0, 2])))]
    decoded = decode(chunks, echo=False)
    assert [d.kind for d in decoded] == [INSTRUCTION, STATUS, INSTRUCTION, STATUS]
    assert decoded[1].text == "STATUS id=1 INPUT_VOLTAGE"
    assert abs(decoded[1].latency_s - 0.0005) < 1e-9
    assert [d.kind for d in decode(chunks)] == [INSTRUCTION, ECHO, INSTRUCTION, STATUS]  # an old trace: as before
    live = Decoder(echo=False)  # the live view's decoder takes the setting too
    assert [d.kind for chunk in chunks for d in live.feed(chunk)] == [INSTRUCTION, STATUS, INSTRUCTION, STATUS]


def test_after_a_write_with_no_reply_the_next_read_is_the_hosts():
    """Status Return Level 1: a WRITE gets no reply, so the READ to the same ID after it is an instruction; a READ's
    answer has exactly the length it asked."""
    write = encode_instruction(1, 0x03, bytes([30, 0, 2]))
    capture = write + READ + encode_status(1, 0, bytes([0, 2]))
    decoded = decode([Chunk(None, None, capture)])
    assert [d.kind for d in decoded] == [INSTRUCTION, INSTRUCTION, STATUS]
    assert decoded[2].text == "STATUS id=1 ok present_position=512"


def test_a_read_retried_after_a_lost_reply_is_the_hosts():
    """An unplugged ID: the READ gets no reply and the host tries another.  A READ has READ's code (2) where a status
    has its error byte: Angle Limit Error alone, which answers a goal write, never a READ."""
    capture = encode_instruction(3, 0x02, bytes([36, 2])) + encode_instruction(3, 0x02, bytes([43, 1]))
    assert _kinds(capture) == [INSTRUCTION, INSTRUCTION]
    # A READ's answer of the asked length is still an answer, whatever alarm it carries (not Angle Limit alone).
    assert _kinds(READ + encode_status(1, 0x24, bytes([0, 2]))) == [INSTRUCTION, STATUS]
    # A write's answer has no parameters: a packet with some, after a write, is the host's.
    assert _kinds(encode_instruction(1, 0x03, bytes([25, 1])) + encode_instruction(1, 0x03, bytes([25, 0]))) == [
        INSTRUCTION, INSTRUCTION]
