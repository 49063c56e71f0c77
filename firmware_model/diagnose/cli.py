"""``python -m firmware_model.diagnose MEASURED.csv --out DIR [--json]``: the workflow's command line.

Why it exists: one command from a measured trace to a verdict, a report and
a parameter file ``ax12emu serve --params`` loads.  Progress goes to stderr;
the verdict (or, with ``--json``, one JSON object) to stdout.
"""

from __future__ import annotations

import argparse
import json
import sys

from ..params import ServoParams
from .effects import LIBRARY
from .output import verdict_json, verdict_text, write_outputs
from .search import diagnose
from .trace import TraceFormatError, read_trace

__all__ = ["parse_args", "main"]


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line (pure: no I/O)."""
    p = argparse.ArgumentParser(prog="python -m firmware_model.diagnose", description=__doc__.splitlines()[0])
    p.add_argument("trace", metavar="MEASURED.csv", help="measured trace (format: firmware_model.diagnose.trace)")
    p.add_argument("--out", required=True, metavar="DIR", help="where report.md, plots and params.toml go")
    p.add_argument("--json", action="store_true", help="print the verdict as one JSON object")
    p.add_argument("--params", metavar="FILE", help="start from these ServoParams (TOML) instead of the defaults")
    p.add_argument("--effects", metavar="LIST", help=f"comma-separated subset of: {', '.join(LIBRARY)}")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    args = p.parse_args(argv)
    if args.effects:
        unknown = [e for e in args.effects.split(",") if e not in LIBRARY]
        if unknown:
            p.error(f"unknown effect(s): {', '.join(unknown)}")
    return args


def main(argv: list[str] | None = None) -> int:
    """Run the workflow; exit 2 on a malformed trace."""
    args = parse_args(argv)
    try:
        trace = read_trace(args.trace)
    except (TraceFormatError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    params = ServoParams.from_toml(args.params) if args.params else ServoParams()
    progress = None if args.quiet else (lambda msg: print(msg, file=sys.stderr, flush=True))
    d = diagnose(trace, params, progress=progress or (lambda msg: None),
                 effects=args.effects.split(",") if args.effects else None)
    write_outputs(trace, d, args.out, source=args.trace, params=params)
    print(json.dumps(verdict_json(d)) if args.json else verdict_text(d))
    return 0
