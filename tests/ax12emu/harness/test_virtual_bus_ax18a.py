"""AX-18As from the harness: ``VirtualBus(servo=...)`` reads the text ``serve --servo`` does."""

from __future__ import annotations

import pytest
from dynamixel_sdk import COMM_SUCCESS, PacketHandler
from emu_testkit import UrlPortHandler

import ax12emu  # noqa: F401  (registers the URL handler)
from ax12emu import VirtualBus
from ax12emu.bus.bus import Bus
from ax12emu.bus.mixed import MixedBus


@pytest.mark.parametrize(
    ("servo", "expected", "kind"),
    [
        ("ax-18a", {1: 18}, Bus),
        ("1-2:ax-12a,3:ax-18a", {1: 12, 2: 12, 3: 18}, Bus),
        ("1:ax-18a,1:xl430-w250", {1: 18}, MixedBus),
    ],
)
def test_dynamixel_sdk_pings_each_model(servo, expected, kind):
    with VirtualBus(servo=servo, transport="inprocess", virtual_time=True, baud_bps=1_000_000) as bus:
        assert type(bus.bus) is kind
        port = UrlPortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(1_000_000)
        try:
            ph = PacketHandler(1.0)
            assert {i: ph.ping(port, i) for i in expected} == {i: (n, COMM_SUCCESS, 0) for i, n in expected.items()}
        finally:
            port.closePort()


def test_ax12as_alone_are_still_the_default_bus():
    with pytest.raises(ValueError, match="AX-12As alone are the default bus"):
        VirtualBus(servo="1-2:ax-12a", transport="inprocess")
