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


def test_ax12as_alone_take_servo_to_start_at_another_rate():
    """They were refused as "the default bus", which starts at 1 Mbps: no way to serve them at 57,600 from Python."""
    with VirtualBus(servo="1-2:ax-12a", transport="inprocess", baud_bps=57_600) as bus:
        assert bus.read(2, "baud_rate") == 34


def test_params_options_and_the_url_shape_the_ax_servos_of_a_servo_wire(tmp_path):
    """As on the command line: params= (a twin of an AX-18A's recording) and the AX bus's options reach the AX
    servos of a servo= wire, from VirtualBus and from an ax12emu:// URL alike."""
    from ax12emu.servo.virtual_servo import ServoOptions
    from firmware_model.params import ServoParams

    twin = ServoParams(static_friction_nm=0.21, supply_voltage_v=9.5)
    with VirtualBus(servo="ax-18a", ids=[1, 2], transport="inprocess", virtual_time=True, params=twin,
                    options=ServoOptions(goal_position_enables_torque=False)) as bus:
        assert bus.bus.model.params == twin
        assert [s.options.goal_position_enables_torque for s in bus.bus.servos] == [False, False]
    twin.to_toml(tmp_path / "twin.toml")
    port = UrlPortHandler(f"ax12emu://?servo=1:ax-18a,2:xl430-w250&baud=1000000&virtual_time=1&goal_torque=unchanged"
                          f"&params={tmp_path / 'twin.toml'}")
    assert port.openPort() and port.setBaudRate(1_000_000)
    try:
        ph = PacketHandler(1.0)
        assert ph.read1ByteTxRx(port, 1, 42) == (95, COMM_SUCCESS, 0)  # Present Voltage: the twin's 9.5 V supply
        assert ph.write2ByteTxRx(port, 1, 30, 600) == (COMM_SUCCESS, 0)  # a goal with the torque off ...
        assert ph.read1ByteTxRx(port, 1, 24) == (0, COMM_SUCCESS, 0)  # ... leaves it off (goal_torque=unchanged)
    finally:
        port.closePort()
