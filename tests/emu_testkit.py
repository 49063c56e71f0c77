"""Helpers shared by the end-to-end tests (dynamixel-sdk ports, result unwrapping) and the bus tests (a servo by register name)."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager

from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

from ax12emu.bus.bus import Bus
from ax12emu.conformance.checks import EEPROM_WAIT_S_PER_BYTE
from ax12emu.protocol.packets import BROADCAST_ID, Instruction, encode_instruction
from ax12emu.protocol.packets2 import Instruction2, decode_packet2, encode_instruction2
from ax12emu.protocol.servo_models import model
from ax12emu.serve.transports.base import Transport

#: How long a test's port waits for a status packet, at least.  dynamixel-sdk's own timeout is
#: about 34 ms at 1 Mbps; a shared CI machine can hold the emulator up longer than that, and the
#: SDK then takes the late reply for the next transaction's.  The tests check what the bus
#: answers; how fast it answers, with the stock port, is tools/bench_protocol.py's job.
PATIENCE_MS = 250.0
#: The same for the conformance suite's runs in tests (its 50 ms default suits hardware).
CONFORMANCE_TIMEOUT_S = 0.2
#: How long those runs listen for a reply that must not come (by default, as long as the reply timeout):
#: the emulator answers at once, so a wrong reply comes within milliseconds, and one that comes later,
#: before the next packet, still fails its check (ax12emu/conformance/link.py).  Longer than a USB
#: adapter's 16 ms latency timer, so the same window would judge a real servo on a quiet host.
EMULATOR_SILENCE_S = 0.02


def wait_eeprom(byte_count: int = 1) -> None:
    """Leave the servos alone while they write ``byte_count`` EEPROM bytes, as a client of real ones must.

    An AX-12 answers a write into its EEPROM area, then ignores packets for
    about 6 ms per byte (``ServoOptions.eeprom_busy_s_per_byte``); this waits
    the conformance suite's bound for hardware.
    """
    time.sleep(byte_count * EEPROM_WAIT_S_PER_BYTE)


class PatientPortHandler(PortHandler):
    """dynamixel-sdk's PortHandler, waiting at least PATIENCE_MS for each reply (nothing else changed)."""

    def setPacketTimeout(self, packet_length):  # noqa: N802 (the SDK's name)
        super().setPacketTimeout(packet_length)
        self.packet_timeout = max(self.packet_timeout, PATIENCE_MS)


class UrlPortHandler(PatientPortHandler):
    """A patient port that opens pyserial URLs (``socket://``, ``ax12emu://``) as well as devices.

    dynamixel-sdk opens ports with ``serial.Serial(name)``, which knows no
    URLs; this is the subclass the docs show users, so the same scenario runs
    over a pty, TCP and the in-process link.
    """

    def setupPort(self, cflag_baud):  # noqa: N802 (the SDK's name)
        import serial

        if self.is_open:  # setBaudRate: change the line speed; reopening would end a private ax12emu:// bus
            self.ser.baudrate = self.baudrate
        else:
            self.ser = serial.serial_for_url(self.port_name, baudrate=self.baudrate, timeout=0)
            self.is_open = True
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True


@contextmanager
def sdk_port(path: str, baud: int = 1_000_000) -> Iterator[tuple[PortHandler, PacketHandler]]:
    """An open dynamixel-sdk port (patient: see PATIENCE_MS) and a Protocol 1.0 packet handler; closed afterwards.

    ``path`` is a device or a pyserial URL.
    """
    port = UrlPortHandler(path) if "://" in path else PatientPortHandler(path)
    # openPort opens at the handler's baud rate; setting it first opens the port once rather than
    # open, close, reopen (pyserial pauses 0.3 s after closing a socket:// port for the server's sake).
    port.baudrate = baud
    assert port.openPort(), f"could not open {path}"
    try:
        yield port, PacketHandler(1.0)
    finally:
        port.closePort()


def ok(result: tuple) -> object:
    """Unwrap an SDK (value, comm_result, error) triple that must have succeeded cleanly."""
    value, comm, error = result
    assert comm == COMM_SUCCESS, f"communication failed: {comm}"
    assert error == 0, f"status error {error:#x}"
    return value


def load_tool(name: str):
    """Import ``tools/NAME.py`` as a module (the tools are scripts, not a package)."""
    import importlib.util
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "tools" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"ax12emu_tool_{name}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the tool loads
    spec.loader.exec_module(module)
    return module


class RegisterLink:
    """One servo, ID 1, of ``key``'s model on ``bus``, written and read by register name in its own protocol's
    packets, as a host speaks to it, whatever its table: for bus tests in virtual time over every served model."""

    def __init__(self, key: str, bus: Bus) -> None:
        self.spec = model(key)
        self.bus = bus
        self.by_name = {entry.name: entry for entry in self.spec.entries}
        self.protocol2 = "2.0" in self.spec.protocols

    def write(self, name: str, value: int) -> None:
        """A WRITE of one register, its status packet without an error."""
        entry = self.by_name[name]
        data = value.to_bytes(entry.size, "little", signed=entry.signed)
        if self.protocol2:
            (reply,) = self.bus.receive(encode_instruction2(1, Instruction2.WRITE, entry.address.to_bytes(2, "little") + data))
            assert decode_packet2(reply.data).error == 0, (name, value)
        else:
            (reply,) = self.bus.receive(encode_instruction(1, Instruction.WRITE, bytes([entry.address]) + data))
            assert reply.data[4] == 0, (name, value)

    def registers(self, *names: str) -> dict[str, int]:
        """The registers ``names`` in one READ (one instant), by name."""
        entries = [self.by_name[name] for name in names]
        start = min(entry.address for entry in entries)
        size = max(entry.address + entry.size for entry in entries) - start
        if self.protocol2:
            (reply,) = self.bus.receive(encode_instruction2(1, Instruction2.READ, start.to_bytes(2, "little") + size.to_bytes(2, "little")))
            data = decode_packet2(reply.data).params
        else:
            (reply,) = self.bus.receive(encode_instruction(1, Instruction.READ, bytes([start, size])))
            data = reply.data[5:-1]
        return {entry.name: int.from_bytes(data[entry.address - start : entry.address - start + entry.size], "little",
                                           signed=entry.signed) for entry in entries}

    def read(self, name: str) -> int:
        """One register, in a READ of it alone."""
        return self.registers(name)[name]

    def run_s(self, seconds: float) -> None:
        """Time passes and the physics follows it, as the serving loop's tick brings it to the clock."""
        self.bus.clock.advance(seconds)
        self.bus.advance()


def u16(value: int) -> bytes:
    """A 2-byte little-endian field (Protocol 2.0's addresses and lengths)."""
    return (value & 0xFFFF).to_bytes(2, "little")


def u32(value: int) -> bytes:
    """A 4-byte little-endian register value."""
    return (value & 0xFFFFFFFF).to_bytes(4, "little")


class Packets2:
    """Protocol 2.0 instruction packets a host sends a bus of servos ``ids`` (the broadcast reads list them all
    by default), as the bus tests in virtual time build them."""

    def __init__(self, ids: tuple[int, ...]) -> None:
        self.ids = ids

    def write(self, servo_id: int, address: int, data: bytes) -> bytes:
        return encode_instruction2(servo_id, Instruction2.WRITE, u16(address) + data)

    def sync_write(self, address: int, values: dict[int, bytes]) -> bytes:
        length = len(next(iter(values.values())))
        params = u16(address) + u16(length) + b"".join(bytes((servo_id,)) + data for servo_id, data in values.items())
        return encode_instruction2(BROADCAST_ID, Instruction2.SYNC_WRITE, params)

    def sync_read(self, address: int, length: int, ids: tuple[int, ...] | None = None) -> bytes:
        return self._listed_read(Instruction2.SYNC_READ, address, length, ids)

    def fast_sync_read(self, address: int, length: int, ids: tuple[int, ...] | None = None) -> bytes:
        return self._listed_read(Instruction2.FAST_SYNC_READ, address, length, ids)

    def bulk_read(self, reads: list[tuple[int, int, int]]) -> bytes:
        params = b"".join(bytes((servo_id,)) + u16(address) + u16(length) for servo_id, address, length in reads)
        return encode_instruction2(BROADCAST_ID, Instruction2.BULK_READ, params)

    def _listed_read(self, instruction: int, address: int, length: int, ids: tuple[int, ...] | None) -> bytes:
        listed = self.ids if ids is None else ids
        return encode_instruction2(BROADCAST_ID, instruction, u16(address) + u16(length) + bytes(listed))


class PipeTransport(Transport):
    """A serving loop's transport for tests: the host's bytes come through a pipe; replies are collected."""

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


def http_json(url: str, body: bytes = b"", headers: dict[str, str] | None = None, method: str = "POST") -> tuple[int, dict]:
    """A request to the live view and its JSON answer, error statuses included: (status, answer)."""
    import json
    import urllib.error
    import urllib.request

    request = urllib.request.Request(url, data=body if method == "POST" else None, method=method, headers=headers or {})
    try:
        with urllib.request.urlopen(request, timeout=5) as answer:
            return answer.status, json.loads(answer.read())
    except urllib.error.HTTPError as error:
        with error:
            return error.code, json.loads(error.read())


def post_json(url: str, body: bytes | dict) -> tuple[int, dict]:
    """A control (a dict, or bytes as they are) posted to the live view as its page posts it: (status, answer)."""
    import json

    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    return http_json(url, data, {"Content-Type": "application/json"})
