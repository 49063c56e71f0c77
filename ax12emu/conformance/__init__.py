"""The conformance suites, as a library: ``run(port, ids)`` -> a report (``protocol="2.0"``: the X series').

Why it exists: one suite judges the emulator and real servos alike, so a
user with hardware finds where they differ in one command
(``ax12emu conformance PORT``) and the project's own tests run the very
same checks over a pty, TCP and in process.  The suite reads every table
before the first check and after the last, and reports any register that
changed as the last check ("table unchanged"): the non-destructive set must
leave the device as it found it.  Both suites first identify every ID and
take its control table from the model file its model number names: the
Protocol 1.0 suite (:mod:`.checks`) reads Model Number, the Protocol 2.0
suite (:mod:`.checks2`) pings.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

from ax12emu.protocol.control_table import DEFAULT_PROFILE

from .checks import CHECKS, Check, Context, Failed, Note, Skipped, table_differences
from .checks2 import CHECKS2, Context2, table_differences2
from .link import Link, Link2, check_waits, open_port

__all__ = ["run", "run_on_link", "Report", "Result", "PASS", "FAIL", "SKIP", "NOTE", "CHECKS", "CHECKS2", "Check",
           "PROTOCOLS"]

PASS, FAIL, SKIP, NOTE = "pass", "FAIL", "skip", "note"
#: The protocols a suite exists for.
PROTOCOLS = ("1.0", "2.0")


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
    #: The checks that turn the shaft were run (``motion=True``).
    motion: bool = False

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
        included = [name for name, on in (("destructive", self.destructive), ("motion", self.motion)) if on]
        lines.append(f"{len(self.results)} checks, {failed} failed" + (f" ({' and '.join(included)} sets included)" if included else ""))
        return "\n".join(lines)


def _run_one(check: Check, ctx: Context | Context2) -> Result:
    start = time.perf_counter()
    late = len(ctx.link.late)
    try:
        figure = check.run(ctx)
        outcome, text = (NOTE, figure.figure) if isinstance(figure, Note) else (PASS, figure)
    except Failed as exc:
        outcome, text = FAIL, str(exc)
    except Skipped as exc:
        outcome, text = SKIP, str(exc)
    except (OSError, ValueError) as exc:  # a port error is this check's failure, not the suite's
        outcome, text = FAIL, f"{type(exc).__name__}: {exc}"
    if len(ctx.link.late) > late and outcome != FAIL:  # see link.py: a reply after its silence window
        outcome = FAIL
        text = (f"a status packet came after the {ctx.link.silence_s * 1e3:g} ms silence window "
                f"(sent -> received: {'; '.join(ctx.link.late[late:])})")
    return Result(check.name, outcome, text, time.perf_counter() - start)


def run_on_link(
    link: Link,
    ids: Sequence[int],
    *,
    destructive: bool = False,
    profile: str = DEFAULT_PROFILE,
    only: Sequence[str] | None = None,
    port_name: str = "",
    motion: bool = False,
) -> Report:
    """Run the checks over an open :class:`Link` (a :class:`Link2` runs the Protocol 2.0 suite)."""
    ctx: Context | Context2
    if isinstance(link, Link2):
        ctx, checks, unchanged = Context2(link, list(ids), destructive=destructive), CHECKS2, _unchanged2
    else:
        ctx, checks, unchanged = Context(link, list(ids), profile=profile, destructive=destructive), CHECKS, _unchanged
    unknown = sorted(set(only or ()) - {check.name for check in checks})
    if unknown:  # a misspelt name would run nothing and report a pass
        raise ValueError(f"no such check: {', '.join(unknown)}; the Protocol {'2.0' if isinstance(link, Link2) else '1.0'} "
                         f"checks are: {', '.join(check.name for check in checks)}")
    results: list[Result] = []
    try:
        _run_checks(ctx, checks, unchanged, results, only=only, destructive=destructive, motion=motion)
    finally:
        # A Status Return Level raised for the run (identify: a servo at level 1 answers no WRITE) is put back however
        # the run ends; the row says so.
        if ctx.raised:
            results.append(_run_one(Check("Status Return Level put back", lambda c: Note(c.put_back_levels())), ctx))
    return Report(port_name, tuple(ids), destructive, tuple(results), motion)


def _run_checks(ctx: Context | Context2, checks: Sequence[Check], unchanged, results: list[Result], *,
                only: Sequence[str] | None, destructive: bool, motion: bool) -> None:
    """Identify the servos, read their tables, run the checks asked for and "table unchanged", into ``results``."""
    try:
        ctx.identify()
        for servo_id in ctx.ids:
            ctx.before[servo_id] = ctx.table(servo_id)
    except (Failed, OSError) as exc:
        results.append(Result("read tables", FAIL, str(exc), 0.0))
        return
    for check in checks:
        if only is not None and check.name not in only:
            continue
        if check.destructive and not destructive:
            results.append(Result(check.name, SKIP, "destructive: needs --destructive", 0.0))
            continue
        if check.motion and not motion:
            results.append(Result(check.name, SKIP, "turns the shaft: needs --motion", 0.0))
            continue
        refusal = ctx.refusal(check)
        if refusal is not None:
            results.append(Result(check.name, SKIP, refusal, 0.0))
            continue
        results.append(_run_one(check, ctx))
    results.append(_run_one(Check("table unchanged", unchanged), ctx))


def _unchanged(ctx: Context) -> str:
    differ = []
    for servo_id, before in ctx.before.items():
        differ += [f"ID {servo_id}: {d}" for d in table_differences(before, ctx.table(servo_id), ctx.layout(servo_id))]
    if differ:
        raise Failed("; ".join(differ))
    return f"{len(ctx.before)} table(s) read before and after: identical"


def _unchanged2(ctx: Context2) -> str:
    differ = []
    for servo_id, before in ctx.before.items():
        layout = ctx.layout(servo_id)
        differ += [f"ID {servo_id}: {d}" for d in table_differences2(before, ctx.table(servo_id), layout)]
    if differ:
        raise Failed("; ".join(differ))
    return f"{len(ctx.before)} table(s) read before and after: identical (registers the firmware sets excepted)"


def run(
    port: str,
    ids: Sequence[int] = (1,),
    *,
    baud: int = 1_000_000,
    timeout_s: float = 0.05,
    silence_s: float | None = None,
    destructive: bool = False,
    profile: str = DEFAULT_PROFILE,
    only: Sequence[str] | None = None,
    protocol: str = "1.0",
    motion: bool = False,
) -> Report:
    """Open ``port`` (a device path or a pyserial URL), run the ``protocol`` suite, close the port.

    ``timeout_s``: how long a reply may take; ``silence_s``: how long a packet that must get no reply is
    listened to (default ``timeout_s``, safe on any adapter; see :mod:`.link`).
    """
    if not ids:
        raise ValueError("conformance needs at least one ID")
    protocol = {1.0: "1.0", 2.0: "2.0"}.get(protocol, protocol) if isinstance(protocol, float) else protocol  # as VirtualBus's
    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {', '.join(PROTOCOLS)}, got {protocol!r}")
    check_waits(timeout_s, silence_s)  # before the port is opened (a refused value left it open)
    link = (Link2 if protocol == "2.0" else Link)(open_port(port, baud), timeout_s=timeout_s, silence_s=silence_s)
    try:
        return run_on_link(link, ids, destructive=destructive, profile=profile, only=only, port_name=port, motion=motion)
    finally:
        link.close()
