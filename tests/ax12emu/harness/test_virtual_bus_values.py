"""VirtualBus takes the values a test computes (numpy's integers too) and refuses, by name, one a register or the
physics cannot hold: they were wrapped (an ID of 300 became 44) or stuck in the physics for good (NaN)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from ax12emu import VirtualBus


@pytest.fixture
def bus():
    with VirtualBus([1, 2], transport="inprocess", virtual_time=True) as bus:
        yield bus


def test_numpy_integers_are_ids_and_register_values():
    with VirtualBus(np.arange(1, 4), transport="inprocess", virtual_time=True) as bus:
        assert bus.bus.ids == [1, 2, 3]
        bus.write(2, "goal_position", np.int64(700))
        assert bus.read(2, "goal_position") == 700
    with VirtualBus([1], servo="xl430-w250", transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "goal_position", np.int32(3000))
        bus.write(1, "homing_offset", -100)  # a signed register takes its negative values
        assert (bus.read(1, "goal_position"), bus.read(1, "homing_offset")) == (3000, -100)


@pytest.mark.parametrize(("call", "error", "says"), [
    (lambda b: b.write(2, "id", 300), ValueError, r"id holds 0..255 \(1 byte\), got 300"),
    (lambda b: b.write(1, "goal_position", 10**9), ValueError, "goal_position holds 0..65535"),
    (lambda b: b.write(1, "goal_position", 1.5), TypeError, "goal_position takes an integer"),
    (lambda b: b.set_temperature(1, 300), ValueError, "present_temperature holds 0..255"),
    (lambda b: b.set_voltage(1, float("nan")), ValueError, "volts must be a finite number"),
    (lambda b: b.set_angle_deg(1, float("nan")), ValueError, "degrees must be a finite number"),
    (lambda b: b.set_external_torque(1, float("inf")), ValueError, "torque_nm must be a finite number"),
    (lambda b: b.step(float("nan")), ValueError, "finite step"),
    (lambda b: b.step(float("inf")), ValueError, "finite step"),
])
def test_a_value_no_register_or_physics_can_hold_is_refused_by_name_and_changes_nothing(bus, call, error, says):
    before = bus.table(1), bus.table(2), bus.now_s
    with pytest.raises(error, match=says):
        call(bus)
    assert (bus.table(1), bus.table(2), bus.now_s) == before
    bus.step(0.01)  # the bus still runs
    assert bus.now_s == pytest.approx(before[2] + 0.01)


def test_ids_that_are_not_integers_are_refused():
    with pytest.raises(TypeError, match="ids must be integers, got '12'"):
        VirtualBus("12", transport="inprocess")


@pytest.mark.parametrize(("given", "says"), [
    ({"model": 5}, "model must be 'physical', 'kinematic' or a firmware_model.ServoModel, got int"),
    ({"faults": {"drop": 0.5}}, "faults must be an ax12emu.faults.FaultConfig, got dict"),
    ({"options": {"profile": "ax12a"}}, "options must be a ServoOptions"),
    ({"servo": 5}, "servo must be a text such as '1-2:xl430-w250', got int"),
    ({"servo": "xl430-w250", "baud_bps": "fast"}, "baud_bps must be a bit rate, got str"),
])
def test_an_argument_of_the_wrong_type_is_named(given, says):
    """They failed deep inside ("'int' object has no attribute 'n'", "Unknown format code 'f'")."""
    with pytest.raises(TypeError, match=re.escape(says)):
        VirtualBus([1], transport="inprocess", **given)


def test_tcp_address_takes_host_colon_port_as_web_does():
    with VirtualBus([1], transport="tcp", tcp_address="127.0.0.1:0") as bus:
        assert bus.port.startswith("socket://127.0.0.1:")
