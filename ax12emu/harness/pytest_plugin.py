"""pytest plugin (entry point ``pytest11``): an ``ax12_bus`` fixture with virtual servos.

Why it exists: ``pip install ax12emu`` should be all a robot project needs
to test against servos in CI.  The fixture yields a running
:class:`~ax12emu.VirtualBus` on a pty (in process where there is no pty, e.g.
Windows) and closes it after the test, pass or fail::

    @pytest.mark.ax12_ids(1, 2)
    def test_arm(ax12_bus):
        port = PortHandler(ax12_bus.port)

IDs come from the ``ax12_ids`` marker, or from indirect parametrization
(``@pytest.mark.parametrize("ax12_bus", [[1, 2]], indirect=True)``); the
default is ID 1.  The ``ax12_bus_options`` marker passes keyword arguments
to :class:`~ax12emu.VirtualBus` (``transport="inprocess"``,
``virtual_time=True``, ``faults=FaultConfig(...)``, ...).
"""

from __future__ import annotations

import importlib.util
from collections.abc import Iterator
from typing import Any

import pytest

__all__ = ["ax12_bus"]


def pytest_configure(config: pytest.Config) -> None:
    """Register the markers so ``--strict-markers`` accepts them."""
    config.addinivalue_line("markers", "ax12_ids(*ids): servo IDs of the ax12_bus fixture (default 1)")
    config.addinivalue_line("markers", "ax12_bus_options(**kwargs): keyword arguments for ax12emu.VirtualBus")


def _default_transport() -> str:
    return "pty" if importlib.util.find_spec("pty") is not None and importlib.util.find_spec("termios") is not None else "inprocess"


@pytest.fixture
def ax12_bus(request: pytest.FixtureRequest) -> Iterator[Any]:
    """A running virtual AX-12 bus; ``ax12_bus.port`` is the port to open."""
    from ax12emu.harness.virtual_bus import VirtualBus

    ids: list[int] = [1]
    marker = request.node.get_closest_marker("ax12_ids")
    if marker is not None:
        ids = [int(i) for arg in marker.args for i in (arg if isinstance(arg, (list, tuple)) else [arg])]
    if hasattr(request, "param"):
        ids = list(request.param) if isinstance(request.param, (list, tuple)) else [int(request.param)]
    options = {"transport": _default_transport()}
    options_marker = request.node.get_closest_marker("ax12_bus_options")
    if options_marker is not None:
        options.update(options_marker.kwargs)
    with VirtualBus(ids, **options) as bus:
        yield bus
