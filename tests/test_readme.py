"""The README stays true and short: its commands match .ci/run, every file it cites exists."""

from __future__ import annotations

import re
from pathlib import Path

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


def test_ci_runs_the_readme_test_command():
    """.ci/run runs the README's test command, word for word."""
    command = re.search(r"Run the tests.*?```sh\n(.*?)\n```", README, re.DOTALL).group(1).strip()
    assert command in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


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
