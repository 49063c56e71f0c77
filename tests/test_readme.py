"""The README stays true and short: CI runs its test command, every file it cites exists, its Koch arm example runs."""

from __future__ import annotations

import ast
import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")
#: The README introduces; reference material belongs in docs/ (see docs/index.md).
MAX_LINES = 150


def cited_paths(text: str) -> set[str]:
    """Repository paths a Markdown text cites: relative link targets and code spans that look like paths."""
    links = {m.group(1) for m in re.finditer(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text) if "://" not in m.group(1)}
    spans = {
        m.group(1)
        for m in re.finditer(r"`([\w.-]+(?:/[\w.-]+)+/?)`", text)
        if not m.group(1).startswith(("/", "."))  # absolute paths are the user's machine, not the repository
    }
    return links | spans


def steps_in_order(command: str, script: str) -> list[str]:
    """The steps of ``command`` (joined by ``&&``) that ``script`` does not run, in their order, after the one before."""
    missing, position = [], 0
    for step in (part.strip() for part in command.split("&&")):
        found = script.find(step, position)
        if found < 0:
            missing.append(step)
        else:
            position = found + len(step)
    return missing


def test_ci_runs_the_readme_test_command():
    """.ci/run runs every step of the README's test command, word for word and in order (checks may come between)."""
    command = re.search(r"Run the tests.*?```sh\n(.*?)\n```", README, re.DOTALL).group(1).strip()
    assert "pytest" in command
    assert steps_in_order(command, (ROOT / ".ci" / "run").read_text(encoding="utf-8")) == []


def test_step_check_catches_a_missing_or_reordered_step():
    assert steps_in_order("a && b && c", "a\nlint\nb && c") == []
    assert steps_in_order("a && b && c", "a && c") == ["b"]
    assert steps_in_order("a && b", "b\na") == ["b"]


def test_every_cited_file_exists():
    """A link or a path in backquotes names a file or folder of the repository that is there."""
    cited = cited_paths(README)
    assert "docs/index.md" in cited  # the finder sees the links it is meant to check
    missing = sorted(path for path in cited if not (ROOT / path).exists())
    assert not missing, f"README cites files that are not in the repository: {missing}"


def test_cited_path_finder_catches_a_missing_file():
    """The check above would fail on a citation of a file outside the repository."""
    text = "measured physics (`shared/reference/report.txt`) and [a page](docs/nowhere.md#part)"
    assert cited_paths(text) == {"shared/reference/report.txt", "docs/nowhere.md"}
    assert not any((ROOT / path).exists() for path in cited_paths(text))


def test_readme_is_an_introduction():
    """At most MAX_LINES lines: the lab notebook and the reference tables live in docs/."""
    assert len(README.splitlines()) <= MAX_LINES


def python_blocks(text: str, containing: str) -> list[str]:
    """The README's ```python blocks that contain ``containing``."""
    return [block for block in re.findall(r"```python\n(.*?)```", text, re.DOTALL) if containing in block]


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="the example serves its bus on a pty")
def test_the_koch_arm_example_runs_as_printed(capsys):
    """The Protocol 2.0 example, run as it stands: six servos reach the goal it sync-writes, as its comment says."""
    (block,) = python_blocks(README, "PacketHandler(2.0)")
    namespace: dict = {}
    try:
        exec(compile(block, "README.md (Koch arm example)", "exec"), namespace)
    finally:
        if "port" in namespace:
            namespace["port"].closePort()  # the example leaves its port to the end of the script
    positions = ast.literal_eval(capsys.readouterr().out.strip().splitlines()[-1])
    printed = int(re.search(r"# (\d+) each", block).group(1))  # what the README says the run prints
    assert len(positions) == 6 and all(abs(p - printed) <= 2 for p in positions), positions
