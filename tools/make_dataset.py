#!/usr/bin/env python3
"""Make a "measured" trace with hidden effects, and its answer key in a separate file.

Why it exists: the diagnosis workflow is checked on data whose answer is
known (firmware_model.diagnose.synthetic); the key goes to KEY.json, which
the workflow never reads.

Usage: ``python tools/make_dataset.py OUT.csv --key KEY.json [--effects coulomb_friction,delay] [--seed N]
[--duration 20] [--rate 100] [--breakaway SECONDS]`` (``--effects none`` for a clean servo; ``cogging`` is out
of the library; ``--breakaway``: the last that many seconds are small steps and moderate-speed moves, which
show breakaway/Stribeck friction, see firmware_model.diagnose.excitation).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ax12emu.cli.arg_types import (  # noqa: E402
    OneLineParser,
    name_list,
    nonnegative_float,
    nonnegative_int,
    output_file,
    positive_float,
)
from firmware_model.diagnose.effects import LIBRARY  # noqa: E402
from firmware_model.diagnose.synthetic import draw_effect, make_trace  # noqa: E402
from firmware_model.diagnose.trace import write_trace  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    """Write the trace and the key."""
    p = OneLineParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=output_file, help="trace CSV to write")
    p.add_argument("--key", type=output_file, required=True,
                   help="answer key JSON to write (keep it away from the workflow)")
    p.add_argument("--effects", type=name_list(("none", *LIBRARY, "cogging")), default=["none"],
                   help="comma-separated hidden effects, or 'none'")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seeds numpy's generator, which refuses < 0")
    p.add_argument("--duration", type=positive_float, default=20.0, help="seconds (default 20)")
    p.add_argument("--rate", type=positive_float, default=100.0, help="samples per second (default 100)")
    p.add_argument("--breakaway", type=nonnegative_float, default=0.0,
                   help="seconds of breakaway block at the end (default 0)")
    args = p.parse_args(argv)
    if Path(args.key).resolve() == Path(args.out).resolve():  # the key would overwrite the trace
        p.error("--key must not be the trace file OUT")
    if "none" in args.effects and args.effects != ["none"]:
        p.error("--effects none stands alone (a clean servo)")
    if round(args.duration * args.rate) < 2:  # a trace of fewer readings is no trace
        p.error("--duration x --rate must give at least 2 readings")
    if not args.breakaway < args.duration:
        p.error("--breakaway must be shorter than --duration")
    rng = np.random.default_rng(args.seed + 100_000)
    names = [] if args.effects == ["none"] else args.effects
    hidden = {n: draw_effect(n, rng) for n in names}
    trace, key = make_trace(hidden, args.seed, args.duration, args.rate, breakaway_s=args.breakaway)
    write_trace(trace, args.out)
    Path(args.key).write_text(json.dumps(key, indent=2), encoding="utf-8")
    print(f"{args.out}: {len(trace)} rows; key in {args.key}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
