#!/usr/bin/env python3
"""Record a trace from a real (or emulated) AX-12 on any Protocol 1.0 port through dynamixel-sdk.

Why it exists: a user with hardware gets data for ``python -m
firmware_model.diagnose`` in one command.  It runs the same excitation
program as tools/make_dataset.py (firmware_model.diagnose.excitation),
writing Goal Position / Moving Speed when they change and reading Present
Position, Speed, Load and Voltage (addresses 36-42, one read) at ``--rate``.
The supply goes into the trace's ``voltage`` column as one value, the
median of the readings (the diagnosis otherwise assumes one, and a fit at
the wrong supply names the difference as friction or a drive ceiling).  The
program's external-load segments are plain holds here (a bus cannot apply a
load; hang one by hand if wanted).  ``t`` is the host's monotonic clock
midway between sending the read and its reply returning, relative to the
start (the servo answers from registers of that moment; a stamp taken after
the reply would be late by the reply's own time, 0.5-3 ms, varying).  Each
command change is written right after a reading, and ``command_t`` records
when it was sent: two recordings of the same servo differ mostly by when
each command went out, and a trace that says so lets the diagnosis tell a
reading latency (effect ``delay``) from it.  ``--write NAME=VALUE`` sets a
control-table register (by its e-manual name, e.g. ``cw_compliance_margin=4``)
before the excitation starts.

Usage: ``python tools/record.py PORT OUT.csv [--id 1] [--baud 1000000] [--duration 20] [--rate 100]
[--breakaway SECONDS] [--write NAME=VALUE ...]`` (``--breakaway``: end with that many seconds of small steps and moderate-speed
moves, which show breakaway/Stribeck friction; see firmware_model.diagnose.excitation).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ax12emu.cli.arg_types import (  # noqa: E402
    OneLineParser,
    int_range,
    nonnegative_float,
    output_file,
    positive_float,
    positive_int,
)
from ax12emu.protocol.control_table import layout  # noqa: E402
from ax12emu.protocol.packets import MAX_ID  # noqa: E402
from firmware_model.diagnose.excitation import program  # noqa: E402
from firmware_model.diagnose.trace import Trace, write_trace  # noqa: E402

#: The registers the recorder itself uses (e-manual names; addresses and sizes from the control table).
_TABLE = layout().by_name
_PRESENT = ("present_position", "present_speed", "present_load", "present_voltage")
_COLUMNS = ("t", "goal_position", "moving_speed", "present_position", "present_speed", "present_load", "command_t",
            "voltage")


def _signed(raw: int) -> int:
    return -(raw & 0x3FF) if raw & 0x400 else raw & 0x3FF


def supply_column(readings: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """The trace's ``voltage`` column from each row's Present Voltage (0.1 V): their median on every row, and a
    comment where the readings varied.

    Why one value: a trace's voltage is a command, in effect from its row on, and each change starts a new
    segment of the replay; a reading that wavers by 0.1 V as the motor draws current would make every waver a
    command the servo never got (and, without a write at that row, a ``command_t`` the trace format refuses).
    """
    volts = np.full(len(readings), int(round(float(np.median(readings)))), dtype=np.int64)
    if int(np.ptp(readings)) == 0:
        return volts, []
    return volts, [f"Present Voltage read {readings.min() / 10:.1f}-{readings.max() / 10:.1f} V; the voltage column "
                   f"is their median, {volts[0] / 10:.1f} V"]


#: Registers whose write cuts the recorder off from the servo it goes on talking to (``--id`` at ``--baud``, every
#: write answered): the next write would go unanswered after the servo had already moved.
UNREACHABLE_AFTER = {
    "id": "the servo would answer as another ID than --id",
    "baud_rate": "the servo would listen at another rate than the port's",
    "status_return_level": "the recorder needs every write answered (Status Return Level 2)",
}


def parse_writes(items: list[str]) -> dict[str, int]:
    """``NAME=VALUE`` strings -> {register name: value}, checked against the control table (ValueError if not)."""
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        entry = _TABLE.get(name.strip())
        if not sep or entry is None:
            known = ", ".join(e.name for e in _TABLE.values() if e.access.value == "RW")
            raise ValueError(f"--write {item!r}: expected NAME=VALUE with NAME a writable register ({known})")
        try:
            number = int(value)
        except ValueError:
            raise ValueError(f"--write {item!r}: {value!r} is not an integer") from None
        if entry.access.value != "RW" or not entry.minimum <= number <= entry.maximum:
            raise ValueError(f"--write {item!r}: {name} takes {entry.minimum}..{entry.maximum} and must be writable")
        if entry.name in UNREACHABLE_AFTER:
            raise ValueError(f"--write {item!r}: {UNREACHABLE_AFTER[entry.name]}; set it before recording")
        out[entry.name] = number
    return out


#: A set-up write is tried this often: on a loaded machine a reply now and then misses dynamixel-sdk's timeout.
WRITE_ATTEMPTS = 3


def _write(ph, port, servo_id: int, name: str, value: int) -> None:
    from dynamixel_sdk import COMM_SUCCESS

    entry = _TABLE[name]
    write = ph.write1ByteTxRx if entry.size == 1 else ph.write2ByteTxRx
    for _ in range(WRITE_ATTEMPTS):
        result, error = write(port, servo_id, entry.address, value)
        if result == COMM_SUCCESS:
            break
    if result != COMM_SUCCESS or error:
        raise RuntimeError(f"writing {name}={value} to servo {servo_id} failed: {ph.getTxRxResult(result)} "
                           f"{ph.getRxPacketError(error) if error else ''}".strip())


def record(port_name: str, servo_id: int, baud: int, duration_s: float, rate_hz: float,
           breakaway_s: float = 0.0, writes: dict[str, int] | None = None) -> Trace:
    """Set ``writes`` (register name -> value), run the excitation and return the trace (with ``command_t``)."""
    from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

    port, ph = PortHandler(port_name), PacketHandler(1.0)
    try:
        opened = port.openPort()
    except (OSError, ValueError) as exc:  # pyserial's SerialException is an OSError: a missing or non-tty path
        raise SystemExit(f"cannot open {port_name}: {exc}") from None
    if not opened:
        raise SystemExit(f"cannot open {port_name}")
    goal = _TABLE["goal_position"]
    first = _TABLE[_PRESENT[0]].address
    span = _TABLE[_PRESENT[-1]].end - first
    try:
        if not port.setBaudRate(baud):
            raise SystemExit(f"cannot set {port_name} to {baud} baud")
        for name, value in (writes or {}).items():
            _write(ph, port, servo_id, name, value)
        _write(ph, port, servo_id, "torque_enable", 1)
        steps = program(duration_s, breakaway_s)
        ends = np.cumsum([s.duration_s for s in steps])
        rows: list[list] = []
        written, sent_t = None, 0.0
        start = time.monotonic()
        next_read = start
        while True:
            now = time.monotonic()
            if now - start >= duration_s:
                break
            if now < next_read:
                time.sleep(next_read - now)
            next_read += 1.0 / rate_hz
            asked = time.monotonic()
            data, result, error = ph.readTxRx(port, servo_id, first, span)
            t = 0.5 * (asked + time.monotonic()) - start
            if result != COMM_SUCCESS or len(data) < span:
                continue
            pos = data[0] | data[1] << 8
            spd = _signed(data[2] | data[3] << 8)
            load = _signed(data[4] | data[5] << 8)
            supply = data[6]  # 0.1 V: one more byte of the same read
            step = steps[min(int(np.searchsorted(ends, t, side="right")), len(steps) - 1)]
            cmd = (step.goal_position, step.moving_speed)
            if cmd != written:  # Goal Position and Moving Speed in one write, after the read
                payload = [cmd[0] & 0xFF, cmd[0] >> 8, cmd[1] & 0xFF, cmd[1] >> 8]
                sent_t = time.monotonic() - start
                ph.writeTxRx(port, servo_id, goal.address, 4, payload)
                written = cmd
            rows.append([t, cmd[0], cmd[1], pos, spd, load, sent_t, supply])
    finally:
        port.closePort()
    if not rows:
        raise RuntimeError(f"no reading of servo {servo_id} on {port_name} succeeded in {duration_s:g} s")
    a = np.array(rows, dtype=float)
    comment = f"recorded by tools/record.py on {port_name}" + "".join(f", {k}={v}" for k, v in (writes or {}).items())
    columns = {c: a[:, i] for i, c in enumerate(_COLUMNS)}
    columns["voltage"], supply_notes = supply_column(columns["voltage"])
    return Trace(columns, comments=[comment, *supply_notes])


def main(argv: list[str] | None = None) -> int:
    """Record and write the trace."""
    p = OneLineParser(description=__doc__.splitlines()[0])
    p.add_argument("port", help="serial port, e.g. /dev/ttyUSB0 (or an emulator's pty)")
    p.add_argument("out", type=output_file, help="trace CSV to write")
    p.add_argument("--id", type=int_range(0, MAX_ID), default=1)  # not 254: a broadcast is never answered
    p.add_argument("--baud", type=positive_int, default=1_000_000)
    p.add_argument("--duration", type=positive_float, default=20.0)
    p.add_argument("--rate", type=positive_float, default=100.0)
    p.add_argument("--breakaway", type=nonnegative_float, default=0.0,
                   help="seconds of breakaway block at the end (default 0)")
    p.add_argument("--write", action="append", default=[], metavar="NAME=VALUE",
                   help="set a register before the excitation, e.g. torque_limit=512 (repeatable)")
    args = p.parse_args(argv)
    try:
        writes = parse_writes(args.write)
    except ValueError as exc:
        p.error(str(exc))
    if not args.rate <= 1000:
        p.error("--rate must be in (0, 1000]")
    if not args.breakaway < args.duration:  # the excitation ends with it: found here, not after opening the port
        p.error("--breakaway must be shorter than --duration")
    try:
        trace = record(args.port, args.id, args.baud, args.duration, args.rate, args.breakaway, writes)
    except RuntimeError as exc:  # a set-up write unanswered, or no reading at all: the servo or port is not there
        print(f"error: {exc}", file=sys.stderr)
        return 3
    write_trace(trace, args.out)
    print(f"{args.out}: {len(trace)} rows over {trace.t[-1]:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
