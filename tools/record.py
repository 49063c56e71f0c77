#!/usr/bin/env python3
"""Record a trace from a real (or emulated) AX-12 on any Protocol 1.0 port through dynamixel-sdk.

Why it exists: a user with hardware gets data for ``python -m
firmware_model.diagnose`` in one command.  It runs the same excitation
program as tools/make_dataset.py (firmware_model.diagnose.excitation),
writing Goal Position / Moving Speed when they change and reading Present
Position, Speed and Load (addresses 36-41, one read) at ``--rate``.  The
program's external-load segments are plain holds here (a bus cannot apply a
load; hang one by hand if wanted).  ``t`` is the host's monotonic clock at
the read, relative to the first read.

Usage: ``python tools/record.py PORT OUT.csv [--id 1] [--baud 1000000] [--duration 20] [--rate 100]
[--breakaway SECONDS]`` (``--breakaway``: end with that many seconds of small steps and moderate-speed
moves, which show breakaway/Stribeck friction; see firmware_model.diagnose.excitation).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from firmware_model.diagnose.excitation import program  # noqa: E402
from firmware_model.diagnose.trace import Trace, write_trace  # noqa: E402

ADDR_TORQUE_ENABLE, ADDR_GOAL, ADDR_PRESENT = 24, 30, 36


def _signed(raw: int) -> int:
    return -(raw & 0x3FF) if raw & 0x400 else raw & 0x3FF


def record(port_name: str, servo_id: int, baud: int, duration_s: float, rate_hz: float,
           breakaway_s: float = 0.0) -> Trace:
    """Run the excitation and return the trace."""
    from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

    port, ph = PortHandler(port_name), PacketHandler(1.0)
    if not port.openPort() or not port.setBaudRate(baud):
        raise SystemExit(f"cannot open {port_name} at {baud} baud")
    try:
        steps = program(duration_s, breakaway_s)
        ends = np.cumsum([s.duration_s for s in steps])
        ph.write1ByteTxRx(port, servo_id, ADDR_TORQUE_ENABLE, 1)
        rows: list[list] = []
        written = None
        start = time.monotonic()
        next_read = start
        while True:
            now = time.monotonic()
            if now - start >= duration_s:
                break
            if now < next_read:
                time.sleep(next_read - now)
            next_read += 1.0 / rate_hz
            data, result, error = ph.readTxRx(port, servo_id, ADDR_PRESENT, 6)
            t = time.monotonic() - start
            if result != COMM_SUCCESS or len(data) < 6:
                continue
            pos = data[0] | data[1] << 8
            spd = _signed(data[2] | data[3] << 8)
            load = _signed(data[4] | data[5] << 8)
            step = steps[min(int(np.searchsorted(ends, t, side="right")), len(steps) - 1)]
            cmd = (step.goal_position, step.moving_speed)
            if cmd != written:  # Goal Position and Moving Speed in one write, after the read
                payload = [cmd[0] & 0xFF, cmd[0] >> 8, cmd[1] & 0xFF, cmd[1] >> 8]
                ph.writeTxRx(port, servo_id, ADDR_GOAL, 4, payload)
                written = cmd
            rows.append([t, cmd[0], cmd[1], pos, spd, load])
    finally:
        port.closePort()
    a = np.array(rows, dtype=float)
    cols = ("t", "goal_position", "moving_speed", "present_position", "present_speed", "present_load")
    return Trace({c: a[:, i] for i, c in enumerate(cols)}, comments=[f"recorded by tools/record.py on {port_name}"])


def main(argv: list[str] | None = None) -> int:
    """Record and write the trace."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("port", help="serial port, e.g. /dev/ttyUSB0 (or an emulator's pty)")
    p.add_argument("out", help="trace CSV to write")
    p.add_argument("--id", type=int, default=1)
    p.add_argument("--baud", type=int, default=1_000_000)
    p.add_argument("--duration", type=float, default=20.0)
    p.add_argument("--rate", type=float, default=100.0)
    p.add_argument("--breakaway", type=float, default=0.0, help="seconds of breakaway block at the end (default 0)")
    args = p.parse_args(argv)
    trace = record(args.port, args.id, args.baud, args.duration, args.rate, args.breakaway)
    write_trace(trace, args.out)
    print(f"{args.out}: {len(trace)} rows over {trace.t[-1]:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
