"""The documentation stays true to the code: generated pages match the data, cited files exist.

The control-table and command-line pages are rendered at build time by ``docs/hooks.py``; these
tests render them with the same functions and check the text against ``ax12emu``'s own table
data and argument parser, so a register or flag the page lost or misstates fails here.
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType

import pytest

from ax12emu.cli.main import build_parser
from ax12emu.protocol.control_table import PROFILES, TABLE_SIZE, Access, layout

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"


def _load(path: Path) -> ModuleType:
    """A module from a file that is not on the import path (the mkdocs hook, the README test)."""
    spec = importlib.util.spec_from_file_location(f"_docs_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


hooks = _load(DOCS / "hooks.py")
cited_paths = _load(ROOT / "tests" / "test_readme.py").cited_paths


# -- the control table --------------------------------------------------------------------------
def table_rows(markdown: str) -> dict[int, list[str]]:
    """Rows of the generated table by address: the cells after the address."""
    rows = {}
    for line in markdown.splitlines():
        match = re.match(r"^\| (\d+) \|(.*)\|$", line)
        if match:
            rows[int(match.group(1))] = [cell.strip() for cell in match.group(2).split("|")]
    return rows


def table_mismatches(markdown: str, profile: str = "ax12a") -> list[str]:
    """Where the table text disagrees with the profile's entries (empty when it agrees)."""
    rows = table_rows(markdown)
    problems = []
    for entry in layout(profile).entries:
        row = rows.get(entry.address)
        span = f"{entry.minimum}–{entry.maximum}" if entry.access is Access.RW else ""
        expected = [str(entry.size), entry.name, entry.area.value, entry.access.value, str(entry.default), span]
        if row is None or row[:6] != expected:
            problems.append(f"address {entry.address}: expected {expected}, page has {row and row[:6]}")
    owned = {a for e in layout(profile).entries for a in range(e.address, e.end)}
    for address, row in rows.items():
        if address not in owned and row[1] != "(unused)":
            problems.append(f"address {address} is unused in {profile} but the page names {row[1]}")
    return problems


def test_control_table_page_matches_the_data():
    """Every ax12a entry appears with its address, size, name, area, access, default and range."""
    assert table_mismatches(hooks.control_table_markdown()) == []


def test_the_table_check_catches_a_wrong_default():
    """A page whose default drifted from the data is reported."""
    right, wrong = "| return_delay_time | EEPROM | RW | 250 |", "| return_delay_time | EEPROM | RW | 200 |"
    text = hooks.control_table_markdown().replace(right, wrong)
    assert text != hooks.control_table_markdown()
    assert any(problem.startswith("address 5:") for problem in table_mismatches(text))


def test_unused_addresses_are_listed():
    """The sentence on unused addresses names exactly the bytes no entry owns."""
    unused = [a for a in range(TABLE_SIZE) if not any(e.address <= a < e.end for e in layout("ax12a").entries)]
    sentence = re.search(r"Unused in `ax12a`.*?: (.*?)\. The table", hooks.control_table_markdown()).group(1)
    listed = []
    for part in sentence.split(", "):
        first, _, last = part.partition("–")
        listed += range(int(first), int(last or first) + 1)
    assert listed == unused


def test_other_profiles_differences_are_shown():
    """Each override and extra entry of the 2006 profile appears in its column."""
    rows = table_rows(hooks.control_table_markdown())
    base = layout("ax12a").by_name
    other = PROFILES["ax12-2006"]
    for name, changes in other.overrides.items():
        cell = rows[base[name].address][-1]
        for key, value in changes.items():
            if key == "default":
                assert f"default {value}" in cell, name
            else:
                assert str(value) in cell.split("range ")[1], name
    for entry in other.extra_entries:
        assert rows[entry.address][-1].startswith(entry.name), entry.name


def test_register_notes_name_real_registers():
    """A note for a register that no profile has is a note that drifted."""
    names = {e.name for profile in PROFILES for e in layout(profile).entries}
    assert set(hooks.NOTES) <= names


# -- the command line ---------------------------------------------------------------------------
def missing_from_page(parser: argparse.ArgumentParser, markdown: str) -> list[str]:
    """Subcommands without a heading and flags without a table row on the page."""
    missing = []
    for name, sub in hooks.subcommands(parser).items():
        if f"## `{parser.prog} {name}`" not in markdown:
            missing.append(name)
        if name in hooks.FORWARDED:
            continue
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            for flag in action.option_strings or [action.metavar or action.dest]:
                if not re.search(rf"\| (?:[^|]*, )?`{re.escape(flag)}[ `]", markdown):
                    missing.append(f"{name} {flag}")
    return missing


def test_cli_page_lists_every_subcommand_and_flag():
    parser = build_parser()
    assert set(hooks.subcommands(parser)) >= {"serve", "decode", "conformance", "diagnose"}
    assert missing_from_page(parser, hooks.cli_markdown(parser)) == []


def test_the_cli_check_catches_a_missing_flag():
    """A page rendered before a flag was added is reported as missing it."""
    parser = build_parser()
    page = hooks.cli_markdown(parser)
    hooks.subcommands(parser)["serve"].add_argument("--brand-new", help="a flag added after the page")
    assert missing_from_page(parser, page) == ["serve --brand-new"]
    assert missing_from_page(parser, hooks.cli_markdown(parser)) == []


def test_forwarded_diagnose_flags_are_on_the_page():
    """``ax12emu diagnose`` shows the flags its program really takes."""
    pytest.importorskip("scipy", reason="the diagnose command needs the [diagnose] extra")
    command = [sys.executable, "-m", "firmware_model.diagnose", "--help"]
    help_text = subprocess.run(command, capture_output=True, text=True, check=True, cwd=ROOT).stdout
    flags = set(re.findall(r"(?<![\w-])--[a-z][\w-]*", help_text))
    assert {"--out", "--effects"} <= flags
    page = hooks.cli_markdown()
    assert sorted(flag for flag in flags if flag not in page) == []


# -- the pages and the site ---------------------------------------------------------------------
def test_pages_carry_the_markers_the_hook_fills():
    """The generated blocks are asked for, and the hook leaves no marker behind."""
    pages = {"protocol.md": "<!-- ax12emu:control-table -->", "cli.md": "<!-- ax12emu:cli -->"}
    for page, marker in pages.items():
        text = (DOCS / page).read_text(encoding="utf-8")
        assert marker in text, page
        assert "<!-- ax12emu:" not in hooks.on_page_markdown(text)
    assert "docs/hooks.py" in (ROOT / "mkdocs.yml").read_text(encoding="utf-8")


def test_sphinx_roles_render_as_code():
    """mkdocstrings leaves a docstring's role name as text before its code span; the hook keeps the span alone."""
    html = ('see :class:<code>~ax12emu.VirtualBus</code>, :meth:<code>step</code>, :mod:<code>.checks2</code> '
            'and :py:func:<code>ax12emu.protocol.servo_models.model</code>; <code>plain</code> stays')
    assert hooks.strip_sphinx_roles(html) == (
        "see <code>VirtualBus</code>, <code>step</code>, <code>checks2</code> "
        "and <code>ax12emu.protocol.servo_models.model</code>; <code>plain</code> stays"
    )
    assert hooks.on_page_content(":attr:<code>busy_until_s</code>") == "<code>busy_until_s</code>"


def _cited_file_exists(page: Path, path: str, published: set[str]) -> bool:
    """A path in backquotes is the repository's; a link is the page's (or a figure the hook publishes)."""
    beside = (page.parent / path).resolve()
    if (ROOT / path).exists() or beside.exists():
        return True
    return beside.is_relative_to(DOCS) and beside.relative_to(DOCS).as_posix() in published


def test_every_file_the_docs_cite_exists():
    """Paths in backquotes and relative links of every page name files that are there."""
    figures = hooks.FIGURES_DIR.rglob("*")
    published = {f"{hooks.FIGURES_URI}/{p.relative_to(hooks.FIGURES_DIR).as_posix()}" for p in figures}
    pages = sorted(DOCS.rglob("*.md"))
    cited = {(page, path) for page in pages for path in cited_paths(page.read_text(encoding="utf-8"))}
    assert any(path == "figures/step_response.png" for _, path in cited)  # links to published figures are checked too
    missing = sorted(
        f"{page.relative_to(ROOT)}: {path}" for page, path in cited if not _cited_file_exists(page, path, published)
    )
    assert missing == []


def test_servo_models_table_lists_every_model_file():
    """The protocol page asks for the models table, and it has one row per model file with its figures."""
    from ax12emu.protocol.servo_models import model, model_names

    assert "<!-- ax12emu:servo-models -->" in (DOCS / "protocol.md").read_text(encoding="utf-8")
    rows = [line for line in hooks.servo_models_markdown().splitlines() if line.startswith("| `ax12emu/protocol/models/")]
    assert len(rows) == len(model_names())
    for key, row in zip(model_names(), rows):
        servo = model(key)
        assert f"models/{key}.toml" in row and f"| {servo.model_number} |" in row
        rating = servo.physical.ratings[0]
        assert f"{rating.stall_torque_nm:g} N m @ {rating.voltage_v:g} V" in row
        assert (ROOT / "ax12emu" / "protocol" / "models" / f"{key}.toml").exists()


# -- the URL port handler users are shown --------------------------------------------------------
def test_the_url_port_handler_of_getting_started_keeps_a_private_bus_through_a_baud_change():
    """The page's UrlPortHandler, run as written: dynamixel-sdk's setBaudRate after a Baud Rate write reaches the
    same servo (reopening the URL built a new private bus: the servo was back at ID 1 and 1 Mbps)."""
    text = (DOCS / "getting-started.md").read_text(encoding="utf-8")
    block = next(code for code in re.findall(r"```python\n(.*?)```", text, re.S) if "class UrlPortHandler" in code)
    namespace: dict = {}
    exec(compile(block.split("port = UrlPortHandler(")[0], "getting-started.md", "exec"), namespace)  # noqa: S102
    from dynamixel_sdk import PacketHandler

    import ax12emu  # noqa: F401  (registers the ax12emu:// handler)

    port = namespace["UrlPortHandler"]("ax12emu://?ids=1")
    packet = PacketHandler(1.0)
    assert port.openPort() and port.setBaudRate(1_000_000)
    try:
        assert packet.write1ByteTxRx(port, 1, 3, 5) == (0, 0)  # ID 5
        time.sleep(0.05)  # the servo writes its EEPROM (deaf meanwhile, as a real AX-12A)
        assert packet.write1ByteTxRx(port, 5, 4, 34) == (0, 0)  # Baud Rate 34: 57,142 bps
        time.sleep(0.05)
        assert port.setBaudRate(57600)
        assert packet.ping(port, 5) == (12, 0, 0)
    finally:
        port.closePort()
