"""Fault injection: each fault's client-side symptom through dynamixel-sdk, and recovery when lifted."""

from __future__ import annotations

import math
import time
from dataclasses import replace

import pytest
from dynamixel_sdk import COMM_RX_CORRUPT, COMM_RX_TIMEOUT, COMM_SUCCESS
from emu_testkit import ok, sdk_port

from ax12emu import FaultConfig, VirtualBus
from ax12emu.bus.bus import Bus
from ax12emu.bus.clock import VirtualClock
from ax12emu.faults.injection import Faults, parse_alarm_bits
from ax12emu.protocol.packets import StatusError, encode_instruction, encode_status
from ax12emu.servo.virtual_servo import ServoOptions
from firmware_model import KinematicModel, ServoParams

PRESENT_POSITION = 36


@pytest.fixture
def vbus():
    """Two servos on a pty, kinematic model, wall clock."""
    with VirtualBus([1, 2], model="kinematic") as bus:
        yield bus


def comm_of(result: tuple) -> int:
    """The comm result of an SDK (value, comm, error) triple."""
    return result[1]


@pytest.mark.parametrize(
    "setting, symptom",
    [({"drop": 1.0}, COMM_RX_TIMEOUT), ({"corrupt": 1.0}, COMM_RX_CORRUPT), ({"delay": 1.0, "delay_s": 0.6}, COMM_RX_TIMEOUT)],
    ids=["drop", "corrupt", "delay"],
)
def test_reply_faults_show_their_symptom_and_lift(vbus, setting, symptom):
    """Dropped and late replies time out, corrupted ones fail the checksum; lifting the fault restores replies."""
    with sdk_port(vbus.port) as (port, ph):
        vbus.faults.set_reply_faults(**setting, ids=[1])
        assert comm_of(ph.read2ByteTxRx(port, 1, PRESENT_POSITION)) == symptom
        assert ok(ph.read2ByteTxRx(port, 2, PRESENT_POSITION)) == 512, "other IDs are untouched"
        vbus.faults.set_reply_faults()
        time.sleep(0.65)  # a delayed reply (later than the port waits) still arrives: let it pass first
        assert ok(ph.read2ByteTxRx(port, 1, PRESENT_POSITION)) == 512


def test_dropped_reply_still_executes(vbus):
    """A WRITE whose reply is lost was still carried out (the client cannot tell)."""
    with sdk_port(vbus.port) as (port, ph):
        vbus.faults.set_reply_faults(drop=1.0)
        assert ph.write1ByteTxRx(port, 1, 25, 1)[0] == COMM_RX_TIMEOUT
        vbus.faults.clear()
        assert ok(ph.read1ByteTxRx(port, 1, 25)) == 1


def test_vanished_servo_times_out_then_comes_back(vbus):
    """An unplugged servo is silent (and deaf); plugged back it answers with its table as it was."""
    with sdk_port(vbus.port) as (port, ph):
        ph.write1ByteTxRx(port, 1, 25, 1)
        vbus.faults.vanish(1)
        assert comm_of(ph.ping(port, 1)) == COMM_RX_TIMEOUT
        ph.write1ByteTxOnly(port, 0xFE, 25, 0)  # broadcast: the vanished servo does not hear it
        assert ok(ph.ping(port, 2)) == 12  # a round trip: the broadcast is served before reappear() runs
        vbus.faults.reappear(1)
        assert ok(ph.ping(port, 1)) == 12
        assert ok(ph.read1ByteTxRx(port, 1, 25)) == 1
        assert ok(ph.read1ByteTxRx(port, 2, 25)) == 0


def test_periodic_vanish_follows_virtual_time():
    """vanish(every_s, for_s): absent for_s out of every every_s of simulated time."""
    clock = VirtualClock()
    bus = Bus([1], clock=clock)
    bus.faults = Faults(bus)
    bus.faults.vanish(1, every_s=1.0, for_s=0.25)
    heard = []
    for _ in range(8):
        heard.append(bool(bus.receive(encode_instruction(1, 1))))
        clock.advance(0.125)
    assert heard == [False, False, True, True, True, True, True, True]


def test_duplicate_ids_collide(vbus):
    """Two servos with ID 1: equal replies merge cleanly, different Present Positions arrive corrupt."""
    vbus.set_angle_deg(2, 100 * 300 / 1023)
    with sdk_port(vbus.port) as (port, ph):
        assert ok(ph.read2ByteTxRx(port, 2, PRESENT_POSITION)) == 100
        vbus.faults.duplicate(2, 1)
        assert ok(ph.ping(port, 1)) == 12, "identical replies AND into the same bytes"
        assert comm_of(ph.read2ByteTxRx(port, 1, PRESENT_POSITION)) == COMM_RX_CORRUPT
        assert comm_of(ph.ping(port, 2)) == COMM_RX_TIMEOUT
        vbus.faults.unduplicate(2)
        assert ok(ph.read2ByteTxRx(port, 1, PRESENT_POSITION)) == 512
        assert ok(ph.read2ByteTxRx(port, 2, PRESENT_POSITION)) == 100


@pytest.mark.parametrize(
    "force, lift, bit",
    [
        (lambda b: b.faults.force_alarm(1, "overload"), lambda b: b.faults.clear_alarm(1), StatusError.OVERLOAD),
        (lambda b: b.set_temperature(1, 85), lambda b: b.set_temperature(1, None), StatusError.OVERHEATING),
        (lambda b: b.set_voltage(1, 5.0), lambda b: b.set_voltage(1, None), StatusError.INPUT_VOLTAGE),
    ],
    ids=["overload", "overheating", "input_voltage"],
)
def test_alarms_set_error_bits_and_clear(vbus, force, lift, bit):
    """Forced alarms (or readings past the limits) appear in every status byte; they clear when lifted."""
    with sdk_port(vbus.port) as (port, ph):
        force(vbus)
        value, comm, error = ph.read2ByteTxRx(port, 1, PRESENT_POSITION)
        assert comm == COMM_SUCCESS and error == bit
        assert ph.read1ByteTxRx(port, 2, 25)[2] == 0
        lift(vbus)
        assert ph.read2ByteTxRx(port, 1, PRESENT_POSITION)[2] == 0


def test_two_forced_alarms_add_up_and_clear_together():
    """A second force_alarm (a second --alarm for one servo) replaced the first's record: the first stayed raised
    after clear_alarm, Torque Limit 0 for good; they add up, as the MX and X servos' do."""
    with VirtualBus([1], transport="inprocess", virtual_time=True) as vbus:
        vbus.faults.force_alarm(1, "overload")
        vbus.faults.force_alarm(1, "overheating")
        assert vbus.bus.servos[0].alarms == StatusError.OVERLOAD | StatusError.OVERHEATING
        vbus.faults.clear_alarm(1)
        vbus.step(0.1)
        assert vbus.bus.servos[0].alarms == 0


def test_overload_alarm_triggers_shutdown(vbus):
    """Alarm Shutdown acts on a forced overload as the firmware does: Torque Limit drops to 0."""
    with sdk_port(vbus.port) as (port, ph):
        vbus.faults.force_alarm(1, parse_alarm_bits("overload"))
        ph.ping(port, 1)
        assert vbus.read(1, "torque_limit") == 0


def test_stalled_shaft_holds_position_and_overloads():
    """A blocked shaft: position frozen, Moving 1, full load, then Overload; released it reaches the goal."""
    with VirtualBus([1], virtual_time=True, model="kinematic") as vbus, sdk_port(vbus.port) as (port, ph):
        vbus.faults.stall(1, overload_after_s=1.0)
        assert ph.write1ByteTxRx(port, 1, 24, 1) == (COMM_SUCCESS, 0)
        assert ph.write2ByteTxRx(port, 1, 30, 800) == (COMM_SUCCESS, 0)
        vbus.step(0.5)
        assert ok(ph.read2ByteTxRx(port, 1, PRESENT_POSITION)) == 512
        assert ok(ph.read1ByteTxRx(port, 1, 46)) == 1
        assert ok(ph.read2ByteTxRx(port, 1, 40)) == 1023
        vbus.step(0.6)
        _, comm, error = ph.read2ByteTxRx(port, 1, PRESENT_POSITION)
        assert comm == COMM_SUCCESS and error == StatusError.OVERLOAD
        vbus.faults.release(1)
        ph.write2ByteTxRx(port, 1, 34, 1023)  # Alarm Shutdown zeroed Torque Limit: the client restores it
        vbus.step(2.0)
        assert ph.read2ByteTxRx(port, 1, PRESENT_POSITION) == (800, COMM_SUCCESS, 0)


def test_stall_drive_timer_starts_at_the_goal_write_not_at_the_next_step():
    """Virtual time without a serving loop: the write is the only event before the step, yet it counts."""
    clock = VirtualClock()
    bus = Bus([1], clock=clock, model=KinematicModel(1))
    bus.faults = Faults(bus)
    bus.faults.stall(1, overload_after_s=1.0)
    bus.receive(encode_instruction(1, 0x03, bytes([24, 1])))
    bus.receive(encode_instruction(1, 0x03, bytes([30, 0x20, 0x03])))  # goal 800: driving from t = 0
    clock.advance(1.05)
    bus.advance()
    (reply,) = bus.receive(encode_instruction(1, 0x02, bytes([36, 2])))
    assert reply.data[4] == StatusError.OVERLOAD


def test_stalled_shaft_in_the_physical_model():
    """Physical model: the blocked shaft stays put while the motor drives at full load; the model's own
    overload timer (0.5 s) raises Overload; released, the servo moves on from where it was held."""
    with VirtualBus([1], virtual_time=True) as vbus, sdk_port(vbus.port) as (port, ph):
        with pytest.raises(ValueError, match="overload_delay_s"):  # it was ignored, silently
            vbus.faults.stall(1, overload_after_s=3.0)
        vbus.faults.stall(1)
        assert ph.write1ByteTxRx(port, 1, 24, 1) == (COMM_SUCCESS, 0)
        assert ph.write2ByteTxRx(port, 1, 30, 800) == (COMM_SUCCESS, 0)
        vbus.step(0.3)
        assert abs(ok(ph.read2ByteTxRx(port, 1, PRESENT_POSITION)) - 512) <= 1
        assert ok(ph.read2ByteTxRx(port, 1, 40)) & 0x3FF >= 1000  # full drive, CCW
        vbus.step(0.5)
        _, comm, error = ph.read2ByteTxRx(port, 1, PRESENT_POSITION)
        assert comm == COMM_SUCCESS and error & StatusError.OVERLOAD
        vbus.faults.release(1)
        ph.write2ByteTxRx(port, 1, 34, 1023)  # Alarm Shutdown zeroed Torque Limit: the client restores it
        vbus.step(1.5)
        value, comm, error = ph.read2ByteTxRx(port, 1, PRESENT_POSITION)
        assert comm == COMM_SUCCESS and abs(value - 800) <= 4 and not error & StatusError.OVERLOAD


@pytest.mark.parametrize("model", ["physical", "kinematic"])
def test_clear_lifts_a_stall_and_the_servo_moves_again(model):
    """clear() frees a blocked shaft whichever way it was blocked (in the model's mechanics or by held registers)."""
    with VirtualBus([1], transport="inprocess", virtual_time=True, model=model) as vbus:
        vbus.faults.stall(1)
        vbus.write(1, "torque_enable", 1)
        vbus.write(1, "goal_position", 800)
        vbus.step(0.2)  # pushing against the block, short of the overload
        assert abs(vbus.read(1, "present_position") - 512) <= 1
        vbus.faults.clear()
        assert vbus.faults.active(1) == []
        vbus.step(1.5)
        assert abs(vbus.read(1, "present_position") - 800) <= 4


def test_same_seed_same_faults():
    """Random faults repeat exactly with the same seed and traffic, and differ with another seed."""

    def pattern(seed):
        bus = Bus([1], clock=VirtualClock(), model=KinematicModel(1))
        FaultConfig(drop=0.3, corrupt=0.3, seed=seed).install(bus)
        return [r[0].data if r else None for r in (bus.receive(encode_instruction(1, 1)) for _ in range(40))]

    assert pattern(5) == pattern(5)
    assert pattern(5) != pattern(6)
    assert None in pattern(5)


@pytest.mark.parametrize(
    "setting",
    [{"drop": 0.3}, {"corrupt": 0.3}, {"delay": 0.3}, {"drop": 0.2, "corrupt": 0.2, "delay": 0.2}],
    ids=["drop", "corrupt", "delay", "all-three"],
)
def test_reply_faults_hit_their_configured_share_of_the_replies(setting):
    """FaultConfig(drop=0.3) drops 30 % of the status packets (likewise corrupt, delay, and the three together):
    over 2000 PINGs with a fixed seed each share lies within 4.5 binomial sigmas of its fraction."""
    bus = Bus([1], clock=VirtualClock(), model=KinematicModel(1))
    FaultConfig(**setting, delay_s=0.1, seed=1).install(bus)
    clean = encode_status(1, 0)
    n = 2000
    counts = {"drop": 0, "corrupt": 0, "delay": 0}
    for _ in range(n):
        replies = bus.receive(encode_instruction(1, 0x01))
        if not replies:
            counts["drop"] += 1
            continue
        (reply,) = replies
        if reply.data != clean:
            assert reply.data[:-1] == clean[:-1]  # only the checksum is spoiled
            counts["corrupt"] += 1
        if reply.delay_s >= 0.1:
            counts["delay"] += 1
    for kind, count in counts.items():
        fraction = setting.get(kind, 0.0)
        bound = 4.5 * math.sqrt(fraction * (1 - fraction) / n)
        assert abs(count / n - fraction) <= bound, (kind, count, fraction)


def test_serve_fault_flags(emulator):
    """ax12emu serve --drop 1 --fault-ids 2: ID 2 times out, ID 1 answers."""
    served = emulator("--ids", "1,2", "--model", "kinematic", "--drop", "1", "--fault-ids", "2", "--alarm", "1:overheating")
    with sdk_port(served.port) as (port, ph):
        assert comm_of(ph.ping(port, 2)) == COMM_RX_TIMEOUT
        value, comm, error = ph.ping(port, 1)
        assert (value, comm, error) == (12, COMM_SUCCESS, StatusError.OVERHEATING)


def test_a_duplicate_is_not_kept_in_the_state_directory(tmp_path):
    """A fault is not the servo's configuration: with --state-dir, the next run without it had two servos at ID 1."""
    from ax12emu.bus.state_store import StateStore

    with Bus([1, 2], state_store=StateStore(tmp_path)) as bus:
        faults = Faults(bus)
        faults.duplicate(2, 1)
        bus.receive(encode_instruction(1, 0x03, bytes((5, 0))))  # an EEPROM write (Return Delay Time) while it lasts
    with Bus([1, 2], state_store=StateStore(tmp_path)) as bus:
        assert [servo.id for servo in bus.servos] == [1, 2]
        assert bus.servos[1].table.get("return_delay_time") == 0


def test_each_stall_keeps_its_own_overload_time():
    """One servo stalled for 5 s and another for the default 1 s: the second stall's time was the bus's, for both."""
    with VirtualBus([1, 2], model="kinematic", transport="inprocess", virtual_time=True) as bus:
        for servo_id in (1, 2):
            bus.write(servo_id, "torque_enable", 1)
        bus.faults.stall(1, overload_after_s=5.0)
        bus.faults.stall(2)
        for servo_id in (1, 2):
            bus.write(servo_id, "goal_position", 700)  # away from where the shafts are held
        for _ in range(4):  # the stall's drive timer runs from the first step that sees the goal
            bus.step(0.6)
        assert [bool(bus.call(lambda b, k=k: b.servos[k].alarms) & StatusError.OVERLOAD) for k in (0, 1)] == [False, True]


def test_a_held_reading_the_register_cannot_show_is_refused():
    """300 degrees wrapped to 44 in the register."""
    bus = Bus([1])
    faults = Faults(bus)
    with pytest.raises(ValueError, match=r"present_temperature holds 0..255, got 300"):
        faults.hold(1, "present_temperature", 300)
    faults.hold(1, "present_temperature", 90)
    assert bus.servos[0].table.get("present_temperature") == 90


@pytest.mark.parametrize("reading, value, alarm", [("present_temperature", 80, StatusError.OVERHEATING),
                                                    ("present_voltage", 150, StatusError.INPUT_VOLTAGE)])
def test_a_pinned_reading_raises_its_alarm_and_shutdown_without_a_packet(reading, value, alarm):
    """A pinned temperature above Temperature Limit (a voltage outside the limits) raised its alarm, and Alarm
    Shutdown cut the output, only when a packet reached the servo: stepped 5 s with no packet, the status bits, the
    live view and Torque Limit showed nothing and the stalled motor kept full drive."""
    with VirtualBus(ids=[1], transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "shutdown", int(alarm))  # the pinned reading's alarm alone (not the stall's Overload)
        bus.write(1, "torque_enable", 1)
        bus.step(0.2)
        bus.faults.stall(1)
        bus.write(1, "goal_position", 800)
        bus.faults.hold(1, reading, value)
        bus.step(5.0)
        assert bus.call(lambda b: b.servos[0].alarms) & alarm
        assert bus.read(1, "torque_limit") == 0
        assert bus.call(lambda b: float(b.model.drive[0])) == 0.0
        assert bus.call(lambda b: float(b.model.temperature_c[0])) < 31.0


@pytest.mark.parametrize("alarm", [lambda faults: faults.force_alarm(1, "overheating"),
                                   lambda faults: faults.hold(1, "present_temperature", 90)], ids=["forced", "pinned"])
@pytest.mark.parametrize("command_delay_s", [0.0, 0.005], ids=["at once", "5 ms command delay"])
@pytest.mark.parametrize("profile, register, on", [("ax12a", "torque_limit", 1023), ("ax12-2006", "torque_enable", 1)])
def test_a_register_set_while_a_forced_or_pinned_alarm_lasts_drives_no_step(profile, register, on, command_delay_s, alarm):
    """Forced alarms (and a pinned reading's) were held after each step, not before: Torque Limit (the 2006
    edition: Torque Enable) set by name while Overheating lasted drove the shaft for the whole next step (full drive
    toward the goal, however long the step), with a command delay that much later, and only then went back to 0
    (90 C is above both editions' factory Temperature Limit, 70 and 85 C)."""
    params = replace(ServoParams(), effects=replace(ServoParams().effects, command_delay_s=command_delay_s))
    options = ServoOptions(profile=profile, eeprom_busy_s_per_byte=0.0)
    with VirtualBus([1], transport="inprocess", virtual_time=True, options=options, params=params) as bus:
        bus.write(1, "torque_enable", 1)
        bus.step(0.05)
        alarm(bus.faults)  # Overheating: both editions' factory Alarm Shutdown selects it
        bus.write(1, "goal_position", 900)
        bus.step(0.05)
        start_deg = bus.angle_deg(1)
        bus.write(1, register, on)
        drives = []
        for _ in range(50):
            bus.step(0.001)
            drives.append(bus.call(lambda b: float(b.model.drive[0])))
        assert bus.read(1, register) == 0
        assert drives == [0.0] * 50 and bus.angle_deg(1) == start_deg


def test_a_forced_alarm_acts_at_once_and_holds_between_packets():
    """The bits showed, and Alarm Shutdown cut the output, only when a packet reached the servo: a live view of an idle
    bus showed no alarm, and a Torque Limit written meanwhile drove the shaft until the next packet."""
    with VirtualBus([1], model="kinematic", transport="inprocess", virtual_time=True) as bus:
        bus.write(1, "torque_enable", 1)
        bus.faults.force_alarm(1, "overload")
        assert bus.call(lambda b: b.servos[0].alarms) & StatusError.OVERLOAD
        assert bus.read(1, "torque_limit") == 0  # Alarm Shutdown selects Overload by default
        bus.write(1, "torque_limit", 1023)
        bus.write(1, "goal_position", 200)
        bus.step(0.5)
        assert bus.read(1, "torque_limit") == 0
        assert bus.call(lambda b: b.servos[0].alarms) & StatusError.OVERLOAD
