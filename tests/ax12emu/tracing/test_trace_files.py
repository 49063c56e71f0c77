"""What ``ax12emu decode`` makes of captures that are odd but real, and of files that are no trace at all."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

from ax12emu.protocol.packets import encode_instruction, encode_status
from ax12emu.protocol.packets2 import Instruction2, encode_instruction2
from ax12emu.tracing.decoder import GARBAGE, INSTRUCTION, STATUS, decode
from ax12emu.tracing.trace import TRACE_FORMAT, Chunk, read_trace

PING, READ, WRITE = 0x01, 0x02, 0x03


def _trace(tmp_path, chunks, **header) -> str:
    path = tmp_path / "t.jsonl"
    lines = [json.dumps({"format": TRACE_FORMAT, "started": "x", **header})]
    lines += [json.dumps({"t": t, "dir": d, "data": bytes(data).hex(" ")}) for t, d, data in chunks]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return str(path)


def _decode_cli(path: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ax12emu", "decode", path], capture_output=True, text=True, timeout=60)


def test_after_a_broadcast_ping_the_hosts_next_instruction_is_an_instruction():
    """A scan (broadcast PING) then a READ in a raw capture: every later packet was taken for a reply."""
    capture = (encode_instruction(0xFE, PING) + encode_status(1, 0) + encode_instruction(1, READ, bytes((36, 2)))
               + encode_status(1, 0, b"\x00\x02"))
    kinds = [(d.kind, d.packet.id) for d in decode([Chunk(None, None, capture)], protocol="1.0")]
    assert kinds == [(INSTRUCTION, 0xFE), (STATUS, 1), (INSTRUCTION, 1), (STATUS, 1)]


def test_a_reply_is_named_by_the_request_to_its_own_id():
    """Two READs, then both replies: ID 1's model number was shown as present_position (ID 2's request)."""
    chunks = [Chunk(0.0, "in", encode_instruction(1, READ, bytes((0, 2)))), Chunk(0.001, "in", encode_instruction(2, READ, bytes((36, 2)))),
              Chunk(0.002, "out", encode_status(1, 0, b"\x0c\x00")), Chunk(0.003, "out", encode_status(2, 0, b"\x00\x02"))]
    texts = [d.text for d in decode(chunks, protocol="1.0")]
    assert "present_position" not in texts[2] and texts[3].endswith("present_position=512")


def test_a_packet_cut_off_at_the_end_is_reported():
    out = decode([Chunk(0.0, "in", encode_instruction(1, PING) + bytes.fromhex("ff ff 01 04 02"))], protocol="1.0")
    assert out[-1].kind == GARBAGE and out[-1].discarded == 5 and "at the end" in out[-1].text


def test_a_corrupt_packet_keeps_the_checksum_it_came_with():
    (item,) = decode([Chunk(0.0, "in", bytes.fromhex("ff ff 01 02 01 00"))], protocol="1.0")
    assert item.raw == bytes.fromhex("ff ff 01 02 01 00")


def test_an_mx_whose_id_is_written_is_named_by_its_table_at_the_new_id():
    """WRITE ID 1 -> 9 on an MX-28: its P Gain (28) was then named by the default AX-12A table (a compliance slope)."""
    chunks = [Chunk(0.0, "in", encode_instruction(1, WRITE, bytes((3, 9)))), Chunk(0.01, "in", encode_instruction(9, WRITE, bytes((28, 41))))]
    texts = [d.text for d in decode(chunks, protocol="1.0", servos="1:mx-28")]
    assert texts[1] == "WRITE id=9 p_gain=41"


def test_sync_write_blocks_are_named_by_each_servos_own_table():
    """An XL-320 and an XL430 share no addresses: 32 is the XL-320's Moving Speed, the XL430's Max Voltage Limit."""
    params = (32).to_bytes(2, "little") + (2).to_bytes(2, "little") + b"\x01\x64\x00" + b"\x02\x64\x00"
    packet = encode_instruction2(0xFE, Instruction2.SYNC_WRITE, params)
    (item,) = decode([Chunk(0.0, "in", packet)], servos="1:xl-320,2:xl430-w250")
    assert "[id=1 moving_speed=" in item.text and "[id=2 max_voltage_limit=" in item.text


def test_the_trace_headers_profile_names_the_registers(tmp_path):
    path = _trace(tmp_path, [(0.0, "in", encode_instruction(1, READ, bytes((20, 2))))], profile="ax12-2006")
    result = _decode_cli(path)
    assert result.returncode == 0 and "down_calibration" in result.stdout, result.stdout + result.stderr


@pytest.mark.parametrize(("lines", "words"), [
    (['{"t": 0.5, "dir": "in", "data": "ff"}', '{"t": 0.1, "dir": "in", "data": "ff"}'], ":3: not a trace line (t 0.1 is before"),
    (['{"t": NaN, "dir": "in", "data": "ff"}'], "t must be a finite number"),
    (['{"t": true, "dir": "in", "data": "ff"}'], "t must be a finite number"),
    (["[" * 100000], ":2: not a trace line (nested too deep)"),
    (['"just a string"'], "a JSON object per line"),
])
def test_bad_trace_lines_are_one_line_naming_the_line(tmp_path, lines, words):
    path = tmp_path / "bad.jsonl"
    path.write_text(json.dumps({"format": TRACE_FORMAT}) + "\n" + "\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(ValueError, match=re.escape(words)):
        list(read_trace(path))
    result = _decode_cli(str(path))
    assert result.returncode != 0 and "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_a_byte_order_mark_and_a_device_file(tmp_path):
    path = tmp_path / "bom.jsonl"
    header = json.dumps({"format": TRACE_FORMAT, "profile": "ax12a"})
    line = json.dumps({"t": 0.0, "dir": "in", "data": encode_instruction(1, PING).hex(" ")})
    path.write_bytes(b"\xef\xbb\xbf" + f"{header}\n{line}\n".encode())
    assert "PING id=1" in _decode_cli(str(path)).stdout  # a trace, not a raw capture of 68 discarded bytes
    result = _decode_cli("/dev/zero")  # read without end, until memory ran out
    assert result.returncode != 0 and "not a regular file" in result.stderr and "Traceback" not in result.stderr


def test_a_trace_on_disk_keeps_up_with_the_wire(tmp_path):
    """Buffered, a short session's trace read while the server ran was empty (and `decode` printed nothing), and a
    server killed hard lost the tail it was killed in."""
    from ax12emu.tracing.trace import TraceWriter

    path = tmp_path / "live.jsonl"
    writer = TraceWriter(path)
    writer.record("in", b"\xff\xff\x01\x02\x01\xfb", now=1.0)
    try:
        assert len(path.read_text().splitlines()) == 2  # header and the chunk, before any flush or close
    finally:
        writer.close()


@pytest.mark.parametrize(("direction", "now"), [("host", 1.0), ('in"', 1.0), ("in", float("nan")), ("in", 0.5)])
def test_the_writer_refuses_a_chunk_its_reader_would(tmp_path, direction, now):
    """It wrote any direction, unescaped, and any time: `ax12emu decode` then refused the file as "not a trace line"."""
    from ax12emu.tracing.trace import TraceWriter

    writer = TraceWriter(tmp_path / "t.jsonl")
    writer.record("in", b"\xff", now=writer._start + 1.0)
    try:
        with pytest.raises(ValueError, match="a trace chunk goes 'in' or 'out'"):
            writer.record(direction, b"\xff", now=writer._start + now)
    finally:
        writer.close()
    assert len(list(read_trace(tmp_path / "t.jsonl"))) == 1
