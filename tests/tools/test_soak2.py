"""Short soaks through dynamixel-sdk on Protocol 2.0 and on a mixed 1.0 + 2.0 wire (tools/soak.py)."""

from __future__ import annotations

import pytest
from emu_testkit import load_tool

#: Real time and real ports: the wall-clock tier (CI runs it too).
pytestmark = pytest.mark.wallclock

soak = load_tool("soak")


@pytest.mark.parametrize("protocol", ["2.0", "mixed"])
def test_three_second_soak_loses_nothing(emulator, protocol):
    """3 s of back-to-back requests (Read, Write, Sync Writes each followed by a Sync Read or a Fast Sync Read) to
    moving servos: every reply arrives and is right (but those the machine kept a process from, see
    ``soak.STARVED_S``)."""
    served = emulator(*soak.serve_args(2, protocol))
    result = soak.soak(served.port, served.process.pid, 3.0, 2, goal_period_s=0.3, warmup_s=0.5, protocol=protocol)
    text = soak.report(result, 2, protocol)
    assert result.requests > 200, text
    # Losses while the emulator or the client waited 32 ms or more for a CPU are the machine's (a loaded runner's).
    assert result.lost_by_emulator == 0 and result.wrong_by_emulator == 0, text
    assert result.spans and not result.still, text  # every servo went most of the way between its goals
    assert protocol == "2.0" or result.moving_seen_1 > 0, text  # an AX-12A reads Moving 1 right after a goal
    assert result.rss_start_kb > 0 and abs(result.rss_growth_kb) <= soak.RSS_LIMIT_KB, text


def test_serve_arguments_name_each_protocols_servos():
    assert soak.serve_args(4) == ["--ids", "1-4"]
    assert soak.serve_args(3, "2.0") == ["--servo", "1-3:xl430-w250", "--baud", "1000000"]
    assert soak.serve_args(2, "mixed") == ["--servo", "1-2:ax-12a,1-2:xl430-w250", "--baud", "1000000"]
