"""docs/lerobot.md's "A gripper holding an object": the figures it gives are the served XL330-M288's.

The gripper is blocked (``faults.stall``) in Current-based Position Control Mode and its goal set past the
contact; the page's currents and Overload times are read back through dynamixel-sdk in virtual time.
"""

from __future__ import annotations

import pytest
from dynamixel_sdk import COMM_SUCCESS, PacketHandler

import ax12emu
from tests.emu_testkit import UrlPortHandler, ok


def done(result: tuple) -> None:
    """A write's (comm_result, error) pair must have succeeded cleanly."""
    ok((None, *result))

OPERATING_MODE, TORQUE_ENABLE, HARDWARE_ERROR, GOAL_CURRENT, GOAL_POSITION, PRESENT_CURRENT = 11, 64, 70, 102, 116, 126
CURRENT_BASED_POSITION = 5
OVERLOAD = 0x20
PULSES_PER_DEG = 4096 / 360


def grasp(past_contact_deg: float, goal_current: int | None, limit_s: float) -> tuple[float, float | None]:
    """Present Current (mA) 0.2 s into the grasp, and the seconds until Overload (None: held for ``limit_s``)."""
    with ax12emu.VirtualBus(servo="xl330-m288", transport="inprocess", virtual_time=True) as bus:
        port, packets = UrlPortHandler(bus.port), PacketHandler(2.0)
        port.baudrate = 57_600
        assert port.openPort()
        try:
            done(packets.write1ByteTxRx(port, 1, OPERATING_MODE, CURRENT_BASED_POSITION))
            if goal_current is not None:
                done(packets.write2ByteTxRx(port, 1, GOAL_CURRENT, goal_current))
            done(packets.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1))
            bus.step(0.2)
            bus.faults.stall(1)
            contact = ok(packets.read4ByteTxRx(port, 1, 132))
            done(packets.write4ByteTxRx(port, 1, GOAL_POSITION, contact + round(past_contact_deg * PULSES_PER_DEG)))
            bus.step(0.2)
            current_ma = ok(packets.read2ByteTxRx(port, 1, PRESENT_CURRENT))
            t_s = 0.2
            while t_s < limit_s:
                bus.step(0.05)
                t_s += 0.05
                status, comm, _alert = packets.read1ByteTxRx(port, 1, HARDWARE_ERROR)  # its status carries the Alert bit
                assert comm == COMM_SUCCESS, comm
                if status & OVERLOAD:
                    return current_ma, t_s
            return current_ma, None
        finally:
            port.closePort()


@pytest.mark.parametrize(
    ("past_deg", "goal_current", "page_ma", "page_trip_s"),
    [(20, None, 360, None), (40, None, 710, 3.3), (58, None, 1030, 1.7), (90, 800, None, 2.6), (90, 500, None, 8.4),
     (90, 300, None, None)],
)
def test_the_pages_grasp_figures(past_deg, goal_current, page_ma, page_trip_s):
    current_ma, trip_s = grasp(past_deg, goal_current, limit_s=20.0)
    if page_ma is not None:  # the page rounds to tens of mA
        assert abs(current_ma - page_ma) <= 0.05 * page_ma, current_ma
    if page_trip_s is None:
        assert trip_s is None, trip_s
    else:  # the page's "about": within a tenth, and the 50 ms polling
        assert trip_s is not None and abs(trip_s - page_trip_s) <= 0.1 * page_trip_s + 0.05, trip_s
