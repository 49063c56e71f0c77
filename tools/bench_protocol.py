"""Benchmark: 2-byte reads through dynamixel-sdk over the pty, against references measured in the same run.

Prints, for each configuration, reads per second and p50/p99 latency, then
ratios against two references taken on this machine in this run:

* a bare pty responder (a few lines that answer every 8-byte read with a
  fixed reply): the ceiling any emulator can reach here;
* the wire limit: a 2-byte READ is 8 bytes out and 8 back, 10 bits each,
  so 160 bit-times per read (6,250 reads/s at 1 Mbps).

Goals (issue 2): at Return Delay Time 0, >= 80 % of the bare responder's
rate with p99 < 1 ms; Return Delay Time 250 adds 500 +/- 50 us per read;
with ``--pace`` the rate matches the wire limit within 5 %.  For ``--pace`` the
emulator's own part of each read (from the instruction's arrival to the
reply's last byte, read from its ``--trace``) is printed beside the rate the
client sees, which also carries the client's own time per transaction.

Usage: ``python tools/bench_protocol.py [--seconds 3]``
"""

from __future__ import annotations

import argparse
import os
import select
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

BARE_RESPONDER = textwrap.dedent(
    """
    import os, pty, select, sys, tty
    master, slave = pty.openpty()
    tty.setraw(slave)
    print(os.ttyname(slave), flush=True)
    reply = bytes([0xFF, 0xFF, 1, 4, 0, 0, 2, 0xF8])
    pending = b""
    while True:
        select.select([master], [], [])
        pending += os.read(master, 4096)
        while len(pending) >= 8:
            pending = pending[8:]
            os.write(master, reply)
    """
)


def start(command: list[str]) -> tuple[subprocess.Popen, str]:
    """Start a server process and read the port path it prints first."""
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    ready, _, _ = select.select([process.stdout], [], [], 20)
    if not ready:
        process.kill()
        raise RuntimeError(f"{command} printed no port")
    return process, process.stdout.readline().strip()


def stop(process: subprocess.Popen) -> None:
    """Terminate by pid and reap."""
    process.terminate()
    try:
        process.wait(5)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


def measure(path: str, seconds: float, *, baud: int = 1_000_000, setup=None) -> dict:
    """Read Present Position of ID 1 as fast as possible for ``seconds``; rate and latency."""
    port = PortHandler(path)
    port.openPort()
    port.setBaudRate(baud)
    ph = PacketHandler(1.0)
    if setup:
        setup(port, ph)
    for _ in range(200):  # warm up
        ph.read2ByteTxRx(port, 1, 36)
    latencies, failures = [], 0
    end = time.perf_counter() + seconds
    start_s = time.perf_counter()
    while time.perf_counter() < end:
        t0 = time.perf_counter()
        _, comm, _ = ph.read2ByteTxRx(port, 1, 36)
        latencies.append(time.perf_counter() - t0)
        failures += comm != COMM_SUCCESS
    elapsed = time.perf_counter() - start_s
    port.closePort()
    latencies.sort()
    return {
        "rate": len(latencies) / elapsed,
        "p50_us": latencies[len(latencies) // 2] * 1e6,
        "p99_us": latencies[int(len(latencies) * 0.99)] * 1e6,
        "failures": failures,
        "count": len(latencies),
    }


def configure(rdt: int, ids: list[int], moving: bool, baud_value: int | None = None):
    """A setup callback: Return Delay Time on every servo, optionally wheel-mode motion and a baud change."""

    def setup(port: PortHandler, ph: PacketHandler) -> None:
        for servo_id in ids:
            ph.write1ByteTxRx(port, servo_id, 5, rdt)
            if moving:
                ph.write4ByteTxRx(port, servo_id, 6, 0)  # both angle limits 0: wheel mode
                ph.write1ByteTxRx(port, servo_id, 24, 1)
                ph.write2ByteTxRx(port, servo_id, 32, 300 + servo_id)
        if baud_value is not None:
            for servo_id in ids:
                ph.write1ByteTxOnly(port, servo_id, 4, baud_value)
            time.sleep(0.05)

    return setup


def transaction_times(trace: Path) -> list[float]:
    """From an emulator trace: time from a READ's arrival to the last byte of its 8-byte reply."""
    from ax12emu.trace import IN, read_trace

    times, start_s, pending = [], None, 0
    for chunk in read_trace(trace):
        if chunk.direction == IN and len(chunk.data) == 8 and chunk.data[4] == 0x02:
            start_s, pending = chunk.t, 8
        elif start_s is not None and chunk.direction != IN:
            pending -= len(chunk.data)
            if pending <= 0:
                times.append(chunk.t - start_s)
                start_s = None
    return times[200:] or times  # skip the warm-up reads


def row(label: str, result: dict, reference: float | None = None) -> str:
    ratio = f"{result['rate'] / reference:7.1%}" if reference else "       "
    return (
        f"{label:<44} {result['rate']:9.0f}/s {ratio}  p50 {result['p50_us']:7.0f} us"
        f"  p99 {result['p99_us']:7.0f} us  failures {result['failures']}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="measuring time per configuration")
    args = parser.parse_args(argv)
    emulator = [sys.executable, "-m", "ax12emu", "serve"]

    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp, "bare.py")
        script.write_text(BARE_RESPONDER)
        process, path = start([sys.executable, str(script)])
        try:
            bare = measure(path, args.seconds)
        finally:
            stop(process)
    wire_1m = 1e6 / 160
    print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}")
    print(row("reference: bare pty responder", bare))
    print(f"{'reference: 1 Mbps wire limit (16 bytes/read)':<44} {wire_1m:9.0f}/s")

    results = {}
    for servos in (1, 18):
        ids = list(range(1, servos + 1))
        for rdt in (0, 250):
            process, path = start(emulator + ["--ids", f"1-{servos}"])
            try:
                result = measure(path, args.seconds, setup=configure(rdt, ids, moving=True))
            finally:
                stop(process)
            results[servos, rdt] = result
            print(row(f"ax12emu, {servos:2d} servo(s) moving, RDT {rdt:3d}", result, bare["rate"]))

    print()
    for servos in (1, 18):
        fast, slow = results[servos, 0], results[servos, 250]
        print(
            f"{servos:2d} servo(s): RDT 0 at {fast['rate'] / bare['rate']:.1%} of bare (goal >= 80 %), "
            f"p99 {fast['p99_us']:.0f} us (goal < 1000); RDT 250 adds {slow['p50_us'] - fast['p50_us']:.0f} us "
            f"at p50 (goal 500 +/- 50)"
        )

    print()
    print("--pace: rate seen by dynamixel-sdk, and the emulator's own time per read (from its --trace)")
    for baud_value, host_baud in ((1, 1_000_000), (16, 115_200), (34, 57_600)):
        servo_bps = 2_000_000 / (baud_value + 1)
        wire_s = 80 / host_baud + 80 / servo_bps
        with tempfile.TemporaryDirectory() as tmp:
            trace = Path(tmp, "pace.jsonl")
            process, path = start(emulator + ["--pace", "--trace", str(trace)])
            try:
                setup = configure(0, [1], moving=False, baud_value=None if baud_value == 1 else baud_value)
                prepare = PortHandler(path)
                prepare.openPort()
                setup(prepare, PacketHandler(1.0))
                prepare.closePort()
                result = measure(path, args.seconds, baud=host_baud)
            finally:
                stop(process)
            own_s = statistics.median(transaction_times(trace))
        print(row(f"--pace at {servo_bps:9.0f} bps (wire limit {1 / wire_s:5.0f}/s)", result, 1 / wire_s))
        print(
            f"{'':<44} emulator's own time per read: median {own_s * 1e6:7.0f} us = "
            f"{own_s / wire_s:.1%} of the wire time {wire_s * 1e6:.0f} us"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
