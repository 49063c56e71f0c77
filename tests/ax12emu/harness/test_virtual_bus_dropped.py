"""A VirtualBus dropped without close(): collected on every transport, said, and its thread and port released;
a port taken at start() is named by the argument that asked for it."""

from __future__ import annotations

import errno
import gc
import logging
import os
import socket
import subprocess
import sys
import threading
import time
import weakref

import pytest
import serial

import ax12emu  # noqa: F401  (registers the URL handler)
from ax12emu import VirtualBus
from ax12emu.harness.virtual_bus import TRANSPORTS

#: How long the release of a collected bus may take: its serving thread sees the stop within a physics period,
#: an in-process bus's live view at its next sample (25 a second); the margin is for a loaded machine.
RELEASE_S = 5.0


def _own_threads(before: set[threading.Thread]) -> list[str]:
    return [t.name for t in threading.enumerate() if t not in before and t.is_alive()]


def _port_answers(port: str) -> bool:
    """Whether a client can still open ``port`` (a pty's path, a socket:// or ax12emu:// URL)."""
    try:
        serial.serial_for_url(port, baudrate=1_000_000, timeout=0.1).close()
    except (serial.SerialException, OSError):
        return False
    return True


@pytest.mark.parametrize("web", [False, True], ids=["no-web", "web"])
@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_bus_dropped_unclosed_is_collected_said_and_released(transport, web, caplog):
    """Its serving thread (and a live view's threads) held it, so a pty or TCP bus was never collected: no warning,
    and a thread and its port kept serving for the life of the process."""
    if web:
        pytest.importorskip("aiohttp")
    before = set(threading.enumerate())
    bus = VirtualBus([1], transport=transport, web=web).start()
    name, port = bus.name, bus.port
    assert _port_answers(port)
    # A pty's path may be another test's pty by the time it is looked at: its master descriptor is this bus's alone.
    master = getattr(bus._transport, "_master", None)
    collected = weakref.ref(bus)
    del bus
    with caplog.at_level(logging.WARNING, logger="ax12emu.harness.virtual_bus"):
        gc.collect()
    assert collected() is None
    assert f"VirtualBus {name} was never closed" in caplog.text
    deadline = time.monotonic() + RELEASE_S
    while _own_threads(before) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not _own_threads(before)
    if master is None:
        assert not _port_answers(port)
    else:
        with pytest.raises(OSError):
            os.fstat(master)


@pytest.mark.parametrize("argument", ["tcp_address", "web"])
def test_a_taken_address_is_named_by_its_argument(argument):
    """Either one taken raised the same bare "[Errno 98] Address already in use"."""
    if argument == "web":
        pytest.importorskip("aiohttp")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        address = ("127.0.0.1", taken.getsockname()[1])
        free = ("127.0.0.1", 0)
        kwargs = {"tcp_address": address, "web": free} if argument == "tcp_address" else {"tcp_address": free, "web": address}
        with pytest.raises(OSError) as raised:
            VirtualBus([1], transport="tcp", **kwargs).start()
    assert raised.value.errno == errno.EADDRINUSE
    assert str(raised.value).startswith(f"[Errno {errno.EADDRINUSE}] {argument} 127.0.0.1:{address[1]}: ")
    assert os.strerror(errno.EADDRINUSE) in str(raised.value)


def test_a_collection_inside_the_name_registrys_lock_does_not_hang():
    """A collection runs wherever an allocation falls, here inside the in-process name registry's lock: a
    release that unregistered the name there, on the collecting thread, waited on that lock for ever."""
    program = (
        "import gc\n"
        "from ax12emu import VirtualBus\n"
        "from ax12emu.harness import inprocess\n"
        "gc.disable()  # the one collection is the one below\n"
        "for transport in ('inprocess', 'pty', 'tcp'):\n"
        "    VirtualBus([1], transport=transport).start()\n"
        "with inprocess._REGISTRY_LOCK:\n"
        "    gc.collect()\n"
        "print('collected')\n"
    )
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=30)
    assert done.stdout.strip() == "collected", done.stderr


@pytest.mark.parametrize("web", [False, True], ids=["no-web", "web"])
def test_a_port_still_open_on_a_dropped_in_process_bus_fails_as_on_the_other_transports(web, caplog):
    """Without a live view the warning said "closing it" and the open port went on answering: with one, it failed."""
    if web:
        pytest.importorskip("aiohttp")
    bus = VirtualBus([1], transport="inprocess", web=web).start()
    port = serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.2)
    try:
        port.write(bytes((0xFF, 0xFF, 1, 2, 1, 0xFB)))
        assert port.read(6) == bytes((0xFF, 0xFF, 1, 2, 0, 0xFC))
        del bus
        with caplog.at_level(logging.WARNING, logger="ax12emu.harness.virtual_bus"):
            gc.collect()
        assert "was never closed" in caplog.text
        deadline = time.monotonic() + RELEASE_S
        while True:  # with a live view the release comes at its next sample
            try:
                port.write(bytes((0xFF, 0xFF, 1, 2, 1, 0xFB)))
            except serial.SerialException as exc:
                assert "closed" in str(exc)
                break
            assert time.monotonic() < deadline, "the port still answers"
            time.sleep(0.02)
    finally:
        port.close()


def test_a_dropped_buss_name_is_free_for_a_new_bus_while_a_port_is_still_open_on_the_old_one(caplog):
    """The name stayed taken (NameTaken) until the stale port closed, and a blocking read on that port (timeout
    None) waited for ever where a pty's or a socket's fails."""
    bus = VirtualBus([1], transport="inprocess", name="rig").start()
    stale = serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=None)
    outcome = []

    def read():
        try:
            outcome.append(stale.read(6))
        except serial.SerialException as exc:
            outcome.append(exc)

    reader = threading.Thread(target=read)
    reader.start()
    try:
        del bus
        with caplog.at_level(logging.WARNING, logger="ax12emu.harness.virtual_bus"):
            gc.collect()
        reader.join(RELEASE_S)
        assert not reader.is_alive() and isinstance(outcome[0], serial.SerialException), outcome
        with VirtualBus([1], transport="inprocess", name="rig") as again:
            port = serial.serial_for_url(again.port, baudrate=1_000_000, timeout=0.5)
            port.write(bytes((0xFF, 0xFF, 1, 2, 1, 0xFB)))
            assert port.read(6) == bytes((0xFF, 0xFF, 1, 2, 0, 0xFC))
            port.close()
    finally:
        stale.close()
