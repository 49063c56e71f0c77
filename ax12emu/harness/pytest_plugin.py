"""pytest plugin (entry point ``pytest11``): an ``ax12_bus`` fixture with virtual servos.

Why it exists: ``pip install ax12emu`` should be all a robot project needs
to test against servos in CI.  The fixture yields a running
:class:`~ax12emu.VirtualBus` on a pty (in process where there is no pty, e.g.
Windows) and closes it after the test, pass or fail::

    @pytest.mark.ax12_ids(1, 2)
    def test_arm(ax12_bus):
        port = PortHandler(ax12_bus.port)     # a pty's path; without ptys, UrlPortHandler (below)

Where there is no pty (Windows) the port is an ``ax12emu://NAME`` URL, which
``serial.serial_for_url`` opens but dynamixel-sdk's ``PortHandler`` does not
(it opens ``serial.Serial(name)``, device paths only): open it with a
``PortHandler`` subclass whose ``setupPort`` calls ``serial_for_url`` (the
``UrlPortHandler`` of ``tools/examples/robot_arm.py`` and docs/testing.md,
which opens device paths too, so one handler serves both platforms).

IDs come from the ``ax12_ids`` marker, or from indirect parametrization
(``@pytest.mark.parametrize("ax12_bus", [[1, 2]], indirect=True)``, which
wins over a module's or class's marker); the default is ID 1.  The
``ax12_bus_options`` marker passes keyword arguments to
:class:`~ax12emu.VirtualBus` (``transport="inprocess"``,
``virtual_time=True``, ``faults=FaultConfig(...)``, ...); markers on the
module, the class and the test add up, and where two give one keyword the
closest wins (a subclass's own over those it inherits).  IDs and servos given twice (``ax12_ids`` and ``ids=``, ``ax12_servo`` and ``servo=``, IDs
beside a per-ID servo text) are a usage error, not a silent choice.

Other models (the X series on Protocol 2.0, the MX series on Protocol 1.0): the ``ax12_servo``
marker takes the servo text of ``ax12emu serve --servo`` (``@pytest.mark.ax12_servo("xl430-w250")``
or ``("mx-28")`` with ``ax12_ids``, or ``@pytest.mark.ax12_servo("1-5:xm430-w350,6:mx-64")`` alone);
``pytest --ax12-servo SPEC`` gives every ax12_bus without the marker those servos, so a suite
written for one model runs against another; each model starts at its factory rate, so such a suite
pins its own with ``ax12_bus_options(baud_bps=...)``, which the AX-12A bus takes too.  Protocol 1.0 models in the text share the wire with
the 2.0 ones (``"1:ax-12a,1:xl430-w250"``; ``protocol=`` names an ID both protocols have).

``pytest --ax12-web`` serves a live page of each bus (see the live-view docs)
and keeps it up after the test, pass or fail, until Ctrl-C, so a failing
test can be watched and its last state inspected; not under pytest-xdist,
whose workers can neither show the URL nor get the Ctrl-C.
"""

from __future__ import annotations

import importlib.util
import numbers
import os
import time
from collections.abc import Iterator
from typing import Any

import pytest

__all__ = ["ax12_bus"]


def pytest_addoption(parser: pytest.Parser) -> None:
    """``--ax12-web``: watch each ax12_bus in the browser; the page stays up after the test until Ctrl-C."""
    group = parser.getgroup("ax12emu")
    group.addoption(
        "--ax12-web",
        action="store_true",
        help="serve a live view of each ax12_bus and keep it up after the test until Ctrl-C (not under pytest-xdist)",
    )
    group.addoption(
        "--ax12-servo",
        default=None,
        metavar="SPEC",
        help="servos of other models for every ax12_bus without an ax12_servo marker: MODEL (e.g. xl430-w250, mx-28) "
        "or IDS:MODEL,... (e.g. 1-5:xm430-w350,6:xl330-m077); 'ax12emu models' lists the models",
    )
    group.addoption(
        "--ax12-web-at",
        default="127.0.0.1:0",
        metavar="HOST:PORT",
        help="where --ax12-web serves (loopback only; default a free port on 127.0.0.1)",
    )


def _say(config: pytest.Config, text: str) -> None:
    """A line on the terminal even while pytest captures output."""
    capture = config.pluginmanager.getplugin("capturemanager")
    writer = config.pluginmanager.getplugin("terminalreporter")
    if capture is not None and writer is not None:
        with capture.global_and_fixture_disabled():
            writer.write_line(text)
    elif writer is not None:
        writer.write_line(text)


def _linger(config: pytest.Config, url: str) -> None:
    """Keep the page up until Ctrl-C, which ends the wait (and not the test run)."""
    _say(config, f"ax12emu live view still at {url} - press Ctrl-C to close it and go on")
    try:
        while True:
            time.sleep(0.2)
    except KeyboardInterrupt:
        _say(config, "ax12emu live view closed")


def _distributed(config: pytest.Config) -> bool:
    """Whether pytest-xdist runs the tests in worker processes: this is its controller, or one of its workers.

    A worker is told by ``config.workerinput``, not by PYTEST_XDIST_WORKER: a pytest started from inside a worker's
    test inherits that variable and is no worker."""
    if hasattr(config, "workerinput"):
        return True
    return getattr(config.option, "dist", "no") != "no" and bool(getattr(config.option, "tx", None))


def _check_servo_option(config: pytest.Config) -> None:
    """A UsageError for an ``--ax12-servo`` text the bus builder would refuse, read by the builder's own parser.

    The fixture reads the option only for a bus without an ``ax12_servo`` marker, so a mistyped model would pass
    the marked tests and error each of the others with a traceback: a run that looks half broken, not mistyped.
    IDs it is paired with (``ax12_ids``) are a fixture's matter: a bare MODEL is checked on ID 1."""
    text = config.getoption("--ax12-servo", None)
    if text is None:
        return
    from ax12emu.bus.wire import servo_models

    try:
        servo_models(text, None, mixed=True)
    except ValueError as exc:
        raise pytest.UsageError(f"--ax12-servo {text!r}: {exc}") from None


def pytest_configure(config: pytest.Config) -> None:
    """Register the markers so ``--strict-markers`` accepts them; refuse ``--ax12-web`` where it cannot work and an
    ``--ax12-servo`` text that names no servos."""
    _check_servo_option(config)
    if config.getoption("--ax12-web", False) and _distributed(config):
        # A worker's output never reaches the terminal (no URL is shown) and its linger waits for a Ctrl-C that
        # only the controller gets, so the run hangs; the workers would also share one --ax12-web-at address.
        raise pytest.UsageError("--ax12-web cannot run under pytest-xdist: its workers' live-view URLs never reach "
                                "this terminal and each waits for a Ctrl-C it never gets; run without -n (or -n 0)")
    config.addinivalue_line("markers", "ax12_ids(*ids): servo IDs of the ax12_bus fixture (default 1)")
    config.addinivalue_line("markers", "ax12_bus_options(**kwargs): keyword arguments for ax12emu.VirtualBus")
    config.addinivalue_line("markers", "ax12_servo(spec): the ax12_bus fixture's servo models (X series, MX, ...), as serve --servo takes them")


def _marker_takes(marker: pytest.Mark, example: str, *, args: bool) -> None:
    """A UsageError for a marker written the other way round (its keywords or its positional arguments were
    ignored: ``ax12_servo(servo=...)`` served an AX-12A), naming how it is written."""
    if (marker.kwargs if args else marker.args):
        raise pytest.UsageError(f"@pytest.mark.{marker.name} takes {'positional arguments' if args else 'keywords'}: {example}")


def _marker_id(value: Any, where: str = "@pytest.mark.ax12_ids", example: str = "ax12_ids(1, 2, 3)") -> int:
    """One ID of ``ax12_ids`` (or of ``where``): an integer (numpy's too); a text such as "1,2" or a float such as
    1.9 (which int() made ID 1) is a UsageError, not a deep one."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise pytest.UsageError(f"{where} takes integer IDs, got {value!r}: {example}")
    return int(value)


def _id_values(values: Any, where: str, example: str) -> list[int]:
    """IDs given as one integer or a list, tuple or range of them, each checked as the ``ax12_ids`` marker's."""
    items = values if isinstance(values, (list, tuple, range)) else [values]
    return [_marker_id(value, where, example) for value in items]


def _bus_options(node: Any) -> dict[str, Any]:
    """The keywords of every ``ax12_bus_options`` marker on the test (its own, its class's, its module's, ...), merged
    closest first: a keyword two of them give takes the closest one's value (the test's over its class's, a
    subclass's own over those it inherits, over its module's), as pytest's own closest marker does; taking the
    closest marker alone dropped the others' keywords without a word."""
    by_node: dict[int, list[Any]] = {}  # closest node first; within one, pytest lists a base class's marks first
    for owner, marker in node.iter_markers_with_node("ax12_bus_options"):
        _marker_takes(marker, "ax12_bus_options(virtual_time=True)", args=False)
        by_node.setdefault(id(owner), []).append(marker)
    given: dict[str, Any] = {}
    for markers in by_node.values():
        for marker in reversed(markers):  # a class's own marks after those it inherits: they win
            for key, value in marker.kwargs.items():
                given.setdefault(key, value)
    return given


def _started(bus: Any, web_at: str | None) -> Any:
    """``bus`` started; the live view's bind error at ``--ax12-web-at`` (a port in use) a UsageError naming the
    option and the address, which a bare "Address already in use" leaves to guess.  ``web_at``: the address the
    command line gave the live view, None where it gave none."""
    try:
        return bus.start()
    except OSError as exc:
        if web_at is None or not bus.port:  # no live view of the command line's, or the bus's own port failed
            raise
        # (the bus's own error names its argument and address again: the errno's words alone here)
        said = os.strerror(exc.errno) if exc.errno else str(exc)
        raise pytest.UsageError(f"--ax12-web-at {web_at}: the live view cannot serve there ({said}); "
                                "give another HOST:PORT, or leave the option out for a free port") from exc


def _default_transport() -> str:
    return "pty" if importlib.util.find_spec("pty") is not None and importlib.util.find_spec("termios") is not None else "inprocess"


@pytest.fixture
def ax12_bus(request: pytest.FixtureRequest) -> Iterator[Any]:
    """A running virtual AX-12 bus; ``ax12_bus.port`` is the port to open."""
    from ax12emu.harness.virtual_bus import VirtualBus

    ids: list[int] | None = None  # VirtualBus's default: ID 1, or the IDs a per-ID servo text names
    ids_from = ""  # where the IDs came from, for a UsageError naming both sides of a conflict
    marker = request.node.get_closest_marker("ax12_ids")
    if marker is not None:
        _marker_takes(marker, "ax12_ids(1, 2, 3) or ax12_ids([1, 2, 3])", args=True)
        ids = [i for arg in marker.args for i in _id_values(arg, "@pytest.mark.ax12_ids", "ax12_ids(1, 2, 3)")]
        ids_from = "ax12_ids"
    if hasattr(request, "param"):  # the closer choice: a parametrized test under a module's or class's ax12_ids
        ids = _id_values(request.param, "an indirect ax12_bus parameter",
                         'parametrize("ax12_bus", [1, [2, 3], range(4, 7)], indirect=True)')
        ids_from = "the indirect ax12_bus parameter"
    options: dict[str, Any] = {"transport": _default_transport()}
    given = _bus_options(request.node)
    if "ids" in given:
        if ids is not None:
            raise pytest.UsageError(f"ax12_bus_options(ids=...) and {ids_from} both give the IDs; give them once")
        ids = _id_values(given.pop("ids"), "ax12_bus_options(ids=...)", "ax12_bus_options(ids=[1, 2])")
        ids_from = "ax12_bus_options(ids=...)"
    servo_marker = request.node.get_closest_marker("ax12_servo")
    if servo_marker is not None:
        _marker_takes(servo_marker, 'ax12_servo("1-2:xl430-w250")', args=True)
        if len(servo_marker.args) != 1:
            raise pytest.UsageError('ax12_servo takes one servo text, e.g. ax12_servo("1-2:xl430-w250")')
        if "servo" in given:
            raise pytest.UsageError("ax12_servo and ax12_bus_options(servo=...) both give the servos; give them once")
    # The test's own choice (the marker, or servo= among its options) before the command line's --ax12-servo.
    servo, servo_from = ((servo_marker.args[0], "ax12_servo") if servo_marker is not None
                         else (given.pop("servo"), "ax12_bus_options(servo=...)") if "servo" in given
                         else (request.config.getoption("--ax12-servo", None), "--ax12-servo"))
    if servo is not None:
        if ids is not None and isinstance(servo, str) and ":" in servo:
            raise pytest.UsageError(f"{ids_from} and the per-ID servo text {servo!r} of {servo_from} both name the IDs; "
                                    "give one of them (IDS:MODEL names them itself)")
        options["servo"] = servo
    options.update(given)
    web = request.config.getoption("--ax12-web", False)
    web_at = request.config.getoption("--ax12-web-at") if web and "web" not in options else None
    if web_at is not None:
        options["web"] = web_at
    with _started(VirtualBus(ids, **options), web_at) as bus:
        if bus.web_url is not None:
            _say(request.config, f"ax12emu live view of {request.node.nodeid}: {bus.web_url}")
        yield bus
        if web and bus.web_url is not None:
            _linger(request.config, bus.web_url)
