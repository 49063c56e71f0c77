"""Argument types shared by the command line's subcommands: a bad value is argparse's one-line error.

Why apart: ``serve``'s flags (:mod:`.main`) and ``conformance``'s (:mod:`.hil`) take the same kinds of number,
and a reply timeout of NaN or 0 must be refused as a flag error there too, not hang or blame the servo.
"""

from __future__ import annotations

import argparse

__all__ = ["file_name", "finite_float", "positive_float"]


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


def file_name(text: str) -> str:
    """A path that names something (an empty one is the working folder, and was refused as "Is a directory")."""
    if not text.strip():
        raise argparse.ArgumentTypeError("names no file (an empty path)")
    return text
