#!/usr/bin/env python3
"""Benchmark the diagnosis workflow: a confusion table over the effect library, and seconds per trace.

Why it exists: the workflow's goals are >= 95 % correct names over all effects x
>= 5 seeds, <= 1 false positive in 20 clean traces, and < 60 s per 20 s
trace at 100 Hz on a 2-core machine.  Each trace has one hidden effect (or
none) with random values (firmware_model.diagnose.synthetic); a trace counts
as correct when the *first* named effect is the hidden one (for "none":
nothing named).  ``--cogging N`` adds N traces with an out-of-library
cogging ripple, reported on their own line (kept out of the "correct"
share, which is about names): right when nothing is named confidently and
the verdict reports an unexplained residual.  The "unexpl." column and
the summary show how often an unexplained residual was reported.  Seconds are wall time per trace in one process; ``--jobs
2`` runs two traces at once (one per core), which is how the table is made
faster, not how the per-trace time is measured.

``--live`` records every trace like a real-time client (random hold phase, stamps after the read
returns, commands a few ms after their rows and not recorded: ``synthetic.make_trace(live=True)``),
whose traits the base fit must absorb without naming anything; ``delay`` is then not offered, so
its row counts what is named instead.

Usage: ``python tools/bench_diagnose.py [--seeds 5] [--clean 20] [--cogging 5] [--duration 20] [--rate 100]
[--jobs 2] [--live] [--effects LIST]``
"""

from __future__ import annotations

import argparse
import sys
import time
from multiprocessing import Pool
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from firmware_model.diagnose.effects import LIBRARY  # noqa: E402
from firmware_model.diagnose.search import diagnose  # noqa: E402
from firmware_model.diagnose.synthetic import draw_effect, make_trace  # noqa: E402


def one(job: tuple[str, int, float, float, bool]) -> tuple:
    """Diagnose one synthetic trace: (hidden, seed, named, seconds, position gap before, after, unexplained, confident)."""
    hidden, seed, duration, rate, live = job
    rng = np.random.default_rng(seed + 100_000)
    effects = {} if hidden == "none" else {hidden: draw_effect(hidden, rng)}
    trace, _ = make_trace(effects, seed, duration, rate, live=live)
    t0 = time.perf_counter()
    d = diagnose(trace, progress=lambda m: None)
    sec = time.perf_counter() - t0
    return (hidden, seed, d.named, sec, d.gaps_before["present_position"]["rms"],
            d.gaps_after["present_position"]["rms"], d.unexplained, d.confident)


def main(argv: list[str] | None = None) -> int:
    """Run the sweep and print the table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=5, help="seeds per effect (default 5)")
    p.add_argument("--clean", type=int, default=20, help="clean traces for the false-positive rate (default 20)")
    p.add_argument("--cogging", type=int, default=5, help="traces with an out-of-library effect (default 5)")
    p.add_argument("--duration", type=float, default=20.0)
    p.add_argument("--rate", type=float, default=100.0)
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--live", action="store_true", help="record like a real-time client (see above)")
    p.add_argument("--effects", metavar="LIST", help="hide only these effects (default: every library effect)")
    args = p.parse_args(argv)
    hide = args.effects.split(",") if args.effects else list(LIBRARY)
    jobs = [(e, s, args.duration, args.rate, args.live) for e in hide for s in range(args.seeds)]
    jobs += [("none", 1000 + s, args.duration, args.rate, args.live) for s in range(args.clean)]
    jobs += [("cogging", 2000 + s, args.duration, args.rate, args.live) for s in range(args.cogging)]
    labels = list(LIBRARY) + ["none"]
    rows = labels + (["cogging"] if args.cogging else [])
    with Pool(args.jobs) as pool:
        results = []
        for r in pool.imap_unordered(one, jobs):
            results.append(r)
            print(f"{r[0]:>20} seed {r[1]:>4}: named {r[2] or '-'}{'  UNEXPLAINED' if r[6] else ''}  {r[3]:.1f} s  "
                  f"pos gap {r[4]:.2f} -> {r[5]:.2f}", flush=True)
    table = {h: {g: 0 for g in labels + ["(other)"]} for h in rows}
    unexpl = {h: 0 for h in rows}
    count = {h: 0 for h in rows}
    correct = 0
    for hidden, _, named, _, _, _, unexplained, _ in results:
        guess = named[0] if named else "none"
        table[hidden][guess if guess in labels else "(other)"] += 1
        unexpl[hidden] += bool(unexplained)
        count[hidden] += 1
        if hidden != "cogging":
            correct += guess == hidden and (hidden != "none" or not named)
    short = {n: n[:6] for n in labels}
    print("\nconfusion (rows hidden, columns first named; unexpl.: unexplained residual reported)")
    print(f"{'':>20} " + " ".join(f"{short[g]:>6}" for g in labels) + "  unexpl.")
    for h in rows:
        print(f"{h:>20} " + " ".join(f"{table[h][g]:>6}" for g in labels) + f"  {unexpl[h]:>3}/{count[h]}")
    secs = np.array([r[3] for r in results])
    effect_rows = [r for r in results if r[0] not in ("none", "cogging")]
    shrink = [1 - r[5] / r[4] for r in effect_rows if r[4] > 0]
    fp = sum(1 for r in results if r[0] == "none" and r[2])
    fu = sum(1 for r in results if r[0] == "none" and r[6])
    named_rows = len([r for r in results if r[0] != "cogging"])
    print(f"\ncorrect names {correct}/{named_rows} = {100 * correct / max(named_rows, 1):.1f} % (goal >= 95 %)")
    print(f"false positives on clean traces: {fp}/{args.clean} named, {fu}/{args.clean} 'unexplained' (goal <= 1 in 20)")
    if args.cogging:
        cg = [r for r in results if r[0] == "cogging"]
        print(f"out-of-library (cogging): unexplained reported {sum(bool(r[6]) for r in cg)}/{len(cg)}, "
              f"confident wrong name {sum(bool(r[7]) for r in cg)}/{len(cg)}")
    print(f"seconds per {args.duration:g} s trace at {args.rate:g} Hz: median {np.median(secs):.1f}, "
          f"max {secs.max():.1f} (goal < 60)")
    if shrink:
        print(f"position RMS gap shrink, effect traces: median {100 * np.median(shrink):.0f} %, "
              f">= 70 % in {sum(x >= 0.7 for x in shrink)}/{len(shrink)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
