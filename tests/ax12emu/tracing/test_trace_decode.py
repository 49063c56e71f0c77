"""Bus traces: recorded by the server, decoded back to packets; raw captures decoded too."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from emu_testkit import CONFORMANCE_TIMEOUT_S, EMULATOR_SILENCE_S

from ax12emu import conformance
from ax12emu.conformance.link import Link, open_port
from ax12emu.protocol.packets import encode_instruction, encode_status
from ax12emu.tracing.decoder import ECHO, GARBAGE, INSTRUCTION, STATUS, decode, format_decoded
from ax12emu.tracing.trace import Chunk, read_trace

#: Real time and real ports: the wall-clock tier (CI runs it too).
pytestmark = pytest.mark.wallclock


def test_conformance_trace_decodes_back_to_the_packets_sent(tmp_path, emulator):
    """Every packet the conformance suite sent appears, in order, among the decoded host packets.

    The emulator runs as its own process (as with ``serve --trace``), so the suite's timed
    return-delay check does not share this process's interpreter lock.
    """
    path = tmp_path / "bus.jsonl"
    served = emulator("--ids", "1,2", "--trace", str(path))
    link = Link(open_port(served.port, 1_000_000), timeout_s=CONFORMANCE_TIMEOUT_S, silence_s=EMULATOR_SILENCE_S)
    try:
        report = conformance.run_on_link(link, [1, 2])
    finally:
        link.close()
    assert served.stop() == 0  # the trace is flushed and closed on exit
    assert report.passed, report.table()
    decoded = decode(read_trace(path))
    host = [d.raw for d in decoded if d.kind == INSTRUCTION]
    assert host == link.sent
    statuses = [d for d in decoded if d.kind == STATUS]
    assert statuses and all(d.latency_s is not None and d.latency_s >= 0 for d in statuses)
    assert any(d.kind == GARBAGE for d in decoded), "the resync check's garbage is shown"
    first = json.loads(path.read_text().splitlines()[0])
    assert first["format"] == "ax12emu-trace/1"


def test_raw_capture_is_split_into_instructions_and_status_packets():
    """A binary capture with host and servo bytes interleaved decodes by context, names registers and errors."""
    capture = (
        encode_instruction(1, 0x02, bytes([36, 2]))
        + encode_status(1, 0x20, b"\x00\x02")
        + encode_instruction(1, 0x03, bytes([30, 0x20, 0x03]))
        + encode_instruction(1, 0x03, bytes([30, 0x20, 0x03]))  # the adapter's echo
        + b"\x00\x13"
        + encode_status(1, 0)
    )
    decoded = decode([Chunk(None, None, capture)])
    assert [d.kind for d in decoded] == [INSTRUCTION, STATUS, INSTRUCTION, ECHO, GARBAGE, STATUS]
    assert decoded[1].text == "STATUS id=1 OVERLOAD present_position=512"
    assert decoded[2].text == "WRITE id=1 goal_position=800"
    assert "OVERLOAD" in format_decoded(decoded[1])


def test_cli_decode_reads_trace_and_raw(tmp_path):
    """ax12emu decode prints one line per packet for a trace and for a raw capture."""
    raw = tmp_path / "capture.bin"
    raw.write_bytes(encode_instruction(1, 0x01) + encode_status(1, 0))
    result = subprocess.run([sys.executable, "-m", "ax12emu", "decode", str(raw)], capture_output=True, text=True, timeout=30)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines()[0].split()[-2:] == ["PING", "id=1"]
    assert "STATUS id=1 ok" in result.stdout


def test_raw_capture_next_instruction_to_same_id_is_not_a_status():
    """After its status packet, the next packet to the same ID is an instruction again."""
    capture = encode_instruction(1, 0x01) + encode_status(1, 0) + encode_instruction(1, 0x02, bytes([3, 1])) + encode_status(1, 0, b"\x01")
    kinds = [d.kind for d in decode([Chunk(None, None, capture)])]
    assert kinds == [INSTRUCTION, STATUS, INSTRUCTION, STATUS]
