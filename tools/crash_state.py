"""SIGKILL the emulator at random moments during bursts of EEPROM writes; the state must survive.

Each iteration starts ``ax12emu serve --state-dir DIR`` (the same DIR every
time), checks the servo came back with the state the directory holds, sends
a pipelined burst of WRITE packets through the pty and kills the server with
SIGKILL after a random delay.  Write number ``k`` sets, in one packet,
ID, Return Delay Time and both angle limits to values derived from ``k``
(see :func:`state_of`), so any mixture of two writes is detectable.

After each kill the state file must:

* parse and load (the server starts again without ``--factory-reset``);
* hold exactly the state of one write ``k`` (or the factory state): never
  a partial or mixed one;
* be no older than the last write the server acknowledged (a status packet
  is sent only after the state file was replaced and fsync'ed) and no newer
  than the last one sent;

and the restarted servo answers at the ID the file gives, with registers equal to it.

The server runs with ``--eeprom-busy-ms 0``: a real AX-12 ignores packets for
a few milliseconds after each EEPROM write, so all but the first write of a
pipelined burst would be dropped and little would be left to kill mid-save.

Usage: ``python tools/crash_state.py [--iterations 100] [--seed N]``
"""

from __future__ import annotations

import json
import os
import random
import select
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import serial

from ax12emu.cli.arg_types import OneLineParser, file_name, positive_int
from ax12emu.protocol.packets import encode_instruction

#: Factory state (no write yet): ID 1, Return Delay 250, CW 0, CCW 1023.
FACTORY = {"id": 1, "return_delay_time": 250, "cw_angle_limit": 0, "ccw_angle_limit": 1023}
BURST = 300


def state_of(k: int) -> dict[str, int]:
    """The registers write ``k`` sets (k = -1: the factory state)."""
    if k < 0:
        return dict(FACTORY)
    return {"id": 1 + (k + 1) % 200, "return_delay_time": k % 251, "cw_angle_limit": k % 500,
            "ccw_angle_limit": 523 + k % 500}


def write_packet(k: int) -> bytes:
    """WRITE to the ID of write k-1, addresses 3..9: ID, baud 1 (1 Mbps), delay, CW, CCW."""
    s = state_of(k)
    data = bytes([s["id"], 1, s["return_delay_time"]]) + s["cw_angle_limit"].to_bytes(2, "little")
    return encode_instruction(state_of(k - 1)["id"], 0x03, bytes([3]) + data + s["ccw_angle_limit"].to_bytes(2, "little"))


def which_write(registers: dict[str, int], low: int, high: int) -> int | None:
    """The k in low..high whose state equals ``registers`` exactly, or None."""
    for k in range(low, high + 1):
        if all(registers.get(name) == value for name, value in state_of(k).items()):
            return k
    return None


@dataclass
class Report:
    """What the iterations showed."""

    iterations: int = 0
    writes_sent: int = 0
    writes_acked: int = 0
    #: Kills that landed with a write sent but not yet acknowledged (the interesting window).
    kills_mid_burst: int = 0
    #: Restarts whose file held a write newer than the last acknowledgement (saved, reply not yet out).
    ahead_of_ack: int = 0
    #: Kills that left a temporary file behind (the next start removes it).
    kills_leaving_temp_file: int = 0
    failures: list[str] = field(default_factory=list)


def _start(state_dir: Path) -> tuple[subprocess.Popen, str]:
    process = subprocess.Popen(
        [sys.executable, "-m", "ax12emu", "serve", "--state-dir", str(state_dir), "--model", "kinematic",
         "--eeprom-busy-ms", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    ready, _, _ = select.select([process.stdout], [], [], 20)
    line = process.stdout.readline().strip() if ready else ""
    if not line:
        process.kill()
        _, err = process.communicate(timeout=5)
        why = (err.strip().splitlines() or [f"exit status {process.returncode}"])[-1]  # its one-line error
        raise RuntimeError(f"the emulator did not start: {why}")
    return process, line


def _read_state(state_dir: Path) -> dict[str, int]:
    path = state_dir / "servo-001.json"
    if not path.exists():
        return dict(FACTORY)
    return json.loads(path.read_text(encoding="utf-8"))["eeprom"]


def run(iterations: int, *, seed: int = 0, state_dir: Path | None = None, max_kill_s: float = 0.06,
        log: callable | None = None) -> Report:
    """Run ``iterations`` kill/restart cycles; failures are collected, not raised."""
    rng = random.Random(seed)
    own_dir = tempfile.TemporaryDirectory(prefix="ax12emu-crash-") if state_dir is None else None
    directory = Path(own_dir.name) if own_dir else Path(state_dir)
    report = Report()
    k_last = -1  # the write the state holds (verified on restart)
    try:
        for iteration in range(iterations):
            try:
                process, port = _start(directory)
            except RuntimeError as exc:
                if not iteration:  # the state folder as given (a file, unwritable, a state it refuses): the caller's
                    raise
                report.failures.append(f"iteration {iteration}: restart after SIGKILL: {exc}")
                break
            leftovers = [p.name for p in directory.iterdir() if p.name.endswith(".tmp")]
            if leftovers:
                report.failures.append(f"iteration {iteration}: temporary files survived a restart: {leftovers}")
            try:
                with serial.Serial(port, 1_000_000, timeout=0.5) as link:
                    # The restarted servo must answer at the persisted ID with the persisted registers.
                    expected = state_of(k_last)
                    link.write(encode_instruction(expected["id"], 0x02, bytes([3, 7])))
                    reply = link.read(13)  # header, ID, LENGTH, error, 7 bytes, checksum
                    want = bytes([expected["id"], 1, expected["return_delay_time"]]) + expected[
                        "cw_angle_limit"].to_bytes(2, "little") + expected["ccw_angle_limit"].to_bytes(2, "little")
                    if len(reply) != 13 or reply[5:12] != want:
                        report.failures.append(f"iteration {iteration}: READ after restart gave {reply.hex()}, "
                                               f"expected registers {want.hex()}")
                        break
                    link.reset_input_buffer()
                    acked = _burst_and_kill(link, process, k_last, rng.uniform(0.0, max_kill_s), report)
            finally:
                if process.poll() is None:
                    process.kill()
                process.wait(10)
                process.stdout.close()
                process.stderr.close()
            report.iterations += 1
            report.writes_acked += acked - k_last
            report.kills_leaving_temp_file += any(p.name.endswith(".tmp") for p in directory.iterdir())
            try:
                registers = _read_state(directory)
            except (ValueError, KeyError, OSError) as exc:
                report.failures.append(f"iteration {iteration}: state file unreadable after SIGKILL: {exc}")
                break
            found = which_write(registers, acked, k_last + BURST)
            if found is None:
                report.failures.append(
                    f"iteration {iteration}: state {registers} is no single write in {acked}..{k_last + BURST} "
                    "(partial, mixed, or older than an acknowledged write)")
                break
            report.ahead_of_ack += found > acked
            if log:
                log(f"iteration {iteration}: acked up to write {acked}, file holds write {found}"
                    f"{' (saved, not yet acknowledged)' if found > acked else ''}")
            k_last = found
    finally:
        if own_dir:
            own_dir.cleanup()
    return report


def _burst_and_kill(link: serial.Serial, process: subprocess.Popen, k_last: int, kill_after_s: float,
                    report: Report) -> int:
    """Send a pipelined burst from write k_last+1, SIGKILL after ``kill_after_s``; return the last write acked."""
    received = bytearray()
    done = threading.Event()

    def reader() -> None:
        while not done.is_set():
            try:
                chunk = link.read(link.in_waiting or 1)
            except (serial.SerialException, OSError, TypeError):
                break
            received.extend(chunk)

    thread = threading.Thread(target=reader, daemon=True)
    thread.start()
    burst = b"".join(write_packet(k) for k in range(k_last + 1, k_last + 1 + BURST))
    started = time.monotonic()
    sent = 0
    for start in range(0, len(burst), 14 * 8):  # 8 packets per write call, as a busy host would
        link.write(burst[start : start + 14 * 8])
        sent += 8
        if time.monotonic() - started >= kill_after_s:
            break
    remaining = kill_after_s - (time.monotonic() - started)
    if remaining > 0:
        time.sleep(remaining)
    os.kill(process.pid, signal.SIGKILL)
    process.wait(10)
    time.sleep(0.02)
    done.set()
    thread.join(2)
    acks = _count_acks(bytes(received), k_last)
    report.writes_sent += min(sent, BURST)
    report.kills_mid_burst += acks < min(sent, BURST)
    return k_last + acks


def _count_acks(data: bytes, k_last: int) -> int:
    """Status packets without error, each from the ID of the write before it (the old ID)."""
    count = 0
    while len(data) >= 6 and data[:2] == b"\xff\xff":
        if data[2] != state_of(k_last + count)["id"] or data[3:5] != b"\x02\x00":
            break
        count += 1
        data = data[6:]
    return count


def main(argv: list[str] | None = None) -> int:
    """Parse arguments, run the kills, print the figures; exit 1 on any failure."""
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--iterations", type=positive_int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--state-dir", type=file_name, help="keep the state here (default: a temporary directory)")
    parser.add_argument("-v", "--verbose", action="store_true", help="one line per iteration")
    args = parser.parse_args(argv)
    started = time.monotonic()
    try:
        report = run(args.iterations, seed=args.seed, state_dir=None if args.state_dir is None else Path(args.state_dir),
                     log=print if args.verbose else None)
    except RuntimeError as exc:  # the emulator's first start refused --state-dir (a file, unwritable, a bad state)
        print(f"{parser.prog}: error: {exc}", file=sys.stderr)
        return 2
    print(f"iterations: {report.iterations} in {time.monotonic() - started:.1f} s; SIGKILL with a write "
          f"unacknowledged: {report.kills_mid_burst}; file newer than the last ack: {report.ahead_of_ack}")
    print(f"writes sent: {report.writes_sent}, acknowledged: {report.writes_acked}; "
          f"kills that left a temporary file (removed at the next start): {report.kills_leaving_temp_file}")
    for failure in report.failures:
        print(f"FAILURE: {failure}")
    print(f"failures: {len(report.failures)}")
    return 1 if report.failures else 0


if __name__ == "__main__":
    sys.exit(main())
