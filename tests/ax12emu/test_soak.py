"""A short soak through dynamixel-sdk (tools/soak.py): no lost or wrong reply, servos moving, memory flat."""

from __future__ import annotations

import pytest
from emu_testkit import load_tool

#: Real time and real ports: the wall-clock tier (CI runs it too).
pytestmark = pytest.mark.wallclock

soak = load_tool("soak")


def test_three_second_soak_loses_nothing(emulator):
    """3 s of back-to-back requests to 3 moving servos: every reply arrives and is right (but those the machine kept a
    process from, see ``soak.STARVED_S``); RSS is read from /proc."""
    served = emulator("--ids", "1-3")
    result = soak.soak(served.port, served.process.pid, 3.0, 3, goal_period_s=0.3, warmup_s=0.5)
    text = soak.report(result, 3)
    assert result.requests > 300, text
    # Losses while the emulator or the client waited 32 ms or more for a CPU are the machine's (a loaded runner's):
    # the same rule as the Protocol 2.0 and mixed soaks (tests/tools/test_soak2.py, ``soak.STARVED_S``).
    assert result.lost_by_emulator == 0 and result.wrong_by_emulator == 0, text
    assert result.moving_seen > 0, text
    assert result.rss_start_kb > 0 and abs(result.rss_growth_kb) <= soak.RSS_LIMIT_KB, text
