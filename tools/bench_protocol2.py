"""Benchmark: dynamixel-sdk with PacketHandler(2.0) against ``ax12emu serve --servo`` over the pty.

Prints transactions per second and p50/p99 latency for what a robot's control loop does on a
bus of X-series servos: a 4-byte read of one servo, a Sync Read, a Fast Sync Read and a Bulk
Read of all of them, and a Sync Write, each with Return Delay Time 0 (the wire's own time
without ``--pace`` is nothing) and at the factory 250 (500 us per servo answering), plus the
time broadcastPing takes to find every servo.  The Sync Read's status packets come one after
another, each Return Delay Time after the previous one (without ``--pace`` bytes take no time, so
not after it ended), so at RDT 250 it should take about 500 us per servo more than at RDT 0; that
difference is printed beside its goal.

Usage: ``python tools/bench_protocol2.py [--seconds 2] [--servos 6] [--model xl430-w250]``
"""

from __future__ import annotations

import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

from dynamixel_sdk import COMM_SUCCESS, GroupBulkRead, GroupSyncRead, GroupSyncWrite, PacketHandler, PortHandler

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from ax12emu.cli.arg_types import OneLineParser, int_range, positive_float  # noqa: E402
from ax12emu.harness.served import start_served  # noqa: E402
from ax12emu.protocol.packets2 import MAX_ID2  # noqa: E402
from ax12emu.protocol.servo_models import model as servo_model  # noqa: E402
from ax12emu.protocol.servo_models import model_names  # noqa: E402

BAUD = 1_000_000
PRESENT_POSITION, GOAL_POSITION, RETURN_DELAY_TIME, LED = 132, 116, 9, 65
#: What ``--model`` may name: the addresses above are the X series' control table, which an XL-320's or a
#: Protocol 1.0 model's is not; another would fail only once served.
X_MODELS = tuple(k for k in model_names() if servo_model(k).protocols == ("2.0",) and servo_model(k).classic is None)


def measure(name: str, transaction: Callable[[], bool], seconds: float) -> list[float]:
    """Run ``transaction`` for ``seconds``; print rate and latency; return the latencies (s)."""
    latencies: list[float] = []
    failures = 0
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        start = time.perf_counter()
        if not transaction():
            failures += 1
        latencies.append(time.perf_counter() - start)
    latencies.sort()
    p99 = latencies[min(len(latencies) - 1, int(0.99 * len(latencies)))]
    print(f"{name:44s} {len(latencies) / seconds:8.0f}/s  p50 {statistics.median(latencies) * 1e6:8.0f} us"
          f"  p99 {p99 * 1e6:8.0f} us  failures {failures}")
    return latencies


def run(seconds: float, servos: int, model: str) -> None:
    ids = list(range(1, servos + 1))
    served = start_served(["--servo", model, "--ids", f"1-{servos}", "--baud", str(BAUD)])
    try:
        port = PortHandler(served.port)
        assert port.openPort() and port.setBaudRate(BAUD)
        ph = PacketHandler(2.0)
        started = time.perf_counter()
        found, comm = ph.broadcastPing(port)
        print(f"broadcastPing: {len(found)} of {servos} found in {(time.perf_counter() - started) * 1e3:.0f} ms "
              f"(the SDK waits its whole timeout, {comm == COMM_SUCCESS and 'success' or comm})")
        sync = GroupSyncRead(port, ph, PRESENT_POSITION, 4)
        bulk = GroupBulkRead(port, ph)
        for servo_id in ids:
            sync.addParam(servo_id)
            bulk.addParam(servo_id, PRESENT_POSITION if servo_id % 2 else LED, 4 if servo_id % 2 else 1)
        write = GroupSyncWrite(port, ph, GOAL_POSITION, 4)
        for servo_id in ids:
            write.addParam(servo_id, list((2048).to_bytes(4, "little")))
        medians = {}
        for rdt in (0, 250):
            for servo_id in ids:
                ph.write1ByteTxRx(port, servo_id, RETURN_DELAY_TIME, rdt)
            print(f"-- Return Delay Time {rdt} ({rdt * 2} us), {servos} x {model}, {BAUD} bps, no --pace")
            measure("read4ByteTxRx (one servo)", lambda: ph.read4ByteTxRx(port, 1, PRESENT_POSITION)[1] == COMM_SUCCESS,
                    seconds)
            medians[rdt] = statistics.median(measure(f"GroupSyncRead x {servos}", lambda: sync.txRxPacket() == COMM_SUCCESS,
                                                     seconds))
            measure(f"fastSyncRead x {servos}", lambda: sync.fastSyncRead() == COMM_SUCCESS, seconds)
            measure(f"GroupBulkRead x {servos}", lambda: bulk.txRxPacket() == COMM_SUCCESS, seconds)
            measure(f"GroupSyncWrite x {servos} (no answer)", lambda: write.txPacket() == COMM_SUCCESS, seconds)
        added_us = (medians[250] - medians[0]) * 1e6
        print(f"\nSync Read at RDT 250 adds {added_us:.0f} us at p50 over RDT 0 (goal {servos} x 500 = {servos * 500} us: "
              "each servo waits its Return Delay Time after the previous status)")
        port.closePort()
    finally:
        served.close()


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=positive_float, default=2.0, help="measuring time per transaction kind")
    parser.add_argument("--servos", type=int_range(1, MAX_ID2), default=6, help="servos on the bus (IDs 1..N)")
    parser.add_argument("--model", default="xl430-w250", choices=X_MODELS, help="the X-series model (ax12emu models)")
    args = parser.parse_args(argv)
    run(args.seconds, args.servos, args.model)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
