"""serial_for_url("ax12emu://..."): an in-process port that behaves like a real one."""

from __future__ import annotations

import time

import pytest
import serial

import ax12emu  # noqa: F401  (registers the handler)
from ax12emu import VirtualBus
from ax12emu.harness.urlhandler.protocol_ax12emu import UrlError
from ax12emu.protocol.packets import encode_instruction, encode_status

PING = encode_instruction(1, 0x01)


def test_private_bus_answers_after_return_delay():
    """A private bus answers PING no sooner than its Return Delay Time (500 us)."""
    with serial.serial_for_url("ax12emu://?ids=1,2", baudrate=1_000_000, timeout=0.5) as link:
        start = time.perf_counter()
        link.write(PING)
        assert link.read(6) == encode_status(1, 0)
        assert time.perf_counter() - start >= 0.0005
        link.write(encode_instruction(2, 0x02, bytes([0, 2])))
        assert link.read(8) == encode_status(2, 0, b"\x0c\x00")


def test_read_blocks_until_timeout_and_returns_short():
    """With nothing to read, read() waits for the timeout and returns what it has, like a real port."""
    with serial.serial_for_url("ax12emu://?ids=1", baudrate=1_000_000, timeout=0.05) as link:
        start = time.perf_counter()
        assert link.read(6) == b""
        assert 0.045 <= time.perf_counter() - start < 0.5
        link.write(PING)
        assert link.read(10) == encode_status(1, 0)  # short read after the timeout


def test_host_baud_must_match():
    """At 57,600 bps the host is not heard by a servo at 1 Mbps (as on a pty or the wire)."""
    with serial.serial_for_url("ax12emu://?ids=1", baudrate=57600, timeout=0.05) as link:
        link.write(PING)
        assert link.read(6) == b""


@pytest.mark.parametrize(
    "url, message",
    [
        ("ax12emu://?idz=1", "unknown option"),
        ("ax12emu://?ids=1-x", "not an ID"),
        ("ax12emu://?drop=3", "drop"),
        ("ax12emu://?virtual_time=yes", "virtual_time"),
        ("ax12emu://?goal_torque=maybe", "goal_torque"),
        ("ax12emu://?eeprom_busy_ms=soon", "eeprom_busy_ms"),
        # As written and in ms, as serve --eeprom-busy-ms says it (not ServoOptions' eeprom_busy_s_per_byte, in s).
        ("ax12emu://?eeprom_busy_ms=-5", r"eeprom_busy_ms: must lie in 0\.\.1000 ms, got -5$"),
        ("ax12emu://?eeprom_busy_ms=5000", r"eeprom_busy_ms: must lie in 0\.\.1000 ms, got 5000$"),
        ("ax12emu://?eeprom_busy_ms=nan", r"eeprom_busy_ms: must lie in 0\.\.1000 ms, got nan$"),
        ("ax12emu://?servo=1:ax-12a,2:xl430-w250&eeprom_busy_ms=-5", r"eeprom_busy_ms: must lie in 0\.\.1000 ms, got -5$"),
        ("ax12emu://?logging=loud", "logging"),
        ("ax12emu://?ids=1&ids=2", "ids given more than once"),  # served ID 2 alone, silently
        ("ax12emu://?trace=/no/such/folder/bus.jsonl", "trace=/no/such/folder/bus.jsonl: No such file"),
        ("ax12emu://?servo=xl430-w250&ids=1&trace=/no/such/folder/bus.jsonl", "trace=.*No such file"),
        ("ax12emu://?delay=1&delay_s=nan", "delay_s: expected seconds 0..60"),  # a bare ValueError from the faults
        ("ax12emu://?params=&virtual_time=1", "params= given no value"),  # served the default model, silently
        ("ax12emu://?servo=xl430-w250&trace=", "trace= given no value"),
    ],
)
def test_bad_urls_quote_the_expected_form(url, message):
    """Bad options raise an error that is both ValueError and SerialException and shows the URL form."""
    with pytest.raises(UrlError, match=message) as caught:
        serial.serial_for_url(url)
    assert isinstance(caught.value, ValueError) and isinstance(caught.value, serial.SerialException)
    assert "ax12emu://[NAME]" in str(caught.value)


def test_named_bus_and_one_host_at_a_time():
    """ax12emu://NAME reaches a VirtualBus in process; a second open is refused; unknown names are errors."""
    with VirtualBus([3], transport="inprocess", name="arm") as bus:
        assert bus.port == "ax12emu://arm"
        with serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.5) as link:
            link.write(encode_instruction(3, 0x01))
            assert link.read(6) == encode_status(3, 0)
            with pytest.raises(serial.SerialException, match="one host at a time"):
                serial.serial_for_url(bus.port)
    with pytest.raises(serial.SerialException, match="no in-process bus named 'arm'"):
        serial.serial_for_url("ax12emu://arm")


def test_a_refused_setting_at_open_leaves_a_named_bus_free():
    """pyserial's own ports release what they took when configuring fails; a bad baud rate claimed the bus for good."""
    with VirtualBus([3], transport="inprocess", name="arm2") as bus:
        with pytest.raises(ValueError, match="invalid baudrate"):
            serial.serial_for_url(bus.port, baudrate=0)
        with serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.5) as link:
            link.write(encode_instruction(3, 0x01))
            assert link.read(6) == encode_status(3, 0)


def test_cancel_read_wakes_a_blocked_read_and_a_closed_port_refuses_flush():
    """As pyserial's ports: cancel_read() ends a read blocked in another thread (serial.threaded.ReaderThread
    relies on it to stop at once), and a closed port raises on flush and out_waiting."""
    import threading

    link = serial.serial_for_url("ax12emu://?ids=1", baudrate=1_000_000, timeout=None)
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(link.read(10)))
    reader.start()
    time.sleep(0.05)
    link.cancel_read()
    reader.join(5.0)
    assert not reader.is_alive() and got == [b""]
    link.cancel_write()
    link.flush()
    assert link.out_waiting == 0
    link.close()
    with pytest.raises(serial.PortNotOpenError):
        link.flush()
    with pytest.raises(serial.PortNotOpenError):
        _ = link.out_waiting


def test_a_port_on_a_closed_bus_fails_as_an_unplugged_adapter():
    """Reads and writes after VirtualBus.close() raise SerialException (they worked on, and a read spun at once)."""
    bus = VirtualBus([3], transport="inprocess", name="arm3").start()
    link = serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.5)
    link.write(encode_instruction(3, 0x01))
    assert link.read(6) == encode_status(3, 0)
    bus.close()
    with pytest.raises(serial.SerialException, match="closed"):
        link.write(encode_instruction(3, 0x01))
    with pytest.raises(serial.SerialException, match="closed"):
        link.read(6)
    link.close()


def test_faults_in_the_url():
    """Fault options work in the URL: drop=1 silences every reply."""
    with serial.serial_for_url("ax12emu://?ids=1&drop=1&seed=3", baudrate=1_000_000, timeout=0.05) as link:
        link.write(PING)
        assert link.read(6) == b""


def test_a_fault_on_one_servo_repeats_per_servo_as_its_serve_flag_does():
    """vanish=1&vanish=2 was refused as "given more than once": no URL could unplug (stall, alarm) two servos."""
    with serial.serial_for_url("ax12emu://?ids=1,2,3&vanish=1&vanish=2", baudrate=1_000_000, timeout=0.05) as link:
        for servo_id, answers in ((1, False), (2, False), (3, True)):
            link.write(encode_instruction(servo_id, 0x01))
            assert bool(link.read(6)) is answers, servo_id
    with pytest.raises(UrlError, match="ids given more than once"):
        serial.serial_for_url("ax12emu://?ids=1&ids=2")


def _write(link, address: int, *data: int) -> bytes:
    link.write(encode_instruction(1, 0x03, bytes([address, *data])))
    return link.read(6)


def test_firmware_quirks_in_the_url():
    """goal_torque and eeprom_busy_ms reach the servos: defaults on, and each can be turned off."""
    with serial.serial_for_url("ax12emu://?ids=1&eeprom_busy_ms=500", baudrate=1_000_000, timeout=0.1) as link:
        assert _write(link, 30, 0x00, 0x02) == encode_status(1, 0)  # Goal Position
        link.write(encode_instruction(1, 0x02, bytes([24, 1])))
        assert link.read(7) == encode_status(1, 0, b"\x01")  # torque turned on
        assert _write(link, 5, 0) == encode_status(1, 0)  # Return Delay Time: EEPROM
        link.write(PING)
        assert link.read(6) == b""  # writing its EEPROM for 500 ms: deaf
    url = "ax12emu://?ids=1&goal_torque=unchanged&eeprom_busy_ms=0"
    with serial.serial_for_url(url, baudrate=1_000_000, timeout=0.1) as link:
        assert _write(link, 30, 0x00, 0x02) == encode_status(1, 0)
        link.write(encode_instruction(1, 0x02, bytes([24, 1])))
        assert link.read(7) == encode_status(1, 0, b"\x00")  # torque left off
        assert _write(link, 5, 0) == encode_status(1, 0)
        link.write(PING)
        assert link.read(6) == encode_status(1, 0)  # answers at once


@pytest.mark.parametrize(("settings", "heard"), [
    ({}, True),
    ({"stopbits": serial.STOPBITS_TWO}, True),  # the extra stop bit is idle line
    ({"parity": serial.PARITY_MARK}, True),  # always 1: read as the stop bit
    ({"bytesize": serial.SEVENBITS}, False),
    ({"parity": serial.PARITY_EVEN}, False),
    ({"parity": serial.PARITY_ODD}, False),
])
def test_a_host_in_another_byte_format_is_heard_as_an_8n1_uart_would(settings, heard):
    """The servos' UARTs run 8N1 (e-manual, AX-12A specifications: "8bit,1stop,No Parity"): a host at 7 bits or with a parity bit
    sends framing errors (it was answered as if 8N1)."""
    with serial.serial_for_url("ax12emu://?ids=1", baudrate=1_000_000, timeout=0.2, **settings) as link:
        link.write(PING)
        assert (link.read(6) == encode_status(1, 0)) is heard


def test_a_held_break_is_heard_as_nothing():
    with serial.serial_for_url("ax12emu://?ids=1", baudrate=1_000_000, timeout=0.2) as link:
        link.break_condition = True
        link.write(PING)
        assert link.read(6) == b""
        link.break_condition = False
        link.write(PING)
        assert link.read(6) == encode_status(1, 0)


@pytest.mark.parametrize("servo", ["1:mx-28,2:ax-12a", "2:ax-18a", "1:xl430-w250,2:ax-12a"])
def test_an_ax_servo_on_a_servo_url_in_virtual_time_answers_after_an_eeprom_write(servo):
    """Its 6 ms-a-byte EEPROM pause ran on a clock that stands still (a URL bus has no step()): after any EEPROM write
    it never answered again, where the AX-12A bus without servo= takes no pause in virtual time."""
    with serial.serial_for_url(f"ax12emu://?servo={servo}&baud=1000000&virtual_time=1", baudrate=1_000_000,
                               timeout=0.1) as link:
        link.write(encode_instruction(2, 0x03, bytes([5, 0])))  # Return Delay Time 0
        assert link.read(6) == encode_status(2, 0)
        link.write(encode_instruction(2, 0x01))
        assert link.read(6) == encode_status(2, 0)


def test_a_url_trace_says_the_link_has_no_echo(tmp_path):
    """A PING answered with the Input Voltage alarm is byte for byte the PING: in a trace whose header does not say
    the wire has no echo, ``ax12emu decode`` took the answer for the adapter's echo."""
    import serial

    from ax12emu.tracing.decoder import ECHO, STATUS, decode
    from ax12emu.tracing.trace import read_capture, trace_header

    path = tmp_path / "bus.jsonl"
    port = serial.serial_for_url(f"ax12emu://?ids=1&alarm=1:input_voltage&trace={path}", baudrate=1_000_000, timeout=0.5)
    try:
        port.write(bytes.fromhex("ffff010201fb"))
        assert port.read(6) == bytes.fromhex("ffff010201fb")
    finally:
        port.close()
    header = trace_header(path)
    assert header["echo"] is False
    kinds = [item.kind for item in decode(read_capture(path), echo=header["echo"])]
    assert STATUS in kinds and ECHO not in kinds
