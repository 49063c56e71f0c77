#!/usr/bin/env python3
"""Benchmark the X-series firmware model: microseconds of Python per 1 ms control step.

Why it exists: each X-series servo's firmware and physics run in the serving loop, one Python
object per servo, so a step must cost a few tens of microseconds at most.  Three scenarios, because
the cost depends on what the servo does: ``moving`` (a 90 degree swing with a trapezoid profile and
back every second: every step computed), ``holding`` (torque on at rest on its goal: after settling
the firmware notices its step repeats exactly and skips), ``off`` (torque off, at rest: skipped).
The serving loop brings a servo to the present in small slices, so the model is stepped 1 ms at a
time here too.  Each figure is the best of ``--repeat`` runs (noise on a shared machine only slows
a run down), with the median beside it.

Usage: ``python tools/bench_xfirmware.py [--seconds S] [--repeat R]``
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ax12emu.cli.arg_types import OneLineParser, positive_float, positive_int  # noqa: E402
from firmware_model.xseries.firmware import build_x_servo  # noqa: E402
from firmware_model.xseries.interface import XCommands  # noqa: E402

#: Data-sheet figures (e-manual model pages) and initial gains of the benchmarked models.
MODELS = {
    "XM430-W350": dict(gear_ratio=353.5, ratings=[(11.1, 3.8, 2.1, 43), (12.0, 4.1, 2.3, 46), (14.8, 4.8, 2.7, 57)],
                       current_unit_a=0.00269, supply_v=12.0, gains=dict(position_p_gain=800, velocity_p_gain=100, velocity_i_gain=1920)),
    "XL430-W250": dict(gear_ratio=258.5, ratings=[(9.0, 1.0, 1.0, 47), (11.1, 1.4, 1.3, 57), (12.0, 1.5, 1.4, 61)],
                       current_unit_a=None, supply_v=11.1,
                       gains=dict(position_p_gain=640, position_d_gain=4000, velocity_p_gain=100, velocity_i_gain=1000)),
    "XL330-M288": dict(gear_ratio=288.4, ratings=[(3.7, 0.42, 1.11, 76), (5.0, 0.52, 1.47, 103), (6.0, 0.60, 1.74, 123)],
                       current_unit_a=0.001, supply_v=5.0, gains=dict(position_p_gain=400, velocity_p_gain=180, velocity_i_gain=1600)),
}


def run_once(model: str, scenario: str, seconds: float) -> float:
    """Microseconds of wall time per simulated millisecond for one servo of ``model`` in ``scenario``."""
    spec = dict(MODELS[model])
    gains = spec.pop("gains")
    servo = build_x_servo(**spec)
    cmd = XCommands(torque_enable=0 if scenario == "off" else 1, goal_pwm=885, profile_velocity=200, profile_acceleration=100,
                    max_voltage_limit=160, min_voltage_limit=30, shutdown=52, **gains)
    servo.command(cmd)
    goals = (1024, 2048)
    if scenario == "holding":
        servo.command(XCommands(**{**vars(cmd), "goal_position": goals[0]}), goal_written=True)
        servo.step_to(3.0)  # settle first: the figure is the cost of holding, not of arriving
    steps = int(seconds * 1000)
    start = time.perf_counter()
    t = servo.time_s
    for k in range(steps):
        if scenario == "moving" and k % 1000 == 0:
            servo.command(XCommands(**{**vars(cmd), "goal_position": goals[(k // 1000) % 2]}), goal_written=True)
        t += 0.001
        servo.step_to(t)
        if k % 10 == 0:
            servo.sense()  # a client polling at 100 Hz
    return (time.perf_counter() - start) / steps * 1e6


def main(argv: list[str] | None = None) -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=positive_float, default=5.0, help="simulated seconds per run")
    parser.add_argument("--repeat", type=positive_int, default=3, help="runs per figure (best and median reported)")
    args = parser.parse_args(argv)
    if int(args.seconds * 1000) < 1:  # the model is stepped 1 ms at a time: a shorter run has no step to time
        parser.error(f"--seconds must be at least 0.001 (one 1 ms step), got {args.seconds:g}")
    print(f"{'model':12} {'scenario':8} {'best us/step':>13} {'median':>8}")
    for model in MODELS:
        for scenario in ("moving", "holding", "off"):
            runs = [run_once(model, scenario, args.seconds) for _ in range(args.repeat)]
            print(f"{model:12} {scenario:8} {min(runs):13.2f} {statistics.median(runs):8.2f}")


if __name__ == "__main__":
    main()
