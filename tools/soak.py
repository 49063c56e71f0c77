"""Soak: the highest request rate through dynamixel-sdk for a bounded time, with every servo moving.

Starts ``ax12emu serve --ids 1-N`` (the physical model), sets Return Delay
Time 0 and Torque Enable 1 on every servo, and then, until the time is up, sends requests back
to back through dynamixel-sdk over the pty:

* every round, for each servo: READ Present Position (2 bytes) and READ
  Goal Position, which must equal the value last written;
* every ``--goal-period`` seconds, a WRITE of a new Goal Position to each
  servo (between 200 and 800, alternating), so every servo keeps moving;
  Moving is read back as a check that they do;
* every 100 rounds, READ Model Number (must be the model's: 12 for the AX-12).

With ``--protocol 2.0`` the servos are XL430-W250s (``serve --servo xl430-w250 --baud 1000000``)
driven by dynamixel-sdk's Protocol 2.0 handler through the X series' registers (4-byte positions,
goals between 1500 and 2500), and every round also reads every servo's Present Position with one
Sync Read and one Fast Sync Read (a share missing or out of range counts as lost or wrong).  With
``--protocol mixed`` N AX-12As and N XL430-W250s share the wire (IDs 1..N in each protocol), both
handlers on one port, each servo moving; a reply of the other protocol's servos would show up as a
wrong or lost one.

A reply that does not come (any comm result but success) is *lost*; one
with an error bit, a wrong value or an out-of-range position is *wrong*.
Both must be 0.  Latency percentiles are printed per tenth of the run,
and the emulator's resident memory (VmRSS from /proc) at the start (after
a warm-up) and at the end, whose difference must stay within 5 MB.

Usage: ``python tools/soak.py [--seconds 600] [--servos 4] [--protocol 1.0|2.0|mixed]``
"""

from __future__ import annotations

import argparse
import select
import subprocess
import sys
import time
from dataclasses import dataclass, field

from dynamixel_sdk import COMM_SUCCESS, GroupSyncRead, PacketHandler, PortHandler

PRESENT_POSITION, GOAL_POSITION, MOVING, RETURN_DELAY, MODEL_NUMBER, TORQUE_ENABLE = 36, 30, 46, 5, 0, 24
#: After a one-byte EEPROM write an AX-12 ignores packets for about 6 ms (9 ms by the ATMega8 datasheet).
EEPROM_WAIT_S = 0.009
RSS_LIMIT_KB = 5 * 1024


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


@dataclass
class Slice:
    """One tenth of the run."""

    latencies_s: list[float] = field(default_factory=list)
    rss_kb: int = 0


@dataclass
class SoakResult:
    """Figures of one soak run."""

    seconds: float = 0.0
    requests: int = 0
    lost: int = 0
    wrong: int = 0
    #: Wrong replies right after a lost one: the late reply, taken by dynamixel-sdk for the next
    #: request to the same ID (it matches replies by ID only).
    wrong_after_lost: int = 0
    moving_seen: int = 0
    moving_checks: int = 0
    rss_start_kb: int = 0
    rss_end_kb: int = 0
    slices: list[Slice] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    @property
    def rss_growth_kb(self) -> int:
        """End minus start resident memory."""
        return self.rss_end_kb - self.rss_start_kb

    @property
    def ok(self) -> bool:
        """No lost or wrong reply, memory flat, and the servos moved."""
        return (not self.lost and not self.wrong and abs(self.rss_growth_kb) <= RSS_LIMIT_KB
                and self.moving_seen > 0)


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
    result = SoakResult(slices=[Slice() for _ in range(10)])
    port = PortHandler(path)
    if not (port.openPort() and port.setBaudRate(1_000_000)):
        raise RuntimeError(f"cannot open {path}")
    kinds = PROTOCOLS[protocol]
    handlers = {kind: PacketHandler(kind.protocol) for kind in kinds}
    #: (kind, ID) of every servo: IDs are per protocol, so a mixed wire has ID 1 twice.
    targets = [(kind, servo_id) for kind in kinds for servo_id in range(1, servos + 1)]
    clock = time.perf_counter
    readers = {}
    for kind in kinds:
        if kind.protocol == 2.0:
            reader = GroupSyncRead(port, handlers[kind], kind.present_position, kind.position_bytes)
            for servo_id in range(1, servos + 1):
                reader.addParam(servo_id)
            readers[kind] = reader

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

        def timed(call, *args):
            t0 = clock()
            out = call(*args)
            elapsed = clock() - t0
            index = min(9, int((t0 - started) / seconds * 10))
            result.slices[index].latencies_s.append(elapsed)
            result.requests += 1
            return out

        previous_lost = [False]

        def check(what: str, comm: int, error: int, bad: bool) -> None:
            elapsed_s = clock() - started
            if comm != COMM_SUCCESS:
                result.lost += 1
                if len(result.problems) < 20:
                    result.problems.append(f"lost at {elapsed_s:.1f} s: {what} (comm {comm})")
            elif error or bad:
                result.wrong += 1
                result.wrong_after_lost += previous_lost[0]
                if len(result.problems) < 20:
                    result.problems.append(f"wrong at {elapsed_s:.1f} s: {what} (error {error:#x})")
            previous_lost[0] = comm != COMM_SUCCESS

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
                    comm, error = timed(write, kind, servo_id, kind.goal_position, kind.position_bytes, goals[target])
                    check(f"WRITE goal {goals[target]} to ID {servo_id} (Protocol {kind.protocol})", comm, error, False)
                for kind, servo_id in targets:
                    value, comm, error = timed(read, kind, servo_id, kind.moving, 1)
                    check(f"READ Moving of ID {servo_id} (Protocol {kind.protocol})", comm, error, value not in (0, 1))
                    result.moving_checks += 1
                    result.moving_seen += value == 1
            for target in targets:
                kind, servo_id = target
                value, comm, error = timed(read, kind, servo_id, kind.present_position, kind.position_bytes)
                check(f"READ Present Position of ID {servo_id} = {value} (Protocol {kind.protocol})", comm, error,
                      not 0 <= value <= kind.position_max)
                value, comm, error = timed(read, kind, servo_id, kind.goal_position, kind.position_bytes)
                check(f"READ Goal Position of ID {servo_id} = {value}, wrote {goals[target]} (Protocol {kind.protocol})",
                      comm, error, value != goals[target])
            for kind, reader in readers.items():
                how = "Fast Sync Read" if rounds % 2 else "Sync Read"
                comm = timed(reader.fastSyncRead if rounds % 2 else reader.txRxPacket)
                for servo_id in range(1, servos + 1):
                    available = comm == COMM_SUCCESS and reader.isAvailable(servo_id, kind.present_position,
                                                                            kind.position_bytes)
                    value = reader.getData(servo_id, kind.present_position, kind.position_bytes) if available else 0
                    check(f"{how} of Present Position, ID {servo_id} = {value}", comm if available else -1001, 0,
                          not 0 <= value <= kind.position_max)
            rounds += 1
            if rounds % 100 == 0:
                for kind in kinds:
                    value, comm, error = timed(read, kind, 1, MODEL_NUMBER, 2)
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
    return result


def report(result: SoakResult, servos: int, protocol: str = "1.0") -> str:
    """The figures as text."""
    models = " and ".join(f"{servos} {kind.serve_name} (Protocol {kind.protocol})" for kind in PROTOCOLS[protocol])
    lines = [
        f"soak: {result.seconds:.0f} s, {models} moving (goal flips every 0.5 s), dynamixel-sdk over the pty",
        f"requests: {result.requests:,} ({result.requests / result.seconds:,.0f}/s); lost replies: {result.lost}; "
        f"wrong replies: {result.wrong} ({result.wrong_after_lost} right after a lost one); Moving read 1 in {result.moving_seen} of {result.moving_checks} checks",
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
    lines.append("PASS" if result.ok else "FAIL")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Start an emulator, soak it, print the figures; exit 1 unless everything held."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=600.0, help="how long to run (default 600)")
    parser.add_argument("--servos", type=int, default=4, help="servos on the bus, IDs 1..N (default 4)")
    parser.add_argument("--goal-period", type=float, default=0.5, help="seconds between goal flips (default 0.5)")
    parser.add_argument("--protocol", choices=tuple(PROTOCOLS), default="1.0",
                        help="AX-12As on Protocol 1.0 (default), XL430-W250s on 2.0, or N of each on one wire")
    parser.add_argument("--attach", nargs=2, metavar=("PORT", "PID"),
                        help="soak an emulator already serving IDs 1..N on PORT (process PID) instead of starting one")
    parser.add_argument("serve_args", nargs="*", help="extra arguments for ax12emu serve (after --)")
    args = parser.parse_args(argv)
    if args.attach:
        result = soak(args.attach[0], int(args.attach[1]), args.seconds, args.servos, goal_period_s=args.goal_period,
                      protocol=args.protocol)
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
    print(report(result, args.servos, args.protocol))
    return 0 if result.ok else 1


if __name__ == "__main__":
    sys.exit(main())
