"""tools/fuzz_coverage.py: the fuzzers' coverage.py, started before ax12emu is imported, or not at all."""

import sys

import pytest
from emu_testkit import load_tool

tool = load_tool("fuzz_coverage")


@pytest.mark.parametrize("flag", sorted(tool.NO_FIGURE))
def test_no_figure_asked_for_starts_nothing(flag, capsys):
    assert tool.start_coverage(("bus/bus",), ["fuzz.py", flag]) is None
    assert capsys.readouterr().out == ""


def test_without_coverage_installed_it_says_so_and_the_fuzzer_runs_on(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "coverage", None)  # import coverage raises ImportError
    assert tool.start_coverage(("bus/bus",), ["fuzz.py"]) is None
    assert "coverage is not installed" in capsys.readouterr().out


def test_it_measures_the_named_modules_of_ax12emu():
    coverage = pytest.importorskip("coverage", reason="coverage.py is not installed (the fuzzers print no figure then)")
    cov = tool.start_coverage(("bus/bus",), ["fuzz.py"])
    try:
        assert isinstance(cov, coverage.Coverage)
        assert cov.config.run_include == ["*/ax12emu/bus/bus.py"] and cov.config.branch
    finally:
        cov.stop()
