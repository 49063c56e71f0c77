"""pypot's ``DxlIO`` (the library Poppy robots drive their AX-12s with), unmodified, against a served bus.

Why it exists: the emulator promises that unmodified clients drive it as they drive real servos,
and pypot has its own Protocol 1.0 code (packets, sync writes, unit conversions, error handlers),
none of it dynamixel-sdk's.  Its heavy requirements (OpenCV among them) are never imported:
``pypot.dynamixel`` needs only numpy and pyserial.

One thing a pypot user meets on real servos as here: an AX-12 ignores packets for about 6 ms per
byte after writing its EEPROM (``ServoOptions.eeprom_busy_s_per_byte``), and pypot reads right
after a write's reply, so a read straight after ``set_angle_limit`` (four EEPROM bytes) goes
unanswered.  The tests wait :data:`EEPROM_SETTLE_S` after such writes, as a pypot program on real
servos must: pypot's own robot set-up (``pypot/robot/config.py``, ``check_motor_eprom_configuration``)
sleeps 0.5 s after writing angle limits and after writing Return Delay Time.
"""

from __future__ import annotations

import time

import pypot.dynamixel as pd
import pytest
from pypot.dynamixel.error import BaseErrorHandler

#: After a write to the EEPROM area: pypot's own set-up's wait.  Four bytes at 6 ms each would do on a servo; the
#: emulator times the deaf spell from when it reads the write, which a loaded machine may delay.
EEPROM_SETTLE_S = 0.5
#: After a write that gets no reply (every pypot setter is a Sync Write): pypot empties the port's output before
#: its next packet, and on a pty the kernel discards a packet the emulator has not read yet (about one in three
#: back to back; none a millisecond later).  Over USB the adapter has sent it by then.
WRITE_SETTLE_S = 0.005
#: How long a move may take to arrive (it takes a few hundred ms; the machine may be busy).
ARRIVE_S = 5.0


class Recorded(BaseErrorHandler):
    """pypot's error handler that keeps what the servos reported (its default only logs)."""

    def __init__(self) -> None:
        self.errors: list[str] = []

    def handle_angle_limit_error(self, instruction_packet) -> None:
        self.errors.append(f"angle limit: {instruction_packet}")

    def handle_range_error(self, instruction_packet) -> None:
        self.errors.append(f"range: {instruction_packet}")

    def handle_timeout(self, timeout_error) -> None:
        self.errors.append(f"timeout: {timeout_error}")


@pytest.fixture
def dxl(emulator):
    """A pypot DxlIO on a served bus of three AX-12As, and its error handler; closed after the test."""
    served = emulator("--ids", "1-3")
    io = pd.DxlIO(served.port, baudrate=1_000_000, timeout=0.2, error_handler_cls=Recorded)
    try:
        yield io, io._error_handler
    finally:
        io.close()


def _arrived(io, goals: dict[int, float], tolerance_deg: float = 1.5) -> dict[int, float]:
    """Poll Present Position until every servo is within ``tolerance_deg`` of its goal (or :data:`ARRIVE_S`)."""
    ids = list(goals)
    deadline = time.monotonic() + ARRIVE_S
    while True:
        now = dict(zip(ids, io.get_present_position(ids)))
        if all(abs(now[i] - goals[i]) <= tolerance_deg for i in ids) or time.monotonic() > deadline:
            return now
        time.sleep(0.02)


def test_pypot_finds_the_served_servos_and_their_model(dxl):
    io, handler = dxl
    assert io.scan(range(8)) == [1, 2, 3]
    assert io.get_model([1, 2, 3]) == ("AX-12",) * 3
    # the factory state pypot converts to its units: centred, 9.6 V, the e-manual's compliance
    assert all(abs(p) < 0.5 for p in io.get_present_position([1, 2, 3]))
    assert io.get_compliance_margin([1]) == ((1, 1),) and io.get_compliance_slope([1]) == ((32, 32),)
    assert io.get_angle_limit([2])[0] == pytest.approx((-150.0, 150.0), abs=0.2)
    assert handler.errors == []


def test_pypot_moves_servos_with_a_sync_write_and_reads_where_they_went(dxl):
    """pypot sends several goals as one Sync Write; each servo goes to its own and says it has stopped."""
    io, handler = dxl
    io.enable_torque([1, 2])
    time.sleep(WRITE_SETTLE_S)
    io.set_moving_speed({1: 200.0, 2: 200.0})
    time.sleep(WRITE_SETTLE_S)
    goals = {1: 30.0, 2: -45.0}
    io.set_goal_position(goals)
    time.sleep(WRITE_SETTLE_S)
    where = _arrived(io, goals)
    assert all(abs(where[i] - goals[i]) <= 1.5 for i in goals), where
    # settling within its compliance, Moving reads 1 while the shaft still turns (a turning point reads 0 once)
    deadline, still = time.monotonic() + ARRIVE_S, 0
    while still < 5 and time.monotonic() < deadline:
        still = 0 if any(io.is_moving([1, 2])) else still + 1
        time.sleep(0.02)
    assert still == 5, "Moving did not stay 0 on both servos for 0.1 s"
    assert io.get_present_position([3]) == pytest.approx((0.0,), abs=0.5)  # not in the Sync Write: not moved
    assert handler.errors == []


def test_pypot_writes_the_eeprom_and_switches_a_servo_to_wheel_mode(dxl):
    io, handler = dxl
    io.set_angle_limit({3: (-45.0, 45.0)})
    time.sleep(EEPROM_SETTLE_S)
    assert io.get_angle_limit([3])[0] == pytest.approx((-45.0, 45.0), abs=0.3)
    io.set_wheel_mode([3])
    time.sleep(EEPROM_SETTLE_S)
    assert io.get_control_mode([3]) == ("wheel",)
    io.enable_torque([3])
    time.sleep(WRITE_SETTLE_S)
    assert io.is_torque_enabled([3]) == (True,)
    # In wheel mode Moving Speed sets the output, CW with bit 10, and Present Speed reads that output back (the
    # e-manual's 0.1 % a unit for both; pypot converts them as speeds): the shaft turns at what the load allows.
    io.set_moving_speed({3: -300.0})
    time.sleep(WRITE_SETTLE_S)
    time.sleep(0.3)  # Present Speed is held for 0.1 s at a time
    (asked,), (speed,) = io.get_moving_speed([3]), io.get_present_speed([3])
    assert asked < 0 and speed == pytest.approx(asked), (asked, speed)
    seen = set()
    for _ in range(6):  # turning: readings change (a third of a turn or more over 0.5 s; the 60-degree gap reads pinned)
        seen.add(io.get_present_position([3])[0])
        time.sleep(0.1)
    assert len(seen) > 2, seen
    assert handler.errors == []


def test_a_goal_beyond_the_angle_limit_is_not_taken_and_pypot_hears_nothing(dxl):
    """pypot writes every setting as a Sync Write, which no servo answers: a goal past the CCW limit is
    refused (nothing written, request_handler's policy) without a word, and the servo stays where it was; a
    goal inside the limits is taken."""
    io, handler = dxl
    io.set_angle_limit({1: (-30.0, 30.0)})
    time.sleep(EEPROM_SETTLE_S)
    io.enable_torque([1])
    time.sleep(WRITE_SETTLE_S)
    io.set_goal_position({1: 60.0})
    time.sleep(0.5)
    assert io.get_present_position([1])[0] == pytest.approx(0.0, abs=0.5)
    assert io.get_goal_position([1])[0] == pytest.approx(0.0, abs=0.5)
    io.set_goal_position({1: 25.0})
    time.sleep(WRITE_SETTLE_S)
    assert abs(_arrived(io, {1: 25.0})[1] - 25.0) <= 1.5
    assert handler.errors == []
