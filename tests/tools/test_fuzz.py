"""tools/fuzz.py beyond its oracle (tested in tests/ax12emu/test_fuzz.py; tools/fuzz2.py's in tests/tools/test_fuzz2.py):
the coverage figure's module names, the driver loop both fuzzers run (on a toy oracle here: it stops at the first
failing case and keeps that case's error and a minimised reproducer), and a replay of a file that holds no case."""

from __future__ import annotations

from emu_testkit import load_tool

fuzz = load_tool("fuzz")


def test_the_coverage_figure_names_modules_that_exist():
    """Both fuzzers' coverage is measured on the files named here (ax12emu/<path>.py): a stale name measures nothing."""
    from pathlib import Path

    fuzz2 = load_tool("fuzz2")
    package = Path(fuzz.__file__).resolve().parents[1] / "ax12emu"
    for tool in (fuzz, fuzz2):
        missing = [name for name in tool.TARGET_MODULES if not (package / f"{name}.py").is_file()]
        assert not missing, f"{tool.__name__}: {missing}"
