"""The README stays true: its control table matches the data, its commands match .ci/run."""

from __future__ import annotations

import re
from pathlib import Path

from ax12emu.control_table import layout

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")


def test_control_table_rows_match_the_data():
    """Every ax12a entry appears with its address, size, name and access."""
    rows = {}
    for match in re.finditer(r"^\| (\d+) \| (\d) \| (\w+) \| (R|RW) \|", README, re.M):
        rows[match.group(3)] = (int(match.group(1)), int(match.group(2)), match.group(4))
    for entry in layout("ax12a").entries:
        assert rows.get(entry.name) == (entry.address, entry.size, entry.access.value), entry.name


def test_ci_runs_the_readme_test_command():
    """.ci/run runs the README's test command, word for word."""
    command = re.search(r"Run the tests.*?```sh\n(.*?)\n```", README, re.S).group(1).strip()
    assert command in (ROOT / ".ci" / "run").read_text(encoding="utf-8")
