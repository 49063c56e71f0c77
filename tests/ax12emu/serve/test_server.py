"""The wire model: merged replies, and pacing, echo and collisions on a real pty."""

from __future__ import annotations

import gc
import os
import socket
import time

import pytest
import serial
from emu_testkit import PipeTransport, wait_eeprom

from ax12emu.bus import Bus, Reply
from ax12emu.bus.clock import WallClock
from ax12emu.bus.reply import merge_replies
from ax12emu.protocol.packets import Instruction, InstructionPacket, encode_instruction, encode_status
from ax12emu.protocol.packets2 import Instruction2, InstructionPacket2
from ax12emu.serve.server import BusServer

#: Real time and real ports: the wall-clock tier (CI runs it too).
pytestmark = pytest.mark.wallclock

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
        assert link.read(6) == encode_status(1, 0)  # heard at 1 Mbps before the host switches
        wait_eeprom()  # Baud Rate is in the EEPROM: the servo ignores packets while it writes it
        link.baudrate = 57600
        link.reset_input_buffer()
        start = time.perf_counter()
        link.write(PING)
        reply = link.read(6)
        elapsed = time.perf_counter() - start
    assert reply == encode_status(1, 0)
    assert elapsed >= 12 * 10 / 57142 + 0.0005 - 1e-4, elapsed


def test_pace_times_each_packet_of_one_write_from_its_own_last_byte(emulator):
    """--pace at 1 Mbps: a PING to ID 1 and a READ to ID 2 in one host write end 60 and 140 us into it, and each
    servo answers its Return Delay Time after its own packet: replies some 80 us apart, both whole. Timed from the
    write's end, both went out at once and collided."""
    served = emulator("--pace", "--ids", "1,2")
    read2 = encode_instruction(2, 0x02, bytes([0, 2]))
    with _open(served.port) as link:
        for _ in range(3):
            link.reset_input_buffer()
            link.write(PING + read2)
            assert link.read(14) == encode_status(1, 0) + encode_status(2, 0, (12).to_bytes(2, "little"))
            time.sleep(0.05)


def test_pace_collision_garbles_both(emulator):
    """--pace: a host packet sent while a slow reply is on the wire garbles it, as on a half-duplex bus.
    An attempt counts only if the host really sent its bytes inside the reply's time on the wire
    (a loaded machine may oversleep); up to ten attempts."""
    served = emulator("--pace")
    with _open(served.port) as link:
        link.write(encode_instruction(1, 0x03, bytes([4, 254])))  # 7,843 bps: 1.3 ms per byte
        assert link.read(6) == encode_status(1, 0)  # heard at 1 Mbps before the host switches
        wait_eeprom()
        link.baudrate = 7843
        link.reset_input_buffer()
        link.write(PING)
        assert link.read(6) == encode_status(1, 0), "alone on the wire the reply is clean"
        garbled = []
        for _ in range(10):
            time.sleep(0.06)  # the framer drops whatever a collision left
            link.reset_input_buffer()
            start = time.perf_counter()
            link.write(PING)
            time.sleep(0.010)  # the reply is on the wire from 8.2 ms (PING 7.7 ms + 0.5 ms delay) to 15.8 ms
            gap_s = time.perf_counter() - start
            link.write(b"\x00\x00\x00")
            reply = link.read(6)
            if 0.0085 < gap_s < 0.013:
                garbled.append(reply != encode_status(1, 0))
                if garbled[-1]:
                    break
    assert any(garbled), garbled


@pytest.mark.parametrize("return_delay", [0, 250])
def test_physics_steps_in_pieces_while_a_host_polls_without_pause(return_delay):
    """A host sending the next READ the moment a reply arrives keeps the loop busy: every read is
    answered, and the 1 kHz step still runs, in pieces between the packets (after a delayed reply
    too), rather than falling behind until a request has to pay for it.  A request may pay after
    the shared machine held the loop up (a pass of over 0.5 ms within the last 2 ms), so those
    steps are excused, as is the start before the first tick, and the tick count is held to the
    time the loop was not held up; margins wide."""
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
    passes: list[float] = []  # when each pass of the loop began
    paid: list[bool] = []  # per whole step taken in the request path: was the loop held up just before?
    advance = bus.plant.advance

    def _held_up_s(edges):
        """Time spent in passes over 0.5 ms (a pass takes microseconds, a step ~0.1 ms): the core was
        taken away, or ran several times slower than usual (a shared VM does both)."""
        return sum(gap for gap in (b - a for a, b in zip(edges, edges[1:])) if gap > 0.5e-3)

    def _paid(sim_time_s):
        now = time.monotonic()  # before the step: a step slowing its own pass must not excuse it
        before_s = bus.model.time_s
        stepped = advance(sim_time_s)
        steps = round((bus.model.time_s - before_s) / bus.model.step_s)
        if steps and finished:  # from the first tick on: before it, the loop is starting up
            recent = [t for t in passes if t > now - 2e-3]
            paid.extend([_held_up_s(passes[-len(recent) - 1:] + [now]) > 0] * steps)
        return stepped

    read = encode_instruction(1, 0x02, bytes([36, 2]))
    with PipeTransport() as transport:
        server = BusServer(bus, transport)
        bus.plant.advance = _paid
        gc.disable()  # a full collection of pytest's heap holds a pass up for ms, on the core
        try:
            start = time.monotonic()
            sent = 0
            while time.monotonic() - start < 0.3:
                sent_sim_s = bus.clock.now_s()
                os.write(transport.write_fd, read)
                sent += 1
                expected = 8 * sent
                while len(transport.replies) < expected:
                    passes.append(time.monotonic())
                    server.run_once()
            elapsed_ms = (time.monotonic() - start) * 1e3
        finally:
            gc.enable()
    assert len(transport.replies) == 8 * sent and sent > 100
    held_ms = 1e3 * _held_up_s(passes)
    assert len(finished) >= 0.5 * (elapsed_ms - held_ms), (len(finished), elapsed_ms, held_ms)
    unexcused = paid.count(False)
    assert unexcused <= 0.05 * elapsed_ms, (unexcused, len(paid), len(finished), elapsed_ms)
    assert bus.model.time_s >= sent_sim_s - 0.01  # the last request found physics at most a tick behind


@pytest.mark.parametrize("time_scale", [1.0, 0.5])
def test_physics_ticks_land_when_the_models_next_step_falls_due(time_scale):
    """The loop's tick comes as soon as the model's next whole step is due, whatever the phase
    between the bus's clock and the loop's start (and in slow motion too); on a beat of its own it
    could come up to a step late, and a request in between paid for the step.  The server starts
    half a step off the grid here; the median tick starts within a quarter step after a grid point
    (wide: select wakes late)."""
    bus = Bus([1], clock=WallClock(time_scale))
    step_s = bus.model.step_s
    while not 0.45 < (bus.clock.now_s() / step_s) % 1 < 0.55:
        pass  # at most one step
    starts = []
    pieces = bus.advance_in_pieces

    def _counted():
        starts.append(bus.clock.now_s())
        yield from pieces()

    bus.advance_in_pieces = _counted
    with PipeTransport() as transport:
        server = BusServer(bus, transport)
        end = time.monotonic() + 2.0  # 60 ticks take 60 to 120 ms, unless the machine stalls
        while len(starts) <= 60 and time.monotonic() < end:
            server.run_once()
    phases = sorted((start / step_s) % 1 for start in starts[1:])
    assert len(phases) >= 60, len(phases)
    assert phases[len(phases) // 2] < 0.25, phases


def test_a_delayed_reply_is_released_after_its_return_delay_not_before():
    """Return Delay Time 100 (200 us): each reply leaves no earlier than 200 us after its READ came in,
    and soon after (the loop meets a release due within microseconds on the clock; margins wide)."""
    bus = Bus([1])
    bus.servos[0].table.set("return_delay_time", 100)
    read = encode_instruction(1, 0x02, bytes([36, 2]))
    with PipeTransport() as transport:
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


def _read_n_times(bus, packet: bytes, reply_bytes: int, times: int) -> None:
    """``packet`` sent ``times`` times over the TCP bus, each reply read whole before the next is sent."""
    host, port = bus.port.split("//")[1].rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=5) as sock:
        for _ in range(times):
            sock.sendall(packet)
            got = b""
            while len(got) < reply_bytes:
                got += sock.recv(64)


READS = {  # servo(s), the read, its reply's length in bytes
    "1.0 READ": ("1:ax-12a", lambda: InstructionPacket(1, Instruction.READ, bytes([36, 2])).encode(), 8),
    "2.0 READ": ("1:xl430-w250", lambda: InstructionPacket2(1, Instruction2.READ, bytes([132, 0, 4, 0])).encode(), 15),
    "2.0 Fast Sync Read": ("1-2:xl430-w250",
                           lambda: InstructionPacket2(0xFE, Instruction2.FAST_SYNC_READ, bytes([132, 0, 4, 0, 1, 2])).encode(),
                           24),
}


@pytest.mark.parametrize("corrupt", [0.0, 1.0])
@pytest.mark.parametrize("kind", list(READS))
def test_status_errors_count_replies_with_error_bits_the_host_can_take_as_such(kind, corrupt):
    """A reply with error bits whose checksum (1.0) or CRC (2.0) the fault injection corrupted reaches the host as a
    checksum error: it is no status error (the live view counted both, where the host saw only the one)."""
    from ax12emu import VirtualBus

    servo, packet, reply_bytes = READS[kind]
    with VirtualBus(servo=servo, transport="tcp", baud_bps=1_000_000) as bus:
        bus.faults.force_alarm(1, "overload")  # every reply of servo 1 carries an error bit
        bus.faults.set_reply_faults(corrupt=corrupt)
        bus.call(lambda _: setattr(bus._server, "count_status_errors", True))  # as a live view asks it to
        _read_n_times(bus, packet(), reply_bytes, 20)
        counted = bus.call(lambda _: bus._server.status_errors)
    assert counted == (0 if corrupt else 20), counted
