"""A serving loop's wall clock slips rather than asking the physics for more than MAX_STRIDE_S between two readings.

At a time scale the model cannot step as fast as (thousands; hundreds with many servos moving), each catch-up
took longer than the last and the serving loop never came back to a packet or a signal.  A clock read only when a
request comes (in process, ``ax12emu://``) is not bounded: a second between requests is a second of the servo's.
"""

from __future__ import annotations

import logging
import signal
import time

import pytest
from dynamixel_sdk import COMM_SUCCESS
from emu_testkit import sdk_port

from ax12emu.bus.clock import MAX_STRIDE_S, WallClock


def test_readings_far_apart_move_at_most_one_stride_and_the_rest_slips():
    clock = WallClock(time_scale=1e6)
    clock.bound_strides()
    first = clock.now_s()
    time.sleep(0.01)  # 10,000 simulated seconds of wall
    second = clock.now_s()
    assert first < second <= first + MAX_STRIDE_S
    assert clock.slipped_s > 1000
    time.sleep(0.001)
    assert second < clock.now_s() <= second + MAX_STRIDE_S  # still moving, as fast as it is read


def test_a_slow_start_before_the_first_reading_is_capped_without_a_warning(caplog):
    """A server may take a while between making its clock and first reading it: that stride is bounded too (at a
    huge scale it would be the first endless catch-up), but it is no news; a later slip is logged once."""
    clock = WallClock(time_scale=1e6)
    clock.bound_strides()
    time.sleep(0.01)
    with caplog.at_level(logging.WARNING, logger="ax12emu.bus.clock"):
        assert clock.now_s() <= MAX_STRIDE_S
        assert not caplog.records
        time.sleep(0.01)
        clock.now_s()
        time.sleep(0.01)
        clock.now_s()
    assert len(caplog.records) == 1 and "slipped" in caplog.records[0].getMessage()


def test_at_the_usual_scales_nothing_slips_and_a_step_by_hand_is_taken_whole():
    clock = WallClock(time_scale=2.0)
    clock.bound_strides()
    start = clock.now_s()
    time.sleep(0.05)
    assert 0.1 <= clock.now_s() - start < MAX_STRIDE_S and clock.slipped_s == 0  # (a loaded machine oversleeps)
    clock.pause()
    before = clock.now_s()
    assert clock.advance(5 * MAX_STRIDE_S) == pytest.approx(before + 5 * MAX_STRIDE_S)
    clock.resume()
    assert before + 5 * MAX_STRIDE_S <= clock.now_s() < before + 6 * MAX_STRIDE_S and clock.slipped_s == 0


@pytest.mark.wallclock
def test_a_clock_no_serving_loop_reads_keeps_the_time_between_requests():
    """In process and over ``ax12emu://`` the clock is read only when a request comes: an idle second and more is
    the servo's time too (bounded, the shaft stopped moving while the host slept)."""
    clock = WallClock()
    start = clock.now_s()
    time.sleep(1.3)
    assert clock.now_s() - start >= 1.3 and clock.slipped_s == 0


def test_a_served_bus_bounds_its_clock_and_an_in_process_one_does_not():
    from ax12emu import VirtualBus

    for transport, bounded in (("inprocess", False), ("pty", True)):
        with VirtualBus([1], transport=transport) as bus:
            assert (bus.bus.clock.stride_s == MAX_STRIDE_S) is bounded, transport


def test_an_infinite_time_scale_is_refused():
    with pytest.raises(ValueError, match="positive and finite"):
        WallClock(float("inf"))


@pytest.mark.wallclock
def test_a_server_far_beyond_the_models_speed_keeps_answering_and_stops_on_sigint(emulator):
    """``serve --time-scale 1e6`` with six servos moving: every write answered, and SIGINT stops it at once
    (it used to spin in one catch-up for good, deaf to both)."""
    served = emulator("--ids", "1-6", "--tcp", "127.0.0.1:0", "--time-scale", "1e6")
    with sdk_port(served.port, 1_000_000) as (port, ph):
        for servo_id in range(1, 7):
            assert ph.write1ByteTxRx(port, servo_id, 24, 1) == (COMM_SUCCESS, 0)
        for k in range(40):
            for servo_id in range(1, 7):
                assert ph.write2ByteTxRx(port, servo_id, 30, 200 if k % 2 else 800) == (COMM_SUCCESS, 0)
    started = time.monotonic()
    assert served.stop(signal.SIGINT, timeout_s=10.0) == 0
    assert time.monotonic() - started < 5.0
