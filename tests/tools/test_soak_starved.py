"""tools/soak.py: losses counted apart when the machine kept the emulator or the client off its CPU, and how that is read."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest
from emu_testkit import load_tool

soak = load_tool("soak")

LOST = -3001  # dynamixel-sdk's COMM_RX_TIMEOUT


def _passing() -> soak.SoakResult:
    """A result whose memory stayed flat and whose servos moved: only the replies decide."""
    return soak.SoakResult(moving_seen=1, rss_start_kb=1000, rss_end_kb=1000)


ON_CPU = soak.OffCpu(0.0, 0.0, 0)


def held_off(off_s: float, stretches: int = 1, waiting_s: float = 0.0) -> soak.OffCpu:
    return soak.OffCpu(off_s, waiting_s, stretches)


def test_a_loss_while_a_process_was_held_off_its_cpu_is_the_machines():
    result = _passing()
    result.count("READ", 1.0, LOST, 0, False, (held_off(soak.STARVED_S + 0.01), ON_CPU))
    result.count("READ after it", 1.0, soak.COMM_SUCCESS, 0, True)  # the late answer to the lost request
    assert (result.lost, result.lost_starved, result.wrong, result.wrong_after_starved) == (1, 1, 1, 1)
    assert result.lost_by_emulator == 0 and result.wrong_by_emulator == 0
    assert result.ok
    assert "emulator 42.0 ms in 1 (0.0 ms waiting for a CPU), client 0.0 ms in 1" in result.problems[0]


def test_the_clients_wait_counts_as_well():
    result = _passing()
    result.count("READ", 1.0, LOST, 0, False, (ON_CPU, soak.OffCpu(soak.STARVED_S, 0.01, 2, longest_sleep_s=0.0)))
    assert result.lost_starved == 1 and result.ok


def test_many_short_absences_of_the_emulator_are_not_a_hold_off():
    """Off its CPU 40 ms in 20 stretches, not waiting for one: up to 20 ms of that may be the sleeps it
    chooses (1 ms each at most, its physics period), so only 20 ms were surely the machine's: the loss is its own."""
    result = _passing()
    result.count("READ", 1.0, LOST, 0, False, (held_off(0.04, stretches=20), ON_CPU))
    assert result.lost_starved == 0 and not result.ok


def test_each_stretch_off_the_cpu_holds_at_most_one_chosen_sleep():
    assert held_off(0.04, stretches=5).kept_off_s == pytest.approx(0.04 - 5 * soak.EMULATOR_LONGEST_SLEEP_S)
    assert held_off(0.04, stretches=5).held_off
    assert not held_off(0.04, stretches=9).held_off


def test_the_emulator_waiting_for_a_cpu_in_many_stretches_is_held_off():
    assert held_off(0.04, stretches=20, waiting_s=soak.STARVED_S).held_off


def test_a_wait_begun_before_the_request_counts_only_as_far_as_the_request_was_off_its_cpu():
    assert not held_off(0.02, stretches=20, waiting_s=0.09).held_off


def test_the_client_never_sleeps_by_choice_so_any_absence_counts():
    scattered = soak.OffCpu(0.04, 0.0, 20, longest_sleep_s=0.0)
    assert scattered.held_off
    assert not soak.OffCpu(soak.STARVED_S * 0.9, 0.0, 1, longest_sleep_s=0.0).held_off


def test_an_unusable_reply_right_after_a_starved_loss_is_the_late_answer():
    result = _passing()
    result.count("READ", 1.0, LOST, 0, False, (held_off(1.0), ON_CPU))
    result.count("WRITE", 1.0, soak.COMM_RX_CORRUPT, 0, False, (ON_CPU, ON_CPU))
    result.count("Sync Read, ID 1", 1.0, soak.COMM_RX_CORRUPT, 0, False, (ON_CPU, ON_CPU))
    assert result.lost == 3 and result.lost_starved == 3 and result.ok


def test_a_timeout_right_after_a_starved_loss_is_judged_on_its_own():
    result = _passing()
    result.count("READ", 1.0, LOST, 0, False, (held_off(1.0), ON_CPU))
    result.count("READ", 1.0, LOST, 0, False, (ON_CPU, ON_CPU))
    assert result.lost_by_emulator == 1 and not result.ok


def test_off_cpu_is_the_wall_time_not_spent_running():
    off = soak.OffCpu.between((1.0, 2.0, 10), (1.005, 2.03, 12), 0.045)
    assert off == soak.OffCpu(pytest.approx(0.04), pytest.approx(0.03), 2)
    assert off.held_off


def test_a_loss_without_a_long_wait_fails_the_soak():
    result = _passing()
    result.count("READ", 1.0, LOST, 0, False, (held_off(soak.STARVED_S * 0.9), held_off(soak.STARVED_S * 0.9)))
    result.count("READ after it", 1.0, soak.COMM_SUCCESS, 0, True)
    assert result.lost_by_emulator == 1 and result.wrong_after_lost == 1 and result.wrong_by_emulator == 1
    assert not result.ok


def test_a_loss_whose_waits_are_unknown_fails_the_soak():
    result = _passing()
    result.count("READ", 1.0, LOST, 0, False, None)
    assert result.lost_by_emulator == 1 and not result.ok


def test_a_wrong_reply_not_right_after_a_starved_loss_fails_the_soak():
    result = _passing()
    result.count("READ", 1.0, LOST, 0, False, (held_off(1.0), held_off(1.0)))
    result.count("READ", 1.0, soak.COMM_SUCCESS, 0, False)
    result.count("READ", 1.0, soak.COMM_SUCCESS, 0x08, False)
    assert result.wrong == 1 and result.wrong_after_lost == 0 and result.wrong_by_emulator == 1
    assert not result.ok


def test_the_verdict_line_says_how_many_losses_were_starved():
    result = _passing()
    result.seconds = 1.0
    result.requests = 10
    result.slices = [soak.Slice(latencies_s=[0.001])]
    result.count("READ", 1.0, LOST, 0, False, (held_off(1.0), ON_CPU))
    assert soak.report(result, 1).splitlines()[-1] == "PASS (1 lost while starved of a CPU, which does not count)"


def test_a_problem_of_its_own_is_listed_after_the_last_starved_loss():
    """Late answers may trail a starved loss by several requests, so the list shows it before the problem."""
    result = _passing()
    for k in range(12):
        result.count(f"READ {k}", 1.0, LOST, 0, False, (held_off(1.0), ON_CPU))
    result.count("READ", 1.0, soak.COMM_SUCCESS, 0, False)
    result.count("READ Moving", 2.0, soak.COMM_SUCCESS, 0, True)
    assert len(result.problems) == 12
    assert result.problems[-2].startswith("(the last starved loss before it) lost at 1.0 s, starved: READ 11")
    assert result.problems[-1].startswith("wrong at 2.0 s: READ Moving")


def test_no_such_process_has_no_figures():
    stat = soak.SchedStat(2**22 + 12345)  # above Linux's largest pid
    assert stat.read() is None
    stat.close()


@pytest.mark.wallclock
@pytest.mark.skipif(not os.path.exists(f"/proc/{os.getpid()}/schedstat") or not hasattr(os, "sched_setaffinity"),
                    reason="needs Linux's /proc/PID/schedstat and CPU affinity")
def test_a_thread_sharing_its_cpu_with_busy_ones_is_seen_waiting():
    """Pinned to one CPU with two processes that never sleep, a busy thread runs about a third of the
    time and waits the rest: the figures read are its run time and its wait, which add up to the wall time."""
    cpu = min(os.sched_getaffinity(0))
    mine = os.sched_getaffinity(0)
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    stat = soak.SchedStat(os.getpid())
    try:
        for hog in hogs:
            os.sched_setaffinity(hog.pid, {cpu})
        os.sched_setaffinity(0, {cpu})
        before, wall_s, cpu_s = stat.read(), time.monotonic(), time.thread_time()
        while time.monotonic() < wall_s + 0.3:
            pass
        after = stat.read()
        wall_s, cpu_s = time.monotonic() - wall_s, time.thread_time() - cpu_s
    finally:
        os.sched_setaffinity(0, mine)
        for hog in hogs:
            hog.kill()
            hog.wait()
        stat.close()
    off = soak.OffCpu.between(before, after, wall_s)
    ran_s = after[0] - before[0]
    text = f"ran {ran_s * 1e3:.1f} ms (thread_time {cpu_s * 1e3:.1f} ms), {off} of {wall_s * 1e3:.1f} ms"
    assert abs(ran_s - cpu_s) <= 0.02, text
    assert off.waiting_s >= 0.1 * wall_s, text
    assert abs(off.waiting_s - off.off_s) <= 0.03 + 0.1 * wall_s, text  # never blocked: off its CPU only waiting for it


def test_a_servo_that_never_moved_half_a_goal_flip_fails_the_soak():
    result = _passing()
    result.spans = {"ID 1, Protocol 1.0": (200, 790, 600), "ID 1, Protocol 2.0": (1990, 2480, 1000)}
    assert result.still == ["ID 1, Protocol 2.0"] and not result.ok
    result.spans["ID 1, Protocol 2.0"] = (1500, 2010, 1000)
    assert result.ok


def test_an_ax12a_whose_moving_never_read_1_after_a_goal_fails_the_soak_an_x_series_one_need_not():
    result = _passing()
    result.moving_checks, result.moving_seen = 40, 0  # X-series, no profile: Moving follows the speed
    assert result.ok
    result.moving_checks_1, result.moving_seen_1 = 20, 0
    assert not result.ok
    result.moving_seen_1 = 20
    assert result.ok


def test_a_failed_run_names_why_and_an_alarm_the_servo_raised_apart():
    """A run that failed on wrong replies said "FAIL (67 lost while starved of a CPU)": the losses that do not
    count, not the replies that did. Replies carrying the servo's alarm are named as such (the physics' alarm,
    an X series' Overload under goals flipped every 0.2 s, not a bus fault)."""
    result = soak.SoakResult(seconds=10.0, goal_period_s=0.2)
    result.count("READ Present Position of ID 2", 7.5, soak.COMM_SUCCESS, 0x80, False)
    result.count("READ Present Position of ID 1", 7.6, soak.COMM_SUCCESS, 0, True)
    result.slices = [soak.Slice(latencies_s=[0.001])]
    assert not result.ok
    last = soak.report(result, 1).splitlines()[-1]
    assert last.startswith("FAIL: 2 replies wrong, 1 carrying the servo's alarm") and "every 0.2 s" in last, last


def test_the_alarm_count_counts_the_wrong_replies_the_verdict_counts():
    """Late answers after a starved loss do not count as wrong; those carrying an alarm bit do not count as alarmed."""
    result = soak.SoakResult(seconds=10.0, goal_period_s=0.5)
    result._previous = "starved"
    result.count("READ Present Position of ID 1", 1.0, soak.COMM_SUCCESS, 0x80, False)
    assert (result.wrong, result.wrong_by_emulator, result.alarmed) == (1, 0, 0)
