"""A VirtualBus's life: a failed start leaves other buses alone, and a closed bus says so instead of working on."""

from __future__ import annotations

import threading
import time

import pytest
import serial

import ax12emu  # noqa: F401  (registers the URL handler)
from ax12emu import VirtualBus


def test_a_start_refused_for_a_taken_name_leaves_that_name_to_its_bus():
    """The refused bus's clean-up unregistered the name, and the first bus could no longer be opened by URL."""
    with VirtualBus([1], name="arm", transport="inprocess") as first:
        with pytest.raises(ValueError, match="an in-process bus named 'arm' already exists"):
            VirtualBus([2], name="arm", transport="inprocess").start()
        with serial.serial_for_url("ax12emu://arm") as link:
            assert link.is_open
        assert first.read(1, "id") == 1


@pytest.mark.parametrize("transport", ["inprocess", "pty"])
def test_a_closed_bus_refuses_calls_and_a_restart(transport):
    """After close() its port is gone (a pty's name may be another's by now) and its state saved: reads, writes
    and faults raise instead of acting on the dead bus, and start() asks for a new one."""
    bus = VirtualBus([1], transport=transport).start()
    bus.close()
    for call in (lambda: bus.read(1, "id"), lambda: bus.write(1, "led", 1), lambda: bus.set_temperature(1, 50)):
        with pytest.raises(RuntimeError, match="is closed"):
            call()
    with pytest.raises(RuntimeError, match="closed; make a new one"):
        bus.start()
    bus.close()  # still safe twice
    assert not bus.running


def test_a_call_waiting_when_the_serving_loop_stops_fails_at_once():
    """A call queued after the loop's last pass was never run, and its caller waited out the 5 s timeout for a
    TimeoutError that blamed a long step; the loop fails what it leaves, and a call made after it ended fails itself."""
    from ax12emu.bus.bus import Bus
    from ax12emu.serve import BusServer, open_transport
    from ax12emu.serve.server import ServerStopped

    bus, transport = Bus([1]), open_transport("pty")
    server = BusServer(bus, transport)
    outcome: list[BaseException] = []

    def caller() -> None:
        try:
            server.call(lambda b: b.ids, 5.0)
        except BaseException as exc:
            outcome.append(exc)

    try:
        thread = threading.Thread(target=caller)
        thread.start()
        while not server._calls:  # queued, and no pass will take it
            time.sleep(0.001)
        started = time.monotonic()
        server.stop()
        server.serve_forever()  # ends at once, failing the call on its way out
        thread.join(2.0)
        assert isinstance(outcome[0], ServerStopped) and time.monotonic() - started < 1.0
        with pytest.raises(ServerStopped, match="the serving loop has stopped; the call did not run"):
            server.call(lambda b: b.ids, 5.0)
    finally:
        transport.close()
        bus.close()


def test_close_fails_reads_of_other_threads_promptly_with_is_closed():
    """A thread reading in a loop while the bus closes: each trial ends in "is closed" at once (a quarter of them
    hung 5 s and ended in a TimeoutError)."""
    for _ in range(10):
        bus = VirtualBus([1]).start()
        outcome: list[tuple[BaseException, float]] = []

        def reader(bus: VirtualBus = bus, outcome: list = outcome) -> None:
            try:
                while True:
                    bus.read(1, "present_position")
            except BaseException as error:
                outcome.append((error, time.monotonic()))

        thread = threading.Thread(target=reader)
        thread.start()
        time.sleep(0.01)
        closed = time.monotonic()
        bus.close()
        thread.join(10.0)
        (exc, ended), = outcome
        assert isinstance(exc, RuntimeError) and "is closed" in str(exc), repr(exc)
        assert ended - closed < 1.0


@pytest.mark.parametrize(("name", "says"), [
    ("arm/left", "'/' is read as part of the URL"),
    ("/", "'/' is read as part of the URL"),  # ax12emu:/// opened a private bus of its own, silently
    ("arm#2", "'#' is read as part of the URL"),
    ("a?b", "'?' is read as part of the URL"),
    ("[arm]", "'\\[' ']' are read as part of the URL"),
    ("arm\t1", "'\\\\t' is read as part of the URL"),
    ("", "is blank"),
    ("  ", "is blank"),
])
def test_an_in_process_name_its_port_cannot_find_is_refused(name, says):
    with pytest.raises(ValueError, match=says):
        VirtualBus([1], transport="inprocess", name=name)


@pytest.mark.parametrize("name", ["arm", "left arm", "arm:1", "arm%41", "arm-2_b.c"])
def test_an_in_process_name_is_the_one_its_port_finds(name):
    with VirtualBus([1], transport="inprocess", name=name) as bus:
        assert bus.port == f"ax12emu://{name}"
        bus.write(1, "id", 7)
        with serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.1) as link:
            link.write(bytes([0xFF, 0xFF, 7, 2, 1, (~(7 + 2 + 1)) & 0xFF]))
            assert link.read(6) == bytes([0xFF, 0xFF, 7, 2, 0, (~(7 + 2)) & 0xFF])


def test_automatic_names_pass_over_names_users_took():
    """A user's "busN" (a natural name) made the unnamed bus that came to that number fail to start."""
    from ax12emu.harness import virtual_bus

    taken = [f"bus{virtual_bus._instances + n}" for n in (1, 2)]
    mine = [VirtualBus([1], transport="inprocess", name=name).start() for name in taken]
    try:
        unnamed = VirtualBus([1], transport="inprocess")  # its name is picked now ...
        late = VirtualBus([1], transport="inprocess", name=unnamed.name).start()  # ... and taken before it starts
        try:
            with unnamed:
                assert unnamed.name not in (*taken, late.name) and unnamed.port == f"ax12emu://{unnamed.name}"
                with serial.serial_for_url(unnamed.port) as link:
                    assert link.is_open
        finally:
            late.close()
    finally:
        for bus in mine:
            bus.close()


def test_a_blank_name_is_refused_on_any_transport():
    with pytest.raises(ValueError, match="is blank"):
        VirtualBus([1], name=" ")
