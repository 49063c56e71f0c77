"""Protocol 2.0 packets in traces and captures: recorded by a served 2.0 bus, decoded with register names, and mixed with 1.0."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import serial

import ax12emu  # noqa: F401  (registers the URL handler)
from ax12emu import VirtualBus
from ax12emu.protocol.packets import encode_instruction, encode_status
from ax12emu.protocol.packets2 import Instruction2, encode_instruction2, encode_status2
from ax12emu.tracing.decoder import ECHO, GARBAGE, INSTRUCTION, STATUS, Decoder, decode
from ax12emu.tracing.trace import IN, OUT, Chunk, read_trace, trace_header

BAUD = 57600
PRESENT_POSITION, GOAL_POSITION, LED = 132, 116, 65


def u32(value: int) -> bytes:
    return value.to_bytes(4, "little")


def _exchange(link: serial.Serial, packet: bytes, reply_bytes: int) -> bytes:
    link.write(packet)
    return link.read(reply_bytes)


def test_a_served_2_0_bus_trace_decodes_with_the_models_register_names(tmp_path):
    """VirtualBus(servo=..., trace=...): the header names the servos; each host packet comes back, replies named."""
    path = tmp_path / "bus.jsonl"
    sent = [
        encode_instruction2(3, Instruction2.READ, bytes([PRESENT_POSITION, 0, 4, 0])),
        encode_instruction2(1, Instruction2.WRITE, bytes([LED, 0, 1])),
        encode_instruction2(1, Instruction2.WRITE, bytes([GOAL_POSITION, 0]) + u32(5000)),  # beyond the limit
        encode_instruction2(0xFE, Instruction2.SYNC_READ, bytes([PRESENT_POSITION, 0, 4, 0, 1, 3])),
    ]
    with VirtualBus(servo="1:xl430-w250,3:xl330-m077", transport="inprocess", trace=str(path)) as bus:
        position = bus.read(3, "present_position")
        with serial.serial_for_url(bus.port, baudrate=BAUD, timeout=0.5) as link:
            for packet, size in zip(sent, (15, 11, 11, 30)):
                assert len(_exchange(link, packet, size)) == size
    assert trace_header(path)["servos"] == "1:xl430-w250,3:xl330-m077"
    decoded = decode(read_trace(path), servos=trace_header(path)["servos"])
    assert [d.raw for d in decoded if d.kind == INSTRUCTION] == sent
    texts = [d.text for d in decoded]
    assert texts == [
        "READ id=3 present_position length=4",
        f"STATUS id=3 ok present_position={position}",
        "WRITE id=1 led=1 (1 byte)",
        "STATUS id=1 ok",
        "WRITE id=1 goal_position=5000 (4 bytes)",
        "STATUS id=1 DATA_RANGE",
        "SYNC_READ id=254 present_position length=4 ids=1,3",
        f"STATUS id=1 ok present_position={position}",
        f"STATUS id=3 ok present_position={position}",
    ]
    statuses = [d for d in decoded if d.kind == STATUS]
    assert all(d.latency_s is not None and d.latency_s >= 0 for d in statuses)
    assert statuses[-1].latency_s > statuses[-2].latency_s  # the Sync Read's answers one after another


def test_without_names_2_0_registers_show_by_address():
    packet = encode_instruction2(1, Instruction2.WRITE, bytes([LED, 0, 1]))
    assert [d.text for d in decode([Chunk(0.0, IN, packet)])] == ["WRITE id=1 @65=1 (1 byte)"]


def test_a_capture_mixing_1_0_and_2_0_decodes_both():
    """A raw capture (no direction, no time) of a wire with AX-12s and X-series servos, noise between packets.

    The 2.0 WRITE carries FF FF FD in its data, so it is stuffed (FF FF FD FD): a 1.0 framer alone
    would take that for a 1.0 header of LENGTH 253 and swallow the 1.0 PING after it.
    """
    write2 = encode_instruction2(2, Instruction2.WRITE, bytes([GOAL_POSITION, 0, 0xFF, 0xFF, 0xFD, 0x00]))
    assert b"\xff\xff\xfd\xfd" in write2
    capture = (
        encode_instruction(1, 0x02, bytes([36, 2]))  # 1.0 READ present_position
        + encode_status(1, 0, b"\x00\x02")
        + write2
        + encode_instruction(1, 0x01)  # 1.0 PING right after the stuffed 2.0 packet
        + encode_status(1, 0)
        + b"\x13\x37"  # noise
        + encode_instruction2(2, Instruction2.READ, bytes([PRESENT_POSITION, 0, 4, 0]))
        + encode_status2(2, 0, u32(2048))
        + encode_status2(2, 0, u32(2048))[:-1] + b"\x00"  # a corrupt copy of the status
    )
    decoded = decode([Chunk(None, None, capture)], servos="2:xm430-w350")
    assert [(d.kind, d.text) for d in decoded] == [
        (INSTRUCTION, "READ id=1 address=36 length=2 (present_position)"),
        (STATUS, "STATUS id=1 ok present_position=512"),
        (INSTRUCTION, f"WRITE id=2 goal_position={0x00FDFFFF} (4 bytes)"),  # the data FF FF FD 00, little-endian
        (INSTRUCTION, "PING id=1"),
        (STATUS, "STATUS id=1 ok"),
        (GARBAGE, "2 byte(s) discarded while hunting for a frame"),
        (INSTRUCTION, "READ id=2 present_position length=4"),
        (STATUS, "STATUS id=2 ok present_position=2048"),
        (STATUS, "STATUS id=2 ok BAD-CRC"),
    ]
    assert decoded[2].raw == write2
    one_protocol = decode([Chunk(None, None, capture)], protocol="1.0")
    assert "PING id=1" not in [d.text for d in one_protocol]  # what framing 1.0 alone would lose
    assert b"".join(d.raw for d in decoded if d.kind != GARBAGE) == capture.replace(b"\x13\x37", b"")


def test_the_echo_of_a_2_0_instruction_is_shown_as_echo():
    packet = encode_instruction2(1, Instruction2.PING)
    reply = encode_status2(1, 0, bytes([0x24, 0x04, 46]))
    decoded = decode([Chunk(0.0, IN, packet), Chunk(0.001, OUT, packet), Chunk(0.002, OUT, reply)])
    assert [d.kind for d in decoded] == [INSTRUCTION, ECHO, STATUS]
    assert decoded[2].text == "STATUS id=1 ok model=1060 firmware=46"


def test_a_1_0_trace_decodes_as_before():
    """Without a 2.0 header in the bytes, decode frames Protocol 1.0 alone, with its noise shown where it was dropped."""
    capture = encode_instruction(1, 0x01) + b"\x00\x13" + encode_status(1, 0)
    chunks = [Chunk(None, None, capture)]
    assert decode(chunks) == decode(chunks, protocol="1.0")
    assert [d.kind for d in decode(chunks)] == [INSTRUCTION, GARBAGE, STATUS]


def test_bad_decoder_arguments_are_named():
    with pytest.raises(ValueError, match="protocol must be one of"):
        Decoder(protocol="3.0")
    with pytest.raises(ValueError, match="unknown servo model 'xl999'"):
        Decoder(protocol="both", servos="1:xl999")


def test_cli_decode_of_a_2_0_trace_and_a_raw_capture(tmp_path):
    path = tmp_path / "t.jsonl"
    header = {"format": "ax12emu-trace/1", "started": "2026-01-01T00:00:00+00:00", "profile": "ax12a", "servos": "1:xl430-w250"}
    lines = [json.dumps(header),
             json.dumps({"t": 0.0, "dir": "in", "data": encode_instruction2(1, Instruction2.WRITE, bytes([LED, 0, 1])).hex(" ")})]
    path.write_text("\n".join(lines) + "\n")
    run = [sys.executable, "-m", "ax12emu", "decode"]
    result = subprocess.run([*run, str(path)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and "WRITE id=1 led=1 (1 byte)" in result.stdout, result.stderr
    raw = tmp_path / "capture.bin"
    raw.write_bytes(encode_instruction2(7, Instruction2.READ, bytes([PRESENT_POSITION, 0, 4, 0])))
    result = subprocess.run([*run, str(raw), "--servo", "7:xm430-w350"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and "READ id=7 present_position length=4" in result.stdout, result.stderr
    result = subprocess.run([*run, str(raw), "--servo", "xm430-w350"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "decode needs IDS:MODEL" in result.stderr  # not serve's "give --ids"
    assert "--ids" not in result.stderr
    header["servos"] = 123  # a header written by hand: an error naming it, not a traceback
    path.write_text("\n".join([json.dumps(header), *lines[1:]]) + "\n")
    result = subprocess.run([*run, str(path)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "the header's servos must be a text" in result.stderr, result.stderr
    assert "Traceback" not in result.stderr
