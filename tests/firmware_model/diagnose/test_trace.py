"""Trace CSV reader and writer: round trip and errors that name line and column."""

import numpy as np
import pytest

from firmware_model.diagnose.trace import Trace, TraceFormatError, departures, parse_trace, read_trace, rest_level, write_trace

GOOD = "# a comment\nt,goal_position,moving_speed,present_position,present_speed,present_load\n0.0,512,0,512,0,0\n0.01,600,100,513,-12,80\n"


def test_round_trip(tmp_path):
    """What the writer writes the reader reads back unchanged."""
    tr = Trace({"t": [0.0, 0.01, 0.02], "goal_position": [1, 2, 3], "moving_speed": [0, 0, 5],
                "present_position": [4, 5, 6], "external_torque_nm": [0.0, 0.25, -0.5]}, ["made here"])
    write_trace(tr, tmp_path / "a.csv")
    back = read_trace(tmp_path / "a.csv")
    assert back.comments == ["made here"]
    for k, v in tr.columns.items():
        np.testing.assert_array_equal(back[k], v)


@pytest.mark.parametrize("text, line, column", [
    (GOOD.replace("513,-12", "513x,-12"), 4, "present_position"),
    (GOOD.replace("0.01,600", "0.0,600"), 4, "t"),
    (GOOD.replace(",80", ",2000"), 4, "present_load"),
    (GOOD.replace("present_load", "present_lode"), 2, "present_lode"),
    (GOOD.replace("moving_speed,", ""), 2, "moving_speed"),
    ("t,goal_position,moving_speed,present_position,external_torque_nm\n0.0,512,0,512,0\n0.01,512,0,512,1e300\n", 3,
     "external_torque_nm"),  # it overflowed the simulation
])
def test_errors_name_line_and_column(text, line, column):
    """A malformed cell, order, range or header is reported at its line and column."""
    with pytest.raises(TraceFormatError) as info:
        parse_trace(text, "x.csv")
    assert info.value.line == line and info.value.column == column
    assert f"x.csv:{line}" in str(info.value)


@pytest.mark.parametrize("value", ['["x"]', '{"a": 1}', "5", '"mx"'])
def test_an_unknown_servo_in_the_metadata_is_named(value):
    """``#@ servo`` holding a list or a table was a TypeError with a traceback; any unknown value is one line."""
    with pytest.raises(TraceFormatError, match="unknown servo"):
        parse_trace(f"#@ servo = {value}\n" + GOOD, "m.csv")
    with pytest.raises(TraceFormatError, match="unknown servo"):
        Trace({"t": [0.0], "goal_position": [1], "moving_speed": [0], "present_position": [1]}, meta={"servo": ["x"]})


def test_row_length_error():
    """A short row names its line."""
    with pytest.raises(TraceFormatError, match=":4"):
        parse_trace(GOOD.replace(",80\n", "\n"))


def test_command_times():
    """``command_t`` is read on command changes only, and must fall between the neighbouring rows' readings."""
    text = ("t,goal_position,moving_speed,present_position,command_t\n"
            "0.0,512,0,512,0.0\n0.01,600,0,512,0.013\n0.02,600,0,513,0.5\n0.03,600,0,520,0.03\n")
    tr = parse_trace(text)
    assert tr.records_command_times and list(tr.change_rows()) == [0, 1]
    with pytest.raises(TraceFormatError) as info:
        parse_trace(text.replace("0.01,600,0,512,0.013", "0.01,600,0,512,0.021"), "c.csv")
    assert info.value.line == 3 and info.value.column == "command_t"


def test_rest_level_is_the_median_of_the_first_or_last_readings():
    """A first reading two units off (the pot's noise, rounded) does not move where the trace rests."""
    pos = np.array([3, 1, 1, 0, 1, 1, 1, 50, 200, 400, 498, 499, 498, 498, 497, 498, 498, 498, 498, 498])
    assert rest_level(pos) == 1.0
    assert rest_level(pos, end=True) == 498.0
    # a trace too short for five readings at rest: its first quarter
    assert rest_level(np.array([1, 3, 300, 500, 500, 500])) == 1.0


def test_a_departure_is_a_reading_away_from_rest_whose_next_reading_is_too():
    pos = np.array([3, 1, 1, 1, 1, 1, 4, 1, 1, 2, 9, 40])
    np.testing.assert_array_equal(departures(pos, 2), [10, 11])


def test_a_byte_order_mark_is_read_past(tmp_path):
    """A spreadsheet's "CSV UTF-8" starts with a byte-order mark; it was read into the first column's name."""
    path = tmp_path / "from_a_spreadsheet.csv"
    path.write_bytes("\ufeff".encode() + b"t,goal_position,moving_speed,present_position\n0,512,0,512\n0.01,512,0,513\n")
    assert read_trace(path)["present_position"].tolist() == [512, 513]


def test_a_trailing_comma_in_the_header_is_named():
    """A trailing comma makes an empty column name: the error named no column ("unknown column (known: ...)")."""
    text = "t,goal_position,moving_speed,present_position,\n0.00,512,0,512,\n0.01,512,0,512,\n"
    with pytest.raises(TraceFormatError, match=r"trace:1: column '': an empty column name \(a trailing comma\?\)"):
        parse_trace(text)
