"""The snapshot and the sampler on Protocol 2.0 and mixed buses, in virtual time.

Each servo is shown by its own table's register names and its readings in the units its model
file (and the e-manual, per register) gives; the packet log decodes 2.0 and mixed traffic.
"""

from __future__ import annotations

import pytest
from dynamixel_sdk import COMM_SUCCESS, PacketHandler
from emu_testkit import UrlPortHandler

from ax12emu import VirtualBus
from ax12emu.live import ByteTap, Sampler
from ax12emu.live.buses import decoder_options
from ax12emu.live.snapshot import REGISTER_UNITS, take
from ax12emu.protocol.packets import Instruction, InstructionPacket
from ax12emu.protocol.packets2 import Instruction2, InstructionPacket2, encode_status2
from ax12emu.protocol.servo_models import model
from ax12emu.tracing.trace import IN, OUT

BAUD = 1_000_000


def readings(servo: dict) -> dict[str, dict]:
    return {reading["name"]: reading for reading in servo["readings"]}


def sampler_of(bus: VirtualBus, **options) -> Sampler:
    return Sampler(bus.call, **bus.call(decoder_options), **options)


def test_x_series_servos_show_their_own_registers_and_units():
    with VirtualBus(servo="1:xl430-w250,2:xl330-m288", transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "torque_enable", 1)
        bus.write(1, "goal_position", 3000)
        bus.step(0.2)  # mid-move: velocity and load are not zero
        frame = sampler_of(bus).sample()
        table = bus.table(1)
    assert frame["protocols"] == ["2.0"] and frame["virtual_time"]
    xl430, xl330 = frame["servos"]
    assert (xl430["model"], xl430["protocol"], xl430["id"]) == ("XL430-W250", "2.0", 1)
    assert xl330["model"] == "XL330-M288"
    assert xl430["registers"]["goal_position"] == 3000 and xl430["registers"]["present_position"] == table["present_position"]
    assert "cw_angle_limit" not in xl430["registers"] and xl430["registers"]["operating_mode"] == 3
    one = readings(xl430)
    resolution_deg = 360 / 4096  # e-manual X series: 0.088 deg a count, 4096 a turn
    assert one["position"]["raw"] == table["present_position"]
    assert one["position"]["value"] == pytest.approx(table["present_position"] * resolution_deg, abs=1e-3)
    assert one["goal"]["value"] == pytest.approx(3000 * resolution_deg, abs=1e-3)
    assert one["velocity"]["register"] == "present_velocity" and one["velocity"]["unit"] == "rpm"
    assert one["velocity"]["raw"] == table["present_velocity"] > 0  # moving CCW towards 3000
    assert one["velocity"]["value"] == pytest.approx(table["present_velocity"] * REGISTER_UNITS["present_velocity"].per_raw, abs=1e-3)
    assert one["pwm"]["raw"] == table["present_pwm"] and one["pwm"]["unit"] == "%"
    assert one["voltage"]["value"] == pytest.approx(table["present_input_voltage"] / 10)
    # The XL430 senses no current (its register 126 is Present Load); the XL330 does, in its model's unit.
    assert "current" not in one and one["load"]["register"] == "present_load"
    two = readings(xl330)
    assert "load" not in two and two["current"]["unit"] == "mA" and two["current"]["register"] == "present_current"
    assert xl430["mode"] == "position" and xl430["limits"] == [table["min_position_limit"], table["max_position_limit"]]
    assert xl430["dial"] == {"max": 4095, "range_deg": model("xl430-w250").physical.position_range_deg, "counts": 4096}
    assert xl430["registers"]["torque_enable"] == 1 and xl430["registers"]["moving"] == 1
    assert xl430["alarm_bits"] == ["input_voltage", "overheating", "motor_encoder", "electrical_shock", "overload"]


def test_operating_mode_and_hardware_errors_follow_the_servo():
    with VirtualBus(servo="1-2:xl430-w250", transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "operating_mode", 1)  # velocity: the position limits do not bound anything
        bus.faults.force_alarm(2, "overload")  # latched in Hardware Error Status, torque off
        bus.faults.vanish(1)
        frame = sampler_of(bus).sample()
    one, two = frame["servos"]
    assert one["mode"] == "velocity" and one["limits"] is None and one["wheel_mode"]
    assert one["faults"] == ["vanished"]
    assert two["alarms"] == two["registers"]["hardware_error_status"] == 0x20
    assert two["alarm_names"] == ["overload"] and "alarm 0x20" in two["faults"]


def test_a_mixed_wire_shows_both_protocols_with_one_id_each():
    with VirtualBus(servo="1:ax-12a,1-2:xl430-w250", transport="inprocess", virtual_time=True, baud_bps=BAUD) as bus:
        bus.faults.vanish(1, protocol=2.0)
        bus.set_temperature(1, 80, protocol=1.0)
        frame = sampler_of(bus).sample()
    assert frame["protocols"] == ["1.0", "2.0"]
    ax, x1, x2 = frame["servos"]
    assert [(s["protocol"], s["id"], s["model"]) for s in frame["servos"]] == [("1.0", 1, "AX-12A"), ("2.0", 1, "XL430-W250"), ("2.0", 2, "XL430-W250")]
    assert readings(ax)["velocity"]["register"] == "present_speed" and readings(ax)["position"]["value"] == pytest.approx(
        ax["registers"]["present_position"] * 300 / 1023, abs=1e-3  # 0..1023 over 300 degrees (0.29 is rounded)
    )
    assert ax["mode"] == "joint" and ax["limits"] == [0, 1023]
    assert ax["faults"] == ["present_temperature held at 80"] and readings(ax)["temperature"]["raw"] == 80
    assert x1["faults"] == ["vanished"] and x2["faults"] == []
    assert set(frame["alarm_choices"]) == {"1.0", "2.0"} and "electrical_shock" in frame["alarm_choices"]["2.0"]
    assert "electrical_shock" not in frame["alarm_choices"]["1.0"]


def test_an_ax12_speed_register_reads_its_direction_bit_as_a_sign():
    with VirtualBus([1], transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "torque_enable", 1)
        bus.write(1, "goal_position", 100)  # CW
        bus.step(0.1)
        raw = bus.read(1, "present_speed")
        frame = take(bus.bus)
    assert raw & 0x400
    assert readings(frame["servos"][0])["velocity"]["raw"] == -(raw & 0x3FF)


def test_the_log_decodes_protocol_2_traffic_and_counts_its_errors():
    with VirtualBus(servo="1:xl430-w250", transport="inprocess", virtual_time=True) as bus:
        tap = ByteTap()
        sampler = sampler_of(bus, tap=tap)
        read = InstructionPacket2(1, Instruction2.READ, bytes([132, 0, 4, 0])).encode()  # Present Position
        tap.record(IN, read, 1.0)
        tap.record(OUT, encode_status2(1, 0, bytes(4)), 1.001)
        tap.record(IN, read, 1.002)
        tap.record(OUT, encode_status2(1, 0x07, b""), 1.003)  # Access Error
        corrupt = bytearray(encode_status2(1, 0, bytes(4)))
        corrupt[-1] ^= 0xFF
        tap.record(IN, read, 1.004)
        tap.record(OUT, bytes(corrupt), 1.005)
        frame = sampler.sample()
    host = [line for line in frame["log"] if line["who"] == "host"]
    servo = [line for line in frame["log"] if line["who"] == "servo"]
    assert len(host) == 3 and all(line["ins"] == "READ" and line["id"] == 1 for line in host)
    assert "present_position" in host[0]["text"]  # named from the servo's model file
    assert len(servo) == 3 and all(line["ins"] == "READ" for line in servo)
    assert frame["stats"]["status_errors"] == 1 and frame["stats"]["checksum_errors"] == 1


def test_the_log_of_a_mixed_wire_decodes_both_protocols():
    with VirtualBus(servo="1:ax-12a,2:xl430-w250", transport="inprocess", virtual_time=True, baud_bps=BAUD) as bus:
        tap = ByteTap()
        sampler = sampler_of(bus, tap=tap)
        tap.record(IN, InstructionPacket(1, Instruction.PING, b"").encode(), 1.0)
        tap.record(IN, InstructionPacket2(2, Instruction2.PING).encode(), 1.01)
        frame = sampler.sample()
    pings = [(line["id"], line["ins"]) for line in frame["log"] if line["who"] == "host"]
    assert pings == [(1, "PING"), (2, "PING")]


def test_real_traffic_from_the_sdk_reaches_the_log():
    with VirtualBus(servo="3:xl430-w250", transport="inprocess", virtual_time=True, baud_bps=BAUD) as bus:
        link = bus._link
        tap = ByteTap(link.trace)
        link.trace = tap  # as the live view taps a served bus
        sampler = sampler_of(bus, tap=tap, counters=lambda: {"packets_in": link.packets_in})
        port = UrlPortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(BAUD)
        try:
            assert PacketHandler(2.0).ping(port, 3)[1] == COMM_SUCCESS
        finally:
            port.closePort()
        frame = sampler.sample()
    assert [line["ins"] for line in frame["log"] if line["who"] in ("host", "servo")] == ["PING", "PING"]
    assert frame["stats"]["packets"] == 1


def test_an_xl320_is_read_by_its_own_table_names_with_no_code_of_its_own():
    """The XL-320's 2.0 table has the AX-12's names (Present Speed with its direction bit, Control Mode for joint/wheel)."""
    with VirtualBus(servo="1:xl-320", transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "torque_enable", 1)
        bus.write(1, "goal_position", 100)  # CW
        bus.step(0.1)
        speed, voltage = bus.read(1, "present_speed"), bus.read(1, "present_voltage")
        joint = take(bus.bus)["servos"][0]
        bus.write(1, "torque_enable", 0)
        bus.write(1, "control_mode", 1)
        bus.write(1, "torque_enable", 1)
        bus.write(1, "moving_speed", 1024 + 500)  # wheel mode: half the output, CW
        bus.step(0.3)
        wheel_speed = bus.read(1, "present_speed")
        wheel = take(bus.bus)["servos"][0]
    assert joint["model"] == "XL-320" and joint["protocol"] == "2.0"
    assert joint["mode"] == "joint" and joint["limits"] == [0, 1023] and wheel["mode"] == "wheel" and wheel["limits"] is None
    one = readings(joint)
    assert speed & 0x400 and one["velocity"]["register"] == "present_speed" and one["velocity"]["raw"] == -(speed & 0x3FF)
    assert one["voltage"]["value"] == pytest.approx(voltage / 10)
    assert one["goal"]["value"] == pytest.approx(100 * 300 / 1023, abs=1e-3)
    assert joint["dial"] == {"max": 1023, "range_deg": model("xl-320").physical.position_range_deg, "counts": 1023}
    # In wheel mode its Present Speed is a share of the output ("the unit is about 0.1%", its model file's wheel_output).
    assert readings(wheel)["velocity"]["unit"] == "%" and readings(wheel)["velocity"]["raw"] == -(wheel_speed & 0x3FF)
    assert readings(wheel)["velocity"]["value"] == pytest.approx(-(wheel_speed & 0x3FF) * 0.1)
    # Its Hardware Error Status bits are its own (the file's [classic] errors), not the X series'.
    assert joint["alarm_bits"] == [name for name, _ in sorted(model("xl-320").classic.errors, key=lambda e: e[1])]


def test_an_mx_wire_shows_each_model_in_its_files_units_and_modes():
    """MX-28 (Protocol 1.0, its [classic] speed unit 0.114 rpm, multi-turn at both limits 4095) beside an AX-12A."""
    from ax12emu.bus import Bus
    from ax12emu.bus.bus1x import Bus1X
    from ax12emu.bus.clock import VirtualClock
    from ax12emu.live import ServedControls, apply
    from ax12emu.servo.plant1x import build_plant1x

    clock = VirtualClock()
    bus = Bus1X([(1, model("mx-28"))], lambda spec, servo: build_plant1x(spec, servo.table), ax_bus=Bus([2], clock=clock))
    bus.receive(InstructionPacket(1, Instruction.WRITE, bytes([6, 0xFF, 0x0F, 0xFF, 0x0F])).encode())  # both limits 4095
    controls = ServedControls(lambda fn: fn(bus))
    assert apply(controls, {"action": "external_torque", "id": 1, "nm": 0.5}) == "servo 1: external torque 0.5 N m"
    clock.advance(0.2)
    bus.advance()
    frame = take(bus)
    mx, ax = sorted(frame["servos"], key=lambda s: s["id"])
    assert (mx["model"], mx["protocol"], ax["model"]) == ("MX-28", "1.0", "AX-12A")
    assert mx["mode"] == "multi-turn" and mx["limits"] is None and ax["mode"] == "joint"
    speed = readings(mx)["velocity"]
    assert speed["register"] == "present_speed" and speed["raw"] > 0  # pushed CCW with the torque off
    assert speed["value"] == pytest.approx(speed["raw"] * model("mx-28").classic.speed_unit_rpm, abs=1e-3)
    assert readings(ax)["velocity"]["value"] == 0
    assert mx["alarm_bits"] == ax["alarm_bits"]  # both answer with Protocol 1.0 status error bits


def test_an_ax_12a_at_its_last_count_reads_the_end_of_its_dial():
    """Goal 1023 is 300 degrees, where the dial draws it (the data sheet's rounded 0.29 deg a count read 296.7)."""
    with VirtualBus([1], transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "goal_position", 1023)
        servo = take(bus.bus)["servos"][0]
    goal = next(r for r in servo["readings"] if r["name"] == "goal")
    assert goal["value"] == pytest.approx(300.0) and servo["dial"] == {"max": 1023, "range_deg": 300, "counts": 1023}


def test_x_series_degrees_take_4096_counts_a_turn_in_extended_position_mode():
    """e-manual X series Goal Position(116): 0.088 deg a count, 0..4095 a turn, -1,048,575..1,048,575 for -256..256
    turns: ten turns out (40960) is 3600 degrees; the AX-12A's 1023 stays 300 (its 0..1023 has two ends)."""
    with VirtualBus(servo="1:xl430-w250", transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "operating_mode", 4)  # extended position
        bus.write(1, "goal_position", 40960)
        goal = readings(take(bus.bus)["servos"][0])["goal"]
    assert goal["raw"] == 40960 and goal["value"] == pytest.approx(3600.0)
    assert readings(take_ax12_at(1023))["goal"]["value"] == pytest.approx(300.0)


def take_ax12_at(goal: int) -> dict:
    with VirtualBus([1], transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "goal_position", goal)
        return take(bus.bus)["servos"][0]


def test_the_rate_a_servo_listens_at_is_shown_after_a_baud_rate_write():
    """A Baud Rate write takes the servo off the host's rate (it falls silent): the view says the rate it is at."""
    with VirtualBus(servo="1:ax-12a,1:xl430-w250", transport="inprocess", virtual_time=True, baud_bps=BAUD) as bus:
        before = {servo["protocol"]: servo for servo in take(bus.bus)["servos"]}
        bus.write(1, "baud_rate", 34, protocol=1.0)  # e-manual AX-12A: 2,000,000 / (34 + 1) bps
        bus.write(1, "baud_rate", 1, protocol=2.0)
        after = {servo["protocol"]: servo for servo in take(bus.bus)["servos"]}
    assert before["1.0"]["baud_bps"] == BAUD and before["2.0"]["baud_bps"] == BAUD
    assert after["1.0"]["registers"]["baud_rate"] == 34 and after["1.0"]["baud_bps"] == pytest.approx(2_000_000 / 35)
    assert after["2.0"]["registers"]["baud_rate"] == 1 and after["2.0"]["baud_bps"] == 57_600  # X series: 1 is 57,600 bps
