"""XL-320s through VirtualBus, ``ax12emu://`` and the pytest plugin (``servo=``), beside X-series servos and AX-12As.

The client is unmodified dynamixel-sdk with PacketHandler(2.0); register helpers take the XL-320's own names.
"""

from __future__ import annotations

import pytest
from dynamixel_sdk import COMM_SUCCESS, PacketHandler
from emu_testkit import UrlPortHandler, ok

import ax12emu  # noqa: F401  (registers the URL handler)
from ax12emu import VirtualBus
from ax12emu.protocol.packets2 import ErrorNumber

XL320, XL430 = 350, 1060
# XL-320 addresses (e-manual, XL-320 "Control Table")
TORQUE_ENABLE, GOAL_POSITION, MOVING = 24, 30, 49


def test_virtual_bus_serves_xl320s_by_their_register_names():
    """A goal in 0.29-degree units turns the shaft that far (virtual time); the other servo stays."""
    with VirtualBus([1, 2], servo="xl-320", transport="inprocess", virtual_time=True) as bus:
        table = bus.table(1)
        assert table["model_number"] == XL320 and table["control_mode"] == 2 and "operating_mode" not in table
        assert bus.read(1, "present_position") == 512 and bus.read(1, "torque_limit") == 1023
        start_deg = bus.angle_deg(1)
        bus.write(1, "torque_enable", 1)
        bus.write(1, "goal_position", 212)
        bus.step(1.5)
        assert abs(bus.read(1, "present_position") - 212) <= 6
        assert bus.angle_deg(1) - start_deg == pytest.approx((bus.read(1, "present_position") - 512) * 300 / 1024, abs=0.3)
        assert bus.read(2, "present_position") == 512


def test_url_serves_xl320s_to_dynamixel_sdk_at_their_factory_baud():
    """ax12emu://?servo=xl-320: the XL-320's factory Baud Rate is 3 (1 Mbps); Ping, a goal write that moves."""
    port = UrlPortHandler("ax12emu://?servo=xl-320&ids=1,2&virtual_time=1")
    assert port.openPort() and port.setBaudRate(1_000_000)
    ph = PacketHandler(2.0)
    try:
        assert [ok(ph.ping(port, i)) for i in (1, 2)] == [XL320, XL320]
        assert ph.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
        assert ph.write2ByteTxRx(port, 1, GOAL_POSITION, 1024) == (COMM_SUCCESS, ErrorNumber.DATA_RANGE)
        assert ph.write2ByteTxRx(port, 1, GOAL_POSITION, 900) == (COMM_SUCCESS, 0)
        assert ok(ph.read1ByteTxRx(port, 1, MOVING)) == 1  # the control loop ran before the read
    finally:
        port.closePort()


def test_xl320s_share_a_wire_with_x_series_servos_and_ax12as():
    """Per-ID models: XL430s and an XL-320 on Protocol 2.0, AX-12As on 1.0 beside them (IDs per protocol)."""
    with VirtualBus(servo="1-2:ax-12a,1-2:xl430-w250,3:xl-320", transport="inprocess") as bus:
        assert bus.read(3, "model_number", protocol=2.0) == XL320
        assert bus.read(1, "model_number", protocol=2.0) == XL430
        assert bus.read(1, "model_number", protocol=1.0) == 12


@pytest.mark.ax12_servo("1:xl430-w250,2-3:xl-320")
@pytest.mark.ax12_bus_options(transport="inprocess")
def test_plugin_marker_serves_xl320s(ax12_bus):
    assert [ax12_bus.read(i, "model_number") for i in (1, 2, 3)] == [XL430, XL320, XL320]
