"""The in-process link: its trace records the line in time order, replies read or not, as a pty's trace does."""

from __future__ import annotations

import serial

from ax12emu import VirtualBus
from ax12emu.protocol.packets import encode_instruction, encode_status
from ax12emu.tracing.decoder import STATUS, decode
from ax12emu.tracing.trace import IN, OUT, read_trace

LED_ON = encode_instruction(1, 0x03, bytes([0x19, 1]))
LED_OFF = encode_instruction(1, 0x03, bytes([0x19, 0]))
PING = encode_instruction(1, 0x01)
OK = encode_status(1, 0)


def _instant_bus(path) -> VirtualBus:
    """An in-process bus whose servo answers at Return Delay Time 0: each reply is due when its packet is handled,
    so it is on the line before the host's next packet without the test waiting for it."""
    bus = VirtualBus([1], transport="inprocess", trace=str(path))
    bus.start()
    bus.write(1, "return_delay_time", 0)
    return bus


def _line(path) -> list[tuple[str | None, bytes]]:
    chunks = list(read_trace(path))
    times = [chunk.t for chunk in chunks]
    assert times == sorted(times)
    return [(chunk.direction, chunk.data) for chunk in chunks]


def test_a_reply_not_read_before_the_next_packet_is_traced_before_it(tmp_path):
    """A host that sends its next packet before reading a status packet: the reply was traced when read, at its
    earlier due time, after the later packet, so the trace raised ValueError out of the port's read."""
    path = tmp_path / "bus.jsonl"
    with _instant_bus(path) as bus:
        with serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.5) as port:
            port.write(LED_ON)
            port.write(PING)
            assert port.read(12) == OK * 2
    assert _line(path) == [(IN, LED_ON), (OUT, OK), (IN, PING), (OUT, OK)]


def test_replies_never_read_are_traced(tmp_path):
    """Replies the host never reads were missing from the trace (``ax12emu decode`` showed no status packet); a
    pty's trace has each after its instruction."""
    path = tmp_path / "bus.jsonl"
    with _instant_bus(path) as bus:
        port = serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.5)
        try:
            for packet in (LED_ON, LED_OFF, PING):
                port.write(packet)
        finally:
            port.close()
    assert _line(path) == [(IN, LED_ON), (OUT, OK), (IN, LED_OFF), (OUT, OK), (IN, PING), (OUT, OK)]
    assert [item.kind for item in decode(read_trace(path), echo=False)].count(STATUS) == 3


def test_replies_due_when_the_bus_closes_are_traced(tmp_path):
    """The bus closed under a port still open: the reply already on the line is in the trace."""
    path = tmp_path / "bus.jsonl"
    port = None
    with _instant_bus(path) as bus:
        port = serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.5)
        port.write(PING)
    port.close()
    assert _line(path) == [(IN, PING), (OUT, OK)]


def test_a_url_bus_traces_replies_its_host_never_read(tmp_path):
    """``ax12emu://?trace=``: the private bus closes with its port, after tracing what was on the line."""
    path = tmp_path / "bus.jsonl"
    port = serial.serial_for_url(f"ax12emu://?ids=1&eeprom_busy_ms=0&trace={path}", baudrate=1_000_000, timeout=0.5)
    try:
        port.write(encode_instruction(1, 0x03, bytes([5, 0])))  # Return Delay Time 0 (answered after the old one)
        assert port.read(6) == OK
        port.write(LED_ON)
        port.write(PING)
    finally:
        port.close()
    assert _line(path)[2:] == [(IN, LED_ON), (OUT, OK), (IN, PING), (OUT, OK)]


def test_a_read_under_way_when_its_port_closes_never_takes_the_next_ports_replies():
    """One host at a time: a thread still in ``read()`` on a closed ``ax12emu://NAME`` port took the reply to the next
    port's PING (about 1 round in 4), where on a pty it never does. Its read ends with its port."""
    import threading
    import time

    reply = encode_status(1, 0)
    with VirtualBus([1], transport="inprocess") as bus:
        for _ in range(20):
            a = serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=2.0)
            got = []

            def read_a(port=a, got=got):
                try:
                    got.append(port.read(len(reply)))
                except serial.PortNotOpenError:  # a round where the close came first: nothing read either
                    got.append(b"")

            reader = threading.Thread(target=read_a)
            reader.start()
            time.sleep(0.01)  # most rounds: the read is waiting when its port closes
            a.close()
            b = serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=1.0)
            try:
                b.write(PING)
                assert b.read(len(reply)) == reply
            finally:
                b.close()
            reader.join(5.0)
            assert not reader.is_alive() and got == [b""], got


def test_a_session_that_ended_neither_writes_to_the_servos_nor_reads_the_next_ones_replies():
    """What a port's read or write racing its own close() comes to, decided by the session it began in: a write
    raced close() into a bare AttributeError (or, past the check, into the next host's session)."""
    import pytest

    from ax12emu.bus import Bus
    from ax12emu.bus.clock import VirtualClock
    from ax12emu.harness.inprocess import InProcessLink, LinkDetached

    link = InProcessLink(Bus([1], clock=VirtualClock()))
    first = link.attach()
    link.detach()
    second = link.attach()
    with pytest.raises(LinkDetached):
        link.write(PING, None, first)
    assert link.packets_in == 0
    link.write(PING, None, second)
    assert link.read(len(OK), 1.0, first) == b""
    assert link.read(len(OK), 1.0, second) == OK
