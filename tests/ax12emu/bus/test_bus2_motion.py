"""Protocol 2.0 requests move the X-series firmware model, in virtual time: what a client reads follows the physics."""

from __future__ import annotations

from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock
from ax12emu.protocol.packets2 import ErrorNumber, Instruction2, decode_packet2, encode_instruction2
from ax12emu.protocol.servo_models import model
from ax12emu.servo.model_factory2 import build_x_firmware


def u32(value: int) -> bytes:
    return (value & 0xFFFFFFFF).to_bytes(4, "little")


def request(bus: Bus2, servo_id: int, instruction: int, params: bytes = b""):
    replies = bus.receive(encode_instruction2(servo_id, instruction, params))
    assert len(replies) == 1
    return decode_packet2(replies[0].data)


def read(bus: Bus2, servo_id: int, address: int, size: int) -> int:
    reply = request(bus, servo_id, Instruction2.READ, address.to_bytes(2, "little") + size.to_bytes(2, "little"))
    assert reply.error == ErrorNumber.NONE
    return int.from_bytes(reply.params, "little", signed=True)


def xl430_bus(ids=(1, 2)) -> Bus2:
    spec = model("xl430-w250")
    return Bus2([(i, spec) for i in ids], lambda s, index: build_x_firmware(s), clock=VirtualClock())


def test_a_goal_write_starts_a_profile_the_next_read_sees_and_the_servo_arrives():
    bus = xl430_bus()
    # A trapezoidal profile: Profile Acceleration 20, Profile Velocity 100 (velocity-based profile).
    assert request(bus, 1, Instruction2.WRITE, bytes((108, 0)) + u32(20) + u32(100)).error == ErrorNumber.NONE
    assert request(bus, 1, Instruction2.WRITE, bytes((64, 0, 1))).error == ErrorNumber.NONE
    assert request(bus, 1, Instruction2.WRITE, bytes((116, 0)) + u32(3048)).error == ErrorNumber.NONE
    assert read(bus, 1, 122, 1) == 1  # Moving, at once: the control loop ran before the next request
    positions = []
    for _ in range(30):
        bus.clock.advance(0.05)
        positions.append(read(bus, 1, 132, 4))
    assert positions == sorted(positions), "it closes in without turning back"
    assert abs(positions[-1] - 3048) <= 10
    assert read(bus, 1, 122, 1) == 0
    assert read(bus, 2, 132, 4) == 2048  # the other servo, torque off, stays


def test_profile_velocity_slows_the_move():
    fast, slow = xl430_bus(ids=(1,)), xl430_bus(ids=(1,))
    request(slow, 1, Instruction2.WRITE, bytes((112, 0)) + u32(20))  # Profile Velocity 20 x 0.229 rpm
    for bus in (fast, slow):
        request(bus, 1, Instruction2.WRITE, bytes((64, 0, 1)))
        request(bus, 1, Instruction2.WRITE, bytes((116, 0)) + u32(3048))
        bus.clock.advance(0.3)
    assert read(slow, 1, 132, 4) < read(fast, 1, 132, 4) - 100


def test_torque_off_leaves_the_shaft_and_a_reboot_keeps_its_angle():
    bus = xl430_bus(ids=(1,))
    request(bus, 1, Instruction2.WRITE, bytes((64, 0, 1)))
    request(bus, 1, Instruction2.WRITE, bytes((116, 0)) + u32(2548))
    bus.clock.advance(2.0)
    before = read(bus, 1, 132, 4)
    assert request(bus, 1, Instruction2.REBOOT).error == ErrorNumber.NONE
    assert read(bus, 1, 64, 1) == 0
    assert abs(read(bus, 1, 132, 4) - before) <= 2
    assert read(bus, 1, 116, 4) == read(bus, 1, 132, 4)  # Goal Position starts at Present Position again


def test_extended_position_mode_turns_past_one_revolution():
    bus = xl430_bus(ids=(1,))
    assert request(bus, 1, Instruction2.WRITE, bytes((11, 0, 4))).error == ErrorNumber.NONE
    request(bus, 1, Instruction2.WRITE, bytes((64, 0, 1)))
    assert request(bus, 1, Instruction2.WRITE, bytes((116, 0)) + u32(2048 + 6000)).error == ErrorNumber.NONE
    bus.clock.advance(5.0)
    assert abs(read(bus, 1, 132, 4) - (2048 + 6000)) <= 10


def test_factory_reset_turns_the_torque_off_in_the_firmware_too():
    bus = xl430_bus(ids=(1,))
    request(bus, 1, Instruction2.WRITE, bytes((64, 0, 1)))
    assert request(bus, 1, Instruction2.FACTORY_RESET, b"\x02").error == ErrorNumber.NONE
    bus.clock.advance(0.01)
    assert read(bus, 1, 64, 1) == 0
    assert bus.servo(1).plant.firmware.sense().torque_enable == 0


def test_settling_after_a_sync_write_takes_the_steps_the_next_packet_would_have_taken():
    """settle_in_pieces (a serving loop's idle time after a packet) steps each servo a write reached, one piece
    each; the packets after it then get the same answers, and the firmware the same time, as without it."""
    settled, plain = xl430_bus(ids=(1, 2, 3)), xl430_bus(ids=(1, 2, 3))
    sync_read = encode_instruction2(0xFE, Instruction2.SYNC_READ, bytes((132, 0, 4, 0, 1, 2, 3)))
    for bus in (settled, plain):
        for servo_id in (1, 2, 3):
            request(bus, servo_id, Instruction2.WRITE, bytes((64, 0, 1)))
    answers = {id(bus): [] for bus in (settled, plain)}
    for cycle in range(40):
        goals = b"".join(bytes((i,)) + u32(2048 + (300 if cycle // 10 % 2 else -300) * i) for i in (1, 2, 3))
        for bus in (settled, plain):
            assert bus.receive(encode_instruction2(0xFE, Instruction2.SYNC_WRITE, bytes((116, 0, 4, 0)) + goals)) == []
        pieces = list(settled.settle_in_pieces())
        assert len(pieces) == 3  # one step per servo written, none for the rest
        assert list(settled.settle_in_pieces()) == []  # nothing owed twice
        for bus in (settled, plain):
            answers[id(bus)].append([reply.data for reply in bus.receive(sync_read)])
            bus.clock.advance(0.004 * (cycle % 4))  # 0 to 12 ms: no step due, or several
    assert answers[id(settled)] == answers[id(plain)]
    assert [s.plant.firmware.time_s for s in settled.servos] == [s.plant.firmware.time_s for s in plain.servos]
    assert len({tuple(a) for a in answers[id(plain)]}) > 10, "the servos moved"
