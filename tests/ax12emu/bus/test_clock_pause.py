"""WallClock pause, resume and stepping while paused (the live view's time controls)."""

from __future__ import annotations

import time

import pytest

from ax12emu.bus.clock import WallClock


def test_paused_time_stands_still_and_resumes_where_it_stood():
    clock = WallClock(time_scale=2.0)
    clock.pause()
    frozen = clock.now_s()
    time.sleep(0.02)
    assert clock.now_s() == frozen and clock.paused
    clock.resume()
    assert not clock.paused
    assert frozen <= clock.now_s() < frozen + 0.02  # no jump by the paused span
    time.sleep(0.02)
    assert clock.now_s() >= frozen + 0.04 * 0.9  # at twice the wall clock again


def test_stepping_while_paused_moves_by_exactly_the_step():
    clock = WallClock(time_scale=0.5)
    clock.pause()
    before = clock.now_s()
    assert clock.advance(0.25) == pytest.approx(before + 0.25)
    assert clock.now_s() == pytest.approx(before + 0.25)
    clock.resume()
    assert clock.now_s() == pytest.approx(before + 0.25, abs=0.01)


def test_a_running_wall_clock_cannot_be_stepped_or_go_back():
    clock = WallClock()
    with pytest.raises(RuntimeError, match="only while paused"):
        clock.advance(0.1)
    clock.pause()
    with pytest.raises(ValueError, match="backwards"):
        clock.advance(-0.1)
