"""Moving on the first read after a goal, on every served model, through packets, in virtual time.

A real servo's 1 ms control loop has run before a host's next packet can arrive over USB, so "write
the goal, poll Moving until 0" must not end at once.  What Moving means differs by table, and each is
checked as its e-manual page words it:

* AX and classic tables (AX-12A/18A, MX-28/64/106, XL-320): "1: Goal position command execution is
  in progress" (Moving(46)/(49), github ROBOTIS-GIT/emanual docs/en/dxl/ax/ax-12a.md,
  docs/en/dxl/mx/mx-28.md @ 01179568a085cfc99bdad6e880e43fa871bd318a, docs/en/dxl/x/xl320.md
  @ 05aa1bdfdfada3bb45a260a5bc60c6da6c016d6d): 1 from the first read, Moving Speed 0 ("the maximum rpm")
  included, and 0 once the move is over.
* X series: "If absolute value of Present Velocity(128) is greater than Moving Threshold(24), Moving(122)
  is set to '1' ... However, [it] will always be set to '1' regardless of Present Velocity(128) while
  Profile is in progress with Goal Position(116) instruction" (_includes/en/dxl/control_table_moving_2.md
  @ 7d10aced8ada4832331a7cd5f57ab080fcec8b78).  With a Profile Velocity a profile runs, so Moving and
  Moving Status's Profile Ongoing bit (0x02, _includes/en/dxl/control_table_moving_status.md) read 1 at
  once; with Profile Velocity 0 no profile is used (Moving Status bits 5:4 "00: Profile not used") and
  Moving is the velocity rule alone, read here in the same packet as Present Velocity and Moving Threshold.
"""

from __future__ import annotations

import pytest
from emu_testkit import RegisterLink

from ax12emu.bus.bus import Bus
from ax12emu.bus.clock import VirtualClock
from ax12emu.harness.servos2 import build_wire
from ax12emu.protocol.control_table import AX12_MODEL
from ax12emu.protocol.servo_models import model_names

#: Moves a little beyond every table's position margin (the AX's Compliance Margin of a unit or two, the
#: X firmware's In-Position window of 20 pulses, 1.8 deg) and a long one, in degrees so every table's units serve.
MOVES_DEG = (2.5, 30.0)
#: Moving Speed / Profile Velocity: 0 (the classic tables' "maximum rpm", the X series' no profile) and a slow speed.
SPEEDS = (0, 100)
PROFILE_ONGOING = 0x02
PROFILE_TYPE_BITS = 0x30


class Link(RegisterLink):
    """One servo, ID 1, of ``key``'s model on the bus the served wire would use, spoken to in its protocol."""

    def __init__(self, key: str) -> None:
        clock = VirtualClock()
        super().__init__(key, Bus([1], clock=clock) if key == AX12_MODEL else build_wire(f"1:{key}", clock=clock))


@pytest.mark.parametrize("speed", SPEEDS, ids=lambda s: f"speed{s}")
@pytest.mark.parametrize("move_deg", MOVES_DEG, ids=lambda d: f"{d}deg")
@pytest.mark.parametrize("key", model_names())
def test_the_first_read_after_a_goal_beyond_the_margin_says_moving(key, move_deg, speed):
    link = Link(key)
    profiled = "profile_velocity" in link.by_name
    link.write("profile_velocity" if profiled else "moving_speed", speed)
    link.write("torque_enable", 1)
    link.run_s(0.5)
    start = link.read("present_position")
    assert link.read("moving") == 0, "at rest before the goal"
    # Toward the middle of the range, whichever side the servo rests on.
    units = round(move_deg / link.spec.physical.resolution_deg)
    middle = round(link.spec.physical.position_range_deg / link.spec.physical.resolution_deg) // 2
    link.write("goal_position", start + units if start < middle else start - units)
    if profiled and speed == 0:
        first = link.registers("moving_threshold", "moving", "moving_status", "present_velocity")
        assert first["moving_status"] & (PROFILE_ONGOING | PROFILE_TYPE_BITS) == 0, first
        assert first["moving"] == int(abs(first["present_velocity"]) > first["moving_threshold"]), first
    else:
        first = link.registers("moving", *(("moving_status",) if profiled else ()))
        assert first["moving"] == 1, first
        if profiled:
            assert first["moving_status"] & PROFILE_ONGOING, first
    link.run_s(3.0)
    assert link.read("moving") == 0, "the move is over"
