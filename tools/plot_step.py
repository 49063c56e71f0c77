#!/usr/bin/env python3
"""Plot a step response of the physical model: position, reference, speed, load; data-sheet figures annotated.

Why it exists: a picture of the model against the data sheet for the README
and for eyeballing a fitted parameter set (``--params FILE``).  Present Speed
and Present Load are drawn as a client polling at 100 Hz sees them (held
about 0.1 s), beside the true shaft speed.

Usage: ``python tools/plot_step.py [--out step.png] [--volts 9.6] [--degrees 60] [--moving-speed 0] [--params FILE]``
Needs matplotlib (not a dependency of the package).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ax12emu.cli.arg_types import (  # noqa: E402
    OneLineParser,
    file_name,
    finite_float,
    int_range,
    output_file,
    positive_float,
)
from firmware_model.interface import Commands  # noqa: E402
from firmware_model.params import HOLDING_TORQUE_NM, MOVE_60_DEG_S, ServoParams  # noqa: E402
from firmware_model.physical import PhysicalModel  # noqa: E402
from firmware_model.units import RAD_PER_POSITION_UNIT, RAD_S_PER_SPEED_UNIT, signed_raw_to_value  # noqa: E402


def simulate(params: ServoParams, volts: float, degrees: float, moving_speed: int, duration_s: float) -> dict:
    """Run one step from raw 512 and record everything at 1 kHz."""
    n_units = int(round(degrees / 300.0 * 1023))
    cmds = Commands.power_up(goal_position=START_UNITS + n_units, moving_speed=moving_speed)
    model = PhysicalModel(1, params=params)
    model.set_supply_voltage(volts)
    rec = {k: [] for k in ("t", "pos", "ref", "speed", "held_speed", "load", "drive")}
    for i in range(1, int(round(duration_s * 1000)) + 1):
        s = model.advance(i * 1e-3, cmds)
        rec["t"].append(model.time_s)
        rec["pos"].append(np.degrees(s.present_position[0] * RAD_PER_POSITION_UNIT))
        rec["ref"].append(np.degrees(model.reference_rad[0]))
        rec["speed"].append(model.speed_rad_s[0])
        rec["held_speed"].append(signed_raw_to_value(s.present_speed)[0] * RAD_S_PER_SPEED_UNIT)
        rec["load"].append(signed_raw_to_value(s.present_load)[0] / 10.23)
        rec["drive"].append(model.drive[0] * 100.0)
    out = {k: np.array(v) for k, v in rec.items()}
    out["goal_deg"] = np.degrees((512 + n_units) * RAD_PER_POSITION_UNIT)
    return out


#: Where the step starts (raw units): the middle of the range.
START_UNITS = 512
#: A step plot is of a step: a minute of simulated time at 1 kHz is already 60,000 points a curve.
MAX_DURATION_S = 60.0
#: Extensions matplotlib's Agg backend writes (checked before the simulation runs, not after).
FIGURE_SUFFIXES = (".png", ".pdf", ".svg")


def step_degrees(text: str) -> float:
    """A step whose goal, START_UNITS plus the step, is a Goal Position the servo takes (0..1023: a real AX-12A
    answers a goal outside it with the Range Error and does not move)."""
    degrees = finite_float(text)
    goal = START_UNITS + int(round(degrees / 300.0 * 1023))
    if not 0 <= goal <= 1023:
        raise argparse.ArgumentTypeError(f"{text} degrees puts the goal at raw {goal}, outside Goal Position's 0..1023")
    return degrees


def duration_s(text: str) -> float:
    """Simulated seconds in (0, MAX_DURATION_S]."""
    seconds = positive_float(text)
    if seconds > MAX_DURATION_S:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_DURATION_S:g} s, got {text}")
    return seconds


def figure_file(text: str) -> str:
    """An output file whose extension names a format the figure can be written in."""
    name = output_file(text)
    if Path(name).suffix.lower() not in FIGURE_SUFFIXES:
        raise argparse.ArgumentTypeError(f"{text}: write a {', '.join(FIGURE_SUFFIXES)} file")
    return name


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command line."""
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=figure_file, default="step_response.png",
                        help=f"figure to write, by its extension: {', '.join(FIGURE_SUFFIXES)} (default step_response.png)")
    parser.add_argument("--volts", type=positive_float, default=9.6, help="supply voltage (default 9.6)")
    parser.add_argument("--degrees", type=step_degrees, default=60.0,
                        help="step size in degrees from the middle (raw 512); the goal must stay within 0..1023 (default 60)")
    parser.add_argument("--moving-speed", type=int_range(0, 1023), default=0,
                        help="Moving Speed register (default 0 = full)")
    parser.add_argument("--duration", type=duration_s, default=0.6,
                        help=f"simulated seconds, at most {MAX_DURATION_S:g} (default 0.6)")
    parser.add_argument("--params", type=file_name, help="TOML parameter file (default: built-in)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Simulate, plot, write the PNG."""
    args = parse_args(argv)
    try:  # a params file it cannot read, or a supply outside the parameters' range: one line, before any work
        params = ServoParams.from_toml(args.params) if args.params else ServoParams()
        params.check_supply(args.volts)
    except (ValueError, OSError) as exc:
        print(f"plot_step.py: error: {exc}", file=sys.stderr)
        return 2
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("plot_step needs matplotlib: pip install matplotlib", file=sys.stderr)
        return 2
    runs = {v: simulate(params, v, args.degrees, args.moving_speed, args.duration) for v in sorted({7.0, args.volts, 10.0})}
    main_run = runs[args.volts]
    fig, (ax_pos, ax_speed, ax_load) = plt.subplots(3, 1, sharex=True, figsize=(8, 9))
    start_deg = np.degrees(512 * RAD_PER_POSITION_UNIT)
    for volts, run in runs.items():
        style = "-" if volts == args.volts else ":"
        ax_pos.plot(run["t"], run["pos"] - start_deg, style, label=f"Present Position, {volts:g} V")
    ax_pos.plot(main_run["t"], main_run["ref"] - start_deg, "k--", lw=1, label="reference (setpoint generator)")
    if args.degrees == 60.0:
        for volts, t60 in MOVE_60_DEG_S.items():
            ax_pos.axvline(t60, color="grey", lw=0.8)
            ax_pos.annotate(f"data sheet 60 deg @{volts:g} V: {t60} s", (t60, 5 + 8 * (volts == 7.0)), fontsize=8, rotation=90)
    ax_pos.set_ylabel("degrees from start")
    ax_pos.legend(fontsize=8, loc="lower right")
    ax_speed.plot(main_run["t"], main_run["speed"], label="true shaft speed")
    ax_speed.step(main_run["t"], main_run["held_speed"], where="post", label="Present Speed (held ~0.1 s)")
    top = params.top_speed_rad_s(args.volts)
    ax_speed.axhline(top, color="grey", lw=0.8)
    ax_speed.annotate(f"model top speed @{args.volts:g} V: {top:.2f} rad/s", (0.0, top + 0.2), fontsize=8)
    ax_speed.set_ylabel("rad/s")
    ax_speed.legend(fontsize=8)
    ax_load.plot(main_run["t"], main_run["drive"], label="controller drive")
    ax_load.step(main_run["t"], main_run["load"], where="post", label="Present Load (held)")
    ax_load.set_ylabel("% of full drive")
    ax_load.set_xlabel("s")
    ax_load.legend(fontsize=8)
    holding = ", ".join(f"{params.holding_torque_nm(v):.2f} N m @{v:g} V (data sheet {h})" for v, h in HOLDING_TORQUE_NM.items())
    fig.suptitle(f"AX-12+ model: {args.degrees:g} deg step at {args.volts:g} V, Moving Speed {args.moving_speed}\n"
                 f"holding torque {holding}", fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
