"""The wire built from the ``--servo`` text, as the harness (VirtualBus, ``ax12emu://``, the pytest plugin) names it.

Why it exists: the builder lives in the bus layer (:mod:`ax12emu.bus.wire`) so ``serve --servo`` and the
harness build every wire through one function; the harness's modules and tests keep importing it from here.
"""

from __future__ import annotations

from ax12emu.bus.wire import build_bus2, build_wire, servo_list, servo_models

__all__ = ["build_bus2", "build_wire", "servo_list", "servo_models"]
