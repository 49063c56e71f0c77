"""ax12emu: a virtual Dynamixel AX-12+ bus speaking Protocol 1.0 byte for byte.

Importing the package registers the ``ax12emu://`` pyserial URL handler
(``serial.serial_for_url("ax12emu://?ids=1,2")``, see
:mod:`ax12emu.harness.urlhandler.protocol_ax12emu`); :class:`VirtualBus` and
:class:`FaultConfig` are imported on first use, so ``import ax12emu`` stays light.
"""

from typing import Any

from .harness.urlhandler import register as _register_url_handler

__version__ = "0.1.0"

__all__ = ["__version__", "VirtualBus", "FaultConfig"]

_register_url_handler()

#: Public names imported lazily: name -> module.
_LAZY = {"VirtualBus": ".harness.virtual_bus", "FaultConfig": ".faults.config"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'ax12emu' has no attribute {name!r}")
