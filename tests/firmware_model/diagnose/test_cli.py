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

    from firmware_model.diagnose.cli import MAX_ROWS, check_span

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
