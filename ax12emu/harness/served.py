"""``ax12emu serve`` as a child process: started, its port read from its first stdout line, stopped by its own pid.

Why it exists: tests, the live-recording tools and anyone scripting a run
against a real serving process need the same three steps, and a process
must be stopped by the id it was started with, even when the caller fails
(also when interrupted while it waits for the port line).

The child's stderr (its log: a line per packet with ``-v``) goes to an
unlinked temporary file, read through ``process.stderr``: a pipe that no
one reads fills at 64 KiB and then blocks the child mid-write, so it stops
answering and no longer sees SIGTERM.  Its stdout stays a pipe: ``serve``
prints two lines there at most (the port, the live view's address), which
callers read as they come.

On Linux the child dies with its starter: it is sent SIGTERM (``PR_SET_PDEATHSIG``) when the process that
started it dies, also of SIGKILL (a CI job's timeout), where no clean-up of the caller's runs; otherwise it
went on serving and kept its ``--state-dir`` locked, so the next run on that folder was refused.  The kernel
ties that signal to the *thread* that started the child, so it is asked for from the main thread only: a
child started from another thread would be stopped when that thread ends.  Elsewhere (macOS has no such
call) a child outlives a killed caller, as it does when started from another thread.
"""

from __future__ import annotations

import ctypes
import os
import select
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

__all__ = ["ServedProcess", "start_served"]

#: prctl(2)'s option for the signal a process gets when its parent dies (linux/prctl.h).
_PR_SET_PDEATHSIG = 1
#: What a child whose parent died before it could ask for the signal exits with: as if SIGTERM had come.
_ORPHAN_EXIT = 128 + signal.SIGTERM


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
    nothing within ``timeout_s``; the process is killed first, as it is
    when anything else (Ctrl-C, a test's timeout) ends the wait.
    """
    log_fd, log_path = tempfile.mkstemp(prefix="ax12emu-serve-", suffix=".log")
    try:
        log_reader = open(log_path, encoding="utf-8", errors="replace")
    finally:
        os.unlink(log_path)  # gone from the directory; the child's descriptor and the reader keep the file
    process: subprocess.Popen | None = None
    try:
        process = subprocess.Popen([sys.executable, "-m", "ax12emu", "serve", *args], cwd=cwd,
                                   stdout=subprocess.PIPE, stderr=log_fd, text=True, preexec_fn=_dying_with_parent())
        process.stderr = log_reader  # read as a pipe's end would be: process.stderr.read() once stopped
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            ready, _, _ = select.select([process.stdout], [], [], 0.1)
            if ready:
                line = process.stdout.readline().strip()
                if line:
                    return ServedProcess(process, line)
            if process.poll() is not None:
                break
    except BaseException:  # the child is ours to stop by its own pid, whatever ended the wait (Ctrl-C, a timeout)
        if process is not None:
            _kill(process)
        log_reader.close()
        raise
    finally:
        os.close(log_fd)  # the child has its own copy
    assert process is not None  # (started: the wait ran out, or the child exited first)
    _kill(process)
    err = log_reader.read()
    log_reader.close()
    raise RuntimeError(f"ax12emu serve {' '.join(args)} did not start: {err.strip()}")


def _dying_with_parent() -> Callable[[], None] | None:
    """What the child runs between fork and exec to be sent SIGTERM when this process dies (module docstring);
    None off Linux or off the main thread."""
    if not sys.platform.startswith("linux") or threading.current_thread() is not threading.main_thread():
        return None
    prctl = ctypes.CDLL(None, use_errno=True).prctl  # looked up before the fork: the child only calls it
    parent_pid = os.getpid()

    def ask() -> None:
        prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM))
        if os.getppid() != parent_pid:  # the parent died between the fork and the prctl: no signal will come
            os._exit(_ORPHAN_EXIT)

    return ask


def _kill(process: subprocess.Popen) -> None:
    """Kill the child by its own pid and reap it; its stdout pipe is closed (its log stays readable)."""
    if process.poll() is None:
        os.kill(process.pid, signal.SIGKILL)
    process.wait(5)
    if process.stdout is not None:
        process.stdout.close()
