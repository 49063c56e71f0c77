"""XL-320s on the Protocol 2.0 bus: their own classic table run by the X-series firmware, in virtual time.

Everything is measured as a client measures it, through the served registers (Present Position,
Present Load, Hardware Error Status ...), except the load on the horn, which is the world's: the
firmware model's external torque, as a dynamometer applies it.  Data sheet (e-manual, XL-320,
"Specifications", in ``ax12emu/protocol/models/xl-320.toml``): stall torque 0.39 N m and no-load
speed 114 rpm at 7.4 V.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock
from ax12emu.protocol.packets2 import ALERT_BIT, ErrorNumber, Instruction2, decode_packet2, encode_instruction2
from ax12emu.protocol.servo_models import model
from ax12emu.servo.model_factory2 import XModelChoice, build_x_firmware
from firmware_model.xseries.interface import HW_ERROR_OVERLOAD

SPEC = model("xl-320")
SHEET = SPEC.physical.rating_at(7.4)
# Addresses (e-manual, XL-320 "Control Table")
CW_ANGLE_LIMIT, CONTROL_MODE, MAX_TORQUE, TORQUE_ENABLE, LED, P_GAIN = 6, 11, 15, 24, 25, 29
GOAL_POSITION, MOVING_SPEED, TORQUE_LIMIT, PRESENT_POSITION, PRESENT_SPEED, PRESENT_LOAD = 30, 32, 35, 37, 39, 41
MOVING, HARDWARE_ERROR_STATUS = 49, 50
DEG_PER_UNIT = 300.0 / 1024.0
CW = 1 << 10
#: A data-sheet figure within 5 %: the sheet's own rounding (two digits) and the model's derivation (see
#: tests/firmware_model/test_datasheets_all_models.py, which measures the same tolerance on the physics alone).
TOLERANCE = 0.05


def xl320_bus(count: int = 1, *, external_torques_nm=None, voltage_v: float | None = None) -> Bus2:
    torques = [0.0] * count if external_torques_nm is None else list(external_torques_nm)
    return Bus2([(i + 1, SPEC) for i in range(count)],
                lambda spec, index: build_x_firmware(spec, XModelChoice(voltage_v=voltage_v, external_torque_nm=torques[index])),
                clock=VirtualClock())


def request(bus: Bus2, servo_id: int, instruction: int, params: bytes = b""):
    replies = bus.receive(encode_instruction2(servo_id, instruction, params))
    return [decode_packet2(reply.data) for reply in replies]


def write(bus: Bus2, servo_id: int, address: int, value: int, size: int = 1) -> int:
    """A WRITE; returns the status packet's error byte (broadcast: no answer, None)."""
    replies = request(bus, servo_id, Instruction2.WRITE, address.to_bytes(2, "little") + value.to_bytes(size, "little"))
    return replies[0].error if replies else None


def read(bus: Bus2, servo_id: int, address: int, size: int = 2) -> int:
    (reply,) = request(bus, servo_id, Instruction2.READ, address.to_bytes(2, "little") + size.to_bytes(2, "little"))
    assert reply.error & ~ALERT_BIT == ErrorNumber.NONE
    return int.from_bytes(reply.params, "little")


def run(bus: Bus2, seconds: float) -> None:
    bus.clock.advance(seconds)
    bus.advance()


def positions(bus: Bus2, seconds: float, servo_id: int = 1) -> list[tuple[float, int]]:
    """(time, Present Position) each millisecond for ``seconds``."""
    out = []
    for _ in range(int(round(seconds * 1000))):
        run(bus, 1e-3)
        out.append((bus.clock.now_s(), read(bus, servo_id, PRESENT_POSITION)))
    return out


def rpm(samples: list[tuple[float, int]], low: int = 300, high: int = 700) -> float:
    """Mean speed over one pass between ``low`` and ``high`` (rpm; negative clockwise)."""
    inside = [i for i, (_, p) in enumerate(samples) if low <= p <= high]
    first = inside[0]
    last = first
    while last + 1 < len(samples) and low <= samples[last + 1][1] <= high:
        last += 1
    (t0, p0), (t1, p1) = samples[first], samples[last]
    assert t1 - t0 > 0.05, "the pass must be long enough to measure"
    return (p1 - p0) * DEG_PER_UNIT / (t1 - t0) / 6.0


def wheel(bus: Bus2, moving_speed: int, servo_id: int = 254) -> None:
    """Wheel mode (Control Mode 1, written with the torque off: an EEPROM register), torque on, Moving Speed."""
    write(bus, servo_id, CONTROL_MODE, 1)
    write(bus, servo_id, TORQUE_ENABLE, 1)
    write(bus, servo_id, MOVING_SPEED, moving_speed, 2)


# -- data sheet ---------------------------------------------------------------------------------
def test_no_load_speed_at_full_output_is_the_data_sheets():
    """Wheel mode at Moving Speed 1023 (100 % output), no load: 114 rpm at 7.4 V, from Present Position over time."""
    bus = xl320_bus(voltage_v=SHEET.voltage_v)
    wheel(bus, 1023)
    run(bus, 0.5)  # up to speed
    measured = rpm(positions(bus, 0.6))
    assert measured == pytest.approx(SHEET.no_load_speed_rpm, rel=TOLERANCE)


def test_stall_torque_at_full_output_is_the_data_sheets():
    """The smallest opposing torque (0.85 .. 1.15 x 0.39 N m, 1 % steps) under which a fully driven shaft makes no
    progress: Present Position does not rise over 0.3 s, and Present Load reads full scale, 1023."""
    loads_nm = SHEET.stall_torque_nm * np.linspace(0.85, 1.15, 31)
    bus = xl320_bus(len(loads_nm), external_torques_nm=-loads_nm, voltage_v=SHEET.voltage_v)
    write(bus, 254, TORQUE_ENABLE, 1)
    write(bus, 254, GOAL_POSITION, 1023, 2)  # far ahead: the loop's output is saturated, 100 %
    run(bus, 0.3)
    start = [read(bus, i, PRESENT_POSITION) for i in range(1, len(loads_nm) + 1)]
    run(bus, 0.3)
    end = [read(bus, i, PRESENT_POSITION) for i in range(1, len(loads_nm) + 1)]
    held = [after <= before for before, after in zip(start, end)]
    assert held[-1] and not held[0], "the grid must bracket the stall torque"
    stall_nm = loads_nm[held.index(True)]
    assert stall_nm == pytest.approx(SHEET.stall_torque_nm, rel=TOLERANCE)
    held_id = held.index(True) + 1
    assert read(bus, held_id, PRESENT_LOAD) == pytest.approx(1023, abs=15)  # CCW, the stall current: full scale


# -- joint mode ---------------------------------------------------------------------------------
def test_a_goal_position_write_turns_the_shaft_to_that_angle():
    """Goal 812 from 512: 300 units x 300/1024 deg = 87.9 deg, the shaft's own angle and Present Position agree.

    The P-only loop (P Gain 32: Kp = 4, full output at 256 units) holds the shaft short of the goal by
    what Coulomb friction takes; a stiffer gain holds it closer (the e-manual: "The less the P gain,
    The larger the back lash").
    """
    soft, stiff = xl320_bus(), xl320_bus()
    write(stiff, 1, P_GAIN, 128)
    errors = []
    for bus in (soft, stiff):
        angle0 = bus.servos[0].plant.firmware.physics.angle_rad
        assert read(bus, 1, PRESENT_POSITION) == 512
        assert write(bus, 1, TORQUE_ENABLE, 1) == ErrorNumber.NONE
        assert write(bus, 1, GOAL_POSITION, 812, 2) == ErrorNumber.NONE
        assert read(bus, 1, MOVING, 1) == 1
        run(bus, 1.5)
        present = read(bus, 1, PRESENT_POSITION)
        turned_deg = math.degrees(bus.servos[0].plant.firmware.physics.angle_rad - angle0)
        assert turned_deg == pytest.approx((present - 512) * DEG_PER_UNIT, abs=DEG_PER_UNIT)
        assert read(bus, 1, MOVING, 1) == 0
        errors.append(812 - present)
    assert 0 <= errors[0] <= 6, errors  # within 1.8 deg
    assert 0 <= errors[1] < errors[0], errors


def test_moving_speed_sets_the_speed_of_the_move():
    """Moving Speed 300 (x 0.111 rpm = 33.3 rpm) from 100 to 900; 0 moves as fast as the motor can."""
    bus = xl320_bus()
    write(bus, 1, TORQUE_ENABLE, 1)
    write(bus, 1, GOAL_POSITION, 100, 2)
    run(bus, 2.0)
    write(bus, 1, MOVING_SPEED, 300, 2)
    write(bus, 1, GOAL_POSITION, 900, 2)
    assert rpm(positions(bus, 1.5)) == pytest.approx(300 * 0.111, rel=0.03)
    write(bus, 1, MOVING_SPEED, 0, 2)
    write(bus, 1, GOAL_POSITION, 100, 2)
    assert rpm(positions(bus, 1.0)) < -0.8 * SHEET.no_load_speed_rpm


def test_a_goal_beyond_the_angle_limits_is_refused_and_a_goal_left_outside_is_held_inside():
    """CW/CCW Angle Limit are "the minimum/maximum value of Goal Position(30)": a goal beyond them is refused with
    Data Limit Error (Protocol 2.0's counterpart of the page's Angle Limit Error bit) and not written; in wheel mode
    the goal is not used and not judged; a goal written before the limit moved is held inside it."""
    bus = xl320_bus()
    assert write(bus, 1, GOAL_POSITION, 100, 2) == ErrorNumber.NONE
    assert write(bus, 1, CW_ANGLE_LIMIT, 400, 2) == ErrorNumber.NONE  # EEPROM: with the torque off
    assert write(bus, 1, GOAL_POSITION, 399, 2) == ErrorNumber.DATA_LIMIT
    assert read(bus, 1, GOAL_POSITION) == 100
    write(bus, 1, TORQUE_ENABLE, 1)
    run(bus, 1.5)
    assert 400 <= read(bus, 1, PRESENT_POSITION) <= 410
    write(bus, 1, TORQUE_ENABLE, 0)
    write(bus, 1, CONTROL_MODE, 1)
    assert write(bus, 1, GOAL_POSITION, 50, 2) == ErrorNumber.NONE


# -- wheel mode ---------------------------------------------------------------------------------
def test_wheel_mode_turns_at_the_moving_speed_share_of_the_output_and_bit_10_reverses():
    """Moving Speed 512 is 50 % output (e-manual: "if it is set to 512, it means the output is controlled by 50%"):
    about half the speed of 1023 at no load; 1024 + 512 the same clockwise; 1024 stops."""
    speeds = {}
    for setting in (1023, 512, CW | 512):
        bus = xl320_bus()
        wheel(bus, setting)
        run(bus, 0.5)
        speeds[setting] = rpm(positions(bus, 0.6))
        if setting == CW | 512:
            assert read(bus, 1, PRESENT_SPEED) == CW | 512  # wheel mode: the output share, "about 0.1%"
            write(bus, 1, MOVING_SPEED, CW, 2)
            run(bus, 0.5)
            still = read(bus, 1, PRESENT_POSITION)
            run(bus, 0.2)
            assert read(bus, 1, PRESENT_POSITION) == still
    assert speeds[512] / speeds[1023] == pytest.approx(0.5, abs=0.03)
    assert speeds[CW | 512] == pytest.approx(-speeds[512], rel=0.01)


# -- torque limit and load ----------------------------------------------------------------------
def test_torque_limit_bounds_the_torque():
    """Torque Limit 512 (50 %): a load of 0.25 N m that the full limit overcomes pushes the shaft back; on a blocked
    shaft Present Load reads about 50 % and the torque at the horn is half the full limit's."""
    bus = xl320_bus(4, external_torques_nm=[-0.25, -0.25, 0.0, 0.0])
    for servo in bus.servos[2:]:
        servo.plant.firmware.set_blocked(True)
    write(bus, 2, TORQUE_LIMIT, 512, 2)
    write(bus, 3, TORQUE_LIMIT, 512, 2)
    write(bus, 254, TORQUE_ENABLE, 1)
    write(bus, 254, GOAL_POSITION, 1000, 2)
    run(bus, 0.2)
    full, half = read(bus, 1, PRESENT_POSITION), read(bus, 2, PRESENT_POSITION)
    run(bus, 0.2)
    assert read(bus, 1, PRESENT_POSITION) > full + 20  # the full limit drives on
    assert read(bus, 2, PRESENT_POSITION) < half  # half of it gives way
    assert read(bus, 3, PRESENT_LOAD) == pytest.approx(512, abs=15)
    assert read(bus, 4, PRESENT_LOAD) == pytest.approx(1023, abs=15)
    torque_half, torque_full = (servo.plant.firmware.physics.motor_torque_nm for servo in bus.servos[2:])
    assert torque_half / torque_full == pytest.approx(512 / 1023, rel=0.02)


def test_present_load_direction_bit_follows_the_torque():
    """Holding against a clockwise load the motor pushes CCW (bit 10 clear); against a CCW load, CW (bit 10 set)."""
    bus = xl320_bus(2, external_torques_nm=[-0.1, 0.1])
    write(bus, 254, TORQUE_ENABLE, 1)
    run(bus, 1.0)
    ccw, cw = read(bus, 1, PRESENT_LOAD), read(bus, 2, PRESENT_LOAD)
    assert 0 < ccw < CW and cw > CW
    assert ccw == pytest.approx(cw - CW, abs=5)


def test_torque_limit_starts_at_max_torque_after_a_reboot():
    """"When the power is turned on, Torque Limit(35) is reset to the value of Max Torque(15)" (e-manual)."""
    bus = xl320_bus()
    assert read(bus, 1, TORQUE_LIMIT) == 1023
    assert write(bus, 1, MAX_TORQUE, 600, 2) == ErrorNumber.NONE
    assert request(bus, 1, Instruction2.REBOOT)[0].error == ErrorNumber.NONE
    assert read(bus, 1, TORQUE_LIMIT) == 600


# -- the table's rules --------------------------------------------------------------------------
def test_the_eeprom_area_is_locked_while_the_torque_is_on():
    """e-manual, control table (XL-320): "Data in the EEPROM Area can only be written to if Torque Enable(24) is
    cleared to '0'(Torque OFF)": Access Error, then accepted with the torque off."""
    bus = xl320_bus()
    write(bus, 1, TORQUE_ENABLE, 1)
    assert write(bus, 1, CW_ANGLE_LIMIT, 100, 2) == ErrorNumber.ACCESS
    assert write(bus, 1, CONTROL_MODE, 1) == ErrorNumber.ACCESS
    assert write(bus, 1, TORQUE_ENABLE, 0) == ErrorNumber.NONE
    assert write(bus, 1, CW_ANGLE_LIMIT, 100, 2) == ErrorNumber.NONE
    assert read(bus, 1, CW_ANGLE_LIMIT) == 100


@pytest.mark.parametrize(("address", "value", "size"), [
    (GOAL_POSITION, 1024, 2), (MOVING_SPEED, 1024, 2), (MOVING_SPEED, 2048, 2), (TORQUE_LIMIT, 1024, 2),
    (LED, 8, 1), (P_GAIN, 255, 1), (CONTROL_MODE, 0, 1), (CONTROL_MODE, 3, 1), (CW_ANGLE_LIMIT, 1024, 2),
])
def test_out_of_range_writes_get_data_range_error(address, value, size):
    """The page's Min/Max for each register (Moving Speed: 0 ~ 1,023 in joint mode, the default)."""
    bus = xl320_bus()
    before = read(bus, 1, address, size)
    assert write(bus, 1, address, value, size) == ErrorNumber.DATA_RANGE
    assert read(bus, 1, address, size) == before


def test_led_takes_its_eight_colours_and_wheel_mode_takes_the_direction_bit():
    bus = xl320_bus()
    for colour in range(8):  # off, red, green, yellow, blue, purple, cyan, white
        assert write(bus, 1, LED, colour) == ErrorNumber.NONE and read(bus, 1, LED, 1) == colour
    write(bus, 1, CONTROL_MODE, 1)
    assert write(bus, 1, MOVING_SPEED, 2047, 2) == ErrorNumber.NONE


def test_an_overload_shows_in_hardware_error_status_in_the_xl320s_bits_and_turns_the_torque_off():
    """Shutdown(18) 3 (its initial value) selects Overload (bit 0) and OverHeating (bit 1); the firmware's overload
    reads bit 0 in Hardware Error Status(50), the status packets carry the Alert bit, the torque goes off."""
    bus = xl320_bus()
    write(bus, 1, TORQUE_ENABLE, 1)
    assert bus.servos[0].plant.firmware.raise_error(HW_ERROR_OVERLOAD) == HW_ERROR_OVERLOAD
    run(bus, 0.01)
    (reply,) = request(bus, 1, Instruction2.READ, HARDWARE_ERROR_STATUS.to_bytes(2, "little") + (1).to_bytes(2, "little"))
    assert reply.error == ALERT_BIT and reply.params == bytes([0x01])
    assert read(bus, 1, TORQUE_ENABLE, 1) == 0


def test_a_stalled_shaft_trips_the_overload_protection():
    """A blocked shaft at full output (the firmware's overload: held at its limit for its overload time)."""
    bus = xl320_bus()
    bus.servos[0].plant.firmware.set_blocked(True)
    write(bus, 1, TORQUE_ENABLE, 1)
    write(bus, 1, GOAL_POSITION, 1000, 2)
    run(bus, 0.2)
    assert read(bus, 1, PRESENT_LOAD) == pytest.approx(1023, abs=15)
    run(bus, 2.0)
    assert read(bus, 1, HARDWARE_ERROR_STATUS, 1) == 0x01 and read(bus, 1, TORQUE_ENABLE, 1) == 0


def test_the_eeprom_area_persists_and_torque_limit_starts_from_the_saved_max_torque(tmp_path):
    """A state store keeps the XL-320's EEPROM (CW Angle Limit, Max Torque); the next power-up starts Torque Limit
    at the saved Max Torque."""
    from ax12emu.bus.state_store import StateStore

    def bus():
        return Bus2([(1, SPEC)], lambda spec, index: build_x_firmware(spec), clock=VirtualClock(), state_store=StateStore(tmp_path))

    with bus() as first:
        assert write(first, 1, CW_ANGLE_LIMIT, 300, 2) == ErrorNumber.NONE
        assert write(first, 1, MAX_TORQUE, 700, 2) == ErrorNumber.NONE
    with bus() as second:
        assert (read(second, 1, CW_ANGLE_LIMIT), read(second, 1, MAX_TORQUE), read(second, 1, TORQUE_LIMIT)) == (300, 700, 700)
