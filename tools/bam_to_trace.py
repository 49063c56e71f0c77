#!/usr/bin/env python3
"""Convert Rhoban BAM pendulum logs (JSON) to X-series diagnosis traces, with the servo's data sheet from its model file.

Why it exists: ``python -m firmware_model.diagnose`` reads the project's trace CSV; a BAM log records an
XL330 in radians and needs the servo's data sheet, which the model files hold
(``ax12emu/protocol/models/*.toml``) and the model package does not read.

Usage::

    python tools/bam_to_trace.py LOG.json OUT.csv [--model xl330-m288]
    python -m firmware_model.diagnose OUT.csv --out report/
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ax12emu.cli.arg_types import OneLineParser, file_name, output_file  # noqa: E402
from ax12emu.protocol.servo_models import model as servo_model  # noqa: E402
from firmware_model.diagnose.bam_trace import bam_trace  # noqa: E402
from firmware_model.diagnose.trace import Trace, write_trace  # noqa: E402
from firmware_model.xseries.bam_log import read_bam_log  # noqa: E402

#: BAM's XL330 is the XL330-M288-T (its README's list of identified servos).
DEFAULT_MODEL = "xl330-m288"


def convert(log_path: str | Path, model_key: str = DEFAULT_MODEL) -> Trace:
    """One log as a trace, the data sheet from model file ``model_key``."""
    spec = servo_model(model_key)
    physical = spec.physical
    ratings = [(r.voltage_v, r.stall_torque_nm, r.stall_current_a, r.no_load_speed_rpm) for r in physical.ratings]
    unit = None if physical.current_unit_ma is None else physical.current_unit_ma * 1e-3
    return bam_trace(read_bam_log(log_path), model=spec.name, gear_ratio=physical.gear_ratio, ratings=ratings,
                     current_unit_a=unit, position_output_scale=spec.controller.position_output_scale)


def main(argv: list[str] | None = None) -> int:
    p = OneLineParser(description=__doc__.splitlines()[0])
    p.add_argument("log", type=file_name, help="a BAM pendulum log (JSON)")
    p.add_argument("out", type=output_file, help="the trace CSV to write")
    p.add_argument("--model", default=DEFAULT_MODEL, help=f"servo model file key (default {DEFAULT_MODEL})")
    args = p.parse_args(argv)
    try:
        trace = convert(args.log, args.model)
        write_trace(trace, args.out)  # an OUT it may not write is the user's path too, not a traceback
    except (ValueError, KeyError, OSError) as exc:
        print(f"{p.prog}: error: {exc}", file=sys.stderr)
        return 2
    print(f"{args.out}: {len(trace)} rows, {trace.t[-1]:.2f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
