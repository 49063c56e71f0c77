"""``ax12emu models``: the servo models the emulator knows, with their data-sheet figures.

Why it exists: a model is a data file (:mod:`ax12emu.protocol.servo_models`); this lists what
the shipped files say, so a user sees which models and protocols there are, what each is
rated for and which firmware model serves it without opening the files.  ``print`` is allowed here as in ``cli.main``.
"""

from __future__ import annotations

import argparse

from ax12emu.protocol.servo_models import ServoModel, model, model_names

__all__ = ["COLUMNS", "add_command", "run", "models_table"]


#: The listing's columns, one line per model (per rated voltage with ``--all-ratings``); the help names them.
COLUMNS = ("key", "name", "protocol", "model number", "firmware", "stall torque", "no-load speed", "firmware model")


def add_command(sub: argparse._SubParsersAction) -> None:
    """The ``models`` subcommand."""
    # The help names what is printed: the model files' figures, not their control tables.
    summary = "list the servo models the emulator knows, with their data-sheet figures and the firmware model serving each"
    models = sub.add_parser("models", help=summary,
                            description=f"{summary[0].upper()}{summary[1:]}: one line per model with its "
                                        f"{', '.join(COLUMNS)} (the figures at the recommended supply where the data sheet rates them there, "
                                        "else at its first rating; "
                                        "--all-ratings: a line per rated voltage).")
    models.add_argument("--all-ratings", action="store_true", help="one line per rated voltage (default: the recommended one)")


def _served_by(servo: ServoModel) -> str:
    """Which firmware model runs the servo when served: the X series' (its tables, and the classic tables
    translated by their ``[classic]`` numbers: the MX series, the XL-320) or the AX-12's (the AX-shaped tables)."""
    return "x-series" if servo.classic is not None or "2.0" in servo.protocols else "ax-12"


def _rows(servo: ServoModel, all_ratings: bool) -> list[list[str]]:
    physical = servo.physical
    ratings = physical.ratings if all_ratings else (physical.rating_at(),)
    firmware = "-" if servo.firmware_version is None else str(servo.firmware_version)
    return [
        [servo.key, servo.name, "/".join(servo.protocols), str(servo.model_number), firmware,
         f"{r.stall_torque_nm:g} N m @ {r.voltage_v:g} V", f"{r.no_load_speed_rpm:g} rpm @ {r.voltage_v:g} V",
         _served_by(servo)]
        for r in ratings
    ]


def models_table(all_ratings: bool = False) -> str:
    """The listing as aligned text columns."""
    header = list(COLUMNS)
    rows = [header] + [row for key in model_names() for row in _rows(model(key), all_ratings)]
    widths = [max(len(row[i]) for row in rows) for i in range(len(header))]
    return "\n".join("  ".join(cell.ljust(width) for cell, width in zip(row, widths)).rstrip() for row in rows)


def run(args: argparse.Namespace) -> int:
    """Print the listing."""
    print(models_table(args.all_ratings))
    return 0
