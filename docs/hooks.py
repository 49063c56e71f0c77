"""mkdocs hook: the pages that must not drift from the code are generated from it at build time.

Why it exists: a hand-kept control table or flag list goes stale the day a register or a
flag changes.  The control table is rendered from :mod:`ax12emu.protocol.control_table`'s
entries and profiles, the command line from the argparse parser ``ax12emu`` itself runs.
A page asks for a generated block with a marker comment on a line of its own (see
``MARKERS``); ``tests/docs/test_docs.py`` checks the rendered text against the same data.

The figures under ``tools/figures/`` (written by the tools that make them) are published
under ``figures/`` without a copy in ``docs/``.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import os
import re
from collections.abc import Callable, Iterator
from pathlib import Path

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.structure.files import File, Files

from ax12emu.cli.main import build_parser
from ax12emu.protocol.control_table import (
    DEFAULT_PROFILE,
    PROFILES,
    TABLE_SIZE,
    Access,
    Entry,
    layout,
)
from ax12emu.protocol.servo_models import model, model_names

ROOT = Path(__file__).resolve().parent.parent
#: Folder of generated figures in the repository, and where the site serves them.
FIGURES_DIR = ROOT / "tools" / "figures"
FIGURES_URI = "figures"

#: What a register's raw value means, for readers (not used by the emulator).
NOTES: dict[str, str] = {
    "baud_rate": "bps = 2,000,000 / (value + 1); 1 = 1 Mbps",
    "return_delay_time": "2 µs per unit; 250 = 500 µs",
    "cw_angle_limit": "both limits 0: wheel mode",
    "ccw_angle_limit": "both limits 0: wheel mode",
    "temperature_limit": "°C",
    "min_voltage_limit": "0.1 V per unit",
    "max_voltage_limit": "0.1 V per unit",
    "max_torque": "1023 = 100 % of the stall torque; copied to Torque Limit at power-up",
    "status_return_level": "0: PING only, 1: PING and READ, 2: all",
    "alarm_led": "alarm bits that blink the LED",
    "shutdown": "alarm bits that act (Alarm Shutdown)",
    "goal_position": "0.29° per unit over 300°; set to Present Position at power-up",
    "moving_speed": "0.111 rpm per unit; 0 = no speed limit; wheel mode: bit 10 is the direction",
    "torque_limit": "set to Max Torque at power-up; Alarm Shutdown sets 0 (ax12a)",
    "present_position": "written by the model",
    "present_speed": "written by the model; bit 10 is the direction",
    "present_load": "written by the model; bit 10 is the direction",
    "present_voltage": "written by the model; 0.1 V per unit",
    "present_temperature": "written by the model; °C",
    "registered": "1 while a REG_WRITE waits for ACTION",
    "moving": "written by the model",
    "lock": "1 until a restart",
}


def _span(entry: Entry) -> str:
    """The write range of a writable entry; read-only entries have none."""
    return f"{entry.minimum}–{entry.maximum}" if entry.access is Access.RW else ""


def _profile_difference(base: Entry | None, other: Entry | None) -> str:
    """How ``other`` (an entry of the other profile at the same address) differs from ``base``."""
    if other is None:
        return "(unused)" if base is not None else ""
    if base is None or base.name != other.name:
        span = _span(other)
        return ", ".join(part for part in (other.name, other.access.value, span) if part)
    parts = []
    if other.default != base.default:
        parts.append(f"default {other.default}")
    if (other.minimum, other.maximum) != (base.minimum, base.maximum) and other.access is Access.RW:
        parts.append(f"range {_span(other)}")
    if other.access is not base.access:
        parts.append(other.access.value)
    return ", ".join(parts)


def control_table_markdown(profile: str = DEFAULT_PROFILE) -> str:
    """The control table of ``profile`` as a Markdown table, with the other profiles' differences."""
    base = layout(profile)
    others = [layout(name) for name in PROFILES if name != profile]
    starts: dict[int, Entry | None] = {e.address: e for e in base.entries}
    for other in others:
        for entry in other.entries:
            starts.setdefault(entry.address, None)
    header = ["addr", "size", "name", "area", "access", "default", "range", "notes"]
    header += [f"{other.profile.name} differs" for other in others]
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    for address in sorted(starts):
        entry = starts[address]
        other_entries = [next((e for e in o.entries if e.address == address), None) for o in others]
        if entry is None:
            sample = next(e for e in other_entries if e is not None)
            cells = [str(address), str(sample.size), "(unused)", sample.area.value, "", "", "", ""]
        else:
            cells = [
                str(entry.address),
                str(entry.size),
                entry.name,
                entry.area.value,
                entry.access.value,
                str(entry.default),
                _span(entry),
                NOTES.get(entry.name, ""),
            ]
        cells += [_profile_difference(entry, other) for other in other_entries]
        lines.append("| " + " | ".join(cells) + " |")
    unused = [address for address in range(TABLE_SIZE) if base.owner[address] < 0]
    lines += [
        "",
        f"Profile `{profile}` ({base.profile.source}).",
        "",
        (
            f"Unused in `{profile}`, reading 0 and refusing writes with a Range Error: "
            f"{_ranges(unused)}. The table ends at address {TABLE_SIZE - 1}."
        ),
    ]
    for other in others:
        lines += ["", f"Profile `{other.profile.name}`: {other.profile.source}."]
    return "\n".join(lines)


def _ranges(addresses: list[int]) -> str:
    """``[10, 19, 20, 21]`` -> ``"10, 19–21"``."""
    groups: list[list[int]] = []
    for address in addresses:
        if groups and address == groups[-1][-1] + 1:
            groups[-1].append(address)
        else:
            groups.append([address])
    return ", ".join(str(g[0]) if len(g) == 1 else f"{g[0]}–{g[-1]}" for g in groups)


def _flags(action: argparse.Action) -> str:
    """``--tcp HOST:PORT`` / ``-v, --verbose`` / ``FILE`` for one argument."""
    if not action.option_strings:
        return f"`{action.metavar or action.dest}`"
    if action.nargs == 0:
        return ", ".join(f"`{flag}`" for flag in action.option_strings)
    if action.metavar is not None:
        value = action.metavar
    elif action.choices is not None:
        value = "{" + ",".join(str(c) for c in action.choices) + "}"
    else:
        value = action.dest.upper()
    return ", ".join(f"`{flag} {value}`" for flag in action.option_strings)


def _default(action: argparse.Action) -> str:
    if action.nargs == 0 or action.default in (None, argparse.SUPPRESS, [], ()):
        return ""
    value = action.default
    if isinstance(value, (list, tuple)):
        value = ",".join(str(v) for v in value)
    return f"`{value}`"


def _cell(text: str | None) -> str:
    return (text or "").replace("|", "\\|").replace("\n", " ")


#: Line width of the rendered usage lines (the terminal's width would make the page vary by machine).
USAGE_WIDTH = 90


def _usage(parser: argparse.ArgumentParser) -> str:
    """``parser.format_usage()`` at a fixed width."""
    formatter = argparse.HelpFormatter(prog=parser.prog, width=USAGE_WIDTH)
    formatter.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups)
    return formatter.format_help().strip()


def _sentence(text: str | None) -> str:
    """A help string as a sentence: capital first letter, one full stop."""
    text = _cell(text).strip().rstrip(".")
    return text[:1].upper() + text[1:] + "." if text else ""


def _arguments_tables(parser: argparse.ArgumentParser) -> list[str]:
    """One table per argument group of ``parser`` (help and subcommand actions left out)."""
    lines: list[str] = []
    for group in parser._action_groups:
        actions = [
            a for a in group._group_actions
            if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))
        ]
        if not actions:
            continue
        lines += ["", f"**{group.title}**", "", "| argument | default | meaning |", "| --- | --- | --- |"]
        for action in actions:
            help_text = action.help if action.help is not argparse.SUPPRESS else ""
            if action.choices is not None and action.option_strings and action.metavar is not None:
                help_text = f"{help_text} (one of: {', '.join(map(str, action.choices))})"
            lines.append(f"| {_flags(action)} | {_default(action)} | {_cell(help_text)} |")
    return lines


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The subcommand parsers of ``parser`` by name, in the order they were added."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


#: Subcommands that hand all their arguments to another program's parser: name -> its module.
#: ``ax12emu diagnose`` runs ``python -m firmware_model.diagnose``, whose parser is built inside
#: its ``parse_args``, so its own ``--help`` text is what the page shows.
FORWARDED = {"diagnose": "firmware_model.diagnose.cli"}


def _forwarded_help(name: str) -> str | None:
    """The ``--help`` text of a forwarded subcommand, or None for one of ``ax12emu``'s own."""
    if name not in FORWARDED:
        return None
    module = importlib.import_module(FORWARDED[name])
    out = io.StringIO()
    with _columns(USAGE_WIDTH), contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        module.parse_args(["--help"])
    return out.getvalue()


@contextlib.contextmanager
def _columns(width: int) -> Iterator[None]:
    """argparse wraps help at ``$COLUMNS``: fix it while a help text is rendered."""
    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(width)
    try:
        yield
    finally:
        if saved is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = saved


def cli_markdown(parser: argparse.ArgumentParser | None = None) -> str:
    """Every subcommand of the ``ax12emu`` parser with its usage and a table of its arguments."""
    parser = parser or build_parser()
    lines = ["```", _usage(parser), "```"]
    lines += _arguments_tables(parser)
    helps = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {choice.dest: choice.help for choice in action._choices_actions}
    for name, sub in subcommands(parser).items():
        lines += ["", f"## `{parser.prog} {name}`", "", _sentence(helps.get(name))]
        forwarded = _forwarded_help(name)
        if forwarded is not None:
            lines += ["", f"Its arguments go to `python -m {FORWARDED[name].rsplit('.', 1)[0]}`:"]
            lines += ["", "```", forwarded.strip(), "```"]
            continue
        lines += ["", "```", _usage(sub), "```"]
        lines += _arguments_tables(sub)
    return "\n".join(lines)


#: Marker comment -> the function whose Markdown replaces it.
def servo_models_markdown() -> str:
    """The shipped servo model files as a Markdown table: identity, table size, rated figures, source."""
    lines = [
        "| file | model | protocol | model number | table bytes (EEPROM) | stall torque | no-load speed | source |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for key in model_names():
        servo = model(key)
        lay = servo.layout()
        ratings = servo.physical.ratings
        torque = "; ".join(f"{r.stall_torque_nm:g} N m @ {r.voltage_v:g} V" for r in ratings)
        speed = "; ".join(f"{r.no_load_speed_rpm:g} rpm @ {r.voltage_v:g} V" for r in ratings)
        page = servo.source.split("https://", 1)[1].split()[0] if "https://" in servo.source else ""
        source = f"[e-manual](https://{page})" if page else _cell(servo.source.split(":")[0])
        lines.append(
            f"| `ax12emu/protocol/models/{key}.toml` | {servo.name} | {'/'.join(servo.protocols)} | {servo.model_number} | "
            f"{lay.table_size} ({lay.eeprom_end}) | {torque} | {speed} | {source} |"
        )
    return "\n".join(lines)


MARKERS: dict[str, Callable[[], str]] = {
    "<!-- ax12emu:control-table -->": control_table_markdown,
    "<!-- ax12emu:cli -->": cli_markdown,
    "<!-- ax12emu:servo-models -->": servo_models_markdown,
}


def on_page_markdown(markdown: str, **_: object) -> str:
    """Replace each marker line with its generated block."""
    for marker, render in MARKERS.items():
        if marker in markdown:
            markdown = markdown.replace(marker, render())
    return markdown


#: A Sphinx cross-reference role as mkdocstrings renders it: the role's name left as text before the
#: code span (``:class:`~ax12emu.VirtualBus``` becomes ``:class:<code>~ax12emu.VirtualBus</code>``).
SPHINX_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|attr|data|mod|obj|exc|const):<code>([~.]?)([^<]*)</code>")


def strip_sphinx_roles(html: str) -> str:
    """The docstrings name code with Sphinx roles (read by ``help()`` and editors alike); the API page is
    rendered by mkdocstrings, which leaves the role's name as text. Keep the code span; ``~`` means its last
    component alone, as Sphinx shows it, and a leading ``.`` (relative to the module) is dropped."""

    def code(match: re.Match[str]) -> str:
        mark, target = match.groups()
        shown = target.rsplit(".", 1)[-1] if mark == "~" else target
        return f"<code>{shown}</code>"

    return SPHINX_ROLE.sub(code, html)


def on_page_content(html: str, **_: object) -> str:
    """Render the docstrings' Sphinx roles as plain code spans."""
    return strip_sphinx_roles(html)


def on_files(files: Files, config: MkDocsConfig, **_: object) -> Files:
    """Publish ``tools/figures/**`` under ``figures/``."""
    for path in sorted(FIGURES_DIR.rglob("*")):
        if path.is_file():
            uri = f"{FIGURES_URI}/{path.relative_to(FIGURES_DIR).as_posix()}"
            files.append(File.generated(config, uri, abs_src_path=str(path)))
    return files
