"""Coverage.py for the fuzzers (``tools/fuzz.py``, ``tools/fuzz2.py``), started before ax12emu is imported.

Why it exists apart: each fuzzer must start coverage before it imports ax12emu, so that module-level
lines count too, and this module imports nothing of ax12emu; the fuzzers import it first.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

#: Arguments under which a fuzzer prints no coverage figure (and coverage.py is not started).
NO_FIGURE = frozenset({"--no-coverage", "--replay", "-h", "--help"})


def start_coverage(target_modules: Sequence[str], argv: Sequence[str]) -> Any:
    """coverage.py measuring lines and branches of ``ax12emu/<module>.py`` for each of ``target_modules``,
    started; None where ``argv`` asks for no figure or coverage.py is not installed (said on stdout)."""
    if NO_FIGURE & set(argv):
        return None
    try:
        import coverage
    except ImportError:
        print("coverage is not installed (pip install coverage): no coverage figure")
        return None
    cov = coverage.Coverage(include=[f"*/ax12emu/{m}.py" for m in target_modules], branch=True, data_file=None)
    cov.start()
    return cov
