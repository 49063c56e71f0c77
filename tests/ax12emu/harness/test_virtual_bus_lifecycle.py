"""A VirtualBus's life: a failed start leaves other buses alone, and a closed bus says so instead of working on."""

from __future__ import annotations

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
