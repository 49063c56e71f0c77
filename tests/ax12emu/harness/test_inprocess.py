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
