"""The command line on input it cannot use: one line on stderr, exit status 2, no traceback, before any work."""

from pathlib import Path

import pytest

from firmware_model.diagnose.cli import main

_AX_HEADER = "t,goal_position,moving_speed,present_position\n"
_WIZARD_HEADER = "DYNAMIXEL Graph,2\nAX-12A,12\nItemCount,1\nPresent Position,#ffff00,0,1,0\nTime[ms],Present Position\n"

#: name -> (file text, or None for a directory in its place; words the error must hold)
CASES = {
    "empty file": ("", "empty file"),
    "header only": (_AX_HEADER, "need at least two rows"),
    "non-numeric row": (_AX_HEADER + "0,512,0,512\n0.01,512,0,abc\n", "column 'present_position'"),
    "trace cut mid-row": (_AX_HEADER + "0,512,0,512\n0.01,512,0", "expected 4 values, got 3"),
    "Wizard export cut in its header": (_WIZARD_HEADER[:40], "ItemCount"),
    "Wizard export with no data row whole": (_WIZARD_HEADER + "0,1\n16,", "need at least two readable data rows"),
    "directory": (None, "Is a directory"),
    # a span no fit can simulate (it used to allocate petabytes): a gap, or a time column in ms
    "trace with a gap of years": (_AX_HEADER + "0,500,0,100\n0.01,500,0,105\n1e12,500,0,110\n",
                                  "widest gap: row 3 of the data, from 0.01 to 1e+12"),
    "trace timed in ms": (_AX_HEADER + "".join(f"{i * 10},500,0,{100 + i}\n" for i in range(40)), "time column's unit"),
    "Wizard export with a row stamped far off": (_WIZARD_HEADER + "0,1\n16,2\n32,3\n99999999999,5\n",
                                                 "the rows span 1e+08 s"),
    # read whole, but its model cannot be built: the data sheet is missing from the metadata
    "X-series trace without its data sheet": ('#@ servo = "x"\nt,goal_position,present_position\n0,1,2\n0.1,1,2\n',
                                              "needs #@ gear_ratio"),
}


@pytest.mark.parametrize("case", CASES)
def test_unusable_input_exits_2_with_one_line(tmp_path, capsys, case):
    text, words = CASES[case]
    path = tmp_path / "measured.csv"
    if text is None:
        path.mkdir()
    else:
        path.write_text(text, encoding="utf-8")
    assert main([str(path), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("error: ") and words in err, err
    assert not (tmp_path / "out" / "report.md").exists()


def test_an_out_that_is_a_file_is_refused_before_any_work(tmp_path, capsys):
    trace = tmp_path / "measured.csv"
    trace.write_text(_AX_HEADER + "".join(f"{i / 100},600,0,{512 + min(i, 60)}\n" for i in range(200)),
                     encoding="utf-8")
    (tmp_path / "out").write_text("not a folder", encoding="utf-8")
    assert main([str(trace), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err == f"error: --out {tmp_path / 'out'}: exists and is not a folder\n", err
    assert Path(tmp_path / "out").read_text(encoding="utf-8") == "not a folder"


def test_an_x_series_effect_is_taken_as_help_offers_it(tmp_path):
    """--help lists load_friction for X-series traces; --effects refused it against the AX library."""
    from firmware_model.diagnose.cli import parse_args

    assert parse_args(["t.csv", "--out", str(tmp_path), "--effects", "load_friction"]).effects == "load_friction"


def test_the_verdict_json_holds_no_number_json_cannot():
    """An exact fit's dBIC is infinite and a grid effect's half-width NaN: json.dumps wrote Infinity and NaN, which
    strict parsers (Python's with parse_constant refusing, JavaScript's JSON.parse) reject."""
    import json

    from firmware_model.diagnose.output import json_safe

    doc = json_safe({"named": [{"delta_bic": float("inf"), "uncertainty_95": {"x": float("nan")}, "values": {"x": 1.0}}]})
    assert json.loads(json.dumps(doc, allow_nan=False)) == {
        "named": [{"delta_bic": None, "uncertainty_95": {"x": None}, "values": {"x": 1.0}}]}


def test_a_trace_of_more_rows_than_the_workflow_holds_is_refused_before_any_work():
    """The span's limit alone let a 300 s log at 1 kHz ask for about 8.5 GB."""
    import numpy as np

    from firmware_model.diagnose.trace import MAX_ROWS, check_span

    with pytest.raises(ValueError, match=r"rows, more than the 100,000 the workflow holds in memory; keep one row in 2"):
        check_span(np.arange(MAX_ROWS + 1) * 1e-3, "log.csv")
    check_span(np.arange(MAX_ROWS) * 1e-3, "log.csv")


@pytest.mark.parametrize("effects", ["backlash,", ",backlash", "backlash,,delay"])
def test_an_empty_effect_entry_is_named(tmp_path, capsys, effects):
    """--effects "backlash," said "unknown effect(s): " and named nothing."""
    from firmware_model.diagnose.cli import parse_args

    with pytest.raises(SystemExit) as exc:
        parse_args(["t.csv", "--out", str(tmp_path), "--effects", effects])
    assert exc.value.code == 2
    assert "has an empty entry (a stray comma?)" in capsys.readouterr().err


def _trace_file(path: Path, voltage: int | None = None) -> Path:
    volts = "" if voltage is None else f",{voltage}"
    path.write_text(_AX_HEADER.strip() + (",voltage\n" if voltage is not None else "\n")
                    + "".join(f"{i / 100},600,0,{512 + min(i, 60)}{volts}\n" for i in range(200)), encoding="utf-8")
    return path


def test_a_trace_without_its_supply_takes_voltage_and_says_what_it_assumed(tmp_path):
    """A trace without a voltage column (tools/record.py wrote none) was fitted at the model's 9.6 V without a
    word, and --voltage, the one way to say a servo ran on 12 V, was refused."""
    from firmware_model.diagnose.cli import load_input, parse_args
    from firmware_model.params import ServoParams

    path = _trace_file(tmp_path / "measured.csv")
    assumed = load_input(parse_args([str(path), "--out", str(tmp_path / "o")]), ServoParams())
    assert "assumed: 9.6 V (the model's default; the trace has no voltage column) — override with --voltage" in assumed.notes
    assert not assumed.trace.has("voltage") and assumed.supply == "assumed"
    assert assumed.facts["voltage_v"] == 9.6 and assumed.facts["assumed"] == ["9.6 V"]
    given = load_input(parse_args([str(path), "--out", str(tmp_path / "o"), "--voltage", "12"]), ServoParams())
    assert given.trace["voltage"].tolist() == [120] * 200 and given.supply == "given"
    assert not any(note.startswith("assumed") for note in given.notes) and given.facts["voltage_v"] == 12.0
    with pytest.raises(ValueError, match=r"--voltage 13.0 V is outside"):
        load_input(parse_args([str(path), "--out", str(tmp_path / "o"), "--voltage", "13"]), ServoParams())


def test_voltage_for_a_trace_that_records_its_supply_takes_its_place_and_says_so(tmp_path):
    """A servo runs past the model's supply range (an AX-12A raises Input Voltage only at 14 V): a recording at
    12.2 V was refused, and --voltage, refused for a trace with the column, left no way to fit it."""
    from firmware_model.diagnose.cli import load_input, parse_args
    from firmware_model.params import ServoParams

    path = _trace_file(tmp_path / "measured.csv", voltage=110)
    recorded = load_input(parse_args([str(path), "--out", str(tmp_path / "o")]), ServoParams())
    assert recorded.supply == "recorded" and not any(note.startswith("assumed") for note in recorded.notes)
    high = _trace_file(tmp_path / "high.csv", voltage=122)
    with pytest.raises(ValueError, match=r"high.csv: the voltage column's 12.2 V is outside .*: give the supply to fit at "
                                         r"with --voltage$"):
        load_input(parse_args([str(high), "--out", str(tmp_path / "o")]), ServoParams())
    given = load_input(parse_args([str(high), "--out", str(tmp_path / "o"), "--voltage", "12"]), ServoParams())
    assert given.supply == "given" and given.trace["voltage"].tolist() == [120] * len(given.trace)
    assert "--voltage 12 V in place of the recorded 12.2-12.2 V" in given.notes


def test_a_supply_given_for_a_trace_is_fitted_and_served(tmp_path):
    """End to end (its own process: plotting keeps font files open): the twin carries the supply given."""
    import subprocess
    import sys

    from firmware_model.params import ServoParams

    path = _trace_file(tmp_path / "measured.csv")
    r = subprocess.run([sys.executable, "-m", "firmware_model.diagnose", str(path), "--out", str(tmp_path / "o"), "-q",
                        "--voltage", "11", "--effects", "coulomb_friction"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert ServoParams.from_toml(tmp_path / "o" / "params.toml").supply_voltage_v == 11.0
    assert "# supply_voltage_v: the supply given (--voltage), 11 V" in (tmp_path / "o" / "params.toml").read_text()


@pytest.fixture
def unwritable_folder(tmp_path):
    """A folder this process cannot create a file in: a read-only one, or (as root, whom modes do not stop) a
    kernel folder."""
    import tempfile

    def writable(folder: Path) -> bool:
        try:
            with tempfile.NamedTemporaryFile(dir=folder):
                return True
        except OSError:
            return False

    mine = tmp_path / "read-only"
    mine.mkdir()
    mine.chmod(0o555)
    try:
        folder = next((f for f in (mine, Path("/sys/kernel"), Path("/proc/self")) if f.is_dir() and not writable(f)),
                      None)
        if folder is None:
            pytest.skip("no folder here that this process cannot write")
        yield folder
    finally:
        mine.chmod(0o755)


def test_an_out_that_cannot_be_written_is_refused_before_the_fit(tmp_path, capsys, monkeypatch, unwritable_folder):
    """--out /sys/kernel ran the whole fit, then ended in a PermissionError traceback."""
    from firmware_model.diagnose import cli

    def no_fit(*args, **kwargs):
        raise AssertionError("the fit ran before --out was found unwritable")

    monkeypatch.setattr(cli, "diagnose", no_fit)
    path = _trace_file(tmp_path / "measured.csv")
    assert cli.main([str(path), "--out", str(unwritable_folder), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --out {unwritable_folder}: cannot write a file in it (") and err.count("\n") == 1, err
    cli._check_out(str(tmp_path / "new" / "out"))  # a folder it can write: made, and left empty by the probe
    assert list((tmp_path / "new" / "out").iterdir()) == []


def test_outputs_that_cannot_be_written_after_the_fit_are_one_line(tmp_path, capsys, monkeypatch):
    """A disk filling up (or a folder changed) between the check and the writing: one line and exit 2."""
    import errno
    from types import SimpleNamespace

    from firmware_model.diagnose import cli

    def full_disk(trace, d, out, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(Path(out) / "measured_vs_model.png"))

    monkeypatch.setattr(cli, "diagnose", lambda *args, **kwargs: SimpleNamespace(recording={}, not_offered={}))
    monkeypatch.setattr(cli, "write_outputs", full_disk)
    path = _trace_file(tmp_path / "measured.csv")
    assert cli.main([str(path), "--out", str(tmp_path / "o"), "-q"]) == 2
    assert capsys.readouterr().err == (f"error: --out {tmp_path / 'o'}: cannot write measured_vs_model.png "
                                       "(No space left on device)\n")
