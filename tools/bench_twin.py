#!/usr/bin/env python3
"""A bar diagnosed from a twin fitted on its servo's unloaded step: the real AX-12A check, with the answer known.

Why it exists: the real AX-12A check (``tests/tools/test_real_ax12a.py``) fits a twin on an unloaded step
(``tools/real_ax12a.py``: supply and rotor inertia on a grid, then what the workflow names on that step
added) and asks the workflow, from it, for the bar on each loaded step.  ``tools/real_ax12a_inertia.py
--synthetic`` asks it on steps the twin made itself, which only shows the bar is within reach when the
twin *is* the servo.  Here the servo is not the twin: servos unlike the default model (:data:`SERVOS`: a
weaker gearbox, less or more friction, at a supply the twin must find) step from 1 to 500 read like a
DYNAMIXEL Wizard 2 export (``synthetic.wizard_step_export``: the served model read every 20 ms at a random
phase, stamped on the 16 ms tick); a twin is fitted on each one's unloaded step and closed exactly as for
the real servo, and each bar of :data:`BARS_KG_M2` is diagnosed from it.  Printed per servo: how often
``extra_inertia`` is named first, how often the 95 % interval of its first-round fit holds the bar (named
or not), and the estimates (``nan``: not among the round's fits).

Usage: ``python tools/bench_twin.py [--seeds 2] [--jobs 2]``
"""

from __future__ import annotations

import dataclasses
import sys
import tempfile
import time
from multiprocessing import Pool
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import real_ax12a  # noqa: E402

from ax12emu.cli.arg_types import OneLineParser, positive_int  # noqa: E402
from firmware_model.diagnose.cli import load_input, parse_args  # noqa: E402
from firmware_model.diagnose.search import diagnose  # noqa: E402
from firmware_model.diagnose.synthetic import wizard_step_export  # noqa: E402
from firmware_model.params import ServoParams  # noqa: E402

#: The servos' supply (V): inside the twin's supply grid, off the default model's 9.6 V.
SUPPLY_V = 10.0
_DEFAULT = ServoParams()
#: Servos unlike the default, each as the fields that differ (name -> overrides).
SERVOS = {
    "weaker gearbox (efficiency 0.68)": {"gearbox_efficiency": 0.68},
    "less friction (x0.6)": {"static_friction_nm": 0.6 * _DEFAULT.static_friction_nm, "coulomb_friction_nm": 0.6 * _DEFAULT.coulomb_friction_nm},
    "more friction (x1.5)": {"static_friction_nm": 1.5 * _DEFAULT.static_friction_nm, "coulomb_friction_nm": 1.5 * _DEFAULT.coulomb_friction_nm},
}
#: Bars on the horn (kg m^2): the real AX-12A recordings' two, then a third and three quarters of the model's own.
BARS_KG_M2 = (0.727e-3, 1.019e-3, 2.0e-3, 4.57e-3)
#: Seeds of the steps (the reading clock's phase and the pot's noise); the unloaded step the twin is fitted on
#: uses the first.
SEED = 7000
#: The unloaded step and the loaded ones: written this long after the first reading, read until this long after.
HEAD_MS, TAIL_MS = 1400.0, 3000.0


def servo_params(name: str, bar_kg_m2: float = 0.0) -> ServoParams:
    """The servo ``name`` of :data:`SERVOS` at :data:`SUPPLY_V`, with ``bar_kg_m2`` on the horn."""
    p = dataclasses.replace(_DEFAULT, supply_voltage_v=SUPPLY_V, **SERVOS[name])
    return dataclasses.replace(p, load_inertia_kg_m2=p.load_inertia_kg_m2 + bar_kg_m2)


def _export(params: ServoParams, seed: int, folder: Path) -> Path:
    phase_ms = float(np.random.default_rng(seed).uniform(0.0, 20.0))
    path = folder / "step.csv"
    path.write_text(wizard_step_export(params, HEAD_MS, TAIL_MS, phase_ms, seed), encoding="utf-8")
    return path


def twin_of(name: str) -> tuple[ServoParams, str]:
    """The closed twin of servo ``name``, fitted on its unloaded step: (params, one line saying what it is)."""
    with tempfile.TemporaryDirectory(prefix="bench_twin_") as tmp:
        path = _export(servo_params(name), SEED, Path(tmp))
        twin, volts, scale, result = real_ax12a.fit_twin(ServoParams(), real_ax12a.load(path), 500)
        closed, d = real_ax12a.close_twin(twin, path, 500)
    truth = servo_params(name).total_inertia_kg_m2
    return closed, (f"twin {volts:.2f} V, rotor and gear inertia x{scale:.1f} ({1e3 * closed.total_inertia_kg_m2:.2f}e-3 "
                    f"kg m^2, the servo's {1e3 * truth:.2f}e-3), RMS {result['rms']:.2f}; its own step names "
                    f"{', '.join(d.named) or 'nothing'}")


def one(job: tuple[str, ServoParams, float, int]) -> tuple:
    """Diagnose one loaded step from ``twin``: (servo, bar, seed, named, first-round estimate, half-width)."""
    name, twin, bar, seed = job
    with tempfile.TemporaryDirectory(prefix="bench_twin_") as tmp:
        path = _export(servo_params(name, bar), seed, Path(tmp))
        args = parse_args([str(path), "--out", tmp, "--goal", "500", "--voltage", str(twin.supply_voltage_v)])
        d = diagnose(load_input(args, twin).trace, twin, progress=lambda m: None)
    fit = next((c for c in d.rounds[0] if c.effect == "extra_inertia"), None) if d.rounds else None
    j = fit.values["extra_inertia_kg_m2"] if fit else float("nan")
    half = fit.uncertainty["extra_inertia_kg_m2"] if fit else float("nan")
    return name, bar, seed, d.named, j, half


def summary(rows: list[tuple]) -> tuple[int, int, int, int]:
    """(named first, named first with the interval holding the bar, first-round intervals holding it, cases) over
    ``rows`` of :func:`one`: the second is the real AX-12A check's goal."""
    holds = [abs(r[4] - r[1]) <= r[5] for r in rows]  # nan (not among the fits) never holds
    first = [r[3][:1] == ["extra_inertia"] for r in rows]
    return sum(first), sum(f and h for f, h in zip(first, holds)), sum(holds), len(rows)


def run(seeds: int, jobs: int, servos: list[str] | None = None, bars: tuple[float, ...] = BARS_KG_M2) -> dict:
    """Every servo x bar x seed; prints the table and returns {servo: rows of :func:`one`}."""
    names = servos or list(SERVOS)
    twins = {}
    for name in names:
        twins[name], line = twin_of(name)
        print(f"{name}: {line}", flush=True)
    work = [(n, twins[n], bar, SEED + 1 + i) for n in names for bar in bars for i in range(seeds)]
    t0 = time.perf_counter()
    with Pool(jobs) as pool:
        results = list(pool.imap(one, work))
    out = {name: [r for r in results if r[0] == name] for name in names}
    print(f"\n{'servo':<34} {'named first':>11} {'and holds it':>13} {'interval holds':>15}   "
          "first-round estimates (1e-3 kg m^2) per bar")
    for name, rows in out.items():
        first, both, holds, n = summary(rows)
        est = "  ".join(f"{1e3 * bar:.2f}: " + ", ".join(f"{1e3 * r[4]:.2f}+-{1e3 * r[5]:.2f}" for r in rows if r[1] == bar)
                        for bar in bars)
        print(f"{name:<34} {first:>5}/{n:<5} {both:>6}/{n:<6} {holds:>8}/{n:<6}   {est}")
    first, both, holds, n = summary(results)
    print(f"all: named first {first}/{n}, named first with the interval holding the bar {both}/{n}, "
          f"first-round interval holding it {holds}/{n}")
    print(f"{len(work)} diagnoses in {time.perf_counter() - t0:.0f} s ({jobs} at once)")
    return out


def main(argv: list[str] | None = None) -> int:
    p = OneLineParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=positive_int, default=2, help="loaded steps per servo and bar (default 2)")
    p.add_argument("--jobs", type=positive_int, default=1, help="diagnoses at once (default 1)")
    args = p.parse_args(argv)
    run(args.seeds, args.jobs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
