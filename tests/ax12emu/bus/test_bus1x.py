"""MX-series servos on a Protocol 1.0 wire (bus1x): data-sheet physics, modes and Bulk Read, in virtual time, through the registers."""

from __future__ import annotations

import pytest

from ax12emu.bus.bus import Bus
from ax12emu.bus.bus1x import Bus1X
from ax12emu.bus.clock import VirtualClock
from ax12emu.protocol.framing import Framer
from ax12emu.protocol.packets import BROADCAST_ID, Instruction, StatusError, encode_instruction
from ax12emu.protocol.servo_models import model
from ax12emu.servo.model_factory2 import XModelChoice
from ax12emu.servo.plant1x import build_plant1x

MX_MODELS = ("mx-28", "mx-64", "mx-106")
#: Addresses of the MX tables (e-manual, MX-28 Protocol 1.0).
CW_LIMIT, CCW_LIMIT, MULTI_TURN_OFFSET, RESOLUTION_DIVIDER = 6, 8, 20, 22
TORQUE_ENABLE, GOAL_POSITION, MOVING_SPEED, TORQUE_LIMIT = 24, 30, 32, 34
PRESENT_POSITION, PRESENT_SPEED, PRESENT_LOAD, GOAL_ACCELERATION = 36, 38, 40, 73
CURRENT, TORQUE_CONTROL, GOAL_TORQUE = 68, 70, 71
#: Moving Speed / Present Speed: "the unit is about 0.114rpm".
RPM_PER_SPEED_UNIT = 0.114
PULSES_PER_REV = 4096
TOLERANCE = 0.07


def mx_bus(keys, voltage_v: float | None = 12.0, ids=None) -> Bus1X:
    ids = ids or list(range(1, len(keys) + 1))
    choice = XModelChoice(voltage_v=voltage_v)
    return Bus1X([(i, model(k)) for i, k in zip(ids, keys)], lambda spec, servo: build_plant1x(spec, servo.table, choice),
                 clock=VirtualClock())


def write(bus, servo_id: int, address: int, *values: int) -> int:
    """A WRITE; the status packet's error byte (None for a broadcast)."""
    replies = bus.receive(encode_instruction(servo_id, Instruction.WRITE, bytes([address, *values])))
    return replies[0].data[4] if replies else None


def write2(bus, servo_id: int, address: int, value: int) -> int:
    return write(bus, servo_id, address, value & 0xFF, (value >> 8) & 0xFF)


def read2(bus, servo_id: int, address: int) -> int:
    reply = bus.receive(encode_instruction(servo_id, Instruction.READ, bytes([address, 2])))[0].data
    assert reply[4] & ~0x25 == 0, f"error byte {reply[4]:#x}"
    return reply[5] | reply[6] << 8


def run_s(bus, seconds: float, every_s: float = 0.001):
    for _ in range(int(round(seconds / every_s))):
        bus.clock.advance(every_s)
        bus.advance()


def directional(raw: int) -> int:
    """A register with the direction bit (bit 10 set: CW) as a signed value."""
    return -(raw & 0x3FF) if raw & 0x400 else raw & 0x3FF


@pytest.mark.parametrize("key", MX_MODELS)
def test_no_load_speed_at_12_v_is_the_data_sheets(key):
    """Wheel mode at Moving Speed 1023 (116 rpm, above every MX's no-load speed): the shaft runs at the sheet's no-load speed."""
    bus = mx_bus([key])
    assert write2(bus, 1, CCW_LIMIT, 0) == 0 and write2(bus, 1, CW_LIMIT, 0) == 0  # wheel mode
    assert write(bus, 1, TORQUE_ENABLE, 1) == 0
    assert write2(bus, 1, MOVING_SPEED, 1023) == 0
    run_s(bus, 1.0)
    speed_rpm = directional(read2(bus, 1, PRESENT_SPEED)) * RPM_PER_SPEED_UNIT
    # Present Position over one second, unwrapped: the same speed measured by the encoder.
    turns, last = 0, read2(bus, 1, PRESENT_POSITION)
    start = last
    for _ in range(100):
        run_s(bus, 0.01)
        now = read2(bus, 1, PRESENT_POSITION)
        turns += now < last
        last = now
    position_rpm = (turns * PULSES_PER_REV + last - start) / PULSES_PER_REV * 60.0
    sheet = model(key).physical.rating_at(12.0).no_load_speed_rpm
    assert speed_rpm == pytest.approx(sheet, rel=TOLERANCE)
    assert position_rpm == pytest.approx(sheet, rel=TOLERANCE)


def creeps_forward(key: str, load_nm: float) -> bool:
    """Full output CCW (wheel mode) against ``load_nm`` CW: whether Present Position still rises."""
    bus = mx_bus([key])
    write2(bus, 1, CCW_LIMIT, 0)
    write2(bus, 1, CW_LIMIT, 0)
    bus.servo(1).plant.firmware.set_external_torque(-load_nm)
    write(bus, 1, TORQUE_ENABLE, 1)
    write2(bus, 1, MOVING_SPEED, 1023)
    run_s(bus, 0.05)
    before = read2(bus, 1, PRESENT_POSITION)
    run_s(bus, 0.4, every_s=0.05)
    after = read2(bus, 1, PRESENT_POSITION)
    return (after - before) % PULSES_PER_REV not in (0,) and (after - before) % PULSES_PER_REV < PULSES_PER_REV // 2


@pytest.mark.parametrize("key", MX_MODELS)
def test_stall_torque_at_12_v_is_the_data_sheets(key):
    """Bisection on an opposing torque: below the stall torque the fully driven shaft still turns forward, above it not."""
    sheet = model(key).physical.rating_at(12.0).stall_torque_nm
    low, high = 0.5 * sheet, 1.5 * sheet
    assert creeps_forward(key, low) and not creeps_forward(key, high)
    while high - low > 0.01 * sheet:
        middle = 0.5 * (low + high)
        if creeps_forward(key, middle):
            low = middle
        else:
            high = middle
    assert 0.5 * (low + high) == pytest.approx(sheet, rel=TOLERANCE)


def test_joint_mode_moves_to_the_goal_and_holds_with_present_load_and_speed_directions():
    bus = mx_bus(["mx-64"])
    assert read2(bus, 1, PRESENT_POSITION) == 2048
    assert write2(bus, 1, GOAL_POSITION, 3072) == 0  # torque on by the goal write
    run_s(bus, 0.1)
    assert directional(read2(bus, 1, PRESENT_SPEED)) > 0  # CCW, toward higher positions
    assert directional(read2(bus, 1, PRESENT_LOAD)) > 0
    run_s(bus, 1.5)
    assert abs(read2(bus, 1, PRESENT_POSITION) - 3072) <= 8
    assert write2(bus, 1, GOAL_POSITION, 1024) == 0
    run_s(bus, 0.1)
    assert directional(read2(bus, 1, PRESENT_SPEED)) < 0  # CW: bit 10 set
    assert read2(bus, 1, PRESENT_SPEED) & 0x400


def test_moving_speed_limits_the_speed_to_the_goal():
    bus = mx_bus(["mx-28"])
    write2(bus, 1, MOVING_SPEED, 100)  # 11.4 rpm
    write2(bus, 1, GOAL_POSITION, 4000)
    run_s(bus, 0.5)
    p0 = read2(bus, 1, PRESENT_POSITION)
    run_s(bus, 1.0)
    rpm = (read2(bus, 1, PRESENT_POSITION) - p0) / PULSES_PER_REV * 60.0
    assert rpm == pytest.approx(100 * RPM_PER_SPEED_UNIT, rel=0.05)


def test_goal_acceleration_shapes_the_start_of_a_move():
    """Goal Acceleration 10: "the present speed of Dynamixel is 0, and Goal Acceleration is 10. The speed of
    Dynamixel after 1 second will be 14.3 RPM" (e-manual): Present Speed climbs at 14.3 rpm/s (the shaft
    follows the ramp a few tens of ms behind, the P-only default gains' lag), where an unshaped move is at full speed at once."""
    shaped, free = mx_bus(["mx-28"]), mx_bus(["mx-28"])
    assert write(shaped, 1, GOAL_ACCELERATION, 10) == 0
    for bus in (shaped, free):
        write2(bus, 1, GOAL_POSITION, 4000)
    run_s(shaped, 0.6)
    rpm_early = directional(read2(shaped, 1, PRESENT_SPEED)) * RPM_PER_SPEED_UNIT
    run_s(shaped, 0.6)
    rpm_late = directional(read2(shaped, 1, PRESENT_SPEED)) * RPM_PER_SPEED_UNIT
    assert (rpm_late - rpm_early) / 0.6 == pytest.approx(10 * 8.583 / 6.0, rel=0.10)  # deg/s^2 to rpm/s: / 6
    run_s(free, 0.3)
    assert directional(read2(free, 1, PRESENT_SPEED)) * RPM_PER_SPEED_UNIT > 0.8 * model("mx-28").physical.rating_at(12.0).no_load_speed_rpm


def test_wheel_mode_turns_both_ways_at_moving_speed():
    bus = mx_bus(["mx-106"])
    write2(bus, 1, CW_LIMIT, 0)
    write2(bus, 1, CCW_LIMIT, 0)
    assert write2(bus, 1, GOAL_POSITION, 100) == 0  # "If it is set to Wheel Mode, Goal Position value is not used": no Angle Limit Error
    write(bus, 1, TORQUE_ENABLE, 1)
    write2(bus, 1, MOVING_SPEED, 200)  # 22.8 rpm CCW
    run_s(bus, 1.0)
    assert directional(read2(bus, 1, PRESENT_SPEED)) == pytest.approx(200, rel=0.05)
    write2(bus, 1, MOVING_SPEED, 1024 + 300)  # 34.2 rpm CW
    run_s(bus, 1.0)
    assert directional(read2(bus, 1, PRESENT_SPEED)) == pytest.approx(-300, rel=0.05)
    assert 0 <= read2(bus, 1, PRESENT_POSITION) < PULSES_PER_REV


def test_multi_turn_mode_takes_goals_over_several_turns_with_offset_and_divider():
    bus = mx_bus(["mx-64"])
    write2(bus, 1, CW_LIMIT, 4095)
    write2(bus, 1, CCW_LIMIT, 4095)
    assert write2(bus, 1, GOAL_POSITION, 2048 + 3 * 4096) == 0  # three turns on
    run_s(bus, 4.0)
    assert abs(read2(bus, 1, PRESENT_POSITION) - (2048 + 3 * 4096)) <= 8
    assert write2(bus, 1, GOAL_POSITION, -4096 & 0xFFFF) == 0  # negative: two's complement
    run_s(bus, 6.0)
    present = read2(bus, 1, PRESENT_POSITION)
    assert abs((present - 0x10000 if present & 0x8000 else present) + 4096) <= 8
    assert write2(bus, 1, GOAL_POSITION, 28673) == StatusError.RANGE  # beyond -28,672..28,672
    # Resolution Divider 2 and Multi Turn Offset 1000: Present Position = Real / 2 + 1000.
    write(bus, 1, TORQUE_ENABLE, 0)
    real = -4096
    assert write(bus, 1, RESOLUTION_DIVIDER, 2) == 0
    assert write2(bus, 1, MULTI_TURN_OFFSET, 1000) == 0
    run_s(bus, 0.01)
    present = read2(bus, 1, PRESENT_POSITION)
    assert abs((present - 0x10000 if present & 0x8000 else present) - (real // 2 + 1000)) <= 4


def test_torque_control_mode_drives_the_goal_torque_current_on_mx64():
    bus = mx_bus(["mx-64"])
    bus.servo(1).plant.firmware.physics.blocked = True  # a held shaft: the current is the torque loop's alone
    assert read2(bus, 1, CURRENT) == 2048  # "At an idle state without current flow, this value is 2,048"
    write(bus, 1, TORQUE_ENABLE, 1)
    assert write(bus, 1, TORQUE_CONTROL, 1) == 0
    assert write2(bus, 1, GOAL_TORQUE, 200) == 0  # 200 x 4.5 mA = 0.9 A CCW
    run_s(bus, 0.2)
    assert read2(bus, 1, CURRENT) - 2048 == pytest.approx(200, abs=6)
    write2(bus, 1, GOAL_TORQUE, 1024 + 100)  # 0.45 A CW
    run_s(bus, 0.2)
    assert read2(bus, 1, CURRENT) - 2048 == pytest.approx(-100, abs=6)


def test_bulk_read_answers_in_list_order_each_after_the_one_before():
    bus = mx_bus(["mx-28", "mx-64", "mx-106"])
    params = bytes([0x00, 2, 3, PRESENT_POSITION, 2, 1, 0, 1, 2, 3])  # ID 3 Present Position, ID 1 Model Number, ID 2 ID
    replies = bus.receive(encode_instruction(BROADCAST_ID, Instruction.BULK_READ, params))
    assert [r.servo_id for r in replies] == [3, 1, 2]
    assert replies[0].data[5:7] == (2048).to_bytes(2, "little")
    assert replies[1].data[5:7] == (29).to_bytes(2, "little")
    assert replies[2].data[5] == 2
    for before, after in zip(replies, replies[1:]):
        assert after.delay_s == pytest.approx(before.delay_s + len(before.data) * 10 / before.baud_bps + 500e-6)
    # A listed ID nobody has breaks the chain there; a repeated ID is read once, as first listed.
    replies = bus.receive(encode_instruction(BROADCAST_ID, Instruction.BULK_READ, bytes([0, 1, 1, 3, 1, 9, 3, 1, 2, 3])))
    assert [r.servo_id for r in replies] == [1]
    replies = bus.receive(encode_instruction(BROADCAST_ID, Instruction.BULK_READ, bytes([0, 1, 1, 3, 2, 1, 0])))
    assert [r.servo_id for r in replies] == [1] and len(replies[0].data) == 7


def test_errors_are_protocol_1_bits():
    bus = mx_bus(["mx-28"])
    assert write(bus, 1, 28, 255) == StatusError.RANGE  # P Gain 0..254
    assert write(bus, 1, 0, 1) == StatusError.RANGE  # Model Number is read-only
    assert write(bus, 1, 31, 1) == StatusError.RANGE  # half of Goal Position
    assert write2(bus, 1, CW_LIMIT, 1000) == 0
    assert write2(bus, 1, GOAL_POSITION, 999) == StatusError.ANGLE_LIMIT
    assert write2(bus, 1, GOAL_POSITION, 1000) == 0
    assert write(bus, 1, 47, 1) == 0  # Lock: the EEPROM freezes
    assert write2(bus, 1, CW_LIMIT, 0) == StatusError.RANGE
    assert write(bus, 1, 47, 0) == StatusError.RANGE  # released only by power-off
    reply = bus.receive(encode_instruction(1, 0x07, b""))[0].data  # no such instruction
    assert reply[4] == StatusError.INSTRUCTION
    assert bus.receive(encode_instruction(1, Instruction.ACTION, b""))[0].data[4] == StatusError.INSTRUCTION


def test_overload_shuts_down_through_torque_limit_and_a_new_torque_limit_restarts():
    """Shutdown's Overload bit (the default 36: Overheating and Overload): a blocked shaft driven hard latches it;
    Torque Limit becomes 0, every status packet carries the bit, and Torque Limit written non-zero lets the motor run."""
    bus = mx_bus(["mx-28"])
    bus.servo(1).plant.firmware.set_blocked(True)
    write2(bus, 1, GOAL_POSITION, 4000)
    run_s(bus, 3.0, every_s=0.01)
    reply = bus.receive(encode_instruction(1, Instruction.READ, bytes([TORQUE_LIMIT, 2])))[0].data
    assert reply[4] == StatusError.OVERLOAD
    assert reply[5:7] == b"\x00\x00"
    bus.servo(1).plant.firmware.set_blocked(False)
    assert write2(bus, 1, TORQUE_LIMIT, 1023) == 0  # the write clears the error before its status packet is built
    run_s(bus, 0.5)
    reply = bus.receive(encode_instruction(1, Instruction.PING, b""))[0].data
    assert reply[4] == 0
    assert read2(bus, 1, PRESENT_POSITION) > 2300  # moving to the goal again


def test_an_mx_holding_a_third_of_its_stall_torque_is_not_overloaded():
    """Protocol 1.0's Overload is "the current load cannot be controlled by the set Torque": a load the output holds
    at under a third of full duty is not one.  The X series' current-over-time rule, applied here too, cut an MX-64
    holding 0.3 of its stall torque after 23 s."""
    bus = mx_bus(["mx-64"])
    write(bus, 1, TORQUE_ENABLE, 1)
    run_s(bus, 0.2)
    bus.servo(1).plant.firmware.set_external_torque(0.3 * model("mx-64").physical.rating_at(12.0).stall_torque_nm)
    run_s(bus, 60.0, every_s=0.5)
    reply = bus.receive(encode_instruction(1, Instruction.READ, bytes([TORQUE_LIMIT, 2])))[0].data
    assert reply[4] & StatusError.OVERLOAD == 0 and reply[5:7] != b"\x00\x00"


def test_an_ax12a_and_mx_servos_share_one_wire():
    clock = VirtualClock()
    ax = Bus([1], clock=clock)
    bus = Bus1X([(2, model("mx-28"))], lambda spec, servo: build_plant1x(spec, servo.table), ax_bus=ax, clock=clock)
    assert bus.ids == [2, 1]
    assert read2(bus, 1, 0) == 12 and read2(bus, 2, 0) == 29
    assert read2(bus, 1, PRESENT_POSITION) == 512 and read2(bus, 2, PRESENT_POSITION) == 2048
    pings = bus.receive(encode_instruction(BROADCAST_ID, Instruction.PING, b""))
    assert sorted(r.servo_id for r in pings) == [1, 2]  # both answer a broadcast PING (their replies collide)
    with pytest.raises(ValueError, match="duplicate IDs"):
        Bus1X([(1, model("mx-28"))], lambda spec, servo: build_plant1x(spec, servo.table), ax_bus=Bus([1], clock=clock))
    assert isinstance(bus.framer, Framer)


def test_the_eeprom_area_persists_in_a_state_store_and_another_model_is_refused(tmp_path):
    from ax12emu.bus.state_store import StateFileError, StateStore

    store = StateStore(tmp_path)
    make = (lambda key: Bus1X([(1, model(key))], lambda spec, servo: build_plant1x(spec, servo.table),
                              clock=VirtualClock(), state_store=store))
    with make("mx-28") as bus:
        assert write2(bus, 1, CW_LIMIT, 4095) == 0 and write2(bus, 1, CCW_LIMIT, 4095) == 0  # multi-turn
        assert write2(bus, 1, MULTI_TURN_OFFSET, -100 & 0xFFFF) == 0
    with make("mx-28") as bus:
        assert read2(bus, 1, CW_LIMIT) == 4095 and read2(bus, 1, MULTI_TURN_OFFSET) == -100 & 0xFFFF
        assert read2(bus, 1, PRESENT_POSITION) == 2048 - 100  # the offset applies from power-up
    with pytest.raises((StateFileError, ValueError), match="another model"):
        make("mx-64")


def test_input_voltage_and_overheating_are_in_every_status_packet_and_shut_down_as_shutdown_selects_them():
    """Max Voltage Limit 11.0 V under a 12 V supply, Temperature Limit under the servo's 25 C: each condition is the
    status packets' bit while it holds, whatever Shutdown(18) selects (the AX-12A's e-manual text); those Shutdown
    selects set Torque Limit to 0, which stays until written once the condition is gone."""
    bus = mx_bus(["mx-64"])
    assert write(bus, 1, 13, 110) == 0  # Max Voltage Limit 11.0 V
    run_s(bus, 0.01)
    assert bus.receive(encode_instruction(1, Instruction.PING, b""))[0].data[4] == StatusError.INPUT_VOLTAGE
    assert read2(bus, 1, TORQUE_LIMIT) == 1023  # the default 36 does not select it: the motor still runs
    assert write2(bus, 1, GOAL_POSITION, 2500) == StatusError.INPUT_VOLTAGE
    run_s(bus, 0.5)
    assert abs(read2(bus, 1, PRESENT_POSITION) - 2500) < 20
    assert write(bus, 1, 18, 36 | 0x01) == StatusError.INPUT_VOLTAGE
    run_s(bus, 0.01)
    assert read2(bus, 1, TORQUE_LIMIT) == 0
    assert write2(bus, 1, TORQUE_LIMIT, 1023) == StatusError.INPUT_VOLTAGE
    run_s(bus, 0.01)
    assert read2(bus, 1, TORQUE_LIMIT) == 0  # the condition holds: the shutdown holds
    assert write(bus, 1, 13, 160) == StatusError.INPUT_VOLTAGE  # the supply within the limits again, from the next step
    run_s(bus, 0.01)
    assert bus.receive(encode_instruction(1, Instruction.PING, b""))[0].data[4] == 0
    assert read2(bus, 1, TORQUE_LIMIT) == 0  # until the client writes it
    assert write2(bus, 1, TORQUE_LIMIT, 1023) == 0
    assert write2(bus, 1, GOAL_POSITION, 1500) == 0
    run_s(bus, 1.0)
    assert abs(read2(bus, 1, PRESENT_POSITION) - 1500) < 20 and read2(bus, 1, TORQUE_LIMIT) == 1023
    hot = mx_bus(["mx-28"])
    assert write(hot, 1, 11, 20) == 0  # Temperature Limit 20 C; the default Shutdown 36 selects Overheating
    run_s(hot, 0.01)
    assert hot.receive(encode_instruction(1, Instruction.PING, b""))[0].data[4] == StatusError.OVERHEATING
    assert read2(hot, 1, TORQUE_LIMIT) == 0


def test_an_angle_limit_error_with_shutdowns_angle_bit_drops_the_output_to_zero():
    bus = mx_bus(["mx-28"])
    write2(bus, 1, CW_LIMIT, 1000)
    assert write2(bus, 1, GOAL_POSITION, 500) == StatusError.ANGLE_LIMIT
    assert read2(bus, 1, TORQUE_LIMIT) == 1023  # the default Shutdown (36) does not select it
    assert write(bus, 1, 18, 36 | StatusError.ANGLE_LIMIT) == 0
    assert write2(bus, 1, GOAL_POSITION, 500) == StatusError.ANGLE_LIMIT
    assert read2(bus, 1, TORQUE_LIMIT) == 0 and read2(bus, 1, GOAL_POSITION) == 2048


def test_a_broadcast_factory_reset_is_not_carried_out_and_reboot_restarts_the_servo():
    """e-manual, Protocol 1.0: "Broadcast ID(0xFE) cannot be used for Reset instruction. Applied Products :
    MX-12W(V41), MX-28(V40), ..." (every ID on the wire went back to 1), and "Reboot" for the same firmware
    (answered with Instruction Error); the servos report that firmware, V40."""
    bus = mx_bus(["mx-28", "mx-28"], ids=[1, 2])
    assert read2(bus, 1, 2) & 0xFF == 40  # Firmware Version
    assert write(bus, 2, 3, 7) == 0  # ID 2 -> 7
    assert bus.receive(encode_instruction(BROADCAST_ID, Instruction.RESET, b"")) == []
    assert sorted(bus.ids) == [1, 7]
    assert write(bus, 1, 25, 1) == 0 and write(bus, 1, 14, 500 & 0xFF, 500 >> 8) == 0  # LED (RAM), Max Torque (EEPROM)
    assert write2(bus, 1, GOAL_POSITION, 3000) == 0  # the torque comes on
    run_s(bus, 0.5)
    reply = bus.receive(encode_instruction(1, Instruction.REBOOT, b""))[0].data
    assert reply[4] == 0  # answered, then restarted
    run_s(bus, 0.01)
    assert read2(bus, 1, 24) & 0xFF == 0 and read2(bus, 1, 25) & 0xFF == 0  # Torque Enable, LED: RAM defaults
    assert read2(bus, 1, 14) == 500 and read2(bus, 1, TORQUE_LIMIT) == 500  # EEPROM kept; Torque Limit loads it
    assert abs(read2(bus, 1, GOAL_POSITION) - 3000) <= 50  # the goal where it stood (the limp shaft settles)


def test_the_reply_to_a_baud_rate_write_goes_out_at_the_old_rate():
    """The status is sent before the new rate takes effect; the MX bus stamped it with the new one (paced so)."""
    bus = mx_bus(["mx-28"])
    write(bus, 1, 4, 1)  # 1 Mbps
    (reply,) = bus.receive(encode_instruction(1, Instruction.WRITE, bytes([4, 3])))  # to 500,000 bps
    assert reply.baud_bps == pytest.approx(1_000_000)


def test_two_servos_sharing_an_id_collide_in_a_bulk_read_as_in_a_read():
    """Both heard the servo before them and answer in the ID's turn at once; only the first answered, clean, so a
    client read one twin's value with COMM_SUCCESS and never saw the other's."""
    from ax12emu.faults.injection import faults_for

    bus = mx_bus(["mx-28", "mx-28", "mx-28"])
    write(bus, 3, 25, 1)  # the twins differ: LED 1 on ID 3, LED 0 on the servo that will answer as 3
    faults = faults_for(bus)
    bus.faults = faults
    faults.duplicate(1, 3)
    replies = bus.receive(encode_instruction(BROADCAST_ID, Instruction.BULK_READ, bytes([0, 1, 2, 25, 1, 3, 25])))
    assert [len(r.data) for r in replies] == [7, 7]
    assert not Framer().feed(replies[1].data)[0].checksum_ok  # the collided answer


def test_debug_logging_names_an_mx_packet_by_the_mx_table(caplog):
    """The AX-12 bus inside the wire logged every packet in AX-12A registers: an MX's Multi Turn Offset as [20]=16."""
    import logging

    bus = mx_bus(["mx-28"])
    with caplog.at_level(logging.DEBUG, logger="ax12emu.bus"):
        bus.receive(encode_instruction(1, Instruction.WRITE, bytes([20, 16, 0])))
    assert "multi_turn_offset=16" in caplog.text and "[20]=16" not in caplog.text


@pytest.mark.parametrize("key", ("mx-28", "mx-64"))
def test_a_mode_change_by_the_angle_limits_with_the_torque_on_runs_the_goals_already_set(key):
    """CW = CCW = 0 with the torque on and Moving Speed set (pypot's ``set_wheel_mode``): the wheel turns at that speed
    without Moving Speed being written again; CCW back at 4095: the joint goes to the Goal Position it holds (the
    AX-12A does both on the same packets)."""
    bus = mx_bus([key])
    assert write(bus, 1, TORQUE_ENABLE, 1) == 0 and write2(bus, 1, MOVING_SPEED, 300) == 0
    run_s(bus, 0.5, every_s=0.01)
    assert write(bus, 1, CW_LIMIT, 0, 0, 0, 0) == 0  # both angle limits 0 in one write: wheel mode
    run_s(bus, 1.0, every_s=0.01)
    assert directional(read2(bus, 1, PRESENT_SPEED)) == pytest.approx(300, rel=0.05)
    assert write2(bus, 1, CCW_LIMIT, 4095) == 0  # joint mode again
    run_s(bus, 3.0, every_s=0.01)
    assert abs(read2(bus, 1, PRESENT_POSITION) - read2(bus, 1, GOAL_POSITION)) <= 8
    assert directional(read2(bus, 1, PRESENT_SPEED)) == 0


def test_joint_to_multi_turn_with_the_torque_on_goes_to_the_goal_position():
    bus = mx_bus(["mx-28"])
    assert write(bus, 1, TORQUE_ENABLE, 1) == 0 and write2(bus, 1, MOVING_SPEED, 200) == 0
    write2(bus, 1, CW_LIMIT, 0)
    write2(bus, 1, CCW_LIMIT, 0)  # wheel mode: it turns and leaves the goal behind
    run_s(bus, 0.7, every_s=0.01)
    assert abs(read2(bus, 1, PRESENT_POSITION) - 2048) > 200
    write(bus, 1, CW_LIMIT, 0xFF, 0x0F, 0xFF, 0x0F)  # multi-turn mode: Goal Position 2048 in the turn the count stands
    run_s(bus, 3.0, every_s=0.01)
    assert directional(read2(bus, 1, PRESENT_SPEED)) == 0
    assert abs(read2(bus, 1, PRESENT_POSITION) - 2048) <= 8


def test_a_bulk_reads_range_error_cuts_the_output_where_shutdown_selects_range():
    bus = mx_bus(["mx-28", "mx-64"])
    assert write(bus, 2, 18, 36 | StatusError.RANGE) == 0
    params = bytes([0x00, 10, 1, 70, 10, 2, 70])  # 10 bytes from 70 on each: past both tables
    replies = bus.receive(encode_instruction(BROADCAST_ID, Instruction.BULK_READ, params))
    assert [r.data[4] & StatusError.RANGE for r in replies] == [StatusError.RANGE] * 2
    assert read2(bus, 1, TORQUE_LIMIT) == 1023 and read2(bus, 2, TORQUE_LIMIT) == 0


def test_torque_limit_0_reads_as_no_load_at_once():
    """Torque Limit 0 written mid-move within the control period of the write before it (a host faster than 1 kHz):
    Present Load, the output's share, already reads 0 beside it."""
    bus = mx_bus(["mx-28"])
    write(bus, 1, TORQUE_ENABLE, 1)
    run_s(bus, 0.1)
    write2(bus, 1, GOAL_POSITION, 2548)
    run_s(bus, 0.05)
    write2(bus, 1, GOAL_POSITION, 2558)  # earns a step: the model is now one ahead of the clock
    assert directional(read2(bus, 1, PRESENT_LOAD)) > 500
    assert write2(bus, 1, TORQUE_LIMIT, 0) == 0  # no step of its own
    assert (read2(bus, 1, TORQUE_LIMIT), read2(bus, 1, PRESENT_LOAD)) == (0, 0)
