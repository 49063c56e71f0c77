"""The Protocol 1.0 conformance suite, as a library: ``run(port, ids)`` -> a report.

Why it exists: one suite judges the emulator and real servos alike, so a
user with hardware finds where they differ in one command
(``ax12emu conformance PORT``) and the project's own tests run the very
same checks over a pty, TCP and in process.  The suite reads every table
before the first check and after the last, and reports any register that
changed as the last check ("table unchanged"): the non-destructive set must
leave the device as it found it.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

from ax12emu.protocol.control_table import DEFAULT_PROFILE

from .checks import CHECKS, Check, Context, Failed, Note, Skipped, table_differences
from .link import Link, open_port

__all__ = ["run", "run_on_link", "Report", "Result", "PASS", "FAIL", "SKIP", "NOTE", "CHECKS", "Check"]

PASS, FAIL, SKIP, NOTE = "pass", "FAIL", "skip", "note"


@dataclass(frozen=True)
class Result:
    """One check's outcome and the figure measured."""

    name: str
    outcome: str
    figure: str
    seconds: float


@dataclass(frozen=True)
class Report:
    """All results of one run."""

    port: str
    ids: tuple[int, ...]
    destructive: bool
    results: tuple[Result, ...]

    @property
    def passed(self) -> bool:
        """True if no check failed."""
        return all(r.outcome != FAIL for r in self.results)

    def outcome(self, name: str) -> str:
        """The outcome of the check called ``name``."""
        return next(r.outcome for r in self.results if r.name == name)

    def table(self) -> str:
        """A fixed-width pass/fail table with the figure of each check."""
        width = max(len(r.name) for r in self.results)
        lines = [f"{'check':<{width}}  result  measured", f"{'-' * width}  ------  --------"]
        lines += [f"{r.name:<{width}}  {r.outcome:<6}  {r.figure}" for r in self.results]
        failed = sum(r.outcome == FAIL for r in self.results)
        lines.append(f"{len(self.results)} checks, {failed} failed" + (" (destructive set included)" if self.destructive else ""))
        return "\n".join(lines)


def _run_one(check: Check, ctx: Context) -> Result:
    start = time.perf_counter()
    try:
        figure = check.run(ctx)
        outcome, text = (NOTE, figure.figure) if isinstance(figure, Note) else (PASS, figure)
    except Failed as exc:
        outcome, text = FAIL, str(exc)
    except Skipped as exc:
        outcome, text = SKIP, str(exc)
    except (OSError, ValueError) as exc:  # a port error is this check's failure, not the suite's
        outcome, text = FAIL, f"{type(exc).__name__}: {exc}"
    return Result(check.name, outcome, text, time.perf_counter() - start)


def run_on_link(
    link: Link,
    ids: Sequence[int],
    *,
    destructive: bool = False,
    profile: str = DEFAULT_PROFILE,
    only: Sequence[str] | None = None,
    port_name: str = "",
) -> Report:
    """Run the checks over an open :class:`Link`."""
    ctx = Context(link, list(ids), profile=profile, destructive=destructive)
    results: list[Result] = []
    try:
        for servo_id in ctx.ids:
            ctx.before[servo_id] = ctx.table(servo_id)
    except Failed as exc:
        return Report(port_name, tuple(ids), destructive, (Result("read tables", FAIL, str(exc), 0.0),))
    for check in CHECKS:
        if only is not None and check.name not in only:
            continue
        if check.destructive and not destructive:
            results.append(Result(check.name, SKIP, "destructive: needs --destructive", 0.0))
            continue
        results.append(_run_one(check, ctx))
    results.append(_run_one(Check("table unchanged", _unchanged), ctx))
    return Report(port_name, tuple(ids), destructive, tuple(results))


def _unchanged(ctx: Context) -> str:
    differ = []
    for servo_id, before in ctx.before.items():
        differ += [f"ID {servo_id}: {d}" for d in table_differences(before, ctx.table(servo_id), ctx.profile)]
    if differ:
        raise Failed("; ".join(differ))
    return f"{len(ctx.before)} table(s) read before and after: identical"


def run(
    port: str,
    ids: Sequence[int] = (1,),
    *,
    baud: int = 1_000_000,
    timeout_s: float = 0.05,
    destructive: bool = False,
    profile: str = DEFAULT_PROFILE,
    only: Sequence[str] | None = None,
) -> Report:
    """Open ``port`` (a device path or a pyserial URL), run the suite, close the port."""
    if not ids:
        raise ValueError("conformance needs at least one ID")
    link = Link(open_port(port, baud), timeout_s=timeout_s)
    try:
        return run_on_link(link, ids, destructive=destructive, profile=profile, only=only, port_name=port)
    finally:
        link.close()
