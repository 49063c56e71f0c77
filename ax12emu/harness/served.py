"""``ax12emu serve`` as a child process: started, its port read from its first stdout line, stopped by its own pid.

Why it exists: tests, the live-recording tools and anyone scripting a run
against a real serving process need the same three steps, and a process
must be stopped by the id it was started with, even when the caller fails.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

__all__ = ["ServedProcess", "start_served"]


@dataclass
class ServedProcess:
    """A running ``ax12emu serve`` and the port it printed."""

    process: subprocess.Popen
    port: str

    def stop(self, sig: int = signal.SIGTERM, timeout_s: float = 10.0) -> int:
        """Signal the process and wait for it; kill it if it does not exit.  Its pipes stay open to be read."""
        if self.process.poll() is None:
            os.kill(self.process.pid, sig)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                os.kill(self.process.pid, signal.SIGKILL)
                self.process.wait(timeout_s)
        return self.process.returncode

    def close(self) -> None:
        """Stop the process and close its pipes."""
        self.stop()
        for stream in (self.process.stdout, self.process.stderr):
            if stream:
                stream.close()


def start_served(args: Sequence[str], *, cwd: str | os.PathLike[str] | Path | None = None,
                 timeout_s: float = 20.0) -> ServedProcess:
    """Start ``python -m ax12emu serve ARGS`` (in ``cwd``) and wait for the port line on its stdout.

    Raises RuntimeError with the process's stderr if it exits or prints
    nothing within ``timeout_s``; the process is killed first.
    """
    process = subprocess.Popen([sys.executable, "-m", "ax12emu", "serve", *args], cwd=cwd,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        ready, _, _ = select.select([process.stdout], [], [], 0.1)
        if ready:
            line = process.stdout.readline().strip()
            if line:
                return ServedProcess(process, line)
        if process.poll() is not None:
            break
    process.kill()
    _, err = process.communicate(timeout=5)
    raise RuntimeError(f"ax12emu serve {' '.join(args)} did not start: {err.strip()}")
