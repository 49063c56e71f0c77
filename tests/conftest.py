"""Shared fixtures: a real ``ax12emu serve`` process, cleaned up by its own process id."""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from ax12emu.harness.served import ServedProcess, start_served

# Test modules import their shared helpers (emu_testkit) from this folder.
sys.path.insert(0, os.path.dirname(__file__))


#: A running emulator process and the port it printed (stopped by its own pid).
Served = ServedProcess


def start_emulator(*args: str, timeout_s: float = 20.0) -> Served:
    """Start ``python -m ax12emu serve ARGS`` and wait for the port line on stdout."""
    return start_served(args, timeout_s=timeout_s)


def _open_fds() -> set[int]:
    """Open descriptors (Linux); the listing's own, closed again by the time of the fstat, drops out."""
    if not os.path.isdir("/proc/self/fd"):
        return set()
    still_open = set()
    for name in os.listdir("/proc/self/fd"):
        try:
            os.fstat(int(name))
        except OSError:
            continue
        still_open.add(int(name))
    return still_open


def _children() -> set[int]:
    """Live child processes of this process (Linux: each thread's ``children`` list)."""
    pids: set[int] = set()
    try:
        for task in os.listdir("/proc/self/task"):
            with open(f"/proc/self/task/{task}/children") as listing:
                pids.update(int(pid) for pid in listing.read().split())
    except OSError:
        return set()
    return pids


#: How long a test's threads, descriptors and processes get to finish closing after it ends.
LEAK_GRACE_S = 3.0


@pytest.fixture(autouse=True)
def leaves_nothing_behind(request):
    """Fail a test that leaves threads, file descriptors or child processes behind.

    Autouse, so it is set up first and torn down last: the other fixtures'
    clean-up (an emulator stopped by pid, a VirtualBus closed) has run when it
    looks.  A bounded grace lets a closing thread finish.
    """
    threads_before, fds_before, children_before = set(threading.enumerate()), _open_fds(), _children()
    yield
    deadline = time.monotonic() + LEAK_GRACE_S
    while True:
        threads = [t.name for t in threading.enumerate() if t not in threads_before and t.is_alive()]
        fds = sorted(_open_fds() - fds_before)
        children = sorted(_children() - children_before)
        if not (threads or fds or children) or time.monotonic() > deadline:
            break
        time.sleep(0.01)
    if threads or fds or children:
        described = {fd: _describe_fd(fd) for fd in fds}
        pytest.fail(f"left behind: threads {threads}, file descriptors {described}, child processes {children}")


def _describe_fd(fd: int) -> str:
    try:
        return os.readlink(f"/proc/self/fd/{fd}")
    except OSError:
        return "?"


@dataclass
class PortKind:
    """One way a client reaches a bus, and what that way carries of a real line."""

    name: str
    #: The host's bit rate reaches the servos (a pty's termios, the in-process link's baud);
    #: over TCP it does not, so a servo at another baud still hears the host.
    carries_baud: bool


#: The ways in that every transport-independent scenario runs over (python-can's back-to-back idea).
PORT_KINDS = (PortKind("pty", True), PortKind("tcp", False), PortKind("inprocess", True))


@dataclass
class OpenBus:
    """A bus a client can open at ``port`` (a device path or a pyserial URL)."""

    port: str
    kind: PortKind


@pytest.fixture(params=PORT_KINDS, ids=lambda kind: kind.name)
def served_bus(request, emulator) -> Iterator[Callable[..., OpenBus]]:
    """Factory: a bus with the given IDs behind each way in: a real ``ax12emu serve`` on a pty or TCP, or in process."""
    kind: PortKind = request.param
    buses = []

    def _open(ids: list[int]) -> OpenBus:
        id_list = ",".join(map(str, ids))
        if kind.name == "pty":
            return OpenBus(emulator("--ids", id_list).port, kind)
        if kind.name == "tcp":
            return OpenBus(emulator("--ids", id_list, "--tcp", "127.0.0.1:0").port, kind)
        from ax12emu import VirtualBus

        bus = VirtualBus(ids, transport="inprocess").start()
        buses.append(bus)
        return OpenBus(bus.port, kind)

    yield _open
    for bus in buses:
        bus.close()


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
        served.close()


# -- The parallel pass (``-n 2 --dist loadfile``): which files go together, and which start first ----------------------

#: Files whose tests share one session fixture too costly to make twice (tests/tools/conftest.py's fitted twin of
#: the real AX-12A, tests/firmware_model/diagnose/conftest.py's synthetic diagnoses): the parallel pass gives each group to one worker, which makes the fixture once.
SCHEDULED_TOGETHER = {
    "tests/tools/test_real_ax12a_inertia.py": "tests/tools/test_real_ax12a.py",
    "tests/firmware_model/diagnose/test_search_state.py": "tests/firmware_model/diagnose/test_search.py",
}

#: The files whose shared setup runs longest (CPU-bound diagnoses and fits, tens of seconds each), slowest first.
#: The parallel pass hands files out in collection order, these first: a long file handed out last would keep
#: one worker busy while the other has finished (xdist's own order, most tests first, put the single-test
#: diagnosis-order check near the end).  The rest keep their order, short files last, so the workers finish
#: within a few seconds of each other.
RUN_FIRST = (
    "tests/firmware_model/diagnose/test_search.py",
    "tests/firmware_model/diagnose/test_search_state.py",
    "tests/tools/test_real_ax12a.py",
    "tests/tools/test_real_ax12a_inertia.py",
    "tests/tools/test_twin_check.py",
    "tests/firmware_model/diagnose/test_cli_tools.py",
    "tests/ax12emu/bus/test_crash_state.py",
)


def _test_file(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


def pytest_collection_modifyitems(config, items):
    """Put the RUN_FIRST files' tests first, in that order (a stable sort: the rest keep theirs)."""
    root = Path(__file__).resolve().parent.parent
    missing = [path for path in (*RUN_FIRST, *SCHEDULED_TOGETHER, *SCHEDULED_TOGETHER.values())
               if not (root / path).is_file()]
    if missing:  # a renamed file would silently lose its place: say so
        raise pytest.UsageError(f"tests/conftest.py schedules files that are not there: {missing}")
    rank = {path: i for i, path in enumerate(RUN_FIRST)}
    items.sort(key=lambda item: rank.get(_test_file(item.nodeid), len(RUN_FIRST)))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` with the SCHEDULED_TOGETHER groups as one unit each, handed out in collection order."""
    if config.getoption("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class GroupedFileScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = _test_file(nodeid)
            return SCHEDULED_TOGETHER.get(path, path)

    # xdist would otherwise reorder the units, most tests first, ignoring the order collection set
    config.option.loadscopereorder = False
    return GroupedFileScheduling(config, log)
