"""Argument types shared by the command line's subcommands and the tools: a bad value is argparse's one-line error.

Why apart: ``serve``'s flags (:mod:`.main`) and ``conformance``'s (:mod:`.hil`) take the same kinds of number,
and a reply timeout of NaN or 0 must be refused as a flag error there too, not hang or blame the servo.  The
benchmarks and utilities in ``tools/`` parse with the same :class:`OneLineParser` and types, so a count of 0 or
a duration of NaN stops there as one line before any work starts, not as a traceback (or a hang) minutes later.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable
from pathlib import Path

__all__ = [
    "OneLineParser",
    "file_name",
    "finite_float",
    "int_range",
    "name_list",
    "nonnegative_float",
    "nonnegative_int",
    "output_file",
    "positive_float",
    "positive_int",
    "positive_int_list",
]


class OneLineParser(argparse.ArgumentParser):
    """argparse, its errors one line on stderr (as every other user error of the program), not the usage block:
    the bad flag is what a user needs to see; ``--help`` shows the rest."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def finite_float(text: str) -> float:
    """A finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
    return value


def positive_float(text: str) -> float:
    """A finite number above zero."""
    value = finite_float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text}")
    return value


def nonnegative_float(text: str) -> float:
    """A finite number, zero or above (a length of time that may be none)."""
    value = finite_float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text}")
    return value


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None


def int_range(low: int, high: int) -> Callable[[str], int]:
    """The type of an integer in ``low..high`` (a register's range, a servo ID, a count with a ceiling)."""

    def in_range(text: str) -> int:
        value = _integer(text)
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be {low}..{high}, got {text}")
        return value

    return in_range


def positive_int(text: str) -> int:
    """An integer >= 1 (a count of runs, servos or workers: none of them can be 0)."""
    value = _integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text}")
    return value


def nonnegative_int(text: str) -> int:
    """An integer >= 0 (a count whose 0 leaves its part out, or a seed of numpy's generator, which refuses < 0)."""
    value = _integer(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def positive_int_list(text: str) -> list[int]:
    """Comma-separated integers, each >= 1 (e.g. servo counts ``1,18,253``)."""
    values = []
    for item in (part.strip() for part in text.split(",")):
        try:
            values.append(int(item))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{item!r} in {text!r} is not an integer (comma-separated, e.g. 1,18)") from None
        if values[-1] < 1:
            raise argparse.ArgumentTypeError(f"each must be >= 1, got {item} in {text!r}")
    return values


def name_list(known: Iterable[str]) -> Callable[[str], list[str]]:
    """The type of a comma-separated list of names, each one of ``known`` (e.g. the diagnosis's effects)."""
    choices = tuple(known)

    def names(text: str) -> list[str]:
        items = [item.strip() for item in text.split(",")]
        unknown = [item for item in items if item not in choices]
        if unknown:
            raise argparse.ArgumentTypeError(f"unknown {', '.join(map(repr, unknown))}; known: {', '.join(choices)}")
        return items

    return names


def file_name(text: str) -> str:
    """A path that names something (an empty one is the working folder, and was refused as "Is a directory")."""
    if not text.strip():
        raise argparse.ArgumentTypeError("names no file (an empty path)")
    return text


def output_file(text: str) -> str:
    """A file to write, in a folder that exists: a tool finds out before its work, not when it writes the result."""
    path = Path(file_name(text))
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder, not a file")
    if not path.absolute().parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: no folder {path.parent}")
    return text
