"""``ax12emu models``: one line per shipped model file, with its data-sheet figures."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from ax12emu.cli.main import build_parser
from ax12emu.cli.models import models_table
from ax12emu.protocol.servo_models import model, model_names


def test_lists_every_model_with_its_protocol_and_rated_figures():
    lines = models_table().splitlines()
    assert lines[0].split()[:3] == ["key", "name", "protocol"]
    rows = {line.split()[0]: line for line in lines[1:]}
    assert set(rows) == set(model_names()) >= {"ax-12a", "xl430-w250", "mx-28", "xl-320"}
    assert rows["xl430-w250"].split()[1:4] == ["XL430-W250", "2.0", "1060"]
    assert "1.4 N m @ 11.1 V" in rows["xl430-w250"] and "57 rpm @ 11.1 V" in rows["xl430-w250"]
    assert "1.5 N m @ 12 V" in rows["ax-12a"] and "59 rpm @ 12 V" in rows["ax-12a"]


def test_all_ratings_gives_one_line_per_rated_voltage():
    lines = models_table(all_ratings=True).splitlines()[1:]
    assert len(lines) == sum(len(model(key).physical.ratings) for key in model_names())
    assert sum(line.startswith("mx-64 ") for line in lines) == 3


def test_the_subcommand_runs_from_the_command_line():
    assert build_parser().parse_args(["models"]).command == "models"
    out = subprocess.run([sys.executable, "-m", "ax12emu", "models"], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == models_table()


def test_the_help_names_what_the_listing_prints(monkeypatch, capsys):
    """``models --help`` said "control tables"; the listing holds none: it says the columns it prints."""
    monkeypatch.setenv("COLUMNS", "1000")  # one line per paragraph: no column name cut at a hyphen
    with pytest.raises(SystemExit):
        build_parser().parse_args(["models", "--help"])
    text = capsys.readouterr().out
    columns = re.split(r"\s{2,}", models_table().splitlines()[0])
    assert all(column in text for column in columns), (columns, text)
    assert "control table" not in text and "control table" not in _listed_help("models")


def _listed_help(command: str) -> str:
    """The line ``ax12emu --help`` gives a subcommand."""
    (sub,) = [action for action in build_parser()._actions if action.dest == "command"]
    return next(choice.help for choice in sub._choices_actions if choice.dest == command)
