"""tools/fuzz.py beyond its oracle (tested in tests/ax12emu/test_fuzz.py; tools/fuzz2.py's in tests/tools/test_fuzz2.py):
the coverage figure's module names, the driver loop both fuzzers run (on a toy oracle here: it stops at the first
failing case and keeps that case's error and a minimised reproducer), and a replay of a file that holds no case."""

from __future__ import annotations

import json
from dataclasses import dataclass

from emu_testkit import load_tool

fuzz = load_tool("fuzz")


@dataclass
class ToyCase:
    inputs: list[tuple[int, float, float]]

    def to_json(self) -> str:
        return json.dumps([value for value, _, _ in self.inputs])


def _make(case_seed: int, count: int) -> ToyCase:
    return ToyCase([((case_seed >> (4 * i)) % 40, 0.1, 0.001) for i in range(count)])


def _run(case: ToyCase) -> int:
    """The toy oracle: an input of 13 is a bug."""
    values = [value for value, _, _ in case.inputs]
    if 13 in values:
        raise AssertionError(f"13 fed as input {values.index(13)}")
    return len(values)


def test_drive_stops_at_the_first_failure_with_its_error_and_a_minimised_reproducer():
    tallies: list[int] = []
    stats = fuzz.drive(fuzz.Stats(), _make, _run, lambda case: fuzz.minimise(case, run=_run), 10**6,
                       round_seed=lambda k: 5 + k, pieces=12, batch=50, counted=lambda case, fed: tallies.append(fed))
    assert stats.failure.startswith("AssertionError: 13 fed as input "), stats.failure
    assert stats.failure.endswith("minimised (1 inputs): AssertionError: 13 fed as input 0")
    assert json.loads(stats.reproducer) == [13]
    assert sum(tallies) == stats.inputs and len(tallies) == stats.cases  # the passing cases, counted once each


def test_drive_spends_its_budget_and_repeats_with_its_seeds():
    def passing(case: ToyCase) -> int:
        return len(case.inputs)

    runs = [fuzz.drive(fuzz.Stats(), _make, passing, lambda case: case, 500, round_seed=lambda k: 9 + k, pieces=12,
                       batch=20) for _ in range(2)]
    assert runs[0].failure is None and runs[0].inputs >= 500
    assert (runs[0].inputs, runs[0].cases) == (runs[1].inputs, runs[1].cases)


def test_replay_of_a_file_that_holds_no_case_is_a_one_line_error(tmp_path, capsys):
    other = tmp_path / "fuzz2-failure.json"
    other.write_text('{"inputs": [], "bus": "2.0"}')
    assert fuzz.main(["--replay", str(other)]) == 2
    assert fuzz.main(["--replay", str(tmp_path / "missing.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("error: ") for line in err), err


def test_the_coverage_figure_names_modules_that_exist():
    """Both fuzzers' coverage is measured on the files named here (ax12emu/<path>.py): a stale name measures nothing."""
    from pathlib import Path

    fuzz2 = load_tool("fuzz2")
    package = Path(fuzz.__file__).resolve().parents[1] / "ax12emu"
    for tool in (fuzz, fuzz2):
        missing = [name for name in tool.TARGET_MODULES if not (package / f"{name}.py").is_file()]
        assert not missing, f"{tool.__name__}: {missing}"
