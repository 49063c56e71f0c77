"""The Wizard 2 graph-export reader: good files, skipped rows counted, header errors at their line, the real files."""

from pathlib import Path

import numpy as np
import pytest

from firmware_model.diagnose.trace import command_time_errors
from firmware_model.diagnose.wizard import (
    TICK_S,
    WizardFormatError,
    is_wizard_export,
    parse_wizard,
    read_wizard,
    reading_times,
    to_trace,
)

REAL = Path(__file__).resolve().parents[3] / ".." / "shared" / "reference" / "real-ax12a"

HEAD = "DYNAMIXEL Graph,2\nAX-12A,12\nItemCount,1\nPresent Position,#ffff00,0,1,0\nTime[ms],Present Position\n"
GOOD = HEAD + "0,1\n96,1\n112,3\n128,20\n144,60\n160,110\n"


def _write(tmp_path, text, name="w.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_good_file(tmp_path):
    """Header, model, items and every row read; times in s from the first row."""
    path = _write(tmp_path, GOOD)
    assert is_wizard_export(path)
    ex = read_wizard(path)
    assert (ex.model_name, ex.model_number, ex.items) == ("AX-12A", 12, ("Present Position",))
    np.testing.assert_allclose(ex.t_s, [0, 0.096, 0.112, 0.128, 0.144, 0.160])
    np.testing.assert_array_equal(ex.values["present_position"], [1, 1, 3, 20, 60, 110])
    assert ex.rows_read == 6 and ex.rows_skipped == 0 and ex.ignored_items == ()


def test_garbled_and_repeated_rows_are_skipped_and_counted():
    """A lost field, a lost time digit, a repeated time and a non-number are skipped and counted by kind."""
    text = HEAD + "0,1\n16,1\n499\n32,2\n5,3\n32,3\n48,x\n64,4\n64,5\n80,6\n"
    ex = parse_wizard(text, "g.csv")
    np.testing.assert_array_equal(ex.values["present_position"], [1, 1, 2, 4, 6])
    assert ex.skipped == {"garbled": 2, "repeated_time": 2, "time_back": 1}
    assert ex.skipped_lines == [8, 10, 11, 12, 14]
    assert ex.rows_seen == 10 and ex.rows_read == 5
    assert "5 rows read, 5 skipped (2 garbled, 2 repeated time, 1 time back)" in ex.summary()


def test_several_items_signed_speed_and_an_unknown_item():
    """Items map to trace columns by name; raw speed/load become signed; an unmapped item is listed, not read."""
    text = ("DYNAMIXEL Graph,2\nAX-12A,12\nItemCount,4\nPresent Position,#ffff00,0,1,0\nPresent Speed,#ff0000,0,1,0\n"
            "Present Temperature,#00ff00,0,1,0\nGoal Position,#0000ff,0,1,0\n"
            "Time[ms],Present Position,Present Speed,Present Temperature,Goal Position\n"
            "0,512,0,31,512\n16,520,300,31,600\n32,530,1324,32,600\n")
    ex = parse_wizard(text)
    np.testing.assert_array_equal(ex.values["present_speed"], [0, 300, -300])
    np.testing.assert_array_equal(ex.values["goal_position"], [512, 600, 600])
    assert ex.ignored_items == ("Present Temperature",) and "present_temperature" not in ex.values
    tr = to_trace(ex, goal_position=900, onset_s=0.0)  # the recorded goal wins over the assumed one
    np.testing.assert_array_equal(tr["goal_position"], [512, 600, 600])
    assert not tr.records_command_times


@pytest.mark.parametrize("text, line, words", [
    ("", None, "empty file"),
    ("\n\n", None, "empty file"),
    ("t,goal_position\n0,1\n", 1, "not a Wizard graph export"),
    ("DYNAMIXEL Graph,2\nAX-12A,12\n", 2, "header ends early"),
    ("DYNAMIXEL Graph,2\nAX-12A\nItemCount,1\n", 2, "model line"),
    ("DYNAMIXEL Graph,2\nAX-12A,12\nItems,1\n", 3, "ItemCount"),
    ("DYNAMIXEL Graph,2\nAX-12A,12\nItemCount,2\nPresent Position,#ffff00,0,1,0\nTime[ms],Present Position\n0,1\n",
     5, "item line"),
    (HEAD.replace("Time[ms],Present Position", "Time[ms],Goal Position") + "0,1\n16,1\n", 5, "column header names"),
    (HEAD.replace("Time[ms],", "Time,") + "0,1\n16,1\n", 5, "expected the column header"),
    (HEAD, 5, "at least two readable data rows, found 0"),
    (HEAD + "0,1\n", 6, "at least two readable data rows"),
    (HEAD + "0,1\nabc\n", 7, "at least two readable data rows"),
    # a register outside its range (it was used: 1e300 gave an RMS gap of 6e17), named at its line
    (GOOD.replace("144,60", "144,5000"), 10, "Present Position 5000 is outside the register's 0..1023"),
    (GOOD.replace("96,1", "96,-7"), 7, "Present Position -7 is outside"),
    (GOOD.replace("144,60", "144,1e300"), 10, "outside the register's 0..1023"),
    (HEAD.replace("ItemCount,1", "ItemCount,2").replace("Time[ms],Present Position", "Present Position,#00ff00,0,1,0\n"
                  "Time[ms],Present Position,Present Position") + "0,1,1\n16,1,1\n", 6, "plotted more than once"),
    # another series' export: its positions are not the AX series' units
    (GOOD.replace("AX-12A,12", "MX-28,29"), 2, "from a MX-28 \\(model number 29\\): the workflow reads the AX series"),
    (GOOD.replace("AX-12A,12", "XL430-W250,1060"), 2, "model number 1060"),
])
def test_malformed_files_name_file_and_line(text, line, words):
    """Header problems, and a file with under two readable rows, are a ValueError naming the file and line."""
    with pytest.raises(ValueError, match=words) as info:
        parse_wizard(text, "bad.csv")
    assert isinstance(info.value, WizardFormatError)
    assert str(info.value).startswith("bad.csv" + (f":{line}:" if line else ":"))


def test_not_a_wizard_file(tmp_path):
    """Detection looks at the first field only: a project trace, a missing file and an empty file are not exports."""
    assert not is_wizard_export(_write(tmp_path, "t,goal_position,moving_speed,present_position\n0,1,0,1\n"))
    assert not is_wizard_export(tmp_path / "missing.csv")
    assert not is_wizard_export(_write(tmp_path, "", "empty.csv"))
    with pytest.raises(WizardFormatError, match="empty.csv: empty file"):
        read_wizard(tmp_path / "empty.csv")


def test_to_trace_places_the_goal_at_the_onset():
    """The assumed goal takes effect at ``onset_s``: the row before it gets the new goal, command_t = onset if known."""
    ex = parse_wizard(GOOD)
    tr = to_trace(ex, goal_position=500, onset_s=0.100, moving_speed=0, voltage_v=12.0)
    np.testing.assert_array_equal(tr["goal_position"], [1, 500, 500, 500, 500, 500])
    assert not tr.records_command_times
    known = to_trace(ex, goal_position=500, onset_s=0.100, onset_known=True)
    assert known["command_t"][1] == pytest.approx(0.100)
    assert known.records_command_times and len(command_time_errors(known)) == 0
    assert set(tr["voltage"]) == {120} and set(tr["moving_speed"]) == {0}
    early = to_trace(ex, goal_position=500, onset_s=-1.0)
    assert set(early["goal_position"]) == {500}


REAL_FILES = {  # file -> (rows after the header, rows skipped), counted by hand: a lost digit of the time
    # ("5,499" after "2496,..."), a lost field ("499"), an earlier time repeated ("2480", "2496" again)
    "AX12A_NOLOAD_1.csv": (207, 2),
    "AX12A_LOAD3_1.csv": (182, 2),
    "AX12A_LOAD2_1.csv": (240, 4),
    "AX18A_NOLOAD_1.csv": (177, 0),
}


@pytest.mark.parametrize("name", list(REAL_FILES))
def test_real_exports(name):
    """The four shared real exports: every row accounted for, a step from about 0 to about 500."""
    if not REAL.is_dir():
        pytest.skip(f"real AX-12A exports not present at {REAL.resolve()}")
    seen, skipped = REAL_FILES[name]
    ex = read_wizard(REAL / name)
    assert ex.rows_seen == seen and ex.rows_skipped == skipped, (ex.rows_seen, ex.skipped)
    assert ex.rows_read == seen - skipped
    assert ex.model_name == name.split("_")[0].replace("AX12A", "AX-12A").replace("AX18A", "AX-18A")
    pos = ex.values["present_position"]
    assert pos[0] <= 2 and 497 <= pos[-1] <= 500
    assert np.all(np.diff(ex.t_s) > 0) and 0.012 < np.median(np.diff(ex.t_s)) < 0.020


def _tick_stamped(period_s: float, phase_s: float, n: int, lost: tuple[int, ...] = (), stall_after: int | None = None):
    """Readings every ``period_s``, each stamped on the first 16 ms tick at or after it (ms, as the Wizard writes
    them); ``lost`` rows dropped; after ``stall_after`` the Wizard stalls 0.2 s and the clock resumes at another
    phase.  Returns (the stamps' seconds from the first, the true reading times from the first reading)."""
    read = phase_s + np.arange(n) * period_s
    if stall_after is not None:
        read[stall_after:] += 0.2 + 0.0071
    keep = np.setdiff1d(np.arange(n), lost)
    read = read[keep]
    stamps_ms = np.ceil(read / TICK_S - 1e-9) * 16.0
    return (stamps_ms - stamps_ms[0]) / 1000.0, read - read[0]


def test_reading_clock_is_rebuilt_from_tick_stamps():
    """Rows read every 19.87 ms but stamped on the 16 ms tick (every fifth tick without a row): the readings come
    back within a fraction of a ms (the stamps were up to a tick off), across a lost row and a stall."""
    t, truth = _tick_stamped(0.01987, 0.0031, 220, lost=(57, 140), stall_after=120)
    assert np.max(np.abs((t - t[0]) - truth)) > 0.012  # the stamps alone
    read, period, share = reading_times(t)
    assert period == pytest.approx(0.01987, abs=5e-5) and share > 0.95
    err = np.abs(read - truth)
    assert np.quantile(err, 0.95) < 0.001 and np.max(err) < 0.002, np.max(err)


def test_exports_not_stamped_on_the_tick_keep_their_stamps(tmp_path):
    """A clock that is not the Wizard's 16 ms tick (here 10 ms with jitter) is taken as stamped: nothing rebuilt."""
    rng = np.random.default_rng(3)
    t_ms = np.rint(np.cumsum(np.r_[0.0, 10.0 + rng.uniform(-1, 1, 99)])).astype(int)
    ex = parse_wizard(HEAD + "".join(f"{t},{i}\n" for i, t in enumerate(t_ms)))
    assert reading_times(ex.t_s) is None and ex.read_s is None and ex.times_s is ex.t_s
    assert "rebuilt" not in ex.summary()


@pytest.mark.parametrize("name", [n for n in REAL_FILES])
def test_real_exports_are_read_on_a_regular_clock(name):
    """At full speed the real servo moves steadily: against the rebuilt reading times its positions lie on a line
    within 2 units RMS, against the stamps 4.5-6 units off it (measured 0.8-1.8 and 4.7-6.1)."""
    if not REAL.is_dir():
        pytest.skip(f"real AX-12A exports not present at {REAL.resolve()}")
    ex = read_wizard(REAL / name)
    assert ex.read_period_s == pytest.approx(0.020, abs=0.0005) and ex.read_share > 0.9
    assert "reading times rebuilt" in ex.summary()
    pos = ex.values["present_position"].astype(float)
    cruise = (pos > 100) & (pos < 420)
    off = {}
    for label, t in (("stamps", ex.t_s), ("read", ex.read_s)):
        line = np.polyfit(t[cruise], pos[cruise], 1)
        off[label] = float(np.std(pos[cruise] - np.polyval(line, t[cruise])))
    assert off["read"] < 2.0 and off["stamps"] > 2.0 * off["read"], off


@pytest.mark.parametrize("moving_speed", [150, 300])
def test_the_cruise_of_a_speed_limited_step_is_its_moving_speed(moving_speed):
    """Read every 20 ms and stamped on the tick as the Wizard does, a step at Moving Speed N cruises at N x 0.111 rpm
    (within 3 %: the rows' stamps jitter by a tick)."""
    from firmware_model.diagnose.synthetic import wizard_step_export
    from firmware_model.diagnose.wizard import cruise_units_s
    from firmware_model.params import ServoParams
    from firmware_model.units import RAD_PER_POSITION_UNIT, RAD_S_PER_SPEED_UNIT

    ex = parse_wizard(wizard_step_export(ServoParams(), 300.0, 5000.0, moving_speed=moving_speed))
    cruise = cruise_units_s(ex.times_s, ex.values["present_position"])
    assert cruise == pytest.approx(moving_speed * RAD_S_PER_SPEED_UNIT / RAD_PER_POSITION_UNIT, rel=0.03)


def test_a_step_too_short_to_cruise_has_no_cruise():
    from firmware_model.diagnose.wizard import cruise_units_s

    with pytest.raises(ValueError, match="cross the middle"):
        cruise_units_s(np.array([0.0, 0.02, 0.04]), np.array([0.0, 0.0, 0.4]))


def _padded(text: str) -> str:
    """``text`` as a spreadsheet re-saves ragged CSV: every line padded with commas to the widest."""
    lines = text.splitlines()
    width = max(line.count(",") for line in lines)
    return "".join(line + "," * (width - line.count(",")) + "\n" for line in lines)


@pytest.mark.parametrize("resave", [
    _padded,                                                  # padded to a rectangle
    lambda text: _padded(text).replace(",", ";"),             # and saved with ';' (a comma-decimal locale)
    lambda text: text.replace(",", "\t"),                     # saved as tab-separated text
    lambda text: HEAD + "".join(line + ",\n" for line in text[len(HEAD):].splitlines()),  # the data rows alone
])
def test_an_export_resaved_by_a_spreadsheet_reads_as_the_original(tmp_path, resave):
    """Empty fields at a line's end are ignored, and the separator is the one after the first line's magic
    (the padded file was refused at its model line 'AX-12A,12,,,', the ';' one taken for a trace CSV, and rows
    with a trailing comma all skipped as garbled)."""
    path = _write(tmp_path, resave(GOOD))
    assert is_wizard_export(path)
    ex, good = read_wizard(path), parse_wizard(GOOD)
    assert (ex.model_name, ex.model_number, ex.items, ex.rows_skipped) == ("AX-12A", 12, ("Present Position",), 0)
    np.testing.assert_array_equal(ex.t_s, good.t_s)
    np.testing.assert_array_equal(ex.values["present_position"], good.values["present_position"])


@pytest.mark.parametrize("rows, line, why", [
    ("0,1,2\n16,1,2\n", 6, "'0,1,2': 3 fields where the column header has 2"),
    ("0.5s,1\n16.5s,1\n", 6, "the time '0.5s' is not a number"),
    ("0,1.5\n16,2.5\n", 6, "Present Position '1.5' is not a whole number"),
    ("0,1\n0,1\n", 7, "its time repeats the last kept row's, 0 ms"),
    ("16,1\n0,1\n", 7, "its time 0 ms is before the last kept row's, 16 ms"),
])
def test_no_readable_rows_names_the_first_skipped_and_why(rows, line, why):
    """Where under two rows are readable, the error points at the first skipped row and says why it was skipped
    (it said only how many were skipped)."""
    with pytest.raises(WizardFormatError, match="need at least two readable data rows") as info:
        parse_wizard(HEAD + rows, "bad.csv")
    assert str(info.value).startswith(f"bad.csv:{line}: ") and why in str(info.value), str(info.value)


def test_an_export_past_the_row_limit_is_refused_before_the_clock_is_rebuilt(monkeypatch):
    """The workflow's row limit is checked on the stamps, before the reading clock (about 1.5 ms a row) is rebuilt:
    120,000 rows were refused after 191 s."""
    from firmware_model.diagnose import wizard
    from firmware_model.diagnose.trace import MAX_ROWS

    def no_clock(t_s):
        raise AssertionError(f"the reading clock was rebuilt for {len(t_s)} rows")

    monkeypatch.setattr(wizard, "reading_times", no_clock)
    n = MAX_ROWS + 1
    text = HEAD + "".join(f"{16 * k},{k % 1000}\n" for k in range(n))
    with pytest.raises(ValueError, match=f"{n:,} rows, more than the {MAX_ROWS:,}"):
        parse_wizard(text, "big.csv")


def test_an_export_past_the_span_limit_is_refused_before_the_clock_is_rebuilt(monkeypatch):
    """The span limit too (a time column in tenths of ms, say), naming the widest gap."""
    from firmware_model.diagnose import wizard
    from firmware_model.diagnose.trace import MAX_SPAN_S

    monkeypatch.setattr(wizard, "reading_times", lambda t_s: pytest.fail("the reading clock was rebuilt"))
    stamps_ms = [16 * k for k in range(20)] + [1000.0 * (MAX_SPAN_S + 16)]
    with pytest.raises(ValueError, match=f"more than the {MAX_SPAN_S:g} s the workflow simulates"):
        parse_wizard(HEAD + "".join(f"{t:g},1\n" for t in stamps_ms), "long.csv")


def test_the_limits_are_the_callers(monkeypatch):
    """``limits=None`` reads an export of any size (the clock is rebuilt), another check runs instead of them."""
    text = HEAD + "".join(f"{16 * k},1\n" for k in range(12))
    assert parse_wizard(text, limits=None).read_period_s is not None
    seen = []
    parse_wizard(text, limits=lambda t_s, source: seen.append((len(t_s), source)))
    assert seen == [(12, "wizard export")]


def test_the_model_is_read_from_the_first_two_lines(tmp_path):
    """:func:`read_wizard_model` reads the model line alone: an export whose rows are all unreadable still names its
    servo; a file that is no export is a WizardFormatError at its line."""
    from firmware_model.diagnose.wizard import read_wizard_model

    path = _write(tmp_path, _padded(GOOD.replace("AX-12A,12", "AX-18A,18")).replace(",", ";") + "x;y;z\n" * 3)
    assert read_wizard_model(path) == ("AX-18A", 18)
    with pytest.raises(WizardFormatError, match=r"w.csv:3: expected the model line"):
        read_wizard_model(_write(tmp_path, "DYNAMIXEL Graph,2\n\nAX-18A\n"))
    with pytest.raises(WizardFormatError, match=r"w.csv:1: not a Wizard graph export"):
        read_wizard_model(_write(tmp_path, "t,goal_position\n"))
    with pytest.raises(WizardFormatError, match=r"w.csv:1: header ends early"):
        read_wizard_model(_write(tmp_path, "DYNAMIXEL Graph,2\n"))
