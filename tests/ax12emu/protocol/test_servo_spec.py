"""Which model each ID is: "MODEL" with --ids, or "IDS:MODEL,..." per ID; every mistake named."""

from __future__ import annotations

import pytest

from ax12emu.protocol.servo_spec import parse_servo_spec


def test_one_model_for_every_id():
    assert parse_servo_spec("XL430-W250", [3, 1]) == [(3, "xl430-w250"), (1, "xl430-w250")]


def test_per_id_models_with_ranges_and_lists():
    assert parse_servo_spec("1-2:xm430-w350,6:xl330-m077") == [(1, "xm430-w350"), (2, "xm430-w350"), (6, "xl330-m077")]
    assert parse_servo_spec("1,4:xl430-w250,7:xm430-w350") == [(1, "xl430-w250"), (4, "xl430-w250"), (7, "xm430-w350")]


@pytest.mark.parametrize(
    ("text", "ids", "message"),
    [
        ("", [1], "empty servo list"),
        ("xl430-w250", None, "names no IDs"),
        ("mx-28", [1], "speaks Protocol 1.0, not 2.0"),
        ("1:nope", None, "unknown servo model 'nope'"),
        ("1:", None, "names no model"),
        ("1-2:xl430-w250,2:xm430-w350", None, "ID 2 is given two models"),
        ("1:xl430-w250,5", None, "have no model"),
        ("1:xl430-w250", [1], "both name the IDs"),
        ("x:xl430-w250", None, "not an ID"),
        ("253:xl430-w250", None, "outside 0..252"),
    ],
)
def test_mistakes_are_named(text, ids, message):
    with pytest.raises(ValueError, match=message):
        parse_servo_spec(text, ids)
