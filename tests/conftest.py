"""Shared fixtures: a real ``ax12emu serve`` process, cleaned up by its own process id."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest

# Test modules import their shared helpers (emu_testkit) from this folder.
sys.path.insert(0, os.path.dirname(__file__))


@dataclass
class Served:
    """A running emulator process and the port it printed."""

    process: subprocess.Popen
    port: str

    def stop(self, sig: int = signal.SIGTERM, timeout_s: float = 10.0) -> int:
        """Signal the process and wait for it; kill it if it does not exit."""
        if self.process.poll() is None:
            os.kill(self.process.pid, sig)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                os.kill(self.process.pid, signal.SIGKILL)
                self.process.wait(timeout_s)
        return self.process.returncode


def start_emulator(*args: str, timeout_s: float = 20.0) -> Served:
    """Start ``python -m ax12emu serve ARGS`` and wait for the port line on stdout."""
    process = subprocess.Popen(
        [sys.executable, "-m", "ax12emu", "serve", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        ready, _, _ = select.select([process.stdout], [], [], 0.1)
        if ready:
            line = process.stdout.readline().strip()
            if line:
                return Served(process, line)
        if process.poll() is not None:
            break
    process.kill()
    _, err = process.communicate(timeout=5)
    raise RuntimeError(f"emulator did not start: {err.strip()}")


@pytest.fixture
def emulator() -> Iterator[Callable[..., Served]]:
    """Factory: start emulators; every one is stopped by pid when the test ends, pass or fail."""
    started: list[Served] = []

    def _start(*args: str) -> Served:
        served = start_emulator(*args)
        started.append(served)
        return served

    yield _start
    for served in started:
        served.stop()
        for stream in (served.process.stdout, served.process.stderr):
            if stream:
                stream.close()
