"""The live view's controls on Protocol 2.0 and mixed buses (ServedControls, as ``ax12emu serve`` uses them), in virtual time.

Each control acts as VirtualBus's method of the same name does; what a servo cannot take is
refused with the reason, and nothing is half done.
"""

from __future__ import annotations

import pytest

from ax12emu import VirtualBus
from ax12emu.live import ControlError, ServedControls, apply
from ax12emu.live.snapshot import take

BAUD = 1_000_000


def servo_of(bus: VirtualBus, servo_id: int, protocol: str = "2.0") -> dict:
    frame = bus.call(take)
    return next(s for s in frame["servos"] if s["id"] == servo_id and s["protocol"] == protocol)


@pytest.fixture
def x_bus():
    with VirtualBus(servo="1-2:xl430-w250,3:xl330-m288", transport="inprocess", virtual_time=True) as bus:
        yield bus, ServedControls(bus.call)


def test_temperature_and_voltage_are_pinned_in_each_models_own_register(x_bus):
    bus, controls = x_bus
    assert apply(controls, {"action": "temperature", "id": 1, "celsius": 75}) == "servo 1: temperature held at 75.0 C"
    assert apply(controls, {"action": "voltage", "id": 3, "volts": 4.2}) == "servo 3: voltage held at 4.2 V"
    bus.step(0.05)
    assert bus.read(1, "present_temperature") == 75
    assert bus.read(3, "present_input_voltage") == 42  # the X series' register, 0.1 V per unit
    assert servo_of(bus, 3)["faults"] == ["present_input_voltage held at 42"]
    apply(controls, {"action": "voltage", "id": 3, "volts": None})
    assert servo_of(bus, 3)["faults"] == []


def test_releasing_a_held_reading_says_released(x_bus):
    """null releases a held reading: the log and the answer say so, not "held at None"."""
    _, controls = x_bus
    apply(controls, {"action": "temperature", "id": 1, "celsius": 75})
    assert apply(controls, {"action": "temperature", "id": 1, "celsius": None}) == "servo 1: temperature released"
    assert apply(controls, {"action": "voltage", "id": 3, "volts": None}) == "servo 3: voltage released"


def test_a_push_turns_a_limp_x_series_shaft(x_bus):
    bus, controls = x_bus
    before = bus.read(2, "present_position")
    assert apply(controls, {"action": "external_torque", "id": 2, "nm": 0.3}) == "servo 2: external torque 0.3 N m"
    bus.step(0.3)
    assert bus.read(2, "present_position") > before + 20  # torque off: positive torque turns it CCW
    assert bus.read(1, "present_position") == before  # the other servos are left alone


def test_hardware_errors_stalls_and_vanishing_go_through_faults2(x_bus):
    bus, controls = x_bus
    apply(controls, {"action": "alarm", "slot": 1, "bits": "electrical_shock"})
    assert servo_of(bus, 1)["alarm_names"] == ["electrical_shock"]
    apply(controls, {"action": "alarm", "slot": 2, "bits": ["overload", "overheating"]})  # a JSON list of names
    assert sorted(servo_of(bus, 2)["alarm_names"]) == ["overheating", "overload"]
    apply(controls, {"action": "clear_alarm", "slot": 2})
    assert apply(controls, {"action": "clear_alarm", "slot": 1}) == "servo 1: forced alarms lifted"
    assert servo_of(bus, 1)["alarms"] == 0  # the firmware rebooted, as REBOOT does
    apply(controls, {"action": "stall", "slot": 2})
    apply(controls, {"action": "vanish", "slot": 3})
    assert servo_of(bus, 2)["faults"] == ["stalled"] and servo_of(bus, 3)["faults"] == ["vanished"]
    apply(controls, {"action": "clear_faults"})
    assert all(not s["faults"] for s in bus.call(take)["servos"])


@pytest.mark.parametrize(
    ("message", "says"),
    [
        # Shutdown(63) of an XL430 selects Overheating, Electrical Shock and Overload by default, not Input Voltage.
        ({"action": "alarm", "slot": 1, "bits": "input_voltage"}, "does not select input_voltage"),
        ({"action": "alarm", "slot": 1, "bits": "angle_limit"}, "unknown alarm 'angle_limit'"),
        ({"action": "alarm", "slot": 1, "bits": "x" * 200}, "at most 80 characters"),
        ({"action": "alarm", "slot": 1, "bits": 0x02}, "Hardware Error Status bits are"),
        ({"action": "alarm", "slot": 1, "bits": [1, 2]}, 'alarm names ("overload,overheating" or ["overload"'),
        ({"action": "alarm", "slot": 1, "bits": []}, "alarm names"),
        ({"action": "vanish", "slot": 9}, "no servo launched as ID 9"),
        ({"action": "temperature", "id": 9, "celsius": 50}, "no servo with ID 9"),
        ({"action": "vanish", "slot": 1, "protocol": 1.0}, "this bus's servos speak Protocol 2"),
        ({"action": "vanish", "slot": 1, "protocol": 3}, "protocol must be 1.0, 2.0 or null"),
        ({"action": "vanish", "slot": 1, "protocol": "2.0"}, "protocol must be 1.0, 2.0 or null"),
        ({"action": "external_torque", "id": 1, "nm": 1e9}, "nm must be a number -10..10"),
        ({"action": "step", "seconds": -1}, "seconds must be a number 0..10"),
        # JSON integers have no size limit: past the float range, refused as out of range (not an OverflowError)
        ({"action": "step", "seconds": 10**400}, "seconds must be a number 0..10, got 1000"),
        ({"action": "external_torque", "id": 1, "nm": -(10**400)}, "(402 characters)"),
        ({"action": "reply_faults", "drop": 10**400}, "drop must be a number 0..1"),
        ({"action": "temperature", "id": 1, "celsius": 10**400}, "celsius must be a number 0..255 or null"),
    ],
)
def test_what_a_servo_cannot_take_is_refused_with_the_reason(x_bus, message, says):
    bus, controls = x_bus
    before = bus.call(take)["servos"]
    with pytest.raises(ControlError) as refused:
        apply(controls, message)
    assert says in str(refused.value)
    assert bus.call(take)["servos"] == before  # nothing half done


def test_a_mixed_wire_names_a_servo_by_id_and_protocol():
    with VirtualBus(servo="1-2:ax-12a,1:xl430-w250", transport="inprocess", virtual_time=True, baud_bps=BAUD) as bus:
        controls = ServedControls(bus.call)
        with pytest.raises(ControlError, match="ID 1 was launched on both protocols"):
            apply(controls, {"action": "vanish", "slot": 1})
        with pytest.raises(ControlError, match="ID 1 answers on both protocols of this wire: give protocol"):
            apply(controls, {"action": "temperature", "id": 1, "celsius": 60})
        assert apply(controls, {"action": "vanish", "slot": 1, "protocol": 2.0}) == "servo 1 vanished (Protocol 2.0)"
        apply(controls, {"action": "temperature", "id": 1, "celsius": 60, "protocol": 1.0})
        apply(controls, {"action": "voltage", "id": 2, "volts": 11})  # only an AX-12A has ID 2: no protocol needed
        # An X-series alarm name on an AX-12A is refused by the AX-12's faults, with the names it takes.
        with pytest.raises(ControlError, match="unknown alarm 'electrical_shock'; use overload"):
            apply(controls, {"action": "alarm", "slot": 2, "bits": "electrical_shock"})
        apply(controls, {"action": "external_torque", "id": 1, "nm": 0.2, "protocol": 1.0})
        bus.step(0.2)
        assert servo_of(bus, 1, "2.0")["faults"] == ["vanished"] and servo_of(bus, 1, "1.0")["faults"] == ["present_temperature held at 60"]
        assert servo_of(bus, 2, "1.0")["registers"]["present_voltage"] == 110
        assert bus.read(1, "present_position", protocol=1.0) > 512  # pushed CCW with the torque off
        assert bus.read(1, "present_position", protocol=2.0) == 2048
        apply(controls, {"action": "reply_faults", "drop": 1.0})
        figures = bus.call(take)["faults"]
        assert figures["drop"] == 1.0


def test_faults_name_the_buses_that_take_them():
    """An MX wire takes the faults (Faults1X); a bus ax12emu.faults does not serve is refused naming the ones it does."""
    from ax12emu.faults.injection import Faults1X

    with VirtualBus(servo="mx-28", transport="inprocess", virtual_time=True) as bus:
        assert isinstance(bus.call(ServedControls(bus.call).faults_of), Faults1X)

    class SomeOtherBus:
        faults = None

    with pytest.raises(ControlError) as refused:
        ServedControls(lambda fn: fn(SomeOtherBus())).faults_of(SomeOtherBus())
    says = str(refused.value)
    assert "not available on a SomeOtherBus" in says
    assert all(name in says for name in ("AX-12", "MX", "Protocol 2.0")), says


def test_a_push_on_one_ax12_keeps_the_torque_serve_put_on_the_others():
    """The AX-12 bus's one model takes every servo's torque at once: changing servo 1's from the page leaves the
    torque ``serve --external-torque`` put on servo 2 (and the model's own record of both is what moves them)."""
    with VirtualBus(ids=[1, 2], transport="inprocess", virtual_time=True) as bus:
        bus.call(lambda b: b.model.set_external_torque(1.0))  # what serve --external-torque 1.0 does
        controls = ServedControls(bus.call)
        apply(controls, {"action": "external_torque", "id": 1, "nm": 0.5})
        assert list(bus.call(lambda b: b.model.external_torque_nm)) == [0.5, 1.0]
        apply(controls, {"action": "external_torque", "id": 2, "nm": 0.0})
        assert list(bus.call(lambda b: b.model.external_torque_nm)) == [0.5, 0.0]


def test_an_ax12_takes_only_its_alarms_by_number_too():
    """Angle Limit, Range, Checksum and Instruction answer one packet, they are no state: refused by name, and by
    number as well (bit 0x02 was forced while "angle_limit" was refused)."""
    with VirtualBus(ids=[1], transport="inprocess", virtual_time=True) as bus:
        controls = ServedControls(bus.call)
        for bits in (0x02, 0x08, 0x10, 0x40, 0x22):
            with pytest.raises(ControlError, match="the AX-12's alarm bits are overload 0x20, overheating 0x04, input_voltage 0x01"):
                apply(controls, {"action": "alarm", "slot": 1, "bits": bits})
        assert apply(controls, {"action": "alarm", "slot": 1, "bits": 0x20}) == "servo 1: alarm 32 forced"


def test_a_parameter_no_check_foresaw_is_the_controls_error(x_bus, monkeypatch):
    """Whatever a parameter's check raises is the message's fault: a ControlError (400), never the emulator's (500)."""
    from ax12emu.live import controls as controls_module

    def fussy(value):
        raise OverflowError("int too large to convert to float")

    action = controls_module.ACTIONS["step"]
    monkeypatch.setitem(controls_module.ACTIONS, "step", controls_module.Action({"seconds": fussy}, action.run, action.says))
    with pytest.raises(ControlError, match=r"step: seconds 1 cannot be taken: OverflowError: int too large"):
        apply(x_bus[1], {"action": "step", "seconds": 1})
