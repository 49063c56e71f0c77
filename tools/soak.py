"""Soak: the highest request rate through dynamixel-sdk for a bounded time, with every servo moving.

Starts ``ax12emu serve --ids 1-N`` (the physical model), sets Return Delay
Time 0 and Torque Enable 1 on every servo, and then, until the time is up, sends requests back
to back through dynamixel-sdk over the pty:

* every round, for each servo: READ Present Position (2 bytes) and READ
  Goal Position, which must equal the value last written;
* every ``--goal-period`` seconds, a WRITE of a new Goal Position to each
  servo (between 200 and 800, alternating), so every servo keeps moving:
  each one's Present Position must span at least half the distance between
  its goals, and an AX-12A's Moving, read right after the write, must read 1
  (its firmware's reference moves at once; an X-series servo with no profile
  reads Moving by its speed, e-manual Moving(122), still low one step after
  the write, so its count is only reported);
* every 100 rounds, READ Model Number (must be the model's: 12 for the AX-12).

With ``--protocol 2.0`` the servos are XL430-W250s (``serve --servo xl430-w250 --baud 1000000``)
driven by dynamixel-sdk's Protocol 2.0 handler through the X series' registers (4-byte positions,
goals between 1500 and 2500), and every round also sends the goals twice as a robot's cycle does,
each time one Sync Write of them all and at once a read of every servo's Present Position, a Sync
Read then a Fast Sync Read (a share missing or out of range counts as lost or wrong): the emulator
holds such a Sync Write, lets the read go first and lets the next write replace it, so the
per-servo READ of Goal Position in the next round checks that none of that shows.  With
``--protocol mixed`` N AX-12As and N XL430-W250s share the wire (IDs 1..N in each protocol), both
handlers on one port, each servo moving; a reply of the other protocol's servos would show up as a
wrong or lost one.

A reply that does not come (any comm result but success, or dynamixel-sdk raising on what came)
is *lost*; one with an error bit, a wrong value or an out-of-range position is *wrong*.
Both must be 0, but for the losses the machine caused.  Why: on a loaded machine (2 cores, load 3
to 8) now and then one of the emulator, the client, or the kernel worker that carries a pty's bytes
from one side to the other (``flush_to_ldisc``, which a reader of the pty waits for in
``__flush_work``, state D) gets no CPU for 35 to 350 ms, longer than dynamixel-sdk's ~34 ms timeout,
whatever the emulator does.  So on Linux the soak reads, before each request and after a lost one,
each process's time on a CPU, time waiting for one, and the number of times it got one
(``/proc/PID/schedstat``); a loss during which the machine kept the emulator or the client from its
CPU for ``STARVED_S`` or more (``OffCpu.held_off``) counts apart, as *starved*, and so do the
wrong or unusable reply right after it (the late answer, taken for the next request's).  Each
loss is listed with both processes' figures.  Latency percentiles are printed per tenth of the run,
and the emulator's resident memory (VmRSS from /proc) at the start (after
a warm-up) and at the end, whose difference must stay within 5 MB.

Usage: ``python tools/soak.py [--seconds 600] [--servos 4] [--protocol 1.0|2.0|mixed]``
"""

from __future__ import annotations

import os
import select
import subprocess
import sys
import time
from dataclasses import dataclass, field

from dynamixel_sdk import COMM_SUCCESS, GroupSyncRead, GroupSyncWrite, PacketHandler, PortHandler

from ax12emu.cli.arg_types import OneLineParser, positive_float, positive_int
from ax12emu.protocol.packets import MAX_ID
from ax12emu.protocol.packets2 import MAX_ID2

PRESENT_POSITION, GOAL_POSITION, MOVING, RETURN_DELAY, MODEL_NUMBER, TORQUE_ENABLE = 36, 30, 46, 5, 0, 24
#: After a one-byte EEPROM write an AX-12 ignores packets for about 6 ms (9 ms by the ATMega8 datasheet).
EEPROM_WAIT_S = 0.009
RSS_LIMIT_KB = 5 * 1024
#: dynamixel-sdk's packet timeout is (bytes x byte time) + 2 x LATENCY_TIMER (16 ms) + 2 ms
#: (dynamixel_sdk/port_handler.py, ``setPacketTimeout``), ~34 ms for the soak's packets at 1 Mbps.
#: A request during which the emulator or the client was kept off its CPU this long (waiting for
#: one, or blocked on the pty's kernel worker) left at most the 2 ms and the bytes' time to answer
#: or to read the answer: a loss then is the machine's.
STARVED_S = 2 * 0.016
#: The longest the emulator sleeps by its own choice: its serving loop's ``select`` is capped at one
#: physics period (``BusServer.run_once``, ``physics_period_s`` 1 ms by default).
EMULATOR_LONGEST_SLEEP_S = 1e-3
#: dynamixel-sdk's result for a reply it could not use; also what a call that raised counts as.
COMM_RX_CORRUPT = COMM_RAISED = -3002


@dataclass(frozen=True)
class Kind:
    """One servo model as the soak drives it: protocol, register addresses, position size and goals."""

    protocol: float
    serve_name: str
    present_position: int
    goal_position: int
    position_bytes: int
    moving: int
    return_delay: int
    torque_enable: int
    model_number: int
    goals: tuple[int, int]
    position_max: int
    #: How long the servo ignores packets after a one-byte write to its EEPROM area.
    eeprom_wait_s: float


AX12 = Kind(1.0, "ax-12a", PRESENT_POSITION, GOAL_POSITION, 2, MOVING, RETURN_DELAY, TORQUE_ENABLE, 12, (200, 800),
            1023, EEPROM_WAIT_S)
#: XL430-W250 (e-manual, X series control table): Return Delay Time 9, Torque Enable 64, Goal Position
#: 116, Moving 122, Present Position 132, Model Number 1060; the emulator models no EEPROM busy time.
XL430 = Kind(2.0, "xl430-w250", 132, 116, 4, 122, 9, 64, 1060, (1500, 2500), 4095, 0.0)
PROTOCOLS = {"1.0": (AX12,), "2.0": (XL430,), "mixed": (AX12, XL430)}


def rss_kb(pid: int) -> int:
    """Resident set size of ``pid`` in kB (VmRSS from /proc/PID/status)."""
    with open(f"/proc/{pid}/status", encoding="ascii") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise RuntimeError(f"no VmRSS for process {pid}")


def percentile(sorted_values: list[float], q: float) -> float:
    """The q-quantile (0..1) of already sorted values, nearest rank."""
    if not sorted_values:
        return float("nan")
    return sorted_values[min(len(sorted_values) - 1, int(q * len(sorted_values)))]


class SchedStat:
    """One thread's time on a CPU, time runnable but waiting for one (seconds), and how many times it got one.

    From ``/proc/PID/schedstat`` (Linux, ``CONFIG_SCHED_INFO``: run time ns, run delay ns, timeslices;
    the thread group leader's, which is the thread that serves in ``ax12emu serve`` and the one that
    soaks here), through a descriptor kept open: ``pread`` regenerates the line, about 3 us a read.
    ``read()`` is None where there is no such file (not Linux) or the process has ended.
    """

    def __init__(self, pid: int) -> None:
        try:
            self._fd: int | None = os.open(f"/proc/{pid}/schedstat", os.O_RDONLY)
        except OSError:
            self._fd = None
        if self._fd is not None and self.read() is None:
            self.close()

    def read(self) -> tuple[float, float, int] | None:
        """(on a CPU s, waiting for a CPU s, timeslices) so far."""
        if self._fd is None:
            return None
        try:
            run_ns, wait_ns, slices = os.pread(self._fd, 128, 0).split()[:3]
            return int(run_ns) * 1e-9, int(wait_ns) * 1e-9, int(slices)
        except (OSError, ValueError):
            return None

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


@dataclass(frozen=True)
class OffCpu:
    """What kept one process from its CPU during a request: ``off_s`` not on a CPU (waiting for one,
    or blocked in the kernel), in ``stretches`` (the times it got one back); ``waiting_s`` runnable,
    which the kernel adds up when a wait ends, so a wait begun before the request counts whole."""

    off_s: float
    waiting_s: float
    stretches: int
    #: The longest the process sleeps at a time by its own choice during a request: the emulator up to
    #: ``EMULATOR_LONGEST_SLEEP_S``; the client never (dynamixel-sdk polls the port, and pyserial's
    #: read with timeout 0 does not block).
    longest_sleep_s: float = EMULATOR_LONGEST_SLEEP_S

    @classmethod
    def between(cls, before: tuple[float, float, int], after: tuple[float, float, int], wall_s: float, *,
                longest_sleep_s: float = EMULATOR_LONGEST_SLEEP_S) -> OffCpu:
        return cls(max(0.0, wall_s - (after[0] - before[0])), after[1] - before[1], after[2] - before[2],
                   longest_sleep_s)

    @property
    def kept_off_s(self) -> float:
        """The least of ``off_s`` that was not the process's choice: each stretch off its CPU holds at
        most one sleep it chose (the rest: waiting for a CPU, or blocked in the kernel, as on the pty's
        worker); and at least the wait for a CPU, as far as it fell in the request."""
        chosen_s = max(1, self.stretches) * self.longest_sleep_s
        return max(self.off_s - chosen_s, min(self.waiting_s, self.off_s))

    @property
    def held_off(self) -> bool:
        """Kept from its CPU by the machine for ``STARVED_S`` or more of the request."""
        return self.kept_off_s >= STARVED_S

    def __str__(self) -> str:
        return f"{self.off_s * 1e3:.1f} ms in {max(1, self.stretches)} ({self.waiting_s * 1e3:.1f} ms waiting for a CPU)"


@dataclass
class Slice:
    """One tenth of the run."""

    latencies_s: list[float] = field(default_factory=list)
    rss_kb: int = 0


@dataclass
class SoakResult:
    """Figures of one soak run."""

    seconds: float = 0.0
    #: How often the goals flipped (s).
    goal_period_s: float = 0.5
    requests: int = 0
    lost: int = 0
    wrong: int = 0
    #: Wrong replies right after a lost one: the late reply, taken by dynamixel-sdk for the next
    #: request to the same ID (it matches replies by ID only).
    wrong_after_lost: int = 0
    #: Of ``lost``, those during whose request the emulator or the client was held off its CPU
    #: (``OffCpu.held_off``); of ``wrong_after_lost``, those right after such a loss.
    lost_starved: int = 0
    wrong_after_starved: int = 0
    #: Whether the processes' CPU figures could be read (Linux); without them no loss counts as starved.
    waits_known: bool = False
    #: How the reply before the one being counted went: None (it came), "lost" or "starved".
    _previous: str | None = field(default=None, repr=False)
    #: The last starved loss, listed or not: shown before a problem the machine does not explain,
    #: since late answers may trail it by several requests.
    _last_starved: str | None = field(default=None, repr=False)
    #: Of ``wrong``, the replies whose status carried an error (the servo's alarm or Alert bit, not a wrong value):
    #: a servo the soak drove into an alarm (an X series' Overload under goals flipped every 0.2 s) answers so.
    alarmed: int = 0
    moving_seen: int = 0
    moving_checks: int = 0
    #: Of those, the Protocol 1.0 servos' (AX-12A): their Moving follows the firmware's reference, so it reads 1
    #: on the first read after a goal beyond the margin.  An X-series servo with no profile (Profile Velocity 0)
    #: reads Moving by its speed (e-manual, Moving(122)), which one control step after the write may be below
    #: the threshold: for it only the positions below tell whether it moved.
    moving_seen_1: int = 0
    moving_checks_1: int = 0
    #: Per servo ("ID n, Protocol p"): the lowest and highest Present Position read, and its goals' distance.
    spans: dict[str, tuple[int, int, int]] = field(default_factory=dict)
    rss_start_kb: int = 0
    rss_end_kb: int = 0
    slices: list[Slice] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    @property
    def still(self) -> list[str]:
        """The servos whose Present Position never spanned half the distance between their two goals."""
        return [name for name, (low, high, distance) in self.spans.items() if high - low < distance / 2]

    @property
    def rss_growth_kb(self) -> int:
        """End minus start resident memory."""
        return self.rss_end_kb - self.rss_start_kb

    @property
    def lost_by_emulator(self) -> int:
        """Lost replies but those the machine's scheduler explains (``OffCpu.held_off``)."""
        return self.lost - self.lost_starved

    @property
    def wrong_by_emulator(self) -> int:
        """Wrong replies but the late answers right after a starved loss."""
        return self.wrong - self.wrong_after_starved

    @property
    def ok(self) -> bool:
        """No lost or wrong reply the machine does not explain, memory flat, the servos moved, and an AX-12A's Moving
        read 1 right after a goal."""
        return not self.reasons

    @property
    def reasons(self) -> list[str]:
        """Why the run failed (empty: it passed), each as the verdict line names it."""
        out = []
        if self.lost_by_emulator:
            out.append(f"{self.lost_by_emulator} replies lost")
        if self.wrong_by_emulator:
            alarm = (f", {self.alarmed} carrying the servo's alarm (an alarm the servo raised, such as Overload from "
                     f"goals flipped every {self.goal_period_s:g} s: its physics, not the bus)") if self.alarmed else ""
            out.append(f"{self.wrong_by_emulator} replies wrong{alarm}")
        if abs(self.rss_growth_kb) > RSS_LIMIT_KB:
            out.append(f"memory {self.rss_growth_kb / 1024:+.1f} MB")
        if self.still:
            out.append("servos that never moved: " + ", ".join(self.still))
        if self.moving_checks_1 and not self.moving_seen_1:
            out.append("an AX-12A's Moving never read 1 right after a goal")
        return out

    def count(self, what: str, at_s: float, comm: int, error: int, bad: bool,
              off_cpu: tuple[OffCpu, OffCpu] | None = None) -> None:
        """Count one reply: ``comm`` dynamixel-sdk's result, ``bad`` a wrong value; ``off_cpu`` the
        emulator's and the client's time off their CPUs during its request (None: not known)."""
        previous = self._previous
        starved = off_cpu is not None and (off_cpu[0].held_off or off_cpu[1].held_off)
        waits = "" if off_cpu is None else f"; off its CPU: emulator {off_cpu[0]}, client {off_cpu[1]}"
        if comm != COMM_SUCCESS:
            # A reply dynamixel-sdk could not use right after a starved loss: the late answer, mixed in.
            starved = starved or (comm == COMM_RX_CORRUPT and previous == "starved")
            self.lost += 1
            self.lost_starved += starved
            line = f"lost at {at_s:.1f} s{', starved' if starved else ''}: {what} (comm {comm}{waits})"
            if starved:
                self._last_starved = line
                if len(self.problems) < 10:  # the emulator's own come first when reading
                    self.problems.append(line)
            else:
                self._list_own(line)
            self._previous = "starved" if starved else "lost"
            return
        if error or bad:
            self.wrong += 1
            self.alarmed += bool(error) and previous != "starved"  # of the wrong ones that count, as the verdict says
            self.wrong_after_lost += previous is not None
            self.wrong_after_starved += previous == "starved"
            line = f"wrong at {at_s:.1f} s{', after a starved loss' if previous == 'starved' else ''}: {what} (error {error:#x})"
            if previous == "starved":
                if len(self.problems) < 10:
                    self.problems.append(line)
            else:
                self._list_own(line)
        self._previous = None

    def _list_own(self, line: str) -> None:
        """List a problem the machine does not explain, after the last starved loss if that is not listed."""
        if self._last_starved is not None and self._last_starved not in self.problems and len(self.problems) < 39:
            self.problems.append(f"(the last starved loss before it) {self._last_starved}")
        if len(self.problems) < 40:
            self.problems.append(line)


def serve_args(servos: int, protocol: str = "1.0") -> list[str]:
    """``ax12emu serve`` arguments for IDs 1..N of each kind of ``protocol``."""
    if protocol == "1.0":
        return ["--ids", f"1-{servos}"]
    models = ",".join(f"1-{servos}:{kind.serve_name}" for kind in PROTOCOLS[protocol])
    return ["--servo", models, "--baud", "1000000"]


def start_emulator(servos: int, extra: list[str], protocol: str = "1.0") -> tuple[subprocess.Popen, str]:
    """Start ``ax12emu serve`` with IDs 1..N of each kind and read the pty path it prints."""
    process = subprocess.Popen([sys.executable, "-m", "ax12emu", "serve", *serve_args(servos, protocol), *extra],
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    ready, _, _ = select.select([process.stdout], [], [], 20)
    line = process.stdout.readline().strip() if ready else ""
    if not line:
        process.kill()
        raise RuntimeError("the emulator did not start")
    return process, line


def soak(path: str, pid: int, seconds: float, servos: int, *, goal_period_s: float = 0.5,
         warmup_s: float = 2.0, protocol: str = "1.0") -> SoakResult:
    """Run the request loop against the emulator at ``path`` (process ``pid``) for ``seconds``."""
    result = SoakResult(slices=[Slice() for _ in range(10)], goal_period_s=goal_period_s)
    port = PortHandler(path)
    if not (port.openPort() and port.setBaudRate(1_000_000)):
        raise RuntimeError(f"cannot open {path}")
    kinds = PROTOCOLS[protocol]
    handlers = {kind: PacketHandler(kind.protocol) for kind in kinds}
    #: (kind, ID) of every servo: IDs are per protocol, so a mixed wire has ID 1 twice.
    targets = [(kind, servo_id) for kind in kinds for servo_id in range(1, servos + 1)]
    clock = time.perf_counter
    emulator_stat, client_stat = SchedStat(pid), SchedStat(os.getpid())
    result.waits_known = emulator_stat.read() is not None and client_stat.read() is not None
    readers, writers = {}, {}
    for kind in kinds:
        if kind.protocol == 2.0:
            reader = GroupSyncRead(port, handlers[kind], kind.present_position, kind.position_bytes)
            for servo_id in range(1, servos + 1):
                reader.addParam(servo_id)
            readers[kind] = reader
            writers[kind] = GroupSyncWrite(port, handlers[kind], kind.goal_position, kind.position_bytes)

    def read(kind: Kind, servo_id: int, address: int, size: int):
        call = {1: handlers[kind].read1ByteTxRx, 2: handlers[kind].read2ByteTxRx, 4: handlers[kind].read4ByteTxRx}[size]
        return call(port, servo_id, address)

    def write(kind: Kind, servo_id: int, address: int, size: int, value: int):
        call = {1: handlers[kind].write1ByteTxRx, 2: handlers[kind].write2ByteTxRx, 4: handlers[kind].write4ByteTxRx}[size]
        return call(port, servo_id, address, value)

    try:
        for kind, servo_id in targets:
            for address, value in ((kind.return_delay, 0), (kind.torque_enable, 1)):
                comm, error = write(kind, servo_id, address, 1, value)
                if comm != COMM_SUCCESS or error:
                    raise RuntimeError(f"writing {value} at {address} of ID {servo_id}: comm {comm}, error {error}")
                if address == kind.return_delay:
                    time.sleep(kind.eeprom_wait_s)  # in the EEPROM: the servo ignores packets while it writes it
        goals = {target: sum(target[0].goals) // 2 for target in targets}
        started = clock()
        end = started + seconds
        next_goal = started
        rss_at = started + min(warmup_s, seconds / 10)
        rounds = 0

        #: Both threads' CPU figures and the clock when the last request began, and their time off
        #: their CPUs during it once a loss asked for it (a Sync Read's shares share one request).
        stats_before: list = [None, None, 0.0]
        off_during: list = [None]

        def timed(call, *args, raised=COMM_RAISED):
            if result.waits_known:
                stats_before[0], stats_before[1], stats_before[2] = emulator_stat.read(), client_stat.read(), clock()
                off_during[0] = None
            t0 = clock()
            try:
                out = call(*args)
            except Exception as exc:  # dynamixel-sdk indexing a reply that is not the one it waits for
                if len(result.problems) < 20:
                    result.problems.append(f"dynamixel-sdk raised at {t0 - started:.1f} s: {exc!r}")
                out = raised
            elapsed = clock() - t0
            index = min(9, int((t0 - started) / seconds * 10))
            result.slices[index].latencies_s.append(elapsed)
            result.requests += 1
            return out

        def off_cpu_of_request() -> tuple[OffCpu, OffCpu] | None:
            if off_during[0] is None and result.waits_known:
                emulator, client, wall_s = emulator_stat.read(), client_stat.read(), clock() - stats_before[2]
                if None not in (emulator, client, stats_before[0], stats_before[1]):
                    off_during[0] = (OffCpu.between(stats_before[0], emulator, wall_s),
                                     OffCpu.between(stats_before[1], client, wall_s, longest_sleep_s=0.0))
            return off_during[0]

        def check(what: str, comm: int, error: int, bad: bool) -> None:
            result.count(what, clock() - started, comm, error, bad,
                         off_cpu_of_request() if comm != COMM_SUCCESS else None)

        while True:
            now = clock()
            if now >= end:
                break
            if result.rss_start_kb == 0 and now >= rss_at:
                result.rss_start_kb = rss_kb(pid)
            if now >= next_goal:
                next_goal = now + goal_period_s
                for target in targets:
                    kind, servo_id = target
                    low, high = kind.goals
                    goals[target] = high if goals[target] < (low + high) // 2 else low
                    comm, error = timed(write, kind, servo_id, kind.goal_position, kind.position_bytes, goals[target],
                                        raised=(COMM_RAISED, 0))
                    check(f"WRITE goal {goals[target]} to ID {servo_id} (Protocol {kind.protocol})", comm, error, False)
                for kind, servo_id in targets:
                    value, comm, error = timed(read, kind, servo_id, kind.moving, 1, raised=(0, COMM_RAISED, 0))
                    check(f"READ Moving of ID {servo_id} (Protocol {kind.protocol})", comm, error, value not in (0, 1))
                    result.moving_checks += 1
                    result.moving_seen += value == 1
                    if kind.protocol == 1.0:
                        result.moving_checks_1 += 1
                        result.moving_seen_1 += value == 1
            for target in targets:
                kind, servo_id = target
                value, comm, error = timed(read, kind, servo_id, kind.present_position, kind.position_bytes,
                                           raised=(0, COMM_RAISED, 0))
                check(f"READ Present Position of ID {servo_id} = {value} (Protocol {kind.protocol})", comm, error,
                      not 0 <= value <= kind.position_max)
                if comm == COMM_SUCCESS and not error and 0 <= value <= kind.position_max:
                    name = f"ID {servo_id}, Protocol {kind.protocol}"
                    low, high, distance = result.spans.get(name, (value, value, kind.goals[1] - kind.goals[0]))
                    result.spans[name] = (min(low, value), max(high, value), distance)
                value, comm, error = timed(read, kind, servo_id, kind.goal_position, kind.position_bytes,
                                           raised=(0, COMM_RAISED, 0))
                check(f"READ Goal Position of ID {servo_id} = {value}, wrote {goals[target]} (Protocol {kind.protocol})",
                      comm, error, value != goals[target])
            for kind, reader in readers.items():
                writer = writers[kind]
                for fast in (False, True):  # twice: the second write replaces the first, held after its read
                    writer.clearParam()  # the goals again, as a robot's cycle sends them before its read
                    for servo_id in range(1, servos + 1):
                        writer.addParam(servo_id, list(goals[(kind, servo_id)].to_bytes(kind.position_bytes, "little")))
                    comm = timed(writer.txPacket)
                    check("Sync Write of the goals (Protocol 2.0)", comm, 0, False)
                    how = "Fast Sync Read" if fast else "Sync Read"
                    comm = timed(reader.fastSyncRead if fast else reader.txRxPacket)
                    for servo_id in range(1, servos + 1):
                        available = comm == COMM_SUCCESS and reader.isAvailable(servo_id, kind.present_position,
                                                                                kind.position_bytes)
                        value = reader.getData(servo_id, kind.present_position, kind.position_bytes) if available else 0
                        check(f"{how} of Present Position, ID {servo_id} = {value}",
                              comm if comm != COMM_SUCCESS else (COMM_SUCCESS if available else -1001), 0,
                              not 0 <= value <= kind.position_max)
            rounds += 1
            if rounds % 100 == 0:
                for kind in kinds:
                    value, comm, error = timed(read, kind, 1, MODEL_NUMBER, 2, raised=(0, COMM_RAISED, 0))
                    check(f"READ Model Number = {value} (Protocol {kind.protocol})", comm, error,
                          value != kind.model_number)
            index = min(9, int((now - started) / seconds * 10))
            result.slices[index].rss_kb = rss_kb(pid) if rounds % 500 == 0 else result.slices[index].rss_kb
        result.seconds = clock() - started
        result.rss_end_kb = rss_kb(pid)
        if result.rss_start_kb == 0:
            result.rss_start_kb = result.rss_end_kb
    finally:
        port.closePort()
        emulator_stat.close()
        client_stat.close()
    return result


def report(result: SoakResult, servos: int, protocol: str = "1.0") -> str:
    """The figures as text."""
    models = " and ".join(f"{servos} {kind.serve_name} (Protocol {kind.protocol})" for kind in PROTOCOLS[protocol])
    lines = [
        f"soak: {result.seconds:.0f} s, {models} moving (goal flips every {result.goal_period_s:g} s), dynamixel-sdk over the pty",
        f"requests: {result.requests:,} ({result.requests / result.seconds:,.0f}/s); lost replies: {result.lost}; "
        f"wrong replies: {result.wrong} ({result.wrong_after_lost} right after a lost one); Moving read 1 in {result.moving_seen} of {result.moving_checks} checks"
        + (f" (AX-12A: {result.moving_seen_1} of {result.moving_checks_1})" if result.moving_checks_1 else "")
        + ("; every servo moved" if not result.still else "; never moved half a goal flip: " + ", ".join(result.still)),
        (f"starved (the machine kept the emulator or this client from its CPU {STARVED_S * 1e3:.0f} ms or more of the request): "
         f"{result.lost_starved} of the lost, {result.wrong_after_starved} of the wrong right after them; "
         f"the emulator's: {result.lost_by_emulator} lost, {result.wrong_by_emulator} wrong"
         if result.waits_known else "time off the CPU not readable here (no /proc/PID/schedstat): every loss counts"),
        "latency per tenth of the run (ms):  requests    p50     p90     p99   p99.9     max   RSS MB",
    ]
    for k, part in enumerate(result.slices):
        values = sorted(part.latencies_s)
        if not values:
            continue
        q = [percentile(values, p) * 1e3 for p in (0.5, 0.9, 0.99, 0.999)]
        rss = f"{part.rss_kb / 1024:8.1f}" if part.rss_kb else "       -"
        lines.append(f"  {k * 10:3d}-{k * 10 + 10:3d} %{'':21s}{len(values):9,d} {q[0]:6.3f}  {q[1]:6.3f}  {q[2]:6.3f}"
                     f"  {q[3]:6.3f}  {values[-1] * 1e3:6.2f}  {rss}")
    everything = sorted(v for part in result.slices for v in part.latencies_s)
    lines.append(f"  whole run{'':25s}{len(everything):9,d} " + "  ".join(
        f"{percentile(everything, p) * 1e3:6.3f}" for p in (0.5, 0.9, 0.99, 0.999)) + f"  {everything[-1] * 1e3:6.2f}")
    lines.append(f"emulator RSS: {result.rss_start_kb / 1024:.1f} MB after warm-up, {result.rss_end_kb / 1024:.1f} MB "
                 f"at the end ({result.rss_growth_kb / 1024:+.2f} MB; limit +/-{RSS_LIMIT_KB / 1024:.0f} MB)")
    lines.extend(result.problems)
    starved = f" ({result.lost_starved} lost while starved of a CPU, which does not count)" if result.lost_starved else ""
    lines.append(("PASS" + starved) if result.ok else ("FAIL: " + "; ".join(result.reasons) + starved))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Start an emulator, soak it, print the figures; exit 1 unless everything held."""
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=positive_float, default=600.0, help="how long to run (default 600)")
    parser.add_argument("--servos", type=positive_int, default=4, help="servos on the bus, IDs 1..N (default 4)")
    parser.add_argument("--goal-period", type=positive_float, default=0.5,
                        help="seconds between goal flips (default 0.5)")
    parser.add_argument("--protocol", choices=tuple(PROTOCOLS), default="1.0",
                        help="AX-12As on Protocol 1.0 (default), XL430-W250s on 2.0, or N of each on one wire")
    parser.add_argument("--attach", nargs=2, metavar=("PORT", "PID"),
                        help="soak an emulator already serving IDs 1..N on PORT (process PID) instead of starting one")
    parser.add_argument("serve_args", nargs="*", help="extra arguments for ax12emu serve (after --)")
    args = parser.parse_args(argv)
    highest = MAX_ID if args.protocol == "1.0" else MAX_ID2  # Protocol 2.0 reserves ID 253
    if args.servos > highest:
        parser.error(f"--servos: IDs 1..N on Protocol {args.protocol} end at {highest}, got {args.servos}")
    if args.attach and not (args.attach[1].isdigit() and int(args.attach[1]) > 0):
        parser.error(f"--attach PORT PID: {args.attach[1]!r} is not a process id")
    try:
        if args.attach:
            result = soak(args.attach[0], int(args.attach[1]), args.seconds, args.servos,
                          goal_period_s=args.goal_period, protocol=args.protocol)
            print(report(result, args.servos, args.protocol))
            return 0 if result.ok else 1
        process, path = start_emulator(args.servos, args.serve_args, args.protocol)
        try:
            result = soak(path, process.pid, args.seconds, args.servos, goal_period_s=args.goal_period,
                          protocol=args.protocol)
            if process.poll() is not None:
                result.problems.append(f"the emulator exited with {process.returncode}")
                result.lost += 1
        finally:
            process.kill()
            process.wait()
    # An emulator that does not start (arguments after -- it refuses), a PORT it cannot open (pyserial's
    # SerialException is an OSError), a PID with no /proc entry, a servo that refuses the set-up writes.
    except (RuntimeError, OSError) as exc:
        print(f"{parser.prog}: error: {exc}", file=sys.stderr)
        return 2
    print(report(result, args.servos, args.protocol))
    return 0 if result.ok else 1


if __name__ == "__main__":
    sys.exit(main())
