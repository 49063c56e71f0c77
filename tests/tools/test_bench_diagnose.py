"""tools/bench_diagnose.py: the Wizard-style steps' part (the synthetic sweep is tests/firmware_model/diagnose's)."""

import pytest
from emu_testkit import load_tool

bench = load_tool("bench_diagnose")


def test_wizard_steps_report_first_names_and_intervals(capsys):
    """One step per bar and one without: each bar named first with its interval holding it, nothing without."""
    assert bench.main(["--seeds", "0", "--clean", "0", "--cogging", "0", "--wizard-steps", "1"]) == 0
    out = capsys.readouterr().out
    n = len(bench.WIZARD_BARS_KG_M2)
    assert f"bars named first: {n}/{n}; intervals holding the bar: {n}/{n}; names without a bar: 0/1" in out, out


def test_negative_counts_are_refused(capsys):
    with pytest.raises(SystemExit):
        bench.main(["--wizard-steps", "-1"])
    assert "must be >= 0" in capsys.readouterr().err
