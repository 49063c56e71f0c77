"""start_served: the child's log never blocks it, an interrupted start leaves no child behind, and on Linux the child
dies with a caller killed outright."""

from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
import time

import pytest
import serial

from ax12emu.harness import served
from ax12emu.protocol.packets import encode_instruction, encode_status

PING = 0x01


def test_the_log_is_a_file_read_through_process_stderr():
    """Its stderr is no pipe that fills (64 KiB) and stops the child; process.stderr still reads the log."""
    process = served.start_served(["--ids", "1", "-v"])
    try:
        assert stat.S_ISREG(os.fstat(process.process.stderr.fileno()).st_mode)
        with serial.serial_for_url(process.port, baudrate=1_000_000, timeout=0.5) as link:
            link.write(encode_instruction(1, PING))
            assert link.read(6) == encode_status(1, 0)
        assert process.stop() == 0
        assert "rx PING id=1" in process.process.stderr.read()
    finally:
        process.close()


@pytest.mark.wallclock
def test_a_serve_logging_every_packet_answers_past_a_pipes_worth_of_log():
    """-v logs about 120 bytes a ping: 1000 pings are twice what a pipe held before the child blocked mid-write
    (it then stopped answering and ignored SIGTERM)."""
    process = served.start_served(["--ids", "1", "-v"])
    try:
        with serial.serial_for_url(process.port, baudrate=1_000_000, timeout=0.5) as link:
            for i in range(1000):
                link.write(encode_instruction(1, PING))
                assert link.read(6) == encode_status(1, 0), f"ping {i} unanswered"
        assert process.stop(timeout_s=5.0) == 0  # SIGTERM heard, not a kill
    finally:
        process.close()


def test_an_interrupted_wait_for_the_port_line_kills_the_child(monkeypatch):
    """Ctrl-C (or a test's timeout) while start_served waits: the child it started is killed and reaped, by its pid."""
    started: list[subprocess.Popen] = []
    real_popen = subprocess.Popen

    def popen(*args, **kwargs):
        started.append(real_popen(*args, **kwargs))
        return started[-1]

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(served.subprocess, "Popen", popen)
    monkeypatch.setattr(served.select, "select", interrupted)
    with pytest.raises(KeyboardInterrupt):
        served.start_served(["--ids", "1"])
    (child,) = started
    assert child.returncode is not None  # reaped: no process, no zombie (the autouse check sees no child left)
    assert child.stdout.closed and child.stderr.closed


def test_a_serve_that_fails_to_start_is_reported_with_its_log():
    with pytest.raises(RuntimeError, match="did not start: .*unrecognized arguments: --no-such-flag"):
        served.start_served(["--no-such-flag"])


def _running(pid: int) -> bool:
    """Whether ``pid`` is a live process (not gone, not a zombie left for its new parent to reap)."""
    try:
        with open(f"/proc/{pid}/stat") as stat_file:
            return stat_file.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the child dies with its starter on Linux only")
def test_a_child_dies_with_a_caller_killed_by_sigkill(tmp_path):
    """A test process killed with SIGKILL (a CI timeout) runs no clean-up: its serve child went on serving and kept
    its --state-dir locked, so the next run on that folder was refused."""
    caller = (
        "import os, signal, sys\n"
        "from ax12emu.harness.served import start_served\n"
        f"served = start_served(['--ids', '1', '--state-dir', {str(tmp_path)!r}])\n"
        "print(served.process.pid, flush=True)\n"
        "os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    killed = subprocess.run([sys.executable, "-c", caller], capture_output=True, text=True, timeout=60)
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    child = int(killed.stdout.split()[0])
    try:
        deadline = time.monotonic() + 10.0
        while _running(child) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _running(child)
        served.start_served(["--ids", "1", "--state-dir", str(tmp_path)]).close()  # the folder is free again
    finally:
        if _running(child):
            os.kill(child, signal.SIGKILL)
