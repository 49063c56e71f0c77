#!/usr/bin/env python3
"""Close the loop live: measure a servo with a hidden effect, diagnose it, serve the twin, measure the twin.

Why it exists: the diagnosis writes a params.toml meant to make the emulator
behave like the measured servo.  This checks that it does, through the same
path a user takes, in real time: serve the emulator with an effect hidden
behind a public knob (``--arm``, ``--voltage``, a register written before
the excitation, or a params file with an effect), record it live through
dynamixel-sdk (tools/record.py: the diagnosis's excitation at ``--rate``),
run ``python -m firmware_model.diagnose`` on the recording, serve
``--params DIR/params.toml`` and record again with the same excitation, and
record the plain emulator too.  It prints each recording's position gap to
the measurement; the goal is a twin gap at most half the plain one.

Gaps are compared with the recordings aligned on when each command was sent
(:func:`aligned_gap`): two live recordings of the same servo differ by
1-2.5 units RMS merely because each command went out a few ms earlier or
later, and aligned segment by segment they agree to about 0.6.  The
measured servo recorded a second time gives that floor (``--floor``).

Usage: ``python tools/twin_check.py [--arm MASS_KG,LENGTH_M] [--hidden-params FILE] [--voltage V]
[--write NAME=VALUE ...] [--duration 20] [--rate 100] [--breakaway 4] [--out DIR] [--floor]``
(with no hidden knob given, ``--arm 0.35,0.1``: an arm of 0.34 N m weight moment).

Exit status: 0 goal met, 1 goal missed, 2 a recording that cannot be compared (cut short, e.g. the served
emulator stopped, or not the same commands as the measurement), 3 the served emulator or the diagnosis
failed; errors are one line on stderr.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import termios
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ax12emu.cli.arg_types import (  # noqa: E402
    OneLineParser,
    file_name,
    name_list,
    nonnegative_float,
    positive_float,
)
from ax12emu.harness.served import start_served  # noqa: E402
from ax12emu.servo.model_factory import parse_arm  # noqa: E402
from firmware_model.diagnose.effects import LIBRARY  # noqa: E402
from firmware_model.diagnose.trace import Trace, TraceFormatError, read_trace, write_trace  # noqa: E402

#: The hidden effect when none is given: an arm whose weight moment (0.34 N m) is a quarter of the stall torque.
DEFAULT_ARM = "0.35,0.1"
#: The twin must come at least this much closer to the measurement than the plain emulator.
GOAL_RATIO = 0.5

#: serve arguments, where the recording goes -> the recorded trace (live: a served emulator and tools/record.py).
Recorder = Callable[[list[str], dict[str, int], Path], Trace]
#: A live recording may end this many read periods (or 0.1 s, whichever is longer) short of its duration:
#: the reads are paced from the start, so only the last one or two can fall past the end.
SHORT_BY_PERIODS = 3


class RecordingError(ValueError):
    """A recording that cannot be compared: cut short, or not the same commands as the measurement."""


def check_complete(trace: Trace, duration_s: float, rate_hz: float, name: str) -> None:
    """Raise :class:`RecordingError` if ``trace`` stops well before ``duration_s`` (a served emulator that died)."""
    slack_s = max(SHORT_BY_PERIODS / rate_hz, 0.1)
    end_s = float(trace.t[-1]) if len(trace) else 0.0
    if end_s < duration_s - slack_s:
        raise RecordingError(f"{name}: the recording ends at {end_s:.2f} s of {duration_s:g} s ({len(trace)} rows): "
                             "cut short (did the served emulator stop?)")


# ---------------------------------------------------------------------------------- comparison
def command_segments(trace: Trace) -> list[tuple[float, np.ndarray]]:
    """Per command sent: (its send time, the row indices read under it), in order.

    A trace without ``command_t`` is cut where the commands change, at the first row under the new ones.
    """
    if trace.has("command_t"):
        sent = trace["command_t"]
    else:
        changed = np.r_[True, (np.diff(trace["goal_position"]) != 0) | (np.diff(trace["moving_speed"]) != 0)]
        sent = np.maximum.accumulate(np.where(changed, trace.t, -np.inf))
    starts = np.r_[0, np.nonzero(np.diff(sent))[0] + 1]
    ends = np.r_[starts[1:], len(sent)]
    return [(float(sent[a]), np.arange(a, b)) for a, b in zip(starts, ends)]


def aligned_gap(measured: Trace, other: Trace) -> float:
    """RMS position gap (units), each command's segment compared on the time since that command was sent.

    Within segment k, ``other``'s position is interpolated at the measured rows' times since command k;
    rows past the end of ``other``'s segment k are left out.  Both must have run the same commands.
    """
    seg_m, seg_o = command_segments(measured), command_segments(other)
    if len(seg_m) != len(seg_o):
        raise RecordingError(f"the recordings sent different numbers of commands ({len(seg_m)} vs {len(seg_o)})")
    errors = []
    for (sent_m, rows_m), (sent_o, rows_o) in zip(seg_m, seg_o):
        goal_m, goal_o = measured["goal_position"][rows_m[0]], other["goal_position"][rows_o[0]]
        if goal_m != goal_o:
            raise RecordingError(f"the recordings sent different commands (goal {goal_m} vs {goal_o})")
        tau_m, tau_o = measured.t[rows_m] - sent_m, other.t[rows_o] - sent_o
        inside = (tau_m >= tau_o[0]) & (tau_m <= tau_o[-1])
        if len(rows_o) == 1:
            inside = np.abs(tau_m - tau_o[0]) < 1e-9
        pos_o = np.interp(tau_m[inside], tau_o, other["present_position"][rows_o].astype(float))
        errors.append(measured["present_position"][rows_m][inside] - pos_o)
    e = np.concatenate(errors)
    return float(np.sqrt(np.mean(e**2))) if len(e) else float("nan")


def timed_gap(measured: Trace, other: Trace) -> float:
    """RMS position gap (units) on the recordings' own clocks (``other`` interpolated at the measured times)."""
    pos = np.interp(measured.t, other.t, other["present_position"].astype(float))
    return float(np.sqrt(np.mean((measured["present_position"] - pos) ** 2)))


# ---------------------------------------------------------------------------------- the loop
@dataclass
class Result:
    """What the loop found: gaps to the measurement (aligned and on the clock), the verdict, where files are."""

    aligned: dict[str, float]
    timed: dict[str, float]
    verdict: dict
    params_file: Path

    @property
    def ratio(self) -> float:
        """Twin gap over plain gap (aligned)."""
        return self.aligned["twin"] / self.aligned["plain"]

    def text(self) -> str:
        named = ", ".join(f"{e['effect']} " + ", ".join(f"{k}={v:.4g}" for k, v in e["values"].items())
                          for e in self.verdict.get("named", [])) or "none"
        lines = [f"diagnosis named: {named}", f"twin parameters: {self.params_file}",
                 "position gap to the measurement, RMS units (aligned on command send times / on the clock):"]
        for name in self.aligned:
            lines.append(f"  {name:6s} {self.aligned[name]:7.2f}   {self.timed[name]:7.2f}")
        lines.append(f"twin / plain = {self.ratio:.2f} (goal <= {GOAL_RATIO}): "
                     + ("met" if self.ratio <= GOAL_RATIO else "NOT met"))
        return "\n".join(lines)


def run_loop(record: Recorder, hidden_args: list[str], writes: dict[str, int], out: Path,
             floor: bool = False, diagnose_args: tuple[str, ...] = ()) -> Result:
    """Measure with ``hidden_args`` and ``writes``, diagnose, record the twin and the plain emulator; compare.

    The hidden knobs (serve arguments, registers written before the excitation) reach only the
    measured servo: the twin has only its params.toml to go on.
    """
    out.mkdir(parents=True, exist_ok=True)
    measured = record(hidden_args, writes, out / "measured.csv")
    diagnosis = out / "diagnosis"
    run = subprocess.run([sys.executable, "-m", "firmware_model.diagnose", str(out / "measured.csv"), "--out",
                          str(diagnosis), "--json", "-q", *diagnose_args], capture_output=True, text=True, cwd=ROOT)
    if run.returncode != 0:  # its last line says why (a one-line error, or a traceback's last line)
        why = (run.stderr.strip().splitlines() or [f"exit status {run.returncode}"])[-1]
        raise RuntimeError(f"the diagnosis of {out / 'measured.csv'} failed: {why}")
    verdict = json.loads(run.stdout)
    params_file = diagnosis / "params.toml"
    others = {"plain": record([], {}, out / "plain.csv"),
              "twin": record(["--params", str(params_file)], {}, out / "twin.csv")}
    if floor:
        others["again"] = record(hidden_args, writes, out / "measured_again.csv")
    aligned = {}
    for name, other in others.items():
        try:
            aligned[name] = aligned_gap(measured, other)
        except RecordingError as exc:
            raise RecordingError(f"{name} recording vs the measurement: {exc} (one was cut short?)") from None
    return Result(aligned, {k: timed_gap(measured, v) for k, v in others.items()}, verdict, params_file)


# ---------------------------------------------------------------------------------- live recording
def live_recorder(duration_s: float, rate_hz: float, breakaway_s: float) -> Recorder:
    """Serve, record through dynamixel-sdk in real time (tools/record.py), stop; the trace is also written."""
    sys.path.insert(0, str(ROOT / "tools"))
    from live_dataset import recording_priority
    from record import record as sdk_record

    def _record(serve_args: list[str], writes: dict[str, int], path: Path) -> Trace:
        served = start_served(["--ids", "1", *serve_args], cwd=ROOT)
        try:
            try:
                # as tools/live_dataset.py records: a server descheduled for 10 ms makes a command take effect that
                # late, which the diagnosis rightly names a latency (live_dataset.RECORDING_PRIORITY)
                with recording_priority(served.process.pid):
                    trace = sdk_record(served.port, 1, 1_000_000, duration_s, rate_hz, breakaway_s, writes)
            # "cannot open PORT", a port gone (pyserial's SerialException or termios.error), a write unanswered
            except (SystemExit, OSError, termios.error, RuntimeError) as exc:
                failure = exc
            else:
                failure = None
            died = served.process.poll()
        finally:
            served.close()
        if died is not None:
            raise RuntimeError(f"{path.name}: the served emulator exited (status {died}) during the recording"
                               + (f" ({failure})" if failure else ""))
        if failure is not None:
            raise RuntimeError(f"{path.name}: {failure}")
        check_complete(trace, duration_s, rate_hz, path.name)
        write_trace(trace, path)
        return read_trace(path)  # as the diagnosis reads it

    return _record


def _arm(text: str) -> str:
    """``--arm`` as serve takes it, checked here: serve would refuse it only after the set-up, as a failed recording."""
    try:
        parse_arm(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command line."""
    p = OneLineParser(description=__doc__.splitlines()[0])
    hidden = p.add_argument_group("the hidden effect (public knobs of the measured servo)")
    hidden.add_argument("--arm", type=_arm, metavar="MASS_KG,LENGTH_M", help=f"an arm under gravity (default "
                        f"{DEFAULT_ARM} when no other knob is given)")
    hidden.add_argument("--hidden-params", type=file_name, metavar="FILE",
                        help="a params file (effects included) for the measured servo")
    hidden.add_argument("--voltage", type=positive_float, metavar="V", help="the measured servo's supply voltage")
    hidden.add_argument("--write", action="append", default=[], metavar="NAME=VALUE",
                        help="a register written before the measured servo's excitation (not the twin's), "
                             "e.g. torque_limit=600")
    p.add_argument("--duration", type=positive_float, default=20.0, help="seconds per recording (default 20)")
    p.add_argument("--rate", type=positive_float, default=100.0, help="reads per second (default 100)")
    p.add_argument("--breakaway", type=nonnegative_float, default=4.0,
                   help="seconds of breakaway block at the end (default 4)")
    p.add_argument("--out", type=file_name, default="twin_check_out", help="folder for the recordings and the diagnosis")
    p.add_argument("--floor", action="store_true", help="also record the measured servo again (the repeatability floor)")
    # checked here, as the diagnosis checks it, so a misspelt effect is not found after the first recording
    p.add_argument("--effects", type=name_list(LIBRARY), metavar="LIST",
                   help="restrict the diagnosis to these effects (comma-separated)")
    args = p.parse_args(argv)
    if not (args.arm or args.hidden_params or args.voltage or args.write):
        args.arm = DEFAULT_ARM
    if not 0 < args.rate <= 1000 or not args.duration > 0 or not 0 <= args.breakaway < args.duration:
        p.error("--rate must be in (0, 1000], --duration positive and --breakaway in [0, duration)")
    if args.hidden_params and not Path(args.hidden_params).is_file():
        p.error(f"--hidden-params {args.hidden_params}: no such file")
    return args


def main(argv: list[str] | None = None) -> int:
    """Run the live loop and print the gaps; exit 1 when the twin misses the goal."""
    args = parse_args(argv)
    sys.path.insert(0, str(ROOT / "tools"))
    from record import parse_writes

    try:
        writes = parse_writes(args.write)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    hidden = []
    if args.arm:
        hidden += ["--arm", args.arm]
    if args.hidden_params:
        hidden += ["--params", str(Path(args.hidden_params).resolve())]
    if args.voltage:
        hidden += ["--voltage", str(args.voltage)]
    record = live_recorder(args.duration, args.rate, args.breakaway)
    diagnose_args = ("--effects", ",".join(args.effects)) if args.effects else ()
    try:
        result = run_loop(record, hidden, writes, Path(args.out).resolve(), args.floor, diagnose_args)
    except (RecordingError, TraceFormatError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (RuntimeError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    print(f"hidden: {' '.join(hidden) or '-'} {' '.join(args.write)}".rstrip())
    print(result.text())
    return 0 if result.ratio <= GOAL_RATIO else 1


if __name__ == "__main__":
    sys.exit(main())
