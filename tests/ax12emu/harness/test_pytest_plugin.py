"""The pytest plugin: the ax12_bus fixture, its markers, and teardown when a test fails."""

from __future__ import annotations

import threading

import pytest
import serial

from ax12emu.protocol.packets import encode_instruction, encode_status

pytest_plugins = ["pytester"]


@pytest.mark.ax12_ids(4, 5)
def test_marker_chooses_ids(ax12_bus):
    """@pytest.mark.ax12_ids(4, 5) gives a running bus with exactly those IDs."""
    assert ax12_bus.running and ax12_bus.bus.ids == [4, 5]
    with serial.Serial(ax12_bus.port, 1_000_000, timeout=0.5) as link:
        link.write(encode_instruction(5, 0x01))
        assert link.read(6) == encode_status(5, 0)


@pytest.mark.parametrize("ax12_bus", [[7], [8, 9]], indirect=True)
def test_indirect_parametrization(ax12_bus):
    """Indirect parametrization of ax12_bus sets the IDs."""
    assert ax12_bus.bus.ids in ([7], [8, 9])


@pytest.mark.ax12_bus_options(transport="inprocess", virtual_time=True)
def test_options_marker(ax12_bus):
    """ax12_bus_options passes keyword arguments to VirtualBus."""
    assert ax12_bus.port.startswith("ax12emu://") and ax12_bus.virtual_time


def test_failing_test_still_tears_down(pytester):
    """A test that fails inside the fixture leaves no serving thread behind, and the marker is registered."""
    pytester.makepyfile(
        """
        import pytest

        @pytest.mark.ax12_ids(1, 2)
        def test_fails(ax12_bus):
            assert ax12_bus.running
            assert False, "boom"
        """
    )
    result = pytester.runpytest_inprocess("--strict-markers", "-p", "no:cacheprovider")
    result.assert_outcomes(failed=1)
    assert not [t for t in threading.enumerate() if t.name.startswith("ax12emu-")]
