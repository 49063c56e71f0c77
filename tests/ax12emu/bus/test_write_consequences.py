"""The request after a write sees what the firmware computes from it, in virtual time.

A real AX-12 runs its control loop every 1 ms and a host's next packet
cannot arrive over USB before it has run, so the first read after a write
already shows the write's consequence.  The bus steps the model one control
step past each write before answering the next request (``Plant.catch_up``);
these checks hold whether physics was up to date at the write (``request_lag_s``
0, the default) or a step behind, as under the serving loop.
"""

from __future__ import annotations

import copy

import pytest

from ax12emu.bus import Bus
from ax12emu.bus.clock import VirtualClock
from ax12emu.protocol.control_table import layout
from ax12emu.protocol.packets import Instruction, encode_instruction
from ax12emu.servo.virtual_servo import ServoOptions
from firmware_model.backend import NUMPY, SCALAR

LAY = layout("ax12a")
STEP_S = 1e-3
#: Registers the firmware computes, compared with the model's own answer after one step.
SENSED = ("present_position", "present_speed", "present_load", "moving")


def _bus(lag_s: float, **options) -> Bus:
    bus = Bus([1], clock=VirtualClock(), options=ServoOptions(eeprom_busy_s_per_byte=0.0, **options))
    bus.request_lag_s = lag_s
    return bus


def _write(bus: Bus, name: str, value: int) -> None:
    entry = LAY.by_name[name]
    data = bytes([entry.address]) + value.to_bytes(entry.size, "little")
    replies = bus.receive(encode_instruction(1, Instruction.WRITE, data))
    assert replies and replies[0].data[4] == 0, f"write {name}={value} failed: {replies}"


def _read(bus: Bus, name: str) -> int:
    entry = LAY.by_name[name]
    (reply,) = bus.receive(encode_instruction(1, Instruction.READ, bytes([entry.address, entry.size])))
    return int.from_bytes(reply.data[5:-1], "little")


def _run(bus: Bus, seconds: float) -> None:
    bus.clock.advance(seconds)
    bus.advance()


def _write_then_compare(bus: Bus, name: str, value: int) -> dict[str, int]:
    """Write, then read the sensed registers at the same instant; check them against the model stepped once.

    The twin is the model as the write left it, stepped one control step with
    the new commands: what the firmware has computed before the next packet
    (the model no further than the clock at the write, so the step is due).
    """
    _write(bus, name, value)
    twin = copy.deepcopy(bus.plant.model, {id(SCALAR): SCALAR, id(NUMPY): NUMPY})  # the backends are compared by identity
    expected = twin.advance(twin.time_s + twin.step_s, bus.plant.commands())
    seen = {register: _read(bus, register) for register in SENSED}
    assert bus.plant.model.time_s == pytest.approx(twin.time_s), "the write earned one control step"
    for register in SENSED:
        assert seen[register] == int(getattr(expected, register)[0]), (name, value, register, seen)
    return seen


LAGS = pytest.mark.parametrize("lag_s", [0.0, STEP_S], ids=["up-to-date", "a-step-behind"])


@LAGS
def test_goal_beyond_the_margin_reads_moving_on_the_first_read(lag_s):
    bus = _bus(lag_s)
    _write(bus, "torque_enable", 1)
    _run(bus, 0.05)
    assert _read(bus, "moving") == 0
    assert _read(bus, "moving") == 0  # now a reply-cache hit: it must not outlive the write below
    assert bus.reply_cache.hits >= 1
    seen = _write_then_compare(bus, "goal_position", 800)
    assert seen["moving"] == 1
    # Reversing toward a goal behind the shaft one step later: still moving, never a 0 in between.
    _run(bus, STEP_S)  # a write in the same step is taken with no time passing (test_write_burst.py)
    assert _write_then_compare(bus, "goal_position", 200)["moving"] == 1
    for _ in range(5):
        _run(bus, STEP_S)
        assert _read(bus, "moving") == 1


@LAGS
def test_torque_off_then_on(lag_s):
    bus = _bus(lag_s, goal_position_enables_torque=False)
    _write(bus, "goal_position", 800)  # with torque off: nothing moves
    _run(bus, 0.05)
    assert _read(bus, "moving") == 0 and _read(bus, "torque_enable") == 0
    assert _write_then_compare(bus, "torque_enable", 1)["moving"] == 1
    _run(bus, 0.1)
    assert _read(bus, "moving") == 1
    assert _write_then_compare(bus, "torque_enable", 0)["moving"] == 0


@LAGS
def test_moving_speed_in_wheel_mode(lag_s):
    bus = _bus(lag_s)
    _write(bus, "ccw_angle_limit", 0)  # both limits 0: wheel mode
    _write(bus, "torque_enable", 1)
    _run(bus, 0.05)
    assert _read(bus, "moving") == 0
    assert _write_then_compare(bus, "moving_speed", 400)["moving"] == 1


@LAGS
def test_torque_limit_0_cuts_the_drive_before_the_next_packet(lag_s):
    bus = _bus(lag_s)
    _write(bus, "torque_enable", 1)
    _write(bus, "goal_position", 900)
    _run(bus, 0.1)
    assert abs(float(bus.plant.model.drive[0])) > 0.1  # driving hard toward the goal
    _write_then_compare(bus, "torque_limit", 0)
    assert float(bus.plant.model.drive[0]) == 0.0


@LAGS
def test_angle_limits_and_compliance_are_acted_on_before_the_next_packet(lag_s):
    bus = _bus(lag_s)
    _write(bus, "torque_enable", 1)
    _run(bus, 0.05)
    _write_then_compare(bus, "cw_compliance_margin", 40)
    _run(bus, STEP_S)
    _write_then_compare(bus, "cw_angle_limit", 600)  # the goal (at 512) now lies below the limit: clamped to it
    assert _read(bus, "moving") == 1


def test_physics_runs_at_most_one_step_ahead_of_the_clock_per_write():
    """The step taken for a write is the control loop's, not extra time: the model leads the clock by at most one step."""
    bus = _bus(0.0)
    _write(bus, "torque_enable", 1)
    _run(bus, 0.02)
    _write(bus, "goal_position", 700)
    _read(bus, "moving")
    assert bus.plant.model.time_s == pytest.approx(0.02 + STEP_S)
    _read(bus, "moving")  # no write since: no further step
    assert bus.plant.model.time_s == pytest.approx(0.02 + STEP_S)
    _run(bus, 0.01)
    assert bus.plant.model.time_s == pytest.approx(0.03)


def test_reset_judges_alarms_under_the_factory_limits_not_the_ones_it_erased():
    """A servo overheating under a low Temperature Limit, then RESET: the fresh table keeps its Torque Limit.

    The alarms of the model's last step were raised under the limits RESET
    has just erased; tripping the Alarm Shutdown with them zeroed Torque Limit
    on the factory table (a case tools/fuzz.py found).  The next control step
    judges the alarms under the factory limits, as a rebooted firmware does.
    """
    bus = _bus(0.0)
    _write(bus, "torque_enable", 1)
    _write(bus, "temperature_limit", 15)  # below the servo's own temperature: Overheating at once
    _run(bus, 0.01)
    assert _read(bus, "torque_limit") == 0, "the overheat tripped the Alarm Shutdown (default Shutdown has bit 2)"
    (reply,) = bus.receive(encode_instruction(1, Instruction.RESET, b""))
    assert reply.data[4] & 0x08 == 0, "RESET is answered (its reply may still show the overheat it ends)"
    assert _read(bus, "torque_limit") == _read(bus, "max_torque")
    _run(bus, 0.01)
    assert _read(bus, "torque_limit") == _read(bus, "max_torque")
    (status,) = bus.receive(encode_instruction(1, Instruction.PING, b""))
    assert status.data[4] == 0, f"no alarm under the factory limits: {status.data[4]:#04x}"
