"""What a trace records beside the bytes: the echo setting, a paced wire's instruction ends; and numbers it refuses."""

from __future__ import annotations

import json
import os
import time

import pytest
from emu_testkit import PipeTransport

from ax12emu.bus import Bus
from ax12emu.bus.clock import WallClock
from ax12emu.protocol.packets import encode_instruction, encode_status
from ax12emu.serve.server import BusServer
from ax12emu.tracing.decoder import INSTRUCTION, STATUS, decode
from ax12emu.tracing.trace import IN, OUT, TraceWriter, read_trace

PING = encode_instruction(1, 0x01)


def _lines(path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_the_header_says_whether_the_wire_echoes(tmp_path):
    path = tmp_path / "t.jsonl"
    with TraceWriter(path, servos="1:xl430-w250") as trace:
        trace.note(echo=False)
        trace.record(IN, PING)
        with pytest.raises(ValueError, match="before its first chunk"):
            trace.note(echo=True)
    header, line = _lines(path)
    assert header["echo"] is False and header["servos"] == "1:xl430-w250"
    assert line["data"] == PING.hex(" ")


@pytest.mark.parametrize("echo", [False, True])
def test_a_served_trace_records_the_echo_setting(tmp_path, echo):
    path = tmp_path / "t.jsonl"
    with PipeTransport() as transport, TraceWriter(path) as trace:
        BusServer(Bus([1], clock=WallClock()), transport, echo=echo, trace=trace)
    assert _lines(path)[0]["echo"] is echo


def test_a_paced_trace_shows_the_return_delay_as_latency(tmp_path):
    """At 57,600 bps a READ of 4 bytes and its answer take 2.4 and 2.6 ms on the wire; the latency is the Return
    Delay Time between them (500 us), measured from the instruction's end to the status's first byte."""
    byte_s = 10 / 57_600
    read = bytes.fromhex("ff ff fd 00 01 07 00 02 84 00 04 00 1d 15")
    status = bytes.fromhex("ff ff fd 00 01 08 00 55 00 00 08 00 00 1c 38")
    path = tmp_path / "t.jsonl"
    with TraceWriter(path, servos="1:xl430-w250") as trace:
        start = time.monotonic() + 1.0
        end = start + len(read) * byte_s
        trace.on_wire(end, byte_s)
        trace.record(IN, read, start)
        for i, value in enumerate(status):  # each byte when its last bit is in, as a paced server sends them
            trace.record(OUT, bytes([value]), end + 500e-6 + (i + 1) * byte_s)
    line = _lines(path)[1]
    assert line["end"] - line["t"] == pytest.approx(len(read) * byte_s, abs=2e-6) and line["byte_s"] == pytest.approx(byte_s)
    decoded = decode(read_trace(path), servos="1:xl430-w250")
    assert [d.kind for d in decoded] == [INSTRUCTION, STATUS]
    assert decoded[1].latency_s == pytest.approx(500e-6, abs=3e-6)


@pytest.mark.wallclock
def test_a_paced_server_records_each_instructions_wire_end(tmp_path):
    path = tmp_path / "t.jsonl"
    with PipeTransport() as transport, TraceWriter(path) as trace:
        server = BusServer(Bus([1], clock=WallClock()), transport, pace=True, trace=trace)
        os.write(transport.write_fd, PING)
        deadline = time.monotonic() + 5.0
        while len(transport.replies) < len(PING) and time.monotonic() < deadline:
            server.run_once()
    assert bytes(transport.replies) == encode_status(1, 0)
    lines = _lines(path)
    (sent,) = [line for line in lines[1:] if line["dir"] == IN]
    byte_s = 10 / 1_000_000  # the AX-12's factory rate (the pipe says none)
    assert sent["byte_s"] == pytest.approx(byte_s) and sent["end"] - sent["t"] == pytest.approx(len(PING) * byte_s, abs=2e-6)
    assert all("end" not in line for line in lines[1:] if line["dir"] == OUT)
    status = decode(read_trace(path))[-1]
    # Measured from the PING's end to the answer's first byte: not the 12 bytes' wire time on top (+120 us).
    assert status.kind == STATUS and status.latency_s < 500e-6 + 100e-6


@pytest.mark.parametrize("line", ['{"t": 1' + "0" * 400 + ', "dir": "in", "data": "ff"}',
                                  '{"t": 0.1, "dir": "in", "data": "ff", "end": 1' + "0" * 400 + ', "byte_s": 1e-5}',
                                  '{"t": 0.1, "dir": "in", "data": "ff", "end": 0.05, "byte_s": 1e-5}',
                                  '{"t": 0.1, "dir": "in", "data": "ff", "end": 0.2}'])
def test_a_bad_number_is_not_a_trace_line(tmp_path, line):
    """A 400-digit integer is no float (OverflowError): the same one-line error as any bad line."""
    path = tmp_path / "t.jsonl"
    path.write_text('{"format": "ax12emu-trace/1", "profile": "ax12a"}\n' + line + "\n")
    with pytest.raises(ValueError, match=r"t\.jsonl:2: not a trace line"):
        list(read_trace(path))


def test_a_trace_that_cannot_be_written_stops_and_says_so_once(tmp_path, caplog):
    """A full disk under a long traced session: the server's loop went down with ENOSPC and the bus with it. The
    trace stops, said once naming its file, and recording goes on as a no-op; the lines written before stay."""
    import errno
    import logging

    class FullDisk:
        def __init__(self, file):
            self.file, self.writes = file, 0

        def write(self, text):
            self.writes += 1
            raise OSError(errno.ENOSPC, "No space left on device")

        def flush(self):
            pass

        def close(self):
            self.file.close()

    path = tmp_path / "t.jsonl"
    writer = TraceWriter(path)
    writer.record(IN, b"\xff\xff\x01\x02\x01\xfb", 1.0)
    full = FullDisk(writer._file)
    writer._file = full
    with caplog.at_level(logging.ERROR, logger="ax12emu.tracing.trace"):
        writer.record(IN, b"\xff\xff\x01\x02\x01\xfb", 1.1)
        writer.record(IN, b"\xff\xff\x01\x02\x01\xfb", 1.2)
        writer.flush()
        writer.close()
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1 and str(path) in said[0] and "No space left on device" in said[0] and "tracing stopped" in said[0]
    assert full.writes == 1
    assert [chunk.data for chunk in read_trace(path)] == [b"\xff\xff\x01\x02\x01\xfb"]


def test_a_trace_goes_to_a_fifo_as_to_a_file(tmp_path):
    """``serve --trace FIFO`` (or ``>(gzip > t.gz)``): the header noted with the wire's echo setting was written
    by rewinding the file, which a pipe cannot do ("underlying stream is not seekable"): the server did not start."""
    import threading

    fifo = tmp_path / "trace.fifo"
    os.mkfifo(fifo)
    got: list[str] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_text()))
    reader.start()
    writer = TraceWriter(fifo)  # opening a FIFO for writing waits for its reader
    writer.note(echo=False)
    writer.record(IN, PING, 1.0)
    writer.close()
    reader.join(timeout=10)
    lines = [json.loads(line) for line in got[0].splitlines()]
    assert lines[0]["echo"] is False and lines[1]["data"] == PING.hex(" ")
