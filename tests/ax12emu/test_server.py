"""The wire model: merged replies, and pacing, echo and collisions on a real pty."""

from __future__ import annotations

import os
import time

import pytest
import serial

from ax12emu.bus import Bus, Reply
from ax12emu.packets import encode_instruction, encode_status
from ax12emu.server import BusServer, merge_replies
from ax12emu.transports.base import Transport

PING = encode_instruction(1, 0x01)


def test_single_reply_released_whole_at_its_delay():
    """Unpaced, one reply goes out whole, delay after the instruction ended."""
    reply = Reply(1, b"\xff\xff\x01\x02\x00\xfc", 0.0005, 1e6)
    assert merge_replies([reply], 10.0, per_byte=False) == [(10.0005, reply.data)]


def test_paced_reply_bytes_take_ten_bit_times():
    """Paced at 1 Mbps each byte is released 10 us after the previous one."""
    reply = Reply(1, b"\xaa\xbb", 0.0, 1e6)
    chunks = merge_replies([reply], 0.0, per_byte=True)
    assert [c[1] for c in chunks] == [b"\xaa", b"\xbb"]
    assert abs(chunks[0][0] - 10e-6) < 1e-12 and abs(chunks[1][0] - 20e-6) < 1e-12


def test_simultaneous_replies_are_anded():
    """Two servos answering in the same slots produce the AND of their bytes (wired-AND line)."""
    a, b = encode_status(1, 0), encode_status(2, 0)
    merged = merge_replies([Reply(1, a, 0.0005, 1e6), Reply(2, b, 0.0005, 1e6)], 0.0, per_byte=False)
    assert merged[0][1] == bytes(x & y for x, y in zip(a, b))


def _open(port: str, baud: int = 1_000_000) -> serial.Serial:
    return serial.Serial(port, baud, timeout=0.5)


def test_echo_shows_instruction_before_status(emulator):
    """--echo: the host reads its own PING back, then the status packet."""
    served = emulator("--echo")
    with _open(served.port) as link:
        link.reset_input_buffer()
        link.write(PING)
        assert link.read(12) == PING + encode_status(1, 0)


def test_pace_takes_wire_time(emulator):
    """--pace at Baud Rate 34 (57,142 bps): PING + reply (12 bytes) take at least 2.1 ms plus the delay."""
    served = emulator("--pace")
    with _open(served.port) as link:
        link.write(encode_instruction(1, 0x03, bytes([4, 34])))
        time.sleep(0.05)
        link.baudrate = 57600
        link.reset_input_buffer()
        start = time.perf_counter()
        link.write(PING)
        reply = link.read(6)
        elapsed = time.perf_counter() - start
    assert reply == encode_status(1, 0)
    assert elapsed >= 12 * 10 / 57142 + 0.0005 - 1e-4, elapsed


def test_pace_collision_garbles_both(emulator):
    """--pace: a host packet sent while a slow reply is on the wire garbles it, as on a half-duplex bus."""
    served = emulator("--pace")
    with _open(served.port) as link:
        link.write(encode_instruction(1, 0x03, bytes([4, 254])))  # 7,843 bps: 1.3 ms per byte
        time.sleep(0.05)
        link.baudrate = 7843
        link.reset_input_buffer()
        link.write(PING)
        assert link.read(6) == encode_status(1, 0), "alone on the wire the reply is clean"
        link.write(PING)
        time.sleep(0.010)  # the reply is on the wire from 8.2 ms (PING 7.7 ms + 0.5 ms delay) to 15.8 ms
        link.write(b"\x00\x00\x00")
        garbled = link.read(6)
    assert garbled != encode_status(1, 0)


class _PipeTransport(Transport):
    """The host's bytes come through a pipe; replies are collected."""

    def __init__(self) -> None:
        self.read_fd, self.write_fd = os.pipe()
        os.set_blocking(self.read_fd, False)
        self.replies = bytearray()
        self.written_at: list[float] = []

    def fds(self) -> list[int]:
        return [self.read_fd]

    def on_readable(self, fd: int) -> bytes:
        try:
            return os.read(fd, 4096)
        except BlockingIOError:
            return b""

    def write(self, data: bytes) -> int:
        self.replies += data
        self.written_at.append(time.monotonic())
        return len(data)

    def close(self) -> None:
        os.close(self.read_fd)
        os.close(self.write_fd)


@pytest.mark.parametrize("return_delay", [0, 250])
def test_physics_steps_in_pieces_while_a_host_polls_without_pause(return_delay):
    """A host sending the next READ the moment a reply arrives keeps the loop busy: every read is
    answered, and the 1 kHz step still runs, in pieces between the packets (after a delayed reply
    too), rather than falling behind until a request has to pay for it (margins wide: a shared
    machine jitters)."""
    bus = Bus([1, 2, 3])
    for servo in bus.servos:
        for name, value in (("return_delay_time", return_delay), ("cw_angle_limit", 0), ("ccw_angle_limit", 0),
                            ("moving_speed", 300), ("torque_enable", 1)):
            servo.table.set(name, value)
    bus.plant.tables_changed()
    finished = []
    pieces = bus.advance_in_pieces

    def _counted():
        yield from pieces()
        finished.append(bus.clock.now_s())

    bus.advance_in_pieces = _counted
    paid = []  # whole steps taken in the request path
    advance = bus.plant.advance

    def _paid(sim_time_s):
        before_s = bus.model.time_s
        stepped = advance(sim_time_s)
        paid.extend([sim_time_s] * round((bus.model.time_s - before_s) / bus.model.step_s))
        return stepped

    bus.plant.advance = _paid
    read = encode_instruction(1, 0x02, bytes([36, 2]))
    with _PipeTransport() as transport:
        server = BusServer(bus, transport)
        start = time.monotonic()
        sent = 0
        while time.monotonic() - start < 0.3:
            os.write(transport.write_fd, read)
            sent += 1
            expected = 8 * sent
            while len(transport.replies) < expected:
                server.run_once()
        elapsed_ms = (time.monotonic() - start) * 1e3
    assert len(transport.replies) == 8 * sent and sent > 100
    assert len(finished) >= 0.5 * elapsed_ms, (len(finished), elapsed_ms)
    assert len(paid) <= 0.1 * elapsed_ms, (len(paid), len(finished), elapsed_ms)
    assert bus.model.time_s >= bus.clock.now_s() - 0.01


def test_a_delayed_reply_is_released_after_its_return_delay_not_before():
    """Return Delay Time 100 (200 us): each reply leaves no earlier than 200 us after its READ came in,
    and soon after (the loop meets a release due within microseconds on the clock; margins wide)."""
    bus = Bus([1])
    bus.servos[0].table.set("return_delay_time", 100)
    read = encode_instruction(1, 0x02, bytes([36, 2]))
    with _PipeTransport() as transport:
        server = BusServer(bus, transport)
        delays = []
        for _ in range(50):
            sent_at = time.monotonic()
            os.write(transport.write_fd, read)
            count = len(transport.written_at)
            while len(transport.written_at) == count:
                server.run_once()
            delays.append(transport.written_at[-1] - sent_at)
    assert len(transport.replies) == 50 * 8
    assert min(delays) >= 200e-6, min(delays)
    assert sorted(delays)[25] < 0.005, sorted(delays)
